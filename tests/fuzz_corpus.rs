//! Replays the checked-in fuzz corpus (`fuzz/corpus/TARGET/*`) through the same bodies the
//! cargo-fuzz targets run, so every input that once crashed a target stays a regression
//! test on stable Rust. Run the fuzzers themselves with `fuzz/run.sh`.
//!
//! The structured seeds (guide, estimator, traverse, scene, texel_file) are written by
//! `write_seed_corpus` below, so a person can see what each seed holds and rewrite them
//! after a format change:
//! `cargo test --test fuzz_corpus -- --ignored write_seed_corpus`.

use std::path::{Path, PathBuf};

use guidebake::test_support::floor_texel;
use guidebake::texels::{PageRecord, TexelFile, TexelWriter, TileRect};
use guidebake_kernels::testing::Pcg32;
use guidebake_suite::fuzzing::TARGETS;

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus")
}

#[test]
fn every_corpus_input_passes_its_target() {
    let corpus = corpus_dir();
    let mut replayed = 0;
    for (name, body) in TARGETS {
        let dir = corpus.join(name);
        let entries = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: every target keeps a seed corpus: {e}", dir.display()));
        let mut seeds = 0;
        for entry in entries {
            let path = entry.expect("readable corpus directory").path();
            let bytes = std::fs::read(&path).expect("readable corpus file");
            let outcome = std::panic::catch_unwind(|| body(&bytes));
            assert!(
                outcome.is_ok(),
                "fuzz target {name} fails on {}",
                path.display()
            );
            seeds += 1;
        }
        assert!(
            seeds >= 3,
            "{name}: a seed corpus of {seeds} inputs is too small"
        );
        replayed += seeds;
    }
    println!(
        "replayed {replayed} fuzz corpus inputs over {} targets",
        TARGETS.len()
    );
}

/// One input through one body, for a look at a crash or a slow input:
/// `FUZZ_TARGET=prepare FUZZ_INPUT=path cargo test --test fuzz_corpus -- --ignored replay_one --nocapture`.
#[test]
#[ignore = "needs FUZZ_TARGET and FUZZ_INPUT"]
fn replay_one() {
    let target = std::env::var("FUZZ_TARGET").expect("FUZZ_TARGET names a target");
    let input = std::env::var("FUZZ_INPUT").expect("FUZZ_INPUT names a file");
    let (_, body) = TARGETS
        .iter()
        .find(|(name, _)| *name == target)
        .unwrap_or_else(|| panic!("no target {target}"));
    let start = std::time::Instant::now();
    body(&std::fs::read(&input).unwrap());
    println!("{target} {input}: {:.3} s", start.elapsed().as_secs_f64());
}

