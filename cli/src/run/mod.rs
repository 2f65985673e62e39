//! `fresco run <photos> -o <ws>`: the whole chain from photos to `<ws>/model.glb`, resumable,
//! with `<ws>/summary.json` and `<ws>/report.html`.
//!
//! - `stages.rs`: the stage table (inputs, outputs, arguments, the call that runs each);
//! - `record.rs`: per-stage records and fingerprints, which decide what is skipped;
//! - `quality.rs`: the `--quality` presets;
//! - `holdout.rs`: the held-out photos' comparison with the textured model;
//! - `inputs.rs`: checks of what the user gave, `--colmap` and `--mesh` imports;
//! - `memory.rs`: peak memory per stage.
//!
//! The runner: check the inputs (nothing written before they pass), remove temporaries of an
//! interrupted run, then for each stage: skip it if its record matches, otherwise remove the
//! record, run it, fingerprint its outputs and write the record. Stages from `--from` on, or
//! all with `--force`, run whatever their records say. Every output is written atomically,
//! so a run killed at any moment and started again gives the same bytes as one that was not.
//! At the end (or at a failure) the summary and the report are written.

pub mod holdout;
pub mod inputs;
pub mod memory;
pub mod quality;
pub mod record;
pub mod stages;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use clap::Args;
use serde::Serialize;

use crate::progress;
use quality::Quality;
use stages::Stage;

#[derive(Args, Debug)]
pub struct RunArgs {
    /// Folder of photos (*.png, *.jpg, *.jpeg; other files are ignored). Never written to.
    pub photos: PathBuf,
    /// Workspace folder (created; must be new, empty or an earlier `fresco run` workspace):
    /// model.glb, report.html, summary.json and every stage's outputs.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Preset of every stage's settings: draft (a first look in under a minute), normal,
    /// high. See `fresco run --help` and the module documentation of run/quality.rs.
    #[arg(long, value_enum, default_value_t = Quality::default())]
    pub quality: Quality,
    /// Run again from this stage on, whatever the records say (features, match, sfm, import,
    /// dense, mesh, import-mesh, unwrap, texture, holdout).
    #[arg(long)]
    pub from: Option<String>,
    /// Run every stage again.
    #[arg(long)]
    pub force: bool,
    /// Start from an existing COLMAP sparse model (folder with cameras, images, points3D as
    /// .txt or .bin) whose images are in the photo folder, instead of features, match, sfm.
    #[arg(long)]
    pub colmap: Option<PathBuf>,
    /// Texture this mesh (.ply or .obj, in the frame of the cameras) instead of making one.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Folder of object masks (<photo name>.png or <stem>.png, 0 = background), used by sfm's
    /// silhouette constraints, dense, texture and the held-out comparison.
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Photos used for the cameras but kept out of dense and texture, to measure the textured
    /// model against them (comma-separated names, e.g. a.png,b.png): summary.json's
    /// `holdout` has the PSNR per photo, raw and gain-fitted.
    #[arg(long, value_delimiter = ',')]
    pub holdout: Vec<String>,
    /// Calibration matrix (3x3, K.txt) shared by all photos; overrides EXIF.
    #[arg(long)]
    pub focal_file: Option<PathBuf>,
}

/// What the stages work from, checked and made canonical.
#[derive(Clone, Debug)]
pub struct Plan {
    pub photos: PathBuf,
    pub ws: PathBuf,
    pub quality: Quality,
    pub colmap: Option<PathBuf>,
    pub mesh: Option<PathBuf>,
    pub masks: Option<PathBuf>,
    pub holdout: Vec<String>,
    pub focal_file: Option<PathBuf>,
}

/// What happened to one stage in this run.
#[derive(Clone, Debug, Serialize)]
pub struct StageOutcome {
    pub name: String,
    pub does: String,
    /// "ran", "skipped" (record matched), "failed", "not run" (an earlier stage failed).
    pub status: String,
    /// Why it ran (no record, what changed, --from, --force).
    pub reason: Option<String>,
    /// Seconds in this run (for a skipped stage: of the run that made its outputs).
    pub seconds: f64,
    pub peak_memory_bytes: Option<u64>,
    /// The peak could not be reset before the stage: it is the process's peak so far.
    pub peak_memory_since_start: bool,
    pub stand_in: Option<String>,
    pub summary: serde_json::Value,
}

