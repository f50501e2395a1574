//! `cluster`: texel clustering (paper §2.1).
//!
//! Silvennoinen & Sloan, *Ray Guiding for Production Lightmap Baking*, §2.1: the texels that
//! share one learned guide are found by splitting the texel set top-down on the longest axis
//! of its bounds until a cluster holds at most 64 texels and its normals lie within 60° of
//! their mean. Every cluster then learns one directional guide (paper §2.2).
//!
//! [`build_clusters`] works on caller-provided buffers, as a memory-mapped texel file hands
//! them over (`&[[f32; 3]]` positions and normals, zero-copy), and writes a permutation of
//! texel indices plus one [`ClusterRange`] per cluster (a range of that permutation). It never
//! allocates; its work stack lives on the call stack (64 entries suffice, see below).
//!
//! # Splitting rule (our reading of the paper, and the cases it leaves open)
//! A node is a leaf when it holds one texel, or when it holds at most
//! [`ClusterParams::max_texels`] texels **and** every unit normal n̂ᵢ satisfies
//! n̂ᵢ · m̂ ≥ cos([`ClusterParams::max_normal_angle_deg`]), m̂ the normalised sum of the unit
//! normals. If Σ n̂ᵢ is shorter than 10⁻⁶·count (normals cancel out) the cone test fails.
//! Otherwise the node is split, in the first of these ways that puts texels on both sides:
//! 1. at the midpoint of the longest axis of the position bounds (the paper's rule);
//! 2. when all positions are equal (or the midpoint cannot separate two adjacent floats): at
//!    the midpoint of the longest axis of the *unit normals'* bounds — so coincident texels
//!    with diverse normals (the two sides of a thin wall, a crease baked to one point) are
//!    separated by direction;
//! 3. otherwise (identical positions and normals, more than `max_texels` of them): in half by
//!    count, in the current permutation order.
//!
//! With [`ClusterParams::normal_split`] (default on) a node that already satisfies the count
//! limit and fails *only* the cone is split by normals first (2, then 1, then 3): a spatial cut
//! does not aim at the normal discontinuity and fragments the region around a crease (a box
//! corner with a 30° cone: 24 clusters with it, 171 without, `tests/cluster.rs`). This is our
//! reading of "split on the longest axis of the bounds" for the normal criterion; the paper
//! does not spell it out. Turn it off for the purely spatial rule.
//!
//! The child with fewer texels is processed first and the larger one is pushed, so the stack
//! never holds more than log₂(n) + 1 entries (≤ 33 for n < 2³²). Clusters are reported in
//! increasing permutation order. The result depends only on the input (it is deterministic).
//!
//! Note on the 60° cone: it bounds the angle to the *mean*, so two faces meeting at 90° (mean
//! 45° from each) or three faces of a box corner (54.7° from their mean) may share a cluster
//! near their common edge; faces at more than 120° (e.g. opposite box faces) never do.
//!
//! # Input requirements (checked; a violation is a [`ClusterError`], not a panic)
//! Positions must be finite. Normals must be finite and non-zero; they need not be unit length
//! (they are normalised here). Bakers filter invalid texels out before clustering.

use bytemuck::{Pod, Zeroable};

/// Default [`ClusterParams::max_texels`] (paper §2.1).
pub const DEFAULT_MAX_TEXELS: u32 = 64;
/// Default [`ClusterParams::max_normal_angle_deg`] (paper §2.1).
pub const DEFAULT_MAX_NORMAL_ANGLE_DEG: f32 = 60.0;

/// Depth of the split stack: enough for any input of fewer than 2³² texels.
const STACK: usize = 64;

/// Limits a leaf cluster must respect.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterParams {
    /// At most this many texels per cluster (≥ 1).
    pub max_texels: u32,
    /// Every normal lies within this angle of the cluster's mean normal, in degrees
    /// (finite, in [0, 180]).
    pub max_normal_angle_deg: f32,
    /// When a node already holds at most `max_texels` texels and fails only the normal cone,
    /// split it at the midpoint of its unit normals' bounds first (positions second) instead
    /// of spatially. See the module docs.
    pub normal_split: bool,
}

impl Default for ClusterParams {
    fn default() -> Self {
        ClusterParams {
            max_texels: DEFAULT_MAX_TEXELS,
            max_normal_angle_deg: DEFAULT_MAX_NORMAL_ANGLE_DEG,
            normal_split: true,
        }
    }
}

/// One cluster: the texels `permutation[start..end]`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct ClusterRange {
    /// First index into the permutation.
    pub start: u32,
    /// One past the last index into the permutation.
    pub end: u32,
}

