//! Group `bake_tile`: one tile's full guided bake — clustering, K learning iterations per
//! cluster, the combination of iterations (paper §2.1–2.5) — per method, on the demo's room
//! lit through a door ajar: the micro view beside the whole-scene harness (`guidebake bench`).
//! ρ is applied when pages are written, not per tile, so methods differ here by `--guiding`
//! and `--combine`; every variant of both is timed, so modes added to the bake join.
//!
//! The tile is the one of the most valid texels; it is baked once per method and checked
//! (every valid texel baked, finite, non-negative) before timing. Throughput: gather samples
//! (valid texels × spp).
//!
//! Group `bake_tile_directional`: the same tile at the default settings, without and with
//! `--directional sh-l1` (docs/lightmaps.md, "Directional lightmaps"): what keeping the L1
//! coefficients costs the gather.
//!
//! `cargo bench --bench bake -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use guidebake::bake::directional::Directional;
use guidebake::bake::gather::TileBaker;
use guidebake::bake::pipeline::TileBuffer;
use guidebake::bake::settings::BakeSettings;
use guidebake::bench::method::{Method, value_name};
use guidebake::bvh::Preset;
use guidebake::demo::{DEMO_TEXELS_PER_METRE, ajar_room};
use guidebake::output::result_file::FLAG_BAKED;
use guidebake::prepare::{Layout, PrepareOptions, Resolution, prepare};
use guidebake::texels::{FLAG_VALID, TexelFile};
use guidebake::transport::world::World;

const SPP: u32 = 64;

fn bake_tile(c: &mut Criterion) {
    let scene = ajar_room();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("ajar.texels");
    prepare(
        &scene,
        &path,
        PrepareOptions {
            resolution: Resolution::TexelsPerUnit(DEMO_TEXELS_PER_METRE),
            layout: Layout::Shared,
        },
    )
    .expect("the demo room prepares");
    let texels = TexelFile::open(&path).expect("the texel file opens");
    let world = World::new(&scene, Preset::DEFAULT).expect("the BVH builds");
    let valid = |t: usize| {
        texels
            .tile_texels(t)
            .iter()
            .filter(|x| x.flags & FLAG_VALID != 0)
            .count()
    };
    let tile = (0..texels.tiles().len())
        .max_by_key(|&t| valid(t))
        .expect("the demo room has tiles");
    let records = texels.tile_texels(tile);
    let first = texels.tiles()[tile].first_texel;
    let mut group = c.benchmark_group("bake_tile");
    group.sample_size(10);
    group.throughput(Throughput::Elements(valid(tile) as u64 * u64::from(SPP)));
    // Every (guiding, combine) of the bake, once (ρ does not act per tile).
    let mut pairs: Vec<_> = Method::all()
        .into_iter()
        .map(|m| (m.guiding, m.combine))
        .collect();
    pairs.dedup();
    for (guiding, combine) in pairs {
        let settings = BakeSettings {
            spp: SPP,
            guiding,
            combine,
            ..Default::default()
        };
        let mut baker = TileBaker::new(&world, settings);
        let mut out = TileBuffer::default();
        baker.bake_tile(tile as u32, first, records, &mut out);
        for (r, t) in out.results.iter().zip(records) {
            if t.flags & FLAG_VALID != 0 {
                assert!(r.flags & FLAG_BAKED != 0, "a valid texel is baked");
                assert!(
                    r.irradiance.iter().all(|v| v.is_finite() && *v >= 0.0),
                    "finite, non-negative irradiance: {r:?}"
                );
            }
        }
        let id = format!("{}/{}", value_name(&guiding), value_name(&combine));
        group.bench_function(BenchmarkId::from_parameter(id), |b| {
            b.iter(|| {
                baker.bake_tile(tile as u32, first, black_box(records), &mut out);
                black_box(&out);
            });
        });
    }
    group.finish();
    let mut group = c.benchmark_group("bake_tile_directional");
    group.sample_size(10);
    group.throughput(Throughput::Elements(valid(tile) as u64 * u64::from(SPP)));
    for directional in [Directional::None, Directional::ShL1] {
        let settings = BakeSettings {
            spp: SPP,
            directional,
            ..Default::default()
        };
        let mut baker = TileBaker::new(&world, settings).keep_directional(true);
        let mut out = TileBuffer::default();
        baker.bake_tile(tile as u32, first, records, &mut out);
        assert!(
            out.directional
                .iter()
                .all(|s| s.coefficients.iter().all(|c| c.is_finite()))
        );
        let id = BenchmarkId::from_parameter(directional);
        group.bench_function(id, |b| {
            b.iter(|| {
                baker.bake_tile(tile as u32, first, black_box(records), &mut out);
                black_box(&out);
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bake_tile);
criterion_main!(benches);
