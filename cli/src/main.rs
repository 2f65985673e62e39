//! The `fresco` command line: argument parsing, progress bars, summaries and exit codes.
//! No algorithms live here; each subcommand is a module that calls one library function.
//!
//! Every subcommand returns a JSON summary; `--json` prints it on stdout, otherwise a short
//! human-readable form is printed. Logs go to stderr (`-v`, `RUST_LOG`).

mod dense;
mod eval;
mod features;
mod geotex;
mod matching;
mod mesh;
mod progress;
mod pst;
mod reconstruct;
mod report;
mod run;
mod sfm;
mod sprites;
mod synth;
mod texture;
mod unwrap;
mod view;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "fresco",
    version,
    about = "Photos to textured 3D models, and the texture tools around them"
)]
struct Cli {
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    threads: Option<usize>,
    /// No progress bars, only errors.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Print a machine-readable JSON summary on stdout.
    #[arg(long, global = true)]
    json: bool,
    /// More log output on stderr (-v info, -vv debug).
    #[arg(long, short, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

/// The verbs, in pipeline order (`fresco --help` lists them so; cli/tests/error_messages.rs
/// holds the same order): the photo pipeline's stages, then the tools around them.
#[derive(Subcommand, Debug)]
enum Command {
    /// Photos to a textured model.glb in one go, resumable, with report.html and summary.json.
    Run(run::RunArgs),
    /// SIFT features of a folder of photos into a workspace (feature files, images.json).
    Features(features::FeaturesArgs),
    /// Match the features of a workspace's images and verify the pairs' two-view geometry.
    Match(matching::MatchArgs),
    /// Cameras and a sparse point cloud from a workspace's features and matches.
    Sfm(sfm::SfmArgs),
    /// Photos to cameras and sparse points in one go: features, match, sfm.
    Reconstruct(reconstruct::ReconstructArgs),
    /// Depth maps of every registered photo and their fusion into <ws>/dense/fused.ply
    /// (PatchMatch multi-view stereo on the CPU).
    Dense(dense::DenseArgs),
    /// Oriented points (<ws>/dense/fused.ply or --points) to <ws>/mesh.ply: screened Poisson,
    /// density trimming, clean-up and decimation.
    Mesh(mesh::MeshArgs),
    /// Charts, flattens and packs a mesh's texture coordinates (with a PNG of the atlas).
    Unwrap(unwrap::UnwrapArgs),
    /// The texture atlas of a mesh from its photos: graph-cut view fusion, leveling, hole
    /// filling; <ws>/texture/ and <ws>/model.glb.
    Texture(texture::TextureArgs),
    /// Measure results against ground truth or a reference (poses).
    Eval(eval::EvalArgs),
    /// Serve a workspace's report and model viewer (or a .glb) on 127.0.0.1.
    View(view::ViewArgs),
    /// Point-sampled textures for meshes too large for memory.
    Pst(pst::PstArgs),
    /// Texture sprites: render or bake a sprite scene, build octree textures.
    Sprites(sprites::SpritesArgs),
    /// Resize models with geometric texture (threads, bumps, scales) keeping the texture at
    /// its size (paper 002); synthetic models with ground truth.
    Geotex(geotex::GeotexArgs),
    /// Write a synthetic dataset: photos of a procedurally textured shape from known cameras,
    /// with masks, ground-truth cameras (COLMAP, Middlebury) and mesh (PLY, GLB).
    Synth(synth::SynthArgs),
}

/// Everything a subcommand needs from the global flags.
pub struct Context {
    pub quiet: bool,
    pub json: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose, cli.quiet);
    if let Some(n) = cli.threads
        && let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
    {
        eprintln!("error: cannot start {n} threads: {e}");
        return ExitCode::from(2);
    }
    let ctx = Context {
        quiet: cli.quiet,
        json: cli.json,
    };
    let result: anyhow::Result<serde_json::Value> = match cli.command {
        Command::Run(args) => run::run(args, &ctx),
        Command::Features(args) => features::run(args, &ctx),
        Command::Match(args) => matching::run(args, &ctx),
        Command::Sfm(args) => sfm::run(args, &ctx),
        Command::Reconstruct(args) => reconstruct::run(args, &ctx),
        Command::Dense(args) => dense::run(args, &ctx),
        Command::Mesh(args) => mesh::run(args, &ctx),
        Command::Unwrap(args) => unwrap::run(args, &ctx),
        Command::Texture(args) => texture::run(args, &ctx),
        Command::Eval(args) => eval::run(args, &ctx),
        Command::View(args) => view::run(args, &ctx),
        Command::Pst(args) => pst::run(args, &ctx),
        Command::Sprites(args) => sprites::run(args, &ctx),
        Command::Geotex(args) => geotex::run(args, &ctx),
        Command::Synth(args) => synth::run(args, &ctx),
    };
    match result {
        Ok(summary) => {
            print_summary(&ctx, &summary);
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn init_logging(verbose: u8, quiet: bool) {
    let default = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "info",
        (false, _) => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
}

/// `--json`: the summary as one JSON document on stdout; otherwise `key: value` lines.
fn print_summary(ctx: &Context, summary: &serde_json::Value) {
    if ctx.json {
        println!(
            "{}",
            serde_json::to_string_pretty(summary).unwrap_or_default()
        );
    } else if !ctx.quiet {
        print_human(summary, 0);
    }
}

fn print_human(value: &serde_json::Value, indent: usize) {
    if let serde_json::Value::Object(map) = value {
        for (k, v) in map {
            match v {
                serde_json::Value::Object(_) => {
                    println!("{:indent$}{k}:", "");
                    print_human(v, indent + 2);
                }
                _ => println!("{:indent$}{k}: {v}", ""),
            }
        }
    }
}
