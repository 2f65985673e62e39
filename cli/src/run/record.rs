//! What a stage of `fresco run` was run with, kept next to its outputs in
//! `<ws>/stages/<stage>.json`, and the fingerprints that decide whether it must run again.
//!
//! A stage is skipped when its record exists and says: the same fresco (package version and a
//! fingerprint of the executable, so that a rebuilt fresco re-runs everything), the same
//! settings (every field of the stage's parsed arguments, defaults included), the same
//! fingerprints of its inputs as they are now, and outputs whose fingerprints are still the
//! ones it wrote. The record is written last, atomically, and removed before the stage starts:
//! a stage killed half way has no record and runs again from the start.
//!
//! Paths inside the workspace are recorded relative to it (`<ws>/dense`), so a workspace that
//! is moved or renamed as a whole still resumes.
//!
//! A fingerprint is a 128-bit hash of a file's bytes (two SplitMix64-mixed lanes over 8-byte
//! words, `fresco_core::rng::splitmix64`), or of a folder's files with their relative names,
//! in name order. Hidden entries (names starting with `.`: temporaries of atomic writes) are
//! not part of a folder. It detects change, not tampering.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use fresco_core::rng::splitmix64;
use serde::{Deserialize, Serialize};

/// Version of the record layout.
pub const RECORD_VERSION: u32 = 1;

/// What a stage ran with and what it wrote.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    pub version: u32,
    pub stage: String,
    pub fresco_version: String,
    /// Fingerprint of the fresco executable that ran the stage.
    pub fresco_build: String,
    /// Every setting of the stage, as its parsed arguments print.
    pub settings: String,
    /// Fingerprint of each input (path as given to the stage, `<ws>` for the workspace folder
    /// -> hash, "missing" if absent).
    pub inputs: BTreeMap<String, String>,
    /// Fingerprint of each output.
    pub outputs: BTreeMap<String, String>,
    pub seconds: f64,
    /// Peak resident memory during the stage, bytes (None where the system does not say).
    pub peak_memory_bytes: Option<u64>,
    /// The stage's own summary.
    pub summary: serde_json::Value,
}

/// Why a record does not allow skipping its stage, or `None` when it does.
pub fn mismatch(
    record: &StageRecord,
    fresco_build: &str,
    settings: &str,
    inputs: &BTreeMap<String, String>,
    outputs: &BTreeMap<String, String>,
) -> Option<String> {
    if record.version != RECORD_VERSION {
        return Some(format!("record version {}", record.version));
    }
    if record.fresco_version != env!("CARGO_PKG_VERSION") || record.fresco_build != fresco_build {
        return Some("another build of fresco ran it".into());
    }
    if record.settings != settings {
        return Some("its settings changed".into());
    }
    if let Some((path, _)) = inputs
        .iter()
        .find(|(k, v)| record.inputs.get(*k) != Some(*v))
    {
        return Some(format!("input {path} changed"));
    }
    if record.inputs.len() != inputs.len() {
        return Some("its inputs changed".into());
    }
    if let Some((path, _)) = outputs
        .iter()
        .find(|(k, v)| record.outputs.get(*k) != Some(*v))
    {
        return Some(format!("output {path} is missing or changed"));
    }
    None
}

/// Path of the record of `stage` in workspace `ws`.
pub fn record_path(ws: &Path, stage: &str) -> PathBuf {
    ws.join("stages").join(format!("{stage}.json"))
}

/// The record of `stage`, if there is a readable one.
pub fn read_record(ws: &Path, stage: &str) -> Option<StageRecord> {
    let text = std::fs::read_to_string(record_path(ws, stage)).ok()?;
    serde_json::from_str(&text).ok()
}

/// Writes the record atomically.
pub fn write_record(ws: &Path, record: &StageRecord) -> anyhow::Result<()> {
    let path = record_path(ws, &record.stage);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let text = serde_json::to_string_pretty(record)?;
    fresco_core::atomic_file::write_bytes_atomically(&path, text.as_bytes())?;
    Ok(())
}

/// Removes the record of `stage` (before the stage runs again).
pub fn remove_record(ws: &Path, stage: &str) -> anyhow::Result<()> {
    let path = record_path(ws, stage);
    match std::fs::remove_file(&path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("removing {}", path.display())),
    }
}

/// A running 128-bit hash.
#[derive(Clone, Copy)]
struct Hasher {
    a: u64,
    b: u64,
}

impl Hasher {
    fn new() -> Hasher {
        Hasher {
            a: 0x6a09_e667_f3bc_c908,
            b: 0xbb67_ae85_84ca_a73b,
        }
    }
    fn word(&mut self, w: u64) {
        self.a = splitmix64(self.a ^ w);
        self.b = splitmix64(self.b.wrapping_add(w).rotate_left(23));
    }
    fn bytes(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            self.word(u64::from_le_bytes(c.try_into().unwrap_or_default()));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut last = [0u8; 8];
            last[..rest.len()].copy_from_slice(rest);
            self.word(u64::from_le_bytes(last));
        }
    }
    fn hex(&self) -> String {
        format!("{:016x}{:016x}", self.a, self.b)
    }
}

