//! Features: SIFT keypoints and descriptors of one photo (Lowe 2004), as COLMAP extracts them.
//!
//! The steps, in pipeline order: `scale_space.rs` (Gaussian octaves, separable blur), `dog.rs`
//! (difference-of-Gaussian extrema, sub-pixel refinement, contrast and edge tests),
//! `orientation.rs` (36-bin gradient histogram peaks), `descriptor.rs` (4x4x8 descriptor,
//! RootSIFT, u8 quantisation); `plain_background.rs` drops keypoints on an object's outline
//! against a plain background; `extract.rs` drives them ([`extract_features`]) and
//! `feature_file.rs` stores the result ([`Features`]) as one binary file per photo;
//! `photo_folder.rs` is the stage over a folder of photos ([`extract_photo_folder`]: focal
//! priors, features, `images.json`).

pub mod descriptor;
pub mod dog;
pub mod extract;
pub mod feature_file;
pub mod orientation;
pub mod photo_folder;
pub mod plain_background;
pub mod scale_space;

pub use extract::{
    ExtractionReport, SiftConfig, extract_features, extract_features_from_file,
    extract_features_reporting,
};
pub use feature_file::{Features, Keypoint, read_feature_file, write_feature_file};
pub use photo_folder::{FeaturesConfig, FeaturesError, FeaturesSummary, extract_photo_folder};
