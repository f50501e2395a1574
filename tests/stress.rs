//! Numerical stress tests of the bake: worlds far from the origin and at small
//! scales, a dynamic range of 10⁹ in one scene, zero albedo, sub-texel and sliver
//! triangles, coincident texels, normals nearly tangent to the surface, a guide learned
//! from a single firefly, and a gather that sees nothing. Every output must be finite,
//! and where an analytic value exists it must be met within a stated tolerance.
//!
//! The bake is driven through its public API: a [`Scene`] built in code, [`World`], and
//! [`TileBaker::bake_tile`] on hand-made texels, with ρ applied from the tiles' sums as the
//! bake's final pass does ([`rho_sums`]).
//!
//! The default variants are small (a few seconds in the test profile). The long variants
//! are `#[ignore]`d; run them with
//! `cargo test --release --test stress -- --ignored --nocapture`.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};
use guidebake::bake::gather::TileBaker;
use guidebake::bake::pipeline::TileBuffer;
use guidebake::bake::settings::{BakeSettings, Combine, Guiding, MAX_BOUNCES, Transport};
use guidebake::bvh::Preset;
use guidebake::output::journal::rho_sums;
use guidebake::output::result_file::{FLAG_BAKED, FLAG_NO_FINITE_SAMPLES, FLAG_VALID};
use guidebake::scene::{Material, Scene, Sky, Sun, Triangle};
use guidebake::test_support::{inward_box_faces, quad};
use guidebake::texels::{FLAG_VALID as TEXEL_VALID, TexelRecord};
use guidebake::transport::world::World;

const MODES: [Guiding; 3] = [Guiding::Off, Guiding::Naive, Guiding::Coherent];

fn settings(guiding: Guiding, spp: u32) -> BakeSettings {
    BakeSettings {
        spp,
        iterations: 3,
        guiding,
        ..Default::default()
    }
}

/// A square of side `2·half` around `centre` in the plane z = centre.z, facing +z.
fn pad(centre: Vec3, half: f32, material: u32) -> [Triangle; 2] {
    let corner = centre - Vec3::new(half, half, 0.0);
    quad(corner, Vec3::X * 2.0 * half, Vec3::Y * 2.0 * half, material)
}

/// The triangle of [`pad`]`(centre, half)` (its first at index `first`) that holds `p`.
fn on_pad(p: Vec3, centre: Vec3, half: f32, first: u32) -> u32 {
    let local = (p - centre + Vec3::splat(half)) / (2.0 * half);
    first + u32::from(local.x < local.y)
}

fn material(albedo: f32, emission: f32) -> Material {
    Material {
        name: format!("albedo {albedo}, emission {emission}"),
        base_color_texture: None,
        albedo: Vec3::splat(albedo),
        emission: Vec3::splat(emission),
    }
}

fn scene(triangles: Vec<Triangle>, materials: Vec<Material>, sky: Vec3, sun: Option<Sun>) -> Scene {
    Scene {
        sun,
        sky: Sky::Constant(sky),
        ..Scene::of_triangles("stress", triangles, materials)
    }
}

/// A texel at `p` with normal `n`, square footprint of side `size` in the plane z = const,
/// lying on scene triangle `triangle`.
fn texel(p: Vec3, n: Vec3, size: f32, triangle: u32, i: usize) -> TexelRecord {
    TexelRecord {
        position: p.to_array(),
        normal: n.to_array(),
        dpdu: [size, 0.0, 0.0],
        dpdv: [0.0, size, 0.0],
        page: 0,
        pixel: [(i % 256) as u16, (i / 256) as u16],
        triangle,
        flags: TEXEL_VALID,
    }
}

/// Bakes `tiles` (each a list of texels, tile i starting at global texel 1000·i) and
/// returns every texel's irradiance after ρ, per tile.
fn bake(world: &World, settings: BakeSettings, tiles: &[Vec<TexelRecord>]) -> Vec<Vec<Vec3>> {
    bake_with_rho(world, settings, tiles).0
}

/// [`bake`], and the ρ it applied.
fn bake_with_rho(
    world: &World,
    settings: BakeSettings,
    tiles: &[Vec<TexelRecord>],
) -> (Vec<Vec<Vec3>>, f64) {
    let mut baker = TileBaker::new(world, settings);
    let mut records = Vec::new();
    let mut raw = Vec::new();
    for (i, texels) in tiles.iter().enumerate() {
        let mut buffer = TileBuffer::default();
        let baked = baker.bake_tile(i as u32, 1000 * i as u64, texels, &mut buffer);
        let out = buffer.results;
        assert!(
            out.iter()
                .all(|r| r.flags & FLAG_BAKED != 0 && r.flags & FLAG_VALID != 0),
            "every texel is baked and valid"
        );
        records.push(baked.record);
        raw.push(out);
    }
    let rho = rho_sums(&records).rho();
    assert!(rho.is_finite() && rho > 0.0, "ρ = {rho}");
    let values = raw
        .iter()
        .map(|out| {
            out.iter()
                .map(|r| {
                    let e = Vec3::from(r.irradiance.map(|c| (f64::from(c) * rho) as f32));
                    assert!(e.is_finite() && e.min_element() >= 0.0, "{r:?} ρ {rho}");
                    e
                })
                .collect()
        })
        .collect();
    (values, rho)
}

