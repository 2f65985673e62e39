//! `fresco match <ws>`: descriptor matching and geometric verification of a workspace's image
//! pairs (`fresco_sfm::matching`, `fresco_sfm::verification`), written to
//! `<ws>/matches/two_view.bin`, with the view graph's connected components in the summary.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_sfm::match_file::write_match_file;
use fresco_sfm::matching::{MatchImage, MatchingConfig, PairSelection, match_pairs, select_pairs};
use fresco_sfm::two_view::PairKind;
use fresco_sfm::verification::VerificationConfig;
use fresco_sfm::view_graph::ViewGraph;
use fresco_sfm::workspace::{matches_path, read_features, read_images};
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
    #[arg(long, default_value_t = 0.8)]
    pub ratio: f32,
    /// Keep matches that are not mutual nearest neighbours.
    #[arg(long)]
    pub no_mutual: bool,
    /// Match each verified pair again near its epipolar lines and verify those matches
    /// (guided matching: more matches on ordinary scenes, wrong ones on repeated structure).
    #[arg(long)]
    pub guided: bool,
    /// RANSAC threshold in pixels (Sampson error for F and E, transfer error for H).
    #[arg(long, default_value_t = 4.0)]
    pub max_error: f64,
    /// Fewest inliers of a verified pair.
    #[arg(long, default_value_t = 15)]
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
    // The error names the file (images.json): the context does not name the folder again.
    let list = read_images(ws).context("reading the workspace")?;
    let features = list
        .images
        .iter()
        .map(|im| read_features(ws, im))
        .collect::<Result<Vec<_>, _>>()?;
    if list.images.len() < 2 {
        tracing::warn!(
            "{} holds {} image(s): nothing to match",
            ws.display(),
            list.images.len()
        );
    }
    for (im, f) in list.images.iter().zip(&features) {
        if f.len() < args.min_inliers {
            tracing::warn!(
                "{} has {} keypoints (fewer than {}): it cannot be verified with any other image",
                im.name,
                f.len(),
                args.min_inliers
            );
        }
    }
    let selection = match (args.sequential, args.retrieval) {
        (Some(n), _) => PairSelection::Sequential { overlap: n },
        (None, Some(k)) => PairSelection::Retrieval { top_k: k },
        (None, None) => PairSelection::Exhaustive,
    };
    let pairs = select_pairs(&features, selection);
    let images: Vec<MatchImage> = list
        .images
        .iter()
        .zip(&features)
        .map(|(im, f)| MatchImage {
            id: im.id,
            features: f,
            prior: &im.prior,
        })
        .collect();
    let matching = MatchingConfig {
        ratio: args.ratio,
        mutual: !args.no_mutual,
        guided: args.guided,
    };
    let verification = VerificationConfig {
        max_error_px: args.max_error,
        min_inliers: args.min_inliers,
        ..Default::default()
    };
    let bars = crate::progress::Bars::new(ctx);
    let verified = match_pairs(&images, &pairs, &matching, &verification, &bars);
    let out = matches_path(ws);
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let kept: Vec<_> = verified
        .iter()
        .filter(|p| p.geometry.kind != PairKind::Degenerate)
        .cloned()
        .collect();
    write_match_file(&out, &kept)?;

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
