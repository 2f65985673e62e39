//! `fresco texture <ws>`: the texture atlas of a workspace's mesh from its photos
//! (`fresco_atlas::texture_mesh`), and the same for COLMAP users without a workspace:
//! `fresco texture --colmap <model> --images <dir> --mesh <mesh> -o <out>`.
//!
//! In a workspace the cameras come from `<ws>/sparse/0`, the photos from `<ws>/images.json`,
//! the mesh from `--mesh`, else `<ws>/charts.ply` (a mesh with UVs), else `<ws>/mesh.ply`;
//! the outputs go to `<ws>/texture/` and `<ws>/model.glb`, or to `-o <dir>` instead.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_atlas::{ImageSource, TextureConfig, TextureInputs, texture_mesh};
use fresco_core::Mesh;

#[derive(Args, Debug)]
pub struct TextureArgs {
    /// Workspace folder (images.json, sparse/0, mesh.ply or charts.ply); outputs go there.
    #[arg(required_unless_present = "colmap")]
    pub workspace: Option<PathBuf>,
    /// Mesh to texture (.ply or .obj); with UVs they are kept, without, it is unwrapped.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// A COLMAP model folder (text or binary) instead of a workspace; needs --images,
    /// --mesh and --output.
    #[arg(long, requires_all = ["images", "mesh", "output"], conflicts_with = "workspace")]
    pub colmap: Option<PathBuf>,
    /// Folder of the photos named in the COLMAP model.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Output folder (needed with --colmap; with a workspace it defaults to the workspace).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Folder of masks (<image name>.png, non-zero on the object).
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Largest atlas width and height, texels.
    #[arg(long, default_value_t = TextureConfig::default().max_atlas_size)]
    pub atlas: u32,
    /// Most atlas images written.
    #[arg(long, default_value_t = TextureConfig::default().max_atlases)]
    pub atlases: u32,
    /// Texels per photo pixel along a side, at the best photo's resolution.
    #[arg(long, default_value_t = TextureConfig::default().texels_per_pixel)]
    pub texels_per_pixel: f64,
    /// Images kept out of the texture (comma-separated names), e.g. held out for evaluation.
    #[arg(long, value_delimiter = ',')]
    pub exclude: Vec<String>,
    /// Do not fit exposure and white-balance gains per view.
    #[arg(long)]
    pub no_gains: bool,
    /// Do not drop photometric outliers (highlights, occluders) before fusing.
    #[arg(long)]
    pub no_outliers: bool,
    /// Level the colours across chart boundaries after fusion (per chart and vertex offsets
    /// by least squares): smaller seams, at the risk of spreading a highlight's influence.
    #[arg(long)]
    pub level_seams: bool,
    /// Width of the strip along the seams over which both sides are brought to their mean
    /// level, texels (0: off).
    #[arg(long, default_value_t = TextureConfig::default().seam_strip_texels)]
    pub seam_strip: f64,
    /// Passes closing the remaining colour step at every texel along the seams (0: off).
    #[arg(long, default_value_t = TextureConfig::default().seam_detail_passes)]
    pub seam_detail_passes: u32,
    /// Seam edges whose faces meet at more than this angle keep their colour step, degrees
    /// (180: every seam edge is blended).
    #[arg(long, default_value_t = TextureConfig::default().seam_strip_crease_deg)]
    pub seam_strip_crease: f64,
    /// How much of the playback blur (a viewer's bilinear lookup, the photos' pixels) the
    /// texels are sharpened against where the views agree to within a pixel: 1 all, 0 off.
    #[arg(long, default_value_t = TextureConfig::default().playback_sharpening)]
    pub playback_sharpening: f64,
    /// Also write model.obj + model.mtl (with the atlas PNGs).
    #[arg(long)]
    pub obj: bool,
    /// Also write the per-vertex colour baseline as vertex_colors.glb.
    #[arg(long)]
    pub vertex_colors: bool,
}