/// Issue 43 (fixed): the wide walks' fused slab test replaced an infinite inverse direction
/// by `2¹⁰⁰` with a slack of `2⁶⁰`, so along such an axis a ray inside a box's slab got a
/// finite far distance, `(hi − o)·2¹⁰⁰ + 2⁶⁰`, where the binary test's `(hi − o)·∞` is
/// unbounded: a hit farther than that was culled (the `wide` fuzz target found it at once).
/// Rays with an infinite inverse now take the exact slab test (`traverse::slab`). Here: the
/// four inputs the target found (`fuzz/corpus/wide/stand-in-*`), every preset, and a hit at
/// t = 10³⁸ beyond the old reach `(0.25 − 0.1)·2¹⁰⁰ + 2⁶⁰ ≈ 2·10²⁹` on the y axis: the wide
/// walks, single ray and packet, equal the binary walk bit for bit.
#[test]
fn wide_walks_keep_hits_beyond_any_finite_reach_of_an_infinite_inverse() {
    use glam::Vec3;
    use guidebake::bvh::{Bvh, Preset};
    use guidebake_kernels::packet::{Hit, Hit8, LANES, Ray, Ray8};
    use guidebake_kernels::traverse::{Tree, intersect1, intersect8, occluded1, occluded8};

    type Bits = Option<(u32, u32, u32, u32)>;
    fn bits(h: Option<Hit>) -> Bits {
        h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim))
    }
    /// A packet through `tree`: the lanes hit, each lane's hit, the lanes blocked.
    fn packet(tree: &impl Tree, rays: &Ray8) -> (u8, Vec<Bits>, u8) {
        let mut hits = Hit8::NONE;
        let mask = intersect8(tree, rays, &mut hits);
        let lanes = (0..LANES).map(|l| bits(hits.lane(l))).collect();
        (mask, lanes, occluded8(tree, rays))
    }
    /// Every ray through `bvh`'s wide tree, single and in packets of eight, gets the binary
    /// tree's answers bit for bit; returns how many of them hit.
    fn wide_equals_binary(bvh: &Bvh, rays: &[Ray], what: &str) -> usize {
        let (binary, wide) = (
            bvh.binary().expect("built with the binary tree"),
            bvh.wide(),
        );
        let mut hits = 0;
        for lanes in rays.chunks(LANES) {
            let rays8 = Ray8::from_rays(lanes);
            assert_eq!(
                packet(&wide, &rays8),
                packet(&binary, &rays8),
                "{what}: {lanes:?}"
            );
            for ray in lanes {
                let got = intersect1(&wide, ray);
                assert_eq!(bits(got), bits(intersect1(&binary, ray)), "{what}: {ray:?}");
                assert_eq!(
                    occluded1(&wide, ray),
                    occluded1(&binary, ray),
                    "{what}: {ray:?}"
                );
                hits += usize::from(got.is_some());
            }
        }
        hits
    }

    let dir = corpus_dir().join("wide");
    let mut inputs = 0;
    for name in [
        "stand-in-far-origin-1.7e38-y",
        "stand-in-far-origin-1.7e38-z",
        "stand-in-far-origin-3e38",
        "stand-in-tiny-direction-1.5e-33",
    ] {
        let bytes = std::fs::read(dir.join(name)).expect("the issue's inputs are in the corpus");
        let (corners, rays) = guidebake_suite::fuzzing::traverse_input(&bytes);
        let mut hits = 0;
        for preset in Preset::ALL {
            let bvh = Bvh::build_with_binary(&corners, preset).expect("finite triangles");
            hits += wide_equals_binary(&bvh, &rays, &format!("{name} {preset:?}"));
        }
        assert!(hits > 0, "{name}: its rays hit");
        inputs += 1;
    }
    assert_eq!(inputs, 4);

    // A square of side 0.5 in the plane x = 0; a ray from x = −10³⁸ along +x, inside the
    // square's slabs in y and z, with dy = 3·10⁻⁴⁵ and dz = 0 (both inverses overflow).
    let (a, b, c, d) = (
        Vec3::new(0.0, -0.25, -0.25),
        Vec3::new(0.0, 0.25, -0.25),
        Vec3::new(0.0, 0.25, 0.25),
        Vec3::new(0.0, -0.25, 0.25),
    );
    let bvh = Bvh::build_with_binary(&[[a, b, c], [a, c, d]], Preset::FastBuild).unwrap();
    let org = |x: f32| Vec3::new(x, 0.1, 0.05);
    let dir = Vec3::new(1.0, 3e-45, 0.0);
    let rays: Vec<Ray> = [-1e15, -1e30, -1e38, -3e38]
        .map(|x| Ray::new(org(x), dir, 0.0, f32::MAX))
        .to_vec();
    let far = intersect1(&bvh.wide(), &rays[2]).expect("the wide walk hits at 10³⁸");
    assert!(far.t > 9e37, "{far:?}");
    assert!(occluded1(&bvh.wide(), &rays[2]));
    assert_eq!(wide_equals_binary(&bvh, &rays, "square"), rays.len());
}

