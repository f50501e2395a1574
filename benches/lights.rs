//! Criterion benches for emitter selection: the power
//! alias table (`transport::alias`) against the light tree (`transport::light_tree`).
//!
//! The emitters are the lit windows of a night city from `guidebake synth --lit-windows`
//! (2 triangles per window, radiance 1.5..1000), converted as the bake converts emissive
//! triangles (`EmitterBounds::from_triangle`); the shading points are texels of the same
//! city (position and normal), spread over the texel file. Two sizes: 10^4 and 10^6
//! emissive triangles.
//!
//! Group `lights_build` (emitters/s): building each structure. Group `lights_pick` (picks/s):
//! one pick and the pmf of the picked emitter (what MIS asks for at a hit), at one shading
//! point after another (about half of the city's texels — roofs, most of the ground — see
//! no window, where the tree's pick fails at the root). Before timing, picks are checked
//! against the pmf, and the bench prints, over shading points that some window can light,
//! the share of picks of both samplers that land on an emitter that can light the point
//! (front face towards it, above its horizon) — a proxy for the samples that are not
//! wasted — and the tree's share of failed picks.
//!
//! Group `lights_pick_bidir` (picks/s): the same pick + pmf through `Emitters` (as next-event
//! estimation calls it) in the Veach bidir room (`../shared/scenes/converted/
//! bitterli_veach_bidir.glb`, 4 emissive triangles; skipped when absent), at random points
//! of the room with random normals, for `power`, `tree` and `local` selection: `SEL/4` as two
//! calls that each make the selection at the receiver (`Emitters::select`, then
//! `Emitters::selection_pmf`), `SEL-at/4` with the selection made once (`Emitters::at`, as
//! next-event estimation and the MIS density of the ray leaving a path vertex share it).
//!
//! Run: `cargo bench --bench lights -- --warm-up-time 1 --measurement-time 2`

use std::hint::black_box;
use std::path::Path;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use guidebake::scene::Scene;
use guidebake::synth::{SynthOptions, synth_with};
use guidebake::texels::TexelFile;
use guidebake::transport::alias::AliasTable;
use guidebake::transport::emitters::{EmitterSelection, Emitters};
use guidebake::transport::light_tree::{EmitterBounds, LightTree};
use guidebake_kernels::testing::Pcg32;

/// Emissive triangles per world (two per window).
const SIZES: [u32; 2] = [10_000, 1_000_000];
/// Shading points per world.
const POINTS: usize = 4096;

/// One world: emitters and shading points (position, normal).
struct World {
    emitters: Vec<EmitterBounds>,
    points: Vec<(Vec3, Vec3)>,
}

/// A night city with `triangles / 2` lit windows, written to `dir` and read back.
fn world(dir: &Path, triangles: u32) -> World {
    let out = dir.join(format!("city{triangles}.texels"));
    let options = SynthOptions {
        lit_windows: triangles / 2,
        night: true,
    };
    let report = synth_with(400_000, &out, &options).expect("synth");
    let scene = Scene::load(&report.scene).expect("scene");
    let emitters: Vec<EmitterBounds> = (0..scene.triangles.len())
        .filter_map(|i| {
            let e = scene.triangle_material(i).emission;
            (e != Vec3::ZERO).then(|| EmitterBounds::from_triangle(scene.triangles[i].positions, e))
        })
        .collect();
    assert_eq!(emitters.len() as u32, triangles);
    let file = TexelFile::open(&out).expect("texels");
    let texels = file.texels();
    let step = (texels.len() / POINTS).max(1);
    let points = texels
        .iter()
        .step_by(step)
        .take(POINTS)
        .map(|t| (t.position(), Vec3::from(t.normal)))
        .collect();
    World { emitters, points }
}

/// Whether emitter `e` can light `p` with normal `n` (front face towards p, a corner above
/// p's horizon).
fn can_light(e: &EmitterBounds, p: Vec3, n: Vec3) -> bool {
    let [a, b, c] = e.corners;
    e.normal.dot(p - a) > 0.0 && [a, b, c].iter().any(|&x| (x - p).dot(n) > 0.0)
}

/// Checks pick against pmf, and prints for the first 256 shading points that some emitter
/// can light the share of picks of both samplers that land on such an emitter, and the
/// tree's failed picks there.
fn check_and_report(w: &World, alias: &AliasTable, tree: &LightTree) {
    let mut rng = Pcg32::new(1, 1);
    let (mut useful_alias, mut useful_tree, mut failed, mut picks) = (0u32, 0u32, 0u32, 0u32);
    let (mut dark_points, mut dark_failed) = (0u32, 0u32);
    for &(p, n) in w.points.iter().take(256) {
        let lit = w.emitters.iter().any(|e| can_light(e, p, n));
        if !lit {
            // No emitter can light p: the alias table wastes its picks, the tree must fail.
            dark_points += 1;
            dark_failed += u32::from(tree.pick(p, n, rng.next_f32()).is_none());
            continue;
        }
        for _ in 0..64 {
            picks += 1;
            let (i, prob) = alias.pick(rng.next_f32());
            assert_eq!(prob, alias.pmf(i));
            useful_alias += u32::from(can_light(&w.emitters[i as usize], p, n));
            match tree.pick(p, n, rng.next_f32()) {
                Some((i, prob)) => {
                    assert_eq!(prob.to_bits(), tree.pmf(p, n, i).to_bits());
                    useful_tree += u32::from(can_light(&w.emitters[i as usize], p, n));
                }
                None => failed += 1,
            }
        }
    }
    assert_eq!(
        dark_failed, dark_points,
        "the tree picked for a point no emitter lights"
    );
    let share = |k: u32| 100.0 * f64::from(k) / f64::from(picks.max(1));
    println!(
        "{} emitters, {} of 256 points lit: picks that can light the point: alias {:.1}%, \
         tree {:.1}% (failed {:.1}%)",
        w.emitters.len(),
        256 - dark_points,
        share(useful_alias),
        share(useful_tree),
        share(failed)
    );
}

