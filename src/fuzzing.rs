//! Fuzz target bodies. Each takes arbitrary bytes and panics only when an invariant is
//! broken; `fuzz/fuzz_targets/NAME.rs` calls `NAME`, and `tests/fuzz_corpus.rs` replays every
//! file under `fuzz/corpus/NAME/` through it on stable Rust.
//!
//! | target | input | invariant |
//! |---|---|---|
//! | [`journal`] | a journal file | opens or errs; accepts only intact records, truncates the rest |
//! | [`result_file`] | a result file | opens or errs; every declared record readable |
//! | [`texel_file`] | a texel file | opens or errs naming the file; every accessor in bounds |
//! | [`guide`] | guide parameters, records, sample points | pdf > 0 and finite, warped points in [0,1)², `pdf(sample(u))` = its pdf, scalar == 8-wide |
//! | [`estimator`] | batches of samples, NaN/∞/huge included | a finite combination inside the batches' range, or an explicit no-samples texel |
//! | [`traverse`] | triangles and rays | packet == scalar == brute force, bit for bit, closest hit and occlusion (at extreme magnitudes: the kernels' contract for hits outside their own box) |
//! | [`wide`] | [`traverse`]'s input, every preset | the collapse keeps every leaf once and covers every triangle; on the wide tree, single rays and packets (of 8, 2 and 1 live lanes: the hybrid switch) equal brute force bit for bit, or keep to the contract |
//! | [`scene`] | glTF / GLB / OBJ / TOML bytes | a scene of finite, indexed triangles, or an error naming the file |
//! | [`prepare`] | a hostile mesh (degenerate, non-manifold, NaN/∞, 10⁶ away, swarms of tiny triangles), unwrap mode, layout, resolution | `prepare_with` (xatlas included) returns an error naming the scene or the texel file, or a texel file whose texels are valid (or inside geometry) and on their triangles |
//!
//! The structured targets read their input with [`Bytes`], which returns zeros once the
//! input is exhausted, so every byte string is a valid input and short inputs are cheap.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use glam::{Vec2, Vec3};
use guidebake::bvh::{Bvh, Preset};
use guidebake::output::journal::{Journal, TileRecord};
use guidebake::output::result_file::{PerTexel, RecordFile, TexelResult};
use guidebake::prepare::{Layout, PrepareOptions, Resolution, Unwrap, prepare_with};
use guidebake::scene::{Material, Mesh, Scene, Triangle};
use guidebake::texels::{FLAG_INSIDE, FLAG_VALID, TexelFile};
use guidebake_kernels::estimator::{
    GraybillDeal, IterationVariance, RhoAccumulator, TexelEstimate, Welford, combine_weighted,
    plain_average,
};
use guidebake_kernels::guide::{self, DEFAULT_AMBIENT, GuideNode, GuideParams, Record};
use guidebake_kernels::packet::{Hit, Hit8, LANES, NO_HIT, Ray, Ray8};
use guidebake_kernels::sobol::ONE_MINUS_EPSILON;
use guidebake_kernels::sobol::to_unit;
use guidebake_kernels::traverse::{
    BvhRef, LEAF, Tree, Tri, WIDTH, WideRef, closest_hit_allowed, intersect_brute, intersect1,
    intersect8, occluded_brute, occluded1, occluded8, occlusion_allowed,
};
use guidebake_kernels::warp;

/// A fuzz target's body: arbitrary bytes in, a panic only on a broken invariant.
pub type Body = fn(&[u8]);

/// The names of the targets, as `fuzz/corpus/` folders and `fuzz/fuzz_targets/` files.
pub const TARGETS: &[(&str, Body)] = &[
    ("journal", journal),
    ("result_file", result_file),
    ("texel_file", texel_file),
    ("guide", guide),
    ("estimator", estimator),
    ("traverse", traverse),
    ("wide", wide),
    ("scene", scene),
    ("prepare", prepare),
];

/// A unique path in the temporary directory for one input, removed when dropped.
struct ScratchFile(PathBuf);

impl ScratchFile {
    fn with(bytes: &[u8]) -> Self {
        Self::named(bytes, "")
    }

    /// A scratch file whose name ends in `suffix` (e.g. `.gltf`).
    fn named(bytes: &[u8], suffix: &str) -> Self {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let path = scratch_dir().join(format!("guidebake-fuzz-{}-{n}{suffix}", std::process::id()));
        std::fs::write(&path, bytes).expect("the temporary directory is writable");
        ScratchFile(path)
    }
}

/// Where scratch files go: `$GUIDEBAKE_FUZZ_DIR`, else `/dev/shm` where it is a writable
/// directory (tmpfs: the journal's and result file's `fsync`s and the writes cost no disk
/// I/O, which dominated those targets), else the temporary directory.
fn scratch_dir() -> &'static Path {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        if let Some(dir) = std::env::var_os("GUIDEBAKE_FUZZ_DIR") {
            return PathBuf::from(dir);
        }
        let shm = Path::new("/dev/shm");
        let probe = shm.join(format!("guidebake-fuzz-probe-{}", std::process::id()));
        if std::fs::write(&probe, b"").is_ok() {
            let _ = std::fs::remove_file(&probe);
            return shm.to_owned();
        }
        std::env::temp_dir()
    })
}

impl Drop for ScratchFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Reads structured values from fuzz bytes; zeros once the bytes run out.
pub struct Bytes<'a> {
    data: &'a [u8],
}

impl<'a> Bytes<'a> {
    /// A reader over `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data }
    }

    /// Bytes left.
    pub fn remaining(&self) -> usize {
        self.data.len()
    }

    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        let n = N.min(self.data.len());
        out[..n].copy_from_slice(&self.data[..n]);
        self.data = &self.data[n..];
        out
    }

    /// One byte.
    pub fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }

    /// A little-endian u16.
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }

    /// A little-endian u32.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }

    /// A little-endian f32's bits as they are: NaN, ±∞ and subnormals included.
    pub fn raw_f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }
}