/// The fuzz/Cargo.toml lists one `[[bin]]` per body here, and every wrapper calls its body:
/// a target added to one place and forgotten in the other fails here, not in a fuzz run.
#[test]
fn every_body_has_a_cargo_fuzz_target() {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let manifest = std::fs::read_to_string(fuzz.join("Cargo.toml")).unwrap();
    for (name, _) in TARGETS {
        assert!(
            manifest.contains(&format!("name = \"{name}\"")),
            "fuzz/Cargo.toml lacks a [[bin]] for {name}"
        );
        let wrapper = std::fs::read_to_string(fuzz.join(format!("fuzz_targets/{name}.rs")))
            .unwrap_or_else(|e| panic!("fuzz/fuzz_targets/{name}.rs: {e}"));
        assert!(
            wrapper.contains(&format!("fuzzing::{name}(data)")),
            "{name}.rs"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Seed writers: the byte layouts are documented on each body in src/fuzzing.rs.

fn write(target: &str, name: &str, bytes: &[u8]) {
    let dir = corpus_dir().join(target);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(name), bytes).unwrap();
}

fn f32s(out: &mut Vec<u8>, values: &[f32]) {
    out.extend(values.iter().flat_map(|v| v.to_le_bytes()));
}

/// The u32 that `sobol::to_unit` maps to `u` (u a multiple of 2^-24 in [0,1)).
fn from_unit(u: f32) -> u32 {
    ((u * 16_777_216.0) as u32) << 8
}

/// A guide input: parameters, raw-flux records, sample points.
fn guide_seed(
    params: [u8; 6],
    capacity: u16,
    records: &[([f32; 2], f32)],
    points: &[[f32; 2]],
) -> Vec<u8> {
    let mut b = params[..5].to_vec();
    let raw_points = params[0] & 2 != 0;
    if params[0] & 1 != 0 {
        b.extend(f32::NAN.to_le_bytes()); // raw α: must be clamped
    } else {
        b.push(params[5]);
    }
    b.extend(capacity.to_le_bytes());
    b.extend((records.len() as u16).to_le_bytes());
    for (u, flux) in records {
        if raw_points {
            f32s(&mut b, u);
        } else {
            b.extend(u.iter().flat_map(|&c| from_unit(c).to_le_bytes()));
        }
        f32s(&mut b, &[*flux]);
    }
    for p in points {
        b.extend(p.iter().flat_map(|&c| from_unit(c).to_le_bytes()));
    }
    b
}

fn write_guide_seeds() {
    let mut rng = Pcg32::new(8, 1);
    let mut point = || [rng.next_f32(), rng.next_f32()];
    let points: Vec<[f32; 2]> = (0..61).map(|_| point()).collect();
    // flags 4: raw flux bits; defaults: ≥4 records, 1% of the flux, depth 10, α 0.25.
    let defaults = [4, 4, 10, 10, 0, 64];
    let disk: Vec<([f32; 2], f32)> = (0..256)
        .map(|_| {
            let u = point();
            let d2 = (u[0] - 0.7).powi(2) + (u[1] - 0.2).powi(2);
            (u, if d2 < 0.01 { 50.0 } else { 0.5 })
        })
        .collect();
    write(
        "guide",
        "disk-and-sky",
        &guide_seed(defaults, 4095, &disk, &points),
    );
    let mut firefly: Vec<([f32; 2], f32)> = (0..64).map(|_| (point(), 0.0)).collect();
    firefly[17].1 = 1e5;
    write(
        "guide",
        "single-firefly",
        &guide_seed(defaults, 4095, &firefly, &points),
    );
    let dark: Vec<([f32; 2], f32)> = (0..64).map(|_| (point(), 0.0)).collect();
    write(
        "guide",
        "all-zero-flux",
        &guide_seed(defaults, 4095, &dark, &points),
    );
    // One point hit 200 times: the split rule runs to the depth cap (19, clamped to 16).
    let spike: Vec<([f32; 2], f32)> = (0..200).map(|_| ([0.3, 0.9], 1.0)).collect();
    write(
        "guide",
        "depth-cap",
        &guide_seed([4, 1, 0, 19, 1, 255], 4095, &spike, &points),
    );
    // Full capacity: 5 nodes for 256 records that want many more.
    write(
        "guide",
        "capacity-5",
        &guide_seed([4, 1, 0, 12, 0, 0], 5, &disk, &points),
    );
    // flags 1|2|4: NaN α, raw points (1.0, −0, NaN rejected or kept), NaN/∞/negative flux.
    let hostile = [
        ([0.5, 0.5], f32::NAN),
        ([1.0, 0.5], 1.0),
        ([-0.0, 0.25], 2.0),
        ([f32::NAN, 0.1], 1.0),
        ([0.1, 0.1], f32::INFINITY),
        ([0.2, 0.2], -3.0),
        ([0.3, 0.3], f32::MAX),
        ([0.31, 0.3], f32::MAX),
        ([0.9, 0.9], 1e-45),
        ([0.6, 0.6], 0.5),
    ];
    write(
        "guide",
        "hostile-records",
        &guide_seed([7, 0, 0, 16, 3, 0], 33, &hostile, &points),
    );
}

/// An estimator input: K, the floor selector, then samples `(batch, rgb)` as raw f32 bits.
fn estimator_seed(k: u8, floor: u8, samples: &[(u8, [f32; 3])]) -> Vec<u8> {
    let mut b = vec![k - 1, floor];
    for (batch, rgb) in samples {
        b.push(0x80 | batch);
        f32s(&mut b, rgb);
    }
    b
}

fn write_estimator_seeds() {
    let mut rng = Pcg32::new(8, 2);
    let noisy: Vec<(u8, [f32; 3])> = (0..128)
        .map(|i| {
            let k = (i % 4) as u8;
            let x = rng.next_f32() * 4.0 / f32::from(k + 1);
            (k, [x, 0.8 * x, 0.5])
        })
        .collect();
    write(
        "estimator",
        "four-iterations",
        &estimator_seed(4, 0, &noisy),
    );
    let nan = f32::NAN;
    let hostile = [
        (0, [1.0, 2.0, 3.0]),
        (0, [nan, 1.0, 1.0]),
        (1, [f32::INFINITY, 0.0, 0.0]),
        (1, [f32::MAX, f32::MAX, f32::MAX]),
        (1, [f32::MAX, 0.0, f32::MAX]),
        (2, [1e-40, 1e-45, 0.0]),
        (2, [-f32::MAX, 1.0, 1.0]),
        (2, [1e5, 1e-4, 1e5]),
        (0, [f32::NEG_INFINITY, 0.0, 0.0]),
    ];
    write("estimator", "nan-inf-huge", &estimator_seed(3, 1, &hostile));
    let all_nan: Vec<(u8, [f32; 3])> = (0..12).map(|i| (i % 3, [nan; 3])).collect();
    write(
        "estimator",
        "no-finite-sample",
        &estimator_seed(3, 0, &all_nan),
    );
    // A noise-free dark batch beside a lit one with a firefly: the floor's case.
    let mut floor: Vec<(u8, [f32; 3])> = (0..32).map(|_| (0, [0.0; 3])).collect();
    floor.extend((0..31).map(|_| (1, [0.5; 3])));
    floor.push((1, [1e5; 3]));
    floor.push((2, [0.25; 3])); // a one-sample batch
    write(
        "estimator",
        "dark-lit-firefly",
        &estimator_seed(3, 255, &floor),
    );
}

/// A traverse input: header, grid triangles, grid rays (`sel` without bit 7) or raw rays.
struct TraverseSeed {
    bytes: Vec<u8>,
}

impl TraverseSeed {
    fn new(preset: u8, scale_exp: i8, offset: u8, flags: u8, tris: &[[[i16; 3]; 3]]) -> Self {
        let mut bytes = vec![
            preset,
            (scale_exp + 20) as u8,
            offset,
            flags,
            tris.len() as u8,
        ];
        for c in tris.iter().flatten().flatten() {
            bytes.extend(c.to_le_bytes());
        }
        Self { bytes }
    }

    /// `tmin` index 0..4 and `tmax` index 0..8 of the tables in `fuzzing::traverse`.
    fn ray(&mut self, tmin: u8, tmax: u8, org: [i16; 3], dir: [i16; 3]) -> &mut Self {
        self.bytes.push(tmin | tmax << 2);
        for c in org.iter().chain(&dir) {
            self.bytes.extend(c.to_le_bytes());
        }
        self
    }

    fn raw_ray(&mut self, tmin: u8, tmax: u8, org: [f32; 3], dir: [f32; 3]) -> &mut Self {
        self.bytes.push(0x80 | tmin | tmax << 2);
        f32s(&mut self.bytes, &org);
        f32s(&mut self.bytes, &dir);
        self
    }
}

/// The cube [−s, s]³ as 12 triangles.
fn cube(s: i16) -> Vec<[[i16; 3]; 3]> {
    let mut tris = Vec::new();
    for axis in 0..3 {
        for side in [-s, s] {
            let corner = |a: i16, b: i16| {
                let mut p = [0i16; 3];
                p[axis] = side;
                p[(axis + 1) % 3] = a;
                p[(axis + 2) % 3] = b;
                p
            };
            tris.push([corner(-s, -s), corner(s, -s), corner(s, s)]);
            tris.push([corner(-s, -s), corner(s, s), corner(-s, s)]);
        }
    }
    tris
}

fn write_traverse_seeds() {
    let mut rng = Pcg32::new(8, 3);
    let mut dir = || std::array::from_fn(|_| (rng.next_u32() >> 16) as i16);
    // Gather packets from the cube's centre (shared origins), corners and edges included.
    let mut inside = TraverseSeed::new(3, -6, 0, 1, &cube(100));
    for i in 0..20 {
        inside.ray(0, 0, [0, 0, 0], dir());
        inside.ray((i % 2) as u8, 2, [0, 0, 0], [1, 1, 1]);
    }
    inside
        .ray(0, 0, [0, 0, 0], [1, 0, 0])
        .ray(0, 0, [0, 0, 0], [1, 1, 0]);
    write("traverse", "cube-gather-packets", &inside.bytes);
    // The same cube 10^6 from the origin, rays skimming its faces and edges.
    let mut far = TraverseSeed::new(4, 0, 3, 0, &cube(100));
    for i in -3..=3i16 {
        far.ray(0, 0, [-200, 100, i * 30], [1, 0, 0]);
        far.ray(0, 1, [-200, 100, 100], [1, 0, i]);
        far.ray(1, 6, [i, -300, i], [0, 1, 0]);
    }
    write("traverse", "far-offset-skimming", &far.bytes);
    // Slivers, zero-area and coincident triangles (ties: the smaller id wins).
    let tris = [
        [[0, 0, 0], [1000, 0, 0], [0, 1, 0]],
        [[0, 0, 0], [1000, 0, 0], [2000, 0, 0]],
        [[0, 0, 0], [0, 0, 0], [0, 0, 0]],
        [[-50, -50, 10], [50, -50, 10], [0, 50, 10]],
        [[-50, -50, 10], [50, -50, 10], [0, 50, 10]],
        [[50, -50, 10], [-50, -50, 10], [0, 50, 10]],
    ];
    let mut slivers = TraverseSeed::new(0, -10, 1, 0, &tris);
    for x in [-1, 0, 1, 500, 999, 1000] {
        slivers.ray(0, 0, [x, 0, -5], [0, 0, 1]);
        slivers.ray(0, 0, [x, 0, 20], [0, 0, -1]);
    }
    slivers.ray(0, 0, [-100, 0, 10], [1, 0, 0]);
    slivers.ray(0, 5, [0, 0, 9], [0, 0, 1]);
    write("traverse", "slivers-and-ties", &slivers.bytes);
    // Rays that must not be traced, and NaN boxes; tiny world at 2^-20.
    let mut hostile = TraverseSeed::new(5, -20, 0, 0, &cube(3));
    hostile.raw_ray(0, 0, [f32::NAN, 0.0, 0.0], [0.0, 0.0, 1.0]);
    hostile.raw_ray(0, 0, [0.0, 0.0, 0.0], [f32::INFINITY, 0.0, 0.0]);
    hostile.raw_ray(0, 0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
    hostile.raw_ray(0, 0, [0.0, 0.0, 0.0], [1e-40, 0.0, 0.0]);
    hostile.raw_ray(3, 4, [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
    hostile.raw_ray(2, 0, [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
    hostile.raw_ray(0, 7, [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
    hostile.raw_ray(0, 1, [-3e38, 0.0, 0.0], [1.0, 1e-30, 0.0]);
    hostile.ray(0, 0, [0, 0, 0], [0, 0, 1]);
    write("traverse", "untraceable-rays", &hostile.bytes);
    write(
        "traverse",
        "empty-scene",
        &TraverseSeed::new(2, 0, 0, 0, &[])
            .ray(0, 0, [0, 0, 0], [0, 0, 1])
            .bytes,
    );
}

/// One triangle with lightmap UVs, its buffer inline as a data URI: a self-contained glTF.
fn triangle_gltf() -> String {
    let mut bin = Vec::new();
    f32s(&mut bin, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
    f32s(&mut bin, &[0.1, 0.1, 0.9, 0.1, 0.1, 0.9]);
    bin.extend([0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
"nodes": [{{"name": "tri", "mesh": 0, "translation": [0, 1, 0]}}],
"materials": [{{"pbrMetallicRoughness": {{"baseColorFactor": [0.5, 0.5, 0.5, 1]}}, "emissiveFactor": [1, 0.5, 0]}}],
"meshes": [{{"name": "tri", "primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_1": 1}}, "indices": 2, "material": 0}}]}}],
"accessors": [
 {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,-1], "max": [1,0,0]}},
 {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}},
 {{"bufferView": 2, "componentType": 5125, "count": 3, "type": "SCALAR"}}],
"bufferViews": [
 {{"buffer": 0, "byteOffset": 0, "byteLength": 36}},
 {{"buffer": 0, "byteOffset": 36, "byteLength": 24}},
 {{"buffer": 0, "byteOffset": 60, "byteLength": 12}}],
"buffers": [{{"byteLength": 72, "uri": "data:application/octet-stream;base64,{}"}}]}}"#,
        base64(&bin)
    )
}

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = c
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, &b)| n | u32::from(b) << (16 - 8 * i));
        for i in 0..4 {
            s.push(if i <= c.len() {
                A[(n >> (18 - 6 * i) & 63) as usize] as char
            } else {
                '='
            });
        }
    }
    s
}

