//! Every verb of `fresco`, run into one representative failure, exits non-zero with one
//! `error:` line that says each thing once (issue 20): no phrase, no run of four words and no
//! path given on the command line appears twice. (Errors that show their inner error and also
//! expose it as `source` print it twice under anyhow's `{:#}`: "Poisson reconstruction: all
//! points coincide: the point cloud has no extent: all points coincide: ...".)
//! Also: `fresco --help` lists the verbs in pipeline order.

use std::path::Path;
use std::process::{Command, Output};

/// The verbs in the order `fresco --help` lists them: the photo pipeline, then the tools.
/// A new verb takes its place here and a failure case in `failure_case`.
const PIPELINE_ORDER: &[&str] = &[
    "run",
    "features",
    "match",
    "sfm",
    "reconstruct",
    "dense",
    "mesh",
    "unwrap",
    "texture",
    "eval",
    "view",
    "pst",
    "sprites",
    "geotex",
    "synth",
];

fn fresco(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fresco"))
        .args(args)
        .output()
        .expect("fresco runs")
}

/// The verbs of `fresco --help`, in its order.
fn verbs_in_help() -> Vec<String> {
    let out = fresco(&["--help"]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    text.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|v| v != "help")
        .collect()
}

#[test]
fn help_lists_the_verbs_in_pipeline_order() {
    let verbs = verbs_in_help();
    assert!(verbs.len() >= 9, "{verbs:?}");
    let rank = |v: &String| {
        PIPELINE_ORDER
            .iter()
            .position(|p| p == v)
            .unwrap_or_else(|| panic!("verb `{v}` has no place in PIPELINE_ORDER"))
    };
    let ranks: Vec<usize> = verbs.iter().map(rank).collect();
    assert!(
        ranks.windows(2).all(|w| w[0] < w[1]),
        "fresco --help lists {verbs:?}, not in pipeline order {PIPELINE_ORDER:?}"
    );
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

/// An ASCII PLY of `n` vertices `x y z nx ny nz` (all the same point) and no faces.
fn identical_points(path: &Path, n: usize) {
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
         property float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n"
    );
    for _ in 0..n {
        text.push_str("1 2 3 0 0 1\n");
    }
    write(path, &text);
}

/// The arguments that run `verb` into a typical failure, with the files they need made in
/// `dir`; `None` for a verb without a case.
fn failure_case(verb: &str, dir: &Path) -> Option<Vec<String>> {
    let p = |name: &str| dir.join(name).to_string_lossy().into_owned();
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let ws = dir.join("ws");
    std::fs::create_dir_all(&ws).unwrap();
    let args: Vec<String> = match verb {
        // A folder with no photo.
        "features" => vec!["features".into(), p("empty"), "-o".into(), p("out")],
        "reconstruct" => vec!["reconstruct".into(), p("empty"), "-o".into(), p("out")],
        // A workspace without images.json.
        "match" => vec!["match".into(), p("ws")],
        "sfm" => vec!["sfm".into(), p("ws")],
        // A folder that is no model.
        "eval" => vec![
            "eval".into(),
            "poses".into(),
            p("ws"),
            "--gt".into(),
            p("gt.txt"),
        ],
        // The case: 12 identical oriented points.
        "mesh" => {
            identical_points(&dir.join("same.ply"), 12);
            vec!["mesh".into(), p("ws"), "--points".into(), p("same.ply")]
        }
        // A mesh without faces.
        "unwrap" => {
            identical_points(&dir.join("points.ply"), 3);
            vec![
                "unwrap".into(),
                p("points.ply"),
                "-o".into(),
                p("charts.ply"),
            ]
        }
        // A configuration value out of range.
        "pst" => {
            identical_points(&dir.join("cloud.ply"), 12);
            vec![
                "pst".into(),
                "sample".into(),
                p("cloud.ply"),
                "-n".into(),
                "0".into(),
                "-o".into(),
                p("cloud.pst"),
            ]
        }
        "synth" => vec![
            "synth".into(),
            "torus".into(),
            "-o".into(),
            p("synth"),
            "--views".into(),
            "0".into(),
        ],
        // A folder with no photo.
        "run" => vec!["run".into(), p("empty"), "-o".into(), p("out")],
        // A workspace without images.json or a sparse model.
        "dense" => vec!["dense".into(), p("ws")],
        "texture" => vec!["texture".into(), p("ws")],
        // A model that does not exist (fails before any server starts).
        "view" => vec!["view".into(), p("missing.glb")],
        // A scene file that does not exist.
        "sprites" => {
            identical_points(&dir.join("points.ply"), 3);
            vec![
                "sprites".into(),
                "render".into(),
                p("points.ply"),
                p("missing.json"),
                "-o".into(),
                p("out.png"),
            ]
        }
        _ => return None,
    };
    Some(args)
}