/// Arbitrary bytes as a journal: opening never panics; what it accepts is a header plus
/// whole, intact records with finite sums, and the file is truncated to exactly those.
pub fn journal(data: &[u8]) {
    let file = ScratchFile::with(data);
    let Ok((_, header, records)) = Journal::open(&file.0, true, None) else {
        return;
    };
    assert!(records.iter().all(|r| r.tile < header.tile_count));
    assert!(
        records
            .iter()
            .all(|r| { r.unweighted_luminance.is_finite() && r.weighted_luminance.is_finite() })
    );
    let len = std::fs::metadata(&file.0).expect("still there").len();
    assert_eq!(len, 64 + 48 * records.len() as u64, "torn tail truncated");
    let (_, _, again) = Journal::open(&file.0, false, None).expect("a truncated journal reopens");
    // Bits, not `==` (which a NaN would fail): the reopened records are the same words.
    let bits = |r: &TileRecord| {
        [
            u64::from(r.tile) << 32 | u64::from(r.texels),
            r.unweighted_luminance.to_bits(),
            r.weighted_luminance.to_bits(),
            r.rays,
            r.reserved,
            r.checksum,
        ]
    };
    assert!(again.iter().map(bits).eq(records.iter().map(bits)));
}

/// Arbitrary bytes as a result file and as a batch file: opening never panics and a refused
/// file's error names it; an accepted file has exactly the record layout asked for (one
/// [`TexelResult`] per texel; K [`Welford`]s per texel, K = 1 + byte 32 % 16, a reserved
/// header byte), its every declared texel can be read, and reads past the end or of partial
/// texels are errors.
pub fn result_file(data: &[u8]) {
    let file = ScratchFile::with(data);
    records::<TexelResult>(&file.0, 1);
    let k = 1 + u32::from(data.get(32).map_or(0, |b| b % 16));
    records::<Welford>(&file.0, k);
}

/// [`result_file`] for one kind of [`RecordFile`] of `per_texel` records per texel.
fn records<T: PerTexel>(path: &Path, per_texel: u32) {
    let (records, header) = match RecordFile::<T>::open_with(path, false, per_texel, None) {
        Ok(opened) => opened,
        Err(e) => {
            assert_names(&e.to_string(), path);
            return;
        }
    };
    let k = per_texel as usize;
    assert_eq!(header.record_bytes as usize, k * size_of::<T>());
    assert_eq!(records.per_texel(), u64::from(per_texel));
    assert_eq!(records.texel_count(), header.texel_count);
    let mut buffer = vec![T::zeroed(); 64 * k];
    let mut first = 0;
    while first < header.texel_count {
        let n = (header.texel_count - first).min(64) as usize;
        records
            .read(first, &mut buffer[..n * k])
            .expect("declared records are readable");
        first += n as u64;
    }
    let past = records
        .read(header.texel_count, &mut buffer[..k])
        .unwrap_err();
    assert_names(&past.to_string(), path);
    if k > 1 {
        let partial = records.read(0, &mut buffer[..k - 1]).unwrap_err();
        assert_names(&partial.to_string(), path);
    }
}

/// Arbitrary bytes as a texel file: opening never panics; a rejected file's error names it;
/// an accepted file's every section and every tile's texels can be read, and every texel
/// lies inside its tile's rectangle on its tile's page with a finite position and a unit
/// normal.
pub fn texel_file(data: &[u8]) {
    let file = ScratchFile::named(data, ".texels");
    let texels = match TexelFile::open(&file.0) {
        Ok(t) => t,
        Err(e) => {
            assert_names(&e.to_string(), &file.0);
            return;
        }
    };
    texels_in_bounds(&texels);
}

/// Every section, tile and texel of an opened texel file can be read, and every texel lies
/// inside its tile's rectangle on its tile's page with a finite position and a unit normal;
/// the tiles cover every texel once.
fn texels_in_bounds(texels: &TexelFile) {
    let header = *texels.header();
    assert_eq!(texels.pages().len(), header.page_count as usize);
    assert_eq!(texels.triangles().len(), header.triangle_count as usize);
    assert_eq!(texels.tiles().len() as u64, header.tile_count);
    assert_eq!(texels.texels().len() as u64, header.texel_count);
    let mut covered = 0u64;
    for (i, tile) in texels.tiles().iter().enumerate() {
        let page = texels.pages()[tile.page as usize];
        assert!(u64::from(tile.x) + u64::from(tile.width) <= u64::from(page.width));
        assert!(u64::from(tile.y) + u64::from(tile.height) <= u64::from(page.height));
        let inside = texels.tile_texels(i);
        assert_eq!(inside.len(), tile.texel_count as usize);
        for t in inside {
            let [x, y] = t.pixel.map(u32::from);
            assert_eq!(t.page, tile.page);
            assert!(
                (tile.x..tile.x + tile.width).contains(&x),
                "tile {i}: {t:?}"
            );
            assert!(
                (tile.y..tile.y + tile.height).contains(&y),
                "tile {i}: {t:?}"
            );
            assert!(t.position().is_finite());
            assert!((t.normal().length() - 1.0).abs() <= 1e-3 * 1.01);
        }
        covered += inside.len() as u64;
    }
    assert_eq!(covered, header.texel_count, "tiles cover every texel once");
}

/// Whether an error message names the file it is about.
fn assert_names(message: &str, path: &Path) {
    let name = path.to_string_lossy();
    assert!(
        message.contains(name.as_ref()),
        "the error does not name {name}: {message}"
    );
}