fn bench_lights(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let worlds: Vec<World> = SIZES.iter().map(|&n| world(dir.path(), n)).collect();
    let powers: Vec<Vec<f32>> = worlds
        .iter()
        .map(|w| w.emitters.iter().map(|e| e.power).collect())
        .collect();

    let mut build = c.benchmark_group("lights_build");
    build.sample_size(10);
    for (w, power) in worlds.iter().zip(&powers) {
        let n = w.emitters.len();
        build.throughput(Throughput::Elements(n as u64));
        build.bench_function(BenchmarkId::new("alias", n), |b| {
            b.iter(|| AliasTable::new(black_box(power)))
        });
        build.bench_function(BenchmarkId::new("tree", n), |b| {
            b.iter(|| LightTree::build(black_box(&w.emitters)))
        });
    }
    build.finish();

    let mut pick = c.benchmark_group("lights_pick");
    for (w, power) in worlds.iter().zip(&powers) {
        let n = w.emitters.len();
        let alias = AliasTable::new(power).expect("alias");
        let tree = LightTree::build(&w.emitters).expect("tree");
        check_and_report(w, &alias, &tree);
        pick.throughput(Throughput::Elements(w.points.len() as u64));
        let mut rng = Pcg32::new(2, 2);
        let us: Vec<f32> = (0..w.points.len()).map(|_| rng.next_f32()).collect();
        pick.bench_function(BenchmarkId::new("alias", n), |b| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for &u in &us {
                    let (i, p) = alias.pick(u);
                    sum += p + alias.pmf(i);
                }
                sum
            })
        });
        pick.bench_function(BenchmarkId::new("tree", n), |b| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for (&(p, normal), &u) in w.points.iter().zip(&us) {
                    if let Some((i, prob)) = tree.pick(p, normal, u) {
                        sum += prob + tree.pmf(p, normal, i);
                    }
                }
                sum
            })
        });
    }
    pick.finish();
    bench_bidir(c);
}

/// The Veach bidir room's emitters through [`Emitters::select`] and
/// [`Emitters::selection_pmf`], and through [`Emitters::at`], by each selection.
fn bench_bidir(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/scenes/converted/bitterli_veach_bidir.glb");
    let Ok(scene) = Scene::load(&path) else {
        eprintln!("lights_pick_bidir: {} not found, skipped", path.display());
        return;
    };
    let triangles: Vec<([Vec3; 3], Vec3, Vec3)> = (0..scene.triangles.len())
        .map(|i| {
            let [a, b, c] = scene.triangles[i].positions;
            let n = (b - a).cross(c - a).normalize_or_zero();
            ([a, b, c], n, scene.triangle_material(i).emission)
        })
        .collect();
    let mut rng = Pcg32::new(3, 5);
    let points: Vec<(Vec3, Vec3, f32)> = (0..POINTS)
        .map(|_| {
            let mut r = || rng.next_f32();
            let p = Vec3::new(8.0 * r() - 4.0, 8.0 * r(), 8.0 * r() - 4.0);
            let n = Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5).normalize_or(Vec3::Y);
            (p, n, r())
        })
        .collect();
    let mut group = c.benchmark_group("lights_pick_bidir");
    group.throughput(Throughput::Elements(points.len() as u64));
    for sel in [
        EmitterSelection::Power,
        EmitterSelection::Tree,
        EmitterSelection::Local,
    ] {
        let emitters = Emitters::new(triangles.iter().copied(), sel).expect("emitters");
        group.bench_function(BenchmarkId::new(sel.to_string(), emitters.len()), |b| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for &(p, n, u) in &points {
                    if let Some((i, prob)) = emitters.select(black_box(p), n, u) {
                        sum += prob + emitters.selection_pmf(p, n, i);
                    }
                }
                sum
            })
        });
        // As the bake asks at one receiver: the selection made once (`Emitters::at`), then
        // its pick and the pmf of the picked emitter.
        group.bench_function(BenchmarkId::new(format!("{sel}-at"), emitters.len()), |b| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for &(p, n, u) in &points {
                    let at = emitters.at(black_box(p), n);
                    if let Some((i, prob)) = at.select(u) {
                        sum += prob + at.selection_pmf(i);
                    }
                }
                sum
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_lights);
criterion_main!(benches);
