//! The presets of `fresco run --quality`: for each stage, the arguments its verb gets (the
//! same flags `fresco <verb> --help` documents). Whatever a preset does not name keeps the
//! verb's default.
//!
//! | stage    | draft                                  | normal                                  | high                         |
//! |----------|----------------------------------------|-----------------------------------------|------------------------------|
//! | features | photos down to 1000 px, 4096 features  | defaults: 3200 px, 8192 features        | 16384 features               |
//! | match    | defaults (exhaustive pairs, ratio 0.8) | defaults                                | defaults                     |
//! | sfm      | defaults                               | defaults                                | defaults                     |
//! | dense    | images down to 320 px, 3 source views, 3 PatchMatch iterations | images up to 1600 px (default), 4 sources, 4 iterations | 3200 px, the defaults' 8 sources and 6 iterations |
//! | mesh     | Poisson depth 7, 20k faces             | depth 9, 200k faces                     | depth 10, 500k faces         |
//! | unwrap   | 1024 px chart packing                  | 2048 px                                 | 4096 px                      |
//! | texture  | 0.5 texel per photo pixel, atlas at most 2048 | defaults: 1.5 texels per pixel, at most 8192 | 2 texels per pixel |
//!
//! The unwrap's atlas size only sets the packing's resolution: the texture stage sizes the
//! atlas for the photos' resolution (`--texels-per-pixel`, capped by `--atlas`). `draft` is
//! for a first look in about a minute on the bundled sets; `high` for the final model.

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

    /// Arguments of `fresco dense`.
    pub fn dense(self) -> &'static [&'static str] {
        match self {
            Quality::Draft => &[
                "--max-image-size",
                "320",
                "--max-sources",
                "3",
                "--iterations",
                "3",
            ],
            Quality::Normal => &["--max-sources", "4", "--iterations", "4"],
            Quality::High => &["--max-image-size", "3200"],
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

    /// Arguments of `fresco texture`.
    pub fn texture(self) -> &'static [&'static str] {
        match self {
            Quality::Draft => &["--texels-per-pixel", "0.5", "--atlas", "2048"],
            Quality::Normal => &[],
            Quality::High => &["--texels-per-pixel", "2"],
        }
    }
}
