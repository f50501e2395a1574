//! The gather against analytic light (sky, sun, emissive box, sphere, point and spot lights,
//! the spherical harmonics of a sun and a gradient sky) and the tile's invariants (the grid
//! comparator's squares, invalid texels, the same bits twice); the fixtures the learning and
//! iteration tests share.

use super::cluster::{cluster_frame, gather_texel};
use super::learning::seed_side;
use super::*;
use crate::bake::directional;
use crate::bake::settings::EmitterSampling;
use crate::bvh::Preset;
use crate::output::result_file::{FLAG_BAKED, FLAG_UNGUIDED};
use crate::output::result_file::{FinishedResults, ResultFile};
use crate::scene::{Material, Scene, Sky, Sun, Triangle};
use crate::test_support::{inward_box_faces, quad};
use crate::transport::emitters::EmitterSelection;
use guidebake_kernels::estimator::{PlainAverage, combine_weighted};
use guidebake_kernels::guide::{self, GuideParams, Record};
use guidebake_kernels::mapping::sample_cosine_hemisphere;
use guidebake_kernels::packet::LANES;
use guidebake_kernels::sobol::to_unit;
use guidebake_kernels::warp;

mod iteration;
mod learning;

/// The 2 m cube around the origin, every face facing inwards.
fn inward_cube(material: u32) -> Vec<Triangle> {
    inward_box_faces(Vec3::splat(-1.0), 2.0)
        .into_iter()
        .flat_map(|(origin, u, v)| quad(origin, u, v, material))
        .collect()
}

fn scene(triangles: Vec<Triangle>, materials: Vec<Material>, sky: Sky, sun: Option<Sun>) -> Scene {
    Scene {
        sky,
        sun,
        ..Scene::of_triangles("test", triangles, materials)
    }
}

fn grey(albedo: f32, emission: f32) -> Material {
    Material {
        name: "m".into(),
        base_color_texture: None,
        albedo: Vec3::splat(albedo),
        emission: Vec3::splat(emission),
    }
}

/// A 20 m ground square at z = 0, facing +z.
fn ground() -> Vec<Triangle> {
    quad(
        Vec3::new(-10.0, -10.0, 0.0),
        Vec3::X * 20.0,
        Vec3::Y * 20.0,
        0,
    )
    .to_vec()
}

/// The world of `triangles` in one material under a constant sky and an optional sun.
fn world(triangles: Vec<Triangle>, material: Material, sky: Vec3, sun: Option<Sun>) -> World {
    World::new(
        &scene(triangles, vec![material], Sky::Constant(sky), sun),
        Preset::DEFAULT,
    )
    .unwrap()
}

/// `n` texels on the plane z = `z` around the origin, normal +z, footprint 1 cm.
/// Each lies on the triangle of [`quad`]'s pair that holds it when the quad is the ground
/// or the cube's floor (the first triangle where y ≤ x).
fn texels_on_plane(n: usize, z: f32) -> Vec<TexelRecord> {
    (0..n)
        .map(|i| (i, (i % 8) as f32 * 0.05 - 0.2, (i / 8) as f32 * 0.05 - 0.2))
        .map(|(i, x, y)| TexelRecord {
            position: [x, y, z],
            normal: [0.0, 0.0, 1.0],
            dpdu: [0.01, 0.0, 0.0],
            dpdv: [0.0, 0.01, 0.0],
            page: 0,
            pixel: [(i % 8) as u16, (i / 8) as u16],
            triangle: u32::from(y > x),
            flags: TEXEL_VALID,
        })
        .collect()
}

/// Mean irradiance over the texels and its standard error (from the texels' spread),
/// after the bias correction ρ of the tile's sums, as the bake's final pass applies it:
/// Graybill–Deal alone is biased when a batch's variance correlates with its mean.
fn bake_mean(
    world: &World,
    settings: BakeSettings,
    texels: &[TexelRecord],
) -> (Vec3, Vec3, GatherCounters) {
    bake_mean_of(TileBaker::new(world, settings), texels)
}

