//! `guide`: the learned directional quadtree and its hierarchical smoothing filter
//! (Silvennoinen & Sloan 2019, §2.2 "Learning" and §2.3 "Filtering").
//!
//! The guide lives on the **primary sample square** [0,1)², not on the hemisphere: the
//! unguided baseline is the uniform density on the square (the cosine-weighted hemisphere map
//! of [`crate::mapping`] turns it into cosθ/π), so a guide learned on the square learns the
//! incident radiance alone and its directional density is p(ω) = p_square(u)·cosθ/π.
//!
//! # Building (§2.2)
//! Records are gather samples `(u, flux)`. The flux of a sample taken with density `p` on the
//! square is its luminance `L / p(u)`, so learning stays unbiased whichever guide (or the
//! baseline, `p = 1`) produced the samples. [`build`] then:
//! 1. rejects and counts records with non-finite or negative flux, or `u` outside [0,1)²
//!    ([`BuildStats`]);
//! 2. splits top-down, breadth first: a node splits into four quadrants while it holds at
//!    least [`GuideParams::min_records`] records (4) and at least
//!    [`GuideParams::min_flux_fraction`] (1%) of the total flux, up to
//!    [`GuideParams::max_depth`]. The records are first sorted by the Morton order of their
//!    quadtree cells, only as deep as the rule can split (`cells`: an MSD radix sort, up to
//!    four levels a pass), so every node's records are one contiguous range and a split
//!    finds its children's ranges by binary search and sums their fluxes (f64) — no
//!    per-level partitioning (the tree is the one the partitioning build gave,
//!    kept as the test oracle `reference`);
//! 3. gives every leaf `max(flux, ambient · total · area)` (with
//!    [`GuideParams::second_moment`], the records' flux is `L²/q` and a leaf's flux is first
//!    `√(total · area · flux)`: the density ∝ `√E[L²]` of variance-aware guiding, Rath et al.
//!    2020): the **ambient floor** is a floor
//!    on the density relative to its mean, so no direction has zero probability (default
//!    [`DEFAULT_AMBIENT`] = 0.1: no leaf below a tenth of the uniform density, which bounds
//!    the variance cost in directions the learning missed);
//! 4. normalizes (root mass 1) and sums masses bottom-up;
//! 5. smooths (§2.3), top-down, every node visited once: each child's share of its parent is
//!    interpolated toward the parent's average (a quarter) by α ([`DEFAULT_ALPHA`] = 0.25):
//!    `m_child' = m_parent' · ((1 − α)·m_child / m_parent + α/4)`, with `m_parent'` the
//!    already smoothed parent mass. Masses stay normalized. With a **defensive mixture**
//!    ([`GuideParams::uniform`] = c > 0) every mass then becomes `c·area + (1 − c)·mass`:
//!    the density `c + (1 − c)·q`, never below `c` (the bake's `--mix`);
//! 6. derives what the warp needs (Clarberg et al. 2005, see [`crate::warp`]): from the
//!    marginal probability `px` of a node's left half and the conditionals `py[h]` of its
//!    lower half given the x-half `h`, the split **thresholds in primary sample space** — the
//!    warp's per-level rescaling folded into the tree — and for each leaf the rectangle of
//!    primary sample space that maps onto it and its density (that rectangle's area over the
//!    leaf's area).
//!
//! If no record survives, or the accepted flux sums to zero, the guide is the uniform density
//! (a root leaf): there is nothing to learn from.
//!
//! # Storage and capacity
//! The caller supplies the node array (`&mut [GuideNode]`, at most [`MAX_NODES`] nodes are used,
//! because child links are `u16`); nothing allocates. The records are sorted in place
//! (their order changes). Before the tree is written the whole storage is the sort's
//! scratch ([`SORT_BYTES_PER_RECORD`] bytes a record; with less room the sort runs in place,
//! several times slower): past the tree and the start table its contents are unspecified
//! after a build. A caller whose records outgrow its tree's storage lends the sort more room
//! with [`build_in`] ([`sort_room`] nodes) and gets the same tree (the records in another
//! order inside the cells that do not split, so a node's f64 flux sum may round otherwise
//! where the fluxes span many decades). Nodes are created
//! breadth first, so **when the storage is full**
//! every level that was split is complete and the nodes that would split further simply stay
//! leaves: the guide is the best coarser tree that fits, still a valid normalized density.
//! The number of refused splits is reported in [`BuildStats::capacity_refusals`].
//!
//! After the tree, if [`START_TABLE_NODES`] nodes of the storage are still free, `build`
//! writes the warp's **start table** there ([`Guide::start_table`]: for each cell of a
//! [`START_GRID`]² grid over the primary sample square, the deepest node the whole cell
//! passes through) and, per cell, four **shortcuts**: for each quadrant of the cell's start
//! node, the deepest node that every point of the cell going that way passes through. They
//! are what lets the 8-wide warp skip the top of the tree; without room for them the guide
//! is the same density and the warp gives the same results, more slowly. Filling the start
//! table visits every node and writes every cell once; each shortcut is one short descent
//! of the cell's part (exact f32 interval tests against the thresholds).
//!
//! # Embedding
//! A whole tiny baker — clustering, a guide learned per cluster over iterations, 8-wide
//! warps, packet tracing, Graybill–Deal with ρ, checked against an analytic light — is
//! `kernels/examples/embed.rs` (`cargo run -p guidebake-kernels --example embed`); the same
//! in C and C++ through the C ABI is under `examples/`, and `kernels/README.md` ("Embedding")
//! gives the ABI's rules. The core of it: learn from one iteration's records, warp the next.
//! ```
//! use guidebake_kernels::guide::{self, GuideParams, GuideNode, Record};
//! use guidebake_kernels::warp;
//! use wide::f32x8;
//!
//! // Records of the previous iteration: bright light arrived around u = (0.9, 0.5).
//! let mut records: Vec<Record> = (0..256)
//!     .map(|i| {
//!         let u = [(i % 16) as f32 / 16.0, (i / 16) as f32 / 16.0];
//!         Record { u, flux: if u[0] > 0.8 { 50.0 } else { 0.5 } }
//!     })
//!     .collect();
//! let mut storage = vec![GuideNode::default(); 1024]; // fixed memory, reused per cluster
//! let (g, stats) = guide::build(&mut records, &GuideParams::default(), &mut storage);
//! assert!(stats.nodes > 1);
//! // One packet of eight points of [0,1)² (presorted, rotated Sobol points in a baker).
//! let x = f32x8::new([0.05, 0.15, 0.3, 0.45, 0.55, 0.7, 0.85, 0.95]);
//! let w = warp::sample8(&g, x, f32x8::splat(0.5));
//! // Most warped points land where the light was; each carries its density for the estimate.
//! let bright = w.x.to_array().iter().filter(|&&x| x >= 0.8).count();
//! assert!(bright >= 4, "{bright}");
//! assert!(w.pdf.to_array().iter().all(|&p| p > 0.0));
//! ```
//!
//! # Deviations from the paper
//! The paper does not state its floor or depth cap; ours are parameters with the defaults
//! above. The paper's smoothing is phrased on node values; ours keeps the masses summing to
//! one exactly (up to rounding) so no renormalization pass is needed.

use wide::f32x8;

mod cells;
#[cfg(any(test, feature = "testing"))]
#[doc(hidden)]
pub mod reference;

/// Largest number of nodes a guide can use: child links are `u16`.
pub const MAX_NODES: usize = u16::MAX as usize;
/// Largest depth cap [`GuideParams::max_depth`] accepts: leaves of side 2⁻¹⁶ still hold 256
/// distinct f32 values per axis near 1.
pub const MAX_DEPTH: u32 = 16;
/// Default ambient floor: no leaf gets less than 0.1× the uniform density before smoothing.
pub const DEFAULT_AMBIENT: f32 = 0.1;
/// Default smoothing strength α (paper §2.3).
pub const DEFAULT_ALPHA: f32 = 0.25;

/// One learning sample: a point of the primary sample square and its flux
/// (luminance divided by the density on the square that generated it).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Record {
    /// The sample's point in [0,1)².
    pub u: [f32; 2],
    /// `L / p_square(u)`, finite and ≥ 0 to be accepted.
    pub flux: f32,
}

/// Parameters of [`build`]; [`Default`] gives the documented defaults.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuideParams {
    /// A node splits only if it holds at least this many records (default 4).
    pub min_records: u32,
    /// ... and at least this fraction of the total flux (default 0.01).
    pub min_flux_fraction: f32,
    /// Depth cap; the root has depth 0 (default 10, clamped to [`MAX_DEPTH`]).
    pub max_depth: u32,
    /// Ambient floor on every leaf's density relative to the mean (default [`DEFAULT_AMBIENT`]).
    /// 0 lets leaves without flux get probability 0 (and the warp never goes there), which
    /// biases an estimator if radiance arrives there after all; for tests and inspection.
    pub ambient: f32,
    /// Smoothing strength α ∈ [0, 1] (default [`DEFAULT_ALPHA`]); 0 disables smoothing,
    /// 1 makes every node uniform over its children.
    pub alpha: f32,
    /// Share `c` ∈ [0, 1] of the uniform density in the **defensive mixture** the guide
    /// samples: `c + (1 − c)·q(u)`, with `q` the floored, smoothed guide (default 0). The
    /// mixture is folded into the tree (every node's mass becomes `c·area + (1 − c)·mass`
    /// before the thresholds are derived), so one warp draws from it and one lookup gives its
    /// density: the bake's presorted points stay one coherent set, none is set aside for the
    /// uniform part, and no sample needs a second density.
    pub uniform: f32,
    /// Learn the **square root of the second moment** instead of the flux (default false):
    /// the records carry `L²/q` (the sampled quantity squared over the density that drew
    /// it), whose sum over a leaf estimates `∫ L²` there, and each leaf's mass before the
    /// floor is `√(area · share)`: the density ∝ `√E[L²]` over the records' texels, which
    /// minimises their summed variance (variance-aware guiding, Rath et al. 2020) where the
    /// flux target ∝ `E[L]` minimises it only for one texel. With one value per direction
    /// the two targets are the same density.
    pub second_moment: bool,
}

