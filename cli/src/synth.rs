//! `fresco synth <shape> -o <dir>`: writes a synthetic dataset with exact ground truth
//! (photos, masks, COLMAP and Middlebury cameras, PLY and GLB meshes); see
//! `fresco_datasets::synthetic`.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_datasets::{Distortion, Layout, SceneConfig, Shape};

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Shape: sphere, torus, double-torus, blob or temple.
    pub shape: String,
    /// Output folder (created; an existing one must be empty or a previous synthetic dataset).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Number of photos.
    #[arg(long, default_value_t = SceneConfig::default().views)]
    pub views: u32,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value_t = default_size())]
    pub size: String,
    /// Seed of the albedo, camera perturbations, exposures and surface samples.
    #[arg(long, default_value_t = SceneConfig::default().seed)]
    pub seed: u64,
    /// Camera layout: ring (at --elevation degrees) or hemisphere.
    #[arg(long, default_value_t = SceneConfig::default().layout.name().to_string())]
    pub layout: String,
    /// Ring elevation in degrees.
    #[arg(long, default_value_t = SceneConfig::default().elevation_deg)]
    pub elevation: f64,
    /// Radial distortion coefficient k1 of a SIMPLE_RADIAL camera (0: SIMPLE_PINHOLE).
    #[arg(long, default_value_t = default_k1(), allow_negative_numbers = true)]
    pub distortion: f64,
    /// Focal length in pixels (default 1.2 times the longer image side).
    #[arg(long)]
    pub focal: Option<f64>,
    /// Mesh resolution (0 coarse; each step about 4x the faces).
    #[arg(long, default_value_t = SceneConfig::default().detail)]
    pub detail: u32,
    /// Surround the object with a textured box (floor and walls) instead of a plain background.
    #[arg(long)]
    pub backdrop: bool,
    /// Contrast of the object's albedo (1: full pattern; 0.1: a weakly textured object).
    #[arg(long, default_value_t = SceneConfig::default().albedo_contrast)]
    pub albedo_contrast: f64,
    /// Each photo's exposure is multiplied by a factor drawn in 1 +- this.
    #[arg(long, default_value_t = SceneConfig::default().exposure_jitter)]
    pub exposure_jitter: f64,
}

/// The library's default image size as `WIDTHxHEIGHT`.
fn default_size() -> String {
    let c = SceneConfig::default();
    format!("{}x{}", c.width, c.height)
}

/// The library's default distortion coefficient (0 when it has none).
fn default_k1() -> f64 {
    match SceneConfig::default().distortion {
        Distortion::SimpleRadial { k } => k,
        Distortion::Radial { k1, .. } => k1,
        Distortion::None => 0.0,
    }
}

pub fn run(args: SynthArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let config = config_from_args(&args)?;
    let bars = crate::progress::Bars::new(ctx);
    let summary = fresco_datasets::write_dataset(&config, &args.output, &bars)
        .with_context(|| format!("writing the synthetic dataset {}", args.output.display()))?;
    Ok(serde_json::to_value(summary)?)
}

fn config_from_args(args: &SynthArgs) -> anyhow::Result<SceneConfig> {
    let Some(shape) = Shape::from_name(&args.shape) else {
        let names: Vec<&str> = Shape::ALL.iter().map(|s| s.name()).collect();
        bail!(
            "unknown shape `{}`; choose one of {}",
            args.shape,
            names.join(", ")
        );
    };
    let Some(layout) = Layout::from_name(&args.layout) else {
        bail!(
            "unknown layout `{}`; choose ring or hemisphere",
            args.layout
        );
    };
    let (width, height) = parse_size(&args.size)?;
    let distortion = if args.distortion == 0.0 {
        Distortion::None
    } else {
        Distortion::SimpleRadial { k: args.distortion }
    };
    Ok(SceneConfig {
        shape,
        detail: args.detail,
        views: args.views,
        width,
        height,
        focal: args.focal,
        distortion,
        layout,
        elevation_deg: args.elevation,
        backdrop: args.backdrop,
        albedo_contrast: args.albedo_contrast,
        exposure_jitter: args.exposure_jitter,
        seed: args.seed,
        ..SceneConfig::default()
    })
}

/// `WIDTHxHEIGHT`, e.g. `640x480`.
fn parse_size(size: &str) -> anyhow::Result<(u32, u32)> {
    let parsed = size
        .split_once(['x', 'X'])
        .and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)));
    match parsed {
        Some((w, h)) => Ok((w, h)),
        None => bail!("size `{size}` is not WIDTHxHEIGHT (e.g. 640x480)"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(shape: &str, output: PathBuf) -> SynthArgs {
        SynthArgs {
            shape: shape.into(),
            output,
            views: 3,
            size: "96x72".into(),
            seed: 3,
            layout: "ring".into(),
            elevation: 30.0,
            distortion: -0.03,
            focal: None,
            detail: 0,
            backdrop: false,
            albedo_contrast: 1.0,
            exposure_jitter: 0.08,
        }
    }

    #[test]
    fn synth_writes_a_dataset_and_a_json_summary() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("t");
        let ctx = crate::Context {
            quiet: true,
            json: true,
        };
        let summary = run(args("torus", out.clone()), &ctx).unwrap();
        assert_eq!(summary["views"], 3);
        assert_eq!(summary["width"], 96);
        assert_eq!(summary["camera_model"], "SimpleRadial");
        for f in [
            "images/view_0002.png",
            "masks/view_0002.png.png",
            "sparse/cameras.txt",
            "mesh.ply",
        ] {
            assert!(out.join(f).is_file(), "{f}");
        }
    }

    #[test]
    fn bad_arguments_are_reported() {
        let dir = tempfile::tempdir().unwrap();
        let ctx = crate::Context {
            quiet: true,
            json: false,
        };
        let e = run(args("cube", dir.path().join("a")), &ctx).unwrap_err();
        assert!(e.to_string().contains("unknown shape `cube`"), "{e}");
        let mut bad = args("torus", dir.path().join("b"));
        bad.size = "640by480".into();
        assert!(
            run(bad, &ctx)
                .unwrap_err()
                .to_string()
                .contains("WIDTHxHEIGHT")
        );
        // A non-empty folder that is not a synthetic dataset is left alone.
        let user = dir.path().join("photos");
        std::fs::create_dir(&user).unwrap();
        std::fs::write(user.join("mine.jpg"), b"not ours").unwrap();
        let e = run(args("torus", user.clone()), &ctx).unwrap_err();
        assert!(format!("{e:#}").contains("refusing"), "{e:#}");
        assert_eq!(std::fs::read(user.join("mine.jpg")).unwrap(), b"not ours");
    }
}
