//! # bvh: obvhs builds the tree, we flatten it into the kernels' layout
//!
//! The bake traces with [`guidebake_kernels::traverse`] (8-wide packets, Silvennoinen & Sloan
//! 2019 §2.4). Building a good tree is obvhs's job: PLOC (Meister & Bittner 2018) plus
//! reinsertion and leaf collapsing ([`obvhs::bvh2::builder::build_bvh2_from_tris`]). This module
//! picks the build parameters ([`Preset`]), then flattens obvhs's binary tree into
//! [`BinaryNode`]s (two child boxes per 64-byte node) over the triangles in leaf order ([`Tri`]s),
//! collapses it into [`WideNode`]s (eight child boxes per node, same leaves, the wide nodes
//! chosen by the least surface-area cost: [`collapse`]; [`Bvh::wide`]),
//! which every ray the bake traces walks, single or in packets (docs/traverse.md,
//! "Whole bakes"), and writes each wide leaf's
//! triangles as structure-of-arrays rows ([`leaf_rows`]), the wide tree's only copy of them.
//! The binary tree and its `Tri`s are the collapse's input; [`Bvh::build`] drops them
//! afterwards (the 1M-triangle city's resident tree: 53 MB, where it held 123 MB with them;
//! [`Bvh::bytes`]), and [`Bvh::build_with_binary`] keeps them ([`Bvh::binary`]) as the
//! comparator of the benches and tests.
//! obvhs builds on every core (its `parallel` feature: PLOC and reinsertion through rayon;
//! 10⁷ triangles with `VerySlowBuild` take 75 s on one thread and 37 s on two, docs/traverse.md).
//! The nodes and leaf rows are then moved to transparent huge pages (`bvh/huge.rs`),
//! as Embree allocates its BVH: a big world's node visits miss the TLB far less.
//!
//! **Bounded scratch** (`bvh/regions.rs`): a soup of more than 2¹⁷ triangles is cut at
//! centroid medians into regions of at most that many, each built (same preset), flattened
//! and collapsed on its own, then joined under a top level over the cuts and written in
//! place into the final arrays; the build's peak is the finished tree plus one region's
//! scratch (≤ 50 MB measured), 4 bytes per triangle and a node per region. Whole, obvhs's
//! scratch (PLOC's node and Morton buffers, its copy of the triangles: ~250 bytes per
//! triangle) and our binary tree beside the wide one grew with the world. Measured
//! 2026-11-28, 2-core AMD EPYC (shared, load average 7–10), `very_slow`, the build alone
//! (`cargo run --release -p guidebake --example bvh_build -- city7.toml very_slow [--whole]
//! [--tile 3] [--duel]`; peak RSS above the RSS before the build):
//!
//! | world | tree | build peak, whole → regions | build s, whole → regions | rays/s, regions ÷ whole |
//! |---|---:|---:|---:|---:|
//! | 10⁷-texel city, 312 448 triangles | 16 MB | +91 → +39–50 MB | 0.9–1.3 → 1.0–1.2 | 1.03 single, 1.05 packets |
//! | 3 × 3 of it, 2 812 032 triangles | 140 MB | +816 → +179 MB | 21.7 → 8.9–10.3 | 1.15 single, 1.16 packets |
//!
//! The unsharded bake of the 10⁷-texel city (`--spp 16 --iterations 2 --bounces 1
//! --transport path --threads 2`) peaks at 131 MB RSS (177 MB before), gathers at 1.02× the
//! rays/s, and writes the same bytes (docs/farm.md, "The BVH build's memory"). Smaller soups
//! are built whole, as before.
//!
//! Deviations: obvhs's own traversals ignore `tmin` in the node test; ours honour it. With the
//! spatial-split presets a triangle can sit in several leaves; it is then copied once per leaf
//! (same primitive id, so hits are unchanged).
//!
//! The input is a plain triangle soup: primitive id = index in the slice, so this module does
//! not depend on the scene loader.
//!
//! Ray origins leaving a surface should be offset with
//! [`guidebake_kernels::packet::offset_origin`] (Wächter & Binder, Ray Tracing Gems ch. 6).

use std::time::{Duration, Instant};

mod huge;
mod regions;
use huge::HugeSlice;
pub(crate) use regions::split_at_median;

