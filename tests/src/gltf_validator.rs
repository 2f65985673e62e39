//! The Khronos glTF validator, run through `tools/gltf-validate/validate.js` with Node.js.
//!
//! The validator is an npm package pinned by `tools/gltf-validate/package-lock.json`. `.ci/run`
//! installs it with `npm ci`; when a developer runs `cargo test` without that step, the first
//! validation installs it the same way, so that the README's test command works on a fresh
//! machine with Node.js. Without Node.js the tests fail with a message saying so: a GLB that
//! was not validated must not count as valid.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// What the validator said about one file.
#[derive(Clone, Debug)]
pub struct ValidatorReport {
    pub errors: u64,
    pub warnings: u64,
    pub infos: u64,
    /// The full JSON line (codes, severities, JSON pointers, messages), for failure messages.
    pub raw: String,
}

impl ValidatorReport {
    /// No errors and no warnings, the bar every GLB fresco writes must pass.
    pub fn is_clean(&self) -> bool {
        self.errors == 0 && self.warnings == 0
    }
}

fn tool_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("tools")
        .join("gltf-validate")
}

/// Installs the pinned validator once per test process if `node_modules` is missing.
fn ensure_installed() -> Result<(), String> {
    static INSTALLED: OnceLock<Result<(), String>> = OnceLock::new();
    INSTALLED
        .get_or_init(|| {
            let dir = tool_dir();
            if dir.join("node_modules").join("gltf-validator").is_dir() {
                return Ok(());
            }
            let status = Command::new("npm")
                .args(["ci", "--no-audit", "--no-fund", "--prefix"])
                .arg(&dir)
                .status()
                .map_err(|e| {
                    format!("cannot run npm to install the glTF validator ({e}); install Node.js")
                })?;
            if status.success() {
                Ok(())
            } else {
                Err(format!(
                    "`npm ci --prefix {}` failed ({status})",
                    dir.display()
                ))
            }
        })
        .clone()
}

/// Validates `glb` and returns the report; `Err` when the validator could not run at all.
pub fn validate(glb: &Path) -> Result<ValidatorReport, String> {
    ensure_installed()?;
    let output = Command::new("node")
        .arg(tool_dir().join("validate.js"))
        .arg(glb)
        .output()
        .map_err(|e| format!("cannot run node ({e}); install Node.js"))?;
    let stdout = String::from_utf8_lossy(&output.stdout).trim().to_string();
    let line = stdout.lines().last().unwrap_or_default().to_string();
    let json: serde_json::Value = serde_json::from_str(&line).map_err(|e| {
        format!(
            "validator output is not JSON ({e}): {stdout} {}",
            String::from_utf8_lossy(&output.stderr)
        )
    })?;
    let count = |k: &str| json.get(k).and_then(|v| v.as_u64()).unwrap_or(u64::MAX);
    Ok(ValidatorReport {
        errors: count("errors"),
        warnings: count("warnings"),
        infos: count("infos"),
        raw: line,
    })
}
