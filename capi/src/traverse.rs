//! `traverse`: 8-wide packet traversal over a caller-owned BVH in the kernels' node layout
//! (paper §2.4; kernels `traverse`, `packet`).
//!
//! **Layout.** A [`GuidebakeBvhNode`] is one 64-byte, 64-aligned cache line holding the boxes
//! of its two children: child `c` is an inner node when `meta[c] == 0` (index `child[c]`,
//! always greater than the parent's), else a leaf of `meta[c] & ~GUIDEBAKE_BVH_LEAF`
//! triangles starting at `child[c]` in the triangle array. Node 0 is the root; an empty slot
//! is a leaf of zero triangles. A [`GuidebakeTri`] holds its three vertices and the
//! primitive id that hits report. This layout is ABI: it is the kernels' own, checked field
//! by field at compile time.
//!
//! **Building.** Bakers with their own builder fill nodes and triangles directly; others call
//! [`guidebake_bvh_build`] (median split, no allocation, buffers sized by
//! [`guidebake_bvh_build_sizes`]). Either way [`guidebake_bvh_view`] validates the layout once
//! (child indices, leaf ranges, depth ≤ 128) and writes a [`GuidebakeBvh`] handle that
//! borrows both arrays: they must outlive it and stay unchanged.
//!
//! **Tracing.** [`guidebake_intersect8`] finds the closest hits of a [`GuidebakeRay8`]
//! (structure of arrays, no alignment required); lanes that miss or are not traced (inactive
//! `tmin > tmax`, non-finite, zero direction, `tmin < 0`) keep their [`GuidebakeHit8`] lane.
//! Results are exact: every tree over the same triangles gives the same hits bit for bit
//! (the smallest primitive id wins ties).

use crate::{
    Fail, GuidebakeStatus, bvh_build, check_one, disjoint, fail, guard, load8, slice, slice_mut,
    store8,
};
use core::mem::offset_of;
use glam::Vec3;
use guidebake_kernels::packet::{Hit, Hit8, NO_HIT, Ray, Ray8};
use guidebake_kernels::traverse::{self, BinaryNode, BvhRef, LEAF, LayoutError, Tri};
use wide::u32x8;

/// `meta` bit of a leaf child; the low bits count its triangles.
pub const GUIDEBAKE_BVH_LEAF: u32 = 0x8000_0000;

/// Primitive id of a lane that hit nothing.
pub const GUIDEBAKE_NO_HIT: u32 = 0xffff_ffff;

const _: () = assert!(GUIDEBAKE_BVH_LEAF == LEAF && GUIDEBAKE_NO_HIT == NO_HIT);

/// A BVH node: the boxes of its two children (the kernels' layout, 64 bytes, 64-aligned).
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeBvhNode {
    /// Box minima, `lo[axis][child]`.
    pub lo: [[f32; 2]; 3],
    /// Box maxima, `hi[axis][child]`.
    pub hi: [[f32; 2]; 3],
    /// Node index (inner child) or first triangle (leaf child).
    pub child: [u32; 2],
    /// `0` for an inner child, `GUIDEBAKE_BVH_LEAF | count` for a leaf.
    pub meta: [u32; 2],
}

/// A triangle: vertices `v[vertex][axis]` and the primitive id hits report (48 bytes,
/// 16-aligned).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeTri {
    /// Vertices.
    pub v: [[f32; 3]; 3],
    /// Primitive id.
    pub prim: u32,
    /// Zero.
    pub pad: [u32; 2],
}

const _: () = {
    assert!(size_of::<GuidebakeBvhNode>() == size_of::<BinaryNode>());
    assert!(align_of::<GuidebakeBvhNode>() == align_of::<BinaryNode>());
    assert!(offset_of!(GuidebakeBvhNode, lo) == offset_of!(BinaryNode, lo));
    assert!(offset_of!(GuidebakeBvhNode, hi) == offset_of!(BinaryNode, hi));
    assert!(offset_of!(GuidebakeBvhNode, child) == offset_of!(BinaryNode, child));
    assert!(offset_of!(GuidebakeBvhNode, meta) == offset_of!(BinaryNode, meta));
    assert!(size_of::<GuidebakeTri>() == size_of::<Tri>());
    assert!(align_of::<GuidebakeTri>() == align_of::<Tri>());
    assert!(offset_of!(GuidebakeTri, v) == offset_of!(Tri, v));
    assert!(offset_of!(GuidebakeTri, prim) == offset_of!(Tri, prim));
    assert!(offset_of!(GuidebakeTri, pad) == offset_of!(Tri, pad));
};