fn write_scene_seeds() {
    // The format byte: 0 .gltf, 1 .glb, 2 .obj, 3 .toml.
    let with = |format: u8, body: &[u8]| [&[format][..], body].concat();
    write(
        "scene",
        "triangle.gltf",
        &with(0, triangle_gltf().as_bytes()),
    );
    let obj = "mtllib none.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
               vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\nf 1 1 2\n";
    write("scene", "quad.obj", &with(2, obj.as_bytes()));
    let toml = "geometry = \"missing.glb\"\n[sky]\nconstant = [0.5, 0.6, 0.8]\n\
                [sun]\ndirection = [0.3, 1.0, 0.2]\nangular_radius_deg = 0.267\nirradiance = [4, 3.8, 3.5]\n";
    write("scene", "scene.toml", &with(3, toml.as_bytes()));
    // The real Cornell box (CC0, Bitterli; ../shared/scenes/converted), when present.
    let cornell = guidebake::test_support::shared_scenes_dir()
        .map(|d| d.join("converted/bitterli_cornell_box.glb"));
    match cornell.and_then(|p| std::fs::read(p).ok()) {
        Some(glb) => write("scene", "bitterli-cornell-box.glb", &with(1, &glb)),
        None => println!("../shared/scenes absent: the Cornell box seed is kept as it is"),
    }
}

