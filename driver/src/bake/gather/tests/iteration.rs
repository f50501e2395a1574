//! One iteration's gather: one frame per cluster, the mixture's sampled density, the
//! 8-wide density against the scalar one.

use super::*;

/// One frame per cluster: texels on a wall facing +x whose normals have n.z = +0 and
/// n.z = −0 (and ±1e-7) map every point of the square to the same direction. The old
/// per-texel frame turned by 180° between them.
#[test]
fn texels_of_one_cluster_sample_the_same_directions() {
    let world = world(ground(), grey(0.5, 0.0), Vec3::ONE, None);
    let settings = BakeSettings::default();
    let normals = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, -0.0),
        Vec3::new(1.0, 0.0, 1e-7),
        Vec3::new(1.0, 0.0, -1e-7),
    ];
    let records: Vec<TexelRecord> = normals
        .iter()
        .map(|n| TexelRecord {
            normal: n.to_array(),
            ..texels_on_plane(1, 0.0)[0]
        })
        .collect();
    let frame = cluster_frame(normals.iter().copied());
    let ctx = IterationCtx::new(&world, &settings, 0, None);
    let directions = |per_texel: bool| -> Vec<Vec<Vec3>> {
        records
            .iter()
            .map(|r| {
                let mut t = gather_texel(r, 0, frame);
                if per_texel {
                    (t.tangent, t.bitangent) = texel_basis(t.normal);
                }
                (0..64)
                    .map(|i| {
                        let u = [(i % 8) as f32 / 8.0 + 0.06, (i / 8) as f32 / 8.0 + 0.02];
                        ctx.to_world(&t, sample_cosine_hemisphere(u))
                    })
                    .collect()
            })
            .collect()
    };
    let cluster = directions(false);
    for texel in &cluster[1..] {
        for (a, b) in texel.iter().zip(&cluster[0]) {
            assert!((*a - *b).length() < 1e-5, "{a} vs {b}");
        }
    }
    let texel = directions(true);
    let apart = texel[1]
        .iter()
        .zip(&texel[0])
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f32::max);
    assert!(
        apart > 1.0,
        "the per-texel frame flips at n.z = -0 ({apart})"
    );
}

/// The density the gather reports for a direction is the mixture's, `c + (1 − c)·q(u)`
/// at the inverse-mapped point (`q` the same guide built without the mixture), for
/// points the mixed guide sampled and for any other point.
#[test]
fn the_sampled_density_is_the_mixtures() {
    let world = world(ground(), grey(0.5, 0.0), Vec3::ONE, None);
    let settings = BakeSettings::default();
    let mut records: Vec<Record> = (0..4096)
        .map(|i| {
            let u = [((i * 37) % 4096) as f32 / 4096.0, (i % 64) as f32 / 64.0];
            let flux = if u[0] < 0.3 && u[1] > 0.6 { 10.0 } else { 0.1 };
            Record { u, flux }
        })
        .collect();
    let c = settings.uniform_share();
    assert_eq!(c, 0.25, "the default mixture");
    let mut nodes = vec![GuideNode::default(); GUIDE_CAPACITY];
    let (plain, _) = guide::build(&mut records.clone(), &GuideParams::default(), &mut nodes);
    let mut mixed_nodes = vec![GuideNode::default(); GUIDE_CAPACITY];
    let params = GuideParams {
        uniform: c,
        ..GuideParams::default()
    };
    let (g, _) = guide::build(&mut records, &params, &mut mixed_nodes);
    assert!(!g.is_uniform());
    let ctx = IterationCtx::new(&world, &settings, 2, Some(IterationGuide::Tree(&g)));
    let t = gather_texel(
        &texels_on_plane(1, 0.0)[0],
        0,
        cluster_frame([Vec3::Z].into_iter()),
    );
    for i in 0..200u32 {
        // Off the square's rim, which maps to the horizon (density 0 there).
        let u = [
            0.02 + 0.96 * to_unit(i.wrapping_mul(0x9e37_79b9)),
            0.02 + 0.96 * (i as f32 + 0.5) / 200.0,
        ];
        let s = warp::sample(&g, u);
        for w in [u, s.u] {
            let dir = ctx.to_world(&t, sample_cosine_hemisphere(w));
            let got = ctx.sampled_density(&t, dir);
            let want = c + (1.0 - c) * warp::pdf(&plain, w);
            assert!((got - want).abs() <= 1e-3 * want, "{w:?}: {got} vs {want}");
        }
    }
    gather_pdf8_is_gather_pdf(&ctx, &t);
    let unguided = IterationCtx::new(&world, &settings, 0, None);
    gather_pdf8_is_gather_pdf(&unguided, &t);
}

/// The 8-wide density equals the scalar one bit for bit in the lanes asked for, below the
/// horizon too, and is 0 in the others.
fn gather_pdf8_is_gather_pdf(ctx: &IterationCtx<'_>, t: &GatherTexel) {
    let mut rng = guidebake_kernels::testing::Pcg32::new(3, 8);
    for round in 0..300 {
        let dirs: [Vec3; LANES] = core::array::from_fn(|_| {
            let d = Vec3::new(
                rng.next_f32() * 2.0 - 1.0,
                rng.next_f32() * 2.0 - 1.0,
                rng.next_f32() * 2.0 - 1.0,
            );
            d.normalize_or(Vec3::Z)
        });
        let live = if round == 0 {
            0xff
        } else {
            rng.next_u32() as u8
        };
        let got = ctx.gather_pdf8(t, &dirs, live);
        for lane in 0..LANES {
            let want = if live >> lane & 1 == 1 {
                ctx.gather_pdf(t, dirs[lane])
            } else {
                0.0
            };
            assert_eq!(
                got[lane].to_bits(),
                want.to_bits(),
                "lane {lane} of {dirs:?}"
            );
        }
    }
}