impl ClusterRange {
    /// Number of texels in the cluster.
    pub fn len(&self) -> usize {
        (self.end - self.start) as usize
    }

    /// Whether the cluster is empty (never true for clusters [`build_clusters`] writes).
    pub fn is_empty(&self) -> bool {
        self.end == self.start
    }
}

/// Why [`build_clusters`] refused its input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ClusterError {
    /// `positions` and `normals` differ in length.
    LengthMismatch {
        /// Number of positions.
        positions: usize,
        /// Number of normals.
        normals: usize,
    },
    /// `permutation` is not exactly as long as `positions`.
    PermutationLength {
        /// Required length (the number of texels).
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// More clusters were needed than `ranges` holds (`ranges.len() >= positions.len()`
    /// always suffices). The permutation is then a valid permutation but the clustering is
    /// incomplete.
    RangesFull {
        /// Length of `ranges`.
        capacity: usize,
    },
    /// More than `u32::MAX` texels.
    TooManyTexels(usize),
    /// The position of texel `index` has a NaN or infinite coordinate.
    NonFinitePosition {
        /// Texel index.
        index: usize,
    },
    /// The normal of texel `index` is zero or not finite.
    InvalidNormal {
        /// Texel index.
        index: usize,
    },
    /// `max_texels` is 0, or the angle is not finite or outside [0, 180].
    InvalidParams,
}

impl core::fmt::Display for ClusterError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ClusterError::LengthMismatch { positions, normals } => {
                write!(f, "{positions} texel positions but {normals} normals")
            }
            ClusterError::PermutationLength { expected, got } => {
                write!(
                    f,
                    "permutation buffer holds {got} entries, {expected} texels need one each"
                )
            }
            ClusterError::RangesFull { capacity } => {
                write!(
                    f,
                    "more than {capacity} clusters needed: cluster range buffer is full"
                )
            }
            ClusterError::TooManyTexels(n) => write!(f, "{n} texels: at most 2^32 - 1 supported"),
            ClusterError::NonFinitePosition { index } => {
                write!(f, "texel {index} has a non-finite position")
            }
            ClusterError::InvalidNormal { index } => {
                write!(f, "texel {index} has a zero or non-finite normal")
            }
            ClusterError::InvalidParams => write!(
                f,
                "cluster parameters invalid: max_texels must be >= 1, angle finite in [0, 180]"
            ),
        }
    }
}

impl core::error::Error for ClusterError {}

/// Clusters texels (paper §2.1, rule in the module docs).
///
/// Writes a permutation of `0..n` into `permutation` (length exactly n) and the clusters, in
/// increasing order of `start`, into the front of `ranges`; returns the number of clusters.
/// Cluster `c` holds the texels `permutation[ranges[c].start..ranges[c].end]`.
///
/// # Errors
/// See [`ClusterError`]: mismatched lengths, invalid parameters, a non-finite position, a zero
/// or non-finite normal, or `ranges` too short.
pub fn build_clusters(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    params: &ClusterParams,
    permutation: &mut [u32],
    ranges: &mut [ClusterRange],
) -> Result<usize, ClusterError> {
    let n = positions.len();
    validate(positions, normals, params, permutation)?;
    for (i, p) in permutation.iter_mut().enumerate() {
        *p = i as u32;
    }
    if n == 0 {
        return Ok(0);
    }
    let cos_max = libm::cosf(params.max_normal_angle_deg.to_radians());
    let leaf = |idx: &[u32]| {
        idx.len() == 1
            || (idx.len() <= params.max_texels as usize && cone_within(normals, idx, cos_max))
    };
    let mut stack = [(0u32, 0u32); STACK];
    let mut depth = 0;
    let mut count = 0;
    let (mut start, mut end) = (0u32, n as u32);
    loop {
        let idx = &mut permutation[start as usize..end as usize];
        if leaf(idx) {
            let slot = ranges
                .get_mut(count)
                .ok_or(ClusterError::RangesFull { capacity: count })?;
            *slot = ClusterRange { start, end };
            count += 1;
            if depth == 0 {
                break;
            }
            depth -= 1;
            (start, end) = stack[depth];
            continue;
        }
        let by_normal_first = params.normal_split && idx.len() <= params.max_texels as usize;
        let mid = start + split(positions, normals, idx, by_normal_first);
        let (small, large) = if mid - start <= end - mid {
            ((start, mid), (mid, end))
        } else {
            ((mid, end), (start, mid))
        };
        debug_assert!(
            depth < STACK,
            "split stack overflow: smaller-first bounds it by log2(n)"
        );
        stack[depth] = large;
        depth += 1;
        (start, end) = small;
    }
    ranges[..count].sort_unstable_by_key(|r| r.start);
    Ok(count)
}