/// [`bake_mean`] of a given baker.
fn bake_mean_of(mut baker: TileBaker<'_>, texels: &[TexelRecord]) -> (Vec3, Vec3, GatherCounters) {
    let mut out = TileBuffer::default();
    let baked = baker.bake_tile(0, 1000, texels, &mut out);
    let out = out.results;
    let sums = crate::output::journal::rho_sums(&[baked.record]);
    let rho = sums.rho() as f32;
    let values: Vec<Vec3> = out.iter().map(|r| Vec3::from(r.irradiance) * rho).collect();
    assert!(values.iter().all(|v| v.is_finite()));
    assert!(out.iter().all(|r| r.flags & FLAG_BAKED != 0));
    let n = values.len() as f32;
    let mean = values.iter().copied().sum::<Vec3>() / n;
    let var = values
        .iter()
        .map(|v| (*v - mean) * (*v - mean))
        .sum::<Vec3>()
        / (n - 1.0);
    (mean, (var / n).powf(0.5), baker.counters)
}

fn assert_within_3_sigma(what: &str, (mean, se): (Vec3, Vec3), want: Vec3) {
    let tol = se * 3.0 + want.abs() * 2e-4;
    assert!(
        (mean - want).abs().cmple(tol).all(),
        "{what}: {mean:?} ± {se:?}, want {want:?}"
    );
}

const MODES: [Guiding; 4] = [
    Guiding::Off,
    Guiding::Naive,
    Guiding::Coherent,
    Guiding::Grid,
];

fn settings(guiding: Guiding) -> BakeSettings {
    BakeSettings {
        spp: 128,
        iterations: 3,
        guiding,
        ..Default::default()
    }
}

#[test]
fn a_plane_under_a_constant_sky_receives_pi_l() {
    let sky = Vec3::new(0.5, 1.0, 2.0);
    let world = world(ground(), grey(0.5, 0.0), sky, None);
    for mode in MODES {
        let (mean, se, counters) = bake_mean(&world, settings(mode), &texels_on_plane(64, 0.0));
        assert_within_3_sigma(&format!("{mode}"), (mean, se), sky * core::f32::consts::PI);
        assert_eq!(counters.gather_rays, 64 * 128);
        assert_eq!(counters.shadow_rays, 0, "no lights, no shadow rays");
    }
}

#[test]
fn a_sun_adds_its_cosine_law_and_is_blocked_inside_a_closed_box() {
    let sky = Vec3::splat(0.2);
    let to_sun = Vec3::new(0.3, 0.1, 1.0).normalize();
    let sun = Sun {
        direction: to_sun,
        angular_radius: 0.05,
        irradiance: Vec3::new(3.0, 2.0, 1.0),
    };
    let open = world(ground(), grey(0.0, 0.0), sky, Some(sun.clone()));
    let want = sun.irradiance * to_sun.z + sky * core::f32::consts::PI;
    for mode in MODES {
        let (mean, se, _) = bake_mean(&open, settings(mode), &texels_on_plane(64, 0.0));
        assert_within_3_sigma(&format!("{mode}"), (mean, se), want);
    }
    // Inside a closed black box: no sun, no sky, and learning sees no energy.
    let closed = world(inward_cube(0), grey(0.0, 0.0), sky, Some(sun));
    for mode in MODES {
        let (mean, _, counters) = bake_mean(&closed, settings(mode), &texels_on_plane(16, -0.999));
        assert_eq!(mean, Vec3::ZERO, "{mode}");
        assert!(
            counters.shadow_rays > 0,
            "{mode}: the sun was tested and found blocked"
        );
        assert!(
            counters.iterations_unguided_no_energy > 0 || mode == Guiding::Off,
            "{mode}: {counters:?}"
        );
    }
}