impl Default for GuideParams {
    fn default() -> Self {
        GuideParams {
            min_records: 4,
            min_flux_fraction: 0.01,
            max_depth: 10,
            ambient: DEFAULT_AMBIENT,
            alpha: DEFAULT_ALPHA,
            uniform: 0.0,
            second_moment: false,
        }
    }
}

/// A node of the directional quadtree. Children of an interior node are four consecutive
/// nodes, quadrants in the order (x low, y low), (x high, y low), (x low, y high),
/// (x high, y high).
///
/// Two spaces meet here: the node's *square* (`origin`, `size`) is where the warp puts
/// points, its *source rectangle* `[lo, hi)` is the part of the primary sample space the warp
/// maps onto that square.
///
/// Layout: 64 bytes, 64-byte aligned (one cache line per node). The eight fields the warp's
/// final step reads (`lo`, `hi`, `origin`, `size`, `pdf`) come first, 32 contiguous bytes;
/// `link` and `inner_kids` exist for the 8-wide warp's branch-free descent.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GuideNode {
    /// Lower corner of the source rectangle.
    pub(crate) lo: [f32; 2],
    /// Upper corner of the source rectangle (exclusive).
    pub(crate) hi: [f32; 2],
    /// Lower corner of the node's square.
    pub(crate) origin: [f32; 2],
    /// Side of the node's square (a power of two).
    pub(crate) size: f32,
    /// Density on the square inside the node: source area over square area.
    pub(crate) pdf: f32,
    /// Interior: the warp goes right if `u.x >= t[0]`, then up if `u.y >= t[1 + right]`
    /// (thresholds in primary sample space). Leaf: unused (0).
    pub(crate) t: [f32; 3],
    /// Probability mass of the node after floor, normalization and smoothing (root 1).
    pub(crate) mass: f32,
    /// First record of the node during the build (the records are sorted in place).
    first: u32,
    /// Number of records of the node.
    count: u32,
    /// Index of the first child; 0 for a leaf (the root is never a child).
    pub(crate) child: u16,
    /// Depth (root 0; at most [`MAX_DEPTH`]).
    depth: u8,
    /// Bit `q` set if child `q` is interior (none for a leaf): the 8-wide warp's step
    /// learns whether a lane arrived in a leaf without reading the child.
    pub(crate) inner_kids: u8,
    /// The 8-wide warp's link: `child` for an interior node; for a leaf its own index
    /// minus 3 (wrapping), so that the branch-free step `link + right + 2·upper` keeps a
    /// lane in its leaf (a leaf's thresholds are 0, so `right` and `upper` are 1).
    pub(crate) link: u32,
}

impl GuideNode {
    /// `lo, hi, origin, size, pdf`: the node's first 32 bytes, what the warp's last step reads.
    #[inline(always)]
    pub(crate) fn leaf_row(&self) -> [f32; 8] {
        *bytemuck::from_bytes(&bytemuck::bytes_of(self)[..32])
    }
    /// Whether the node is a leaf.
    pub fn is_leaf(&self) -> bool {
        self.child == 0
    }
    /// Index of the first of the four children (quadrant order in the type's doc), `None`
    /// for a leaf.
    pub fn first_child(&self) -> Option<usize> {
        (self.child != 0).then_some(usize::from(self.child))
    }
    /// Probability mass of the node after floor, normalization and smoothing.
    pub fn mass(&self) -> f32 {
        self.mass
    }
    /// Split thresholds in primary sample space: x, then y given the left or the right half
    /// (interior nodes; zeros for a leaf).
    pub fn thresholds(&self) -> [f32; 3] {
        self.t
    }
    /// The source rectangle `[lo, hi)` of primary sample space that the warp maps onto the
    /// node's square.
    pub fn source(&self) -> ([f32; 2], [f32; 2]) {
        (self.lo, self.hi)
    }
    /// The node's square: lower corner and side.
    pub fn square(&self) -> ([f32; 2], f32) {
        (self.origin, self.size)
    }
    /// Density on the square inside the node (the warp's pdf for a leaf).
    pub fn pdf(&self) -> f32 {
        self.pdf
    }
    /// Depth of the node (root 0).
    pub fn depth(&self) -> u32 {
        u32::from(self.depth)
    }
    /// Number of accepted records that fell in the node.
    pub fn records(&self) -> u32 {
        self.count
    }
}

/// What [`build`] did with its input.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BuildStats {
    /// Records used for learning.
    pub accepted: u32,
    /// Records dropped for non-finite or negative flux.
    pub rejected_flux: u32,
    /// Records dropped for a point outside [0,1)² (or NaN).
    pub rejected_point: u32,
    /// Total accepted flux (before the floor).
    pub total_flux: f64,
    /// Nodes used.
    pub nodes: u32,
    /// Leaves.
    pub leaves: u32,
    /// Deepest leaf.
    pub depth: u32,
    /// Splits the rule asked for but the storage could not hold.
    pub capacity_refusals: u32,
    /// Splits stopped by the depth cap.
    pub depth_refusals: u32,
}

/// Cells per axis of the warp's start table (a power of two, so `u · START_GRID` is exact).
pub const START_GRID: usize = 32;
/// Nodes of storage the start table occupies after the tree: `START_GRID²` u16 start
/// nodes and `START_GRID²` × 4 u16 shortcuts (10 KB).
pub const START_TABLE_NODES: usize =
    (START_GRID * START_GRID * 2 * 5).div_ceil(core::mem::size_of::<GuideNode>());

/// A built guide: a view of the caller's node storage.
#[derive(Clone, Copy, Debug)]
pub struct Guide<'a> {
    nodes: &'a [GuideNode],
    /// The start table ([`Guide::start_table`]), empty when the storage had no room for it.
    start: &'a [u16],
    /// Per start-table cell, per quadrant of its start node: the deepest node that every
    /// point of the cell in that quadrant passes through (empty with `start`).
    shortcuts: &'a [[u16; 4]],
}

/// A leaf as a square of the primary sample space with its constant density.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leaf {
    /// Lower corner.
    pub origin: [f32; 2],
    /// Side length (a power of two).
    pub size: f32,
    /// Density on the square inside the leaf, as [`crate::warp::pdf`] returns it.
    pub pdf: f32,
}

impl<'a> Guide<'a> {
    /// The uniform guide (one root leaf) in `storage`.
    ///
    /// # Panics
    /// If `storage` is empty.
    pub fn uniform(storage: &'a mut [GuideNode]) -> Guide<'a> {
        assert!(
            !storage.is_empty(),
            "guide storage must hold at least one node"
        );
        storage[0] = root_leaf(0);
        Guide {
            nodes: &storage[..1],
            start: &[],
            shortcuts: &[],
        }
    }

    /// The nodes in breadth-first order; index 0 is the root.
    pub fn nodes(&self) -> &'a [GuideNode] {
        self.nodes
    }

    /// The warp's **start table**: for each cell `(cx, cy)` of a `START_GRID × START_GRID`
    /// grid over the primary sample square, at index `cx + START_GRID · cy`, the deepest node
    /// that every point of the cell `[cx, cx+1)/G × [cy, cy+1)/G` passes through on its way
    /// down (the thresholds are in primary sample space, so this is exact). The 8-wide warp
    /// starts each lane there instead of at the root. Empty for the uniform guide and when
    /// the storage has fewer than [`START_TABLE_NODES`] nodes left after the tree; the warp
    /// then starts at the root (same results, slower).
    pub fn start_table(&self) -> &'a [u16] {
        self.start
    }

    /// For each start-table cell and each quadrant `q` (`right + 2·upper`) of the cell's
    /// start node: the deepest node that every point of the cell taking quadrant `q` there
    /// passes through, the 8-wide warp's second node (the start node itself, all four, when
    /// it is a leaf). Empty with the start table.
    pub(crate) fn shortcuts(&self) -> &'a [[u16; 4]] {
        self.shortcuts
    }

    /// Whether the guide is the uniform density (a single leaf).
    pub fn is_uniform(&self) -> bool {
        self.nodes.len() == 1
    }

    /// Visits every leaf with its square and density (for inspection, tests and plots).
    pub fn for_each_leaf(&self, mut f: impl FnMut(Leaf)) {
        // Side 0: a node cut off the tree by `collapse`.
        for n in self.nodes.iter().filter(|n| n.is_leaf() && n.size > 0.0) {
            f(Leaf {
                origin: n.origin,
                size: n.size,
                pdf: n.pdf,
            });
        }
    }
}

