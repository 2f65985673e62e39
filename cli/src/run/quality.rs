//! The presets of `fresco run --quality`: for each stage, the arguments its verb gets (the
//! same flags `fresco <verb> --help` documents). Whatever a preset does not name keeps the
//! verb's default.
//!
//! | stage    | draft                                        | normal                 | high                   |
//! |----------|----------------------------------------------|------------------------|------------------------|
//! | features | photos down to 1000 px, 4096 features | defaults: 3200 px, 8192 features | 16384 features |
//! | match    | defaults (exhaustive pairs, ratio 0.8)        | defaults               | defaults               |
//! | sfm      | defaults                                     | defaults               | defaults               |
//! | mesh     | Poisson depth 7, 20k faces                   | depth 9, 200k faces    | depth 10, 500k faces   |
//! | unwrap   | 1024 px atlas                                | 2048 px atlas          | 4096 px atlas          |
//!
//! `draft` is for a first look in under a minute on the bundled sets; `high` for the final
//! model. Dense stereo and the texture atlas get their rows when those stages land.

use clap::ValueEnum;
use serde::Serialize;

/// `--quality`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// A first look in under a minute on the bundled photo sets.
    Draft,
    /// The default.
    #[default]
    Normal,
    /// Larger images, denser surface, larger atlas: slower.
    High,
}

impl Quality {
    pub fn name(self) -> &'static str {
        match self {
            Quality::Draft => "draft",
            Quality::Normal => "normal",
            Quality::High => "high",
        }
    }

    /// Arguments of `fresco features`.
    pub fn features(self) -> &'static [&'static str] {
        match self {
            Quality::Draft => &["--max-image-size", "1000", "--max-features", "4096"],
            Quality::Normal => &[],
            Quality::High => &["--max-features", "16384"],
        }
    }

    /// Arguments of `fresco mesh`.
    pub fn mesh(self) -> &'static [&'static str] {
        match self {
            Quality::Draft => &["--depth", "7", "--faces", "20000"],
            Quality::Normal => &["--depth", "9", "--faces", "200000"],
            Quality::High => &["--depth", "10", "--faces", "500000"],
        }
    }

    /// Arguments of `fresco unwrap`.
    pub fn unwrap(self) -> &'static [&'static str] {
        match self {
            Quality::Draft => &["--atlas", "1024"],
            Quality::Normal => &["--atlas", "2048"],
            Quality::High => &["--atlas", "4096"],
        }
    }
}