use glam::{Vec3, Vec3A};
use guidebake_kernels::traverse::{
    BinaryNode, BvhRef, LEAF, LayoutError, Tri, WideNode, WideRef, collapse, leaf_rows,
};
use obvhs::{
    BvhBuildParams,
    bvh2::{Bvh2, builder::build_bvh2_from_tris},
    triangle::Triangle,
};

/// obvhs's build presets ([`BvhBuildParams`]), from fastest build to best tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Preset {
    /// `BvhBuildParams::fastest_build` (one triangle per leaf, no reinsertion).
    FastestBuild,
    /// `BvhBuildParams::very_fast_build`.
    VeryFastBuild,
    /// `BvhBuildParams::fast_build`.
    FastBuild,
    /// `BvhBuildParams::medium_build`.
    MediumBuild,
    /// `BvhBuildParams::slow_build` (spatial splits).
    SlowBuild,
    /// `BvhBuildParams::very_slow_build` (spatial splits, full reinsertion).
    VerySlowBuild,
}

impl Preset {
    /// Every preset, fastest build first.
    pub const ALL: [Preset; 6] = [
        Preset::FastestBuild,
        Preset::VeryFastBuild,
        Preset::FastBuild,
        Preset::MediumBuild,
        Preset::SlowBuild,
        Preset::VerySlowBuild,
    ];

    /// The bake's choice. Measured in docs/traverse.md ("Build presets and sizes",
    /// round-robin): on cities of 10⁵, 10⁶ and 10⁷ triangles `VerySlowBuild` traces 1.3×,
    /// 1.3–1.6× and 1.3–2.0× faster than `MediumBuild` for 5–7× its build time (0.14 s,
    /// 2.6 s and 128 s on one core), which pays back after at most ~0.7·10⁹ rays on 10⁷
    /// triangles and ~60·10⁶ on 10⁶ — less than one bake of such a world traces. On the Veach
    /// room every preset from `FastBuild` up traces alike and builds in milliseconds.
    pub const DEFAULT: Preset = Preset::VerySlowBuild;

    /// Rays per triangle from which [`Preset::DEFAULT`]'s better tree repays its longer
    /// build (the payback above: ~60 rays per triangle on 10⁶ triangles, ~70 on 10⁷).
    pub const PAYBACK_RAYS_PER_TRIANGLE: f64 = 70.0;

    /// The preset for a run that traces about `rays` rays through `triangles` triangles:
    /// [`Preset::DEFAULT`] when its tree repays its build, else `MediumBuild` — a farm's
    /// small shard of a huge world (10⁶ texels at 16 spp of a 3.1 M-triangle city traces
    /// ~3·10⁷ rays, 10 per triangle) would spend longer building than the better tree saves.
    pub fn for_rays(triangles: usize, rays: f64) -> Preset {
        if rays >= Self::PAYBACK_RAYS_PER_TRIANGLE * triangles as f64 {
            Self::DEFAULT
        } else {
            Preset::MediumBuild
        }
    }

    /// obvhs's parameters for this preset.
    pub fn params(self) -> BvhBuildParams {
        match self {
            Preset::FastestBuild => BvhBuildParams::fastest_build(),
            Preset::VeryFastBuild => BvhBuildParams::very_fast_build(),
            Preset::FastBuild => BvhBuildParams::fast_build(),
            Preset::MediumBuild => BvhBuildParams::medium_build(),
            Preset::SlowBuild => BvhBuildParams::slow_build(),
            Preset::VerySlowBuild => BvhBuildParams::very_slow_build(),
        }
    }

    /// Short name (bench ids, docs).
    pub fn name(self) -> &'static str {
        match self {
            Preset::FastestBuild => "fastest",
            Preset::VeryFastBuild => "very_fast",
            Preset::FastBuild => "fast",
            Preset::MediumBuild => "medium",
            Preset::SlowBuild => "slow",
            Preset::VerySlowBuild => "very_slow",
        }
    }
}

/// Why a BVH could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BvhError {
    /// A vertex has a NaN or infinite coordinate.
    #[error("triangle {triangle}: vertex {vertex} is not finite: {value:?}")]
    NonFinite {
        /// Index of the triangle in the soup.
        triangle: usize,
        /// Vertex 0, 1 or 2.
        vertex: usize,
        /// Its coordinates.
        value: [f32; 3],
    },
    /// More triangles than 32-bit primitive ids can name.
    #[error("{count} triangles: at most {} are supported", u32::MAX - 1)]
    TooMany {
        /// Triangles given.
        count: usize,
    },
    /// The flattened tree is not a valid kernel layout (deeper than the traversal stack).
    #[error("the flattened BVH is not a valid kernel layout: {0:?}")]
    Layout(LayoutError),
}

