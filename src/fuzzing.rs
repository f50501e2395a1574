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
//! | [`scene`] | glTF / GLB / OBJ / TOML bytes | a scene of finite, indexed triangles, or an error naming the file |
//!
//! The structured targets read their input with [`Bytes`], which returns zeros once the
//! input is exhausted, so every byte string is a valid input and short inputs are cheap.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use guidebake::bvh::{Bvh, Preset};
use guidebake::output::journal::{Journal, TileRecord};
use guidebake::output::result_file::{PerTexel, RecordFile, TexelResult};
use guidebake::scene::Scene;
use guidebake::texels::TexelFile;
use guidebake_kernels::estimator::{
    GraybillDeal, IterationVariance, RhoAccumulator, TexelEstimate, Welford, combine_weighted,
    plain_average,
};
use guidebake_kernels::guide::{self, DEFAULT_AMBIENT, GuideParams, Node, Record};
use guidebake_kernels::packet::{Hit, Hit8, LANES, NO_HIT, Ray, Ray8};
use guidebake_kernels::sobol::ONE_MINUS_EPSILON;
use guidebake_kernels::sobol::to_unit;
use guidebake_kernels::traverse::{
    BvhRef, LEAF, Tri, closest_hit_allowed, intersect_brute, intersect1, intersect8,
    occluded_brute, occluded1, occluded8, occlusion_allowed,
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
    ("scene", scene),
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
        static STORAGE: std::cell::RefCell<Vec<Node>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    STORAGE.with_borrow_mut(|storage| {
        storage.clear();
        storage.resize(capacity, Node::default());
        guide_checks(&params, &mut records, count, storage, points);
    });
}

/// [`guide`] after decoding: build into `storage` and check every invariant.
fn guide_checks(
    params: &GuideParams,
    records: &mut [Record],
    count: usize,
    storage: &mut [Node],
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

    let corners: Vec<[_; 3]> = soup.iter().map(|t| t.map(Into::into)).collect();
    let bvh = match Bvh::build_with_binary(&corners, preset) {
        Ok(bvh) => bvh,
        Err(e) => panic!("finite triangles build a BVH: {e}"),
    };
    let Some(view) = bvh.binary() else {
        panic!("build_with_binary keeps the binary tree")
    };
    let tris: Vec<Tri> = corners
        .iter()
        .enumerate()
        .map(|(i, &v)| Tri::new(v, i as u32))
        .collect();
    leaves_cover_their_triangles(&view, &soup);
    let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim));
    let sentinel = Hit {
        t: -7.0,
        u: 0.125,
        v: 0.5,
        prim: NO_HIT - 1,
    };
    for (p, packet) in rays.chunks(LANES).enumerate() {
        let rays8 = Ray8::from_rays(packet);
        let mut hits = Hit8::NONE;
        (0..LANES).for_each(|l| hits.set_lane(l, &sentinel));
        let hit_mask = intersect8(&view, &rays8, &mut hits);
        let blocked = occluded8(&view, &rays8);
        for (l, ray) in packet.iter().enumerate() {
            // Bit for bit brute force, else the contract (kernels' traverse docs, "Hits outside
            // their own box"; in the corpus: `contract-*`).
            let brute = intersect_brute(&tris, ray);
            let allowed =
                |h: Option<Hit>| bits(h) == bits(brute) || closest_hit_allowed(&view, ray, h);
            let scalar = intersect1(&view, ray);
            let n = p * LANES + l;
            assert!(
                allowed(scalar),
                "ray {n}: {ray:?}: {:?} vs brute force {:?}",
                bits(scalar),
                bits(brute)
            );
            let lane = (hit_mask >> l & 1 != 0).then(|| hits.lane(l)).flatten();
            assert!(
                allowed(lane),
                "packet lane {l}: {ray:?}: {:?} vs brute force {:?}",
                bits(lane),
                bits(brute)
            );
            if hit_mask >> l & 1 == 0 {
                assert_eq!(
                    bits(hits.lane(l)),
                    bits(Some(sentinel)),
                    "untouched lane {l}"
                );
            }
            let occluded = occluded_brute(&tris, ray);
            let occlusion_ok = |got: bool| got == occluded || occlusion_allowed(&view, ray, got);
            assert!(occlusion_ok(occluded1(&view, ray)), "ray {ray:?}");
            assert!(
                occlusion_ok(blocked >> l & 1 != 0),
                "packet lane {l}: {ray:?}"
            );
        }
        assert_eq!(
            u32::from(hit_mask) >> packet.len(),
            0,
            "inactive lanes never hit"
        );
        assert_eq!(
            u32::from(blocked) >> packet.len(),
            0,
            "inactive lanes are never blocked"
        );
    }
}

/// The traversal contract is stated on the leaves' boxes (a leaf of a spatial-split BVH holds
/// a clipped part of its triangle), so the builder must not shrink them: every vertex of
/// every triangle lies in the box of a leaf that holds the triangle.
fn leaves_cover_their_triangles(view: &BvhRef<'_>, corners: &[[[f32; 3]; 3]]) {
    let mut covered = vec![[false; 3]; corners.len()];
    for node in view.nodes() {
        for slot in 0..2 {
            if node.meta[slot] == 0 {
                continue;
            }
            let inside = |v: &[f32; 3]| {
                (0..3).all(|a| (node.lo[a][slot]..=node.hi[a][slot]).contains(&v[a]))
            };
            let first = node.child[slot] as usize;
            let count = (node.meta[slot] & !LEAF) as usize;
            for tri in &view.tris()[first..first + count] {
                let prim = tri.prim as usize;
                for (k, v) in corners[prim].iter().enumerate() {
                    covered[prim][k] |= inside(v);
                }
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
