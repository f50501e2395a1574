//! `guide`: the learned directional quadtree (paper §2.2–2.3) and its hierarchical warp
//! (§2.4), behind an opaque handle over caller-owned node storage.
//!
//! **Storage.** The caller allocates the nodes as raw bytes: [`guidebake_guide_node_size`]
//! bytes per node, aligned to [`guidebake_guide_node_align`] (64 today: one cache line per
//! node). The layout inside is private and may change; only size and alignment are ABI, and
//! they are queried, not compiled in. A guide uses at most 65 535 nodes; after the tree it
//! writes the warp's start table into [`guidebake_guide_start_table_nodes`] further nodes when
//! they are free (same results without it, slower warps). 1024 nodes (64 KiB) is the bake's
//! size per cluster.
//!
//! **Handle.** [`guidebake_guide_build`] and [`guidebake_guide_uniform`] write a
//! [`GuidebakeGuide`]: a 64-byte value the caller keeps anywhere (stack, array per cluster)
//! that borrows the storage. Rebuilding into the same storage invalidates every handle made
//! from it before; the storage must outlive its handles.
//!
//! **Parameters** ([`GuidebakeGuideParams`]) are versioned by their `size` field, so fields can
//! be added at the end without breaking callers compiled against an older header.

use crate::{
    Fail, GuidebakeStatus, check_one, disjoint, fail, guard, load8, read_array, read_versioned,
    sampling::check_points8, slice, slice_mut, store8, write_array,
};
use guidebake_kernels::guide::{self, Guide, GuideNode, GuideParams, Record};
use guidebake_kernels::warp;
use wide::f32x8;

/// One learning record: a point of the primary sample square and its flux, the luminance
/// divided by the density on the square that drew the sample (`pdf` from the warp; 1 for
/// the cosine baseline).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeRecord {
    /// The sample's point in [0,1)².
    pub u: [f32; 2],
    /// `L / p_square(u)`; records with a negative or non-finite flux, or `u` outside [0,1)²,
    /// are counted and ignored.
    pub flux: f32,
}

const _: () = {
    assert!(size_of::<GuidebakeRecord>() == size_of::<Record>());
    assert!(align_of::<GuidebakeRecord>() == align_of::<Record>());
    assert!(core::mem::offset_of!(GuidebakeRecord, u) == core::mem::offset_of!(Record, u));
    assert!(core::mem::offset_of!(GuidebakeRecord, flux) == core::mem::offset_of!(Record, flux));
};

/// Parameters of [`guidebake_guide_build`] (versioned: get them from
/// [`guidebake_guide_params_default`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeGuideParams {
    /// `sizeof(GuidebakeGuideParams)` as the caller compiled it.
    pub size: u32,
    /// A node splits only if it holds at least this many records (default 4).
    pub min_records: u32,
    /// ... and at least this fraction of the total flux (default 0.01).
    pub min_flux_fraction: f32,
    /// Depth cap, root depth 0 (default 10, clamped to 16).
    pub max_depth: u32,
    /// Ambient floor: no leaf's density below this fraction of the mean (default 0.1).
    pub ambient: f32,
    /// Smoothing strength α in 0..=1 of §2.3 (default 0.25; 0 disables smoothing).
    pub alpha: f32,
    /// Share `c` in 0..=1 of the uniform density in the defensive mixture the guide samples,
    /// `c + (1 − c)·guide` (default 0; the bake's `--mix 25` is 0.25): one warp draws from
    /// the mixture and its pdf is the mixture's. Added after `alpha`: callers compiled
    /// without it get 0.
    pub uniform: f32,
    /// The guide's target: 0 (default) learns a density ∝ the records' flux `L/q`, the
    /// paper's; 1 learns a density ∝ `√E[L²]` over the records (variance-aware guiding, Rath
    /// et al. 2020: least summed variance over the texels that share the guide), and each
    /// record's `flux` must then carry `L²/q` (the bake's default, `--guide-target
    /// second-moment`). Other values are refused. Added after `uniform`: callers compiled
    /// without it get 0.
    pub second_moment: u32,
}

impl GuidebakeGuideParams {
    fn kernel_defaults() -> Self {
        let d = GuideParams::default();
        Self {
            size: size_of::<Self>() as u32,
            min_records: d.min_records,
            min_flux_fraction: d.min_flux_fraction,
            max_depth: d.max_depth,
            ambient: d.ambient,
            alpha: d.alpha,
            uniform: d.uniform,
            second_moment: u32::from(d.second_moment),
        }
    }