/// A BVH in the kernels' layout, owning its nodes and leaf-ordered triangles.
#[derive(Clone, Debug)]
pub struct Bvh {
    // On huge pages when big enough ([`huge`]).
    /// The binary tree and its triangles in leaf order, kept only by
    /// [`Bvh::build_with_binary`].
    binary: Option<(HugeSlice<BinaryNode>, HugeSlice<Tri>)>,
    wide: HugeSlice<WideNode>,
    /// The triangles as structure-of-arrays rows per wide leaf ([`leaf_rows`]): the wide
    /// tree's only copy of them.
    rows: HugeSlice<f32>,
    build_time: Duration,
    preset: Preset,
}

impl Bvh {
    /// Builds a BVH over `soup` (primitive id = index) with obvhs, flattens it and collapses
    /// it into the wide layout the bake walks; the binary tree is dropped.
    ///
    /// An empty soup gives a valid tree that every ray misses.
    ///
    /// # Errors
    /// [`BvhError::NonFinite`] for a NaN/∞ vertex, [`BvhError::TooMany`] past `u32::MAX − 1`
    /// triangles, [`BvhError::Layout`] if the tree is deeper than the kernels' stack.
    pub fn build(soup: &[[Vec3; 3]], preset: Preset) -> Result<Self, BvhError> {
        Self::build_keeping(soup, preset, false)
    }

    /// [`Bvh::build`] that also keeps the binary tree ([`Bvh::binary`]): the comparator of
    /// the benches and tests, and of embedders walking the binary layout.
    ///
    /// # Errors
    /// As [`Bvh::build`].
    pub fn build_with_binary(soup: &[[Vec3; 3]], preset: Preset) -> Result<Self, BvhError> {
        Self::build_keeping(soup, preset, true)
    }

    fn build_keeping(
        soup: &[[Vec3; 3]],
        preset: Preset,
        keep_binary: bool,
    ) -> Result<Self, BvhError> {
        Self::build_in_regions(soup, None, preset, regions::REGION_TRIANGLES, keep_binary)
    }

    /// [`Bvh::build`] over the triangles of `soup` that `ids` names (ascending; all of them
    /// for `None`), primitive id still the index in `soup`: the tree of a scene whose
    /// surfaces of some roles rays pass through (`scene::roles`).
    ///
    /// # Errors
    /// As [`Bvh::build`].
    pub fn build_over(
        soup: &[[Vec3; 3]],
        ids: Option<&[u32]>,
        preset: Preset,
    ) -> Result<Self, BvhError> {
        Self::build_in_regions(soup, ids, preset, regions::REGION_TRIANGLES, false)
    }

    /// [`Bvh::build`] with regions of at most `region` triangles ([`regions`]; the bake's
    /// size is `REGION_TRIANGLES`, 2¹⁷); `usize::MAX` builds the whole soup in one obvhs build,
    /// as before regions: the comparator of the benches and measurements.
    ///
    /// # Errors
    /// As [`Bvh::build`].
    pub fn build_in_regions_of(
        soup: &[[Vec3; 3]],
        preset: Preset,
        region: usize,
    ) -> Result<Self, BvhError> {
        Self::build_in_regions(soup, None, preset, region.max(16), false)
    }

    /// The build, cutting a soup of more than `region` triangles into regions of at most
    /// that many ([`regions`]); a smaller soup is built whole.
    fn build_in_regions(
        soup: &[[Vec3; 3]],
        ids: Option<&[u32]>,
        preset: Preset,
        region: usize,
        keep_binary: bool,
    ) -> Result<Self, BvhError> {
        check_soup(soup)?;
        let start = Instant::now();
        let count = ids.map_or(soup.len(), <[u32]>::len);
        let (wide, rows, binary) = if count > region {
            let built = regions::build(soup, ids, preset, region, keep_binary)?;
            (built.wide, built.rows, built.binary)
        } else {
            Self::build_whole(soup, ids, preset, keep_binary)?
        };
        WideRef::new(&wide, &rows).map_err(BvhError::Layout)?;
        if let Some((nodes, tris)) = &binary {
            BvhRef::new(nodes, tris).map_err(BvhError::Layout)?;
        }
        Ok(Self {
            binary,
            wide,
            rows,
            build_time: start.elapsed(),
            preset,
        })
    }