/// Mean and standard error of the mean over texels, per channel.
fn mean_se(values: &[Vec3]) -> (Vec3, Vec3) {
    let n = values.len() as f32;
    let mean = values.iter().copied().sum::<Vec3>() / n;
    let var = values
        .iter()
        .map(|v| (*v - mean) * (*v - mean))
        .sum::<Vec3>()
        / (n - 1.0);
    (mean, (var / n).powf(0.5))
}

fn luminance(c: Vec3) -> f32 {
    guidebake_kernels::estimator::luminance_f32(c.to_array())
}

// ---------------------------------------------------------------------------------------------
// Offset and scaled worlds.

/// A 200 m ground square at z = 0 (triangles 0, 1), a 40 m roof at 8 m facing down
/// (2, 3) and a 20 m wall along y = 15 (4, 5); sky and a low sun.
fn yard(transform: impl Fn(Vec3) -> Vec3) -> Scene {
    let mut tris = Vec::new();
    tris.extend(quad(
        Vec3::new(-100.0, -100.0, 0.0),
        Vec3::X * 200.0,
        Vec3::Y * 200.0,
        0,
    ));
    tris.extend(quad(
        Vec3::new(-20.0, -20.0, 8.0),
        Vec3::Y * 40.0,
        Vec3::X * 40.0,
        0,
    ));
    tris.extend(quad(
        Vec3::new(-10.0, 15.0, 0.0),
        Vec3::Z * 12.0,
        Vec3::X * 20.0,
        0,
    ));
    for t in &mut tris {
        t.positions = t.positions.map(&transform);
    }
    let sun = Sun {
        direction: Vec3::new(0.4, -0.6, 0.7).normalize(),
        angular_radius: 0.01,
        irradiance: Vec3::new(3.0, 2.5, 2.0),
    };
    scene(
        tris,
        vec![material(0.5, 0.0)],
        Vec3::new(0.4, 0.5, 0.7),
        Some(sun),
    )
}

/// `n`² ground texels on a grid over [−40, 40]² m (under the roof, beside the wall, in the
/// open), footprint 0.5 m, transformed like the scene.
fn yard_texels(n: usize, transform: impl Fn(Vec3) -> Vec3, scale: f32) -> Vec<TexelRecord> {
    (0..n * n)
        .map(|i| {
            let s = (i % n) as f32 / (n - 1) as f32;
            let t = (i / n) as f32 / (n - 1) as f32;
            let p = Vec3::new(-40.0 + 80.0 * s, -40.0 + 80.0 * t, 0.0);
            // The ground quad's first triangle holds the points with local s ≥ t.
            let (ls, lt) = ((p.x + 100.0) / 200.0, (p.y + 100.0) / 200.0);
            let triangle = u32::from(ls < lt);
            let mut r = texel(transform(p), Vec3::Z, 0.5 * scale, triangle, i);
            r.pixel = [(i % n) as u16, (i / n) as u16];
            r
        })
        .collect()
}

/// How far a moved world's lightmap is from the one at the origin.
struct Deviation {
    /// Relative difference of the mean luminance over all texels.
    mean: f32,
    /// Fraction of texels whose luminance differs by more than 2 %.
    outliers: f32,
    /// Largest per-texel relative difference.
    worst: f32,
}

fn deviation(moved: &[Vec3], origin: &[Vec3]) -> Deviation {
    let (lm, lo): (Vec<f32>, Vec<f32>) = moved
        .iter()
        .zip(origin)
        .map(|(a, b)| (luminance(*a), luminance(*b)))
        .unzip();
    let mean_o = lo.iter().sum::<f32>() / lo.len() as f32;
    let mean_m = lm.iter().sum::<f32>() / lm.len() as f32;
    let rel: Vec<f32> = lm
        .iter()
        .zip(&lo)
        .map(|(a, b)| (a - b).abs() / b.max(0.05 * mean_o))
        .collect();
    Deviation {
        mean: (mean_m - mean_o).abs() / mean_o,
        outliers: rel.iter().filter(|&&r| r > 0.02).count() as f32 / rel.len() as f32,
        worst: rel.iter().copied().fold(0.0, f32::max),
    }
}