/// Eight rays, structure of arrays: lane i is `org[·][i] + t · dir[·][i]`, t ∈
/// `[tmin[i], tmax[i]]`. No alignment beyond `float`'s is required.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeRay8 {
    /// Origins: x, y, z rows of eight lanes.
    pub org: [[f32; 8]; 3],
    /// Directions (any length): x, y, z rows.
    pub dir: [[f32; 8]; 3],
    /// Smallest accepted distances (inclusive; a lane with `tmin > tmax` is inactive).
    pub tmin: [f32; 8],
    /// Largest accepted distances (inclusive; `INFINITY` for unbounded rays).
    pub tmax: [f32; 8],
}

/// Eight hits, structure of arrays.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeHit8 {
    /// Distances.
    pub t: [f32; 8],
    /// Barycentric weights of the second vertices.
    pub u: [f32; 8],
    /// Barycentric weights of the third vertices.
    pub v: [f32; 8],
    /// Primitive ids; `GUIDEBAKE_NO_HIT` where nothing was hit.
    pub prim: [u32; 8],
}

/// One ray.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeRay {
    /// Origin.
    pub org: [f32; 3],
    /// Direction.
    pub dir: [f32; 3],
    /// Smallest accepted distance.
    pub tmin: f32,
    /// Largest accepted distance.
    pub tmax: f32,
}

/// One hit.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeHit {
    /// Distance.
    pub t: f32,
    /// Barycentric weight of the second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
    /// Primitive id.
    pub prim: u32,
}

/// A validated BVH: an opaque, caller-owned 64-byte value borrowing the node and triangle
/// arrays it was made from. Copy it freely; no destructor.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeBvh {
    /// Private; zero-initialise if you must initialise it.
    pub opaque: [u64; 8],
}

#[repr(C)]
struct BvhSlot {
    magic: u64,
    bvh: BvhRef<'static>,
}

const BVH_MAGIC: u64 = u64::from_le_bytes(*b"gbbvh001");

const _: () = {
    assert!(size_of::<BvhSlot>() <= size_of::<GuidebakeBvh>());
    assert!(align_of::<BvhSlot>() <= align_of::<GuidebakeBvh>());
};

/// Alignment, in bytes, of node arrays (64).
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_bvh_node_align() -> usize {
    align_of::<BinaryNode>()
}

/// Array lengths [`guidebake_bvh_build`] needs for `tri_count` triangles: nodes to
/// `out_nodes` (`max(1, tri_count − 1)`), triangles to `out_tris` (`tri_count`).
///
/// # Safety
/// `out_nodes`, `out_tris` point to writable `size_t`s.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_bvh_build_sizes(
    tri_count: usize,
    out_nodes: *mut usize,
    out_tris: *mut usize,
) -> GuidebakeStatus {
    guard("guidebake_bvh_build_sizes", || {
        check_one(out_nodes, "out_nodes")?;
        check_one(out_tris, "out_tris")?;
        // SAFETY: checked.
        unsafe {
            out_nodes.write(bvh_build::nodes_needed(tri_count));
            out_tris.write(tri_count);
        }
        Ok(())
    })
}