    /// One tree over the whole soup.
    #[allow(clippy::type_complexity)]
    fn build_whole(
        soup: &[[Vec3; 3]],
        ids: Option<&[u32]>,
        preset: Preset,
        keep_binary: bool,
    ) -> Result<
        (
            HugeSlice<WideNode>,
            HugeSlice<f32>,
            Option<(HugeSlice<BinaryNode>, HugeSlice<Tri>)>,
        ),
        BvhError,
    > {
        // Each array is dropped, or moved to huge pages, as soon as the next step allows: a
        // big world's build peaks at the sum of what is alive at once.
        let (nodes, tris) = obvhs_flattened(soup, ids, preset);
        let tree = BvhRef::new(&nodes, &tris).map_err(BvhError::Layout)?;
        let wide = HugeSlice::new(collapse(&tree));
        let rows = HugeSlice::new(leaf_rows(&wide, &tris));
        let binary = keep_binary.then(|| (HugeSlice::new(nodes), HugeSlice::new(tris)));
        Ok((wide, rows, binary))
    }

    /// The binary view for [`guidebake_kernels::traverse`]'s functions (two child boxes per
    /// node) when built by [`Bvh::build_with_binary`]. Cheap: the build validated the layout.
    pub fn binary(&self) -> Option<BvhRef<'_>> {
        // The build validated this exact layout and nothing mutates it since.
        let (nodes, tris) = self.binary.as_ref()?;
        Some(BvhRef::new_trusted(nodes, tris))
    }

    /// The wide view (eight child boxes per node, collapsed from the binary tree, same
    /// triangles). Same results as [`Bvh::binary`], bit for bit, wherever every hit lies inside
    /// its leaf's box (the kernels' `traverse` docs, "Hits outside their own box": rays that
    /// start within ulps of a triangle's plane). Cheap: `build` validated it.
    pub fn wide(&self) -> WideRef<'_> {
        WideRef::new_trusted(&self.wide, &self.rows)
    }

    /// Wide nodes, root first.
    pub fn wide_nodes(&self) -> &[WideNode] {
        &self.wide
    }

    /// Bytes the tree holds: wide nodes and leaf rows, and the binary tree's nodes and
    /// triangles if kept.
    pub fn bytes(&self) -> usize {
        let binary = self.binary.as_ref().map_or(0, |(nodes, tris)| {
            std::mem::size_of_val::<[BinaryNode]>(nodes) + std::mem::size_of_val::<[Tri]>(tris)
        });
        std::mem::size_of_val::<[WideNode]>(&self.wide)
            + std::mem::size_of_val::<[f32]>(&self.rows)
            + binary
    }

    /// Wall time of the build (obvhs build, flattening and collapsing).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// The preset it was built with.
    pub fn preset(&self) -> Preset {
        self.preset
    }
}

fn check_soup(soup: &[[Vec3; 3]]) -> Result<(), BvhError> {
    if soup.len() >= u32::MAX as usize {
        return Err(BvhError::TooMany { count: soup.len() });
    }
    for (triangle, t) in soup.iter().enumerate() {
        if let Some(vertex) = t.iter().position(|v| !v.is_finite()) {
            return Err(BvhError::NonFinite {
                triangle,
                vertex,
                value: t[vertex].to_array(),
            });
        }
    }
    Ok(())
}

/// obvhs's tree over the triangles `ids` name in `soup` (all of them, in order, for
/// `None`), flattened ([`flatten`]) with the ids as primitive ids; obvhs's tree and its copy
/// of the triangles are dropped on return.
fn obvhs_flattened(
    soup: &[[Vec3; 3]],
    ids: Option<&[u32]>,
    preset: Preset,
) -> (Vec<BinaryNode>, Vec<Tri>) {
    let count = ids.map_or(soup.len(), <[u32]>::len);
    if count == 0 {
        return (vec![BinaryNode::EMPTY], Vec::new());
    }
    let id = |i: usize| ids.map_or(i, |ids| ids[i] as usize);
    let triangles: Vec<Triangle> = (0..count)
        .map(|i| {
            let t = &soup[id(i)];
            Triangle {
                v0: Vec3A::from(t[0]),
                v1: Vec3A::from(t[1]),
                v2: Vec3A::from(t[2]),
            }
        })
        .collect();
    let mut core = Duration::ZERO;
    let bvh2 = build_bvh2_from_tris(&triangles, preset.params(), &mut core);
    drop(triangles);
    flatten(&bvh2, count, |prim| {
        let global = id(prim as usize);
        Tri::new(soup[global], global as u32)
    })
}

