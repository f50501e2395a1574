//! Whole bakes of the real scenes in `../shared/scenes` (skipped, with a message, when the
//! folder is absent): every bake completes with finite output; guided and unguided agree
//! statistically; `series` agrees with `path` at equal bounces up to the lightmap's
//! resolution error, which is measured and printed.
//!
//! How agreement is measured: both bakes estimate the same lightmap, so the per-texel
//! differences d_i = a_i − b_i cancel the true values; their mean over the valid texels is
//! compared with its standard error, std(d)/√n (texels are independent estimates: every random
//! number derives from the texel id). For series against path the mean relative difference
//! is reported: it is the resolution error of the previous pass's lightmap lookups (plus
//! noise), not zero in expectation, and must stay within 10% of the mean plus three standard
//! errors.
//!
//! The scenes are prepared at 64×64 texels (a few thousand valid texels) so the test fits in
//! CI's time; `cargo test --release --test scenes_bake -- --nocapture` prints the figures.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use guidebake::bake::finish::FinishOptions;
use guidebake::bake::run::{BakeJob, bake};
use guidebake::bake::settings::{BakeSettings, Guiding, Transport};
use guidebake::bake::shard::Shard;
use guidebake::output::readback::read_channel;
use guidebake::prepare::{Layout, PrepareOptions, Resolution, prepare};
use guidebake::scene::Scene;
use guidebake::test_support::shared_scenes_dir;

const SCENES: [&str; 3] = [
    "bitterli_cornell_box.glb",
    "bitterli_veach_bidir.glb",
    "bitterli_veach_ajar_no_teapots.glb",
];

/// Irradiance luminance of every valid texel, in pixel order, and the validity mask.
fn valid_luminance(path: &Path) -> Vec<Option<f64>> {
    let channel = |name: &str| -> Vec<f64> {
        read_channel(path, name)
            .unwrap()
            .into_iter()
            .map(f64::from)
            .collect()
    };

    let (r, g, b, valid) = (
        channel("R"),
        channel("G"),
        channel("B"),
        channel("validity"),
    );
    (0..r.len())
        .map(|i| {
            (valid[i] > 0.0).then(|| guidebake_kernels::estimator::luminance([r[i], g[i], b[i]]))
        })
        .collect()
}

struct Baked {
    luminance: Vec<Option<f64>>,
}

fn bake_scene(scene: &Scene, texels: &Path, out: PathBuf, settings: BakeSettings) -> Baked {
    let job = BakeJob {
        texels: texels.to_owned(),
        out: out.clone(),
        settings,
        threads: 2,
        shard: Shard::WHOLE,
        resume: false,
        aux: true,
        finish: FinishOptions::default(),
    };
    let report = bake(&job, scene, &AtomicBool::new(false), &mut |_, _| {})
        .unwrap_or_else(|e| panic!("{}: {e}", scene.path.display()));
    assert_eq!(report.non_finite_pixels, 0, "{}", scene.path.display());
    let luminance = valid_luminance(&out);
    assert!(
        luminance
            .iter()
            .flatten()
            .all(|v| v.is_finite() && *v >= 0.0),
        "{}: finite, non-negative irradiance",
        out.display()
    );
    Baked { luminance }
}

/// Mean of the per-texel differences, its standard error, and the mean of `b`.
fn paired(a: &Baked, b: &Baked) -> (f64, f64, f64) {
    let pairs: Vec<(f64, f64)> = a
        .luminance
        .iter()
        .zip(&b.luminance)
        .filter_map(|(x, y)| Some(((*x)?, (*y)?)))
        .collect();
    let n = pairs.len() as f64;
    assert!(n > 100.0, "{n} texels");
    let d: Vec<f64> = pairs.iter().map(|(x, y)| x - y).collect();
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let base = pairs.iter().map(|p| p.1).sum::<f64>() / n;
    (mean, (var / n).sqrt(), base)
}

#[test]
fn real_scenes_bake_finite_guided_agrees_with_unguided_and_series_with_path() {
    let Some(dir) = shared_scenes_dir() else {
        eprintln!("skipping: ../shared/scenes is absent (set GUIDEBAKE_SCENES to run)");
        return;
    };
    let work = tempfile::tempdir().unwrap();
    for name in SCENES {
        let scene = Scene::load(&dir.join("converted").join(name)).unwrap();
        let texels = work.path().join(format!("{name}.texels"));
        prepare(
            &scene,
            &texels,
            PrepareOptions {
                resolution: Resolution::Size(64, 64),
                layout: Layout::Auto,
            },
        )
        .unwrap();
        let settings = |guiding, transport| BakeSettings {
            spp: 64,
            iterations: 2,
            guiding,
            transport,
            bounces: 2,
            ..Default::default()
        };
        let out = |what: &str| work.path().join(format!("{name}.{what}.exr"));
        let unguided = bake_scene(
            &scene,
            &texels,
            out("off"),
            settings(Guiding::Off, Transport::Series),
        );
        let guided = bake_scene(
            &scene,
            &texels,
            out("coherent"),
            settings(Guiding::Coherent, Transport::Series),
        );
        let path = bake_scene(
            &scene,
            &texels,
            out("path"),
            settings(Guiding::Off, Transport::Path),
        );
        let (d, se, base) = paired(&guided, &unguided);
        eprintln!(
            "{name}: guided − unguided = {d:.4} ± {se:.4} (mean {base:.4}, {:.2}%)",
            100.0 * d / base
        );
        assert!(
            d.abs() < 4.0 * se + 1e-6 * base,
            "{name}: guided and unguided differ by {d} ± {se}"
        );
        let (d, se, base) = paired(&unguided, &path);
        let relative = d / base;
        eprintln!(
            "{name}: series − path = {d:.4} ± {se:.4} (mean {base:.4}): {:.2}% resolution error",
            100.0 * relative
        );
        assert!(
            d.abs() < 3.0 * se + 0.1 * base,
            "{name}: series and path differ by {:.1}% ± {:.1}% at 64×64 texels",
            100.0 * relative,
            100.0 * se / base
        );
    }
}