    // Fields the kernels' `GuideParams` gains later keep their defaults.
    #[allow(clippy::needless_update)]
    fn to_kernel(self) -> Result<GuideParams, Fail> {
        if self.second_moment > 1 {
            return Err(fail(
                GuidebakeStatus::InvalidArgument,
                format_args!(
                    "`params->second_moment` is {}: 0 (the flux) or 1 (the second moment)",
                    self.second_moment
                ),
            ));
        }
        Ok(GuideParams {
            min_records: self.min_records,
            min_flux_fraction: self.min_flux_fraction,
            max_depth: self.max_depth,
            ambient: self.ambient,
            alpha: self.alpha,
            uniform: self.uniform,
            second_moment: self.second_moment == 1,
            ..GuideParams::default()
        })
    }
}

/// What [`guidebake_guide_build`] did (an optional output; set `size` before the call).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeGuideStats {
    /// `sizeof(GuidebakeGuideStats)` as the caller compiled it; the library writes only the
    /// fields this covers.
    pub size: u32,
    /// Records used for learning.
    pub accepted: u32,
    /// Records dropped for a negative or non-finite flux.
    pub rejected_flux: u32,
    /// Records dropped for a point outside [0,1)².
    pub rejected_point: u32,
    /// Nodes of the tree.
    pub nodes: u32,
    /// Its leaves.
    pub leaves: u32,
    /// Deepest leaf.
    pub depth: u32,
    /// Splits the storage could not hold.
    pub capacity_refusals: u32,
    /// Splits stopped by the depth cap.
    pub depth_refusals: u32,
    /// 1 if the warp's start table fitted after the tree.
    pub has_start_table: u32,
    /// Accepted flux, summed.
    pub total_flux: f64,
}

/// A built guide: an opaque, caller-owned 64-byte value borrowing the node storage it was
/// built in. Copy it freely (every copy borrows the same storage); no destructor.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeGuide {
    /// Private; zero-initialise if you must initialise it.
    pub opaque: [u64; 8],
}

/// What a [`GuidebakeGuide`] holds.
#[repr(C)]
struct GuideSlot {
    magic: u64,
    guide: Guide<'static>,
}

const GUIDE_MAGIC: u64 = u64::from_le_bytes(*b"gbguide1");

const _: () = {
    assert!(size_of::<GuideSlot>() <= size_of::<GuidebakeGuide>());
    assert!(align_of::<GuideSlot>() <= align_of::<GuidebakeGuide>());
};

/// Bytes of one guide node in caller storage.
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_guide_node_size() -> usize {
    size_of::<GuideNode>()
}

/// Alignment, in bytes, the guide storage must have.
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_guide_node_align() -> usize {
    align_of::<GuideNode>()
}

/// Nodes the warp's start table takes after the tree (see the module docs).
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_guide_start_table_nodes() -> usize {
    guide::START_TABLE_NODES
}

/// The documented defaults, with `size` set.
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_guide_params_default() -> GuidebakeGuideParams {
    GuidebakeGuideParams::kernel_defaults()
}

/// Views caller storage as nodes: 64-aligned, at least one node; bytes past the last whole
/// node are not used.
///
/// # Safety
/// `storage` points to `storage_bytes` writable bytes, not otherwise referenced while the
/// guide made from it is used.
unsafe fn nodes<'a>(storage: *mut u8, storage_bytes: usize) -> Result<&'a mut [GuideNode], Fail> {
    let count = storage_bytes / size_of::<GuideNode>();
    if count == 0 {
        return Err(fail(
            GuidebakeStatus::Capacity,
            format_args!(
                "`storage_bytes` is {storage_bytes}: at least one node ({} bytes) is needed",
                size_of::<GuideNode>()
            ),
        ));
    }
    // SAFETY: the caller's contract; `slice_mut` checks null, alignment and size. Any bytes
    // are a valid `GuideNode` (it is Pod) and the build overwrites what it uses.
    unsafe { slice_mut(storage.cast::<GuideNode>(), count, "storage") }
}