/// `<ws>/summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub fresco_version: String,
    pub photos: PathBuf,
    pub workspace: PathBuf,
    pub quality: Quality,
    pub holdout: Vec<String>,
    /// With --holdout: the model against each held-out photo (PSNR, SSIM raw and
    /// gain-fitted, the side-by-side picture), from the holdout stage.
    pub held_out_comparison: Option<serde_json::Value>,
    pub model: Option<PathBuf>,
    pub report: Option<PathBuf>,
    /// Set when the run stopped at a stage: the stage and the error.
    pub error: Option<String>,
    /// What is not the real thing yet (stand-in stages), and other things to know.
    pub warnings: Vec<String>,
    pub stages: Vec<StageOutcome>,
    pub seconds_total: f64,
}

fn check(args: &RunArgs) -> anyhow::Result<Plan> {
    let photos = inputs::check_photos(&args.photos)?;
    let colmap = inputs::check_path("--colmap", args.colmap.as_deref(), true)?;
    let mesh = inputs::check_path("--mesh", args.mesh.as_deref(), false)?;
    let masks = inputs::check_path("--masks", args.masks.as_deref(), true)?;
    let focal_file = inputs::check_path("--focal-file", args.focal_file.as_deref(), false)?;
    let holdout = inputs::check_holdout(&args.holdout, &photos)?;
    if let Some(from) = &args.from
        && !stages::NAMES.contains(&from.as_str())
    {
        bail!(
            "--from {from}: no such stage; the stages are {}",
            stages::NAMES.join(", ")
        );
    }
    let ws = inputs::prepare_workspace(&args.output, &photos)?;
    Ok(Plan {
        photos,
        ws,
        quality: args.quality,
        colmap,
        mesh,
        masks,
        holdout,
        focal_file,
    })
}

/// Whether `stage` must run and why, or `None` when its record lets it be skipped.
fn why_run(
    stage: &Stage,
    plan: &Plan,
    forced: Option<&str>,
    build: &str,
    settings: &str,
) -> anyhow::Result<Option<String>> {
    if let Some(reason) = forced {
        return Ok(Some(reason.to_string()));
    }
    let Some(rec) = record::read_record(&plan.ws, stage.name) else {
        return Ok(Some("not run before".into()));
    };
    let inputs = record::fingerprints(&(stage.inputs)(plan)?, &plan.ws)?;
    let outputs = record::fingerprints(&(stage.outputs)(plan), &plan.ws)?;
    Ok(record::mismatch(&rec, build, settings, &inputs, &outputs))
}

/// Runs one stage and records it.
fn execute(
    stage: &Stage,
    plan: &Plan,
    argv: &[String],
    settings: String,
    build: &str,
    ctx: &crate::Context,
) -> anyhow::Result<record::StageRecord> {
    record::remove_record(&plan.ws, stage.name)?;
    let inputs = record::fingerprints(&(stage.inputs)(plan)?, &plan.ws)?;
    let meter = memory::Meter::start();
    let t0 = Instant::now();
    let summary = (stage.execute)(plan, argv, ctx)?;
    let seconds = t0.elapsed().as_secs_f64();
    let peak = meter.stop();
    let outputs = record::fingerprints(&(stage.outputs)(plan), &plan.ws)?;
    if let Some((path, _)) = outputs.iter().find(|(_, f)| *f == "missing") {
        bail!("internal: the stage did not write {path}");
    }
    let rec = record::StageRecord {
        version: record::RECORD_VERSION,
        stage: stage.name.to_string(),
        fresco_version: env!("CARGO_PKG_VERSION").to_string(),
        fresco_build: build.to_string(),
        settings,
        inputs,
        outputs,
        seconds,
        peak_memory_bytes: peak.map(|p| p.bytes),
        summary: serde_json::json!({
            "peak_memory_since_start": peak.is_some_and(|p| p.since_start),
            "stage": summary,
        }),
    };
    record::write_record(&plan.ws, &rec)?;
    Ok(rec)
}

