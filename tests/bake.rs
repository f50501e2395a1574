//! End-to-end bakes through the texel file, the pipeline and the EXR pages: the analytic
//! value survives the whole chain, and the output is the same bits for any thread count,
//! shard split, or an interruption followed by `--resume`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use glam::{Vec2, Vec3};
use guidebake::bake::directional::Directional;
use guidebake::bake::finish::{FinishOptions, finish, merge_pass};
use guidebake::bake::run::{BakeError, BakeJob, bake, bake_pass_with_progress};
use guidebake::bake::settings::{
    BakeSettings, Budget, Combine, EmitterSampling, Guiding, Transport,
};
use guidebake::bake::shard::Shard;
use guidebake::bake::workdir::{merged_results, work_dir};
use guidebake::output::readback::read_channel;
use guidebake::scene::{Material, Mesh, Scene, Sky, Triangle};
use guidebake::test_support::{inward_box_faces, triangles_on_page};
use guidebake::texels::{
    FLAG_VALID, PageRecord, SEEN_FRONT, TexelFile, TexelRecord, TexelWriter, TileRect,
};

const SKY: f32 = 0.75;
const SIDE: u32 = 24; // page side in texels: 9 tiles of 8×8
const TILE: u32 = 8;
const TILES: usize = 9;
/// Series passes of the fixture's default bake after its direct pass 0: one per bounce.
const PASSES: usize = 3;
/// Passes over the world of the fixture's default bake: the direct pass and [`PASSES`].
const RUNS: usize = PASSES + 1;

/// A 4 m square ground plane under a constant sky, mapped 1:1 onto one page.
fn plane_scene() -> Scene {
    let n = Vec3::Z;
    let p = |x: f32, y: f32| Vec3::new(x * 4.0 - 2.0, y * 4.0 - 2.0, 0.0);
    let tri = |a: Vec2, b: Vec2, c: Vec2| Triangle {
        positions: [p(a.x, a.y), p(b.x, b.y), p(c.x, c.y)],
        normals: [n; 3],
        lightmap_uv: Some([a, b, c]),
        texture_uv: None,
        colour: None,
        mesh: 0,
        material: 0,
    };
    let (o, x, y, xy) = (Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE);
    Scene {
        path: PathBuf::from("<plane>"),
        meshes: vec![Mesh {
            name: "ground".into(),
            first_triangle: 0,
            triangle_count: 2,
            has_lightmap_uvs: true,
        }],
        triangles: vec![tri(o, x, xy), tri(o, xy, y)],
        materials: vec![Material {
            name: "grey".into(),
            base_color_texture: None,
            albedo: Vec3::splat(0.5),
            emission: Vec3::ZERO,
        }],
        lights: Vec::new(),
        sun: None,
        sky: Sky::Constant(Vec3::splat(SKY)),
        degenerate_triangles: 0,
        roles: Vec::new(),
    }
}

/// The plane's texel file, written tile by tile.
fn write_texels(path: &Path) {
    let page = PageRecord {
        width: SIDE,
        height: SIDE,
    };
    let triangles = triangles_on_page(&plane_scene(), page, SEEN_FRONT);
    let mut writer = TexelWriter::create(path, &[page], &triangles, SIDE as f32 / 4.0).unwrap();
    let size = 4.0 / SIDE as f32;
    for ty in 0..SIDE / TILE {
        for tx in 0..SIDE / TILE {
            let texels: Vec<TexelRecord> = (0..TILE * TILE)
                .map(|i| {
                    let (x, y) = (tx * TILE + i % TILE, ty * TILE + i / TILE);
                    TexelRecord {
                        position: [
                            (x as f32 + 0.5) * size - 2.0,
                            (y as f32 + 0.5) * size - 2.0,
                            0.0,
                        ],
                        normal: [0.0, 0.0, 1.0],
                        dpdu: [size, 0.0, 0.0],
                        dpdv: [0.0, size, 0.0],
                        page: 0,
                        pixel: [x as u16, y as u16],
                        triangle: 0,
                        flags: FLAG_VALID,
                    }
                })
                .collect();
            let rect = TileRect {
                page: 0,
                x: tx * TILE,
                y: ty * TILE,
                width: TILE,
                height: TILE,
            };
            writer.push_tile(rect, &texels).unwrap();
        }
    }
    writer.finish().unwrap();
}

struct Fixture {
    dir: tempfile::TempDir,
    scene: Scene,
}

impl Fixture {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        write_texels(&dir.path().join("plane.texels"));
        Fixture {
            dir,
            scene: plane_scene(),
        }
    }

    fn job(&self, out: &str, threads: usize, shard: Shard) -> BakeJob {
        BakeJob {
            texels: self.dir.path().join("plane.texels"),
            out: self.dir.path().join(out),
            settings: BakeSettings {
                spp: 64,
                iterations: 2,
                guiding: Guiding::Coherent,
                transport: Transport::Series,
                bounces: PASSES as u32,
                ..Default::default()
            },
            threads,
            shard,
            resume: false,
            aux: true,
            finish: FinishOptions::default(),
        }
    }

    fn run(
        &self,
        job: &BakeJob,
        cancel_after: Option<u64>,
    ) -> Result<guidebake::bake::run::BakeReport, BakeError> {
        let cancel = AtomicBool::new(false);
        bake(job, &self.scene, &cancel, &mut |done, _| {
            if cancel_after.is_some_and(|n| done >= n) {
                cancel.store(true, Ordering::Relaxed);
            }
        })
    }
}

