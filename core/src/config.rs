//! What every stage's `Config` shares: the one "invalid configuration" error, the helper its
//! `check()` is written with, and the test that keeps documented defaults true.
//!
//! Conventions (as COLMAP's option structs with their `Check()`): each default lives once, in
//! `Config::default()`, and each field's doc comment states it as "Default: `value`" (the
//! value as `{:?}` prints it); the CLI binds its flags to those defaults
//! (`default_value_t = Config::default().field`); `check()` validates every field and names
//! the one at fault; the library entry point calls it before any work. Each crate's tests
//! run [`assert_documented_defaults`] over its `Config`s, so a doc cannot drift from the code.

use std::fmt::Display;

/// A configuration field outside its meaningful range, named as it is in the `Config`
/// (`poisson.depth` for a nested field).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("invalid configuration: `{field}` is {value}; it must be {expected}")]
pub struct ConfigError {
    pub field: String,
    /// The rejected value as written.
    pub value: String,
    /// What the field must be ("in 2..=12", "finite and >= 0").
    pub expected: String,
}

impl ConfigError {
    pub fn new(field: &str, value: impl Display, expected: impl Into<String>) -> ConfigError {
        ConfigError {
            field: field.to_string(),
            value: value.to_string(),
            expected: expected.into(),
        }
    }

    /// The same error for a field of a nested `Config` held in `parent`.
    pub fn within(mut self, parent: &str) -> ConfigError {
        self.field = format!("{parent}.{}", self.field);
        self
    }
}

/// `Ok` when `valid`, else the [`ConfigError`] naming `field`: one line per field in a
/// `check()` (`require((2..=12).contains(&c.depth), "depth", c.depth, "in 2..=12")?`).
pub fn require(
    valid: bool,
    field: &str,
    value: impl Display,
    expected: &str,
) -> Result<(), ConfigError> {
    if valid {
        Ok(())
    } else {
        Err(ConfigError::new(field, value, expected))
    }
}

/// Panics, listing every mismatch, unless each public field of `struct_name` (in `source`,
/// the text of the file that defines it) documents its default as "Default: `value`" and
/// that value is the field's in `default_debug` (`format!("{:?}", Config::default())`).
///
/// Comparison is on text, after three normalisations so that docs read naturally: digit
/// separators are dropped (`200_000`), enum paths are dropped (`Layout::Ring` reads as
/// `Ring`), and an expression listed in `known` (such as `PoissonConfig::default()`) is
/// replaced by the `{:?}` text given beside it.
pub fn assert_documented_defaults(
    source: &str,
    struct_name: &str,
    default_debug: &str,
    known: &[(&str, String)],
) {
    let documented = documented_defaults(source, struct_name);
    let actual = debug_fields(default_debug);
    let mut problems = Vec::new();
    if documented.is_empty() {
        problems.push(format!(
            "no `pub struct {struct_name}` with public fields found"
        ));
    }
    for (field, doc) in &documented {
        let Some(doc) = doc else {
            problems.push(format!("`{field}`: its doc has no \"Default: `...`\""));
            continue;
        };
        let Some((_, value)) = actual.iter().find(|(name, _)| name == field) else {
            problems.push(format!(
                "`{field}`: not in the Debug output {default_debug}"
            ));
            continue;
        };
        let mut expected = doc.clone();
        for (expr, debug) in known {
            expected = expected.replace(expr, debug);
        }
        if normalise(&expected) != normalise(value) {
            problems.push(format!(
                "`{field}`: documented `{doc}`, default is `{value}`"
            ));
        }
    }
    for (name, _) in &actual {
        if !documented.iter().any(|(field, _)| field == name) {
            problems.push(format!(
                "`{name}`: in the default but not found in the source"
            ));
        }
    }
    assert!(
        problems.is_empty(),
        "{struct_name}'s documented defaults:\n  {}",
        problems.join("\n  ")
    );
}

/// Each public field of `struct_name` with the "Default: `...`" of its doc comment.
fn documented_defaults(source: &str, struct_name: &str) -> Vec<(String, Option<String>)> {
    let header = format!("pub struct {struct_name} {{");
    let mut fields = Vec::new();
    let Some(start) = source.find(&header) else {
        return fields;
    };
    let mut doc = String::new();
    for line in source[start + header.len()..].lines() {
        let line = line.trim();
        if line == "}" {
            break;
        }
        if let Some(text) = line.strip_prefix("///") {
            doc.push(' ');
            doc.push_str(text.trim());
        } else if let Some(rest) = line.strip_prefix("pub ") {
            let name = rest.split(':').next().unwrap_or("").trim().to_string();
            fields.push((name, default_in(&doc)));
            doc.clear();
        } else if !line.starts_with("#[") {
            doc.clear();
        }
    }
    fields
}