fn moved_world_matches(offset: Vec3, scale: f32, n: usize, spp: u32) -> Deviation {
    moved_world_matches_with(offset, scale, n, spp, Combine::Texel)
}

/// [`moved_world_matches`] with the iterations combined by `combine`.
fn moved_world_matches_with(
    offset: Vec3,
    scale: f32,
    n: usize,
    spp: u32,
    combine: Combine,
) -> Deviation {
    let settings = |guiding| BakeSettings {
        combine,
        bias_correction: combine == Combine::Texel,
        ..settings(guiding, spp)
    };
    let at = move |p: Vec3| p * scale + offset;
    let reference = {
        let world = World::new(&yard(|p| p), Preset::DEFAULT).unwrap();
        bake(
            &world,
            settings(Guiding::Coherent),
            &[yard_texels(n, |p| p, 1.0)],
        )
    };
    let moved = {
        let world = World::new(&yard(at), Preset::DEFAULT).unwrap();
        bake(
            &world,
            settings(Guiding::Coherent),
            &[yard_texels(n, at, scale)],
        )
    };
    let d = deviation(&moved[0], &reference[0]);
    println!(
        "offset {offset}, scale {scale:e}: mean luminance {:.2e} relative, {:.1} % of texels beyond 2 %, worst {:.2e}",
        d.mean,
        100.0 * d.outliers,
        d.worst
    );
    d
}

fn assert_matches(offset: Vec3, scale: f32, d: &Deviation, outliers: f32) {
    assert!(
        d.mean < 1e-3,
        "offset {offset}, scale {scale}: mean off by {}",
        d.mean
    );
    assert!(
        d.outliers <= outliers,
        "offset {offset}, scale {scale}: {} of texels beyond 2 %",
        d.outliers
    );
}

/// Irradiance does not depend on where the world sits or on its unit: the same scene and
/// texels moved 10⁶ sideways or scaled by 10⁻³ and 10² (same seeds, so the same
/// directions) give the origin's lightmap. Stated tolerance: the mean luminance within
/// 0.1 %, and at most 8 % of texels more than 2 % off — texels near the sun's shadow edges,
/// where the moved positions' rounding (f32 spacing is 6 cm at 10⁶) decides lit or shadowed
/// for some of their rays. Measured (12² texels, 64 spp): 10⁶ → mean 1.0·10⁻⁴, 5.6 % of
/// texels beyond 2 %; 10⁻³ and 10² → identical bits (the origin offset scales with the
/// triangle's size, so a scaled world lifts its origins by the scaled amount; with a fixed
/// 1.5·10⁻⁵ near the origin, 10⁻³ gave 2.6·10⁻⁵ and 0.7 %); 10³…10⁵ sideways → identical
/// bits.
///
/// Moving the world along the surfaces' normal axis: `worlds_moved_along_the_normal_axis`.
#[test]
fn offset_and_scaled_worlds_bake_the_origins_lightmap() {
    for (offset, scale) in [
        (Vec3::new(1e6, -1e6, 0.0), 1.0),
        (Vec3::ZERO, 1e-3),
        (Vec3::ZERO, 1e2),
    ] {
        let d = moved_world_matches(offset, scale, 12, 64);
        assert_matches(offset, scale, &d, 0.08);
    }
}

#[test]
#[ignore = "long: cargo test --release --test stress -- --ignored --nocapture"]
fn offset_and_scaled_worlds_long() {
    for (offset, scale) in [
        (Vec3::new(1e6, 1e6, 0.0), 1.0),
        (Vec3::new(-1e6, 3e5, 0.0), 1.0),
        (Vec3::ZERO, 1e-3),
        (Vec3::ZERO, 1e3),
    ] {
        let d = moved_world_matches(offset, scale, 40, 256);
        assert_matches(offset, scale, &d, 0.08);
    }
}