fn exr_bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn a_plane_under_the_sky_bakes_to_pi_l_in_the_exr() {
    let f = Fixture::new();
    let job = f.job("lm.exr", 2, Shard::WHOLE);
    let report = f.run(&job, None).unwrap();
    assert_eq!(
        report.tiles_baked,
        TILES * RUNS,
        "every tile in every series pass"
    );
    assert_eq!(report.passes, RUNS as u32);
    assert!(!report.interrupted);
    // The passes before the last take the lookups' share of the rays.
    let lookup = u64::from(job.settings.default_lookup_spp());
    assert!(lookup < 64);
    assert_eq!(
        report.counters.gather_rays,
        u64::from(SIDE * SIDE) * (64 + lookup * (PASSES as u64 - 1)),
        "gather rays in every pass but the direct one"
    );
    assert!(
        !work_dir(&job.out, Shard::WHOLE).exists(),
        "a finished bake removes its work"
    );
    let values = channel(&job.out, "R");
    assert_eq!(values.len(), (SIDE * SIDE) as usize);
    let mean = values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len() as f64;
    let want = f64::from(SKY) * std::f64::consts::PI;
    assert!(
        (mean - want).abs() < 0.01 * want,
        "mean irradiance {mean}, want πL = {want}"
    );
    assert!(values.iter().all(|v| v.is_finite() && *v > 0.0));
}

#[test]
fn one_or_two_threads_write_the_same_bits() {
    let f = Fixture::new();
    f.run(&f.job("one.exr", 1, Shard::WHOLE), None).unwrap();
    f.run(&f.job("two.exr", 2, Shard::WHOLE), None).unwrap();
    assert_eq!(
        exr_bytes(&f.dir.path().join("one.exr")),
        exr_bytes(&f.dir.path().join("two.exr"))
    );
}

#[test]
fn three_shards_merged_equal_one_bake() {
    let f = Fixture::new();
    for directional in [Directional::None, Directional::ShL1] {
        let path = |mut job: BakeJob| {
            job.settings.transport = Transport::Path;
            job.settings.directional = directional;
            job
        };
        let whole = f.dir.path().join(format!("whole-{directional}.exr"));
        let name = |what: &str| format!("{what}-{directional}.exr");
        f.run(&path(f.job(&name("whole"), 2, Shard::WHOLE)), None)
            .unwrap();
        let mut dirs = Vec::new();
        for index in [1, 2, 0] {
            let job = path(f.job(&name("sharded"), 1, Shard { index, count: 3 }));
            let report = f.run(&job, None).unwrap();
            assert_eq!(report.tiles_baked, 3);
            dirs.push(work_dir(&job.out, job.shard));
        }
        let texels = TexelFile::open(&f.dir.path().join("plane.texels")).unwrap();
        let merged = f.dir.path().join(name("sharded"));
        let err = finish(&texels, &dirs[..2], &merged)
            .unwrap_err()
            .to_string();
        assert!(err.contains("shards") && err.contains("0..3"), "{err}");
        finish(&texels, &dirs, &merged).unwrap();
        assert_eq!(exr_bytes(&whole), exr_bytes(&merged), "{directional}");
    }
}

/// Shards own contiguous runs of tiles (`bake/shard.rs`); a work directory that holds another
/// shard's tiles — one split by an older guidebake, which split tiles modulo the shard count —
/// is refused by the merge instead of merged from the wrong files.
#[test]
fn shards_split_another_way_are_refused() {
    let f = Fixture::new();
    let mut dirs = Vec::new();
    for index in 0..3 {
        let mut job = f.job("split.exr", 1, Shard { index, count: 3 });
        job.settings.transport = Transport::Path;
        let report = f.run(&job, None).unwrap();
        assert_eq!(report.tiles_baked, 3);
        dirs.push(work_dir(&job.out, job.shard));
    }
    let texels = TexelFile::open(&f.dir.path().join("plane.texels")).unwrap();
    // Shards 0 and 1 swap their manifests: each now claims the other's tiles.
    let (m0, m1) = (dirs[0].join("manifest.json"), dirs[1].join("manifest.json"));
    let (b0, b1) = (std::fs::read(&m0).unwrap(), std::fs::read(&m1).unwrap());
    std::fs::write(&m0, b1).unwrap();
    std::fs::write(&m1, b0).unwrap();
    let out = f.dir.path().join("split.exr");
    let err = finish(&texels, &dirs, &out).unwrap_err().to_string();
    assert!(
        err.contains("split another way")
            && err.contains("shard 0 of 3 holds tile 3, which shard 1 owns"),
        "{err}"
    );
    assert!(!out.exists(), "no pages from a refused merge");
}

