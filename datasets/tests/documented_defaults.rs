//! Every `Config` of fresco-datasets states its defaults in its doc comments
//! ("Default: `...`"), and those are the values `Config::default()` sets: the docs cannot
//! drift from the code. Each default is valid (`check()` accepts it) and `check()` names a
//! field it rejects.

use fresco_core::config::assert_documented_defaults;
use fresco_datasets::{SampleConfig, SceneConfig};

#[test]
fn scene_config() {
    let source = include_str!("../src/synthetic.rs");
    let default = format!("{:?}", SceneConfig::default());
    assert_documented_defaults(source, "SceneConfig", &default, &[]);
    SceneConfig::default().check().unwrap();
    let bad = SceneConfig {
        exposure_jitter: 0.95,
        ..SceneConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "exposure_jitter");
}

#[test]
fn sample_config() {
    let source = include_str!("../src/point_clouds.rs");
    let default = format!("{:?}", SampleConfig::default());
    assert_documented_defaults(source, "SampleConfig", &default, &[]);
    SampleConfig::default().check().unwrap();
    let bad = SampleConfig {
        hole_radius: f64::NAN,
        ..SampleConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "hole_radius");
}