/// Builds a BVH over `tri_count` triangles, `vertices[9·i .. 9·i+9]` = three xyz vertices of
/// triangle i (primitive id i; finite). Writes the nodes, root first, to `nodes` and the
/// triangles in leaf order to `tris` (capacities from [`guidebake_bvh_build_sizes`]), and the
/// number of nodes used to `out_node_count`. Then make a handle with [`guidebake_bvh_view`].
///
/// # Safety
/// `vertices` points to `9·tri_count` readable floats; `nodes` to `node_capacity` writable
/// nodes (64-aligned); `tris` to `tri_capacity` writable triangles; `out_node_count` to a
/// writable `size_t`. No overlap (checked).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_bvh_build(
    vertices: *const f32,
    tri_count: usize,
    nodes: *mut GuidebakeBvhNode,
    node_capacity: usize,
    tris: *mut GuidebakeTri,
    tri_capacity: usize,
    out_node_count: *mut usize,
) -> GuidebakeStatus {
    guard("guidebake_bvh_build", || {
        let Some(floats) = tri_count.checked_mul(9) else {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("`tri_count` = {tri_count} is larger than any buffer"),
            ));
        };
        if tri_count >= u32::MAX as usize {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("{tri_count} triangles: primitive ids are 32-bit"),
            ));
        }
        let needed = bvh_build::nodes_needed(tri_count);
        if node_capacity < needed || tri_capacity < tri_count {
            return Err(fail(
                GuidebakeStatus::Capacity,
                format_args!(
                    "{tri_count} triangles need {needed} nodes and {tri_count} triangles; \
                     capacities are {node_capacity} and {tri_capacity}"
                ),
            ));
        }
        check_one(out_node_count, "out_node_count")?;
        disjoint(
            vertices,
            floats,
            nodes,
            node_capacity,
            "`vertices` and `nodes`",
        )?;
        disjoint(
            vertices,
            floats,
            tris,
            tri_capacity,
            "`vertices` and `tris`",
        )?;
        disjoint(
            nodes,
            node_capacity,
            tris,
            tri_capacity,
            "`nodes` and `tris`",
        )?;
        // SAFETY: each buffer is checked by `slice`/`slice_mut`, they are disjoint (checked),
        // validity is the caller's contract; the layouts are asserted equal above.
        let (verts, nodes, tris) = unsafe {
            (
                slice(vertices, floats, "vertices")?,
                slice_mut(nodes.cast::<BinaryNode>(), node_capacity, "nodes")?,
                slice_mut(tris.cast::<Tri>(), tri_capacity, "tris")?,
            )
        };
        if let Some(i) = verts.iter().position(|c| !c.is_finite()) {
            return Err(fail(
                GuidebakeStatus::InvalidArgument,
                format_args!("triangle {} has a non-finite vertex coordinate", i / 9),
            ));
        }
        let tris = &mut tris[..tri_count];
        for (i, (t, v)) in tris.iter_mut().zip(verts.chunks_exact(9)).enumerate() {
            let p = |k: usize| Vec3::new(v[3 * k], v[3 * k + 1], v[3 * k + 2]);
            *t = Tri::new([p(0), p(1), p(2)], i as u32);
        }
        let used = bvh_build::build(tris, nodes);
        BvhRef::new(&nodes[..used], tris).map_err(layout_error)?;
        // SAFETY: checked.
        unsafe { out_node_count.write(used) };
        Ok(())
    })
}

#[cold]
fn layout_error(e: LayoutError) -> Fail {
    fail(
        GuidebakeStatus::InvalidArgument,
        format_args!("the node/triangle layout is invalid: {e:?}"),
    )
}

/// Validates a BVH layout (see the module docs) and writes its handle to `out`.
///
/// # Safety
/// `nodes` points to `node_count` readable nodes (64-aligned), `tris` to `tri_count`
/// readable triangles, both unchanged and alive while the handle is used; `out` to a
/// writable handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_bvh_view(
    nodes: *const GuidebakeBvhNode,
    node_count: usize,
    tris: *const GuidebakeTri,
    tri_count: usize,
    out: *mut GuidebakeBvh,
) -> GuidebakeStatus {
    guard("guidebake_bvh_view", || {
        check_one(out, "out")?;
        // SAFETY: checked by `slice`; the contract above; layouts asserted equal.
        let (nodes, tris): (&'static [BinaryNode], &'static [Tri]) = unsafe {
            (
                slice(nodes.cast::<BinaryNode>(), node_count, "nodes")?,
                slice(tris.cast::<Tri>(), tri_count, "tris")?,
            )
        };
        disjoint(nodes.as_ptr(), nodes.len(), out, 1, "`nodes` and `out`")?;
        disjoint(tris.as_ptr(), tris.len(), out, 1, "`tris` and `out`")?;
        let bvh = BvhRef::new(nodes, tris).map_err(layout_error)?;
        let mut handle = GuidebakeBvh { opaque: [0; 8] };
        // SAFETY: `BvhSlot` fits in and is no more aligned than the handle (asserted); `out`
        // checked.
        unsafe {
            (&raw mut handle).cast::<BvhSlot>().write(BvhSlot {
                magic: BVH_MAGIC,
                bvh,
            });
            out.write(handle);
        }
        Ok(())
    })
}

/// # Safety
/// `handle` is null or points to a readable handle made by `guidebake_bvh_view` whose arrays
/// are still valid.
#[inline(always)]
unsafe fn load<'a>(handle: *const GuidebakeBvh) -> Result<&'a BvhRef<'static>, Fail> {
    check_one(handle, "bvh")?;
    // SAFETY: non-null and aligned (checked); layout asserted.
    let slot = unsafe { &*handle.cast::<BvhSlot>() };
    if slot.magic != BVH_MAGIC {
        return Err(bad_handle());
    }
    Ok(&slot.bvh)
}

#[cold]
fn bad_handle() -> Fail {
    fail(
        GuidebakeStatus::InvalidHandle,
        format_args!("`bvh` was not made by guidebake_bvh_view"),
    )
}

