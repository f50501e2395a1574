//! Criterion bench of the albedo a gather hit reads (`scene::texture::HitAlbedo::at`, which
//! `World::albedo_at` calls for triangles whose albedo varies): a constant albedo (every
//! untextured hit), and a base-colour texture sampled bilinearly from 8-bit sRGB through the
//! decoding table — a 64² texture (in cache) and a 1024² one (3 MiB, the default cap) at
//! random UVs over 16 repeats (cache misses as scattered gather hits make them) — with and
//! without vertex colours. docs/lightmaps.md, "Textured albedo at hits".
//!
//! Run: `cargo bench --bench albedo -- --warm-up-time 1 --measurement-time 2`

use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Vec2, Vec3};
use guidebake::scene::texture::{HitAlbedo, Image, TextureOptions, Wrap};
use guidebake::scene::{BaseColorTexture, Material, Triangle};
use guidebake_kernels::testing::Pcg32;

/// Hits per iteration.
const HITS: usize = 4096;

fn noise_image(side: u32, rng: &mut Pcg32) -> Image {
    let bytes: Vec<u8> = (0..side * side * 3).map(|_| rng.next_u32() as u8).collect();
    Image::from_srgb8(
        "noise".into(),
        side,
        side,
        3,
        &bytes,
        TextureOptions::default(),
    )
    .unwrap()
}

fn albedo(image: Option<Image>, colours: bool) -> HitAlbedo {
    let material = Material {
        name: "m".into(),
        albedo: Vec3::splat(0.5),
        emission: Vec3::ZERO,
        base_color_texture: image.map(|image| BaseColorTexture {
            image: Arc::new(image),
            wrap: [Wrap::Repeat; 2],
            factor: Vec3::splat(0.9),
        }),
    };
    let triangle = Triangle {
        positions: [Vec3::ZERO, Vec3::X, Vec3::Y],
        normals: [Vec3::Z; 3],
        lightmap_uv: None,
        // 16 repeats of the texture across the triangle.
        texture_uv: Some([Vec2::ZERO, Vec2::X * 16.0, Vec2::Y * 16.0]),
        colour: colours.then_some([Vec3::ONE, Vec3::splat(0.5), Vec3::new(1.0, 0.8, 0.6)]),
        mesh: 0,
        material: 0,
    };
    HitAlbedo::of(&triangle, &material)
}

fn bench(c: &mut Criterion) {
    let mut rng = Pcg32::new(7, 0);
    let hits: Vec<(f32, f32)> = (0..HITS)
        .map(|_| {
            let (u, v) = (rng.next_f32(), rng.next_f32());
            if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            }
        })
        .collect();
    let cases = [
        ("constant", albedo(None, false)),
        ("texture_64", albedo(Some(noise_image(64, &mut rng)), false)),
        (
            "texture_1024",
            albedo(Some(noise_image(1024, &mut rng)), false),
        ),
        (
            "texture_1024_colours",
            albedo(Some(noise_image(1024, &mut rng)), true),
        ),
    ];
    assert!(matches!(cases[0].1, HitAlbedo::Constant(_)));
    let mut group = c.benchmark_group("albedo_at");
    group.throughput(Throughput::Elements(HITS as u64));
    for (name, a) in &cases {
        group.bench_function(*name, |b| {
            b.iter(|| {
                let mut sum = Vec3::ZERO;
                for &(u, v) in &hits {
                    sum += black_box(a).at(u, v);
                }
                sum
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