/// Series transport's direct pass: next-event estimation alone, no gather ray. Under a
/// sun and a sky it bakes the sun's cosine law without the sky (which only gather rays
/// find); inside a closed emissive box, π Le from the emitters sampled as lights (weighing
/// 1: there is no gather to weigh them against) — in every guiding mode.
#[test]
fn the_direct_pass_bakes_the_direct_light_alone() {
    let to_sun = Vec3::new(0.3, 0.1, 1.0).normalize();
    let sun = Sun {
        direction: to_sun,
        angular_radius: 0.05,
        irradiance: Vec3::new(3.0, 2.0, 1.0),
    };
    let open = world(
        ground(),
        grey(0.5, 0.0),
        Vec3::splat(0.2),
        Some(sun.clone()),
    );
    let le = 1.5;
    let boxed = world(inward_cube(0), grey(0.5, le), Vec3::splat(100.0), None);
    for mode in MODES {
        let direct = |world| TileBaker::new(world, settings(mode)).direct_only(true);
        let (mean, se, counters) = bake_mean_of(direct(&open), &texels_on_plane(64, 0.0));
        assert_within_3_sigma(&format!("{mode}"), (mean, se), sun.irradiance * to_sun.z);
        assert_eq!(counters.gather_rays, 0, "{mode}");
        assert_eq!(counters.shadow_rays, 64 * 128, "{mode}: one per sample");
        assert_eq!(counters.clusters, 0, "{mode}: nothing to learn");
        let (mean, se, _) = bake_mean_of(direct(&boxed), &texels_on_plane(32, -0.999));
        let want = Vec3::splat(le * core::f32::consts::PI);
        assert_within_3_sigma(&format!("{mode}, box"), (mean, se), want);
        // `--direct-spp`: that many next-event samples, the gather's 128 notwithstanding.
        let more = BakeSettings {
            direct_spp: Some(320),
            ..settings(mode)
        };
        let baker = TileBaker::new(&open, more).direct_only(true);
        let (mean, se, counters) = bake_mean_of(baker, &texels_on_plane(64, 0.0));
        assert_within_3_sigma(
            &format!("{mode}, 320"),
            (mean, se),
            sun.irradiance * to_sun.z,
        );
        assert_eq!(counters.shadow_rays, 64 * 320, "{mode}: --direct-spp 320");
    }
}

#[test]
fn inside_a_closed_emissive_box_every_texel_sees_pi_le() {
    // A 2 m cube emitting Le inwards, albedo 0: E = π Le in the first pass.
    let le = 1.5;
    let world = world(inward_cube(0), grey(0.0, le), Vec3::splat(100.0), None);
    for mode in MODES {
        let (mean, se, _) = bake_mean(&world, settings(mode), &texels_on_plane(32, -0.999));
        assert_within_3_sigma(
            &format!("{mode}"),
            (mean, se),
            Vec3::splat(le * core::f32::consts::PI),
        );
    }
}

/// An equirectangular sky of `h` rows × `4h` columns whose radiance depends on the
/// latitude only: row j (θ from the +y zenith in [jπ/h, (j+1)π/h]) holds
/// `colour · (a + b cos θ_mid)` — a sky brighter towards +y, a gradient across the
/// ground's normal +z.
fn gradient_sky(h: u32, colour: Vec3, a: f32, b: f32) -> (Sky, Vec<Vec3>) {
    let rows: Vec<Vec3> = (0..h)
        .map(|j| {
            let mid = (j as f32 + 0.5) * core::f32::consts::PI / h as f32;
            colour * (a + b * mid.cos())
        })
        .collect();
    let pixels = rows
        .iter()
        .flat_map(|&l| std::iter::repeat_n(l, 4 * h as usize))
        .collect();
    let sky = Sky::Equirect {
        path: "gradient.exr".into(),
        width: 4 * h,
        height: h,
        pixels,
    };
    (sky, rows)
}

/// The exact L1 coefficients of [`gradient_sky`]'s rows over the hemisphere z > 0 (the
/// ground's), cell by cell in closed form (docs/lightmaps.md derives them): with the sky's
/// φ = atan2(x, −z), the hemisphere is the columns with |φ| > π/2, a whole number of them,
/// and per row `∫dω = π (cos θ0 − cos θ1)`, `∫ω_y dω = (π/2)(sin²θ1 − sin²θ0)`,
/// `∫ω_z dω = 2 ∫sin²θ dθ`, `∫ω_x dω = 0` (odd in φ over the hemisphere).
fn gradient_sky_coefficients(rows: &[Vec3]) -> [Vec3; 4] {
    use std::f64::consts::PI;
    let h = rows.len() as f64;
    let mut c = [glam::DVec3::ZERO; 4];
    for (j, l) in rows.iter().enumerate() {
        let (t0, t1) = (j as f64 * PI / h, (j + 1) as f64 * PI / h);
        let sin2 = |t: f64| t / 2.0 - (2.0 * t).sin() / 4.0;
        let l = l.as_dvec3();
        c[0] += l * (PI * (t0.cos() - t1.cos()));
        c[2] += l * (PI / 2.0 * (t1.sin().powi(2) - t0.sin().powi(2)));
        c[3] += l * (2.0 * (sin2(t1) - sin2(t0)));
    }
    let (y0, y1) = (f64::from(directional::Y0), f64::from(directional::Y1));
    [c[0] * y0, c[1] * y1, c[2] * y1, c[3] * y1].map(|v| v.as_vec3())
}

