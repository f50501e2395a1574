//! The `guidebake` command line. See README.md for the two commands a new user runs first.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use guidebake::cmd;

/// guidebake: a CPU lightmap baker with ray guiding (Silvennoinen & Sloan 2019).
#[derive(Debug, Parser)]
#[command(name = "guidebake", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Render the presorted Sobol packets (paper Figure 3) to a PNG.
    Samples(cmd::samples::SamplesArgs),
    /// Rasterize a scene's lightmap UVs into a memory-mapped texel file.
    Prepare(cmd::prepare::PrepareArgs),
    /// Write a procedural world of N texels and its scene, streaming.
    Synth(cmd::synth::SynthArgs),
    /// The bundled default: bake a generated room lit through a door ajar, unguided and guided.
    Demo(cmd::demo::DemoArgs),
    /// Bake a lightmap from a texel file with ray guiding.
    Bake(cmd::bake::BakeArgs),
    /// Combine the shards of a `bake --shard I/N` into the final lightmap.
    Merge(cmd::merge::MergeArgs),
    /// Run time against error of every method, and the guiding overhead (paper Figure 5).
    Bench(cmd::bench::BenchArgs),
    /// Render a picture of the lit scene from its glTF camera or an automatic view.
    Render(cmd::render::RenderArgs),
    /// Place light probes over a baked level and bake them with the guided gather.
    Probes(cmd::probes::ProbesArgs),
    /// Print a texel file's header and counts; dump chosen texels as JSON.
    Inspect(cmd::inspect::InspectArgs),
    /// Show the baked level in a browser (three.js): write the viewer's folder and serve it.
    View(cmd::view::ViewArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    cmd::interrupt::install();
    let result = match &cli.command {
        Command::Samples(a) => cmd::samples::run(a),
        Command::Prepare(a) => cmd::prepare::run(a),
        Command::Synth(a) => cmd::synth::run(a),
        Command::Inspect(a) => cmd::inspect::run(a),
        Command::Demo(a) => cmd::demo::run(a),
        Command::Bake(a) => cmd::bake::run(a),
        Command::Merge(a) => cmd::merge::run(a),
        Command::Bench(a) => cmd::bench::run_bench(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Probes(a) => cmd::probes::run(a),
        Command::View(a) => cmd::view::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let lines = cmd::error_lines(e.as_ref());
            eprintln!("guidebake: {}", lines[0]);
            for cause in &lines[1..] {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::from(cmd::exit_code(&e))
        }
    }
}