/// Guide parameters, learning records and sample points → [`guide::build`] (split rule,
/// floor, normalization, smoothing, defensive mixture) and the warp. For every point: the warped point lies in
/// [0,1)², its pdf is finite and positive and equals [`warp::pdf`] there bit for bit,
/// inverting and warping again lands on the same density, and [`warp::sample8`] /
/// [`warp::sample8_lanes`] equal the scalar warp lane for lane, bit for bit. The leaves'
/// probability masses sum to 1.
///
/// Input: 7 bytes of parameters, a record count (u16), 12 bytes per record, then sample
/// points as pairs of u32 (mapped to [0,1) as the Sobol points are).
pub fn guide(data: &[u8]) {
    let mut b = Bytes::new(data);
    let flags = b.u8();
    let params = GuideParams {
        min_records: u32::from(b.u8() % 9),
        min_flux_fraction: f32::from(b.u8()) / 1024.0,
        // Up to 19: depths above guide::MAX_DEPTH must be clamped.
        max_depth: u32::from(b.u8() % 20),
        ambient: match b.u8() {
            0 => DEFAULT_AMBIENT,
            a => f32::from(a) / 64.0,
        },
        alpha: if flags & 1 != 0 {
            b.raw_f32() // NaN, negative or > 1 must be clamped
        } else {
            f32::from(b.u8()) / 255.0
        },
        // The defensive mixture's share, from flag bits 4–6 (no input byte of its own, so
        // older inputs keep their meaning): out-of-range and NaN shares must be clamped.
        uniform: [0.0, 0.25, 0.5, 1.0, -0.5, f32::NAN, 2.0, 0.02][usize::from(flags >> 4 & 7)],
        // Flag bit 3 (unused before, so older inputs keep their meaning): the records are
        // second moments and the leaves take their roots.
        second_moment: flags & 8 != 0,
    };
    let capacity = 1 + usize::from(b.u16() % 4096);
    let count = usize::from(b.u16()).min(b.remaining() / 12);
    let mut records: Vec<Record> = (0..count)
        .map(|_| {
            let u = if flags & 2 != 0 {
                [b.raw_f32(), b.raw_f32()] // points outside [0,1) must be rejected
            } else {
                [to_unit(b.u32()), to_unit(b.u32())]
            };
            let f = b.u32();
            let flux = if flags & 4 != 0 {
                f32::from_bits(f) // NaN, ∞, negative, huge, subnormal
            } else {
                // 16 bits of mantissa over 2^-140 … 2^115: tiny to huge, always valid.
                (f & 0xffff) as f32 * ((((f >> 16) & 0xff) as i32 - 140) as f32).exp2()
            };
            Record { u, flux }
        })
        .collect();
    let mut points: Vec<[f32; 2]> = Vec::new();
    while b.remaining() >= 8 {
        points.push([to_unit(b.u32()), to_unit(b.u32())]);
    }

    // One node buffer per thread, reused: allocating and zeroing up to 4096 fresh nodes per
    // input (page faults included) took a third of the target's time.
    thread_local! {
        static STORAGE: std::cell::RefCell<Vec<GuideNode>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    STORAGE.with_borrow_mut(|storage| {
        storage.clear();
        storage.resize(capacity, GuideNode::default());
        guide_checks(&params, &mut records, count, storage, points);
    });
}

/// [`guide`] after decoding: build into `storage` and check every invariant.
fn guide_checks(
    params: &GuideParams,
    records: &mut [Record],
    count: usize,
    storage: &mut [GuideNode],
    mut points: Vec<[f32; 2]>,
) {
    let params = *params;
    let capacity = storage.len();
    let (g, stats) = guide::build(records, &params, storage);
    assert_eq!(
        (stats.accepted + stats.rejected_flux + stats.rejected_point) as usize,
        count
    );
    assert_eq!(g.nodes().len(), stats.nodes as usize);
    assert!(g.nodes().len() <= capacity.min(guide::MAX_NODES));
    assert!(stats.depth <= guide::MAX_DEPTH);
    let mut mass = 0.0f64;
    g.for_each_leaf(|leaf| {
        assert!(
            leaf.pdf.is_finite() && leaf.pdf > 0.0,
            "{leaf:?} {params:?}"
        );
        mass += f64::from(leaf.pdf) * f64::from(leaf.size) * f64::from(leaf.size);
    });
    assert!((mass - 1.0).abs() < 1e-3, "leaf masses sum to {mass}");

    // The split thresholds and their neighbours: where rounding decides the path.
    points.extend([
        [0.0, 0.0],
        [ONE_MINUS_EPSILON, ONE_MINUS_EPSILON],
        [0.0, ONE_MINUS_EPSILON],
    ]);
    for n in g.nodes().iter().take(64).filter(|n| !n.is_leaf()) {
        let [tx, ty0, ty1] = n.thresholds();
        for (x, y) in [(tx, ty0), (tx, ty1)] {
            let below = |v: f32| f32::from_bits(v.to_bits().saturating_sub(1));
            for p in [[x, y], [below(x), below(y)], [x, below(y)], [below(x), y]] {
                points.push(p.map(|v| if (0.0..1.0).contains(&v) { v } else { 0.0 }));
            }
        }
    }

    let mut warped = Vec::with_capacity(points.len());
    for &u in &points {
        let s = warp::sample(&g, u);
        let in_square = |v: f32| (0.0..1.0).contains(&v);
        assert!(in_square(s.u[0]) && in_square(s.u[1]), "{u:?} → {s:?}");
        assert!(s.pdf.is_finite() && s.pdf > 0.0, "{u:?} → {s:?}");
        assert_eq!(
            warp::pdf(&g, s.u).to_bits(),
            s.pdf.to_bits(),
            "{u:?} → {s:?}"
        );
        let back = warp::invert(&g, s.u);
        assert!(in_square(back[0]) && in_square(back[1]), "{s:?} → {back:?}");
        assert_eq!(
            warp::sample(&g, back).pdf.to_bits(),
            s.pdf.to_bits(),
            "{u:?} → {s:?} → {back:?}"
        );
        warped.push(s);
    }
    for (chunk, want) in points.chunks(LANES).zip(warped.chunks(LANES)) {
        let lanes = chunk.len();
        let pad = |a: usize, fill: f32| -> [f32; LANES] {
            std::array::from_fn(|l| chunk.get(l).map_or(fill, |p| p[a]))
        };
        let (x, y) = (pad(0, 0.25), pad(1, 0.75));
        let w = if lanes == LANES {
            warp::sample8(&g, x.into(), y.into())
        } else {
            warp::sample8_lanes(&g, x.into(), y.into(), lanes)
        };
        let (wx, wy, wp) = (w.x.to_array(), w.y.to_array(), w.pdf.to_array());
        for l in 0..LANES {
            if let Some(s) = want.get(l) {
                let got = [wx[l], wy[l], wp[l]].map(f32::to_bits);
                let scalar = [s.u[0], s.u[1], s.pdf].map(f32::to_bits);
                assert_eq!(got, scalar, "lane {l} of {chunk:?}");
            } else {
                assert_eq!((wx[l], wy[l], wp[l]), (0.25, 0.75, 0.0), "idle lane {l}");
            }
        }
    }
}

/// Batches of radiance samples — NaN, ±∞ and values up to `f32::MAX` included — through
/// [`Welford`], [`GraybillDeal`], [`plain_average`], Müller's [`combine_weighted`] and ρ:
/// every count is exact, every mean lies within its samples' range, and every combination
/// is either a finite value inside the range of the batch means (a convex combination) or
/// [`TexelEstimate::NoSamples`] exactly when no sample was finite; ρ is finite, and positive
/// when no sample is negative.
///
/// Input: the batch count (1 + byte % 16), the variance floor, then per sample a selector
/// byte (batch = byte % K; bit 7: the three channels are raw f32 bits, else moderate
/// values) and 12 bytes.
pub fn estimator(data: &[u8]) {
    let mut b = Bytes::new(data);
    let k = 1 + usize::from(b.u8() % 16);
    let gd = GraybillDeal {
        rel_std_floor: match b.u8() {
            0 => GraybillDeal::default().rel_std_floor,
            c => f64::from(c) / 64.0,
        },
    };
    let mut batches = vec![Welford::new(); k];
    let (mut finite, mut rejected) = (vec![0u64; k], vec![0u64; k]);
    let mut range = vec![[(f64::INFINITY, f64::NEG_INFINITY); 3]; k];
    while b.remaining() >= 13 {
        let sel = b.u8();
        let which = usize::from(sel) % k;
        let rgb: [f32; 3] = if sel & 0x80 != 0 {
            [b.raw_f32(), b.raw_f32(), b.raw_f32()]
        } else {
            [b.u32(), b.u32(), b.u32()].map(|x| (x >> 8) as f32 / 65536.0)
        };
        batches[which].push(rgb);
        if rgb.iter().all(|c| c.is_finite()) {
            finite[which] += 1;
            for (r, &c) in range[which].iter_mut().zip(&rgb) {
                *r = (r.0.min(f64::from(c)), r.1.max(f64::from(c)));
            }
        } else {
            rejected[which] += 1;
        }
    }

    let mut means = [(f64::INFINITY, f64::NEG_INFINITY); 3];
    for (i, batch) in batches.iter().enumerate() {
        assert_eq!((batch.count(), batch.rejected()), (finite[i], rejected[i]));
        let Some(mean) = batch.mean_rgb() else {
            assert_eq!(finite[i], 0);
            continue;
        };
        for c in 0..3 {
            assert!(within(mean[c], range[i][c]), "batch {i} mean {mean:?}");
            means[c] = (means[c].0.min(mean[c]), means[c].1.max(mean[c]));
        }
        if let Some(var) = batch.variance() {
            assert!(var.iter().all(|v| v.is_finite() && *v >= 0.0), "{var:?}");
        }
    }

    let total: u64 = finite.iter().sum();
    let bad: u64 = rejected.iter().sum();
    let mut muller = IterationVariance::<16>::new();
    muller.add_texel(&batches);
    let weights = muller.weights();
    assert!(
        weights.iter().all(|w| w.is_finite() && *w >= 0.0),
        "{weights:?}"
    );
    let average = plain_average(&batches);
    let combined = gd.combine(&batches);
    for (what, estimate) in [
        ("average", average),
        ("Graybill–Deal", combined),
        ("Müller", combine_weighted(&batches, &weights)),
    ] {
        match estimate {
            TexelEstimate::NoSamples { rejected } => {
                assert_eq!((total, rejected), (0, bad), "{what}");
            }
            TexelEstimate::Value(e) => {
                assert_eq!((e.samples, e.rejected), (total, bad), "{what}");
                assert!(e.luminance.is_finite(), "{what}: {e:?}");
                for c in 0..3 {
                    assert!(within(e.rgb[c], means[c]), "{what}: {e:?} vs {means:?}");
                }
            }
        }
    }
    let mut floored = vec![0.0; k];
    gd.floored_variances(&batches, &mut floored);
    for (f, batch) in floored.iter().zip(&batches) {
        assert!(
            *f > 0.0 && (f.is_finite() || batch.count() == 0),
            "{floored:?}"
        );
    }
    let mut rho = RhoAccumulator::new();
    rho.add_texel(&average, &combined);
    assert!(rho.rho().is_finite(), "ρ = {}", rho.rho());
    // Radiance is never negative in a bake (the scene loaders clamp emission and albedo at
    // 0); negative samples may give a negative ρ, which is outside the contract.
    if range.iter().flatten().all(|&(lo, _)| lo >= 0.0) {
        assert!(rho.rho() > 0.0, "ρ = {}", rho.rho());
    }
}

/// Whether `x` lies in `[lo, hi]` up to rounding (a few ulps of the larger bound).
fn within(x: f64, (lo, hi): (f64, f64)) -> bool {
    let slack = 1e-12 * lo.abs().max(hi.abs());
    x.is_finite() && x >= lo - slack && x <= hi + slack
}

/// Triangles and rays → the BVH (every obvhs preset) → [`intersect8`] and [`intersect1`]
/// each equal [`intersect_brute`] bit for bit per ray (t, u, v and primitive), and so do
/// [`occluded8`], [`occluded1`] and [`occluded_brute`] — or, where they differ, the result
/// keeps to the kernels' documented contract for hits outside their own box's interval, at
/// extreme magnitudes ([`closest_hit_allowed`], [`occlusion_allowed`]); lanes that miss or
/// are not traced come back untouched.
///
/// Input: a header (preset, scale exponent 2^-20 … 2^20, world offset up to 10^6, flags),
/// the triangle count, triangles as 9 × i16 grid coordinates, then rays: a selector byte
/// (raw f32 bits or grid coordinates; tmin, tmax from a table of edge cases), origin,
/// direction. Flag bit 0 makes each packet of 8 share its first ray's origin, as gather
/// packets do.
pub fn traverse(data: &[u8]) {
    let input = TraverseInput::decode(data);
    let corners = input.corners();
    let bvh = match Bvh::build_with_binary(&corners, input.preset) {
        Ok(bvh) => bvh,
        Err(e) => panic!("finite triangles build a BVH: {e}"),
    };
    let Some(view) = bvh.binary() else {
        panic!("build_with_binary keeps the binary tree")
    };
    leaves_cover_their_triangles(binary_leaves(&view), &input.soup);
    let tris = input.tris();
    for packet in input.rays.chunks(LANES) {
        let lanes = std::array::from_fn(|l| packet.get(l).map(|r| (*r, Brute::of(&tris, r))));
        lanes_keep_to_the_contract(&view, &lanes, true);
    }
}

/// The wide (8-child) tree the bake walks, built from [`traverse`]'s input with *every*
/// preset (the input's preset byte is not read): [`Bvh::build_with_binary`]'s collapse
/// keeps every leaf of the binary tree — box and triangles, read back from the wide tree's
/// rows bit for bit — once, every vertex of every triangle lies in a leaf box holding it,
/// every inner slot's box holds its node's boxes, and every node but the root is some slot's
/// child exactly once; [`Bvh::build`] (the bake's, which drops the binary tree) gives the same
/// wide nodes for the first preset of each input. Then, per ray, on the wide tree, the checks
/// of [`traverse`]: [`intersect1`], [`occluded1`], [`intersect8`] and [`occluded8`] equal
/// brute force bit for bit or keep to the contract. Besides each packet of eight, every pair
/// of its lanes (0–1, 2–3, …) is traced again as a packet of two live lanes, and every lane
/// alone as a packet of one: below the root such packets take the any-hit walk's hybrid
/// switch (`occluded_alone`, at most two live lanes) and the closest-hit walk's leaf rows for
/// few lanes.
///
/// Not reached: the interleaved walk `occluded8` takes for packets without a shared origin
/// on trees above `INTERLEAVE_BYTES` (1 MiB; 63 triangles make a few kilobytes); the kernels'
/// unit tests call it directly.
pub fn wide(data: &[u8]) {
    let input = TraverseInput::decode(data);
    let corners = input.corners();
    let tris = input.tris();
    let brute: Vec<Brute> = input.rays.iter().map(|r| Brute::of(&tris, r)).collect();
    for (i, preset) in Preset::ALL.into_iter().enumerate() {
        let bvh = match Bvh::build_with_binary(&corners, preset) {
            Ok(bvh) => bvh,
            Err(e) => panic!("finite triangles build a BVH ({preset:?}): {e}"),
        };
        if i == 0 {
            let bake = Bvh::build(&corners, preset).expect("built once already");
            assert!(bake.binary().is_none(), "Bvh::build drops the binary tree");
            assert!(
                bake.wide_nodes() == bvh.wide_nodes(),
                "{preset:?}: Bvh::build and build_with_binary collapse alike"
            );
        }
        let Some(binary) = bvh.binary() else {
            panic!("build_with_binary keeps the binary tree")
        };
        let wide = bvh.wide();
        collapse_keeps_the_tree(&binary, &wide, &input.soup, preset);
        for (packet, brute) in input.rays.chunks(LANES).zip(brute.chunks(LANES)) {
            let lane = |l: usize| Some((packet[l], brute[l]));
            lanes_keep_to_the_contract(
                &wide,
                &std::array::from_fn(|l| (l < packet.len()).then(|| lane(l)).flatten()),
                true,
            );
            // Pairs of lanes and lone lanes, at their own lane positions: the hybrid switch.
            let pairs = (0..packet.len())
                .step_by(2)
                .map(|l| l..(l + 2).min(packet.len()));
            for used in pairs.chain((0..packet.len()).map(|l| l..l + 1)) {
                let lanes = std::array::from_fn(|l| used.contains(&l).then(|| lane(l)).flatten());
                lanes_keep_to_the_contract(&wide, &lanes, false);
            }
        }
    }
}

/// [`traverse`]'s (and [`wide`]'s) input decoded as those bodies read it: the triangles'
/// corners (primitive id = index) and the rays, for tests that replay a corpus input through
/// other checks (`tests/fuzz_corpus.rs`).
pub fn traverse_input(data: &[u8]) -> (Vec<[Vec3; 3]>, Vec<Ray>) {
    let input = TraverseInput::decode(data);
    (input.corners(), input.rays)
}

/// [`traverse`]'s input, decoded.
struct TraverseInput {
    preset: Preset,
    soup: Vec<[[f32; 3]; 3]>,
    rays: Vec<Ray>,
}

impl TraverseInput {
    fn decode(data: &[u8]) -> Self {
        let mut b = Bytes::new(data);
        let preset = Preset::ALL[usize::from(b.u8()) % Preset::ALL.len()];
        let scale = ((i32::from(b.u8() % 41) - 20) as f32).exp2();
        let offset = [0.0, 1.0, 1e3, 1e6, -1e6, 0.5][usize::from(b.u8()) % 6];
        let flags = b.u8();
        let coord = |b: &mut Bytes| f32::from(b.u16() as i16) * scale + offset;
        let tri_count = usize::from(b.u8() % 64);
        let soup: Vec<[[f32; 3]; 3]> = (0..tri_count)
            .map(|_| std::array::from_fn(|_| std::array::from_fn(|_| coord(&mut b))))
            .collect();
        let mut rays: Vec<Ray> = Vec::new();
        while b.remaining() >= 13 && rays.len() < 64 {
            let sel = b.u8();
            let (org, dir): ([f32; 3], [f32; 3]) = if sel & 0x80 != 0 {
                (
                    std::array::from_fn(|_| b.raw_f32()),
                    std::array::from_fn(|_| b.raw_f32()),
                )
            } else {
                (
                    std::array::from_fn(|_| coord(&mut b)),
                    std::array::from_fn(|_| f32::from(b.u16() as i16)),
                )
            };
            let tmin = [0.0, 1e-4 * scale, -1.0, f32::NAN][usize::from(sel & 3)];
            let tmax = [
                f32::INFINITY,
                f32::MAX,
                64.0 * scale,
                0.0,
                f32::NAN,
                1e-4 * scale,
                1e30,
                -1.0,
            ][usize::from((sel >> 2) & 7)];
            let org = if flags & 1 != 0 && !rays.len().is_multiple_of(LANES) {
                rays[rays.len() - rays.len() % LANES].org
            } else {
                org.into()
            };
            rays.push(Ray::new(org, dir.into(), tmin, tmax));
        }
        Self { preset, soup, rays }
    }

    fn corners(&self) -> Vec<[Vec3; 3]> {
        self.soup.iter().map(|t| t.map(Into::into)).collect()
    }

    /// The triangles as brute force takes them: primitive id = index.
    fn tris(&self) -> Vec<Tri> {
        self.corners()
            .into_iter()
            .enumerate()
            .map(|(i, v)| Tri::new(v, i as u32))
            .collect()
    }
}

/// Brute force's answers for one ray: closest hit and occlusion.
#[derive(Clone, Copy)]
struct Brute {
    hit: Option<Hit>,
    occluded: bool,
}

impl Brute {
    fn of(tris: &[Tri], ray: &Ray) -> Self {
        Self {
            hit: intersect_brute(tris, ray),
            occluded: occluded_brute(tris, ray),
        }
    }
}

/// The rays `lanes` (`None`: an inactive lane) through `tree` as one packet, and as single
/// rays when `single`: closest hits and occlusion equal brute force bit for bit, else keep
/// to the kernels' contract (`traverse`'s docs, "Hits outside their own box"; in the
/// corpus: `contract-*`); a lane without a hit comes back untouched, an inactive lane never
/// hits and is never blocked.
fn lanes_keep_to_the_contract(
    tree: &impl Tree,
    lanes: &[Option<(Ray, Brute)>; LANES],
    single: bool,
) {
    let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim));
    let sentinel = Hit {
        t: -7.0,
        u: 0.125,
        v: 0.5,
        prim: NO_HIT - 1,
    };
    let mut rays8 = Ray8::INACTIVE;
    for (l, lane) in lanes.iter().enumerate() {
        if let Some((ray, _)) = lane {
            rays8.set_lane(l, ray);
        }
    }
    let mut hits = Hit8::NONE;
    (0..LANES).for_each(|l| hits.set_lane(l, &sentinel));
    let hit_mask = intersect8(tree, &rays8, &mut hits);
    let blocked = occluded8(tree, &rays8);
    for (l, lane) in lanes.iter().enumerate() {
        let Some((ray, brute)) = lane else {
            assert_eq!(hit_mask >> l & 1, 0, "inactive lane {l} never hits");
            assert_eq!(blocked >> l & 1, 0, "inactive lane {l} is never blocked");
            continue;
        };
        // Bit for bit brute force, else the contract.
        let allowed =
            |h: Option<Hit>| bits(h) == bits(brute.hit) || closest_hit_allowed(tree, ray, h);
        let occlusion_ok = |got: bool| got == brute.occluded || occlusion_allowed(tree, ray, got);
        if single {
            let scalar = intersect1(tree, ray);
            assert!(
                allowed(scalar),
                "single ray {ray:?}: {:?} vs brute force {:?}",
                bits(scalar),
                bits(brute.hit)
            );
            assert!(occlusion_ok(occluded1(tree, ray)), "single ray {ray:?}");
        }
        let got = (hit_mask >> l & 1 != 0).then(|| hits.lane(l)).flatten();
        assert!(
            allowed(got),
            "packet lane {l} of {:#010b}: {ray:?}: {:?} vs brute force {:?}",
            rays8_lanes(lanes),
            bits(got),
            bits(brute.hit)
        );
        if hit_mask >> l & 1 == 0 {
            assert_eq!(
                bits(hits.lane(l)),
                bits(Some(sentinel)),
                "untouched lane {l}"
            );
        }
        assert!(
            occlusion_ok(blocked >> l & 1 != 0),
            "packet lane {l} of {:#010b}: {ray:?}",
            rays8_lanes(lanes)
        );
    }
}

