//! `estimator`: per-iteration batches, their per-texel combination and the global bias
//! correction ρ (paper §2.5; kernel `estimator`).
//!
//! A texel's iteration k accumulates its irradiance samples in a [`GuidebakeWelford`] batch
//! (Welford's running mean and variance of R, G, B and luminance, in `f64`). The batches of a
//! texel are then combined:
//! - [`guidebake_combine_default`]: what the bake does by default, Graybill–Deal per texel
//!   with the variance floor 0.25 (the driver's `--combine texel`), to be multiplied by ρ;
//! - [`guidebake_combine_graybill_deal`]: the same with a chosen floor;
//! - [`guidebake_combine_average`]: the plain sample-count weighted average (unbiased);
//! - [`guidebake_combine_weighted`]: given per-iteration weights (Müller et al.'s global
//!   scheme, pass 2).
//!
//! ρ = Σ average luminance / Σ Graybill–Deal luminance over all texels is accumulated in a
//! [`GuidebakeRho`] per thread or shard; accumulators merge in any order to bit-identical
//! results, and serialize to 96 little-endian bytes to cross machines.
//!
//! [`GuidebakeWelford`] and [`GuidebakeRho`] are opaque, fixed-size, plain-old-data values
//! (any bytes are a valid value, copying is fine): keep them in arrays or files.

use crate::{Fail, GuidebakeStatus, check_one, fail, guard, read_array, slice};
use guidebake_kernels::estimator::{
    self, DEFAULT_REL_STD_FLOOR, Estimate, GraybillDeal, RHO_BYTES, RhoAccumulator, TexelEstimate,
    Welford,
};

/// One batch of samples (one texel, one iteration): opaque, 80 bytes, plain old data.
/// Initialise with [`guidebake_welford_init`] (all-zero bytes are the empty batch too).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeWelford {
    /// Private.
    pub opaque: [u64; 10],
}

/// The global ρ sums: opaque, 96 bytes, plain old data. Initialise with
/// [`guidebake_rho_init`] (all-zero bytes are the empty accumulator too).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeRho {
    /// Private.
    pub opaque: [u64; 12],
}

const _: () = {
    assert!(size_of::<GuidebakeWelford>() == size_of::<Welford>());
    assert!(align_of::<GuidebakeWelford>() == align_of::<Welford>());
    assert!(size_of::<GuidebakeRho>() == size_of::<RhoAccumulator>());
    assert!(align_of::<GuidebakeRho>() == align_of::<RhoAccumulator>());
    assert!(RHO_BYTES == 96);
};

/// A batch's statistics ([`guidebake_welford_stats`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeWelfordStats {
    /// Finite samples accepted.
    pub count: u64,
    /// Non-finite samples rejected.
    pub rejected: u64,
    /// Mean R, G, B and luminance (0 without samples).
    pub mean: [f64; 4],
    /// Unbiased sample variance of R, G, B and luminance (0 with fewer than two samples).
    pub variance: [f64; 4],
}

/// A texel's combined estimate.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeEstimate {
    /// 1 if the texel has an estimate; 0 if no batch had a finite sample (the other fields
    /// are then 0 but `rejected`).
    pub valid: u32,
    /// Reserved (0).
    pub reserved: u32,
    /// Finite samples over all batches.
    pub samples: u64,
    /// Non-finite samples rejected over all batches.
    pub rejected: u64,
    /// Combined RGB.
    pub rgb: [f64; 3],
    /// Combined luminance.
    pub luminance: f64,
}

impl GuidebakeEstimate {
    fn from_kernel(e: &TexelEstimate) -> Self {
        match e {
            TexelEstimate::NoSamples { rejected } => Self {
                rejected: *rejected,
                ..Self::default()
            },
            TexelEstimate::Value(v) => Self {
                valid: 1,
                reserved: 0,
                samples: v.samples,
                rejected: v.rejected,
                rgb: v.rgb,
                luminance: v.luminance,
            },
        }
    }

    fn to_kernel(self) -> TexelEstimate {
        if self.valid == 0 {
            return TexelEstimate::NoSamples {
                rejected: self.rejected,
            };
        }
        TexelEstimate::Value(Estimate {
            rgb: self.rgb,
            luminance: self.luminance,
            samples: self.samples,
            rejected: self.rejected,
        })
    }
}