/// What the message says twice, if anything: a `: `-separated phrase of two words or more,
/// a run of four words, or one of the paths given on the command line.
fn said_twice(message: &str, paths: &[String]) -> Option<String> {
    let phrases: Vec<&str> = message.split(": ").map(str::trim).collect();
    for (i, a) in phrases.iter().enumerate() {
        if a.split_whitespace().count() >= 2 && phrases[i + 1..].contains(a) {
            return Some(format!("the phrase `{a}`"));
        }
    }
    let words: Vec<String> = message
        .split_whitespace()
        .map(|w| {
            w.trim_matches(|c: char| !c.is_alphanumeric())
                .to_lowercase()
        })
        .collect();
    for i in 0..words.len().saturating_sub(3) {
        let run = &words[i..i + 4];
        if words[i + 1..].windows(4).any(|w| w == run) {
            return Some(format!("the words `{}`", run.join(" ")));
        }
    }
    for path in paths {
        if message.matches(path.as_str()).count() > 1 {
            return Some(format!("the path {path}"));
        }
    }
    None
}

#[test]
fn said_twice_finds_the_repetitions_it_is_meant_to() {
    let paths = vec!["/tmp/a/ws".to_string()];
    assert!(said_twice("reading /tmp/a/ws: no such folder", &paths).is_none());
    assert!(
        said_twice(
            "Poisson reconstruction: all points coincide: the point cloud has no extent: all \
             points coincide: the point cloud has no extent",
            &paths
        )
        .is_some()
    );
    assert!(
        said_twice(
            "reading workspace /tmp/a/ws: /tmp/a/ws/images.json: missing",
            &paths
        )
        .is_some()
    );
    assert!(said_twice("a b c d then a b c d", &paths).is_some());
}

#[test]
fn every_verb_fails_with_a_message_that_says_each_thing_once() {
    let mut problems = Vec::new();
    for verb in verbs_in_help() {
        let dir = tempfile::tempdir().unwrap();
        let Some(args) = failure_case(&verb, dir.path()) else {
            problems.push(format!(
                "`{verb}` has no failure case in cli/tests/error_messages.rs: add one"
            ));
            continue;
        };
        let arg_refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = fresco(&arg_refs);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        let Some(message) = stderr.lines().find_map(|l| l.strip_prefix("error: ")) else {
            problems.push(format!("`{verb}`: no `error:` line in {stderr:?}"));
            continue;
        };
        // A usage error (exit 2) would mean the case never reached the library.
        if out.status.code() != Some(1) {
            problems.push(format!(
                "`{verb}`: exit {:?} for {message}",
                out.status.code()
            ));
        }
        if stderr.contains("panicked") {
            problems.push(format!("`{verb}` panicked: {stderr}"));
        }
        let paths: Vec<String> = args
            .iter()
            .filter(|a| a.starts_with('/'))
            .cloned()
            .collect();
        if let Some(what) = said_twice(message, &paths) {
            problems.push(format!("`{verb}` says {what} twice: {message}"));
        }
        eprintln!("{verb}: {message}");
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