fn outcome(
    stage: &Stage,
    status: &str,
    reason: Option<String>,
    rec: Option<&record::StageRecord>,
) -> StageOutcome {
    StageOutcome {
        name: stage.name.to_string(),
        does: stage.does.to_string(),
        status: status.to_string(),
        reason,
        seconds: rec.map_or(0.0, |r| r.seconds),
        peak_memory_bytes: rec.and_then(|r| r.peak_memory_bytes),
        peak_memory_since_start: rec
            .and_then(|r| r.summary["peak_memory_since_start"].as_bool())
            .unwrap_or(false),
        stand_in: stage.stand_in.map(str::to_string),
        summary: rec.map_or(serde_json::Value::Null, |r| r.summary["stage"].clone()),
    }
}

fn megabytes(bytes: Option<u64>) -> String {
    bytes.map_or_else(|| "? MB".into(), |b| format!("{:.0} MB", b as f64 / 1e6))
}

/// Runs the chain; returns the summary and the first error, if any.
fn run_chain(
    plan: &Plan,
    args: &RunArgs,
    ctx: &crate::Context,
) -> (Vec<StageOutcome>, Option<anyhow::Error>) {
    let chain = stages::chain(plan);
    let build = record::fresco_build();
    let outputs: Vec<PathBuf> = chain.iter().flat_map(|s| (s.outputs)(plan)).collect();
    inputs::remove_temporaries(&plan.ws, &outputs);
    let from_index = args
        .from
        .as_deref()
        .and_then(|f| chain.iter().position(|s| s.name == f));
    if let Some(from) = &args.from
        && from_index.is_none()
    {
        let names: Vec<&str> = chain.iter().map(|s| s.name).collect();
        return (
            Vec::new(),
            Some(anyhow::anyhow!(
                "--from {from}: this run's stages are {}",
                names.join(", ")
            )),
        );
    }
    let mut done = Vec::new();
    let n = chain.len();
    for (i, stage) in chain.iter().enumerate() {
        let head = format!("[{}/{n}] {}", i + 1, stage.name);
        progress::set_stage(Some(stage.name));
        let forced = if args.force {
            Some("--force")
        } else if from_index.is_some_and(|f| i >= f) {
            Some("--from")
        } else {
            None
        };
        let argv = (stage.argv)(plan);
        let result = (stage.settings)(&argv).and_then(|settings| {
            let settings = record::portable(&settings, &plan.ws);
            match why_run(stage, plan, forced, &build, &settings)? {
                None => Ok((None, settings)),
                Some(reason) => Ok((Some(reason), settings)),
            }
        });
        let (reason, settings) = match result {
            Ok(r) => r,
            Err(e) => {
                done.push(outcome(stage, "failed", None, None));
                return (done, Some(e.context(format!("stage {}", stage.name))));
            }
        };
        match reason {
            None => {
                let rec = record::read_record(&plan.ws, stage.name);
                progress::stage_line(
                    ctx,
                    &format!(
                        "{head}: up to date, skipped (it took {:.1} s)",
                        rec.as_ref().map_or(0.0, |r| r.seconds)
                    ),
                );
                done.push(outcome(stage, "skipped", None, rec.as_ref()));
            }
            Some(reason) => {
                progress::stage_line(ctx, &format!("{head}: {} ({reason})", stage.does));
                match execute(stage, plan, &argv, settings, &build, ctx) {
                    Ok(rec) => {
                        progress::stage_line(
                            ctx,
                            &format!(
                                "{head}: done in {:.1} s, peak memory {}",
                                rec.seconds,
                                megabytes(rec.peak_memory_bytes)
                            ),
                        );
                        done.push(outcome(stage, "ran", Some(reason), Some(&rec)));
                    }
                    Err(e) => {
                        done.push(outcome(stage, "failed", Some(reason), None));
                        for rest in &chain[i + 1..] {
                            done.push(outcome(rest, "not run", None, None));
                        }
                        progress::set_stage(None);
                        return (
                            done,
                            Some(e.context(format!("stage {} failed", stage.name))),
                        );
                    }
                }
            }
        }
    }
    progress::set_stage(None);
    (done, None)
}

