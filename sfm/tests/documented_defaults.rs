//! Every `Config` of fresco-sfm states its defaults in its doc comments ("Default: `...`"),
//! and those are the values `Config::default()` sets: the docs cannot drift from the code
//! (issue 20: `merge_min_points`' doc said 10 where the code set 6). Each default is valid
//! (`check()` accepts it) and `check()` names the field it rejects, nested ones by their path.

use fresco_core::config::assert_documented_defaults;
use fresco_sfm::bundle::BundleConfig;
use fresco_sfm::bundle::silhouette::SilhouetteConfig;
use fresco_sfm::features::dog::DetectorConfig;
use fresco_sfm::features::orientation::OrientationConfig;
use fresco_sfm::features::plain_background::PlainBackgroundConfig;
use fresco_sfm::features::scale_space::ScaleSpaceConfig;
use fresco_sfm::features::{FeaturesConfig, SiftConfig};
use fresco_sfm::geometry::pnp::PnpConfig;
use fresco_sfm::geometry::ransac::RansacConfig;
use fresco_sfm::geometry::triangulation::TriangulationConfig;
use fresco_sfm::mapping::mapper::MapperConfig;
use fresco_sfm::mapping::reconstruct::SfmConfig;
use fresco_sfm::matching::guided_matching::GuidedConfig;
use fresco_sfm::matching::{MatchStageConfig, MatchingConfig};
use fresco_sfm::verification::VerificationConfig;

fn debug<T: std::fmt::Debug>(value: &T) -> String {
    format!("{value:?}")
}

fn known(expr: &str, value: impl std::fmt::Debug) -> (&str, String) {
    (expr, debug(&value))
}

