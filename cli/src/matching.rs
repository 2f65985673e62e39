//! `fresco match <ws>`: descriptor matching and geometric verification of a workspace's image
//! pairs (`fresco_sfm::matching`, `fresco_sfm::verification`), written to
//! `<ws>/matches/two_view.bin`, with the view graph's connected components in the summary.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_sfm::geometry::two_view::PairKind;
use fresco_sfm::matching::{
    MatchStageConfig, MatchStageOutput, MatchingConfig, PairSelection, match_workspace,
};
use fresco_sfm::verification::VerificationConfig;
use fresco_sfm::verification::view_graph::ViewGraph;
use fresco_sfm::workspace::matches_path;
use serde_json::json;

#[derive(Args, Debug)]
pub struct MatchArgs {
    /// Workspace folder written by `fresco features` (images.json, features/).
    pub workspace: PathBuf,
    /// Match each image only with the next N images (video-like captures) instead of all pairs.
    #[arg(long, conflicts_with = "retrieval")]
    pub sequential: Option<usize>,
    /// Match each image only with its K most similar images by a global descriptor.
    #[arg(long)]
    pub retrieval: Option<usize>,
    /// Lowe's ratio test threshold.
    #[arg(long, default_value_t = MatchingConfig::default().ratio)]
    pub ratio: f32,
    /// Keep matches that are not mutual nearest neighbours.
    #[arg(long)]
    pub no_mutual: bool,
    /// Match each verified pair again near its epipolar lines and verify those matches
    /// (guided matching: more matches on ordinary scenes, wrong ones on repeated structure).
    #[arg(long)]
    pub guided: bool,
    /// RANSAC threshold in pixels (Sampson error for F and E, transfer error for H).
    #[arg(long, default_value_t = VerificationConfig::default().max_error_px)]
    pub max_error: f64,
    /// Fewest inliers of a verified pair.
    #[arg(long, default_value_t = VerificationConfig::default().min_inliers)]
    pub min_inliers: usize,
}

pub fn run(args: MatchArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let start = Instant::now();
    let ws = &args.workspace;
    if !(args.ratio > 0.0 && args.ratio <= 1.0) {
        bail!("--ratio must be in (0, 1], got {}", args.ratio);
    }
    if !(args.max_error > 0.0 && args.max_error.is_finite()) {
        bail!("--max-error must be positive, got {}", args.max_error);
    }
    let selection = match (args.sequential, args.retrieval) {
        (Some(n), _) => PairSelection::Sequential { overlap: n },
        (None, Some(k)) => PairSelection::Retrieval { top_k: k },
        (None, None) => PairSelection::Exhaustive,
    };
    let config = MatchStageConfig {
        selection,
        matching: MatchingConfig {
            ratio: args.ratio,
            mutual: !args.no_mutual,
            guided: args.guided,
        },
        verification: VerificationConfig {
            max_error_px: args.max_error,
            min_inliers: args.min_inliers,
            ..Default::default()
        },
    };
    let bars = crate::progress::Bars::new(ctx);
    let MatchStageOutput {
        images: list,
        pairs: verified,
    } = match_workspace(ws, &config, &bars)
        // The error names the file at fault: the context does not name the folder again.
        .context("matching the workspace")?;
    let out = matches_path(ws);
    let kept: Vec<_> = verified
        .iter()
        .filter(|p| p.geometry.kind != PairKind::Degenerate)
        .cloned()
        .collect();
    let ids: Vec<u32> = list.images.iter().map(|im| im.id).collect();
    let graph = ViewGraph::new(&ids, &kept, args.min_inliers);
    let name_of = |id: u32| {
        list.images
            .iter()
            .find(|im| im.id == id)
            .map_or_else(String::new, |im| im.name.clone())
    };
    let components: Vec<_> = graph
        .components()
        .into_iter()
        .map(|c| {
            json!({
                "images": c.images.iter().map(|&i| name_of(i)).collect::<Vec<_>>(),
                "pairs": c.pairs,
                "inliers": c.inliers,
            })
        })
        .collect();
    let mut by_kind = serde_json::Map::new();
    for p in &verified {
        let key = serde_json::to_value(p.geometry.kind)?
            .as_str()
            .unwrap_or("unknown")
            .to_string();
        let slot = by_kind.entry(key).or_insert(json!(0));
        *slot = json!(slot.as_u64().unwrap_or(0) + 1);
    }
    let per_pair: Vec<_> = verified
        .iter()
        .map(|p| {
            json!({
                "image1": name_of(p.image1),
                "image2": name_of(p.image2),
                "matches": p.num_matches,
                "inliers": p.geometry.inliers.len(),
                "kind": p.geometry.kind,
            })
        })
        .collect();
    Ok(json!({
        "workspace": ws,
        "matches_file": out,
        "images": list.images.len(),
        "selection": selection,
        "pairs_tried": verified.len(),
        "pairs_verified": kept.len(),
        "pairs_by_kind": by_kind,
        "components": components,
        "pairs": per_pair,
        "seconds": start.elapsed().as_secs_f64(),
    }))
}
