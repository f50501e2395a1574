//! `sampling`: presorted Sobol packets with their Cranley–Patterson rotation, and the
//! cosine-weighted hemisphere map (paper §2.4 and §2.2; kernels `sobol`, `presort`,
//! `mapping`).
//!
//! A baker computes the presorted order once per sample count N ([`guidebake_presort`]), then
//! per texel and iteration the rotation ([`guidebake_rotation`]), the order reordered for that
//! rotation ([`guidebake_reorder_after_rotation`]), and per packet of eight indices the rotated
//! points in [0,1)² ([`guidebake_packet_points8`]) that the guide's warp takes.

use crate::{
    GuidebakeStatus, check_one, disjoint, fail, guard, load8, read_array, slice, slice_mut, store8,
    write_array,
};
use glam::Vec3;
use guidebake_kernels::{mapping, presort, sobol};
use wide::f32x8;

/// Writes the Cranley–Patterson offset of (`seed`, `texel`, `iteration`) to `out[2]`
/// (32-bit fixed point per axis).
///
/// # Safety
/// `out` points to 2 writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_rotation(
    seed: u32,
    texel: u64,
    iteration: u32,
    out: *mut u32,
) -> GuidebakeStatus {
    guard("guidebake_rotation", || {
        check_one(out, "out")?;
        // SAFETY: checked; 2 writable values is the caller's contract.
        unsafe { write_array(out, sobol::rotation(seed, texel, iteration)) };
        Ok(())
    })
}

/// Writes the Sobol point `index` (first two dimensions, 32-bit fixed point) to `out[2]`.
///
/// # Safety
/// `out` points to 2 writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_sobol_2d(index: u32, out: *mut u32) -> GuidebakeStatus {
    guard("guidebake_sobol_2d", || {
        check_one(out, "out")?;
        // SAFETY: checked; 2 writable values is the caller's contract.
        unsafe { write_array(out, sobol::sobol_2d(index)) };
        Ok(())
    })
}

/// 32-bit fixed point to a float in [0, 1) (exact: the top 24 bits times 2⁻²⁴).
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_to_unit(x: u32) -> f32 {
    sobol::to_unit(x)
}

/// Writes the presorted order of the first `n` Sobol points to `out` (`out_len` must equal
/// `n`): consecutive groups of 8 are coherent packets. Once per sample count; the only call
/// of the ABI whose cost is a sort (no allocation).
///
/// # Safety
/// `out` points to `out_len` writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_presort(
    n: u32,
    out: *mut u32,
    out_len: usize,
) -> GuidebakeStatus {
    guard("guidebake_presort", || {
        if out_len as u64 != u64::from(n) {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("`out_len` is {out_len}, it must equal n = {n}"),
            ));
        }
        // SAFETY: checked by `slice_mut`; validity is the caller's contract.
        let out = unsafe { slice_mut(out, out_len, "out") }?;
        presort::presort_into(n, out);
        Ok(())
    })
}

/// Reorders a presorted `order` for one texel's rotation so packets stay coherent after the
/// torus wrap (a stable partition by wrap quadrant) into `out` (`out_len == len`, no
/// overlap with `order`).
///
/// # Safety
/// `order` points to `len` readable, `rotation` to 2 readable and `out` to `out_len`
/// writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_reorder_after_rotation(
    order: *const u32,
    len: usize,
    rotation: *const u32,
    out: *mut u32,
    out_len: usize,
) -> GuidebakeStatus {
    guard("guidebake_reorder_after_rotation", || {
        if out_len != len {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("`out_len` is {out_len}, it must equal `len` = {len}"),
            ));
        }
        // SAFETY: each pointer is checked before use; validity is the caller's contract.
        let r = unsafe { read_array::<u32, 2>(rotation, "rotation") }?;
        disjoint(order, len, out, out_len, "`order` and `out`")?;
        // SAFETY: as above; the two buffers are disjoint (checked).
        let order = unsafe { slice(order, len, "order") }?;
        // SAFETY: as above.
        let out = unsafe { slice_mut(out, out_len, "out") }?;
        presort::reorder_after_rotation_into(order, r, out);
        Ok(())
    })
}

/// One packet's points: lane i of `out_x`/`out_y` is the Sobol point `indices[i]` rotated by
/// `rotation`, in [0,1). `count` is 1..=8; lanes past it repeat the last index (valid points
/// the caller masks off).
///
/// # Safety
/// `indices` points to `count` readable `uint32_t`, `rotation` to 2; `out_x` and `out_y` to 8
/// writable floats each.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_packet_points8(
    indices: *const u32,
    count: usize,
    rotation: *const u32,
    out_x: *mut f32,
    out_y: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_packet_points8", || {
        if !(1..=8).contains(&count) {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("`count` is {count}, it must be 1..=8"),
            ));
        }
        // SAFETY: each pointer is checked before use; validity is the caller's contract.
        let packet = unsafe { slice(indices, count, "indices") }?;
        // SAFETY: as above.
        let r = unsafe { read_array::<u32, 2>(rotation, "rotation") }?;
        check_one(out_x, "out_x")?;
        check_one(out_y, "out_y")?;
        let [x, y] = presort::packet_u_x8(packet, r);
        // SAFETY: checked; 8 writable floats each is the caller's contract.
        unsafe {
            write_array(out_x, x.to_array());
            write_array(out_y, y.to_array());
        }
        Ok(())
    })
}