/// # Safety
/// `out` was checked with `check_one`.
unsafe fn store(out: *mut GuidebakeGuide, guide: Guide<'_>) {
    // SAFETY: the handle's contract extends the storage's borrow to the caller's use of the
    // handle (module docs): the storage outlives the handle and is not modified meanwhile.
    let guide: Guide<'static> = unsafe { core::mem::transmute::<Guide<'_>, Guide<'static>>(guide) };
    let mut handle = GuidebakeGuide { opaque: [0; 8] };
    // SAFETY: `GuideSlot` fits in and is no more aligned than `GuidebakeGuide` (asserted).
    unsafe {
        (&raw mut handle).cast::<GuideSlot>().write(GuideSlot {
            magic: GUIDE_MAGIC,
            guide,
        });
        out.write(handle);
    }
}

/// The guide a handle holds.
///
/// # Safety
/// `handle` is null or points to a readable `GuidebakeGuide`; if it carries the magic, it was
/// written by `store` and its storage is still valid (the handle's contract).
#[inline(always)]
unsafe fn load<'a>(handle: *const GuidebakeGuide) -> Result<&'a Guide<'static>, Fail> {
    check_one(handle, "guide")?;
    // SAFETY: non-null and aligned (checked); layout as asserted above.
    let slot = unsafe { &*handle.cast::<GuideSlot>() };
    if slot.magic != GUIDE_MAGIC {
        return Err(bad_handle());
    }
    Ok(&slot.guide)
}

#[cold]
fn bad_handle() -> Fail {
    fail(
        GuidebakeStatus::InvalidHandle,
        format_args!("`guide` was not made by guidebake_guide_build or guidebake_guide_uniform"),
    )
}

/// Writes the uniform guide (the cosine baseline: one leaf, density 1) into `storage` and its
/// handle into `out`.
///
/// # Safety
/// `storage` points to `storage_bytes` writable bytes; `out` to a writable
/// `GuidebakeGuide`. See the module docs for the storage's lifetime.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_uniform(
    storage: *mut core::ffi::c_void,
    storage_bytes: usize,
    out: *mut GuidebakeGuide,
) -> GuidebakeStatus {
    guard("guidebake_guide_uniform", || {
        check_one(out, "out")?;
        disjoint(
            storage.cast::<u8>(),
            storage_bytes,
            out,
            1,
            "`storage` and `out`",
        )?;
        // SAFETY: the caller's contract (module docs).
        let nodes = unsafe { nodes(storage.cast(), storage_bytes) }?;
        // SAFETY: `out` checked.
        unsafe { store(out, Guide::uniform(nodes)) };
        Ok(())
    })
}

/// Builds a guide from `records` (reordered in place: accepted records first) into
/// `storage` and writes its handle to `out`. `params` may be null (defaults); `stats` may be
/// null. Fewer nodes than the rule asks for is not an error: the guide is the best coarser
/// tree that fits (`stats->capacity_refusals` counts the refused splits).
///
/// # Safety
/// `records` points to `record_count` writable records; `storage` to `storage_bytes`
/// writable bytes; `params`, `stats` are null or valid; `out` points to a writable handle.
/// None of the buffers overlap (checked).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_build(
    records: *mut GuidebakeRecord,
    record_count: usize,
    params: *const GuidebakeGuideParams,
    storage: *mut core::ffi::c_void,
    storage_bytes: usize,
    out: *mut GuidebakeGuide,
    stats: *mut GuidebakeGuideStats,
) -> GuidebakeStatus {
    guard("guidebake_guide_build", || {
        // SAFETY: the caller's contract for `params`.
        let p =
            unsafe { read_versioned(params, GuidebakeGuideParams::kernel_defaults(), "params") }?
                .to_kernel()?;
        check_one(out, "out")?;
        let storage = storage.cast::<u8>();
        disjoint(
            records,
            record_count,
            storage,
            storage_bytes,
            "`records` and `storage`",
        )?;
        disjoint(storage, storage_bytes, out, 1, "`storage` and `out`")?;
        disjoint(records, record_count, out, 1, "`records` and `out`")?;
        let stats_size = if stats.is_null() {
            0
        } else {
            check_one(stats, "stats")?;
            disjoint(storage, storage_bytes, stats, 1, "`storage` and `stats`")?;
            disjoint(records, record_count, stats, 1, "`records` and `stats`")?;
            // SAFETY: checked; readable is the caller's contract.
            let size = unsafe { stats.cast::<u32>().read() } as usize;
            if !(4..=size_of::<GuidebakeGuideStats>()).contains(&size) {
                return Err(fail(
                    GuidebakeStatus::InvalidArgument,
                    format_args!("`stats->size` is {size}: set it to sizeof(GuidebakeGuideStats)"),
                ));
            }
            size
        };
        // SAFETY: checked by `slice_mut`; the layouts are asserted equal above.
        let records = unsafe { slice_mut(records.cast::<Record>(), record_count, "records") }?;
        // SAFETY: the caller's contract (module docs).
        let nodes = unsafe { nodes(storage, storage_bytes) }?;
        let (g, s) = guide::build(records, &p, nodes);
        if stats_size > 0 {
            let full = GuidebakeGuideStats {
                size: stats_size as u32,
                accepted: s.accepted,
                rejected_flux: s.rejected_flux,
                rejected_point: s.rejected_point,
                nodes: s.nodes,
                leaves: s.leaves,
                depth: s.depth,
                capacity_refusals: s.capacity_refusals,
                depth_refusals: s.depth_refusals,
                has_start_table: u32::from(!g.start_table().is_empty()),
                total_flux: s.total_flux,
            };
            // SAFETY: `stats` points to at least `stats_size` writable bytes (its contract).
            unsafe {
                core::ptr::copy_nonoverlapping(
                    bytemuck::bytes_of(&full).as_ptr(),
                    stats.cast::<u8>(),
                    stats_size,
                );
            }
        }
        // SAFETY: `out` checked.
        unsafe { store(out, g) };
        Ok(())
    })
}

