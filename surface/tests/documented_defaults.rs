//! Every `Config` of fresco-surface states its defaults in its doc comments ("Default: `...`"),
//! and those are the values `Config::default()` sets: the docs cannot drift from the code.
//! Each default is valid (`check()` accepts it) and `check()` names a field it rejects.

use fresco_core::config::assert_documented_defaults;
use fresco_surface::PoissonConfig;
use fresco_surface::cleanup::CleanupConfig;
use fresco_surface::decimate::DecimateConfig;
use fresco_surface::metrics::DistanceConfig;
use fresco_surface::normals::NormalConfig;
use fresco_surface::pipeline::MeshConfig;
use fresco_surface::trim::TrimConfig;

fn debug<T: std::fmt::Debug>(value: &T) -> String {
    format!("{value:?}")
}

#[test]
fn poisson_config() {
    let source = include_str!("../src/poisson.rs");
    assert_documented_defaults(
        source,
        "PoissonConfig",
        &debug(&PoissonConfig::default()),
        &[],
    );
    PoissonConfig::default().check().unwrap();
    let bad = PoissonConfig {
        depth: 40,
        ..PoissonConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "depth");
}

#[test]
fn trim_config() {
    let source = include_str!("../src/trim.rs");
    assert_documented_defaults(source, "TrimConfig", &debug(&TrimConfig::default()), &[]);
    TrimConfig::default().check().unwrap();
    let bad = TrimConfig {
        below_median: Some(f32::NAN),
        ..TrimConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "below_median");
}

#[test]
fn cleanup_config() {
    let source = include_str!("../src/cleanup.rs");
    assert_documented_defaults(
        source,
        "CleanupConfig",
        &debug(&CleanupConfig::default()),
        &[],
    );
    CleanupConfig::default().check().unwrap();
    let bad = CleanupConfig {
        weld_tolerance: -1.0,
        ..CleanupConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "weld_tolerance");
}

#[test]
fn decimate_config() {
    let source = include_str!("../src/decimate.rs");
    assert_documented_defaults(
        source,
        "DecimateConfig",
        &debug(&DecimateConfig::default()),
        &[],
    );
    DecimateConfig::default().check().unwrap();
    let bad = DecimateConfig {
        min_normal_cos: 2.0,
        ..DecimateConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "min_normal_cos");
}

#[test]
fn normal_config() {
    let source = include_str!("../src/normals.rs");
    assert_documented_defaults(
        source,
        "NormalConfig",
        &debug(&NormalConfig::default()),
        &[],
    );
    NormalConfig::default().check().unwrap();
    let bad = NormalConfig {
        k: 2,
        ..NormalConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "k");
}

#[test]
fn distance_config() {
    let source = include_str!("../src/metrics.rs");
    assert_documented_defaults(
        source,
        "DistanceConfig",
        &debug(&DistanceConfig::default()),
        &[],
    );
    DistanceConfig::default().check().unwrap();
    let bad = DistanceConfig {
        f_threshold: f64::INFINITY,
        ..DistanceConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "f_threshold");
}

#[test]
fn mesh_config() {
    let source = include_str!("../src/pipeline.rs");
    let trim = TrimConfig {
        below_median: Some(1.0),
        ..TrimConfig::default()
    };
    assert_documented_defaults(
        source,
        "MeshConfig",
        &debug(&MeshConfig::default()),
        &[
            ("PoissonConfig::default()", debug(&PoissonConfig::default())),
            ("NormalConfig::default()", debug(&NormalConfig::default())),
            ("CleanupConfig::default()", debug(&CleanupConfig::default())),
            (
                "TrimConfig { below_median: Some(1.0), ..TrimConfig::default() }",
                debug(&trim),
            ),
        ],
    );
    MeshConfig::default().check().unwrap();
    let mut bad = MeshConfig::default();
    bad.poisson.point_weight = f64::NAN;
    assert_eq!(bad.check().unwrap_err().field, "poisson.point_weight");
}
