//! Headless-Chromium checks of what fresco shows people, through `tools/viewer/check.mjs`
//! (Debian's chromium driven by playwright-core, three.js from npm; both pinned by
//! `tools/viewer/package-lock.json`):
//!
//! - [`check_report`]: a `report.html` opens with no console or page error and its model
//!   viewer draws a canvas that is not blank;
//! - [`check_glb_in_three`]: a GLB loads in three.js's GLTFLoader and renders a canvas that is
//!   not blank.
//!
//! Screenshots are kept under `target/viewer/` (a CI artefact). `.ci/run` installs Chromium
//! and the npm packages; a developer without them gets the npm install done here and a clear
//! error naming what is missing. This file is also compiled into the CLI's tests (`#[path]`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// What a check found.
#[derive(Clone, Debug)]
pub struct ViewerCheck {
    pub ok: bool,
    /// Console errors, page errors, failed requests, time-outs.
    pub errors: Vec<String>,
    /// Fraction of the canvas's pixels that differ from the background.
    pub non_blank: f64,
    pub screenshot: PathBuf,
    /// The whole JSON line, for failure messages.
    pub raw: String,
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn tool_dir() -> PathBuf {
    repo().join("tools").join("viewer")
}

/// Where screenshots are kept: `target/viewer/` of the workspace (or CARGO_TARGET_DIR).
pub fn screenshot_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("target"));
    target.join("viewer")
}

fn ensure_installed() -> Result<(), String> {
    static INSTALLED: OnceLock<Result<(), String>> = OnceLock::new();
    INSTALLED
        .get_or_init(|| {
            let dir = tool_dir();
            if !dir.join("node_modules").join("playwright-core").is_dir()
                || !dir.join("node_modules").join("three").is_dir()
            {
                let status = Command::new("npm")
                    .args(["ci", "--no-audit", "--no-fund", "--prefix"])
                    .arg(&dir)
                    .status()
                    .map_err(|e| format!("cannot run npm ({e}); install Node.js"))?;
                if !status.success() {
                    return Err(format!("`npm ci --prefix {}` failed ({status})", dir.display()));
                }
            }
            let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
            if !Path::new(&chromium).exists() {
                return Err(format!(
                    "{chromium} is missing: install Debian's chromium package (`apt-get install chromium`, as .ci/run does)"
                ));
            }
            Ok(())
        })
        .clone()
}

fn check(mode: &str, file: &Path, name: &str) -> Result<ViewerCheck, String> {
    ensure_installed()?;
    let shot = screenshot_dir().join(format!("{name}.png"));
    let output = Command::new("node")
        .arg(tool_dir().join("check.mjs"))
        .arg(mode)
        .arg(file)
        .arg(&shot)
        .output()
        .map_err(|e| format!("cannot run node ({e}); install Node.js"))?;
    let stdout = String::from_utf8_lossy(&output.stdout).trim().to_string();
    let line = stdout.lines().last().unwrap_or_default().to_string();
    let json: serde_json::Value = serde_json::from_str(&line).map_err(|e| {
        format!(
            "check.mjs printed no JSON ({e}): {stdout} {}",
            String::from_utf8_lossy(&output.stderr)
        )
    })?;
    if output.status.code() == Some(2) {
        return Err(format!("the viewer check could not run: {line}"));
    }
    Ok(ViewerCheck {
        ok: json["ok"].as_bool().unwrap_or(false),
        errors: json["errors"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|e| e.as_str().unwrap_or("?").to_string())
                    .collect()
            })
            .unwrap_or_default(),
        non_blank: json["nonBlank"].as_f64().unwrap_or(0.0),
        screenshot: shot,
        raw: line,
    })
}

/// Opens `report` (a report.html) and checks its viewer; the screenshot is
/// `target/viewer/<name>.png`.
pub fn check_report(report: &Path, name: &str) -> Result<ViewerCheck, String> {
    check("report", report, name)
}

/// Loads `glb` in three.js and checks the render; the screenshot is `target/viewer/<name>.png`.
pub fn check_glb_in_three(glb: &Path, name: &str) -> Result<ViewerCheck, String> {
    check("three", glb, name)
}