/// The texels' directional coefficients (after ρ, as the final pass applies it): mean
/// and standard error over the texels, per coefficient.
fn bake_sh_mean(
    world: &World,
    settings: BakeSettings,
    texels: &[TexelRecord],
) -> ([Vec3; 4], [Vec3; 4]) {
    let mut baker = TileBaker::new(world, settings).keep_directional(true);
    let mut out = TileBuffer::default();
    let baked = baker.bake_tile(0, 1000, texels, &mut out);
    let rho = crate::output::journal::rho_sums(&[baked.record]).rho();
    assert_eq!(out.directional.len(), texels.len());
    let values: Vec<[f32; 12]> = out.directional.iter().map(|s| s.scaled(rho)).collect();
    let n = values.len() as f64;
    let (mut mean, mut se) = ([Vec3::ZERO; 4], [Vec3::ZERO; 4]);
    for i in 0..12 {
        let m = values.iter().map(|v| f64::from(v[i])).sum::<f64>() / n;
        let var = values
            .iter()
            .map(|v| (f64::from(v[i]) - m).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        mean[i / 3][i % 3] = m as f32;
        se[i / 3][i % 3] = (var / n).sqrt() as f32;
    }
    (mean, se)
}

#[test]
fn a_sun_and_a_gradient_sky_give_the_analytic_sh_coefficients() {
    let (sky, rows) = gradient_sky(32, Vec3::new(0.5, 1.0, 2.0), 1.0, 0.8);
    let to_sun = Vec3::new(0.3, 0.1, 1.0).normalize();
    let alpha = 0.05f32;
    let sun = Sun {
        direction: to_sun,
        angular_radius: alpha,
        irradiance: Vec3::new(3.0, 2.0, 1.0),
    };
    let world = World::new(
        &scene(ground(), vec![grey(0.0, 0.0)], sky, Some(sun.clone())),
        Preset::DEFAULT,
    )
    .unwrap();
    // The sun: a disc of radiance E/(π sin²α): ∫L dω = E · 2/(1 + cos α), ∫L ω dω = E s.
    let mut want = gradient_sky_coefficients(&rows);
    want[0] += sun.irradiance * (directional::Y0 * 2.0 / (1.0 + alpha.cos()));
    for (a, s) in [to_sun.x, to_sun.y, to_sun.z].into_iter().enumerate() {
        want[1 + a] += sun.irradiance * (directional::Y1 * s);
    }
    // L1x: the sun's alone (the sky's is 0 by symmetry), L1y the sky's gradient.
    assert!(want[2].x > 0.1 && want[1].x > 0.1, "{want:?}");
    for (mode, combine) in [
        (Guiding::Off, Combine::Average),
        (Guiding::Naive, Combine::Texel),
        (Guiding::Coherent, Combine::Texel),
        (Guiding::Coherent, Combine::Cluster),
        (Guiding::Grid, Combine::Average),
    ] {
        let settings = BakeSettings {
            combine,
            bias_correction: combine == Combine::Texel,
            directional: Directional::ShL1,
            ..settings(mode)
        };
        let (mean, se) = bake_sh_mean(&world, settings, &texels_on_plane(64, 0.0));
        // Printed for docs/lightmaps.md (`-- --nocapture`).
        eprintln!("{mode} {combine}: L = {mean:?} ± {se:?}, analytic {want:?}");
        for i in 0..4 {
            assert_within_3_sigma(&format!("{mode} {combine} L{i}"), (mean[i], se[i]), want[i]);
        }
    }
}

#[test]
fn directional_coefficients_reconstruct_the_irradiance_and_leave_it_unchanged() {
    let sky = Vec3::new(0.5, 1.0, 2.0);
    let world = world(ground(), grey(0.5, 0.0), sky, None);
    let texels = texels_on_plane(64, 0.0);
    // Global weights: the tile keeps K means per texel for the final pass.
    let plain = BakeSettings {
        combine: Combine::Global,
        bias_correction: false,
        ..settings(Guiding::Coherent)
    };
    let with = BakeSettings {
        directional: Directional::ShL1,
        ..plain
    };
    let (mut a, mut b) = (TileBuffer::default(), TileBuffer::default());
    TileBaker::new(&world, plain).bake_tile(0, 0, &texels, &mut a);
    let mut baker = TileBaker::new(&world, with).keep_directional(true);
    baker.bake_tile(0, 0, &texels, &mut b);
    assert_eq!(a.results, b.results, "the irradiance does not change");
    assert!(a.directional.is_empty());
    // Global weights: K means per texel, combined in the final pass.
    let k = with.iterations as usize;
    assert_eq!(b.directional.len(), texels.len() * k);
    let e: Vec<Vec3> = (0..texels.len())
        .map(|i| {
            let sh = directional::combine(
                &b.directional[i * k..(i + 1) * k],
                &b.batches[i * k..(i + 1) * k],
                &PlainAverage,
            );
            assert!(sh.coefficients.iter().all(|c| c.is_finite()));
            sh.irradiance(Vec3::Z)
        })
        .collect();
    // (√π/2) L0 + √(π/3) L1·n estimates the irradiance: per sample it is
    // `E (1/(4 cosθ) + 1/2)`, whose mean under the cosine density is E.
    let n = e.len() as f32;
    let mean = e.iter().copied().sum::<Vec3>() / n;
    let var = e.iter().map(|v| (*v - mean) * (*v - mean)).sum::<Vec3>() / (n - 1.0);
    let want = sky * core::f32::consts::PI;
    assert_within_3_sigma("E(n) from SH", (mean, (var / n).powf(0.5)), want);
}

/// A black ground under a black sky lit by `lights` only.
fn lit_world(lights: Vec<crate::scene::SceneLight>) -> World {
    let mut scene = scene(ground(), vec![grey(0.0, 0.0)], Sky::None, None);
    scene.lights = lights;
    World::new(&scene, Preset::DEFAULT).unwrap()
}

#[test]
fn a_sphere_light_facing_a_point_gives_pi_l_r_over_d_squared() {
    let (radius, d, l) = (0.25f32, 2.0f32, Vec3::new(40.0, 20.0, 10.0));
    let world = lit_world(vec![crate::scene::SceneLight::Sphere {
        center: Vec3::new(0.0, 0.0, d),
        radius,
        radiance: l,
    }]);
    // Texels within 0.2 m of the axis: the closed form holds at the axis; off it, the
    // cosine and distance change by at most 1 % here, so use the mean over the texels.
    let texels = texels_on_plane(64, 0.0);
    let want = texels
        .iter()
        .map(|t| {
            let p = Vec3::from(t.position);
            let to = Vec3::new(0.0, 0.0, d) - p;
            let (dist, cos) = (to.length(), to.normalize().z);
            // Exact for a sphere seen from a point: π L sin²θmax · cos of its centre
            // direction (the cone lies wholly above the horizon).
            l * core::f32::consts::PI * (radius / dist).powi(2) * cos
        })
        .sum::<Vec3>()
        / texels.len() as f32;
    let on_axis = l * core::f32::consts::PI * (radius / d).powi(2);
    assert!((want - on_axis).abs().max_element() < 0.02 * on_axis.max_element());
    for mode in MODES {
        let (mean, se, counters) = bake_mean(&world, settings(mode), &texels);
        assert_within_3_sigma(&format!("{mode}"), (mean, se), want);
        assert!(counters.shadow_rays > 0);
    }
}

#[test]
fn point_and_spot_lights_follow_the_cosine_and_inverse_square_laws() {
    use crate::transport::lights::spot_falloff;
    let intensity = Vec3::new(8.0, 4.0, 2.0);
    let position = Vec3::new(1.5, -0.5, 2.0);
    let axis = (Vec3::new(0.4, 0.0, 0.0) - position).normalize();
    // A penumbra wide against the 1 cm texels, whose origins are jittered over them.
    let (inner, outer) = (0.05f32, 0.3f32);
    let point = crate::scene::SceneLight::Point {
        position,
        intensity,
    };
    let spot = crate::scene::SceneLight::Spot {
        position,
        direction: axis,
        intensity,
        inner_cone: inner,
        outer_cone: outer,
    };
    let texels = texels_on_plane(64, 0.0);
    for (light, is_spot) in [(point, false), (spot, true)] {
        let world = lit_world(vec![light]);
        let mut baker = TileBaker::new(&world, settings(Guiding::Coherent));
        let mut out = TileBuffer::default();
        baker.bake_tile(0, 0, &texels, &mut out);
        let out = out.results;
        let mut dimmed = 0;
        for (t, r) in texels.iter().zip(&out) {
            let to = position - Vec3::from(t.position);
            let mut want = intensity * to.normalize().z / to.length_squared();
            if is_spot {
                want *= spot_falloff(-to.normalize().dot(axis), inner.cos(), outer.cos());
            }
            let full = intensity * to.normalize().z / to.length_squared();
            dimmed += usize::from(want.x < 0.99 * full.x);
            // A delta light: no noise beyond the origins jittered within the 1 cm texel.
            let got = Vec3::from(r.irradiance);
            assert!(
                (got - want).abs().max_element() < 0.01 * intensity.x / to.length_squared(),
                "spot {is_spot}: {got} vs {want}"
            );
        }
        assert_eq!(dimmed > 0, is_spot, "{dimmed} texels in the spot's falloff");
    }
}

#[test]
fn the_grid_comparator_learns_per_8x8_square_of_texels() {
    let world = world(ground(), grey(0.5, 0.0), Vec3::ONE, None);
    // A 16×16-texel tile: four squares of 8×8.
    let texels: Vec<TexelRecord> = (0..256)
        .map(|i| {
            let mut t = texels_on_plane(1, 0.0)[0];
            t.pixel = [(i % 16) as u16, (i / 16) as u16];
            t.position = [(i % 16) as f32 * 0.02, (i / 16) as f32 * 0.02, 0.0];
            t.triangle = u32::from(t.position[1] > t.position[0]);
            t
        })
        .collect();
    let settings = BakeSettings {
        spp: 64,
        iterations: 3,
        guiding: Guiding::Grid,
        ..Default::default()
    };
    let mut baker = TileBaker::new(&world, settings);
    baker.bake_tile(0, 0, &texels, &mut TileBuffer::default());
    assert_eq!(baker.counters.clusters, 4, "{:?}", baker.counters);
    assert_eq!(
        baker.counters.iterations_guided,
        4 * 2,
        "every square learns after iterations 0 and 1"
    );
    let squares: Vec<Vec<(u16, u16)>> = baker.ranges[..4]
        .iter()
        .map(|r| {
            baker.permutation[r.start as usize..r.end as usize]
                .iter()
                .map(|&m| {
                    let p = texels[baker.valid[m as usize] as usize].pixel;
                    (p[0] / 8, p[1] / 8)
                })
                .collect()
        })
        .collect();
    for sq in &squares {
        assert_eq!(sq.len(), 64);
        assert!(sq.iter().all(|&s| s == sq[0]), "one square per group");
    }
}

#[test]
fn invalid_texels_are_skipped_and_counted() {
    let world = world(ground(), grey(0.5, 0.0), Vec3::ONE, None);
    let mut texels = texels_on_plane(16, 0.0);
    texels[3].flags = 0;
    let mut baker = TileBaker::new(&world, settings(Guiding::Coherent));
    let mut out = TileBuffer::default();
    let baked = baker.bake_tile(5, 0, &texels, &mut out);
    let out = out.results;
    assert_eq!(out[3], TexelResult::default());
    assert_eq!(baker.counters.texels_invalid_skipped, 1);
    assert_eq!(baked.record.texels, 15);
    assert_eq!(baked.record.tile, 5);
}

#[test]
fn a_tile_bakes_to_the_same_bits_twice() {
    let mut tris = ground();
    tris.extend(quad(
        Vec3::new(-0.3, -0.3, 0.5),
        Vec3::Y * 0.6,
        Vec3::X * 0.6,
        0,
    ));
    let world = world(tris, grey(0.5, 0.0), Vec3::ONE, None);
    let texels = texels_on_plane(40, 0.0);
    let run = || {
        let mut out = TileBuffer::default();
        TileBaker::new(&world, settings(Guiding::Coherent)).bake_tile(0, 7, &texels, &mut out);
        out.results
    };
    assert_eq!(
        bytemuck::cast_slice::<_, u8>(&run()),
        bytemuck::cast_slice::<_, u8>(&run())
    );
}
