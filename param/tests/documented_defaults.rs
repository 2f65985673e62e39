//! Every `Config` of fresco-param states its defaults in its doc comments ("Default: `...`"),
//! and those are the values `Config::default()` sets: the docs cannot drift from the code.
//! Each default is valid (`check()` accepts it) and `check()` names a field it rejects.

use fresco_core::config::assert_documented_defaults;
use fresco_param::UnwrapConfig;
use fresco_param::charts::ChartConfig;

fn debug<T: std::fmt::Debug>(value: &T) -> String {
    format!("{value:?}")
}

#[test]
fn chart_config() {
    let source = include_str!("../src/charts.rs");
    assert_documented_defaults(source, "ChartConfig", &debug(&ChartConfig::default()), &[]);
    ChartConfig::default().check().unwrap();
    let bad = ChartConfig {
        bands: 3,
        ..ChartConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "bands");
}

#[test]
fn unwrap_config() {
    let source = include_str!("../src/unwrap.rs");
    assert_documented_defaults(
        source,
        "UnwrapConfig",
        &debug(&UnwrapConfig::default()),
        &[("ChartConfig::default()", debug(&ChartConfig::default()))],
    );
    UnwrapConfig::default().check().unwrap();
    let bad = UnwrapConfig {
        gutter: 2048,
        ..UnwrapConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "gutter");
    let mut nested = UnwrapConfig::default();
    nested.charts.isovalue = 0.0;
    assert_eq!(nested.check().unwrap_err().field, "charts.isovalue");
}