/// Warps eight points `(x[i], y[i])` ∈ [0,1)² through the guide: lane i of
/// `out_x/out_y` is the warped point, of `out_pdf` its density on the square. Equals eight
/// calls of [`guidebake_guide_sample`] bit for bit. Outputs may alias the inputs.
///
/// # Safety
/// `guide` points to a handle (see the module docs); `x`, `y` to 8 readable floats each;
/// `out_x`, `out_y`, `out_pdf` to 8 writable floats each.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_sample8(
    guide: *const GuidebakeGuide,
    x: *const f32,
    y: *const f32,
    out_x: *mut f32,
    out_y: *mut f32,
    out_pdf: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_guide_sample8", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let g = unsafe { load(guide) }?;
        check_one(x, "x")?;
        check_one(y, "y")?;
        check_one(out_x, "out_x")?;
        check_one(out_y, "out_y")?;
        check_one(out_pdf, "out_pdf")?;
        // SAFETY: checked; 8 readable floats each is the caller's contract.
        let (vx, vy) = unsafe { (load8(x), load8(y)) };
        check_points8(vx, vy)?;
        let w = warp::sample8(g, vx, vy);
        // SAFETY: checked; writable is the caller's contract. The inputs were read first.
        unsafe {
            store8(out_x, w.x);
            store8(out_y, w.y);
            store8(out_pdf, w.pdf);
        }
        Ok(())
    })
}

/// [`guidebake_guide_sample8`] for `packets` packets at once: packet p is lanes
/// `8·p .. 8·p + 8` of each array. The per-call checks are paid once, so a baker warping a
/// texel's whole sample set pays next to nothing for the ABI. Every point is checked before
/// anything is written. Each output may be its input (in place) or disjoint from every input.
///
/// # Safety
/// `guide` points to a handle; `x`, `y` to `8·packets` readable floats each; `out_x`,
/// `out_y`, `out_pdf` to `8·packets` writable floats each.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_sample_packets(
    guide: *const GuidebakeGuide,
    x: *const f32,
    y: *const f32,
    packets: usize,
    out_x: *mut f32,
    out_y: *mut f32,
    out_pdf: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_guide_sample_packets", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let g = unsafe { load(guide) }?;
        let Some(n) = packets.checked_mul(8) else {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("`packets` = {packets} is larger than any buffer"),
            ));
        };
        // Lengths, nulls and alignment of all five arrays (views are not kept: the outputs
        // may be the inputs).
        // SAFETY: only checked, not dereferenced here.
        unsafe {
            slice(x, n, "x")?;
            slice(y, n, "y")?;
            slice(out_x.cast_const(), n, "out_x")?;
            slice(out_y.cast_const(), n, "out_y")?;
            slice(out_pdf.cast_const(), n, "out_pdf")?;
        }
        for (out, name) in [(out_x, "out_x"), (out_y, "out_y"), (out_pdf, "out_pdf")] {
            for (input, input_name) in [(x, "x"), (y, "y")] {
                if out.cast_const() != input {
                    disjoint(input, n, out, n, "an input and an output")
                        .map_err(|_| overlap(input_name, name))?;
                }
            }
        }
        for p in 0..packets {
            // SAFETY: in bounds of the checked arrays.
            let (vx, vy) = unsafe { (load8(x.add(8 * p)), load8(y.add(8 * p))) };
            check_points8(vx, vy)?;
        }
        for p in 0..packets {
            // SAFETY: as above; a packet is read before it is written, so in place is fine.
            unsafe {
                let w = warp::sample8(g, load8(x.add(8 * p)), load8(y.add(8 * p)));
                store8(out_x.add(8 * p), w.x);
                store8(out_y.add(8 * p), w.y);
                store8(out_pdf.add(8 * p), w.pdf);
            }
        }
        Ok(())
    })
}

