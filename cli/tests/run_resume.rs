//! `fresco run` is resumable (issue 15): a run killed (SIGKILL) in three different stages and
//! started again each time ends with the same bytes in every output as a run that was never
//! interrupted, skipping the stages that were complete; moved elsewhere, the workspace still
//! resumes. Then a changed setting re-runs only the stages it reaches, and `--from` re-runs
//! from the stage it names.
//!
//! The runs use one thread, so that what is checked is what the runner adds (records,
//! skipping, temporaries), not each stage's independence of the thread count, which the
//! stages' own tests check.

mod common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Stdio;

use common::*;

/// Every output of a workspace (stage records, summaries and report left out: they hold
/// times).
fn outputs(ws: &Path) -> std::collections::BTreeMap<std::path::PathBuf, Vec<u8>> {
    snapshot(ws)
        .into_iter()
        .filter(|(p, _)| {
            let s = p.to_string_lossy();
            !(s.starts_with("stages")
                || s == "summary.json"
                || s == "report.html"
                || s == "dense/summary.json")
        })
        .collect()
}

/// `fresco --threads 1 run <photos> -o <ws> --quality draft <extra>`, to its end.
fn run_draft(photos: &Path, ws: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["--threads", "1", "run", photos.to_str().unwrap()];
    args.extend(["-o", ws.to_str().unwrap(), "--quality", "draft"]);
    args.extend(extra);
    run(&args)
}

/// Starts a run and kills it (SIGKILL) once stage `stage` has started and shown progress;
/// returns whether it was killed there (false: the run ended first).
fn kill_in(photos: &Path, ws: &Path, stage: &str) -> bool {
    let mut child = fresco()
        .args(["--threads", "1", "run", photos.to_str().unwrap()])
        .args(["-o", ws.to_str().unwrap(), "--quality", "draft"])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let err = child.stderr.take().unwrap();
    let mut in_stage = false;
    let mut killed = false;
    for line in BufReader::new(err).lines() {
        let line = line.unwrap();
        // "[4/6] mesh: surface: ... (reason)" starts the stage; its task lines follow.
        if line.starts_with('[') && line.contains(&format!("] {stage}: ")) && line.ends_with(')') {
            in_stage = true;
        } else if in_stage && line.starts_with("  ") {
            child.kill().unwrap();
            killed = true;
            break;
        }
    }
    child.wait().unwrap();
    killed
}

#[test]
fn killed_in_three_stages_and_resumed_gives_the_same_bytes_as_one_run() {
    // A small synthetic set keeps the runs (two whole dense stages among them) short.
    let dir = tempfile::tempdir().unwrap();
    let syn = dir.path().join("syn");
    let out = run(&[
        "--quiet",
        "synth",
        "temple",
        "--views",
        "12",
        "--size",
        "320x240",
        "-o",
        syn.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let photos = syn.join("images");
    let whole = dir.path().join("whole");
    let out = run_draft(&photos, &whole, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let reference = outputs(&whole);
    assert!(reference.contains_key(Path::new("model.glb")));

    let ws = dir.path().join("resumed");
    for stage in ["match", "dense", "texture"] {
        assert!(kill_in(&photos, &ws, stage), "the run ended before {stage}");
        assert!(
            !ws.join("stages").join(format!("{stage}.json")).exists(),
            "a killed stage has no record"
        );
    }
    let out = run_draft(&photos, &ws, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    // Only the stage killed last (and those after it) ran in the final run.
    let st = statuses(&ws);
    let ran: Vec<&str> = st
        .iter()
        .filter(|(_, s)| s == "ran")
        .map(|(n, _)| n.as_str())
        .collect();
    assert_eq!(ran, ["texture"], "{st:?}");
    let resumed = outputs(&ws);
    assert_eq!(
        resumed.keys().collect::<Vec<_>>(),
        reference.keys().collect::<Vec<_>>()
    );
    let differ: Vec<_> = reference
        .iter()
        .filter(|(path, bytes)| resumed[*path] != **bytes)
        .map(|(path, _)| path.display().to_string())
        .collect();
    if !differ.is_empty() {
        let kept = dir.keep();
        panic!("{differ:?} differ (workspaces kept in {})", kept.display());
    }

    // Nothing changed: everything is skipped.
    let out = run_draft(&photos, &ws, &[]);
    assert!(out.status.success());
    assert!(
        statuses(&ws).iter().all(|(_, s)| s == "skipped"),
        "{:?}",
        statuses(&ws)
    );
    // A workspace moved as a whole still resumes: its records write paths inside it `<ws>/..`.
    let moved = dir.path().join("moved");
    std::fs::rename(&ws, &moved).unwrap();
    let out = run_draft(&photos, &moved, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        statuses(&moved).iter().all(|(_, s)| s == "skipped"),
        "{:?}",
        statuses(&moved)
    );
    std::fs::rename(&moved, &ws).unwrap();
    // A changed output is noticed and remade.
    std::fs::write(ws.join("model.glb"), b"damaged").unwrap();
    let out = run_draft(&photos, &ws, &[]);
    assert!(out.status.success());
    assert_eq!(
        std::fs::read(ws.join("model.glb")).unwrap(),
        reference[Path::new("model.glb")]
    );
    // --from re-runs from that stage on.
    let out = run_draft(&photos, &ws, &["--from", "unwrap"]);
    assert!(out.status.success());
    let st = statuses(&ws);
    assert_eq!(st[5], ("unwrap".to_string(), "ran".to_string()), "{st:?}");
    assert_eq!(st[6], ("texture".to_string(), "ran".to_string()), "{st:?}");
    assert_eq!(st[4], ("mesh".to_string(), "skipped".to_string()), "{st:?}");
}
