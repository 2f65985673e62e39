//! Every `Config` of fresco-geotex states its defaults in its doc comments ("Default:
//! `...`"), and those are the values `Config::default()` sets; each default passes
//! `check()`, and `check()` names a field it rejects.

use fresco_core::config::assert_documented_defaults;
use fresco_geotex::curvature::CurvatureConfig;
use fresco_geotex::fairing::FairingConfig;
use fresco_geotex::protective_grid::GridConfig;
use fresco_geotex::segmentation::SegmentationConfig;
use fresco_geotex::{GeotexError, ResizeConfig, SynthesisConfig};

fn debug<T: std::fmt::Debug>(value: &T) -> String {
    format!("{value:?}")
}

#[test]
fn documented_defaults_are_the_defaults() {
    let d = ResizeConfig::default();
    assert_documented_defaults(
        include_str!("../src/curvature.rs"),
        "CurvatureConfig",
        &debug(&d.curvature),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/segmentation.rs"),
        "SegmentationConfig",
        &debug(&d.segmentation),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/fairing.rs"),
        "FairingConfig",
        &debug(&d.fairing),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/protective_grid.rs"),
        "GridConfig",
        &debug(&d.grid),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/synthesis.rs"),
        "SynthesisConfig",
        &debug(&d.synthesis),
        &[],
    );
    assert_documented_defaults(
        include_str!("../src/resize.rs"),
        "ResizeConfig",
        &debug(&d),
        &[
            (
                "CurvatureConfig::default()",
                debug(&CurvatureConfig::default()),
            ),
            (
                "SegmentationConfig::default()",
                debug(&SegmentationConfig::default()),
            ),
            ("FairingConfig::default()", debug(&FairingConfig::default())),
            ("GridConfig::default()", debug(&GridConfig::default())),
            (
                "SynthesisConfig::default()",
                debug(&SynthesisConfig::default()),
            ),
        ],
    );
}

#[test]
fn defaults_pass_check_and_a_bad_field_is_named() {
    ResizeConfig::default().check().unwrap();
    let bad = ResizeConfig {
        synthesis: SynthesisConfig {
            levels: 0,
            ..SynthesisConfig::default()
        },
        ..ResizeConfig::default()
    };
    match bad.check() {
        Err(GeotexError::Config(e)) => assert_eq!(e.field, "synthesis.levels"),
        other => panic!("{other:?}"),
    }
}