fn root_leaf(count: u32) -> GuideNode {
    GuideNode {
        t: [0.0; 3],
        lo: [0.0; 2],
        hi: [1.0; 2],
        origin: [0.0; 2],
        size: 1.0,
        pdf: 1.0,
        mass: 1.0,
        first: 0,
        count,
        child: 0,
        depth: 0,
        inner_kids: 0,
        link: 0u32.wrapping_sub(3),
    }
}

/// Builds the guide from `records` into `storage` (see the module docs for the rule).
/// `records` is reordered in place; rejected records end up after the accepted ones.
/// Records beyond the first `u32::MAX` are ignored (node record counts are `u32`). All of
/// `storage` is scratch during the build: past the tree and the start table its contents
/// are unspecified afterwards.
///
/// # Panics
/// If `storage` is empty. Parameters out of range are clamped (depth to [`MAX_DEPTH`], α and
/// the flux fraction to [0, 1], a negative or NaN ambient floor to 0).
///
/// The warp's start table ([`Guide::start_table`]) is written into the
/// [`START_TABLE_NODES`] nodes of `storage` that follow the tree, when they are free.
pub fn build<'a>(
    records: &mut [Record],
    params: &GuideParams,
    storage: &'a mut [GuideNode],
) -> (Guide<'a>, BuildStats) {
    build_in(records, params, storage, &mut [])
}

/// [`build`], its records' sort scattering through `room` when `storage` has too little
/// ([`sort_room`] nodes for the records): the same tree (up to the rounding of the flux
/// sums, module docs), faster. `room`'s contents are unspecified afterwards.
pub fn build_in<'a>(
    records: &mut [Record],
    params: &GuideParams,
    storage: &'a mut [GuideNode],
    room: &mut [GuideNode],
) -> (Guide<'a>, BuildStats) {
    build_with(records, params, storage, room, sort, split)
}

/// Bytes of scratch the records' counting sort scatters through, a record: the record and
/// its bucket.
pub const SORT_BYTES_PER_RECORD: usize = size_of::<Record>() + 1;

/// Nodes whose bytes hold the sort's scratch for `records` records ([`build_in`]).
pub const fn sort_room(records: usize) -> usize {
    (records * SORT_BYTES_PER_RECORD).div_ceil(size_of::<GuideNode>())
}

/// Sorts the accepted records by their cells ([`cells::sort`]), scattering through `storage`
/// (not yet written) or, where that is too small, `room`: [`SORT_BYTES_PER_RECORD`] bytes a
/// record (the bake's 4 096 nodes hold 20 000 records); with neither it sorts in place.
fn sort(
    records: &mut [Record],
    params: &GuideParams,
    storage: &mut [GuideNode],
    room: &mut [GuideNode],
) {
    let n = records.len();
    let space = if storage.len() >= sort_room(n) {
        storage
    } else {
        room
    };
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(space);
    let (scratch, digits) = match bytes.get_mut(..n * SORT_BYTES_PER_RECORD) {
        Some(room) => {
            let (scratch, digits) = room.split_at_mut(size_of_val(records));
            (bytemuck::cast_slice_mut(scratch), digits)
        }
        None => (&mut [][..], &mut [][..]),
    };
    let max_depth = params.max_depth.min(MAX_DEPTH);
    cells::sort(records, scratch, digits, 0, max_depth, params.min_records);
}

/// Splits a node (`records`, `nodes`, the node, its first child's index, the total flux).
type SplitFn = fn(&mut [Record], &mut [GuideNode], usize, usize, f64);

/// [`build`] with its record order (`sort`, run on the accepted records before the
/// subdivision, with the storage and the room it may scatter through) and its `split`;
/// `reference::build` passes the partitioning ones.
fn build_with<'a>(
    records: &mut [Record],
    params: &GuideParams,
    storage: &'a mut [GuideNode],
    room: &mut [GuideNode],
    sort: fn(&mut [Record], &GuideParams, &mut [GuideNode], &mut [GuideNode]),
    split: SplitFn,
) -> (Guide<'a>, BuildStats) {
    assert!(
        !storage.is_empty(),
        "guide storage must hold at least one node"
    );
    let capacity = storage.len().min(MAX_NODES);
    let usable = records.len().min(u32::MAX as usize);
    let records = &mut records[..usable];
    let mut stats = BuildStats::default();
    let accepted = partition_valid(records, &mut stats);
    let records = &mut records[..accepted];
    stats.accepted = accepted as u32;
    stats.total_flux = flux_sum(records);
    storage[0] = root_leaf(stats.accepted);
    if !(stats.total_flux > 0.0 && stats.total_flux.is_finite()) {
        stats.nodes = 1;
        stats.leaves = 1;
        return (
            Guide {
                nodes: &storage[..1],
                start: &[],
                shortcuts: &[],
            },
            stats,
        );
    }
    // The sort may use all of `storage` as scratch: the root is written again after it.
    sort(records, params, storage, room);
    storage[0] = root_leaf(stats.accepted);
    subdivide(records, params, &mut storage[..capacity], &mut stats, split);
    let (nodes, rest) = storage.split_at_mut(stats.nodes as usize);
    set_masses(
        nodes,
        f64::from(sanitize(params.ambient, 0.0, f32::MAX)),
        params.second_moment,
    );
    smooth(
        nodes,
        f64::from(sanitize(params.alpha, 0.0, 1.0)),
        f64::from(sanitize(params.uniform, 0.0, 1.0)),
    );
    set_links(nodes);
    let (start, shortcuts): (&mut [u16], &mut [[u16; 4]]) = match rest.get_mut(..START_TABLE_NODES)
    {
        Some(room) if nodes.len() > 1 => {
            let cells = START_GRID * START_GRID;
            let words: &mut [u16] = bytemuck::cast_slice_mut(room);
            let (table, rest) = words.split_at_mut(cells);
            let shortcuts = bytemuck::cast_slice_mut(&mut rest[..4 * cells]);
            fill_start_table(nodes, table);
            fill_shortcuts(nodes, table, shortcuts);
            (table, shortcuts)
        }
        _ => (&mut [], &mut []),
    };
    (
        Guide {
            nodes,
            start,
            shortcuts,
        },
        stats,
    )
}

/// Sets every node's `link` and `inner_kids` (the 8-wide warp's branch-free step).
fn set_links(nodes: &mut [GuideNode]) {
    for i in 0..nodes.len() {
        let (link, inner_kids) = match nodes[i].first_child() {
            Some(c) => {
                let kids = (0..4).fold(0, |m, q| m | u8::from(!nodes[c + q].is_leaf()) << q);
                (c as u32, kids)
            }
            None => {
                debug_assert_eq!(nodes[i].t, [0.0; 3], "a leaf's thresholds are 0");
                ((i as u32).wrapping_sub(3), 0)
            }
        };
        nodes[i].link = link;
        nodes[i].inner_kids = inner_kids;
    }
}

/// Fills the start table (see [`Guide::start_table`]) top-down, writing every cell once.
fn fill_start_table(nodes: &[GuideNode], table: &mut [u16]) {
    let g = START_GRID as u32;
    fill_cells(nodes, 0, [0, g], [0, g], table);
}

/// The cells of `[lo, hi)` (in cell units along one axis) whose points all lie below the
/// threshold `t`, and those whose points all lie at or above it. A cell `c` holds the f32
/// values `v` with `⌊v·G⌋ = c`, i.e. `c/G ≤ v < (c+1)/G` exactly (G is a power of two), so
/// it lies below `t` iff `c + 1 ≤ t·G` and at or above iff `c ≥ t·G`. A cell in neither
/// range straddles `t`.
fn cells_by_side(t: f32, [lo, hi]: [u32; 2]) -> ([u32; 2], [u32; 2]) {
    let tg = t * START_GRID as f32; // exact, in [0, G]
    let floor = tg as u32;
    let ceil = floor + u32::from((floor as f32) < tg);
    ([lo, floor.clamp(lo, hi)], [ceil.clamp(lo, hi), hi])
}

/// Writes node `i` into the cells of `[xs) × [ys)` (all of whose points reach node `i`)
/// that straddle one of its thresholds, and recurses into the children with the rest.
fn fill_cells(nodes: &[GuideNode], i: usize, xs: [u32; 2], ys: [u32; 2], table: &mut [u16]) {
    let write = |table: &mut [u16], xs: [u32; 2], ys: [u32; 2]| {
        if xs[0] >= xs[1] {
            return;
        }
        for cy in ys[0]..ys[1] {
            let row = cy as usize * START_GRID;
            for cell in &mut table[row + xs[0] as usize..row + xs[1] as usize] {
                *cell = i as u16;
            }
        }
    };
    let Some(c) = nodes[i].first_child() else {
        write(table, xs, ys);
        return;
    };
    let t = nodes[i].t;
    let (left, right) = cells_by_side(t[0], xs);
    write(table, [left[1], right[0]], ys); // the column straddling the x threshold, if any
    for (half, x) in [left, right].into_iter().enumerate() {
        if x[0] >= x[1] {
            continue;
        }
        let (below, above) = cells_by_side(t[1 + half], ys);
        write(table, x, [below[1], above[0]]);
        for (q, y) in [(0, below), (2, above)] {
            if y[0] < y[1] {
                fill_cells(nodes, c + half + q, x, y, table);
            }
        }
    }
}