/// The live lanes of a packet, as a mask (for messages).
fn rays8_lanes(lanes: &[Option<(Ray, Brute)>; LANES]) -> u8 {
    (0..LANES).fold(0, |m, l| m | u8::from(lanes[l].is_some()) << l)
}

/// A leaf: its box (lo, hi) and its triangles.
type Leaf = (([f32; 3], [f32; 3]), Vec<Tri>);

/// The binary tree's leaves (empty slots, of no triangles, included).
fn binary_leaves(view: &BvhRef<'_>) -> Vec<Leaf> {
    let mut leaves = Vec::new();
    for node in view.nodes() {
        for slot in 0..2 {
            if node.meta[slot] == 0 {
                continue;
            }
            let first = node.child[slot] as usize;
            let count = (node.meta[slot] & !LEAF) as usize;
            leaves.push((
                (
                    [0, 1, 2].map(|a| node.lo[a][slot]),
                    [0, 1, 2].map(|a| node.hi[a][slot]),
                ),
                view.tris()[first..first + count].to_vec(),
            ));
        }
    }
    leaves
}

/// The wide tree's used leaves, their triangles read back from its rows: the rows hold the
/// leaves in node order, slots in storage order ([`WideRef::tris`]).
fn wide_leaves(view: &WideRef<'_>) -> Vec<Leaf> {
    let mut rows = view.tris();
    let mut leaves = Vec::new();
    for node in view.nodes() {
        for slot in 0..WIDTH {
            let meta = node.meta[slot];
            if meta == 0 || meta == LEAF {
                continue;
            }
            let count = (meta & !LEAF) as usize;
            let tris: Vec<Tri> = rows.by_ref().take(count).collect();
            assert_eq!(tris.len(), count, "the rows hold every leaf's triangles");
            leaves.push((
                (
                    [0, 1, 2].map(|a| node.lo[a][slot]),
                    [0, 1, 2].map(|a| node.hi[a][slot]),
                ),
                tris,
            ));
        }
    }
    assert!(rows.next().is_none(), "no rows beyond the leaves");
    leaves
}