#[test]
fn series_shards_must_name_their_pass() {
    let f = Fixture::new();
    let job = f.job("s.exr", 1, Shard { index: 0, count: 2 });
    let err = f.run(&job, None).unwrap_err().to_string();
    assert!(
        err.contains("--shard 0/2") && err.contains("bake --pass B --shard 0/2"),
        "{err}"
    );
    for pass in [PASSES as u32 + 1, 7] {
        let err = bake_pass(&job, pass, &f.scene).unwrap_err().to_string();
        assert!(
            err.contains(&format!("--pass {pass}")) && err.contains("0..=3"),
            "{err}"
        );
    }
    let err = bake_pass(&job, 2, &f.scene).unwrap_err().to_string();
    assert!(
        err.contains("pass 1 is not merged") && err.contains("merge --pass 1"),
        "{err}"
    );
}

/// Bakes pass `pass` of `job` alone (`bake --pass`).
fn bake_pass(
    job: &BakeJob,
    pass: u32,
    scene: &Scene,
) -> Result<guidebake::bake::run::BakeReport, BakeError> {
    bake_pass_with_progress(job, Some(pass), scene, &AtomicBool::new(false), &mut |_| {})
}

/// Bakes `job` pass by pass in `count` shards (shards in a scrambled order), merging each
/// pass, and returns the final lightmap's path.
/// An unsharded bake of `texels` into `out` on `threads` threads, with the auxiliary channels.
fn whole_job(texels: &Path, out: PathBuf, threads: usize, settings: BakeSettings) -> BakeJob {
    BakeJob {
        texels: texels.to_path_buf(),
        out,
        settings,
        threads,
        shard: Shard::WHOLE,
        resume: false,
        aux: true,
        finish: FinishOptions::default(),
    }
}