/// Fills [`Guide::shortcuts`]: for each cell whose start node is interior, the four parts
/// of the cell by the start node's thresholds, each followed down its child as far as all
/// of its points go the same way.
fn fill_shortcuts(nodes: &[GuideNode], table: &[u16], shortcuts: &mut [[u16; 4]]) {
    let g = START_GRID as f32;
    for (k, (&n, s)) in table.iter().zip(shortcuts).enumerate() {
        let n = usize::from(n);
        let Some(c) = nodes[n].first_child() else {
            *s = [n as u16; 4];
            continue;
        };
        // The cell's points: [cx, cx+1)/G × [cy, cy+1)/G, exact (G a power of two).
        let (cx, cy) = ((k % START_GRID) as f32, (k / START_GRID) as f32);
        let (xs, ys) = ([cx / g, (cx + 1.0) / g], [cy / g, (cy + 1.0) / g]);
        let t = nodes[n].t;
        for (q, s) in s.iter_mut().enumerate() {
            let (right, upper) = (q & 1, q >> 1);
            let part_x = side(xs, t[0], right);
            let part_y = side(ys, t[1 + right], upper);
            *s = deepest_passed(nodes, c + q, part_x, part_y) as u16;
        }
    }
}

/// The part of the f32 interval `[a, b)` below the threshold `t` (`upper` 0) or at or
/// above it (`upper` 1); empty when `a ≥ b`.
fn side([a, b]: [f32; 2], t: f32, upper: usize) -> [f32; 2] {
    if upper == 1 {
        [a.max(t), b]
    } else {
        [a, b.min(t)]
    }
}

/// The deepest node below node `i` (or `i`) that every point of `[xs) × [ys)` passes
/// through, given that they all reach `i` (`i` for an empty rectangle). The points of
/// `[a, b)` all lie below `t` iff `b ≤ t` and all at or above it iff `a ≥ t`; otherwise `t`
/// itself is one of them and `a` another, on the other side, so the test is exact.
fn deepest_passed(nodes: &[GuideNode], mut i: usize, xs: [f32; 2], ys: [f32; 2]) -> usize {
    if xs[0] >= xs[1] || ys[0] >= ys[1] {
        return i;
    }
    let side_of = |[a, b]: [f32; 2], t: f32| {
        if b <= t {
            Some(0)
        } else if a >= t {
            Some(1)
        } else {
            None
        }
    };
    while let Some(c) = nodes[i].first_child() {
        let t = nodes[i].t;
        let Some(right) = side_of(xs, t[0]) else {
            break;
        };
        let Some(upper) = side_of(ys, t[1 + right]) else {
            break;
        };
        i = c + right + 2 * upper;
    }
    i
}

fn sanitize(x: f32, lo: f32, hi: f32) -> f32 {
    if x >= lo { x.min(hi) } else { lo }
}

/// Moves valid records to the front (in their order), counting the rejected ones; returns
/// how many are valid. The leading valid records (usually all) are only read, eight at a
/// time ([`count_leading_valid`]); from the first rejected one on, every record is swapped
/// to the front of the rejected ones, which grows past it only if it is valid (branch-free).
fn partition_valid(records: &mut [Record], stats: &mut BuildStats) -> usize {
    let in_square = |v: f32| (0.0..1.0).contains(&v);
    let leading = count_leading_valid(records);
    let mut kept = leading;
    for i in leading..records.len() {
        let r = records[i];
        let flux_ok = r.flux.is_finite() & (r.flux >= 0.0);
        let point_ok = in_square(r.u[0]) & in_square(r.u[1]);
        stats.rejected_flux += u32::from(!flux_ok);
        stats.rejected_point += u32::from(flux_ok & !point_ok);
        records[i] = records[kept];
        records[kept] = r;
        kept += usize::from(flux_ok & point_ok);
    }
    kept
}

/// The number of valid records before the first rejected one, or a few fewer (a multiple
/// of eight, the rest is for the caller): eight records are 24 floats, three vectors each
/// checked against `0 ≤ v < bound` with the bound 1 for `u` and ∞ for the flux (NaN fails).
fn count_leading_valid(records: &[Record]) -> usize {
    const INF: f32 = f32::INFINITY;
    let bound = [
        f32x8::new([1.0, 1.0, INF, 1.0, 1.0, INF, 1.0, 1.0]),
        f32x8::new([INF, 1.0, 1.0, INF, 1.0, 1.0, INF, 1.0]),
        f32x8::new([1.0, INF, 1.0, 1.0, INF, 1.0, 1.0, INF]),
    ];
    let floats: &[f32] = bytemuck::cast_slice(records);
    let valid = |c: &[f32]| {
        (0..3).all(|k| {
            let v = f32x8::new(c[8 * k..8 * k + 8].try_into().unwrap());
            (v.simd_ge(f32x8::ZERO) & v.simd_lt(bound[k])).to_bitmask() == 0xff
        })
    };
    8 * floats.chunks_exact(24).take_while(|c| valid(c)).count()
}

/// Breadth-first subdivision. Each node's share of the accepted flux is left in its `mass`
/// field: a fraction of the total, not the flux itself, because a sum of f32 fluxes can
/// exceed `f32::MAX` (the `guide` fuzz target found leaves whose flux rounded to zero
/// beside an infinite sibling, and so pdf 0).
fn subdivide(
    records: &mut [Record],
    params: &GuideParams,
    nodes: &mut [GuideNode],
    stats: &mut BuildStats,
    split: SplitFn,
) {
    let max_depth = params.max_depth.min(MAX_DEPTH);
    let min_share = f64::from(sanitize(params.min_flux_fraction, 0.0, 1.0));
    nodes[0].mass = 1.0;
    let mut len = 1usize;
    let mut next = 0usize;
    while next < len {
        let n = nodes[next];
        let wants = n.count >= params.min_records && f64::from(n.mass) >= min_share;
        if wants && u32::from(n.depth) >= max_depth {
            stats.depth_refusals += 1;
        } else if wants && len + 4 > nodes.len() {
            stats.capacity_refusals += 1;
        } else if wants {
            split(records, nodes, next, len, stats.total_flux);
            len += 4;
        }
        next += 1;
    }
    stats.nodes = len as u32;
    for n in &nodes[..len] {
        stats.leaves += u32::from(n.is_leaf());
        stats.depth = stats.depth.max(n.depth());
    }
}

/// Splits node `i` into four children at `first`. The node's records are sorted by their
/// cells ([`cells::sort`]), so each child's records are the next sorted range: three binary
/// searches find them, and each child's `mass` is its share of `total_flux`.
fn split(records: &mut [Record], nodes: &mut [GuideNode], i: usize, first: usize, total_flux: f64) {
    let n = nodes[i];
    let start = n.first as usize;
    let range = &records[start..start + n.count as usize];
    let depth = u32::from(n.depth);
    let ends: [usize; 4] = core::array::from_fn(|q| {
        if q == 3 {
            range.len()
        } else {
            range.partition_point(|r| cells::quadrant(r, depth) <= q)
        }
    });
    let mut lo = 0;
    for (q, &hi) in ends.iter().enumerate() {
        let flux = flux_sum(&range[lo..hi]);
        nodes[first + q] = child(&n, q, start + lo, hi - lo, flux / total_flux);
        lo = hi;
    }
    nodes[i].child = first as u16;
}