/// The same world moved along z, the ground's normal, where every origin must be lifted off
/// a surface whose coordinate is large. Found failing by this test (issue 8): origins were
/// offset by 256 ulps of the coordinate (Wächter & Binder's constant), 0.25 m at 10⁴ and
/// 16 m at 10⁶, past the 8 m roof (at 10⁴ 32 % of texels more than 2 % off; at 10⁶ the mean
/// 27 % off). `offset_origin` now lifts by 2–4 ulps of the coordinate plus a few of the
/// triangle's size.
///
/// Stated tolerance: at 10⁴ the origin's lightmap bit for bit (the lift is 2.4 mm and every
/// ray takes the same path). At 10⁵ and 10⁶ the lift is 2.4 cm and 25 cm (the f32 spacing
/// is 0.8 cm and 6.25 cm), which changes which rays graze the roof's edge: the mean within
/// 0.5 % and, combined without Graybill–Deal's per-texel weights (`Combine::Average`),
/// every texel within 50 % (64 samples per texel, a sixteenth of them seeing the sky under
/// the roof: a ray that now passes the edge moves such a texel by several per cent).
/// Graybill–Deal itself turns one such ray into a texel 98 % off: an iteration that by
/// chance saw no sky has a small variance and takes the weight (the per-texel bias that ρ
/// corrects only on average, docs/estimator.md). Measured (12² texels): 10⁵ → mean
/// 5.9·10⁻⁴, worst texel 23 % (average); 10⁶ → 3.3·10⁻³, 43 %.
#[test]
fn worlds_moved_along_the_normal_axis() {
    let d = moved_world_matches(Vec3::new(0.0, 0.0, 1e4), 1.0, 12, 64);
    assert!(
        d.mean == 0.0 && d.worst == 0.0,
        "moved 10⁴ along the normal: mean {}, worst {}",
        d.mean,
        d.worst
    );
    for z in [1e5, 1e6] {
        let offset = Vec3::new(0.0, 0.0, z);
        let d = moved_world_matches(offset, 1.0, 12, 64);
        assert!(
            d.mean < 5e-3,
            "{z} along the normal: mean off by {}",
            d.mean
        );
        let d = moved_world_matches_with(offset, 1.0, 12, 64, Combine::Average);
        assert!(
            d.mean < 5e-3 && d.worst < 0.5,
            "{z} along the normal, averaged: mean {}, worst {}",
            d.mean,
            d.worst
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Dynamic range.

/// The form factor from a point at the origin facing +z to the rectangle
/// [x0, x1] × [y0, y1] in the plane z = h facing down (corner formula, signed).
fn form_factor(x0: f32, x1: f32, y0: f32, y1: f32, h: f32) -> f32 {
    let corner = |a: f32, b: f32| {
        let (a, b) = ((a / h) as f64, (b / h) as f64);
        let (sa, sb) = ((1.0 + a * a).sqrt(), (1.0 + b * b).sqrt());
        (a / sa * (b / sa).atan() + b / sb * (a / sb).atan()) / (2.0 * std::f64::consts::PI)
    };
    (corner(x1, y1) - corner(x0, y1) - corner(x1, y0) + corner(x0, y0)) as f32
}

/// A 1 m panel of radiance 10⁵ 1 m above the ground, under a sky of 10⁻⁴: nine orders of
/// magnitude in one world and one bake. Texels under the panel receive π·L·F (+ the sky
/// it does not hide); texels 5 km away see only the sky, π·10⁻⁴ (the panel's share there is
/// below 10⁻⁸ of it). ρ is world-wide, as in the
/// bake, so the dim tile is scaled by the bright one's correction. Tolerance: the bright
/// tile within 4 standard errors of the mean over texels plus 3 % (Graybill–Deal's residual
/// bias after ρ, docs/estimator.md); the dim tile, *before* ρ, within 4 standard errors plus
/// 0.1 %. Measured ρ: 1.012 unguided, 1.067–1.070 guided — the world-wide correction moves
/// a dim region by the bright region's bias (paper §2.5 makes ρ global; noted in
/// docs/RELIABILITY.md).
fn dynamic_range(n: usize, spp: u32) {
    let (panel, sky) = (1e5f32, 1e-4f32);
    let far_centre = Vec3::new(5000.0, 0.0, 0.0);
    let mut tris = Vec::new();
    tris.extend(pad(Vec3::ZERO, 1.0, 0));
    tris.extend(pad(far_centre, 100.0, 0));
    tris.extend(quad(Vec3::new(-0.5, -0.5, 1.0), Vec3::Y, Vec3::X, 1));
    let world = World::new(
        &scene(
            tris,
            vec![material(0.0, 0.0), material(0.0, panel)],
            Vec3::splat(sky),
            None,
        ),
        Preset::DEFAULT,
    )
    .unwrap();
    let near: Vec<TexelRecord> = (0..n)
        .map(|i| {
            texel(
                Vec3::ZERO,
                Vec3::Z,
                0.01,
                on_pad(Vec3::ZERO, Vec3::ZERO, 1.0, 0),
                i,
            )
        })
        .collect();
    let far: Vec<TexelRecord> = (0..n)
        .map(|i| {
            let p = far_centre + Vec3::new((i % 64) as f32, (i / 64) as f32, 0.0);
            texel(p, Vec3::Z, 0.01, on_pad(p, far_centre, 100.0, 2), i)
        })
        .collect();
    let f = form_factor(-0.5, 0.5, -0.5, 0.5, 1.0);
    let want_near = PI * panel * f + PI * sky * (1.0 - f);
    let want_far = PI * sky;
    for mode in MODES {
        let (out, rho) = bake_with_rho(&world, settings(mode, spp), &[near.clone(), far.clone()]);
        let (m, se) = mean_se(&out[0]);
        println!("{mode}: near {m} ± {se} (want {want_near}), F = {f}");
        assert!(
            (m.x - want_near).abs() <= 4.0 * se.x + 0.03 * want_near,
            "{mode}: near {m} ± {se}, want {want_near}"
        );
        let (m, se) = mean_se(&out[1]);
        println!("{mode}: far {m} ± {se} (want {want_far}), ρ = {rho}");
        let rho = rho as f32;
        assert!(
            (m.x / rho - want_far).abs() <= 4.0 * se.x / rho + 1e-3 * want_far,
            "{mode}: far {m} ± {se}, want {want_far}"
        );
    }
}

#[test]
fn radiance_from_1e_minus_4_to_1e5_in_one_scene() {
    dynamic_range(48, 96);
}

#[test]
#[ignore = "long: cargo test --release --test stress -- --ignored --nocapture"]
fn radiance_from_1e_minus_4_to_1e5_long() {
    dynamic_range(256, 512);
}

// ---------------------------------------------------------------------------------------------
// Zero albedo, all-zero gather.

/// A black (albedo 0) roof over part of a black ground, sun and sky: the roof adds nothing,
/// so a texel in the open gets exactly sun·cosθ + π·L_sky·(1 − F_roof), and one under the
/// roof's middle, in its shadow, only the sky around it.
#[test]
fn zero_albedo_reflects_nothing() {
    let sky = 0.3f32;
    let to_sun = Vec3::new(0.0, 0.0, 1.0);
    let sun = Sun {
        direction: to_sun,
        angular_radius: 0.0,
        irradiance: Vec3::splat(2.0),
    };
    let mut tris = Vec::new();
    tris.extend(pad(Vec3::ZERO, 0.5, 0));
    tris.extend(quad(
        Vec3::new(-1.0, -1.0, 1.0),
        Vec3::Y * 2.0,
        Vec3::X * 2.0,
        0,
    ));
    let world = World::new(
        &scene(tris, vec![material(0.0, 0.0)], Vec3::splat(sky), Some(sun)),
        Preset::DEFAULT,
    )
    .unwrap();
    let under: Vec<TexelRecord> = (0..32)
        .map(|i| {
            texel(
                Vec3::ZERO,
                Vec3::Z,
                0.01,
                on_pad(Vec3::ZERO, Vec3::ZERO, 0.5, 0),
                i,
            )
        })
        .collect();
    let f = form_factor(-1.0, 1.0, -1.0, 1.0, 1.0);
    for mode in MODES {
        let out = bake(&world, settings(mode, 96), std::slice::from_ref(&under));
        let (m, se) = mean_se(&out[0]);
        let want = PI * sky * (1.0 - f);
        assert!(
            (m - Vec3::splat(want)).abs().max_element() <= 4.0 * se.max_element() + 1e-4,
            "{mode}: {m} ± {se}, want {want}"
        );
    }
}

/// The 2 m cube around the origin, every face facing inwards, in `material`.
fn inward_cube(material: u32) -> Vec<Triangle> {
    inward_box_faces(Vec3::splat(-1.0), 2.0)
        .into_iter()
        .flat_map(|(origin, u, v)| quad(origin, u, v, material))
        .collect()
}

/// Inside a closed box of albedo 0.999 emitting Le, light bounces ~1000 times before it is
/// absorbed: path transport with the most bounces the bake allows (B = 64, Russian roulette
/// after the first vertices) must stay finite and unbiased, E_B = π·Le·(1 − ρ^B)/(1 − ρ)
/// ≈ 62·π·Le, within 4 standard errors of the mean over texels + 0.1 %.
fn albedo_0999(texels: usize, spp: u32) {
    let (albedo, le) = (0.999f32, 0.5f32);
    let mut world = World::new(
        &scene(
            inward_cube(0),
            vec![material(albedo, le)],
            Vec3::splat(100.0),
            None,
        ),
        Preset::DEFAULT,
    )
    .unwrap();
    world.set_transport(Transport::Path, MAX_BOUNCES);
    let on_floor: Vec<TexelRecord> = (0..texels)
        .map(|i| {
            let p = Vec3::new(
                -0.2 + 0.9 * (i % 64) as f32 / 64.0,
                -0.5 + 0.002 * (i / 64) as f32,
                -1.0,
            );
            texel(p, Vec3::Z, 0.01, 0, i)
        })
        .collect();
    let b = MAX_BOUNCES as i32;
    let want = (std::f64::consts::PI * f64::from(le) * (1.0 - f64::from(albedo).powi(b))
        / (1.0 - f64::from(albedo))) as f32;
    for mode in MODES {
        let s = BakeSettings {
            transport: Transport::Path,
            bounces: MAX_BOUNCES,
            ..settings(mode, spp)
        };
        let tiles: Vec<Vec<TexelRecord>> = on_floor.chunks(64).map(<[_]>::to_vec).collect();
        let out: Vec<Vec3> = bake(&world, s, &tiles).concat();
        let (m, se) = mean_se(&out);
        println!("albedo {albedo}, {mode}: {m} ± {se}, want {want}");
        assert!(
            (m.x - want).abs() <= 4.0 * se.x + 1e-3 * want,
            "{mode}: {m} ± {se}, want {want}"
        );
    }
}

#[test]
fn albedo_0999_energy_still_converges() {
    albedo_0999(64, 64);
}

#[test]
#[ignore = "long: cargo test --release --test stress -- --ignored --nocapture"]
fn albedo_0999_energy_still_converges_long() {
    albedo_0999(512, 256);
}

/// Inside a closed black box with no light: every sample is 0, learning sees no energy,
/// ρ has nothing to correct (0/0 must not become NaN) and every texel is exactly 0, valid.
#[test]
fn an_all_zero_gather_gives_exact_zeros() {
    let tris = inward_cube(0);
    let world = World::new(
        &scene(tris, vec![material(0.0, 0.0)], Vec3::splat(5.0), None),
        Preset::DEFAULT,
    )
    .unwrap();
    let texels: Vec<TexelRecord> = (0..24)
        .map(|i| texel(Vec3::new(0.0, 0.0, -0.999), Vec3::Z, 0.01, 0, i))
        .collect();
    for mode in MODES {
        for combine in [Combine::Average, Combine::Texel] {
            let s = BakeSettings {
                combine,
                ..settings(mode, 64)
            };
            let mut baker = TileBaker::new(&world, s);
            let mut buffer = TileBuffer::default();
            let baked = baker.bake_tile(0, 0, &texels, &mut buffer);
            let out = buffer.results;
            assert_eq!(rho_sums(&[baked.record]).rho(), 1.0, "{mode}");
            for r in &out {
                assert_eq!(r.irradiance, [0.0; 3], "{mode}: {r:?}");
                assert_eq!(
                    r.flags & FLAG_NO_FINITE_SAMPLES,
                    0,
                    "zeros are finite samples"
                );
                assert_eq!(r.rel_std_error, 0.0, "{mode}: {r:?}");
            }
            assert_eq!(baker.counters.samples_rejected, 0);
            if mode != Guiding::Off {
                assert!(baker.counters.iterations_unguided_no_energy > 0, "{mode}");
                assert_eq!(baker.counters.iterations_guided, 0, "{mode}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Degenerate geometry and texels.

/// The ground as a fan of 1000 slivers (aspect about 1:10⁴) plus a cloud of 1 mm triangles
/// (smaller than a texel) floating above it, black, under a constant sky. A texel on a
/// sliver must not see its own ground (a self-hit would darken it): unguided, every sample
/// is exactly π·L (sky) or 0 (a floater), so the mean lies in [0, π·L] and only the
/// floaters' solid angle (a few 10⁻⁵ of the hemisphere) may take sky away.
#[test]
fn slivers_and_sub_texel_triangles_stay_finite_and_do_not_self_shadow() {
    let sky = 0.8f32;
    let mut tris = Vec::new();
    let fan = 1000;
    let (r, centre) = (50.0f32, Vec3::ZERO);
    for k in 0..fan {
        let a0 = 2.0 * PI * k as f32 / fan as f32;
        let a1 = 2.0 * PI * (k + 1) as f32 / fan as f32;
        let p = |a: f32| Vec3::new(r * a.cos(), r * a.sin(), 0.0);
        tris.push(Triangle {
            positions: [centre, p(a0), p(a1)],
            normals: [Vec3::Z; 3],
            lightmap_uv: Some([Vec2::ZERO; 3]),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        });
    }
    for k in 0..200 {
        let c = Vec3::new(
            (k % 20) as f32 * 0.3 - 3.0,
            (k / 20) as f32 * 0.3 - 1.5,
            3.0,
        );
        tris.push(Triangle {
            positions: [c, c + Vec3::X * 1e-3, c + Vec3::Y * 1e-3],
            normals: [Vec3::NEG_Z; 3],
            lightmap_uv: Some([Vec2::ZERO; 3]),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        });
    }
    let world = World::new(
        &scene(tris, vec![material(0.0, 0.0)], Vec3::splat(sky), None),
        Preset::DEFAULT,
    )
    .unwrap();
    // Texels on slivers near their apex (the centre), along their long edges, and far out.
    let texels: Vec<TexelRecord> = (0..64)
        .map(|i| {
            let k = (i * 37) % fan;
            let a = 2.0 * PI * (k as f32 + [0.5, 0.01, 0.99, 0.5][i % 4]) / fan as f32;
            let d = [0.01, 1.0, 20.0, 49.0][i / 16];
            texel(
                Vec3::new(d * a.cos(), d * a.sin(), 0.0),
                Vec3::Z,
                0.02,
                k as u32,
                i,
            )
        })
        .collect();
    let full = PI * sky;
    for mode in MODES {
        let out = bake(&world, settings(mode, 96), std::slice::from_ref(&texels));
        let (m, se) = mean_se(&out[0]);
        println!("{mode}: {m} ± {se} (sky alone {full})");
        if mode == Guiding::Off {
            for (i, e) in out[0].iter().enumerate() {
                assert!(e.max_element() <= full * (1.0 + 1e-6), "texel {i}: {e}");
            }
        }
        assert!(
            m.x >= 0.99 * full - 4.0 * se.x,
            "{mode}: {m} ± {se}, want ≈ {full}"
        );
    }
}

/// 64 texels at one point with one normal (a degenerate chart, or duplicated texels):
/// clustering sees zero extent, every texel still gets its own random numbers, and the mean
/// under a constant sky is π·L.
#[test]
fn coincident_texels_bake_independently() {
    let sky = Vec3::new(0.2, 0.4, 0.6);
    let world = World::new(
        &scene(
            quad(
                Vec3::new(-10.0, -10.0, 0.0),
                Vec3::X * 20.0,
                Vec3::Y * 20.0,
                0,
            )
            .to_vec(),
            vec![material(0.5, 0.0)],
            sky,
            None,
        ),
        Preset::DEFAULT,
    )
    .unwrap();
    let texels: Vec<TexelRecord> = (0..64)
        .map(|i| texel(Vec3::new(0.3, 0.2, 0.0), Vec3::Z, 0.0, 0, i))
        .collect();
    for mode in MODES {
        let out = bake(&world, settings(mode, 64), std::slice::from_ref(&texels));
        let (m, se) = mean_se(&out[0]);
        assert!(
            ((m - sky * PI).abs() - se * 4.0).max_element() <= 1e-4,
            "{mode}: {m} ± {se}, want {}",
            sky * PI
        );
    }
}

fn tilted_normals(ground_half: f32, thetas: &[f32]) {
    let sky = 1.0f32;
    let world = World::new(
        &scene(
            pad(Vec3::ZERO, ground_half, 0).to_vec(),
            vec![material(0.0, 0.0)],
            Vec3::splat(sky),
            None,
        ),
        Preset::DEFAULT,
    )
    .unwrap();
    for &theta in thetas {
        let n = Vec3::new(theta.sin(), 0.0, theta.cos());
        let texels: Vec<TexelRecord> = (0..48)
            .map(|i| {
                let p = Vec3::new(0.01 * i as f32, 0.0, 0.0);
                texel(p, n, 0.01, on_pad(p, Vec3::ZERO, ground_half, 0), i)
            })
            .collect();
        let want = PI * sky * (1.0 + theta.cos()) / 2.0;
        for mode in MODES {
            let out = bake(&world, settings(mode, 96), std::slice::from_ref(&texels));
            let (m, se) = mean_se(&out[0]);
            assert!(
                (m.x - want).abs() <= 4.0 * se.x + 0.01 * want,
                "ground {ground_half} m, θ = {theta}, {mode}: {m} ± {se}, want {want}"
            );
        }
    }
}

/// Texel normals tilted θ from the ground's normal, up to 10⁻³ rad short of tangent, on
/// a black 2 m ground under a constant sky: the hemisphere around the normal sees the sky
/// over the part above the ground, E = π·L·(1 + cos θ)/2 (within 4 standard errors + 1 %).
/// The gather must neither leak below the ground nor lose the upper part to self-hits.
#[test]
fn normals_nearly_tangent_to_the_surface() {
    tilted_normals(1.0, &[1.0, 1.5, PI / 2.0 - 1e-2]);
}

/// A texel normal 10⁻³ rad short of tangent. Found failing by this test (issue 8): the gather
/// offset its origins along the *texel's* normal, so the origin rose only 10⁻³ × 1.5·10⁻⁵ m
/// above its surface and grazing rays slipped through the ground (1.678 ± 0.014 instead of
/// π(1 + cos θ)/2 = 1.572, 7 % bright). Origins are now offset along the triangle's own
/// normal on the texel's side.
#[test]
fn normal_within_a_milliradian_of_tangent() {
    tilted_normals(1.0, &[PI / 2.0 - 1e-3]);
}

/// The same on a 2 km ground of two triangles. Found failing by this test (issue 8): near the
/// origin `offset_origin` lifted origins by a fixed 1.5·10⁻⁵, but a grazing ray's hit
/// distance on a triangle whose vertices are 10³ away is only known to about 10⁻⁴, so rays
/// leaving just above the surface "hit" their own ground (θ = 0.5 gave 2.61 instead of 2.95,
/// θ = 1 gave 2.10 instead of 2.42: 13 % dark). The lift now grows with the triangle's size
/// seen from the origin (`triangle_extent`).
#[test]
fn grazing_rays_on_a_large_ground() {
    tilted_normals(1e3, &[0.5, 1.0, 1.5]);
}

/// Texels under a 1 m emitting panel on a 20 km ground quad. Found failing by this test
/// (issue 8): `World::onto_triangle` moved every gather origin a thousandth of the way to
/// its triangle's centroid, 3–5 m here, so the texels gathered from beside the panel (205 ±
/// 142 instead of π·L·F = 7.5·10⁴). The nudge is now capped at a hundredth of the texel.
#[test]
fn origins_stay_on_their_texel_on_a_huge_triangle() {
    let panel = 1e5f32;
    let mut tris = pad(Vec3::ZERO, 1e4, 0).to_vec();
    tris.extend(quad(Vec3::new(-0.5, -0.5, 1.0), Vec3::Y, Vec3::X, 1));
    let world = World::new(
        &scene(
            tris,
            vec![material(0.0, 0.0), material(0.0, panel)],
            Vec3::ZERO,
            None,
        ),
        Preset::DEFAULT,
    )
    .unwrap();
    let texels: Vec<TexelRecord> = (0..32)
        .map(|i| texel(Vec3::ZERO, Vec3::Z, 0.01, 0, i))
        .collect();
    let out = bake(&world, settings(Guiding::Off, 96), &[texels]);
    let (m, se) = mean_se(&out[0]);
    let want = PI * panel * form_factor(-0.5, 0.5, -0.5, 0.5, 1.0);
    assert!(
        (m.x - want).abs() <= 4.0 * se.x + 0.03 * want,
        "{m} ± {se}, want {want}"
    );
}

/// A small, very bright source (radiance 10⁷ on 4 × 4 cm, 1 m up, F ≈ 5·10⁻⁴) that a
/// cluster's 64 × 32 learning samples hit about once: the next iteration's guide is
/// learned from a single firefly. The guided bakes stay finite and agree with the analytic irradiance π·L·F, like
/// the unguided one, within 5 standard errors of the mean over texels plus the 3 %
/// Graybill–Deal allowance.
fn single_firefly(texels: usize, spp: u32) {
    let radiance = 1e7f32;
    let side = 0.04f32;
    let mut tris = Vec::new();
    tris.extend(pad(Vec3::ZERO, 0.5, 0));
    tris.extend(quad(
        Vec3::new(-side / 2.0, -side / 2.0, 1.0),
        Vec3::Y * side,
        Vec3::X * side,
        1,
    ));
    let world = World::new(
        &scene(
            tris,
            vec![material(0.0, 0.0), material(0.0, radiance)],
            Vec3::ZERO,
            None,
        ),
        Preset::DEFAULT,
    )
    .unwrap();
    // Texels spread over a few cm so each has its own view; all see the source near zenith.
    let tiles: Vec<Vec<TexelRecord>> = (0..texels / 64)
        .map(|t| {
            (0..64)
                .map(|i| {
                    let p = Vec3::new(0.001 * i as f32, 0.001 * t as f32, 0.0);
                    texel(p, Vec3::Z, 0.001, on_pad(p, Vec3::ZERO, 0.5, 0), i)
                })
                .collect()
        })
        .collect();
    let h = side / 2.0;
    let want = PI * radiance * form_factor(-h, h, -h, h, 1.0);
    for mode in MODES {
        let s = BakeSettings {
            iterations: 4,
            ..settings(mode, spp)
        };
        let out: Vec<Vec3> = bake(&world, s, &tiles).concat();
        let (m, se) = mean_se(&out);
        println!("{mode}: {m} ± {se}, want {want}");
        assert!(
            (m.x - want).abs() <= 5.0 * se.x + 0.03 * want,
            "{mode}: {m} ± {se}, want {want}"
        );
    }
}

#[test]
fn a_guide_learned_from_a_single_firefly() {
    single_firefly(256, 128);
}

#[test]
#[ignore = "long: cargo test --release --test stress -- --ignored --nocapture"]
fn a_guide_learned_from_a_single_firefly_long() {
    single_firefly(4096, 256);
}
