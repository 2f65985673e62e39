//! Every `Config` of fresco-core states its defaults in its doc comments ("Default: `...`"),
//! and those are the values `Config::default()` sets: the docs cannot drift from the code.

use fresco_core::config::assert_documented_defaults;
use fresco_core::raster::RasterConfig;

#[test]
fn raster_config_defaults_are_the_documented_ones() {
    assert_documented_defaults(
        include_str!("../src/raster.rs"),
        "RasterConfig",
        &format!("{:?}", RasterConfig::default()),
        &[],
    );
}

#[test]
fn raster_config_check_names_the_bad_field() {
    assert!(RasterConfig::default().check().is_ok());
    let e = RasterConfig {
        near: f64::NAN,
        ..RasterConfig::default()
    }
    .check()
    .unwrap_err();
    assert_eq!(e.field, "near");
}