/// The traversal contract is stated on the leaves' boxes (a leaf of a spatial-split BVH holds
/// a clipped part of its triangle), so the builder must not shrink them: every vertex of
/// every triangle lies in the box of a leaf that holds the triangle.
fn leaves_cover_their_triangles(leaves: Vec<Leaf>, corners: &[[[f32; 3]; 3]]) {
    let mut covered = vec![[false; 3]; corners.len()];
    for ((lo, hi), tris) in &leaves {
        let inside = |v: &[f32; 3]| (0..3).all(|a| (lo[a]..=hi[a]).contains(&v[a]));
        for tri in tris {
            let prim = tri.prim as usize;
            for (k, v) in corners[prim].iter().enumerate() {
                covered[prim][k] |= inside(v);
            }
        }
    }
    if let Some(prim) = covered.iter().position(|c| !c.iter().all(|&b| b)) {
        panic!(
            "triangle {prim} {:?}: a vertex outside every leaf box holding it",
            corners[prim]
        );
    }
}

/// The collapse ([`guidebake_kernels::traverse::collapse`]) of `binary` into `wide`: the
/// same leaves, each once (box bits and triangle bits), covering every triangle; every inner
/// slot's box holds the boxes of its node; every node but the root is one slot's child.
fn collapse_keeps_the_tree(
    binary: &BvhRef<'_>,
    wide: &WideRef<'_>,
    corners: &[[[f32; 3]; 3]],
    preset: Preset,
) {
    let key = |(aabb, tris): &Leaf| {
        let mut tris: Vec<_> = tris
            .iter()
            .map(|t| (t.prim, t.v.map(|v| v.map(f32::to_bits))))
            .collect();
        tris.sort_unstable();
        ((aabb.0.map(f32::to_bits), aabb.1.map(f32::to_bits)), tris)
    };
    let mut want: Vec<_> = binary_leaves(binary)
        .iter()
        .filter(|(_, tris)| !tris.is_empty())
        .map(key)
        .collect();
    let leaves = wide_leaves(wide);
    let mut got: Vec<_> = leaves.iter().map(key).collect();
    want.sort_unstable();
    got.sort_unstable();
    assert!(
        got == want,
        "{preset:?}: the wide tree's leaves are not the binary tree's ({} vs {})",
        got.len(),
        want.len()
    );
    leaves_cover_their_triangles(leaves, corners);
    let nodes = wide.nodes();
    let mut parents = vec![0u32; nodes.len()];
    for (index, node) in nodes.iter().enumerate() {
        for slot in 0..WIDTH {
            if node.meta[slot] != 0 {
                continue;
            }
            let child = node.child[slot] as usize;
            parents[child] += 1;
            let lo = [0, 1, 2].map(|a| node.lo[a][slot]);
            let hi = [0, 1, 2].map(|a| node.hi[a][slot]);
            let c = &nodes[child];
            for s in (0..WIDTH).filter(|&s| c.meta[s] != LEAF) {
                assert!(
                    (0..3).all(|a| lo[a] <= c.lo[a][s] && c.hi[a][s] <= hi[a]),
                    "{preset:?}: node {index} slot {slot}'s box does not hold node {child} slot {s}'s"
                );
            }
        }
    }
    assert_eq!(parents[0], 0, "{preset:?}: the root is no node's child");
    if let Some(n) = parents.iter().skip(1).position(|&p| p != 1) {
        panic!(
            "{preset:?}: node {} is the child of {} slots",
            n + 1,
            parents[n + 1]
        );
    }
}