/// The small valid texel file of driver/tests/bad_input.rs: one 8×8 page, two tiles.
fn two_tile_texels(path: &Path) {
    let page = PageRecord {
        width: 8,
        height: 8,
    };
    let mut w = TexelWriter::create(path, &[page], &[], 1.0).unwrap();
    let texel = floor_texel;
    let rect = |y| TileRect {
        page: 0,
        x: 0,
        y,
        width: 8,
        height: 4,
    };
    w.push_tile(rect(0), &(0..8).map(|x| texel(x, 0)).collect::<Vec<_>>())
        .unwrap();
    w.push_tile(rect(4), &(0..4).map(|x| texel(x, 5)).collect::<Vec<_>>())
        .unwrap();
    w.finish().unwrap();
}

fn write_texel_file_seeds() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small.texels");
    two_tile_texels(&small);
    let bytes = std::fs::read(&small).unwrap();
    write("texel_file", "two-tiles", &bytes);
    write(
        "texel_file",
        "two-tiles-truncated",
        &bytes[..bytes.len() - 10],
    );
    let city = dir.path().join("city.texels");
    guidebake::synth::synth(guidebake::synth::MIN_TEXELS, &city).unwrap();
    TexelFile::open(&city).unwrap();
    write("texel_file", "synth-min", &std::fs::read(&city).unwrap());
}

