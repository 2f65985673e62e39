//! `fresco eval poses <model> --gt <par.txt | model>`: pose accuracy of a model (a COLMAP
//! folder or a workspace) against a reference after a similarity alignment, with the figures
//! of `fresco_sfm::evaluate` (DESIGN.md, "How quality is measured").

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
    }
}

fn poses(args: PosesArgs) -> anyhow::Result<serde_json::Value> {
    let model = read_model_or_workspace(&args.model)
        .with_context(|| format!("reading the model {}", args.model.display()))?;
    let reference = read_reference(&args.gt, &model)
        .with_context(|| format!("reading the reference {}", args.gt.display()))?;
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