/// Arbitrary bytes as a scene: the first byte picks the format (`.gltf`, `.glb`, `.obj`,
/// `.toml`), the rest is the file. Loading never panics; an error names the file; a loaded
/// scene has triangles, each with finite positions, finite normals, a real material and
/// mesh, and meshes whose triangle ranges tile the triangle list.
pub fn scene(data: &[u8]) {
    let Some((&format, body)) = data.split_first() else {
        return;
    };
    let ext = [".gltf", ".glb", ".obj", ".toml"][usize::from(format) % 4];
    let file = ScratchFile::named(body, ext);
    let scene = match Scene::load(&file.0) {
        Ok(scene) => scene,
        Err(e) => {
            // A TOML scene's error may be about the geometry file it names instead.
            if ext != ".toml" {
                assert_names(&e.to_string(), &file.0);
            }
            return;
        }
    };
    assert!(!scene.triangles.is_empty());
    for (i, t) in scene.triangles.iter().enumerate() {
        assert!(
            t.positions.iter().all(|p| p.is_finite()),
            "triangle {i}: {t:?}"
        );
        assert!(
            t.normals.iter().all(|n| n.is_finite()),
            "triangle {i}: {t:?}"
        );
        assert!(
            (t.material as usize) < scene.materials.len(),
            "triangle {i}"
        );
        assert!((t.mesh as usize) < scene.meshes.len(), "triangle {i}");
        // The albedo a hit reads (textured or not) is a finite reflectance.
        let albedo = scene.hit_albedo(i).at(0.25, 0.25).to_array();
        assert!(
            albedo.iter().all(|a| (0.0..=1.0).contains(a)),
            "triangle {i}: albedo {albedo:?}"
        );
    }
    let mut next = 0u32;
    for m in &scene.meshes {
        assert_eq!(m.first_triangle, next, "mesh {}", m.name);
        next += m.triangle_count;
    }
    assert_eq!(next as usize, scene.triangles.len());
    let (lo, hi) = scene.bounds();
    assert!(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all());
}