/// The packet, loaded row by row straight into vector registers.
///
/// # Safety
/// `rays` was checked with `check_one`.
#[inline(always)]
unsafe fn ray8(rays: *const GuidebakeRay8) -> Ray8 {
    let row = |p: *const [f32; 8]| {
        // SAFETY: a row of the checked packet.
        unsafe { load8(p.cast()) }
    };
    // SAFETY: field projections of the checked pointer (no reference is formed).
    unsafe {
        Ray8 {
            org: [0, 1, 2].map(|a| row(&raw const (*rays).org[a])),
            dir: [0, 1, 2].map(|a| row(&raw const (*rays).dir[a])),
            tmin: row(&raw const (*rays).tmin),
            tmax: row(&raw const (*rays).tmax),
        }
    }
}

/// Closest hits of eight rays. Lanes that hit get their hit in `hits`; the others keep what
/// `hits` held (initialise it, e.g. `t = INFINITY`, `prim = GUIDEBAKE_NO_HIT`). The mask of
/// lanes that hit goes to `out_mask` (optional: may be null).
///
/// # Safety
/// `bvh` points to a handle; `rays` to a readable packet; `hits` to a readable and
/// writable one; `out_mask` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_intersect8(
    bvh: *const GuidebakeBvh,
    rays: *const GuidebakeRay8,
    hits: *mut GuidebakeHit8,
    out_mask: *mut u8,
) -> GuidebakeStatus {
    guard("guidebake_intersect8", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let bvh = unsafe { load(bvh) }?;
        check_one(rays, "rays")?;
        check_one(hits, "hits")?;
        if !out_mask.is_null() {
            check_one(out_mask, "out_mask")?;
        }
        // SAFETY: checked; rows loaded straight into registers (see `load8`).
        let (rays, mut h) = unsafe {
            let ht = &raw mut (*hits).t;
            let (hu, hv) = (&raw mut (*hits).u, &raw mut (*hits).v);
            let hp = &raw mut (*hits).prim;
            let h = Hit8 {
                t: load8(ht.cast()),
                u: load8(hu.cast()),
                v: load8(hv.cast()),
                prim: hp.cast::<u32x8>().read_unaligned(),
            };
            (ray8(rays), h)
        };
        let mask = traverse::intersect8(bvh, &rays, &mut h);
        // SAFETY: checked; the packet was read before, so `hits` may alias `rays`.
        unsafe {
            store8((&raw mut (*hits).t).cast(), h.t);
            store8((&raw mut (*hits).u).cast(), h.u);
            store8((&raw mut (*hits).v).cast(), h.v);
            (&raw mut (*hits).prim)
                .cast::<u32x8>()
                .write_unaligned(h.prim);
            if !out_mask.is_null() {
                out_mask.write(mask);
            }
        }
        Ok(())
    })
}

/// Which of eight rays are blocked on `[tmin, tmax]` (early exit): bit i of `out_mask` is
/// lane i. Lanes that are not traced are never blocked.
///
/// # Safety
/// `bvh` points to a handle; `rays` to a readable packet; `out_mask` to a writable byte.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_occluded8(
    bvh: *const GuidebakeBvh,
    rays: *const GuidebakeRay8,
    out_mask: *mut u8,
) -> GuidebakeStatus {
    guard("guidebake_occluded8", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let bvh = unsafe { load(bvh) }?;
        check_one(rays, "rays")?;
        check_one(out_mask, "out_mask")?;
        // SAFETY: checked.
        let rays = unsafe { ray8(rays) };
        let mask = traverse::occluded8(bvh, &rays);
        // SAFETY: checked.
        unsafe { out_mask.write(mask) };
        Ok(())
    })
}

/// Closest hit of one ray, the scalar reference: 1 to `out_hit` and the hit to `hit` when it
/// hits, else 0 to `out_hit` and `hit` untouched.
///
/// # Safety
/// `bvh` points to a handle; `ray` to a readable ray; `hit` to a writable hit; `out_hit` to a
/// writable `int32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_intersect1(
    bvh: *const GuidebakeBvh,
    ray: *const GuidebakeRay,
    hit: *mut GuidebakeHit,
    out_hit: *mut i32,
) -> GuidebakeStatus {
    guard("guidebake_intersect1", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let bvh = unsafe { load(bvh) }?;
        check_one(ray, "ray")?;
        check_one(hit, "hit")?;
        check_one(out_hit, "out_hit")?;
        // SAFETY: checked.
        let r = unsafe { ray.read() };
        let ray = Ray::new(
            Vec3::from_array(r.org),
            Vec3::from_array(r.dir),
            r.tmin,
            r.tmax,
        );
        let found: Option<Hit> = traverse::intersect1(bvh, &ray);
        // SAFETY: checked.
        unsafe {
            if let Some(h) = found {
                hit.write(GuidebakeHit {
                    t: h.t,
                    u: h.u,
                    v: h.v,
                    prim: h.prim,
                });
            }
            out_hit.write(i32::from(found.is_some()));
        }
        Ok(())
    })
}