/// Maps eight points of [0,1)² to directions on the cosine-weighted hemisphere around +z
/// (local frame, z = the normal): lane i of `out_x/out_y/out_z`. Density cosθ/π.
///
/// # Safety
/// `x`, `y` point to 8 readable floats each; `out_x`, `out_y`, `out_z` to 8 writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_sample_cosine_hemisphere8(
    x: *const f32,
    y: *const f32,
    out_x: *mut f32,
    out_y: *mut f32,
    out_z: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_sample_cosine_hemisphere8", || {
        check_one(x, "x")?;
        check_one(y, "y")?;
        check_one(out_x, "out_x")?;
        check_one(out_y, "out_y")?;
        check_one(out_z, "out_z")?;
        // SAFETY: checked; 8 readable floats each is the caller's contract.
        let u = unsafe { [load8(x), load8(y)] };
        check_points8(u[0], u[1])?;
        let [dx, dy, dz] = mapping::sample_cosine_hemisphere_x8(u);
        // SAFETY: checked; writable is the caller's contract. The inputs were read first.
        unsafe {
            store8(out_x, dx);
            store8(out_y, dy);
            store8(out_z, dz);
        }
        Ok(())
    })
}

/// [`guidebake_sample_cosine_hemisphere8`] for one point: `u[2]` → `out[3]`.
///
/// # Safety
/// `u` points to 2 readable floats, `out` to 3 writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_sample_cosine_hemisphere(
    u: *const f32,
    out: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_sample_cosine_hemisphere", || {
        // SAFETY: checked before reading.
        let u = unsafe { read_array::<f32, 2>(u, "u") }?;
        check_points8(f32x8::splat(u[0]), f32x8::splat(u[1]))?;
        check_one(out, "out")?;
        // SAFETY: checked; writable is the caller's contract.
        unsafe { write_array(out, mapping::sample_cosine_hemisphere(u).to_array()) };
        Ok(())
    })
}

/// Density per unit solid angle of the cosine-weighted hemisphere: cosθ/π, 0 below the
/// horizon.
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    mapping::cosine_hemisphere_pdf(cos_theta)
}

/// A right-handed orthonormal basis (`out_t`, `out_b`) with t × b = n for a unit normal
/// `n[3]` (Duff et al. 2017). A world direction is `t·x + b·y + n·z` of a local one.
///
/// # Safety
/// `n` points to 3 readable floats; `out_t`, `out_b` to 3 writable floats each.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_orthonormal_basis(
    n: *const f32,
    out_t: *mut f32,
    out_b: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_orthonormal_basis", || {
        // SAFETY: checked before reading.
        let n = unsafe { read_array::<f32, 3>(n, "n") }?;
        if !n.iter().all(|c| c.is_finite()) {
            return Err(fail(
                GuidebakeStatus::InvalidArgument,
                format_args!("`n` = {n:?} is not finite"),
            ));
        }
        check_one(out_t, "out_t")?;
        check_one(out_b, "out_b")?;
        let (t, b) = mapping::orthonormal_basis(Vec3::from_array(n));
        // SAFETY: checked; writable is the caller's contract.
        unsafe {
            write_array(out_t, t.to_array());
            write_array(out_b, b.to_array());
        }
        Ok(())
    })
}

/// Fails unless every lane lies in [0,1)² (the warps' and maps' domain).
#[inline(always)]
pub(crate) fn check_points8(x: f32x8, y: f32x8) -> Result<(), crate::Fail> {
    let (zero, one) = (f32x8::splat(0.0), f32x8::splat(1.0));
    let inside = x.simd_ge(zero) & x.simd_lt(one) & y.simd_ge(zero) & y.simd_lt(one);
    if inside.to_bitmask() == 0xff {
        return Ok(());
    }
    Err(outside(x.to_array(), y.to_array()))
}

#[cold]
#[inline(never)]
fn outside(x: [f32; 8], y: [f32; 8]) -> crate::Fail {
    let lane = (0..8)
        .find(|&i| !((0.0..1.0).contains(&x[i]) && (0.0..1.0).contains(&y[i])))
        .unwrap_or(0);
    fail(
        GuidebakeStatus::InvalidArgument,
        format_args!(
            "point {lane} = ({}, {}) is outside [0,1)^2",
            x[lane], y[lane]
        ),
    )
}
