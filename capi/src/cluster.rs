//! `cluster`: texel clustering into caller buffers (paper §2.1; kernel `cluster`).
//!
//! Texels are split top-down on the longest axis of their bounds until a cluster holds at
//! most `max_texels` texels whose normals lie within `max_normal_angle_deg` of their mean;
//! each cluster then learns one guide. [`guidebake_build_clusters`] writes a permutation of
//! the texel indices and one [`GuidebakeClusterRange`] per cluster (a range of that
//! permutation). Deterministic, no allocation.

use crate::{GuidebakeStatus, check_one, disjoint, fail, guard, read_versioned, slice, slice_mut};
use guidebake_kernels::cluster::{self, ClusterError, ClusterParams, ClusterRange};

/// Parameters of [`guidebake_build_clusters`] (versioned: get them from
/// [`guidebake_cluster_params_default`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeClusterParams {
    /// `sizeof(GuidebakeClusterParams)` as the caller compiled it.
    pub size: u32,
    /// At most this many texels per cluster, ≥ 1 (default 64).
    pub max_texels: u32,
    /// Every normal within this angle of the cluster's mean normal, degrees in [0, 180]
    /// (default 60).
    pub max_normal_angle_deg: f32,
    /// 1: a cluster small enough that fails only the normal cone is split by its normals
    /// first (default); 0: purely spatial splits.
    pub normal_split: u32,
}

/// One cluster: the texels `permutation[start .. end]`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuidebakeClusterRange {
    /// First index into the permutation.
    pub start: u32,
    /// One past the last.
    pub end: u32,
}

const _: () = {
    assert!(size_of::<GuidebakeClusterRange>() == size_of::<ClusterRange>());
    assert!(align_of::<GuidebakeClusterRange>() == align_of::<ClusterRange>());
    assert!(
        core::mem::offset_of!(GuidebakeClusterRange, start)
            == core::mem::offset_of!(ClusterRange, start)
    );
    assert!(
        core::mem::offset_of!(GuidebakeClusterRange, end)
            == core::mem::offset_of!(ClusterRange, end)
    );
};

/// The paper's defaults (64 texels, 60°, normal splits on), with `size` set.
#[unsafe(no_mangle)]
pub extern "C" fn guidebake_cluster_params_default() -> GuidebakeClusterParams {
    let d = ClusterParams::default();
    GuidebakeClusterParams {
        size: size_of::<GuidebakeClusterParams>() as u32,
        max_texels: d.max_texels,
        max_normal_angle_deg: d.max_normal_angle_deg,
        normal_split: u32::from(d.normal_split),
    }
}

/// Clusters `texel_count` texels with positions `positions[3·i..]` and normals
/// `normals[3·i..]` (finite; normals non-zero, any length). Writes a permutation of
/// `0..texel_count` to `permutation` (`permutation_len == texel_count`) and the clusters, in
/// increasing `start`, to the front of `ranges`; their number to `out_count`. `params` may be
/// null (defaults). `ranges_len >= texel_count` always suffices; fewer may fail with
/// `GUIDEBAKE_STATUS_CAPACITY`.
///
/// # Safety
/// `positions`, `normals` point to `3·texel_count` readable floats; `permutation` to
/// `permutation_len` writable `uint32_t`; `ranges` to `ranges_len` writable ranges;
/// `out_count` to a writable `size_t`; `params` is null or valid.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)] // one pointer and one length per buffer, as C needs
pub unsafe extern "C" fn guidebake_build_clusters(
    positions: *const f32,
    normals: *const f32,
    texel_count: usize,
    params: *const GuidebakeClusterParams,
    permutation: *mut u32,
    permutation_len: usize,
    ranges: *mut GuidebakeClusterRange,
    ranges_len: usize,
    out_count: *mut usize,
) -> GuidebakeStatus {
    guard("guidebake_build_clusters", || {
        // SAFETY: the caller's contract for `params`.
        let p = unsafe { read_versioned(params, guidebake_cluster_params_default(), "params") }?;
        let Some(floats) = texel_count.checked_mul(3) else {
            return Err(fail(
                GuidebakeStatus::BadLength,
                format_args!("`texel_count` = {texel_count} is larger than any buffer"),
            ));
        };
        check_one(out_count, "out_count")?;
        for (input, name) in [(positions, "positions"), (normals, "normals")] {
            disjoint(
                input,
                floats,
                permutation,
                permutation_len,
                "an input and `permutation`",
            )
            .map_err(|e| rename(e, name, "permutation"))?;
            disjoint(input, floats, ranges, ranges_len, "an input and `ranges`")
                .map_err(|e| rename(e, name, "ranges"))?;
        }
        disjoint(
            permutation,
            permutation_len,
            ranges,
            ranges_len,
            "`permutation` and `ranges`",
        )?;
        // SAFETY: each buffer is checked by `slice`/`slice_mut`; the output buffers are
        // disjoint from the inputs and each other (checked); validity is the caller's contract.
        let (pos, nrm, perm, out) = unsafe {
            (
                slice(positions, floats, "positions")?,
                slice(normals, floats, "normals")?,
                slice_mut(permutation, permutation_len, "permutation")?,
                slice_mut(ranges.cast::<ClusterRange>(), ranges_len, "ranges")?,
            )
        };
        let kernel = ClusterParams {
            max_texels: p.max_texels,
            max_normal_angle_deg: p.max_normal_angle_deg,
            normal_split: p.normal_split != 0,
        };
        let count = cluster::build_clusters(
            bytemuck::cast_slice(pos),
            bytemuck::cast_slice(nrm),
            &kernel,
            perm,
            out,
        )
        .map_err(|e| {
            let status = match e {
                ClusterError::RangesFull { .. } => GuidebakeStatus::Capacity,
                ClusterError::PermutationLength { .. }
                | ClusterError::LengthMismatch { .. }
                | ClusterError::TooManyTexels(_) => GuidebakeStatus::BadLength,
                _ => GuidebakeStatus::InvalidArgument,
            };
            fail(status, format_args!("{e}"))
        })?;
        // SAFETY: checked.
        unsafe { out_count.write(count) };
        Ok(())
    })
}

/// Rewrites an overlap message with the buffers' names.
fn rename(e: crate::Fail, a: &str, b: &str) -> crate::Fail {
    fail(e.0, format_args!("`{a}` and `{b}` overlap"))
}
