//! Every `Config` of fresco-pst states its defaults in its doc comments ("Default: `...`"),
//! and those are the values `Config::default()` sets: the docs cannot drift from the code.
//! Each default is valid (`check()` accepts it) and `check()` names a field it rejects.

use fresco_core::config::assert_documented_defaults;
use fresco_pst::apply::ApplyConfig;
use fresco_pst::{Channel, CreateConfig, FieldConfig, Kernel, SamplingConfig};

fn debug<T: std::fmt::Debug>(value: &T) -> String {
    format!("{value:?}")
}

#[test]
fn field_config() {
    let source = include_str!("../src/field.rs");
    assert_documented_defaults(source, "FieldConfig", &debug(&FieldConfig::default()), &[]);
    FieldConfig::default().check().unwrap();
    let bad = FieldConfig {
        kernel: Kernel::Singular { power: -1.0 },
        ..FieldConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "kernel.power");
}

#[test]
fn sampling_config() {
    let source = include_str!("../src/sampling.rs");
    assert_documented_defaults(
        source,
        "SamplingConfig",
        &debug(&SamplingConfig::default()),
        &[],
    );
    SamplingConfig::default().check().unwrap();
    let bad = SamplingConfig {
        target: 0,
        ..SamplingConfig::default()
    };
    assert_eq!(bad.check().unwrap_err().field, "target");
}

#[test]
fn create_config() {
    let source = include_str!("../src/store.rs");
    assert_documented_defaults(
        source,
        "CreateConfig",
        &debug(&CreateConfig::default()),
        &[
            (
                "SamplingConfig::default()",
                debug(&SamplingConfig::default()),
            ),
            (
                r#"vec![Channel::new("rgb", &[0.8, 0.8, 0.8])]"#,
                debug(&vec![Channel::new("rgb", &[0.8, 0.8, 0.8])]),
            ),
        ],
    );
    CreateConfig::default().check().unwrap();
    let mut bad = CreateConfig::default();
    bad.sampling.alpha = f64::NAN;
    assert_eq!(bad.check().unwrap_err().field, "sampling.alpha");
    let no_channel = CreateConfig {
        channels: Vec::new(),
        ..CreateConfig::default()
    };
    assert_eq!(no_channel.check().unwrap_err().field, "channels");
}

#[test]
fn apply_config() {
    let source = include_str!("../src/apply.rs");
    assert_documented_defaults(
        source,
        "ApplyConfig",
        &debug(&ApplyConfig::default()),
        &[("FieldConfig::default()", debug(&FieldConfig::default()))],
    );
    ApplyConfig::default().check().unwrap();
    let mut bad = ApplyConfig::default();
    bad.field.k = 0;
    assert_eq!(bad.check().unwrap_err().field, "field.k");
}