#[cold]
fn overlap(input: &str, output: &str) -> Fail {
    fail(
        GuidebakeStatus::Overlap,
        format_args!("`{input}` and `{output}` overlap without being the same array"),
    )
}

/// Warps one point `u[2]` ∈ [0,1)²: the warped point to `out[2]`, its density to `out_pdf`.
/// The scalar reference of [`guidebake_guide_sample8`].
///
/// # Safety
/// `guide` points to a handle; `u` to 2 readable floats; `out` to 2 writable floats;
/// `out_pdf` to a writable float.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_sample(
    guide: *const GuidebakeGuide,
    u: *const f32,
    out: *mut f32,
    out_pdf: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_guide_sample", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let g = unsafe { load(guide) }?;
        // SAFETY: as above.
        let u = unsafe { read_array::<f32, 2>(u, "u") }?;
        check_points8(f32x8::splat(u[0]), f32x8::splat(u[1]))?;
        check_one(out, "out")?;
        check_one(out_pdf, "out_pdf")?;
        let w = warp::sample(g, u);
        // SAFETY: checked.
        unsafe {
            write_array(out, w.u);
            out_pdf.write(w.pdf);
        }
        Ok(())
    })
}

/// The guide's density on the square at eight points `(x[i], y[i])` ∈ [0,1)², to
/// `out_pdf[8]`; equals the `pdf` the warp returns with each point it produces.
///
/// # Safety
/// `guide` points to a handle; `x`, `y` to 8 readable floats each; `out_pdf` to 8 writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_pdf8(
    guide: *const GuidebakeGuide,
    x: *const f32,
    y: *const f32,
    out_pdf: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_guide_pdf8", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let g = unsafe { load(guide) }?;
        check_one(x, "x")?;
        check_one(y, "y")?;
        check_one(out_pdf, "out_pdf")?;
        // SAFETY: checked; 8 readable floats each is the caller's contract.
        let (vx, vy) = unsafe { (load8(x), load8(y)) };
        check_points8(vx, vy)?;
        // SAFETY: checked.
        unsafe { store8(out_pdf, warp::pdf8(g, vx, vy)) };
        Ok(())
    })
}

/// The guide's density on the square at one point `w[2]` ∈ [0,1)², to `out_pdf`.
///
/// # Safety
/// `guide` points to a handle; `w` to 2 readable floats; `out_pdf` to a writable float.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_pdf(
    guide: *const GuidebakeGuide,
    w: *const f32,
    out_pdf: *mut f32,
) -> GuidebakeStatus {
    guard("guidebake_guide_pdf", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let g = unsafe { load(guide) }?;
        // SAFETY: as above.
        let w = unsafe { read_array::<f32, 2>(w, "w") }?;
        check_points8(f32x8::splat(w[0]), f32x8::splat(w[1]))?;
        check_one(out_pdf, "out_pdf")?;
        // SAFETY: checked.
        unsafe { out_pdf.write(warp::pdf(g, w)) };
        Ok(())
    })
}

/// Number of nodes the guide's tree uses (1 for the uniform guide), to `out`.
///
/// # Safety
/// `guide` points to a handle; `out` to a writable `size_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn guidebake_guide_node_count(
    guide: *const GuidebakeGuide,
    out: *mut usize,
) -> GuidebakeStatus {
    guard("guidebake_guide_node_count", || {
        // SAFETY: the caller's contract; every pointer is checked before use.
        let g = unsafe { load(guide) }?;
        check_one(out, "out")?;
        // SAFETY: checked.
        unsafe { out.write(g.nodes().len()) };
        Ok(())
    })
}