/// The f64 sum of the records' fluxes (four running sums: a quarter of the dependency chain).
fn flux_sum(records: &[Record]) -> f64 {
    let mut s = [0.0f64; 4];
    let mut quads = records.chunks_exact(4);
    for c in &mut quads {
        for (s, r) in s.iter_mut().zip(c) {
            *s += f64::from(r.flux);
        }
    }
    let tail: f64 = quads.remainder().iter().map(|r| f64::from(r.flux)).sum();
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// Child `q` of node `n` holding the `count` records from `first`, with `share` of the
/// accepted flux in its `mass`.
fn child(n: &GuideNode, q: usize, first: usize, count: usize, share: f64) -> GuideNode {
    let h = n.size * 0.5;
    let (hx, hy) = ((q & 1) as f32, (q >> 1) as f32);
    GuideNode {
        origin: [n.origin[0] + h * hx, n.origin[1] + h * hy],
        size: h,
        mass: share as f32,
        first: first as u32,
        count: count as u32,
        child: 0,
        depth: n.depth + 1,
        ..GuideNode::default()
    }
}

/// Floors the leaves at `floor` times their area, sums masses bottom-up and normalizes.
/// Children always follow their parent in breadth-first order, so one reverse pass sums
/// every node after its children. On entry a leaf's `mass` holds its share of the accepted
/// flux (so the floor is the ambient fraction itself); with `second_moment` its share of the
/// second moment, which becomes `√(area · share)` before the floor (a uniform share stays
/// `area`; the roots sum to at most 1, the normalization restores it). Masses are stored
/// in f32 between passes (relative error ~1e-7, far below the sampling noise).
fn set_masses(nodes: &mut [GuideNode], floor: f64, second_moment: bool) {
    for i in (0..nodes.len()).rev() {
        let n = nodes[i];
        let m = match n.first_child() {
            None => {
                let area = f64::from(n.size) * f64::from(n.size);
                let share = f64::from(n.mass);
                let mass = if second_moment {
                    libm::sqrt(area * share)
                } else {
                    share
                };
                mass.max(floor * area)
            }
            Some(c) => (c..c + 4).map(|k| f64::from(nodes[k].mass)).sum(),
        };
        nodes[i].mass = m as f32;
    }
    let total = f64::from(nodes[0].mass);
    for n in nodes.iter_mut() {
        n.mass = (f64::from(n.mass) / total) as f32;
    }
    nodes[0].mass = 1.0;
}

/// Hierarchical smoothing (§2.3), the defensive mixture with the uniform density (share
/// `uniform`, [`GuideParams::uniform`]) and the warp's thresholds, top-down: when node `i`
/// is visited its mass and source rectangle are final, and it fixes its children's. The
/// thresholds split the mixed masses `uniform·area + (1 − uniform)·mass`; the smoothing
/// works on the unmixed ones, which are replaced by the mixed ones at the end (mixing is
/// linear in the masses, so children still sum to their parent).
fn smooth(nodes: &mut [GuideNode], alpha: f64, uniform: f64) {
    let mixed = |mass: f64, size: f32| {
        if uniform > 0.0 {
            (1.0 - uniform) * mass + uniform * f64::from(size) * f64::from(size)
        } else {
            mass
        }
    };
    for i in 0..nodes.len() {
        let n = nodes[i];
        let Some(c) = n.first_child() else {
            nodes[i].pdf = leaf_pdf(&n);
            continue;
        };
        let mut raw: [f64; 4] = core::array::from_fn(|q| f64::from(nodes[c + q].mass));
        let mut sum: f64 = raw.iter().sum();
        if sum <= 0.0 {
            // Only with `ambient = 0`: a node without flux spreads its (zero) mass evenly.
            // (Masses are finite and ≥ 0 here: the records were checked, the floor clamped.)
            (raw, sum) = ([0.25; 4], 1.0);
        }
        let parent = f64::from(n.mass);
        let m: [f64; 4] =
            core::array::from_fn(|q| parent * ((1.0 - alpha) * raw[q] / sum + alpha * 0.25));
        let sampled: [f64; 4] = core::array::from_fn(|q| mixed(m[q], nodes[c + q].size));
        // A ratio 0/0 (zero-mass parent, only with `ambient = 0`) becomes ½: the node is
        // unreachable by sampling.
        let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.5 };
        let px = ratio(
            sampled[0] + sampled[2],
            sampled[0] + sampled[1] + sampled[2] + sampled[3],
        );
        let py = [
            ratio(sampled[0], sampled[0] + sampled[2]),
            ratio(sampled[1], sampled[1] + sampled[3]),
        ];
        let tx = split_at(n.lo[0], n.hi[0], px);
        let ty = [
            split_at(n.lo[1], n.hi[1], py[0]),
            split_at(n.lo[1], n.hi[1], py[1]),
        ];
        let lo = |q: usize| [[n.lo[0], tx][q & 1], [n.lo[1], ty[q & 1]][q >> 1]];
        let hi = |q: usize| [[tx, n.hi[0]][q & 1], [ty[q & 1], n.hi[1]][q >> 1]];
        let empty = |q: usize| (0..2).any(|a| lo(q)[a] >= hi(q)[a]);
        if (0..4).any(|q| sampled[q] > 0.0 && empty(q)) {
            make_leaf(nodes, i);
            continue;
        }
        nodes[i].t = [tx, ty[0], ty[1]];
        nodes[i].pdf = (mixed(parent, n.size) / (f64::from(n.size) * f64::from(n.size))) as f32;
        for (q, &mass) in m.iter().enumerate() {
            let k = &mut nodes[c + q];
            k.mass = mass as f32;
            k.lo = lo(q);
            k.hi = hi(q);
        }
    }
    if uniform > 0.0 {
        for n in nodes.iter_mut().filter(|n| n.size > 0.0) {
            n.mass = mixed(f64::from(n.mass), n.size) as f32;
        }
    }
}

/// Makes interior node `i` a leaf when its source rectangle is too narrow in f32 to give
/// every child of positive mass a non-empty part (a deep, lopsided tree: found by the
/// `guide` fuzz target at depth 12, α = 0, where one f32 step near u = 0.003 had to hold two
/// children). The leaf keeps the node's mass and source rectangle, so its density is still
/// exactly that of the map as rounded; its former descendants stay in the storage but are
/// cut off (side 0, never reached from the root, skipped by [`Guide::for_each_leaf`]).
fn make_leaf(nodes: &mut [GuideNode], i: usize) {
    if let Some(c) = nodes[i].first_child() {
        for q in 0..4 {
            cut_off(nodes, c + q);
        }
    }
    let n = &mut nodes[i];
    n.child = 0;
    n.t = [0.0; 3];
    n.pdf = leaf_pdf(n);
}

/// A leaf's density on the square: the area of its source rectangle over its square's.
fn leaf_pdf(n: &GuideNode) -> f32 {
    let side = |a: usize| f64::from(n.hi[a]) - f64::from(n.lo[a]);
    let size = f64::from(n.size);
    (side(0) * side(1) / (size * size)) as f32
}

/// Cuts node `k` and its subtree off the tree (see [`collapse`]); the recursion is at most
/// [`MAX_DEPTH`] deep.
fn cut_off(nodes: &mut [GuideNode], k: usize) {
    if let Some(c) = nodes[k].first_child() {
        for q in 0..4 {
            cut_off(nodes, c + q);
        }
    }
    nodes[k] = GuideNode {
        child: 0,
        size: 0.0,
        mass: 0.0,
        pdf: 0.0,
        t: [0.0; 3],
        ..nodes[k]
    };
}

/// The threshold that gives `[lo, t)` the share `p` of `[lo, hi)`, rounded to f32 and kept
/// inside the interval. Children inherit these exact f32 values as their bounds, so the
/// source rectangles tile the square without gaps or overlaps.
///
/// A share strictly between 0 and 1 keeps both sides at least one f32 step wide while the
/// interval has room: rounding must not give a child of positive mass an empty source
/// rectangle (pdf 0: the warp would never go there, and the ambient floor would be lost).
/// Found by the `guide` fuzz target (depth 12, α = 0: a leaf of mass ~10⁻⁹ near u = 0.44).
fn split_at(lo: f32, hi: f32, p: f64) -> f32 {
    let t = f64::from(lo) + (f64::from(hi) - f64::from(lo)) * p;
    let t = (t as f32).clamp(lo, hi);
    if p > 0.0 && p < 1.0 && lo < hi {
        let (above_lo, below_hi) = (next_up(lo), next_down(hi));
        if above_lo <= below_hi {
            return t.clamp(above_lo, below_hi);
        }
    }
    t
}

/// The next f32 above `x` (finite, ≥ 0).
fn next_up(x: f32) -> f32 {
    f32::from_bits(x.to_bits() + 1)
}

