//! `guidebake demo [-o DIR]`: the bundled default. Builds the generated room lit through a
//! door ajar ([`crate::demo`]), prepares its texels, and bakes it twice at equal sample
//! counts — unguided baseline and coherent guiding — writing both lightmaps (EXR) and their
//! previews (PNG), each bake's stats JSON, and the room seen through [`demo_camera`] lit by
//! each lightmap ([`crate::render`]): `baseline.view.png`, `guided.view.png` and the two side
//! by side at one exposure, `views.png`; and the room as `ajar.glb` (its lightmap UVs and
//! that camera), for `guidebake view` and engines.

use std::path::PathBuf;

use crate::bake::finish::FinishOptions;
use crate::bake::run::BakeJob;
use crate::bake::settings::{BakeSettings, Budget, Guiding};
use crate::bake::shard::Shard;
use crate::demo::{DEMO_TEXELS_PER_METRE, ajar_room, demo_camera};
use crate::prepare::{Layout, PrepareOptions, Resolution, prepare};
use crate::render::{Lightmap, Stage, View, ViewOptions, render, side_by_side};
use crate::texels::TexelFile;

/// Size of each rendered view of the demo.
const VIEW: ViewOptions = ViewOptions {
    width: 640,
    height: 400,
    cutaway: false,
};

/// Arguments of `guidebake demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Directory for the texel file, lightmaps, previews and stats.
    #[arg(short, long = "output", alias = "out", default_value = "out/demo")]
    pub out: PathBuf,
    /// Final-gather rays per texel for both bakes.
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Worker threads (default: every core).
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
}

/// Runs `guidebake demo`.
///
/// # Errors
/// When the output directory cannot be created or a step fails; names the file.
pub fn run(args: &DemoArgs) -> Result<(), super::CmdError> {
    std::fs::create_dir_all(&args.out)
        .map_err(|e| format!("{}: cannot create: {e}", args.out.display()))?;
    let scene = ajar_room();
    let texels = args.out.join("ajar.texels");
    let options = PrepareOptions {
        resolution: Resolution::TexelsPerUnit(DEMO_TEXELS_PER_METRE),
        layout: Layout::Shared,
    };
    let prepared = prepare(&scene, &texels, options)?;
    crate::output::seams::prepare_seams(&scene, &texels)?;
    eprintln!(
        "prepared {} texels in {} tiles: {}",
        prepared.texels,
        prepared.tiles,
        texels.display()
    );
    let glb = args.out.join("ajar.glb");
    write_room_glb(&scene, &texels, &glb)?;
    let threads = args.threads.unwrap_or_else(super::every_core);
    for (name, guiding) in [("baseline", Guiding::Off), ("guided", Guiding::Coherent)] {
        let out = args.out.join(format!("{name}.exr"));
        // A demo is always baked afresh: an earlier, interrupted demo's work is not resumed.
        let _ = std::fs::remove_dir_all(crate::bake::workdir::work_dir(&out, Shard::WHOLE));
        let job = BakeJob {
            texels: texels.clone(),
            out: out.clone(),
            settings: BakeSettings {
                spp: args.spp,
                guiding,
                // As `bake --guiding off` would: the baseline spends --spp at every texel.
                budget: Budget::default_for(guiding, None),
                ..Default::default()
            },
            threads,
            shard: Shard::WHOLE,
            resume: false,
            aux: true,
            finish: FinishOptions::default(),
        };
        let feedback = super::bake::Feedback::for_stderr();
        let report = super::bake::run_with_progress(&job, None, &scene, feedback)?;
        if report.interrupted {
            return Err(Box::new(super::Interrupted(
                "interrupted: run guidebake demo again to start over".into(),
            )));
        }
        super::bake::write_stats(&args.out.join(format!("{name}.json")), &report)?;
        eprintln!(
            "{name:>8}: {:.2} s gather, {:.1} Mrays/s, ρ = {:.4}, {} guided cluster-iterations: {} (+ .atlas.png)",
            report.seconds.gather,
            report.rays_per_second / 1e6,
            report.rho,
            report.counters.iterations_guided,
            out.display()
        );
    }
    write_views(&args.out, &scene, &texels)
}

/// The room as a glb for engines and `guidebake view`/`render`: its lightmap UVs as
/// `TEXCOORD_1` and [`demo_camera`] as its camera (at the views' aspect), so `render
/// ajar.glb` and `view --scene ajar.glb` start from the demo's view.
fn write_room_glb(
    scene: &crate::scene::Scene,
    texels: &std::path::Path,
    glb: &std::path::Path,
) -> Result<(), super::CmdError> {
    use crate::render::Projection;
    use crate::scene::gltf_write::{GlbCamera, write_new_with_camera};
    let layout = crate::prepare::Lightmap::of_texel_file(&TexelFile::open(texels)?, scene);
    let aspect = VIEW.width as f32 / VIEW.height as f32;
    let camera = demo_camera(aspect);
    let Projection::Perspective { tan_half_fov } = camera.projection else {
        unreachable!("the demo's camera is a perspective one")
    };
    let camera = GlbCamera {
        eye: camera.eye,
        forward: camera.forward,
        up: camera.up,
        yfov: 2.0 * tan_half_fov.atan(),
        aspect,
    };
    write_new_with_camera(scene, &layout, Some(camera), glb)?;
    Ok(())
}

/// Renders the room lit by each lightmap; writes each view and both side by side, at the
/// guided view's automatic exposure.
fn write_views(
    dir: &std::path::Path,
    scene: &crate::scene::Scene,
    texels: &std::path::Path,
) -> Result<(), super::CmdError> {
    let texels = TexelFile::open(texels)?;
    let stage = Stage::new(scene, &texels)?;
    let camera = demo_camera(VIEW.width as f32 / VIEW.height as f32);
    let mut views: Vec<View> = Vec::new();
    for name in ["baseline", "guided"] {
        let lightmap = Lightmap::load(&texels, scene, &dir.join(format!("{name}.exr")))?;
        views.push(render(&stage, &lightmap, &camera, VIEW));
    }
    let exposure = views[1].auto_exposure();
    for (name, view) in ["baseline", "guided"].iter().zip(&views) {
        let path = dir.join(format!("{name}.view.png"));
        crate::preview::write_png_rgb8(&path, view.width, view.height, &view.to_rgb8(exposure))?;
    }
    let (w, h, rows) = side_by_side(&[&views[0], &views[1]], exposure, 8);
    let path = dir.join("views.png");
    crate::preview::write_png_rgb8(&path, w, h, &rows)?;
    eprintln!("  views: {} (baseline | guided)", path.display());
    Ok(())
}
