//! What can go wrong in fresco-sprites, naming the sprite, pattern or file at fault.

use std::path::PathBuf;

use fresco_core::FormatError;

/// Errors of every sprites operation. Libraries return these; the CLI prints them.
#[derive(Debug, thiserror::Error)]
pub enum SpriteError {
    /// A file could not be read or written, or did not parse.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// A sprite-scene file is malformed; the message names the sprite or pattern.
    #[error("{path}: {message}")]
    Scene { path: PathBuf, message: String },
    /// A sprite's parameters are unusable (NaN, zero size, degenerate frame).
    #[error("sprite {index}: {message}")]
    Sprite { index: usize, message: String },
    /// A pattern image is unusable or missing.
    #[error("pattern {index} ({path}): {message}")]
    Pattern {
        index: usize,
        path: PathBuf,
        message: String,
    },
    /// Insertion failed (section 5.2): more than O_max sprites overlap in one cell.
    #[error(
        "sprite {index}: O_max too small: it overlaps all {o_max} sprites of a full leaf (level {level}); raise o_max"
    )]
    OmaxTooSmall {
        index: usize,
        o_max: usize,
        level: u32,
    },
    /// Insertion failed (section 5.2): splitting would go below the maximum depth.
    #[error(
        "sprite {index}: max depth reached: {o_max} sprites crowd a cell at level {level} (max depth {max_depth}); raise max_depth or o_max"
    )]
    MaxDepth {
        index: usize,
        o_max: usize,
        level: u32,
        max_depth: u32,
    },
    /// The indirection pool or leaf-vector table cannot grow.
    #[error("sprite {index}: {message}")]
    Full { index: usize, message: String },
    /// No sprite with this id.
    #[error("no sprite with id {0}")]
    NoSprite(usize),
    /// A setting is out of range; names the field.
    #[error("invalid configuration: {field}: {message}")]
    Config {
        field: &'static str,
        message: String,
    },
    /// A mesh, camera or texture given to a render or bake is unusable.
    #[error("{0}")]
    Input(String),
}

pub type Result<T> = std::result::Result<T, SpriteError>;