#[test]
fn feature_configs() {
    assert_documented_defaults(
        include_str!("../src/features/scale_space.rs"),
        "ScaleSpaceConfig",
        &debug(&ScaleSpaceConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/features/dog.rs"),
        "DetectorConfig",
        &debug(&DetectorConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/features/orientation.rs"),
        "OrientationConfig",
        &debug(&OrientationConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/features/plain_background.rs"),
        "PlainBackgroundConfig",
        &debug(&PlainBackgroundConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/features/extract.rs"),
        "SiftConfig",
        &debug(&SiftConfig::default()),
        &[
            known("ScaleSpaceConfig::default()", ScaleSpaceConfig::default()),
            known("DetectorConfig::default()", DetectorConfig::default()),
            known("OrientationConfig::default()", OrientationConfig::default()),
            known(
                "PlainBackgroundConfig::default()",
                PlainBackgroundConfig::default(),
            ),
        ],
    );
    assert_documented_defaults(
        include_str!("../src/features/photo_folder.rs"),
        "FeaturesConfig",
        &debug(&FeaturesConfig::default()),
        &[known("SiftConfig::default()", SiftConfig::default())],
    );
    FeaturesConfig::default().check().unwrap();
    let mut bad = FeaturesConfig::default();
    bad.sift.detector.edge_threshold = 0.5;
    assert_eq!(
        bad.check().unwrap_err().field,
        "sift.detector.edge_threshold"
    );
    let mut bad = SiftConfig {
        min_contrast_threshold: f32::NAN,
        ..SiftConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "min_contrast_threshold");
    bad = SiftConfig::default();
    bad.scale_space.input_blur = 2.0;
    assert_eq!(bad.check().unwrap_err().field, "scale_space.input_blur");
    bad = SiftConfig::default();
    bad.orientation.bins = 0;
    assert_eq!(bad.check().unwrap_err().field, "orientation.bins");
}

#[test]
fn matching_configs() {
    assert_documented_defaults(
        include_str!("../src/matching/descriptor_matching.rs"),
        "MatchingConfig",
        &debug(&MatchingConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/matching/guided_matching.rs"),
        "GuidedConfig",
        &debug(&GuidedConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/verification/geometric.rs"),
        "VerificationConfig",
        &debug(&VerificationConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/matching/workspace_matching.rs"),
        "MatchStageConfig",
        &debug(&MatchStageConfig::default()),
        &[
            known("MatchingConfig::default()", MatchingConfig::default()),
            known(
                "VerificationConfig::default()",
                VerificationConfig::default(),
            ),
        ],
    );
    MatchStageConfig::default().check().unwrap();
    let mut bad = MatchStageConfig::default();
    bad.matching.ratio = 1.5;
    assert_eq!(bad.check().unwrap_err().field, "matching.ratio");
    bad = MatchStageConfig::default();
    bad.verification.min_inliers = 3;
    assert_eq!(bad.check().unwrap_err().field, "verification.min_inliers");
    bad = MatchStageConfig::default();
    bad.verification.max_error_px = f64::INFINITY;
    assert_eq!(bad.check().unwrap_err().field, "verification.max_error_px");
}

#[test]
fn geometry_and_bundle_configs() {
    assert_documented_defaults(
        include_str!("../src/geometry/triangulation.rs"),
        "TriangulationConfig",
        &debug(&TriangulationConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/geometry/pnp.rs"),
        "PnpConfig",
        &debug(&PnpConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/geometry/ransac.rs"),
        "RansacConfig",
        &debug(&RansacConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/bundle/adjust.rs"),
        "BundleConfig",
        &debug(&BundleConfig::default()),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/bundle/silhouette.rs"),
        "SilhouetteConfig",
        &debug(&SilhouetteConfig::default()),
        &[],
    );
    TriangulationConfig::default().check().unwrap();
    PnpConfig::default().check().unwrap();
    BundleConfig::default().check().unwrap();
    SilhouetteConfig::default().check().unwrap();
    let bad = BundleConfig {
        function_tolerance: -1.0,
        ..BundleConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "function_tolerance");
    let bad = SilhouetteConfig {
        ray_samples: 1,
        ..SilhouetteConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "ray_samples");
}

#[test]
fn mapping_configs() {
    let mapper = MapperConfig::default();
    assert_documented_defaults(
        include_str!("../src/mapping/mapper.rs"),
        "MapperConfig",
        &debug(&mapper),
        &[
            known(
                "TriangulationConfig::default()",
                TriangulationConfig::default(),
            ),
            known("PnpConfig::default()", PnpConfig::default()),
            known(
                "BundleConfig::default() with loss Cauchy(1.0)",
                BundleConfig {
                    loss: fresco_sfm::bundle::loss::Loss::Cauchy(1.0),
                    ..BundleConfig::default()
                },
            ),
        ],
    );
    assert_documented_defaults(
        include_str!("../src/mapping/reconstruct.rs"),
        "SfmConfig",
        &debug(&SfmConfig::default()),
        &[
            known("MapperConfig::default()", MapperConfig::default()),
            known("SilhouetteConfig::default()", SilhouetteConfig::default()),
            known(
                "FocalFromFConfig::default()",
                fresco_sfm::focal_from_f::FocalFromFConfig::default(),
            ),
            known(
                "TrackRefinementConfig::default()",
                fresco_sfm::mapping::track_refinement::TrackRefinementConfig::default(),
            ),
        ],
    );
    assert_documented_defaults(
        include_str!("../src/mapping/track_refinement.rs"),
        "TrackRefinementConfig",
        &debug(&fresco_sfm::mapping::track_refinement::TrackRefinementConfig::default()),
        &[],
    );
    let mut bad = SfmConfig::default();
    bad.track_refinement.min_ncc = f64::NAN;
    assert_eq!(bad.check().unwrap_err().field, "track_refinement.min_ncc");
    assert_documented_defaults(
        include_str!("../src/focal_from_f.rs"),
        "FocalFromFConfig",
        &debug(&fresco_sfm::focal_from_f::FocalFromFConfig::default()),
        &[],
    );
    SfmConfig::default().check().unwrap();
    let mut bad = SfmConfig::default();
    bad.focal_from_f.max_spread = -1.0;
    assert_eq!(bad.check().unwrap_err().field, "focal_from_f.max_spread");
    let mut bad = SfmConfig::default();
    bad.mapper.merge_min_points = 2;
    assert_eq!(bad.check().unwrap_err().field, "mapper.merge_min_points");
    bad = SfmConfig::default();
    bad.mapper.pnp.min_inlier_ratio = 2.0;
    assert_eq!(
        bad.check().unwrap_err().field,
        "mapper.pnp.min_inlier_ratio"
    );
    bad = SfmConfig::default();
    bad.mapper.bundle.gradient_tolerance = f64::NAN;
    let e = bad.check().unwrap_err();
    assert_eq!(e.field, "mapper.bundle.gradient_tolerance");
    assert!(e.to_string().starts_with("invalid configuration"), "{e}");
}