fn validate(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    params: &ClusterParams,
    permutation: &[u32],
) -> Result<(), ClusterError> {
    let n = positions.len();
    if normals.len() != n {
        return Err(ClusterError::LengthMismatch {
            positions: n,
            normals: normals.len(),
        });
    }
    if permutation.len() != n {
        return Err(ClusterError::PermutationLength {
            expected: n,
            got: permutation.len(),
        });
    }
    if n > u32::MAX as usize {
        return Err(ClusterError::TooManyTexels(n));
    }
    let angle = params.max_normal_angle_deg;
    if params.max_texels == 0 || !angle.is_finite() || !(0.0..=180.0).contains(&angle) {
        return Err(ClusterError::InvalidParams);
    }
    if let Some(index) = positions
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(ClusterError::NonFinitePosition { index });
    }
    let bad_normal = |v: &[f32; 3]| {
        let l2 = dot(*v, *v);
        !(l2.is_finite() && l2 > 0.0 && v.iter().all(|c| c.is_finite()))
    };
    if let Some(index) = normals.iter().position(bad_normal) {
        return Err(ClusterError::InvalidNormal { index });
    }
    Ok(())
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `v / |v|` (v is finite and non-zero: validated).
fn unit(v: [f32; 3]) -> [f32; 3] {
    let inv = 1.0 / libm::sqrtf(dot(v, v));
    [v[0] * inv, v[1] * inv, v[2] * inv]
}

/// Whether every unit normal of `idx` lies within the cone of half-angle acos(`cos_max`)
/// around their normalised mean.
fn cone_within(normals: &[[f32; 3]], idx: &[u32], cos_max: f32) -> bool {
    let mut sum = [0.0f32; 3];
    for &i in idx {
        let u = unit(normals[i as usize]);
        for c in 0..3 {
            sum[c] += u[c];
        }
    }
    let len = libm::sqrtf(dot(sum, sum));
    if len <= 1e-6 * idx.len() as f32 {
        return false;
    }
    let mean = [sum[0] / len, sum[1] / len, sum[2] / len];
    idx.iter()
        .all(|&i| dot(unit(normals[i as usize]), mean) >= cos_max)
}

/// Bounds of `key(i)` over `idx`.
fn bounds(idx: &[u32], key: impl Fn(u32) -> [f32; 3]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for &i in idx {
        let v = key(i);
        for c in 0..3 {
            lo[c] = lo[c].min(v[c]);
            hi[c] = hi[c].max(v[c]);
        }
    }
    (lo, hi)
}

/// Partitions `idx` so texels with `key(i)[axis] < midpoint` of the longest axis come first;
/// returns how many, or 0 if the midpoint does not separate them.
fn midpoint_partition(idx: &mut [u32], key: impl Fn(u32) -> [f32; 3]) -> usize {
    let (lo, hi) = bounds(idx, &key);
    let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] {
        0
    } else if ext[1] >= ext[2] {
        1
    } else {
        2
    };
    if ext[axis] <= 0.0 {
        return 0;
    }
    let mid = lo[axis] + 0.5 * ext[axis];
    let mut left = 0;
    for j in 0..idx.len() {
        if key(idx[j])[axis] < mid {
            idx.swap(left, j);
            left += 1;
        }
    }
    if left == idx.len() { 0 } else { left }
}