/// The next f32 below `x` (finite, > 0).
fn next_down(x: f32) -> f32 {
    f32::from_bits(x.to_bits() - 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::{format, vec, vec::Vec};

    fn rec(x: f32, y: f32, flux: f32) -> Record {
        Record { u: [x, y], flux }
    }

    #[test]
    fn no_records_gives_uniform_guide() {
        let mut storage = [GuideNode::default(); 8];
        let (g, s) = build(&mut [], &GuideParams::default(), &mut storage);
        assert!(g.is_uniform());
        assert_eq!((s.nodes, s.leaves, s.accepted), (1, 1, 0));
    }

    #[test]
    fn bad_records_are_rejected_and_counted() {
        let mut r = [
            rec(0.1, 0.1, f32::NAN),
            rec(0.1, 0.1, -1.0),
            rec(0.1, 0.1, f32::INFINITY),
            rec(1.0, 0.1, 1.0),
            rec(f32::NAN, 0.1, 1.0),
            rec(0.2, 0.3, 2.0),
        ];
        let mut storage = [GuideNode::default(); 8];
        let (_, s) = build(&mut r, &GuideParams::default(), &mut storage);
        assert_eq!((s.rejected_flux, s.rejected_point, s.accepted), (3, 2, 1));
        assert_eq!(r[0], rec(0.2, 0.3, 2.0));
        assert_eq!(s.total_flux, 2.0);
    }

    #[test]
    fn leading_valid_records_are_counted_eight_at_a_time() {
        let below_one = f32::from_bits(1.0f32.to_bits() - 1);
        let good = rec(0.5, below_one, 3.0);
        let edge_ok = [
            rec(0.0, -0.0, 0.0),
            rec(below_one, 0.0, f32::MAX),
            rec(-0.0, 0.5, -0.0),
        ];
        let bad = [
            rec(0.5, 0.5, f32::NAN),
            rec(0.5, 0.5, -1.0),
            rec(0.5, 0.5, f32::INFINITY),
            rec(0.5, 0.5, f32::NEG_INFINITY),
            rec(1.0, 0.5, 1.0),
            rec(0.5, 1.0, 1.0),
            rec(-1e-30, 0.5, 1.0),
            rec(0.5, f32::NAN, 1.0),
            rec(f32::INFINITY, 0.5, 1.0),
        ];
        for n in [0, 7, 8, 9, 40] {
            for p in 0..=n {
                for (k, b) in bad.iter().enumerate() {
                    let mut r: Vec<Record> = (0..n)
                        .map(|i| if i % 5 == 1 { edge_ok[i % 3] } else { good })
                        .collect();
                    if p < n {
                        r[p] = *b;
                    }
                    let c = count_leading_valid(&r);
                    assert!(
                        c.is_multiple_of(8) && c <= p && p < c + 8 + n % 8,
                        "n {n} bad {k} at {p}: {c}"
                    );
                    let mut stats = BuildStats::default();
                    let kept = partition_valid(&mut r, &mut stats);
                    assert_eq!(kept, n - usize::from(p < n), "n {n} bad {k} at {p}");
                    assert_eq!(stats.rejected_flux + stats.rejected_point, u32::from(p < n));
                    assert!(r[..kept].iter().all(|r| r.flux >= 0.0 && r.u[0] < 1.0));
                }
            }
        }
    }

    #[test]
    fn split_rule_needs_four_records_and_one_percent_of_flux() {
        // Four records in one quadrant with 99.9% of the flux: the root splits, that
        // quadrant splits again, the dim quadrant (3 records < 4) does not.
        let mut r = [
            rec(0.1, 0.1, 1000.0),
            rec(0.2, 0.1, 1000.0),
            rec(0.1, 0.3, 1000.0),
            rec(0.3, 0.3, 1000.0),
            rec(0.9, 0.9, 1.0),
            rec(0.8, 0.9, 1.0),
            rec(0.9, 0.7, 1.0),
        ];
        let p = GuideParams {
            alpha: 0.0,
            ..GuideParams::default()
        };
        let mut storage = [GuideNode::default(); 64];
        let (g, s) = build(&mut r, &p, &mut storage);
        let root = g.nodes()[0];
        let c = root.first_child().unwrap();
        assert!(!g.nodes()[c].is_leaf(), "bright quadrant splits");
        assert!(g.nodes()[c + 3].is_leaf(), "3 records do not split");
        assert!(g.nodes()[c + 1].is_leaf() && g.nodes()[c + 2].is_leaf());
        assert_eq!(s.capacity_refusals, 0);
        // Masses sum to one at every interior node.
        for n in g.nodes() {
            if let Some(c) = n.first_child() {
                let sum: f32 = (c..c + 4).map(|k| g.nodes()[k].mass()).sum();
                assert!(
                    (sum - n.mass()).abs() <= 1e-6 * n.mass().max(1e-30),
                    "{sum} vs {}",
                    n.mass()
                );
            }
        }
    }

    #[test]
    fn a_second_moment_guide_is_the_root_of_the_second_moment() {
        // Records on a 16×16 grid: the left half's second moment 16× the right half's. The
        // flux target gives the left half 16× the right's density, the second-moment target
        // √16 = 4×; both stay normalized. The depth cap (1) leaves four leaves, one per
        // quadrant, so each leaf's density is exact.
        let records = || -> Vec<Record> {
            (0..256)
                .map(|i| {
                    let (x, y) = ((i % 16) as f32 / 16.0 + 0.03, (i / 16) as f32 / 16.0 + 0.03);
                    rec(x, y, if x < 0.5 { 16.0 } else { 1.0 })
                })
                .collect()
        };
        let density_ratio = |second_moment: bool| {
            let p = GuideParams {
                max_depth: 1,
                alpha: 0.0,
                ambient: 0.0,
                second_moment,
                ..GuideParams::default()
            };
            let mut r = records();
            let mut storage = [GuideNode::default(); 64];
            let (g, _) = build(&mut r, &p, &mut storage);
            let (mut left, mut right, mut mass) = (Vec::new(), Vec::new(), 0.0);
            g.for_each_leaf(|leaf| {
                mass += leaf.pdf * leaf.size * leaf.size;
                if leaf.origin[0] < 0.5 {
                    &mut left
                } else {
                    &mut right
                }
                .push(leaf.pdf);
            });
            assert_eq!((left.len(), right.len()), (2, 2));
            assert!((mass - 1.0).abs() < 1e-6, "{mass}");
            assert!(
                left.iter()
                    .chain(&right)
                    .all(|&p| p == left[0] || p == right[0])
            );
            left[0] / right[0]
        };
        assert!((density_ratio(false) - 16.0).abs() < 1e-4);
        assert!((density_ratio(true) - 4.0).abs() < 1e-5);
    }

    #[test]
    fn one_percent_rule_stops_dim_regions() {
        // 8 records in one quadrant but with 0.5% of the flux: no split there.
        let mut r = [rec(0.9, 0.9, 10_000.0); 12];
        for (k, x) in r.iter_mut().take(8).enumerate() {
            *x = rec(0.05 + 0.05 * k as f32, 0.1, 6.0);
        }
        let p = GuideParams {
            max_depth: 1,
            ..GuideParams::default()
        };
        let mut storage = [GuideNode::default(); 64];
        let (g, s) = build(&mut r, &p, &mut storage);
        assert_eq!(s.nodes, 5);
        assert!(
            s.depth_refusals >= 1,
            "the bright quadrant hit the depth cap"
        );
        assert!(g.nodes()[1].is_leaf());
    }

    #[test]
    fn flux_summing_past_f32_max_keeps_every_leaf_floored() {
        // Eight records of 2^127 in one corner sum past f32::MAX; a node's flux stored as
        // f32 became ∞ and its dim siblings' mass 0/∞ = 0 (found by the `guide` fuzz target).
        let mut r: [Record; 12] = core::array::from_fn(|k| {
            if k < 8 {
                rec(0.01 * k as f32, 0.01, f32::MAX / 2.0)
            } else {
                rec(0.9, 0.1 + 0.2 * k as f32 / 12.0, 1.0)
            }
        });
        let p = GuideParams {
            alpha: 0.0,
            ..GuideParams::default()
        };
        let mut storage = [GuideNode::default(); 64];
        let (g, s) = build(&mut r, &p, &mut storage);
        assert!(s.total_flux > f64::from(f32::MAX));
        assert!(s.nodes > 1);
        let mut mass = 0.0f64;
        g.for_each_leaf(|l| {
            assert!(l.pdf.is_finite() && l.pdf > 0.0, "{l:?}");
            mass += f64::from(l.pdf) * f64::from(l.size) * f64::from(l.size);
        });
        assert!((mass - 1.0).abs() < 1e-4, "{mass}");
    }

    #[test]
    fn ambient_floor_bounds_every_leaf_density() {
        let mut r: [Record; 64] = core::array::from_fn(|k| rec(0.001 * k as f32, 0.002, 1.0));
        let p = GuideParams {
            alpha: 0.0,
            ..GuideParams::default()
        };
        let mut storage = [GuideNode::default(); 256];
        let (g, _) = build(&mut r, &p, &mut storage);
        let mut min_pdf = f32::MAX;
        g.for_each_leaf(|l| min_pdf = min_pdf.min(l.pdf));
        // Floor: density ≥ ambient × mean before normalization; the normalization divides by
        // (1 + floored area share) ≤ 1 + ambient.
        assert!(
            min_pdf >= DEFAULT_AMBIENT / (1.0 + DEFAULT_AMBIENT) * 0.999,
            "{min_pdf}"
        );
    }

    #[test]
    fn smoothing_alpha_one_gives_uniform_density() {
        let mut r: [Record; 64] =
            core::array::from_fn(|k| rec(0.01 * k as f32, 0.5, 1.0 + k as f32));
        let p = GuideParams {
            alpha: 1.0,
            ..GuideParams::default()
        };
        let mut storage = [GuideNode::default(); 256];
        let (g, s) = build(&mut r, &p, &mut storage);
        assert!(s.nodes > 5);
        g.for_each_leaf(|l| assert!((l.pdf - 1.0).abs() < 1e-5, "{l:?}"));
    }

    /// The start table's oracle: each cell descends from the root while the whole cell
    /// `[cx, cx+1)/G × [cy, cy+1)/G` lies on one side of the node's thresholds.
    fn start_node_of_cell(nodes: &[GuideNode], cx: usize, cy: usize) -> usize {
        let g = START_GRID as f32;
        let side = |t: f32, lo: f32, hi: f32| {
            if t <= lo {
                Some(1)
            } else if hi <= t {
                Some(0)
            } else {
                None
            }
        };
        let (x, y) = (cx as f32, cy as f32);
        let mut i = 0;
        while let Some(c) = nodes[i].first_child() {
            let t = nodes[i].t;
            let Some(right) = side(t[0], x / g, (x + 1.0) / g) else {
                break;
            };
            let Some(upper) = side(t[1 + right], y / g, (y + 1.0) / g) else {
                break;
            };
            i = c + right + 2 * upper;
        }
        i
    }

    /// Whether the root-to-leaf path of `u` (by the warp's thresholds) passes node `k`.
    fn path_passes(nodes: &[GuideNode], u: [f32; 2], k: usize) -> bool {
        let mut i = 0;
        loop {
            if i == k {
                return true;
            }
            let Some(c) = nodes[i].first_child() else {
                return false;
            };
            let t = nodes[i].t;
            let right = u[0] >= t[0];
            let upper = u[1] >= t[1 + usize::from(right)];
            i = c + usize::from(right) + 2 * usize::from(upper);
        }
    }

    /// Disk and sky everywhere plus a tight cluster: shallow and very deep regions.
    fn shallow_and_deep_records(rng: &mut crate::testing::Pcg32) -> [Record; 900] {
        core::array::from_fn(|k| {
            if k < 700 {
                let u = [rng.next_f32(), rng.next_f32()];
                rec(u[0], u[1], crate::testing::disk_and_sky(u))
            } else {
                rec(
                    0.3 + 1e-4 * rng.next_f32(),
                    0.6 + 1e-4 * rng.next_f32(),
                    5.0,
                )
            }
        })
    }

    #[test]
    fn start_table_is_the_deepest_node_each_cell_shares() {
        let mut rng = crate::testing::Pcg32::new(21, 5);
        let mut r = shallow_and_deep_records(&mut rng);
        let p = GuideParams {
            max_depth: MAX_DEPTH,
            ..GuideParams::default()
        };
        let mut storage = [GuideNode::default(); 2048];
        let (g, s) = build(&mut r, &p, &mut storage);
        assert!(s.depth >= 12 && s.nodes > 100, "{s:?}");
        let (nodes, table) = (g.nodes(), g.start_table());
        assert_eq!(table.len(), START_GRID * START_GRID);
        let below = |v: f32| f32::from_bits(v.to_bits() - 1);
        let gf = START_GRID as f32;
        let mut deeper_than_root = 0;
        for (k, &start) in table.iter().enumerate() {
            let (cx, cy) = (k % START_GRID, k / START_GRID);
            assert_eq!(
                usize::from(start),
                start_node_of_cell(nodes, cx, cy),
                "cell {cx},{cy}"
            );
            deeper_than_root += usize::from(start != 0);
            // The cell's corners and random interior points all pass the start node.
            let (x0, y0) = (cx as f32 / gf, cy as f32 / gf);
            let (x1, y1) = (below((cx + 1) as f32 / gf), below((cy + 1) as f32 / gf));
            let mut pts = [[x0, y0], [x1, y0], [x0, y1], [x1, y1], [0.0; 2], [0.0; 2]];
            for q in &mut pts[4..] {
                *q = [x0 + rng.next_f32() / gf, y0 + rng.next_f32() / gf];
            }
            for u in pts {
                let u = [u[0].clamp(x0, x1), u[1].clamp(y0, y1)];
                assert!(
                    path_passes(nodes, u, usize::from(start)),
                    "cell {cx},{cy} point {u:?}"
                );
            }
        }
        assert!(
            deeper_than_root > START_GRID * START_GRID / 2,
            "{deeper_than_root}"
        );
    }

    #[test]
    fn shortcuts_are_passed_by_every_point_of_their_cell_part() {
        let mut rng = crate::testing::Pcg32::new(23, 7);
        let mut r = shallow_and_deep_records(&mut rng);
        let p = GuideParams {
            max_depth: MAX_DEPTH,
            ..GuideParams::default()
        };
        let mut storage = [GuideNode::default(); 2048];
        let (g, _) = build(&mut r, &p, &mut storage);
        let (nodes, table, short) = (g.nodes(), g.start_table(), g.shortcuts());
        assert_eq!(short.len(), table.len());
        let below = |v: f32| f32::from_bits(v.to_bits() - 1);
        let gf = START_GRID as f32;
        let (mut deeper, mut interior) = (0, 0);
        for (k, (&start, s)) in table.iter().zip(short).enumerate() {
            let (n, s) = (usize::from(start), s.map(usize::from));
            let Some(c) = nodes[n].first_child() else {
                assert_eq!(s, [n; 4], "cell {k}");
                continue;
            };
            interior += 1;
            let (cx, cy) = (k % START_GRID, k / START_GRID);
            let (x0, y0) = (cx as f32 / gf, cy as f32 / gf);
            let (x1, y1) = (below((cx + 1) as f32 / gf), below((cy + 1) as f32 / gf));
            // Corners, random points, and the start node's thresholds and the floats just
            // below them, where they fall inside the cell.
            let t = nodes[n].t;
            let mut xs = alloc::vec![x0, x1, t[0], below(t[0])];
            let mut ys = alloc::vec![y0, y1, t[1], below(t[1]), t[2], below(t[2])];
            for _ in 0..4 {
                xs.push(x0 + rng.next_f32() / gf);
                ys.push(y0 + rng.next_f32() / gf);
            }
            for &x in &xs {
                for &y in &ys {
                    if !(x0..=x1).contains(&x) || !(y0..=y1).contains(&y) {
                        continue;
                    }
                    let right = x >= t[0];
                    let upper = y >= t[1 + usize::from(right)];
                    let q = usize::from(right) + 2 * usize::from(upper);
                    assert!(path_passes(nodes, [x, y], s[q]), "cell {k} point {x},{y}");
                    assert!(path_passes(nodes, [x, y], c + q));
                }
            }
            deeper += s.iter().enumerate().filter(|&(q, &s)| s != c + q).count();
        }
        // The shortcuts skip levels in many cells (else they would be worthless).
        assert!(
            interior > 100 && deeper > interior / 2,
            "{interior} {deeper}"
        );
    }

    #[test]
    fn warp_links_step_to_the_child_or_stay_in_the_leaf() {
        let mut rng = crate::testing::Pcg32::new(9, 4);
        let mut r: [Record; 600] = core::array::from_fn(|_| {
            let u = [rng.next_f32(), rng.next_f32()];
            rec(u[0], u[1], crate::testing::disk_and_sky(u))
        });
        let mut storage = [GuideNode::default(); 1024];
        let (g, s) = build(&mut r, &GuideParams::default(), &mut storage);
        assert!(s.nodes > 20);
        let nodes = g.nodes();
        for (i, n) in nodes.iter().enumerate() {
            for q in 0..4u32 {
                let next = n.link.wrapping_add(q) as usize;
                match n.first_child() {
                    Some(c) => {
                        assert_eq!(next, c + q as usize, "node {i}");
                        assert_eq!(n.inner_kids >> q & 1, u8::from(!nodes[next].is_leaf()));
                    }
                    // A leaf's thresholds are 0, so every point takes quadrant 3.
                    None => {
                        assert_eq!(n.t, [0.0; 3], "leaf {i}");
                        assert_eq!(n.inner_kids, 0, "leaf {i}");
                        assert_eq!(q == 3, next == i, "leaf {i}");
                    }
                }
            }
        }
        let mut one = [GuideNode::default(); 1];
        let root = Guide::uniform(&mut one).nodes()[0];
        assert_eq!((root.link.wrapping_add(3), root.inner_kids), (0, 0));
        // The warp reads a leaf's eight placement fields as the node's first 32 bytes.
        let n = &nodes[nodes.len() - 1];
        let row = [n.lo, n.hi, n.origin, [n.size, n.pdf]].concat();
        assert_eq!(n.leaf_row().as_slice(), row.as_slice());
        assert_eq!(core::mem::align_of::<GuideNode>(), 64);
    }

    #[test]
    fn start_table_needs_room_after_the_tree() {
        let mut rng = crate::testing::Pcg32::new(3, 8);
        let recs: [Record; 256] =
            core::array::from_fn(|_| rec(rng.next_f32(), rng.next_f32(), 1.0));
        let mut storage = [GuideNode::default(); 1024];
        let n = {
            let (g, s) = build(&mut recs.clone(), &GuideParams::default(), &mut storage);
            assert_eq!(g.start_table().len(), START_GRID * START_GRID);
            s.nodes as usize
        };
        // Room for the tree but not for the table: the same tree, no table.
        let (g, s) = build(
            &mut recs.clone(),
            &GuideParams::default(),
            &mut storage[..n + START_TABLE_NODES - 1],
        );
        assert_eq!((s.nodes as usize, s.capacity_refusals), (n, 0));
        assert!(g.start_table().is_empty());
        let (g, _) = build(
            &mut recs.clone(),
            &GuideParams::default(),
            &mut storage[..n + START_TABLE_NODES],
        );
        assert_eq!(g.start_table().len(), START_GRID * START_GRID);
        assert!(Guide::uniform(&mut storage).start_table().is_empty());
    }

    /// Record sets for the comparison with [`reference::build`]: `kind` picks the layout.
    /// Fluxes are multiples of 2⁻⁶ below 2¹⁶, so every f64 flux sum is exact and the two
    /// builds' different summation orders cannot round differently.
    fn comparison_records(kind: usize, n: usize, rng: &mut crate::testing::Pcg32) -> Vec<Record> {
        let below_one = f32::from_bits(1.0f32.to_bits() - 1);
        let flux = |rng: &mut crate::testing::Pcg32, bright: bool| {
            let f = (rng.next_u32() % 4096) as f32 / 64.0;
            if bright { f * 16.0 } else { f }
        };
        (0..n)
            .map(|k| {
                let bright = k % 5 == 0;
                let u = match kind {
                    // Uniform.
                    0 => [rng.next_f32(), rng.next_f32()],
                    // Lobes: a tight cluster (max depth) and a wider one over uniform.
                    1 => match k % 4 {
                        0 => [0.3 + 1e-4 * rng.next_f32(), 0.6 + 1e-4 * rng.next_f32()],
                        1 => [0.7 + 0.05 * rng.next_f32(), 0.2 + 0.05 * rng.next_f32()],
                        _ => [rng.next_f32(), rng.next_f32()],
                    },
                    // All records at one point.
                    2 => [0.4, 0.55],
                    // The square's edges: 0, 1 − ε, dyadic midpoints and the floats beside them.
                    _ => {
                        let m = (rng.next_u32() % 64) as f32 / 64.0;
                        let v = |rng: &mut crate::testing::Pcg32| match rng.next_u32() % 5 {
                            0 => 0.0,
                            1 => below_one,
                            2 => m,
                            3 if m > 0.0 => f32::from_bits(m.to_bits() - 1),
                            _ => rng.next_f32(),
                        };
                        [v(rng), v(rng)]
                    }
                };
                let mut r = rec(u[0], u[1], flux(rng, bright));
                // Invalid records, rejected by both builds alike.
                match rng.next_u32() % 64 {
                    0 => r.flux = f32::NAN,
                    1 => r.flux = -1.0,
                    2 => r.flux = f32::INFINITY,
                    3 => r.u[0] = 1.0,
                    4 => r.u[1] = f32::NAN,
                    5 => r.u[0] = -0.25,
                    _ => {}
                }
                r
            })
            .collect()
    }

    /// A node without its build-time record offset (the two builds order records differently).
    fn without_first(n: &GuideNode) -> GuideNode {
        GuideNode { first: 0, ..*n }
    }

    /// The bake's split rule: 64-record splits, α 0.1, ambient floor 0.02.
    fn bake_params() -> GuideParams {
        GuideParams {
            min_records: 64,
            alpha: 0.1,
            ambient: 0.02,
            ..GuideParams::default()
        }
    }

    /// Asserts two builds' guides identical: every node bit for bit (but the record offset),
    /// the start table, shortcuts and stats (`what` names the case).
    fn assert_same_guides(
        (ga, ta): &(Guide<'_>, BuildStats),
        (gb, tb): &(Guide<'_>, BuildStats),
        what: &dyn Fn() -> alloc::string::String,
    ) {
        assert_eq!(ta, tb, "{}", what());
        assert_eq!(ga.nodes().len(), gb.nodes().len(), "{}", what());
        for (k, (x, y)) in ga.nodes().iter().zip(gb.nodes()).enumerate() {
            let (x, y) = (without_first(x), without_first(y));
            assert_eq!(
                bytemuck::bytes_of(&x),
                bytemuck::bytes_of(&y),
                "node {k}: {x:?} vs {y:?}; {}",
                what()
            );
        }
        assert_eq!(ga.start_table(), gb.start_table(), "{}", what());
        assert_eq!(ga.shortcuts(), gb.shortcuts(), "{}", what());
    }

    /// Builds `records` both ways into `capacity` nodes and asserts identical guides
    /// ([`assert_same_guides`]) and the same records, accepted ones first.
    fn assert_same_as_reference(records: &[Record], params: &GuideParams, capacity: usize) {
        let (mut a, mut b) = (records.to_vec(), records.to_vec());
        let mut sa = vec![GuideNode::default(); capacity];
        let mut sb = vec![GuideNode::default(); capacity];
        let built = build(&mut a, params, &mut sa);
        let oracle = reference::build(&mut b, params, &mut sb);
        let what = || format!("{} records, {params:?}, capacity {capacity}", records.len());
        assert_same_guides(&built, &oracle, &what);
        // The same records, accepted ones first.
        let acc = built.1.accepted as usize;
        let key = |r: &Record| [r.u[0].to_bits(), r.u[1].to_bits(), r.flux.to_bits()];
        for r in [&mut a[..acc], &mut b[..acc]] {
            r.sort_by_key(key);
        }
        for r in [&mut a[acc..], &mut b[acc..]] {
            r.sort_by_key(key);
        }
        assert!(a.iter().map(key).eq(b.iter().map(key)), "{}", what());
    }

    #[test]
    fn sorted_build_equals_the_partitioning_build() {
        let mut rng = crate::testing::Pcg32::new(41, 9);
        let params = [
            GuideParams::default(),
            bake_params(),
            GuideParams {
                max_depth: MAX_DEPTH,
                min_records: 1,
                ..GuideParams::default()
            },
            GuideParams {
                max_depth: 0,
                ..GuideParams::default()
            },
            GuideParams {
                max_depth: 5,
                min_records: 0,
                min_flux_fraction: 0.0,
                ..GuideParams::default()
            },
            GuideParams {
                alpha: 0.0,
                ambient: 0.0,
                ..GuideParams::default()
            },
        ];
        let mut sets = 0;
        for n in [
            0, 1, 3, 4, 5, 31, 32, 33, 64, 100, 257, 1000, 1500, 4096, 9000,
        ] {
            for kind in 0..4 {
                let records = comparison_records(kind, n, &mut rng);
                for p in &params {
                    // Zero-flux records only: the uniform guide both ways.
                    let zero: Vec<Record> =
                        records.iter().map(|r| Record { flux: 0.0, ..*r }).collect();
                    assert_same_as_reference(&zero, p, 64);
                    for capacity in [1, 7, 64, 4096] {
                        assert_same_as_reference(&records, p, capacity);
                        sets += 1;
                    }
                }
            }
        }
        assert!(sets > 1000, "{sets}");
    }

    #[test]
    fn room_lent_to_the_sort_gives_the_same_tree() {
        // More records than the bake's 4 096 nodes hold as scratch: without room the sort
        // permutes in place; with `build_in`'s room it scatters, and the tree is the same.
        let mut rng = crate::testing::Pcg32::new(47, 3);
        let params = bake_params();
        for kind in 0..4 {
            let n = 30_000;
            assert!(sort_room(n) > 4096);
            let records = comparison_records(kind, n, &mut rng);
            let (mut a, mut b) = (records.clone(), records);
            let (mut sa, mut sb) = (
                vec![GuideNode::default(); 4096],
                vec![GuideNode::default(); 4096],
            );
            let poison = GuideNode {
                mass: f32::NAN,
                ..GuideNode::default()
            };
            let mut room = vec![poison; sort_room(n)];
            let in_place = build(&mut a, &params, &mut sa);
            let scattered = build_in(&mut b, &params, &mut sb, &mut room);
            assert!(in_place.1.nodes > 1, "kind {kind}: {:?}", in_place.1);
            assert_same_guides(&in_place, &scattered, &|| format!("kind {kind}"));
            // The sort scattered through the room (a cell left unsplit keeps any order).
            assert!(
                room.iter().any(|r| !r.mass.is_nan()),
                "kind {kind}: room unused"
            );
        }
        // Room too small for the accepted records (about 9 in 10): the sort runs in place
        // and leaves it alone.
        let mut records = comparison_records(1, 30_000, &mut rng);
        let mut room = vec![GuideNode::default(); sort_room(20_000)];
        let before = room.clone();
        let mut storage = vec![GuideNode::default(); 4096];
        let (g, _) = build_in(&mut records, &params, &mut storage, &mut room);
        assert!(g.nodes().len() > 1);
        assert!(
            room.iter()
                .zip(&before)
                .all(|(x, y)| bytemuck::bytes_of(x) == bytemuck::bytes_of(y))
        );
    }

    #[test]
    fn sorted_build_matches_the_partitioning_build_on_continuous_fluxes() {
        // Fluxes over ten decades (L / p with a guide's p): the f64 sums are not exact, and
        // the two summation orders may round a node's f32 share one step apart. The trees
        // must still be the same and every node within a relative 1e-6.
        let mut rng = crate::testing::Pcg32::new(43, 2);
        let mut bitwise = 0;
        let mut total = 0;
        for n in [100, 1000, 4096, 16_384] {
            for _ in 0..8 {
                let records: Vec<Record> = (0..n)
                    .map(|_| {
                        let u = [rng.next_f32(), rng.next_f32()];
                        let e = 10f32.powf(10.0 * rng.next_f32() - 5.0);
                        rec(u[0], u[1], e * crate::testing::disk_and_sky(u))
                    })
                    .collect();
                let p = GuideParams::default();
                let (mut a, mut b) = (records.clone(), records.clone());
                let mut sa = vec![GuideNode::default(); 4096];
                let mut sb = vec![GuideNode::default(); 4096];
                let (ga, ta) = build(&mut a, &p, &mut sa);
                let (gb, tb) = reference::build(&mut b, &p, &mut sb);
                assert_eq!(
                    (ta.nodes, ta.leaves, ta.depth),
                    (tb.nodes, tb.leaves, tb.depth)
                );
                let close = |x: f32, y: f32| (x - y).abs() <= 1e-6 * x.abs().max(y.abs());
                for (x, y) in ga.nodes().iter().zip(gb.nodes()) {
                    assert_eq!((x.child, x.count, x.depth), (y.child, y.count, y.depth));
                    assert!(close(x.mass, y.mass) && close(x.pdf, y.pdf), "{x:?} {y:?}");
                    for k in 0..3 {
                        assert!(close(x.t[k], y.t[k]), "{x:?} {y:?}");
                    }
                    bitwise += usize::from(
                        bytemuck::bytes_of(&without_first(x))
                            == bytemuck::bytes_of(&without_first(y)),
                    );
                    total += 1;
                }
            }
        }
        // Most nodes agree bit for bit even so.
        assert!(bitwise * 10 >= total * 9, "{bitwise} of {total}");
    }

    #[test]
    fn full_capacity_keeps_complete_levels() {
        let mut rng = crate::testing::Pcg32::new(3, 4);
        let mut r: [Record; 512] =
            core::array::from_fn(|_| rec(rng.next_f32(), rng.next_f32(), 1.0));
        let mut storage = [GuideNode::default(); 7]; // room for the root and one split only
        let (g, s) = build(&mut r, &GuideParams::default(), &mut storage);
        assert_eq!(s.nodes, 5);
        assert_eq!(s.capacity_refusals, 4, "all four children wanted to split");
        assert_eq!(g.nodes().len(), 5);
        let mut total = 0.0;
        g.for_each_leaf(|l| total += l.pdf * l.size * l.size);
        assert!((total - 1.0).abs() < 1e-5);
    }
}