fn welford_mut(w: &mut GuidebakeWelford) -> &mut Welford {
    bytemuck::cast_mut(w)
}

fn welfords(w: &[GuidebakeWelford]) -> &[Welford] {
    bytemuck::cast_slice(w)
}

/// Rec. 709 luminance 0.2126 R + 0.7152 G + 0.0722 B (the weights of every combination).
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_luminance(r: f64, g: f64, b: f64) -> f64 {
    estimator::luminance([r, g, b])
}

/// Empties a batch.
///
/// # Safety
/// `w` points to a writable `GuidebakeWelford`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_welford_init(w: *mut GuidebakeWelford) -> GuidebakeStatus {
    guard("guidebake_welford_init", || {
        check_one(w, "w")?;
        // SAFETY: checked.
        unsafe { w.write(bytemuck::cast(Welford::new())) };
        Ok(())
    })
}

/// Adds one sample `rgb[3]`; a sample with a NaN or infinite channel is counted as rejected.
///
/// # Safety
/// `w` points to a writable batch; `rgb` to 3 readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_welford_push(
    w: *mut GuidebakeWelford,
    rgb: *const f32,
) -> GuidebakeStatus {
    guard("guidebake_welford_push", || {
        // SAFETY: checked before reading.
        let rgb = unsafe { read_array::<f32, 3>(rgb, "rgb") }?;
        check_one(w, "w")?;
        // SAFETY: checked; exclusive use is the caller's contract.
        welford_mut(unsafe { &mut *w }).push(rgb);
        Ok(())
    })
}

/// Adds `count` samples, `rgb[3·i .. 3·i+3]` for sample i, in order.
///
/// # Safety
/// `w` points to a writable batch; `rgb` to `3·count` readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_welford_push_n(
    w: *mut GuidebakeWelford,
    rgb: *const f32,
    count: usize,
) -> GuidebakeStatus {
    guard("guidebake_welford_push_n", || {
        let Some(floats) = count.checked_mul(3) else {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("`count` = {count} samples is larger than any buffer"),
            ));
        };
        check_one(w, "w")?;
        crate::disjoint(rgb, floats, w, 1, "`rgb` and `w`")?;
        // SAFETY: checked by `slice`; readable is the caller's contract.
        let rgb = unsafe { slice(rgb, floats, "rgb") }?;
        // SAFETY: checked; exclusive use is the caller's contract.
        let w = welford_mut(unsafe { &mut *w });
        for s in rgb.chunks_exact(3) {
            w.push([s[0], s[1], s[2]]);
        }
        Ok(())
    })
}

/// Adds batch `other`'s samples to `w` (Chan et al.'s pairwise update). `other` may be `w`.
///
/// # Safety
/// `w` points to a writable batch, `other` to a readable one.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_welford_merge(
    w: *mut GuidebakeWelford,
    other: *const GuidebakeWelford,
) -> GuidebakeStatus {
    guard("guidebake_welford_merge", || {
        check_one(other, "other")?;
        check_one(w, "w")?;
        // SAFETY: checked; read by value before `w` is borrowed, so they may alias.
        let other: Welford = bytemuck::cast(unsafe { other.read() });
        // SAFETY: checked.
        welford_mut(unsafe { &mut *w }).merge(&other);
        Ok(())
    })
}

/// A batch's count, mean and variance, to `out`.
///
/// # Safety
/// `w` points to a readable batch, `out` to a writable `GuidebakeWelfordStats`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_welford_stats(
    w: *const GuidebakeWelford,
    out: *mut GuidebakeWelfordStats,
) -> GuidebakeStatus {
    guard("guidebake_welford_stats", || {
        check_one(w, "w")?;
        check_one(out, "out")?;
        // SAFETY: checked.
        let b: Welford = bytemuck::cast(unsafe { w.read() });
        let mean = match (b.mean_rgb(), b.mean_luminance()) {
            (Some(rgb), Some(l)) => [rgb[0], rgb[1], rgb[2], l],
            _ => [0.0; 4],
        };
        let stats = GuidebakeWelfordStats {
            count: b.count(),
            rejected: b.rejected(),
            mean,
            variance: b.variance().unwrap_or([0.0; 4]),
        };
        // SAFETY: checked.
        unsafe { out.write(stats) };
        Ok(())
    })
}