/// Splits a node that is not a leaf (≥ 2 texels); returns the size of the first part, in
/// 1..len.
fn split(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    idx: &mut [u32],
    by_normal_first: bool,
) -> u32 {
    let by_position = |idx: &mut [u32]| midpoint_partition(idx, |i| positions[i as usize]);
    let by_normal = |idx: &mut [u32]| midpoint_partition(idx, |i| unit(normals[i as usize]));
    let first = if by_normal_first {
        by_normal(idx)
    } else {
        by_position(idx)
    };
    if first > 0 {
        return first as u32;
    }
    let second = if by_normal_first {
        by_position(idx)
    } else {
        by_normal(idx)
    };
    if second > 0 {
        return second as u32;
    }
    (idx.len() / 2) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(p: &[[f32; 3]], n: &[[f32; 3]], params: &ClusterParams) -> ([u32; 256], usize) {
        let mut perm = [0u32; 256];
        let mut ranges = [ClusterRange::default(); 256];
        let c = build_clusters(p, n, params, &mut perm[..p.len()], &mut ranges).unwrap();
        (perm, c)
    }

    #[test]
    fn coincident_texels_split_by_normal() {
        // 6 axis directions × 10 texels, all at the origin.
        let dirs = [
            [1., 0., 0.],
            [-1., 0., 0.],
            [0., 1., 0.],
            [0., -1., 0.],
            [0., 0., 1.],
            [0., 0., -1.],
        ];
        let normals: [[f32; 3]; 60] = core::array::from_fn(|i| dirs[i % 6]);
        let positions = [[0.0f32; 3]; 60];
        let mut perm = [0u32; 60];
        let mut ranges = [ClusterRange::default(); 60];
        let count = build_clusters(
            &positions,
            &normals,
            &ClusterParams::default(),
            &mut perm,
            &mut ranges,
        )
        .unwrap();
        for r in &ranges[..count] {
            let cos = libm::cosf(60f32.to_radians());
            assert!(cone_within(
                &normals,
                &perm[r.start as usize..r.end as usize],
                cos
            ));
        }
        assert!(
            count >= 3,
            "opposite directions must be separated: {count} clusters"
        );
    }

    #[test]
    fn identical_texels_split_by_count() {
        let p = [[1.0f32, 2.0, 3.0]; 200];
        let n = [[0.0f32, 0.0, 2.0]; 200];
        let (_, count) = run(&p, &n, &ClusterParams::default());
        assert_eq!(count, 4, "200 identical texels: 4 clusters of at most 64");
    }

    #[test]
    fn rejects_bad_input_with_the_offending_index() {
        let mut perm = [0u32; 3];
        let mut ranges = [ClusterRange::default(); 3];
        let p = [[0.0f32; 3], [1.0, f32::NAN, 0.0], [0.0; 3]];
        let n = [[0.0f32, 0.0, 1.0]; 3];
        let d = ClusterParams::default();
        assert_eq!(
            build_clusters(&p, &n, &d, &mut perm, &mut ranges),
            Err(ClusterError::NonFinitePosition { index: 1 })
        );
        let p = [[0.0f32; 3]; 3];
        let n0 = [[0.0f32, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0; 3]];
        assert_eq!(
            build_clusters(&p, &n0, &d, &mut perm, &mut ranges),
            Err(ClusterError::InvalidNormal { index: 2 })
        );
        let ninf = [
            [0.0f32, 0.0, 1.0],
            [f32::INFINITY, 0.0, 1.0],
            [0.0, 0.0, 1.0],
        ];
        assert_eq!(
            build_clusters(&p, &ninf, &d, &mut perm, &mut ranges),
            Err(ClusterError::InvalidNormal { index: 1 })
        );
        assert_eq!(
            build_clusters(&p, &n[..2], &d, &mut perm, &mut ranges),
            Err(ClusterError::LengthMismatch {
                positions: 3,
                normals: 2
            })
        );
        assert_eq!(
            build_clusters(&p, &n, &d, &mut perm[..2], &mut ranges),
            Err(ClusterError::PermutationLength {
                expected: 3,
                got: 2
            })
        );
        let bad = ClusterParams { max_texels: 0, ..d };
        assert_eq!(
            build_clusters(&p, &n, &bad, &mut perm, &mut ranges),
            Err(ClusterError::InvalidParams)
        );
        let bad = ClusterParams {
            max_normal_angle_deg: f32::NAN,
            ..d
        };
        assert_eq!(
            build_clusters(&p, &n, &bad, &mut perm, &mut ranges),
            Err(ClusterError::InvalidParams)
        );
        let one = ClusterParams { max_texels: 1, ..d };
        assert_eq!(
            build_clusters(&p, &n, &one, &mut perm, &mut ranges[..2]),
            Err(ClusterError::RangesFull { capacity: 2 })
        );
        assert_eq!(build_clusters(&[], &[], &d, &mut [], &mut []), Ok(0));
    }

    #[test]
    fn zero_angle_terminates_with_singletons_where_normals_differ() {
        let p: [[f32; 3]; 16] = core::array::from_fn(|i| [i as f32, 0.0, 0.0]);
        let n: [[f32; 3]; 16] = core::array::from_fn(|i| [0.0, libm::sinf(i as f32), 1.0]);
        let params = ClusterParams {
            max_normal_angle_deg: 0.0,
            ..Default::default()
        };
        let (_, count) = run(&p, &n, &params);
        assert_eq!(
            count, 16,
            "all normals differ: only singletons lie within 0°"
        );
    }
}