/// Flattens obvhs's binary tree (children of inner node `i` at `first_index` and
/// `first_index + 1`) over `count` triangles into two-child-box nodes, depth first, triangles
/// in leaf order (`tri` of obvhs's primitive index).
fn flatten(bvh2: &Bvh2, count: usize, tri: impl Fn(u32) -> Tri) -> (Vec<BinaryNode>, Vec<Tri>) {
    let mut nodes = vec![BinaryNode::EMPTY];
    let mut tris = Vec::with_capacity(count);
    let mut fill = |nodes: &mut Vec<BinaryNode>, ours: usize, slot: usize, from: usize| {
        fill_slot(nodes, ours, slot, bvh2, from, &tri, &mut tris)
    };
    let root = &bvh2.nodes[0];
    if root.is_leaf() {
        fill(&mut nodes, 0, 0, 0);
    } else {
        // (obvhs index of the left child, our node index)
        let mut pending = vec![(root.first_index as usize, 0usize)];
        while let Some((left, ours)) = pending.pop() {
            for slot in 0..2 {
                if let Some(inner) = fill(&mut nodes, ours, slot, left + slot) {
                    pending.push(inner);
                }
            }
        }
    }
    (nodes, tris)
}

/// Writes obvhs node `from` into slot `slot` of our node `ours`; for an inner node allocates
/// its flattened node and returns `(its left child, its index)` to process.
fn fill_slot(
    nodes: &mut Vec<BinaryNode>,
    ours: usize,
    slot: usize,
    bvh2: &Bvh2,
    from: usize,
    tri: &impl Fn(u32) -> Tri,
    tris: &mut Vec<Tri>,
) -> Option<(usize, usize)> {
    let src = &bvh2.nodes[from];
    nodes[ours].set_box(slot, src.aabb().min.into(), src.aabb().max.into());
    if src.is_leaf() {
        let first = tris.len();
        let range = src.first_index as usize..(src.first_index + src.prim_count) as usize;
        for &prim in &bvh2.primitive_indices[range] {
            tris.push(tri(prim));
        }
        nodes[ours].child[slot] = first as u32;
        nodes[ours].meta[slot] = LEAF | src.prim_count;
        None
    } else {
        let index = nodes.len();
        nodes.push(BinaryNode::EMPTY);
        nodes[ours].child[slot] = index as u32;
        nodes[ours].meta[slot] = 0;
        Some((src.first_index as usize, index))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use guidebake_kernels::packet::{Hit8, Ray, Ray8};
    use guidebake_kernels::traverse::{intersect_brute, intersect1, intersect8, occluded8};

    #[test]
    fn the_better_tree_only_where_it_repays_its_build() {
        // The 10⁸-texel city (3.1 M triangles): a 1 % shard at 16 spp traces ~3·10⁷ rays.
        assert_eq!(Preset::for_rays(3_124_992, 3.2e7), Preset::MediumBuild);
        // The whole city, or the shard at 256 spp.
        assert_eq!(Preset::for_rays(3_124_992, 3.2e9), Preset::DEFAULT);
        assert_eq!(Preset::for_rays(3_124_992, 5.1e8), Preset::DEFAULT);
        // The ajar room, 128² texels at 256 spp; a 4-spp test bake of it builds fast.
        assert_eq!(
            Preset::for_rays(4_546, 128.0 * 128.0 * 256.0 * 2.0),
            Preset::DEFAULT
        );
        assert_eq!(
            Preset::for_rays(4_546, 4_000.0 * 4.0 * 2.0),
            Preset::MediumBuild
        );
    }

    fn quad() -> Vec<[Vec3; 3]> {
        vec![
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            [Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        ]
    }

    #[test]
    fn rejects_non_finite_vertices_naming_the_triangle() {
        let mut soup = quad();
        soup[1][2] = Vec3::new(0.0, f32::NAN, 0.0);
        let err = Bvh::build(&soup, Preset::DEFAULT).unwrap_err();
        assert!(
            matches!(
                err,
                BvhError::NonFinite {
                    triangle: 1,
                    vertex: 2,
                    ..
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn empty_and_single_triangle_soups_trace() {
        let ray = Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
        let empty = Bvh::build_with_binary(&[], Preset::DEFAULT).unwrap();
        assert_eq!(intersect1(&empty.binary().unwrap(), &ray), None);
        assert_eq!(intersect1(&empty.wide(), &ray), None);
        let one = Bvh::build_with_binary(&quad()[..1], Preset::DEFAULT).unwrap();
        assert_eq!(
            intersect1(&one.wide(), &ray),
            intersect1(&one.binary().unwrap(), &ray)
        );
        let hit = intersect1(&one.binary().unwrap(), &ray).unwrap();
        assert_eq!((hit.prim, hit.t), (0, 1.0));
    }

    /// `n` unit triangles on rows of `side`, at heights stepping by `step` over `levels`.
    fn grid(n: usize, side: usize, levels: usize, step: f32) -> Vec<[Vec3; 3]> {
        (0..n)
            .map(|i| {
                let p = Vec3::new(
                    (i % side) as f32,
                    (i / side) as f32,
                    (i % levels) as f32 * step,
                );
                [p, p + Vec3::X, p + Vec3::Y]
            })
            .collect()
    }

    #[test]
    fn a_large_world_traces_the_same_through_both_layouts() {
        let grid = grid(1 << 17, 512, 7, 0.1);
        let bvh = Bvh::build_with_binary(&grid, Preset::FastBuild).unwrap();
        assert!(bvh.wide_nodes().len() * 2 < bvh.binary().unwrap().nodes().len());
        for i in 0..200 {
            let o = Vec3::new(i as f32 * 2.3 % 512.0, i as f32 * 1.7 % 256.0, 5.0);
            let ray = Ray::new(o, Vec3::new(0.3, -0.2, -1.0), 0.0, f32::INFINITY);
            let want = intersect1(&bvh.binary().unwrap(), &ray);
            assert_eq!(intersect1(&bvh.wide(), &ray), want);
            assert_eq!(want, intersect_brute(bvh.binary().unwrap().tris(), &ray));
        }
        packets_match_brute_force(&bvh, Vec3::new(100.5, 60.25, 3.0), 0.8);
    }

    #[test]
    fn the_bake_s_tree_drops_the_binary_tree_and_traces_the_same() {
        let grid = grid(1 << 12, 64, 5, 0.2);
        let bake = Bvh::build(&grid, Preset::DEFAULT).unwrap();
        let both = Bvh::build_with_binary(&grid, Preset::DEFAULT).unwrap();
        assert!(bake.binary().is_none());
        let binary = both.binary().unwrap();
        assert!(binary.nodes().len() > 1000);
        assert_eq!(
            both.bytes() - bake.bytes(),
            std::mem::size_of_val(binary.nodes()) + std::mem::size_of_val(binary.tris())
        );
        assert_eq!(bake.wide_nodes(), both.wide_nodes());
        // The wide tree's rows are its only triangles: every leaf's, read back bit for bit.
        let mut rows: Vec<Tri> = bake.wide().tris().collect();
        let mut tris = binary.tris().to_vec();
        let key = |t: &Tri| (t.prim, t.v.map(|v| v.map(f32::to_bits)));
        rows.sort_by_key(key);
        tris.sort_by_key(key);
        assert_eq!(rows, tris);
        for i in 0..100 {
            let o = Vec3::new(i as f32 * 0.61 % 64.0, i as f32 * 0.37 % 64.0, 3.0);
            let ray = Ray::new(o, Vec3::new(0.2, 0.1, -1.0), 0.0, f32::INFINITY);
            assert_eq!(intersect1(&bake.wide(), &ray), intersect_brute(&tris, &ray));
        }
    }

    #[test]
    fn packets_through_the_wide_tree_of_a_small_world_match_brute_force() {
        let bvh = Bvh::build_with_binary(&quad(), Preset::FastBuild).unwrap();
        packets_match_brute_force(&bvh, Vec3::new(0.4, 0.3, 0.5), 0.6);
    }

    /// Packets of eight rays from `origin`, fanned downwards by `spread` (some miss), through
    /// both views of `bvh`: every lane's closest hit and occlusion (also with a `tmax` short of
    /// the hit) as brute force gives them.
    fn packets_match_brute_force(bvh: &Bvh, origin: Vec3, spread: f32) {
        let (mut hit, mut missed) = (0, 0);
        for k in 0..32 {
            let dirs: [Vec3; 8] = core::array::from_fn(|lane| {
                let a = (k * 8 + lane) as f32 * 0.37;
                Vec3::new(a.cos() * spread, a.sin() * spread, -1.0 + 0.025 * k as f32)
            });
            for tmax in [f32::INFINITY, 1.5] {
                let packet = Ray8::from_origin(origin, &dirs, 0.0, tmax);
                let (mut hits, mut binary) = (Hit8::NONE, Hit8::NONE);
                let hit_lanes = intersect8(&bvh.wide(), &packet, &mut hits);
                assert_eq!(
                    intersect8(&bvh.binary().unwrap(), &packet, &mut binary),
                    hit_lanes
                );
                assert_eq!(binary, hits);
                let blocked = occluded8(&bvh.wide(), &packet);
                assert_eq!(occluded8(&bvh.binary().unwrap(), &packet), blocked);
                for (lane, &dir) in dirs.iter().enumerate() {
                    let want = intersect_brute(
                        bvh.binary().unwrap().tris(),
                        &Ray::new(origin, dir, 0.0, tmax),
                    );
                    assert_eq!(hit_lanes >> lane & 1 == 1, want.is_some(), "{k} {lane}");
                    assert_eq!(blocked >> lane & 1 == 1, want.is_some(), "{k} {lane}");
                    if want.is_none() {
                        missed += 1;
                    }
                    if let Some(want) = want {
                        hit += 1;
                        assert_eq!(hits.prim.to_array()[lane], want.prim, "{k} {lane}");
                        assert_eq!(hits.t.to_array()[lane].to_bits(), want.t.to_bits());
                    }
                }
            }
        }
        assert!(hit > 50 && missed > 50, "{hit} hits, {missed} misses");
    }

    /// A city-like soup of `n` triangles: grids of unit triangles on `levels` floors, some
    /// of them slanted, some long thin ones across the whole world.
    fn jumbled(n: usize) -> Vec<[Vec3; 3]> {
        let mut rng = guidebake_kernels::testing::Pcg32::new(41, 7);
        let mut f = || rng.next_f32();
        (0..n)
            .map(|i| {
                if i % 97 == 0 {
                    let p = Vec3::new(f() * 64.0, f() * 64.0, f() * 8.0);
                    [p, Vec3::new(64.0 - p.x, p.y, p.z), p + Vec3::Z * 0.5]
                } else {
                    let p = Vec3::new(f() * 64.0, f() * 64.0, (f() * 8.0).floor());
                    [
                        p,
                        p + Vec3::new(1.0, 0.0, f()),
                        p + Vec3::new(0.0, 1.0, f() * 0.5),
                    ]
                }
            })
            .collect()
    }

    #[test]
    fn a_tree_built_in_regions_covers_every_triangle_and_traces_as_the_whole_one() {
        let soup = jumbled(6000);
        let whole = Bvh::build_with_binary(&soup, Preset::MediumBuild).unwrap();
        for preset in [Preset::MediumBuild, Preset::VerySlowBuild] {
            // 6000 triangles in regions of at most 700: 16 regions.
            let cut = Bvh::build_in_regions(&soup, None, preset, 700, true).unwrap();
            let bake = Bvh::build_in_regions(&soup, None, preset, 700, false).unwrap();
            assert_eq!(bake.wide_nodes(), cut.wide_nodes(), "{preset:?}");
            assert!(bake.binary().is_none());
            // Every triangle, bit for bit, in both layouts (spatial splits may repeat one).
            let key = |t: &Tri| (t.prim, t.v.map(|v| v.map(f32::to_bits)));
            let mut want: Vec<Tri> = soup
                .iter()
                .enumerate()
                .map(|(i, t)| Tri::new(*t, i as u32))
                .collect();
            want.sort_by_key(key);
            for mut got in [
                bake.wide().tris().collect::<Vec<_>>(),
                cut.binary().unwrap().tris().to_vec(),
            ] {
                got.sort_by_key(key);
                got.dedup();
                assert_eq!(got, want, "{preset:?}");
            }
            let mut rng = guidebake_kernels::testing::Pcg32::new(41, 8);
            let mut f = || rng.next_f32();
            for _ in 0..3000 {
                let o = Vec3::new(f() * 80.0 - 8.0, f() * 80.0 - 8.0, f() * 12.0 - 2.0);
                let d = Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5);
                let ray = Ray::new(o, d, 0.0, f32::INFINITY);
                let brute = intersect_brute(&want, &ray);
                assert_eq!(intersect1(&whole.wide(), &ray), brute);
                assert_eq!(intersect1(&bake.wide(), &ray), brute);
                assert_eq!(intersect1(&cut.binary().unwrap(), &ray), brute);
            }
            packets_match_brute_force(&cut, Vec3::new(30.5, 20.25, 12.0), 3.0);
        }
    }

    #[test]
    fn a_tree_over_some_triangles_meets_only_those_and_names_them_by_their_scene_index() {
        let soup = jumbled(3000);
        // Every third triangle is left out (as rays pass through a `sky` or `skip` surface).
        let ids: Vec<u32> = (0..soup.len() as u32).filter(|i| i % 3 != 0).collect();
        let want: Vec<Tri> = ids.iter().map(|&i| Tri::new(soup[i as usize], i)).collect();
        let whole = Bvh::build_over(&soup, Some(&ids), Preset::MediumBuild).unwrap();
        let cut =
            Bvh::build_in_regions(&soup, Some(&ids), Preset::MediumBuild, 500, false).unwrap();
        let mut rng = guidebake_kernels::testing::Pcg32::new(43, 2);
        let mut f = || rng.next_f32();
        let mut hits = 0;
        for _ in 0..3000 {
            let o = Vec3::new(f() * 60.0 - 8.0, f() * 60.0 - 8.0, f() * 12.0 - 2.0);
            let d = Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5);
            let ray = Ray::new(o, d, 0.0, f32::INFINITY);
            let brute = intersect_brute(&want, &ray);
            hits += usize::from(brute.is_some());
            assert_eq!(intersect1(&whole.wide(), &ray), brute);
            assert_eq!(intersect1(&cut.wide(), &ray), brute);
        }
        assert!(hits > 300, "the rays meet the kept triangles: {hits}");
        let all = Bvh::build_over(&soup, None, Preset::MediumBuild).unwrap();
        let prims: std::collections::BTreeSet<u32> = all.wide().tris().map(|t| t.prim).collect();
        assert_eq!(prims.len(), soup.len());
    }

    #[test]
    fn a_tree_built_in_regions_is_the_same_on_any_number_of_threads() {
        let soup = jumbled(5000);
        let on = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| Bvh::build_in_regions(&soup, None, Preset::VerySlowBuild, 600, false))
                .unwrap()
        };
        let (one, three) = (on(1), on(3));
        assert_eq!(one.wide_nodes(), three.wide_nodes());
        assert_eq!(
            one.wide().tris().collect::<Vec<_>>(),
            three.wide().tris().collect::<Vec<_>>()
        );
        assert_eq!(one.bytes(), three.bytes());
    }

    #[test]
    fn every_preset_keeps_every_triangle() {
        let soup = quad();
        for preset in Preset::ALL {
            let bvh = Bvh::build_with_binary(&soup, preset).unwrap();
            let mut prims: Vec<u32> = bvh
                .binary()
                .unwrap()
                .tris()
                .iter()
                .map(|t| t.prim)
                .collect();
            prims.sort_unstable();
            prims.dedup();
            assert_eq!(prims, [0, 1], "{preset:?}");
            let ray = Ray::new(Vec3::new(0.7, 0.7, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
            assert_eq!(
                intersect1(&bvh.binary().unwrap(), &ray),
                intersect_brute(bvh.binary().unwrap().tris(), &ray)
            );
            assert_eq!(intersect1(&bvh.binary().unwrap(), &ray).unwrap().prim, 1);
            assert_eq!(
                intersect1(&bvh.wide(), &ray),
                intersect1(&bvh.binary().unwrap(), &ray)
            );
        }
    }
}