/// Bakes `job(out, threads)` on one thread, on two, and in three shards pass by pass, asserts
/// the three lightmaps are the same bytes and returns the one-thread job (baked).
fn same_bits_however_split(job: impl Fn(&str, usize) -> BakeJob, scene: &Scene) -> BakeJob {
    let run = |job: &BakeJob| bake(job, scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
    let (one, two) = (job("one.exr", 1), job("two.exr", 2));
    run(&one);
    run(&two);
    assert_eq!(exr_bytes(&one.out), exr_bytes(&two.out));
    let sharded = bake_sharded_passes(&job("sharded.exr", 2), 3, scene);
    assert_eq!(exr_bytes(&one.out), exr_bytes(&sharded));
    one
}

fn bake_sharded_passes(job: &BakeJob, count: u32, scene: &Scene) -> PathBuf {
    let texels = TexelFile::open(&job.texels).unwrap();
    let passes = job.settings.last_pass();
    for pass in job.settings.first_pass()..=passes {
        let mut dirs = Vec::new();
        for index in (0..count).rev() {
            let shard = BakeJob {
                shard: Shard { index, count },
                ..job.clone()
            };
            let report = bake_pass(&shard, pass, scene).unwrap();
            assert_eq!(report.passes, 1);
            assert!(report.pages.is_empty(), "a pass of a shard writes no pages");
            dirs.push(work_dir(&shard.out, shard.shard));
        }
        if pass < passes {
            let merged = merge_pass(&texels, &dirs, &job.out, pass).unwrap();
            assert_eq!(merged, merged_results(&job.out, pass));
            let err = merge_pass(&texels, &dirs[1..], &job.out, pass).unwrap_err();
            assert!(err.to_string().contains("shards"), "{err}");
        } else {
            let err = merge_pass(&texels, &dirs, &job.out, pass).unwrap_err();
            assert!(err.to_string().contains("into pages"), "{err}");
            finish(&texels, &dirs, &job.out).unwrap();
        }
    }
    job.out.clone()
}

#[test]
fn series_passes_sharded_pass_by_pass_merge_to_the_same_bits() {
    let (albedo, le) = (0.5f32, 1.5f32);
    let dir = tempfile::tempdir().unwrap();
    let texels = dir.path().join("box.texels");
    let scene = emissive_box(&texels, albedo, le);
    // Graybill–Deal per texel with ρ, and Müller's global weights: 3 bounces, 3 shards.
    for (name, combine, bias_correction) in [
        ("texel", Combine::Texel, true),
        ("global", Combine::Global, false),
    ] {
        let job = |out: &str| BakeJob {
            texels: texels.clone(),
            out: dir.path().join(out),
            settings: BakeSettings {
                spp: 64,
                iterations: 3,
                combine,
                bias_correction,
                transport: Transport::Series,
                bounces: 3,
                // Every cluster guided, so the last pass combines iterations and ρ has
                // something to correct (a flat cluster bakes one set: ρ 1).
                flat_below: 0,
                ..Default::default()
            },
            threads: 2,
            shard: Shard::WHOLE,
            resume: false,
            aux: true,
            finish: FinishOptions::default(),
        };
        let whole = job(&format!("{name}-whole.exr"));
        let report = bake(&whole, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
        assert_eq!(report.passes, 4, "the direct pass and 3 bounces");
        if bias_correction {
            assert_ne!(report.rho, 1.0, "ρ is applied");
        }
        let sharded = bake_sharded_passes(&job(&format!("{name}-sharded.exr")), 3, &scene);
        assert_eq!(exr_bytes(&whole.out), exr_bytes(&sharded), "{name}");
        assert_eq!(
            exr_bytes(&whole.out.with_extension("atlas.png")),
            exr_bytes(&sharded.with_extension("atlas.png")),
            "{name}"
        );
    }
}

#[test]
fn a_pass_run_resumes_and_continues_its_work_directory() {
    let f = Fixture::new();
    let whole = f.job("whole.exr", 1, Shard::WHOLE);
    f.run(&whole, None).unwrap();
    let texels = TexelFile::open(&whole.texels).unwrap();
    let out = f.dir.path().join("passes.exr");
    let cancel = AtomicBool::new(false);
    // `--pass B` without `--shard`: one work directory that every pass continues.
    let mut job = f.job("passes.exr", 1, Shard::WHOLE);
    let dirs = [work_dir(&job.out, job.shard)];
    for pass in 0..=PASSES as u32 {
        job.resume = false;
        if pass == 2 {
            // One worker and a window of 4 tiles: cut after the first tile, refused without
            // --resume, resumed.
            let cut = bake_pass_with_progress(&job, Some(pass), &f.scene, &cancel, &mut |p| {
                cancel.store(p.texels_done >= 64, Ordering::Relaxed);
            })
            .unwrap();
            cancel.store(false, Ordering::Relaxed);
            assert!(cut.interrupted && cut.tiles_baked < TILES, "{cut:?}");
            let again = bake_pass(&job, pass, &f.scene).unwrap_err();
            assert!(matches!(again, BakeError::WorkExists { .. }), "{again}");
            job.resume = true;
            let rest = bake_pass(&job, pass, &f.scene).unwrap();
            assert_eq!(rest.tiles_resumed, cut.tiles_baked);
            assert_eq!(rest.tiles_baked + cut.tiles_baked, TILES);
        } else {
            assert_eq!(bake_pass(&job, pass, &f.scene).unwrap().tiles_baked, TILES);
        }
        // A finished pass rerun with --resume (a scheduler's retry) bakes nothing.
        job.resume = true;
        assert_eq!(bake_pass(&job, pass, &f.scene).unwrap().tiles_baked, 0);
        if pass < PASSES as u32 {
            merge_pass(&texels, &dirs, &out, pass).unwrap();
        } else {
            finish(&texels, &dirs, &out).unwrap();
        }
    }
    assert_eq!(exr_bytes(&whole.out), exr_bytes(&out));
}

#[test]
fn an_interrupted_bake_resumes_to_the_same_bits_and_is_never_clobbered() {
    let f = Fixture::new();
    // With directional coefficients: their file resumes with the results.
    let directional = |mut job: BakeJob| {
        job.settings.directional = Directional::ShL1;
        job
    };
    f.run(&directional(f.job("whole.exr", 2, Shard::WHOLE)), None)
        .unwrap();
    let pass_texels = u64::from(SIDE * SIDE);
    // One worker and a window of 4 tiles: cancelling after the first tile of a pass leaves
    // most of that pass undone. Cut in the first pass, then in the second.
    for (name, cut_after) in [("first.exr", 64), ("second.exr", pass_texels + 64)] {
        let mut job = directional(f.job(name, 1, Shard::WHOLE));
        let cut = f.run(&job, Some(cut_after)).unwrap();
        assert!(cut.interrupted && cut.tiles_baked < TILES * RUNS, "{cut:?}");
        assert!(
            !job.out.exists(),
            "an interrupted bake leaves no output that looks complete"
        );
        let again = f.run(&job, None).unwrap_err();
        assert!(matches!(again, BakeError::WorkExists { .. }), "{again}");
        job.resume = true;
        let rest = f.run(&job, None).unwrap();
        assert_eq!(rest.tiles_resumed, cut.tiles_baked, "{name}");
        assert_eq!(cut.tiles_baked + rest.tiles_baked, TILES * RUNS, "{name}");
        assert_eq!(
            exr_bytes(&f.dir.path().join("whole.exr")),
            exr_bytes(&job.out),
            "{name}"
        );
    }
}

#[test]
fn a_scene_that_does_not_match_the_texel_file_is_refused() {
    let f = Fixture::new();
    let mut other = plane_scene();
    other.triangles.pop();
    let cancel = AtomicBool::new(false);
    let err = bake(
        &f.job("x.exr", 1, Shard::WHOLE),
        &other,
        &cancel,
        &mut |_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("2 triangles") && err.contains("has 1"),
        "{err}"
    );
}

/// Texels per face edge of the closed box; faces are charts in a 3×2 grid on one page.
const FACE: u32 = 8;

/// A closed 2 m cube, every face facing inwards, of albedo `albedo` emitting `le`, with one
/// lightmap chart per face, and its texel file at `path`.
fn emissive_box(path: &Path, albedo: f32, le: f32) -> Scene {
    let s = 2.0;
    let faces = inward_box_faces(Vec3::splat(-1.0), s);
    let (w, h) = (3 * FACE, 2 * FACE);
    let chart = |i: usize| ((i % 3) as u32 * FACE, (i / 3) as u32 * FACE);
    let mut triangles = Vec::new();
    for (i, &(c, u, v)) in faces.iter().enumerate() {
        let n = u.cross(v).normalize();
        let (cx, cy) = chart(i);
        let uv = |a: f32, b: f32| {
            Vec2::new(
                (cx as f32 + a * FACE as f32) / w as f32,
                (cy as f32 + b * FACE as f32) / h as f32,
            )
        };
        let tri = |p: [Vec3; 3], q: [Vec2; 3]| Triangle {
            positions: p,
            normals: [n; 3],
            lightmap_uv: Some(q),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        triangles.push(tri(
            [c, c + u, c + u + v],
            [uv(0.0, 0.0), uv(1.0, 0.0), uv(1.0, 1.0)],
        ));
        triangles.push(tri(
            [c, c + u + v, c + v],
            [uv(0.0, 0.0), uv(1.0, 1.0), uv(0.0, 1.0)],
        ));
    }
    let page = PageRecord {
        width: w,
        height: h,
    };
    let scene = Scene {
        path: PathBuf::from("<box>"),
        meshes: vec![Mesh {
            name: "box".into(),
            first_triangle: 0,
            triangle_count: 12,
            has_lightmap_uvs: true,
        }],
        triangles,
        materials: vec![Material {
            name: "glow".into(),
            base_color_texture: None,
            albedo: Vec3::splat(albedo),
            emission: Vec3::splat(le),
        }],
        lights: Vec::new(),
        sun: None,
        sky: Sky::Constant(Vec3::splat(100.0)),
        degenerate_triangles: 0,
        roles: Vec::new(),
    };
    let records = triangles_on_page(&scene, page, SEEN_FRONT);
    let mut writer = TexelWriter::create(path, &[page], &records, FACE as f32 / s).unwrap();
    for (i, &(c, u, v)) in faces.iter().enumerate() {
        let n = u.cross(v).normalize();
        let (cx, cy) = chart(i);
        let texels: Vec<TexelRecord> = (0..FACE * FACE)
            .map(|j| {
                let (fx, fy) = ((j % FACE) as f32 + 0.5, (j / FACE) as f32 + 0.5);
                let p = c + u * (fx / FACE as f32) + v * (fy / FACE as f32);
                TexelRecord {
                    position: p.to_array(),
                    normal: n.to_array(),
                    dpdu: (u / FACE as f32).to_array(),
                    dpdv: (v / FACE as f32).to_array(),
                    page: 0,
                    pixel: [(cx + j % FACE) as u16, (cy + j / FACE) as u16],
                    triangle: 2 * i as u32 + u32::from(fy > fx),
                    flags: FLAG_VALID,
                }
            })
            .collect();
        let rect = TileRect {
            page: 0,
            x: cx,
            y: cy,
            width: FACE,
            height: FACE,
        };
        writer.push_tile(rect, &texels).unwrap();
    }
    writer.finish().unwrap();
    scene
}

/// The closed box of [`emissive_box`] (albedo 0.5) lit by one glowing wall (Le 1.5, its first
/// two triangles), the others grey: the texels close to the light are the noisy ones.
fn box_lit_by_one_wall(texels: &Path) -> Scene {
    let mut scene = emissive_box(texels, 0.5, 1.5);
    let mut grey = scene.materials[0].clone();
    grey.emission = Vec3::ZERO;
    scene.materials.push(grey);
    for t in &mut scene.triangles[2..] {
        t.material = 1;
    }
    scene
}

/// Channel `name` of the single-page lightmap at `path`, row by row.
fn channel(path: &Path, name: &str) -> Vec<f32> {
    read_channel(path, name).unwrap()
}

/// Every texel's irradiance (R channel) of the single-page lightmap at `path`.
fn red_channel(path: &Path) -> Vec<f64> {
    channel(path, "R").into_iter().map(f64::from).collect()
}

/// Irradiance inside a closed box of albedo ρ emitting Le everywhere, from light that left
/// an emitter and was reflected at most `reflections` times:
/// E = π Le (1 + ρ + … + ρ^reflections) = π Le (1 − ρ^(reflections+1)) / (1 − ρ), at every
/// point. A bake of B bounces reflects emitters' light B times when emitters are lights
/// (next-event estimation at the last hit), B − 1 times when only rays find them.
/// The mean of `values` and its standard error.
fn mean_and_se(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// How much more a series bake's mean errs than its texels' spread says: every texel of a
/// pass reads the same previous pass, whose error (ρ times its own, and so on back) all
/// texels share, √(Σ_j albedo^{2j}) over the `bounces` passes.
fn series_shared_error(albedo: f32, bounces: u32) -> f64 {
    (0..bounces)
        .map(|j| f64::from(albedo).powi(2 * j as i32))
        .sum::<f64>()
        .sqrt()
}

fn closed_box_irradiance(le: f32, albedo: f32, reflections: u32) -> f64 {
    let rho = f64::from(albedo);
    std::f64::consts::PI * f64::from(le) * (1.0 - rho.powi(reflections as i32 + 1)) / (1.0 - rho)
}

/// The spatial budget (`--budget`): the last pass's texels take ¼–4× the uniform samples by
/// the error the previous passes measured (in a closed box lit by one glowing wall, the
/// texels close to it are the noisy ones), about `--spp` in all, and the direct pass's later
/// iterations by its tiles' earlier ones; the lightmap keeps the uniform bake's mean and is
/// the same bits on one or two threads and sharded pass by pass.
#[test]
fn a_spatial_budget_moves_samples_and_bakes_the_same_bits_however_it_is_split() {
    let dir = tempfile::tempdir().unwrap();
    let texels = dir.path().join("box.texels");
    let scene = box_lit_by_one_wall(&texels);
    let job = |out: &str, threads: usize, budget: Budget| {
        let settings = BakeSettings {
            spp: 128,
            transport: Transport::Series,
            bounces: 3,
            budget,
            ..Default::default()
        };
        whole_job(&texels, dir.path().join(out), threads, settings)
    };
    let run = |job: &BakeJob| bake(job, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
    let one = same_bits_however_split(|out, threads| job(out, threads, Budget::Mse), &scene);
    let samples = channel(&one.out, "samples");
    let (least, most) = samples
        .iter()
        .fold((f32::MAX, 0.0f32), |(a, b), &s| (a.min(s), b.max(s)));
    let mean = samples.iter().map(|&s| f64::from(s)).sum::<f64>() / samples.len() as f64;
    assert!(least < 128.0 && most > 128.0, "{least} … {most}");
    assert!(
        (mean / 128.0 - 1.0).abs() < 0.1,
        "{mean} samples a texel on average"
    );
    let uniform = job("uniform.exr", 2, Budget::Uniform);
    run(&uniform);
    assert!(channel(&uniform.out, "samples").iter().all(|&s| s == 128.0));
    let average = |path: &Path| {
        let red = red_channel(path);
        red.iter().sum::<f64>() / red.len() as f64
    };
    let (got, want) = (average(&one.out), average(&uniform.out));
    assert!((got / want - 1.0).abs() < 0.02, "{got} against {want}");
}

/// The stopping rule (`--target-error`): in a closed box lit by one glowing wall, clusters
/// and direct-pass texels stop where their estimate is within the target, so the bake traces
/// fewer rays (counted: `texel_iterations_stopped`) and some texels take fewer samples than
/// the cap, with the uniform bake's mean; and it is the same bits on one or two threads,
/// sharded pass by pass, and cut and resumed (each stop reads only its cluster's or tile's
/// own samples).
#[test]
fn the_stopping_rule_skips_converged_work_and_bakes_the_same_bits_however_it_is_split() {
    let dir = tempfile::tempdir().unwrap();
    let texels = dir.path().join("box.texels");
    let scene = box_lit_by_one_wall(&texels);
    let (spp, iterations) = (512, 6);
    let job = |out: &str, threads: usize, target_error: Option<f32>| {
        let settings = BakeSettings {
            spp,
            iterations,
            bounces: 2,
            target_error,
            ..Default::default()
        };
        whole_job(&texels, dir.path().join(out), threads, settings)
    };
    let run = |job: &BakeJob| bake(job, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
    let one = same_bits_however_split(|out, threads| job(out, threads, Some(0.1)), &scene);

    // Cut after the first tiles of a pass, then resumed: the same bytes.
    let mut cut = job("cut.exr", 1, Some(0.1));
    let cancel = AtomicBool::new(false);
    let first = bake(&cut, &scene, &cancel, &mut |done, _| {
        cancel.store(done >= 64, Ordering::Relaxed);
    })
    .unwrap();
    assert!(first.interrupted, "{first:?}");
    cut.resume = true;
    run(&cut);
    assert_eq!(exr_bytes(&one.out), exr_bytes(&cut.out), "cut and resumed");

    let stopping = run(&job("stopping.exr", 2, Some(0.1)));
    let uniform = run(&job("uniform.exr", 2, None));
    assert!(stopping.counters.texel_iterations_stopped > 0);
    assert_eq!(uniform.counters.texel_iterations_stopped, 0);
    assert!(
        stopping.counters.gather_rays < uniform.counters.gather_rays
            && stopping.counters.shadow_rays < uniform.counters.shadow_rays,
        "{:?} against {:?}",
        stopping.counters,
        uniform.counters
    );
    let samples = channel(&one.out, "samples");
    assert!(samples.iter().all(|&s| s <= spp as f32));
    assert!(samples.iter().any(|&s| s < spp as f32), "no texel stopped");
    let average = |path: &Path| {
        let red = red_channel(path);
        red.iter().sum::<f64>() / red.len() as f64
    };
    let (got, want) = (average(&one.out), average(&dir.path().join("uniform.exr")));
    assert!((got / want - 1.0).abs() < 0.02, "{got} against {want}");
}

/// `--direct-spp`: the lightmap takes its texels' direct light from the direct pass (at twice
/// the gather's samples here) and its last pass gathers the indirect light alone. In a
/// closed glowing box it still receives π·Le times the bounce series, and it is the same bits
/// on one or two threads and sharded pass by pass (the finish then reads the merged pass 0);
/// its relative standard error is of the sum. With `--lookup-spp` it keeps its mean too.
#[test]
fn a_lightmap_that_takes_its_direct_light_from_the_direct_pass_keeps_its_mean_and_bits() {
    let (albedo, le) = (0.5f32, 1.5f32);
    let dir = tempfile::tempdir().unwrap();
    let texels = dir.path().join("box.texels");
    let scene = emissive_box(&texels, albedo, le);
    let bounces = 3;
    let job = |out: &str, threads: usize, direct_spp: Option<u32>| {
        let settings = BakeSettings {
            spp: 128,
            iterations: 2,
            bounces,
            direct_spp,
            ..Default::default()
        };
        whole_job(&texels, dir.path().join(out), threads, settings)
    };
    let run = |job: &BakeJob| bake(job, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
    let one = same_bits_however_split(|out, threads| job(out, threads, Some(256)), &scene);

    let want = closed_box_irradiance(le, albedo, bounces);
    let (mean, se) = mean_and_se(&red_channel(&one.out));
    let tolerance = 3.5 * se * series_shared_error(albedo, bounces) + 1e-4 * want;
    assert!(
        (mean - want).abs() < tolerance,
        "{mean}, want {want} ± {tolerance}"
    );
    let errors = channel(&one.out, "rel_std_error");
    assert!(
        errors.iter().all(|e| e.is_finite() && *e > 0.0 && *e < 0.1),
        "{errors:?}"
    );

    // `--lookup-spp`: fewer rays in the passes that only feed lookups, the same mean.
    let mut fewer = job("fewer.exr", 2, None);
    fewer.settings.lookup_spp = Some(32);
    run(&fewer);
    let (mean, se) = mean_and_se(&red_channel(&fewer.out));
    let tolerance = 3.5 * se * series_shared_error(albedo, bounces) + 1e-4 * want;
    assert!(
        (mean - want).abs() < tolerance,
        "{mean}, want {want} ± {tolerance}"
    );
}

#[test]
fn a_closed_emissive_box_receives_pi_le_times_the_bounce_series_in_both_transports() {
    let (albedo, le) = (0.5f32, 1.5f32);
    let dir = tempfile::tempdir().unwrap();
    let texels = dir.path().join("box.texels");
    let scene = emissive_box(&texels, albedo, le);
    use guidebake::bake::settings::GuidedPasses::{Every, Last};
    // (transport, bounces, guiding, emitters, which series passes are guided)
    for (transport, bounces, guiding, emitters, guided_passes) in [
        (
            Transport::Series,
            1,
            Guiding::Off,
            EmitterSampling::Hits,
            Last,
        ),
        (
            Transport::Series,
            4,
            Guiding::Off,
            EmitterSampling::Hits,
            Last,
        ),
        (
            Transport::Series,
            1,
            Guiding::Off,
            EmitterSampling::Mis,
            Last,
        ),
        (
            Transport::Series,
            4,
            Guiding::Off,
            EmitterSampling::Mis,
            Last,
        ),
        (
            Transport::Series,
            4,
            Guiding::Coherent,
            EmitterSampling::Mis,
            Last,
        ),
        (
            Transport::Series,
            4,
            Guiding::Coherent,
            EmitterSampling::Mis,
            Every,
        ),
        (
            Transport::Series,
            3,
            Guiding::Coherent,
            EmitterSampling::Nee,
            Last,
        ),
        (
            Transport::Path,
            4,
            Guiding::Coherent,
            EmitterSampling::Mis,
            Last,
        ),
        (
            Transport::Path,
            4,
            Guiding::Off,
            EmitterSampling::Hits,
            Last,
        ),
        (
            Transport::Path,
            64,
            Guiding::Off,
            EmitterSampling::Mis,
            Last,
        ),
    ] {
        let out = dir.path().join(format!(
            "{transport}-{bounces}-{guiding}-{emitters}-{guided_passes:?}.exr"
        ));
        let job = BakeJob {
            texels: texels.clone(),
            out: out.clone(),
            settings: BakeSettings {
                spp: 128,
                iterations: 2,
                transport,
                bounces,
                guiding,
                emitters,
                guided_passes,
                ..Default::default()
            },
            threads: 2,
            shard: Shard::WHOLE,
            resume: false,
            aux: false,
            finish: FinishOptions::default(),
        };
        let report = bake(&job, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
        let values = red_channel(&out);
        assert_eq!(values.len(), (6 * FACE * FACE) as usize);
        let (mean, se) = mean_and_se(&values);
        let reflections = match emitters {
            EmitterSampling::Hits => bounces - 1,
            EmitterSampling::Mis | EmitterSampling::Nee => bounces,
        };
        let want = closed_box_irradiance(le, albedo, reflections);
        let what = format!(
            "{transport} B={bounces} {guiding} {emitters} {guided_passes:?}: {mean} ± {se}, \
             want {want}"
        );
        if transport == Transport::Series
            && guiding == Guiding::Off
            && emitters == EmitterSampling::Hits
        {
            // Constant radiance everywhere, cosine sampling and no light sampled: every
            // sample is the same.
            assert!(
                values.iter().all(|v| (v - want).abs() < 1e-4 * want),
                "{what}"
            );
        } else {
            // A learned guide's density is not constant, nor are paths: noise, no bias. Under
            // series every texel of a pass reads the same previous pass, whose error (ρ times
            // its own, and so on back) all texels share: the texels' spread alone misses it.
            // Six seeds of series B = 4 (coherent and off) spread 1.27× the texels' `se`.
            let shared = match transport {
                Transport::Series => series_shared_error(albedo, bounces),
                Transport::Path => 1.0,
            };
            let tolerance = 3.5 * se * shared + 1e-4 * want;
            assert!(
                (mean - want).abs() < tolerance,
                "{what} (tolerance {tolerance})"
            );
        }
        match transport {
            Transport::Series => {
                assert_eq!(report.passes, bounces + 1, "the direct pass and B bounces");
                // Every hit in the box can be read: the only path rays are the one bounce on
                // from hits within a texel of their origin (`NEAR_PATH_TEXELS`), which read
                // pass b − 2 — from pass 2 on.
                let (path, gather) = (report.counters.path_rays, report.counters.gather_rays);
                if bounces < 2 {
                    assert_eq!(path, 0, "{what}");
                } else {
                    assert!(path > 0 && path * 4 < gather, "{what}: {path} of {gather}");
                }
                // Every gather pass clusters its texels; only the guided ones learn.
                let c = &report.counters;
                let learned = c.iterations_learnable();
                let guided_passes = match (guiding, guided_passes) {
                    (Guiding::Off, _) => 0,
                    (_, Last) => 1,
                    (_, Every) => u64::from(bounces),
                };
                let clusters_per_pass = c.clusters / u64::from(bounces);
                assert_eq!(learned, clusters_per_pass * guided_passes, "{what}");
                // The last pass's clusters may start from the pass before's seed.
                if guiding != Guiding::Off && bounces >= 2 {
                    assert!(c.clusters_seeded <= clusters_per_pass, "{what}");
                } else {
                    assert_eq!(c.clusters_seeded, 0, "{what}");
                }
                // From pass 1 on, hits inside the box read the previous pass's total.
                let reads = report.counters.series_totals_read;
                assert!(reads > 0, "{what}: {reads} totals read");
            }
            Transport::Path => {
                assert_eq!(report.passes, 1);
                assert!(report.counters.path_rays > 0);
                assert_eq!(report.counters.series_totals_read, 0);
            }
        }
    }
}

#[test]
fn global_weights_bake_the_closed_form_and_merge_shards_to_the_same_bits() {
    let (albedo, le) = (0.5f32, 1.5f32);
    let dir = tempfile::tempdir().unwrap();
    let texels = dir.path().join("box.texels");
    let scene = emissive_box(&texels, albedo, le);
    let want = closed_box_irradiance(le, albedo, 3);
    // Emitters are lights: paths of 3 vertices carry light reflected up to 3 times.
    let job = |out: &str, shard: Shard| BakeJob {
        texels: texels.clone(),
        out: dir.path().join(out),
        settings: BakeSettings {
            spp: 128,
            iterations: 4,
            combine: Combine::Global,
            transport: Transport::Path,
            bounces: 3,
            directional: Directional::ShL1,
            ..Default::default()
        },
        threads: 2,
        shard,
        resume: false,
        aux: true,
        finish: FinishOptions::default(),
    };
    let whole = job("whole.exr", Shard::WHOLE);
    let report = bake(&whole, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
    assert!(
        (report.rho - 1.0).abs() < 0.05,
        "global weights are unbiased: ρ = {}",
        report.rho
    );
    let (mean, se) = mean_and_se(&red_channel(&whole.out));
    assert!((mean - want).abs() < 3.0 * se, "{mean} ± {se}, want {want}");
    // The same radiance E/π from every direction of a texel's hemisphere: L0 = E/√π, and
    // the L1 reconstruction at the texel's normal gives E back (docs/lightmaps.md).
    let sh0: Vec<f64> = channel(&whole.out, "SH0.R")
        .into_iter()
        .map(f64::from)
        .collect();
    let (mean0, se0) = mean_and_se(&sh0);
    let want0 = want / std::f64::consts::PI.sqrt();
    assert!(
        (mean0 - want0).abs() < 3.0 * se0 + 1e-3 * want0,
        "L0 {mean0} ± {se0}, want {want0}"
    );
    let mut dirs = Vec::new();
    for index in [2, 0, 1] {
        let shard = job("sharded.exr", Shard { index, count: 3 });
        bake(&shard, &scene, &AtomicBool::new(false), &mut |_, _| {}).unwrap();
        dirs.push(work_dir(&shard.out, shard.shard));
    }
    let merged = dir.path().join("sharded.exr");
    finish(&TexelFile::open(&texels).unwrap(), &dirs, &merged).unwrap();
    assert_eq!(exr_bytes(&whole.out), exr_bytes(&merged));
}

#[test]
fn aux_channels_hold_samples_error_validity_position_and_normal() {
    let f = Fixture::new();
    let job = f.job("aux.exr", 2, Shard::WHOLE);
    f.run(&job, None).unwrap();
    let channel = |name: &str| channel(&job.out, name);
    for name in guidebake::bake::finish::AUX_CHANNELS {
        assert!(channel(name).iter().all(|v| v.is_finite()), "{name}");
    }
    assert!(channel("samples").iter().all(|&s| s == 64.0));
    assert!(channel("validity").iter().all(|&v| v == 1.0));
    assert!(channel("N.Z").iter().all(|&z| z == 1.0));
    assert!(channel("P.Z").iter().all(|&z| z == 0.0));
    // Pixel (x, y) of the 4 m plane lies at x·size − 2 + size/2.
    let px = channel("P.X");
    let size = 4.0 / SIDE as f32;
    for (x, p) in px.iter().take(SIDE as usize).enumerate() {
        assert!((p - ((x as f32 + 0.5) * size - 2.0)).abs() < 1e-6);
    }
    let err = channel("rel_std_error");
    assert!(err.iter().all(|&e| (0.0..1.0).contains(&e)));
}