/// A prepare input (layout on `fuzzing::prepare`): header, vertices, triangles as
/// (three indices, selector byte, extra bytes), then the swarm's bytes.
struct PrepareSeed {
    bytes: Vec<u8>,
}

impl PrepareSeed {
    /// `flags`: unwrap mode (bits 0–1), layout (2–3), swarm (4), loose swarm (5);
    /// `res`, `res2`: the resolution selector and its argument; `scale_exp` −20…20.
    fn new(flags: u8, res: u8, res2: u8, scale_exp: i8, offset: u8, verts: &[[i16; 3]]) -> Self {
        let mut bytes = vec![
            flags,
            res,
            res2,
            (scale_exp + 20) as u8,
            offset,
            verts.len() as u8,
        ];
        for c in verts.iter().flatten() {
            bytes.extend(c.to_le_bytes());
        }
        Self { bytes }
    }

    /// Triangles: indices and selector (bit 0 new mesh, bits 1–2 UVs: 2 projected, 3 raw
    /// i8 pairs, bit 3 raw normal), and the selector's extra bytes.
    fn tris(&mut self, tris: &[([u8; 3], u8, &[u8])]) -> &mut Self {
        self.bytes.push(tris.len() as u8);
        for (idx, sel, extra) in tris {
            self.bytes.extend(idx);
            self.bytes.push(*sel);
            self.bytes.extend(*extra);
        }
        self
    }