/// Shared by the combinations: checks `(batches, count)` and `out`, runs `combine`.
///
/// # Safety
/// `batches` points to `count` readable batches, `out` to a writable estimate.
unsafe fn combine_with(
    batches: *const GuidebakeWelford,
    count: usize,
    out: *mut GuidebakeEstimate,
    combine: impl FnOnce(&[Welford]) -> Result<TexelEstimate, Fail>,
) -> Result<(), Fail> {
    // SAFETY: checked by `slice`; readable is the caller's contract.
    let batches = unsafe { slice(batches, count, "batches") }?;
    check_one(out, "out")?;
    let e = combine(welfords(batches))?;
    // SAFETY: checked; the estimate was computed before the write, so `out` may alias.
    unsafe { out.write(GuidebakeEstimate::from_kernel(&e)) };
    Ok(())
}

/// The bake's default combination of a texel's `count` batches: Graybill–Deal with the
/// variance floor 0.25 (multiply its RGB by ρ in the final pass).
///
/// # Safety
/// `batches` points to `count` readable batches; `out` to a writable estimate.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_combine_default(
    batches: *const GuidebakeWelford,
    count: usize,
    out: *mut GuidebakeEstimate,
) -> GuidebakeStatus {
    guard("guidebake_combine_default", || {
        // SAFETY: forwarded contract.
        unsafe {
            combine_with(batches, count, out, |b| {
                Ok(GraybillDeal::default().combine(b))
            })
        }
    })
}

/// Graybill–Deal (paper eq. 3): weights n_k / max(σ̂²_k, (c·μ̄)²) with `rel_std_floor` = c,
/// finite and > 0.
///
/// # Safety
/// As [`guidebake_combine_default`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_combine_graybill_deal(
    batches: *const GuidebakeWelford,
    count: usize,
    rel_std_floor: f64,
    out: *mut GuidebakeEstimate,
) -> GuidebakeStatus {
    guard("guidebake_combine_graybill_deal", || {
        if !(rel_std_floor.is_finite() && rel_std_floor > 0.0) {
            return Err(fail(
                GuidebakeStatus::InvalidArgument,
                format_args!(
                    "`rel_std_floor` is {rel_std_floor}; it must be finite and > 0 (default \
                     {DEFAULT_REL_STD_FLOOR})"
                ),
            ));
        }
        let gd = GraybillDeal { rel_std_floor };
        // SAFETY: forwarded contract.
        unsafe { combine_with(batches, count, out, |b| Ok(gd.combine(b))) }
    })
}

/// The plain sample-count weighted average of the batches (unbiased).
///
/// # Safety
/// As [`guidebake_combine_default`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_combine_average(
    batches: *const GuidebakeWelford,
    count: usize,
    out: *mut GuidebakeEstimate,
) -> GuidebakeStatus {
    guard("guidebake_combine_average", || {
        // SAFETY: forwarded contract.
        unsafe { combine_with(batches, count, out, |b| Ok(estimator::plain_average(b))) }
    })
}

/// Σ w_k μ_k / Σ w_k with `weights[k]` for batch k (missing, negative or non-finite weights
/// count as 0; all zero gives the plain average).
///
/// # Safety
/// As [`guidebake_combine_default`], and `weights` points to `weight_count` readable doubles.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_combine_weighted(
    batches: *const GuidebakeWelford,
    count: usize,
    weights: *const f64,
    weight_count: usize,
    out: *mut GuidebakeEstimate,
) -> GuidebakeStatus {
    guard("guidebake_combine_weighted", || {
        // SAFETY: checked by `slice`.
        let weights = unsafe { slice(weights, weight_count, "weights") }?;
        // SAFETY: forwarded contract.
        unsafe {
            combine_with(batches, count, out, |b| {
                Ok(estimator::combine_weighted(b, weights))
            })
        }
    })
}