/// Hashes one file's length and bytes into `h`, reading 1 MiB at a time.
fn hash_file(h: &mut Hasher, path: &Path) -> std::io::Result<()> {
    let mut file = std::fs::File::open(path)?;
    let len = file.metadata()?.len();
    h.word(len);
    // A multiple of 8 so that words never straddle two reads.
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let mut filled = 0;
        while filled < buf.len() {
            let n = file.read(&mut buf[filled..])?;
            if n == 0 {
                break;
            }
            filled += n;
        }
        h.bytes(&buf[..filled]);
        if filled < buf.len() {
            return Ok(());
        }
    }
}

/// The files under `dir` (recursively, hidden entries left out), sorted, relative to `dir`.
pub fn folder_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        for entry in std::fs::read_dir(dir.join(&rel))? {
            let entry = entry?;
            let name = entry.file_name();
            if name.to_string_lossy().starts_with('.') {
                continue;
            }
            let child = rel.join(&name);
            if entry.file_type()?.is_dir() {
                stack.push(child);
            } else {
                out.push(child);
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Fingerprint of a file or a folder, or "missing".
pub fn fingerprint(path: &Path) -> anyhow::Result<String> {
    let mut h = Hasher::new();
    if path.is_dir() {
        let files = folder_files(path).with_context(|| format!("listing {}", path.display()))?;
        for rel in files {
            h.bytes(rel.to_string_lossy().as_bytes());
            h.word(0xff);
            hash_file(&mut h, &path.join(&rel))
                .with_context(|| format!("reading {}", path.join(&rel).display()))?;
        }
        Ok(format!("dir:{}", h.hex()))
    } else if path.is_file() {
        hash_file(&mut h, path).with_context(|| format!("reading {}", path.display()))?;
        Ok(h.hex())
    } else {
        Ok("missing".into())
    }
}

/// Fingerprints of several paths, keyed by their display form with the workspace folder
/// written `<ws>` (see [`portable`]).
pub fn fingerprints(paths: &[PathBuf], ws: &Path) -> anyhow::Result<BTreeMap<String, String>> {
    paths
        .iter()
        .map(|p| Ok((portable(&p.display().to_string(), ws), fingerprint(p)?)))
        .collect()
}

/// `text` (a path or a stage's settings) with every occurrence of the workspace folder
/// written `<ws>`, so that a workspace moved or renamed as a whole keeps records that match:
/// what a stage reads and writes inside the workspace is the same wherever the folder is.
/// Paths outside it (the photos, --mesh, --colmap) stay absolute: moving those is a change.
pub fn portable(text: &str, ws: &Path) -> String {
    text.replace(&ws.display().to_string(), "<ws>")
}

/// Fingerprint of the running fresco executable ("unknown" if it cannot be read).
pub fn fresco_build() -> String {
    std::env::current_exe()
        .ok()
        .and_then(|exe| fingerprint(&exe).ok())
        .unwrap_or_else(|| "unknown".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fingerprint_changes_with_any_byte_and_with_the_length() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a");
        let mut bytes: Vec<u8> = (0..3_000_000u32).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(&a, &bytes).unwrap();
        let f0 = fingerprint(&a).unwrap();
        assert_eq!(f0, fingerprint(&a).unwrap());
        // One byte in the second 1 MiB read.
        bytes[1_500_001] ^= 1;
        std::fs::write(&a, &bytes).unwrap();
        let f1 = fingerprint(&a).unwrap();
        assert_ne!(f0, f1);
        // A trailing zero byte: same words, another length.
        bytes.push(0);
        std::fs::write(&a, &bytes).unwrap();
        assert_ne!(f1, fingerprint(&a).unwrap());
        assert_eq!(fingerprint(&dir.path().join("none")).unwrap(), "missing");
    }

    #[test]
    fn a_folder_fingerprint_sees_names_and_contents_but_not_hidden_files() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("d");
        std::fs::create_dir_all(d.join("sub")).unwrap();
        std::fs::write(d.join("x"), b"1").unwrap();
        std::fs::write(d.join("sub").join("y"), b"2").unwrap();
        let f0 = fingerprint(&d).unwrap();
        std::fs::write(d.join(".x.tmp-1-0"), b"half").unwrap();
        assert_eq!(f0, fingerprint(&d).unwrap());
        std::fs::rename(d.join("x"), d.join("z")).unwrap();
        assert_ne!(f0, fingerprint(&d).unwrap());
    }

    #[test]
    fn a_record_matches_only_with_the_same_build_settings_inputs_and_outputs() {
        let inputs: BTreeMap<String, String> = [("in".to_string(), "1".to_string())].into();
        let outputs: BTreeMap<String, String> = [("out".to_string(), "2".to_string())].into();
        let record = StageRecord {
            version: RECORD_VERSION,
            stage: "s".into(),
            fresco_version: env!("CARGO_PKG_VERSION").into(),
            fresco_build: "b".into(),
            settings: "x".into(),
            inputs: inputs.clone(),
            outputs: outputs.clone(),
            seconds: 1.0,
            peak_memory_bytes: None,
            summary: serde_json::Value::Null,
        };
        assert_eq!(mismatch(&record, "b", "x", &inputs, &outputs), None);
        assert!(mismatch(&record, "c", "x", &inputs, &outputs).is_some());
        assert!(mismatch(&record, "b", "y", &inputs, &outputs).is_some());
        let other: BTreeMap<String, String> = [("in".to_string(), "3".to_string())].into();
        assert!(mismatch(&record, "b", "x", &other, &outputs).is_some());
        let gone: BTreeMap<String, String> = [("out".to_string(), "missing".to_string())].into();
        assert!(mismatch(&record, "b", "x", &inputs, &gone).is_some());
    }
}
