//! The matching stage over a workspace (`fresco match`): the features of `images.json`'s
//! photos, the selected pairs matched and verified ([`match_pairs`]), the verified ones
//! written to `<ws>/matches/two_view.bin`.

use std::path::Path;

use fresco_core::config::ConfigError;
use fresco_core::{FormatError, Progress};

use crate::geometry::two_view::{PairKind, VerifiedPair};
use crate::matching::match_file::write_match_file;
use crate::matching::{MatchImage, MatchingConfig, PairSelection, match_pairs, select_pairs};
use crate::verification::VerificationConfig;
use crate::workspace::{ImageList, matches_path, read_features, read_images};

/// Settings of the matching stage.
#[derive(Clone, Debug)]
pub struct MatchStageConfig {
    /// Default: `Exhaustive`.
    pub selection: PairSelection,
    /// Default: `MatchingConfig::default()`.
    pub matching: MatchingConfig,
    /// Default: `VerificationConfig::default()`.
    pub verification: VerificationConfig,
}

impl Default for MatchStageConfig {
    fn default() -> Self {
        MatchStageConfig {
            selection: PairSelection::Exhaustive,
            matching: MatchingConfig::default(),
            verification: VerificationConfig::default(),
        }
    }
}

impl MatchStageConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        self.matching.check().map_err(|e| e.within("matching"))?;
        self.verification
            .check()
            .map_err(|e| e.within("verification"))
    }
}

/// Why [`match_workspace`] failed.
#[derive(Debug, thiserror::Error)]
pub enum MatchStageError {
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// What [`match_workspace`] did.
#[derive(Clone, Debug)]
pub struct MatchStageOutput {
    /// The workspace's images.
    pub images: ImageList,
    /// Every pair tried, degenerate ones included (only the others are written), ordered by
    /// image ids.
    pub pairs: Vec<VerifiedPair>,
}

/// Runs the matching stage on workspace `ws` (see the module documentation).
pub fn match_workspace(
    ws: &Path,
    config: &MatchStageConfig,
    progress: &dyn Progress,
) -> Result<MatchStageOutput, MatchStageError> {
    config.check()?;
    let images = read_images(ws)?;
    let features = images
        .images
        .iter()
        .map(|im| read_features(ws, im))
        .collect::<Result<Vec<_>, _>>()?;
    if images.images.len() < 2 {
        tracing::warn!(
            "{} holds {} image(s): nothing to match",
            ws.display(),
            images.images.len()
        );
    }
    let min_inliers = config.verification.min_inliers;
    for (im, f) in images.images.iter().zip(&features) {
        if f.len() < min_inliers {
            tracing::warn!(
                "{} has {} keypoints (fewer than {min_inliers}): it cannot be verified with any other image",
                im.name,
                f.len(),
            );
        }
    }
    let selected = select_pairs(&features, config.selection);
    let match_images: Vec<MatchImage> = images
        .images
        .iter()
        .zip(&features)
        .map(|(im, f)| MatchImage {
            id: im.id,
            features: f,
            prior: &im.prior,
        })
        .collect();
    let pairs = match_pairs(
        &match_images,
        &selected,
        &config.matching,
        &config.verification,
        progress,
    );
    let out = matches_path(ws);
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(|e| FormatError::io(dir, e))?;
    }
    let kept: Vec<VerifiedPair> = pairs
        .iter()
        .filter(|p| p.geometry.kind != PairKind::Degenerate)
        .cloned()
        .collect();
    write_match_file(&out, &kept)?;
    Ok(MatchStageOutput { images, pairs })
}
