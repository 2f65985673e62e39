//! What the `fresco run` tests share: running the binary, checksums of a folder, the temple
//! photos.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn fresco() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fresco"))
}

pub fn run(args: &[&str]) -> Output {
    fresco().args(args).output().expect("fresco runs")
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// No panic message on stderr.
pub fn assert_no_panic(out: &Output) {
    let err = stderr(out);
    assert!(!err.contains("panicked"), "{err}");
}

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

pub fn temple() -> PathBuf {
    repo().join("datasets").join("templeSparseRing")
}

/// Every file under `dir` (relative path) with its bytes: what "untouched" is checked against.
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

/// Copies the temple photos into `dir`.
pub fn copy_temple(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    for e in std::fs::read_dir(temple()).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "png") {
            std::fs::copy(&p, dir.join(p.file_name().unwrap())).unwrap();
        }
    }
}

pub fn summary(ws: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(ws.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).unwrap()
}

/// Status of each stage in `<ws>/summary.json`, in order.
pub fn statuses(ws: &Path) -> Vec<(String, String)> {
    summary(ws)["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["name"].as_str().unwrap().to_string(),
                s["status"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}
