//! `fresco dense <ws>`: depth maps and their fusion into `<ws>/dense/fused.ply`, from the
//! workspace's sparse model (`<ws>/sparse/0`) and photos (`<ws>/images.json`); or, for COLMAP
//! users, `fresco dense --colmap <model dir> --images <dir> -o <ws>`. See
//! `fresco_surface::dense::densify`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_core::colmap;
use fresco_surface::dense::{DenseConfig, DenseInputs, ImageSource, densify, with_reference_poses};

#[derive(Args, Debug)]
pub struct DenseArgs {
    /// Workspace folder: reads sparse/0 and images.json, writes dense/. With --colmap, the
    /// output workspace is -o instead.
    pub workspace: Option<PathBuf>,
    /// A COLMAP model folder (text or binary) to densify instead of a workspace's.
    #[arg(long, requires = "images", requires = "output")]
    pub colmap: Option<PathBuf>,
    /// Folder of the photos the COLMAP model names (with --colmap).
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Output workspace (with --colmap): writes <output>/dense.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Folder of object masks (<image name>.png or <stem>.png; 0 = background).
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Replace the model's cameras and poses by these ground-truth ones (a Middlebury
    /// *_par.txt file or a COLMAP model), moving the sparse points with the similarity that
    /// aligns the camera centres.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Longest side of the undistorted images in pixels (0: full size).
    #[arg(long, default_value_t = DenseConfig::default().max_image_size)]
    pub max_image_size: u32,
    /// Most source views per image.
    #[arg(long, default_value_t = DenseConfig::default().view_selection.max_sources)]
    pub max_sources: usize,
    /// PatchMatch iterations.
    #[arg(long, default_value_t = DenseConfig::default().patch_match.iterations)]
    pub iterations: usize,
    /// PatchMatch sweeps at full resolution in the first pass (1: about a quarter less time,
    /// slightly less complete).
    #[arg(long, default_value_t = DenseConfig::default().patch_match.finest_iterations)]
    pub finest_iterations: usize,
    /// Fewest agreeing views for a fused point.
    #[arg(long, default_value_t = DenseConfig::default().fusion.min_views)]
    pub min_views: usize,
    /// Leave these images out (repeat the option for several).
    #[arg(long)]
    pub exclude: Vec<String>,
    /// Seed of the random draws.
    #[arg(long, default_value_t = DenseConfig::default().seed)]
    pub seed: u64,
    /// Do not write the false-colour PNG of each depth map.
    #[arg(long)]
    pub no_depth_pngs: bool,
    /// The draft preset (DenseConfig::draft: images at most 320 px, fewer sweeps): a first
    /// look in seconds.
    #[arg(long, conflicts_with_all = ["max_image_size", "iterations", "finest_iterations"])]
    pub draft: bool,
    /// Skip the second PatchMatch pass (geometric consistency): faster, less complete.
    #[arg(long)]
    pub no_geometric: bool,
    /// Keep the plane the object stands on: by default, for object-centric captures
    /// (cameras looking inward at one point from above), the dominant plane under the object
    /// and everything below it are removed from the fused cloud, when the plane is seen
    /// around the object (a table or a platform, not the object's own plinth).
    #[arg(long)]
    pub keep_support_plane: bool,
}

pub fn run(args: DenseArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let (model_dir, images, out) = match (&args.colmap, &args.workspace) {
        (Some(model), None) => {
            let images = args.images.clone().context("--colmap needs --images")?;
            let out = args.output.clone().context("--colmap needs -o")?;
            (
                model.clone(),
                ImageSource::Folder(images),
                out.join("dense"),
            )
        }
        (None, Some(ws)) => {
            if !ws.is_dir() {
                bail!("workspace {} is not a folder", ws.display());
            }
            let list = fresco_sfm::workspace::read_images(ws)?;
            let files: BTreeMap<String, PathBuf> =
                list.images.into_iter().map(|e| (e.name, e.path)).collect();
            (
                ws.join("sparse").join("0"),
                ImageSource::Files(files),
                ws.join("dense"),
            )
        }
        (Some(_), Some(_)) => bail!("give either a workspace or --colmap, not both"),
        (None, None) => bail!("give a workspace, or --colmap <model> --images <dir> -o <ws>"),
    };
    let mut rec = colmap::read_model(&model_dir)
        .with_context(|| format!("reading the sparse model {}", model_dir.display()))?;
    if let Some(poses) = &args.poses {
        let reference = if poses.is_file() {
            let (w, h) = rec
                .cameras
                .values()
                .next()
                .map(|c| (c.width, c.height))
                .context("the model has no cameras")?;
            let views = fresco_core::middlebury::read_par(poses, w, h)?;
            fresco_core::middlebury::views_to_reconstruction(&views)
        } else {
            colmap::read_model(poses)?
        };
        rec = with_reference_poses(&rec, &reference)
            .with_context(|| format!("adopting the poses of {}", poses.display()))?;
    }
    let mut config = DenseConfig {
        exclude_images: args.exclude.clone(),
        seed: args.seed,
        depth_pngs: !args.no_depth_pngs,
        geometric: !args.no_geometric,
        ..if args.draft {
            DenseConfig::draft()
        } else {
            DenseConfig::default()
        }
    };
    if !args.draft {
        config.max_image_size = args.max_image_size;
        config.patch_match.iterations = args.iterations;
        config.patch_match.finest_iterations = args.finest_iterations;
    }
    config.view_selection.max_sources = args.max_sources;
    config.fusion.min_views = args.min_views;
    config.fusion.support_plane.remove = !args.keep_support_plane;
    let inputs = DenseInputs {
        reconstruction: &rec,
        images: &images,
        masks: args.masks.as_deref(),
    };
    let bars = crate::progress::Bars::new(ctx);
    let summary = densify(&inputs, &config, &out, &bars)
        .with_context(|| format!("dense stage into {}", out.display()))?;
    Ok(serde_json::to_value(summary)?)
}