/// Most tiny triangles the `prepare` target's swarm appends: 2 048 welded ones take ~0.3 s
/// (xatlas and `facing_sides`), so more would starve the campaign of executions.
pub const SWARM: usize = 2048;

/// A hostile mesh → [`prepare_with`] with unwrapping (xatlas, C++: run under
/// AddressSanitizer by `fuzz/run.sh`, which builds it instrumented): a clear error — one that
/// names the scene (`<fuzz>`) or the texel file — or a texel file that opens, whose every
/// texel is in bounds (as [`texel_file`] checks), valid, on a triangle of the scene that has
/// lightmap UVs, within that triangle's box (up to f32 rounding of the interpolation); the
/// report counts what the file holds; the returned layout has one finite UV triple or `None`
/// per triangle.
///
/// Input: a header (flags: unwrap mode, layout, a tiny-triangle swarm; the resolution:
/// a density from a table — 0, −1, NaN, ∞, 10⁻³⁰, 10³⁰, `f32::MAX`, or one aiming at
/// 16 … 4 096 texels for the scene's area —, or a page size from a table of 0 … 2³² − 1;
/// a scale 2⁻²⁰ … 2²⁰ and an offset up to 10⁶), up to 64 vertices as 3 × i16 grid
/// coordinates (i16::MIN is NaN, i16::MIN + 1 is ∞), then triangles as three vertex indices
/// (repeated indices: degenerate; shared ones: welded edges, non-manifold ones included) and
/// a selector byte: a new mesh starts here (up to 4), lightmap UVs (projected from the
/// positions, or 6 raw i8 bytes over −2…2), geometric or raw normals (3 raw f32 bits,
/// zero and NaN included). The swarm appends up to [`SWARM`] triangles of side 2⁻⁴ … 2⁻¹⁹ (xatlas
/// skips those below [`TINY_AREA`](guidebake::prepare::unwrap::TINY_AREA)) as a grid of
/// welded quads or as loose triangles, in a mesh of their own.
pub fn prepare(data: &[u8]) {
    let mut b = Bytes::new(data);
    let flags = b.u8();
    let unwrap = [
        Unwrap::Missing,
        Unwrap::Always,
        Unwrap::Never,
        Unwrap::Missing,
    ][usize::from(flags & 3)];
    let layout =
        [Layout::Auto, Layout::Shared, Layout::PerMesh, Layout::Auto][usize::from(flags >> 2 & 3)];
    let (r, r2) = (b.u8(), b.u8());
    let scale = ((i32::from(b.u8() % 41) - 20) as f32).exp2();
    let offset = [0.0, 1.0, 1e3, 1e6, -1e6, 0.5][usize::from(b.u8()) % 6];
    let coord = |b: &mut Bytes| match b.u16() as i16 {
        i16::MIN => f32::NAN,
        -32767 => f32::INFINITY,
        c => f32::from(c) * scale + offset,
    };
    let vertex_count = usize::from(b.u8() % 64);
    let vertices: Vec<Vec3> = (0..vertex_count)
        .map(|_| Vec3::new(coord(&mut b), coord(&mut b), coord(&mut b)))
        .collect();
    let triangle_count = usize::from(b.u8()) * usize::from(vertex_count > 0);
    let mut triangles = Vec::new();
    let mut mesh = 0u32;
    for _ in 0..triangle_count {
        let corners: [Vec3; 3] =
            std::array::from_fn(|_| vertices[usize::from(b.u8()) % vertex_count]);
        let sel = b.u8();
        if sel & 1 != 0 && !triangles.is_empty() && mesh < 3 {
            mesh += 1;
        }
        let lightmap_uv = match sel >> 1 & 3 {
            0 | 1 => None,
            2 => Some(corners.map(|p| Vec2::new(p.x, p.y) / (65536.0 * scale) + 0.5)),
            _ => Some(std::array::from_fn(|_| {
                Vec2::new(f32::from(b.u8() as i8), f32::from(b.u8() as i8)) / 64.0
            })),
        };
        let normals = if sel & 8 != 0 {
            let n = Vec3::new(b.raw_f32(), b.raw_f32(), b.raw_f32());
            [n; 3]
        } else {
            let [a, p, q] = corners;
            [(p - a).cross(q - a).normalize_or_zero(); 3]
        };
        triangles.push(Triangle {
            positions: corners,
            normals,
            lightmap_uv,
            texture_uv: None,
            colour: None,
            mesh,
            material: 0,
        });
    }
    if flags & 16 != 0 {
        // Many tiny triangles: a grid of welded quads, or loose triangles (flag 32).
        let count = usize::from(b.u16()) % (SWARM + 1);
        let side = (-f32::from(4 + b.u8() % 16)).exp2();
        let columns = 1 + usize::from(b.u8());
        let origin = Vec3::splat(offset);
        if !triangles.is_empty() {
            mesh += 1;
        }
        for i in 0..count {
            let (quad, upper) = (i / 2, i % 2 == 1);
            let (x, y) = ((quad % columns) as f32, (quad / columns) as f32);
            let gap = if flags & 32 != 0 { 3.0 } else { 1.0 };
            let at = |dx: f32, dy: f32| {
                origin + Vec3::new((x * gap + dx) * side, (y * gap + dy) * side, 0.0)
            };
            let positions = if upper {
                [at(1.0, 0.0), at(1.0, 1.0), at(0.0, 1.0)]
            } else {
                [at(0.0, 0.0), at(1.0, 0.0), at(0.0, 1.0)]
            };
            triangles.push(Triangle {
                positions,
                normals: [Vec3::Z; 3],
                lightmap_uv: None,
                texture_uv: None,
                colour: None,
                mesh,
                material: 0,
            });
        }
    }
    let mut scene = Scene::of_triangles("fuzz", triangles, vec![Material::default_grey()]);
    scene.meshes = (0..=mesh)
        .map(|m| {
            let first = scene.triangles.partition_point(|t| t.mesh < m);
            let count = scene.triangles[first..].partition_point(|t| t.mesh == m);
            let mine = &scene.triangles[first..first + count];
            Mesh {
                name: format!("mesh{m}"),
                first_triangle: first as u32,
                triangle_count: count as u32,
                has_lightmap_uvs: mine.iter().all(|t| t.lightmap_uv.is_some()),
            }
        })
        .collect();
    // Texel counts the density choices aim at, for the scene's finite area.
    let area: f64 = scene
        .triangles
        .iter()
        .map(|t| f64::from(t.area()))
        .filter(|a| a.is_finite())
        .sum();
    let aim = |texels: f64| (texels / area.max(1e-30)).sqrt() as f32;
    const SIDES: [u32; 16] = [
        0,
        1,
        6,
        7,
        8,
        12,
        16,
        31,
        32,
        33,
        64,
        100,
        256,
        16_385,
        65_536,
        u32::MAX,
    ];
    // Never `Resolution::Default`: it is a 1024² page's worth of texels, each traced for
    // being inside geometry — 20–64 s an input under AddressSanitizer, a CI smoke run's
    // timeout — on the code path an aimed density takes with 1/256 of the texels.
    let resolution = match r % 4 {
        0 | 1 => Resolution::TexelsPerUnit(match r2 % 12 {
            0 => 0.0,
            1 => -1.0,
            2 => f32::NAN,
            3 => f32::INFINITY,
            4 => 1e-30,
            5 => 1e30,
            6 => f32::MAX,
            k => aim(f64::from(16u32 << (2 * (k - 7)))),
        }),
        _ => Resolution::Size(SIDES[usize::from(r2 & 15)], SIDES[usize::from(r2 >> 4)]),
    };
    let out = ScratchFile::named(b"", ".texels");
    let opts = PrepareOptions { resolution, layout };
    let (report, lightmap) = match prepare_with(&scene, &out.0, opts, unwrap) {
        Ok(done) => done,
        Err(e) => {
            let message = e.to_string();
            assert!(
                message.contains("<fuzz>") || message.contains(&*out.0.to_string_lossy()),
                "the error names neither the scene nor the texel file: {message}"
            );
            return;
        }
    };
    let texels = match TexelFile::open(&out.0) {
        Ok(t) => t,
        Err(e) => panic!("prepare wrote a texel file that does not open: {e}"),
    };
    texels_in_bounds(&texels);
    let header = *texels.header();
    assert!(report.texels > 0, "Ok without texels: {report:?}");
    assert_eq!(report.texels, header.texel_count);
    assert_eq!(report.tiles, header.tile_count);
    let pages: Vec<(u32, u32)> = texels.pages().iter().map(|p| (p.width, p.height)).collect();
    assert_eq!(report.pages, pages);
    assert_eq!(lightmap.uv.len(), scene.triangles.len());
    assert!(
        lightmap
            .uv
            .iter()
            .flatten()
            .flatten()
            .all(|v| v.is_finite()),
        "a non-finite lightmap UV"
    );
    let inside = texels
        .texels()
        .iter()
        .filter(|t| t.flags & FLAG_INSIDE != 0)
        .count() as u64;
    assert_eq!(inside, report.inside_texels, "{report:?}");
    for t in texels.texels() {
        // Valid, or inside geometry (not valid, flagged, filled by the dilation).
        assert!(
            (t.flags & FLAG_VALID != 0) != (t.flags & FLAG_INSIDE != 0),
            "{t:?}"
        );
        let tri = scene
            .triangles
            .get(t.triangle as usize)
            .unwrap_or_else(|| panic!("{t:?}: no such triangle"));
        assert!(
            lightmap.uv[t.triangle as usize].is_some(),
            "{t:?}: a texel on a triangle without lightmap UVs"
        );
        let [a, p, q] = tri.positions;
        let (lo, hi) = (a.min(p).min(q), a.max(p).max(q));
        let slack = (lo.abs().max(hi.abs()).max_element() * f32::EPSILON * 8.0).max(1e-30);
        let pos = t.position();
        assert!(
            pos.cmpge(lo - slack).all() && pos.cmple(hi + slack).all(),
            "{t:?} lies outside its triangle's box {lo} … {hi}"
        );
    }
}