fn rho_mut(r: &mut GuidebakeRho) -> &mut RhoAccumulator {
    bytemuck::cast_mut(r)
}

/// Empties a ρ accumulator.
///
/// # Safety
/// `rho` points to a writable `GuidebakeRho`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_rho_init(rho: *mut GuidebakeRho) -> GuidebakeStatus {
    guard("guidebake_rho_init", || {
        check_one(rho, "rho")?;
        // SAFETY: checked.
        unsafe { rho.write(bytemuck::cast(RhoAccumulator::new())) };
        Ok(())
    })
}

/// Adds one texel: its plain average and its Graybill–Deal estimate (a texel invalid in either
/// is counted as skipped).
///
/// # Safety
/// `rho` points to a writable accumulator; `average`, `combined` to readable estimates.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_rho_add_texel(
    rho: *mut GuidebakeRho,
    average: *const GuidebakeEstimate,
    combined: *const GuidebakeEstimate,
) -> GuidebakeStatus {
    guard("guidebake_rho_add_texel", || {
        check_one(average, "average")?;
        check_one(combined, "combined")?;
        check_one(rho, "rho")?;
        // SAFETY: checked; read by value first.
        let (a, c) = unsafe { (average.read(), combined.read()) };
        // SAFETY: checked.
        rho_mut(unsafe { &mut *rho }).add_texel(&a.to_kernel(), &c.to_kernel());
        Ok(())
    })
}

/// Adds another accumulator (another thread's or shard's); any order gives the same bits.
///
/// # Safety
/// `rho` points to a writable accumulator, `other` to a readable one (it may be `rho`).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_rho_merge(
    rho: *mut GuidebakeRho,
    other: *const GuidebakeRho,
) -> GuidebakeStatus {
    guard("guidebake_rho_merge", || {
        check_one(other, "other")?;
        check_one(rho, "rho")?;
        // SAFETY: checked; read by value first.
        let other: RhoAccumulator = bytemuck::cast(unsafe { other.read() });
        // SAFETY: checked.
        rho_mut(unsafe { &mut *rho }).merge(&other);
        Ok(())
    })
}

/// ρ = L̂ / L̂_GD to `out` (1 when there is nothing to correct).
///
/// # Safety
/// `rho` points to a readable accumulator, `out` to a writable double.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_rho_value(
    rho: *const GuidebakeRho,
    out: *mut f64,
) -> GuidebakeStatus {
    guard("guidebake_rho_value", || {
        check_one(rho, "rho")?;
        check_one(out, "out")?;
        // SAFETY: checked.
        let r: RhoAccumulator = bytemuck::cast(unsafe { rho.read() });
        // SAFETY: checked.
        unsafe { out.write(r.rho()) };
        Ok(())
    })
}

/// The accumulator as 96 little-endian bytes (`out[96]`), to merge shards across machines.
///
/// # Safety
/// `rho` points to a readable accumulator, `out` to 96 writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_rho_to_bytes(
    rho: *const GuidebakeRho,
    out: *mut u8,
) -> GuidebakeStatus {
    guard("guidebake_rho_to_bytes", || {
        check_one(rho, "rho")?;
        check_one(out, "out")?;
        // SAFETY: checked.
        let r: RhoAccumulator = bytemuck::cast(unsafe { rho.read() });
        // SAFETY: checked; 96 writable bytes is the caller's contract.
        unsafe { crate::write_array(out, r.to_le_bytes()) };
        Ok(())
    })
}

/// The inverse of [`guidebake_rho_to_bytes`]: `bytes[96]` to `rho`.
///
/// # Safety
/// `bytes` points to 96 readable bytes, `rho` to a writable accumulator.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_rho_from_bytes(
    bytes: *const u8,
    rho: *mut GuidebakeRho,
) -> GuidebakeStatus {
    guard("guidebake_rho_from_bytes", || {
        // SAFETY: checked before reading.
        let b = unsafe { read_array::<u8, RHO_BYTES>(bytes, "bytes") }?;
        check_one(rho, "rho")?;
        // SAFETY: checked.
        unsafe { rho.write(bytemuck::cast(RhoAccumulator::from_le_bytes(&b))) };
        Ok(())
    })
}