/// Notes for the summary: stand-ins, skipped photos, unregistered images.
fn warnings(stages: &[StageOutcome]) -> Vec<String> {
    let mut out = Vec::new();
    for s in stages {
        if let Some(note) = &s.stand_in {
            out.push(format!("{}: stand-in: {note}", s.name));
        }
        if let Some(skipped) = s.summary["skipped_photos"].as_array() {
            for p in skipped {
                out.push(format!(
                    "{}: skipped a photo: {}",
                    s.name,
                    p["reason"].as_str().unwrap_or("?")
                ));
            }
        }
        if let Some(notes) = s.summary["warnings"].as_array() {
            for w in notes.iter().filter_map(|w| w.as_str()) {
                out.push(format!("{}: {w}", s.name));
            }
        }
        if let Some(names) = s.summary["not_registered"].as_array() {
            for n in names.iter().filter_map(|n| n.as_str()) {
                out.push(format!(
                    "{}: held-out photo {n} has no camera (sfm did not register it): not compared",
                    s.name
                ));
            }
        }
        if let Some(unreg) = s.summary["unregistered"].as_array() {
            for u in unreg {
                out.push(format!(
                    "{}: {} not registered: {}",
                    s.name,
                    u["name"].as_str().unwrap_or("?"),
                    u["reason"].as_str().unwrap_or("?")
                ));
            }
        }
    }
    out
}

pub fn run(args: RunArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let start = Instant::now();
    let plan = check(&args)?;
    // The stages' own bars show under the stage lines, also with --json (on stderr).
    let stage_ctx = crate::Context {
        quiet: ctx.quiet || ctx.json,
        json: false,
    };
    let (stages, error) = run_chain(&plan, &args, &stage_ctx);
    let model = plan.ws.join("model.glb");
    let mut summary = RunSummary {
        fresco_version: env!("CARGO_PKG_VERSION").to_string(),
        photos: plan.photos.clone(),
        workspace: plan.ws.clone(),
        quality: plan.quality,
        holdout: plan.holdout.clone(),
        held_out_comparison: None,
        model: (error.is_none() && model.is_file()).then_some(model),
        report: None,
        error: error.as_ref().map(|e| format!("{e:#}")),
        warnings: warnings(&stages),
        stages,
        seconds_total: 0.0,
    };
    summary.held_out_comparison = summary
        .stages
        .iter()
        .find(|s| s.name == "holdout" && s.status != "failed" && !s.summary.is_null())
        .map(|s| s.summary.clone());
    summary.seconds_total = start.elapsed().as_secs_f64();
    match crate::report::write_report(&plan, &summary) {
        Ok(path) => summary.report = Some(path),
        Err(e) => summary.warnings.push(format!("report: not written: {e:#}")),
    }
    summary.seconds_total = start.elapsed().as_secs_f64();
    write_summary(&plan.ws, &summary)?;
    if let Some(e) = error {
        return Err(e);
    }
    print_stage_table(ctx, &summary);
    if ctx.json {
        Ok(serde_json::to_value(&summary)?)
    } else {
        // The whole summary is in summary.json; the terminal gets where things are.
        Ok(serde_json::json!({
            "model": summary.model,
            "report": summary.report,
            "summary": plan.ws.join("summary.json"),
            "seconds": summary.seconds_total,
        }))
    }
}

fn write_summary(ws: &Path, summary: &RunSummary) -> anyhow::Result<()> {
    let path = ws.join("summary.json");
    let text = serde_json::to_string_pretty(summary)?;
    fresco_core::atomic_file::write_bytes_atomically(&path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// The final table on stderr: stage, status, seconds, peak memory; then the warnings.
fn print_stage_table(ctx: &crate::Context, s: &RunSummary) {
    if ctx.quiet || ctx.json {
        return;
    }
    let mut lines = vec![format!(
        "{:<12} {:<8} {:>9} {:>10}",
        "stage", "status", "seconds", "peak mem"
    )];
    for st in &s.stages {
        lines.push(format!(
            "{:<12} {:<8} {:>9.1} {:>10}",
            st.name,
            st.status,
            st.seconds,
            megabytes(st.peak_memory_bytes)
        ));
    }
    lines.push(format!("total {:.1} s", s.seconds_total));
    for w in &s.warnings {
        lines.push(format!("warning: {w}"));
    }
    for l in lines {
        progress::stage_line(ctx, &l);
    }
}