    fn swarm(&mut self, count: u16, side_exp: u8, columns: u8) -> &mut Self {
        self.bytes.extend(count.to_le_bytes());
        self.bytes.extend([side_exp - 4, columns - 1]);
        self
    }
}

/// A `prepare` input's triangle: vertex indices, selector and the selector's extra bytes
/// (`PrepareSeed::tris`).
type FuzzTriangle = ([u8; 3], u8, &'static [u8]);

/// The unit cube's corners (times `s`) and its 12 triangles, welded, wound outwards.
fn cube_mesh(s: i16, sel: u8) -> (Vec<[i16; 3]>, Vec<FuzzTriangle>) {
    let verts: Vec<[i16; 3]> = (0..8)
        .map(|i| {
            [
                (i & 1) as i16 * s,
                (i >> 1 & 1) as i16 * s,
                (i >> 2 & 1) as i16 * s,
            ]
        })
        .collect();
    let faces: [[u8; 4]; 6] = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let tris = faces
        .iter()
        .flat_map(|f| {
            [
                ([f[0], f[1], f[2]], sel, &[][..]),
                ([f[0], f[2], f[3]], sel, &[][..]),
            ]
        })
        .collect();
    (verts, tris)
}

fn write_prepare_seeds() {
    // A unit cube without UVs, unwrapped by xatlas at 64² texels for its area.
    let (verts, tris) = cube_mesh(1024, 0);
    write(
        "prepare",
        "cube-unwrapped",
        &PrepareSeed::new(0, 1, 9, -10, 0, &verts).tris(&tris).bytes,
    );
    // The same cube 10⁶ from the origin, every mesh unwrapped at 1024 texels for its area.
    write(
        "prepare",
        "cube-far-away",
        &PrepareSeed::new(1, 1, 10, 0, 3, &verts).tris(&tris).bytes,
    );
    // A quad with projected lightmap UVs beside the cube without (shared layout, a 32² page).
    let mut mixed = tris.clone();
    mixed[0].1 = 1;
    let quad = [([0, 1, 3], 1 | 4, &[][..]), ([0, 3, 2], 4, &[][..])];
    let mut seed = PrepareSeed::new(0, 2, 0x88, -10, 0, &verts);
    seed.tris(&[&quad[..], &tris[..]].concat());
    write("prepare", "uv-quad-and-unwrapped-cube", &seed.bytes);
    // Degenerate and non-manifold: repeated indices, a fin of four triangles on one edge,
    // a NaN vertex, raw normals (zero, NaN).
    let hostile_verts = [
        [0, 0, 0],
        [1000, 0, 0],
        [0, 1000, 0],
        [0, -1000, 0],
        [0, 0, 1000],
        [0, 0, -1000],
        [i16::MIN, 0, 0],
        [-32767, 5, 5],
    ];
    let zero = [0u8; 12];
    let nan = [0xff_u8; 12];
    let hostile = [
        ([0, 1, 2], 0, &[][..]),
        ([0, 1, 3], 0, &[][..]),
        ([0, 1, 4], 0, &[][..]),
        ([0, 1, 5], 8, &zero[..]),
        ([1, 1, 2], 8, &nan[..]),
        ([2, 2, 2], 0, &[][..]),
        ([0, 1, 6], 0, &[][..]),
        ([0, 2, 7], 0, &[][..]),
    ];
    write(
        "prepare",
        "degenerate-non-manifold-nan",
        &PrepareSeed::new(1, 1, 10, -10, 0, &hostile_verts)
            .tris(&hostile)
            .bytes,
    );
    // The same without its NaN and ∞ vertices, so xatlas charts it.
    write(
        "prepare",
        "degenerate-non-manifold",
        &PrepareSeed::new(1, 1, 10, -10, 0, &hostile_verts)
            .tris(&hostile[..6])
            .bytes,
    );
    // 2048 welded triangles of side 2⁻⁸ beside the cube, and 2000 loose ones of 2⁻¹²
    // (below xatlas's area threshold).
    write(
        "prepare",
        "tiny-triangle-grid",
        &PrepareSeed::new(16, 1, 9, -10, 0, &verts)
            .tris(&tris)
            .swarm(2048, 8, 64)
            .bytes,
    );
    write(
        "prepare",
        "tiny-loose-triangles",
        &PrepareSeed::new(16 | 32, 1, 10, -10, 0, &[])
            .tris(&[])
            .swarm(2000, 12, 50)
            .bytes,
    );
    // Raw UVs outside 0…1 and out-of-range densities and sizes.
    let raw_uv: [u8; 6] = [0x80, 0x80, 0x7f, 0x00, 0x10, 0x7f];
    let outside = [([0, 1, 2], 6, &raw_uv[..]), ([1, 3, 2], 6, &raw_uv[..])];
    let square = [[0, 0, 0], [512, 0, 0], [0, 512, 0], [512, 512, 0]];
    for (name, res, res2) in [
        ("uvs-outside-the-square", 2, 0x88),
        ("density-nan", 1, 2),
        ("page-too-large", 2, 0xdd),
    ] {
        write(
            "prepare",
            name,
            &PrepareSeed::new(2, res, res2, -10, 0, &square)
                .tris(&outside)
                .bytes,
        );
    }
}

#[test]
#[ignore = "rewrites fuzz/corpus: cargo test --test fuzz_corpus -- --ignored write_seed_corpus"]
fn write_seed_corpus() {
    write_guide_seeds();
    write_estimator_seeds();
    write_traverse_seeds();
    write_scene_seeds();
    write_texel_file_seeds();
    write_prepare_seeds();
}