/// The text between the backticks of "Default: `...`".
fn default_in(doc: &str) -> Option<String> {
    let rest = &doc[doc.find("Default: `")? + "Default: `".len()..];
    Some(rest[..rest.find('`')?].to_string())
}

/// The top-level `name: value` pairs of a struct's `{:?}` text.
fn debug_fields(debug: &str) -> Vec<(String, String)> {
    let (Some(open), Some(close)) = (debug.find('{'), debug.rfind('}')) else {
        return Vec::new();
    };
    let body = &debug[open + 1..close];
    let mut parts = Vec::new();
    let (mut depth, mut in_string, mut start) = (0i32, false, 0);
    for (i, c) in body.char_indices() {
        match c {
            '"' => in_string = !in_string,
            '{' | '[' | '(' if !in_string => depth += 1,
            '}' | ']' | ')' if !in_string => depth -= 1,
            ',' if depth == 0 && !in_string => {
                parts.push(&body[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&body[start..]);
    parts
        .into_iter()
        .filter_map(|p| {
            let (name, value) = p.split_once(':')?;
            Some((name.trim().to_string(), value.trim().to_string()))
        })
        .collect()
}

/// Drops digit separators, `Type::` paths and spaces.
fn normalise(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c == '_'
            && i > 0
            && chars[i - 1].is_ascii_digit()
            && chars.get(i + 1).is_some_and(|d| d.is_ascii_digit())
        {
            i += 1;
            continue;
        }
        if c == ':' && chars.get(i + 1) == Some(&':') {
            // Drop the path segment just written (`Layout::` of `Layout::Ring`).
            while out.ends_with(|p: char| p.is_alphanumeric() || p == '_') {
                out.pop();
            }
            i += 2;
            continue;
        }
        if !c.is_whitespace() {
            out.push(c);
        }
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE: &str = r#"
/// Example.
#[derive(Clone, Debug)]
pub struct ExampleConfig {
    /// Depth of the tree, 2 ..= 12. Default: `9`.
    pub depth: u32,
    /// Samples. Default: `200_000`
    /// (a second line).
    pub samples: usize,
    /// Layout. Default: `Layout::Ring`.
    pub layout: Layout,
    /// Nested. Default: `InnerConfig::default()`.
    pub inner: InnerConfig,
}
"#;

    #[allow(dead_code)] // read through Debug only
    #[derive(Debug)]
    enum Layout {
        Ring,
    }
    #[allow(dead_code)]
    #[derive(Debug, Default)]
    struct InnerConfig {
        k: usize,
    }
    #[allow(dead_code)]
    #[derive(Debug)]
    struct ExampleConfig {
        depth: u32,
        samples: usize,
        layout: Layout,
        inner: InnerConfig,
    }

    fn example(depth: u32) -> String {
        format!(
            "{:?}",
            ExampleConfig {
                depth,
                samples: 200_000,
                layout: Layout::Ring,
                inner: InnerConfig { k: 0 },
            }
        )
    }

    fn known() -> Vec<(&'static str, String)> {
        vec![(
            "InnerConfig::default()",
            format!("{:?}", InnerConfig::default()),
        )]
    }

    #[test]
    fn documented_defaults_that_match_pass() {
        assert_documented_defaults(SOURCE, "ExampleConfig", &example(9), &known());
    }

    #[test]
    #[should_panic(expected = "`depth`: documented `9`, default is `10`")]
    fn a_drifted_default_is_named() {
        assert_documented_defaults(SOURCE, "ExampleConfig", &example(10), &known());
    }

    #[test]
    #[should_panic(expected = "`samples`: its doc has no")]
    fn an_undocumented_default_is_named() {
        let source = SOURCE.replace("Default: `200_000`", "200 000 by default");
        assert_documented_defaults(&source, "ExampleConfig", &example(9), &known());
    }

    #[test]
    fn config_errors_name_the_field_and_the_range() {
        let e = require(false, "depth", 40, "in 2..=12").unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid configuration: `depth` is 40; it must be in 2..=12"
        );
        assert_eq!(
            e.within("poisson").to_string(),
            "invalid configuration: `poisson.depth` is 40; it must be in 2..=12"
        );
        assert!(require(true, "depth", 9, "in 2..=12").is_ok());
    }
}