fn read_mesh(path: &Path) -> anyhow::Result<Mesh> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    Ok(match ext.as_str() {
        "ply" => fresco_core::ply::read_mesh(path)?,
        "obj" => fresco_core::obj::read_mesh(path)?,
        _ => bail!(
            "{}: unknown mesh format (expected .ply or .obj)",
            path.display()
        ),
    })
}

/// The photos of a workspace, by name, from its images.json.
fn workspace_images(ws: &Path) -> anyhow::Result<ImageSource> {
    let list = fresco_sfm::workspace::read_images(ws)?;
    let map: BTreeMap<String, PathBuf> =
        list.images.into_iter().map(|e| (e.name, e.path)).collect();
    Ok(ImageSource::Files(map))
}

pub fn run(args: TextureArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let (rec, images, mesh_path, out) = match (&args.colmap, &args.workspace) {
        (Some(model), _) => {
            let rec = fresco_core::colmap::read_model(model)
                .with_context(|| format!("reading the COLMAP model {}", model.display()))?;
            let images = args.images.clone().expect("clap requires --images");
            if !images.is_dir() {
                bail!("--images {} is not a folder", images.display());
            }
            (
                rec,
                ImageSource::Folder(images),
                args.mesh.clone().expect("clap requires --mesh"),
                args.output.clone().expect("clap requires --output"),
            )
        }
        (None, Some(ws)) => {
            if !ws.is_dir() {
                bail!("workspace {} is not a folder", ws.display());
            }
            let sparse = ws.join("sparse").join("0");
            let rec = fresco_core::colmap::read_model(&sparse).context("reading the cameras")?;
            let mesh = match &args.mesh {
                Some(m) => m.clone(),
                None if ws.join("charts.ply").is_file() => ws.join("charts.ply"),
                None => ws.join("mesh.ply"),
            };
            // -o keeps the workspace's own model.glb when trying variants.
            let out = args.output.clone().unwrap_or_else(|| ws.clone());
            (rec, workspace_images(ws)?, mesh, out)
        }
        (None, None) => bail!("give a workspace, or --colmap with --images, --mesh and -o"),
    };
    let mesh = read_mesh(&mesh_path)?;
    std::fs::create_dir_all(&out)
        .with_context(|| format!("cannot create the output folder {}", out.display()))?;
    let config = TextureConfig {
        max_atlas_size: args.atlas,
        max_atlases: args.atlases,
        texels_per_pixel: args.texels_per_pixel,
        exclude_images: args.exclude.clone(),
        exposure_gains: !args.no_gains,
        outlier_rejection: !args.no_outliers,
        seam_leveling: args.level_seams,
        seam_strip_texels: args.seam_strip,
        seam_detail_passes: args.seam_detail_passes,
        seam_strip_crease_deg: args.seam_strip_crease,
        playback_sharpening: args.playback_sharpening,
        write_obj: args.obj,
        ..TextureConfig::default()
    };
    let inputs = TextureInputs {
        mesh: &mesh,
        reconstruction: &rec,
        images: &images,
        masks: args.masks.as_deref(),
    };
    let bars = crate::progress::Bars::new(ctx);
    let summary = texture_mesh(&inputs, &config, &out, &bars)
        .with_context(|| format!("texturing {}", mesh_path.display()))?;
    let mut json = serde_json::to_value(&summary)?;
    if args.vertex_colors {
        let (coloured, _) = fresco_atlas::vertex_colors(&inputs, &config, &bars)?;
        let path = out.join("vertex_colors.glb");
        fresco_core::gltf::write_glb(&path, &coloured, &[])?;
        if let serde_json::Value::Object(map) = &mut json {
            map.insert("vertex_colors".into(), path.display().to_string().into());
        }
    }
    if let serde_json::Value::Object(map) = &mut json {
        map.insert("mesh".into(), mesh_path.display().to_string().into());
    }
    Ok(json)
}
