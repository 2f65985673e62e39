//! `fresco eval poses <model> --gt <par.txt | model>`: pose accuracy of a model (a COLMAP
//! folder or a workspace) against a reference after a similarity alignment, with the figures
//! of `fresco_sfm::evaluate` (DESIGN.md, "How quality is measured").
//!
//! `fresco eval texture <model.glb> --colmap <model> --images <dir> --views a.png,b.png`:
//! renders the textured (or vertex-coloured) model into the named photos with their cameras
//! and compares (`fresco_atlas::compare_to_photo`): PSNR, SSIM and 1 - NCC inside the photo's
//! mask (`--masks`) and the model's silhouette, raw and after a per-channel gain.

use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, Subcommand};
use fresco_sfm::evaluate::evaluate_poses;
use fresco_sfm::mapping::reconstruct::{read_model_or_workspace, read_reference};

#[derive(Args, Debug)]
pub struct EvalArgs {
    #[command(subcommand)]
    pub what: EvalWhat,
}

#[derive(Subcommand, Debug)]
pub enum EvalWhat {
    /// Camera poses against ground truth (Middlebury *_par.txt) or another COLMAP model.
    Poses(PosesArgs),
    /// A textured model re-rendered into photos (held out from its texture).
    Texture(TextureEvalArgs),
}

#[derive(Args, Debug)]
pub struct TextureEvalArgs {
    /// The textured model (.glb, as `fresco texture` writes it).
    pub model: PathBuf,
    /// COLMAP model folder (or a workspace) with the photos' cameras.
    #[arg(long)]
    pub colmap: PathBuf,
    /// Folder of the photos.
    #[arg(long)]
    pub images: PathBuf,
    /// Photos to compare with (comma-separated image names of the COLMAP model).
    #[arg(long, value_delimiter = ',', required = true)]
    pub views: Vec<String>,
    /// Folder of masks (<image name>.png, non-zero on the object).
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Samples per pixel side of the rendering (anti-aliasing).
    #[arg(long, default_value_t = 2)]
    pub supersample: u32,
    /// Write each rendering as <dir>/<view>.png.
    #[arg(long)]
    pub save_renders: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct PosesArgs {
    /// COLMAP model folder, or a workspace (its sparse/0).
    pub model: PathBuf,
    /// Reference: a Middlebury *_par.txt file, a COLMAP model folder or a workspace.
    #[arg(long)]
    pub gt: PathBuf,
    /// Also list the errors of every image.
    #[arg(long)]
    pub per_image: bool,
}

pub fn run(args: EvalArgs, _ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    match args.what {
        EvalWhat::Poses(a) => poses(a),
        EvalWhat::Texture(a) => texture(a),
    }
}

fn poses(args: PosesArgs) -> anyhow::Result<serde_json::Value> {
    let model = read_model_or_workspace(&args.model).context("reading the model")?;
    let reference = read_reference(&args.gt, &model).context("reading the reference")?;
    let e = evaluate_poses(&model, &reference).with_context(|| {
        format!(
            "comparing {} with {}",
            args.model.display(),
            args.gt.display()
        )
    })?;
    let mut v = serde_json::to_value(&e)?;
    if !args.per_image
        && let Some(map) = v.as_object_mut()
    {
        map.remove("rotation_deg");
        map.remove("centre_frac");
    }
    Ok(v)
}

fn texture(args: TextureEvalArgs) -> anyhow::Result<serde_json::Value> {
    let (mesh, textures) = fresco_core::gltf::read_glb(&args.model)?;
    let model = fresco_atlas::TexturedModel { mesh, textures };
    let rec = read_model_or_workspace(&args.colmap)
        .with_context(|| format!("reading the cameras {}", args.colmap.display()))?;
    let mut per_view = serde_json::Map::new();
    let (mut psnr, mut psnr_gain, mut ssim) = (0.0, 0.0, 0.0);
    for name in &args.views {
        let image = rec
            .image_by_name(name)
            .with_context(|| format!("{}: no image {name} in the model", args.colmap.display()))?;
        let camera = &rec.cameras[&image.camera_id];
        let path = args.images.join(name);
        let photo = fresco_core::photo::load_photo(&path)?.rgb;
        if (photo.width(), photo.height()) != (camera.width, camera.height) {
            anyhow::bail!(
                "{}: the photo is {}x{} but its camera is {}x{}",
                path.display(),
                photo.width(),
                photo.height(),
                camera.width,
                camera.height
            );
        }
        let mask = match &args.masks {
            Some(dir) => {
                let p = dir.join(format!("{name}.png"));
                Some(
                    image::open(&p)
                        .with_context(|| format!("reading the mask {}", p.display()))?
                        .into_luma8(),
                )
            }
            None => None,
        };
        let render =
            fresco_atlas::render_textured(&model, camera, &image.cam_from_world, args.supersample)?;
        if let Some(dir) = &args.save_renders {
            std::fs::create_dir_all(dir)?;
            let mut bytes = Vec::new();
            render.image.write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )?;
            fresco_core::atomic_file::write_bytes_atomically(&dir.join(name), &bytes)?;
        }
        let m = fresco_atlas::comparison_mask(&render, mask.as_ref());
        let c = fresco_atlas::compare_to_photo(&render.image, &photo, &m);
        if c.pixels == 0 {
            anyhow::bail!("{name}: the model covers no pixel of the photo's mask");
        }
        psnr += c.psnr / args.views.len() as f64;
        psnr_gain += c.psnr_gain / args.views.len() as f64;
        ssim += c.ssim_gain / args.views.len() as f64;
        per_view.insert(name.clone(), serde_json::to_value(&c)?);
    }
    let seams = fresco_atlas::seam_discrepancy(&model.mesh, &model.textures);
    Ok(serde_json::json!({
        "model": args.model,
        "seam_discrepancy": seams,
        "mean_psnr": psnr,
        "mean_psnr_gain": psnr_gain,
        "mean_ssim_gain": ssim,
        "views": per_view,
    }))
}
