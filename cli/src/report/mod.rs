//! `<ws>/report.html`: one self-contained page (no network: pictures, the model and the viewer
//! are embedded) saying what each stage of `fresco run` did, with its figures and pictures,
//! and an interactive viewer of model.glb (`viewer.js`, a small WebGL viewer of our own).
//!
//! Sections follow the chain and appear when their stage's outputs exist: photos, features
//! and matches of the best pair, the view graph, cameras and sparse points from above, depth
//! maps (dense/), the mesh rendered from a photo's camera, the unwrapped charts, the atlas
//! (texture/), held-out comparisons, the viewer. Pictures are made by `figures.rs`.
//!
//! [`viewer_page`] is the viewer alone, for `fresco view model.glb`.

pub mod figures;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use fresco_core::colmap;
use fresco_sfm::workspace::read_images;

use crate::run::{Plan, RunSummary};
use figures::{Picture, escape};

/// The viewer's script, embedded in every page that shows a model.
pub const VIEWER_JS: &str = include_str!("viewer.js");

/// GLBs larger than this are not embedded but loaded from beside the report (works when the
/// report is served by `fresco view`; browsers refuse `fetch` of local files).
const MAX_EMBEDDED_GLB: u64 = 96 << 20;

const STYLE: &str = r#"
body { font-family: system-ui, sans-serif; margin: 0 auto; max-width: 1100px; padding: 1em 2em; color: #222; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
table { border-collapse: collapse; } td, th { padding: 0.25em 0.8em; text-align: left; border-bottom: 1px solid #eee; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.warn { background: #fff4d6; border-left: 4px solid #e0a800; padding: 0.4em 0.8em; margin: 0.3em 0; }
.error { background: #fde2e2; border-left: 4px solid #d33; padding: 0.4em 0.8em; }
figure { margin: 0.8em 0; } figcaption { color: #555; font-size: 0.9em; }
img.pic { max-width: 100%; border: 1px solid #ddd; }
.row figure { display: inline-block; width: 32%; margin-right: 1%; vertical-align: top; }
.thumbs img { height: 72px; margin: 2px; border: 1px solid #ddd; }
.status-ran { color: #186a1d; } .status-skipped { color: #555; } .status-failed { color: #b00; }
#viewer { width: 100%; height: 520px; background: #17171c; display: block; border-radius: 4px; }
button { margin: 0.4em 0.4em 0.4em 0; }
code { background: #f3f3f3; padding: 0 0.2em; }
"#;

fn data_uri(p: &Picture) -> String {
    format!("data:{};base64,{}", p.mime, base64(&p.bytes))
}

fn figure(out: &mut String, p: &Picture) {
    let _ = write!(
        out,
        r#"<figure><img class="pic" src="{}" alt="{}"><figcaption>{}</figcaption></figure>"#,
        data_uri(p),
        escape(&p.caption),
        escape(&p.caption)
    );
}

fn svg_figure(out: &mut String, svg: &str, caption: &str) {
    let _ = write!(
        out,
        "<figure>{svg}<figcaption>{}</figcaption></figure>",
        escape(caption)
    );
}

/// Standard base64 with padding (RFC 4648).
pub fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        s.push(T[(n >> 18) as usize & 63] as char);
        s.push(T[(n >> 12) as usize & 63] as char);
        s.push(if c.len() > 1 {
            T[(n >> 6) as usize & 63] as char
        } else {
            '='
        });
        s.push(if c.len() > 2 {
            T[n as usize & 63] as char
        } else {
            '='
        });
    }
    s
}

/// A section's content, or a line saying why it has none (a picture that failed is reported,
/// never fatal to the report).
fn attempt(out: &mut String, what: &str, f: impl FnOnce(&mut String) -> anyhow::Result<()>) {
    let mut body = String::new();
    match f(&mut body) {
        Ok(()) => out.push_str(&body),
        Err(e) => {
            let _ = write!(
                out,
                r#"<p class="warn">{}: {}</p>"#,
                escape(what),
                escape(&format!("{e:#}"))
            );
        }
    }
}

fn stage_summary<'a>(s: &'a RunSummary, name: &str) -> Option<&'a crate::run::StageOutcome> {
    s.stages.iter().find(|st| st.name == name)
}

/// Key figures of a stage, for the stage table.
fn key_figures(st: &crate::run::StageOutcome) -> String {
    let v = &st.summary;
    let get = |k: &str| v.get(k).filter(|x| !x.is_null()).map(|x| x.to_string());
    let mut parts = Vec::new();
    let mut add = |label: &str, key: &str| {
        if let Some(x) = get(key) {
            parts.push(format!("{label} {x}"));
        }
    };
    match st.name.as_str() {
        "features" => {
            add("photos", "images");
            add("skipped", "skipped");
            add("keypoints", "keypoints");
        }
        "match" => {
            add("pairs tried", "pairs_tried");
            add("verified", "pairs_verified");
        }
        "sfm" | "import" => {
            add("registered", "registered");
            add("points", "points");
            if let Some(e) = v.get("mean_reprojection_px").and_then(|x| x.as_f64()) {
                parts.push(format!("reprojection {e:.3} px"));
            }
        }
        "dense" => {
            if let Some(n) = v.get("views").and_then(|x| x.as_array()) {
                parts.push(format!("depth maps {}", n.len()));
            }
            if let Some(n) = v.get("fusion").and_then(|f| f.get("points")) {
                parts.push(format!("fused points {n}"));
            }
        }
        "texture" => {
            add("faces", "faces");
            add("views", "views_used");
            add("atlas", "atlas_size");
            if let Some(c) = v.get("coverage").and_then(|x| x.as_f64()) {
                parts.push(format!("coverage {:.1}%", 100.0 * c));
            }
        }
        "holdout" => {
            if let (Some(a), Some(b)) = (
                v.get("mean_psnr").and_then(|x| x.as_f64()),
                v.get("mean_psnr_gain_fitted").and_then(|x| x.as_f64()),
            ) {
                parts.push(format!("PSNR {a:.2} dB, gain-fitted {b:.2} dB"));
            }
        }
        _ => {
            add("faces", "faces");
            if let Some(c) = v.get("report").and_then(|r| r.get("charts")) {
                parts.push(format!("charts {c}"));
            }
        }
    }
    parts.join(", ")
}

fn stage_table(out: &mut String, s: &RunSummary) {
    out.push_str("<table><tr><th>stage</th><th>what</th><th>status</th><th>seconds</th><th>peak memory</th><th>figures</th></tr>");
    for st in &s.stages {
        let mem = st.peak_memory_bytes.map_or_else(
            || "?".to_string(),
            |b| {
                format!(
                    "{:.0} MB{}",
                    b as f64 / 1e6,
                    if st.peak_memory_since_start {
                        " (process)"
                    } else {
                        ""
                    }
                )
            },
        );
        let _ = write!(
            out,
            r#"<tr><td>{}</td><td>{}</td><td class="status-{}">{}</td><td class="num">{:.1}</td><td class="num">{}</td><td>{}</td></tr>"#,
            escape(&st.name),
            escape(&st.does),
            escape(&st.status),
            escape(&st.status),
            st.seconds,
            mem,
            escape(&key_figures(st))
        );
    }
    let _ = write!(
        out,
        r#"<tr><td><b>total</b></td><td></td><td></td><td class="num">{:.1}</td><td></td><td></td></tr></table>"#,
        s.seconds_total
    );
}

/// PNG files under `dir` whose name contains `needle`, sorted.
fn pictures_under(dir: &Path, needle: &str) -> Vec<PathBuf> {
    let Ok(files) = crate::run::record::folder_files(dir) else {
        return Vec::new();
    };
    files
        .into_iter()
        .filter(|f| {
            let name = f.to_string_lossy().to_lowercase();
            name.ends_with(".png") && name.contains(needle)
        })
        .map(|f| dir.join(f))
        .collect()
}

/// The viewer: a canvas, buttons and the script, loading `glb` (embedded base64 or a URL).
/// `up` is the world's up in the model's frame (from the cameras, see
/// [`figures::up_direction`]): an SfM frame has no up of its own, and glTF's +Y is only a
/// convention there; without it the viewer orbits around +Y.
fn viewer_section(out: &mut String, glb: GlbSource, up: Option<[f64; 3]>) {
    out.push_str(r#"<canvas id="viewer" width="1040" height="520"></canvas>
<div><button id="wire">Wireframe (W)</button><button id="home">Reset view</button>
<span id="viewer-status">loading the model...</span></div>
<p style="color:#555;font-size:0.9em">Drag to orbit, wheel to zoom, shift-drag or right-drag to pan.</p>
"#);
    let load = match glb {
        GlbSource::Embedded(bytes) => format!(
            "Promise.resolve(Uint8Array.from(atob('{}'), c => c.charCodeAt(0)))",
            base64(&bytes)
        ),
        GlbSource::Url(url) => format!(
            "fetch('{}').then(r => {{ if (!r.ok) throw new Error('cannot load {}: ' + r.status); return r.arrayBuffer(); }}).then(b => new Uint8Array(b))",
            url, url
        ),
    };
    let up = match up {
        Some([x, y, z]) if (x * x + y * y + z * z).is_finite() => format!("[{x}, {y}, {z}]"),
        _ => "null".to_string(),
    };
    let _ = write!(
        out,
        r#"<script>{VIEWER_JS}
(function () {{
  const canvas = document.getElementById('viewer');
  const status = document.getElementById('viewer-status');
  {load}.then(bytes => frescoViewer(canvas, bytes, status, {up})).then(v => {{
    window.frescoViewerResult = v;
    document.getElementById('wire').onclick = () => v.api.toggleWireframe();
    document.getElementById('home').onclick = () => v.api.reset();
    canvas.dataset.nonBlank = String(v.nonBlank);
    document.body.dataset.viewer = 'ready';
  }}).catch(e => {{
    status.textContent = 'the model could not be shown: ' + e.message;
    document.body.dataset.viewer = 'failed';
    console.error(e);
  }});
}})();
</script>"#
    );
}

enum GlbSource {
    Embedded(Vec<u8>),
    Url(String),
}

/// A page with the viewer alone (for `fresco view model.glb`), loading `url`.
pub fn viewer_page(title: &str, url: &str) -> String {
    let mut out = format!(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><link rel=\"icon\" href=\"data:,\"><title>{}</title><style>{STYLE}</style></head><body><h1>{}</h1>",
        escape(title),
        escape(title)
    );
    viewer_section(&mut out, GlbSource::Url(url.to_string()), None);
    out.push_str("</body></html>");
    out
}

/// The held-out photos beside the model rendered into their cameras, with the figures.
fn held_out_section(out: &mut String, s: &RunSummary) {
    let Some(h) = &s.held_out_comparison else {
        return;
    };
    out.push_str("<h2>Held-out photos</h2>");
    let _ = write!(
        out,
        "<p>Photos kept out of dense and texture; the model rendered into their cameras. Mean PSNR {:.2} dB, after a per-channel gain fitted to the photo {:.2} dB (SSIM {:.3}).</p>",
        h["mean_psnr"].as_f64().unwrap_or(f64::NAN),
        h["mean_psnr_gain_fitted"].as_f64().unwrap_or(f64::NAN),
        h["mean_ssim_gain_fitted"].as_f64().unwrap_or(f64::NAN),
    );
    for v in h["views"].as_array().into_iter().flatten() {
        let Some(path) = v["picture"].as_str() else {
            continue;
        };
        let caption = format!(
            "{}: photo | model | 4x difference (grey: not compared). PSNR {:.2} dB, gain-fitted {:.2} dB, SSIM {:.3}, over {} pixels",
            v["name"].as_str().unwrap_or("?"),
            v["psnr"].as_f64().unwrap_or(f64::NAN),
            v["psnr_gain_fitted"].as_f64().unwrap_or(f64::NAN),
            v["ssim_gain_fitted"].as_f64().unwrap_or(f64::NAN),
            v["pixels"],
        );
        attempt(out, "held-out picture", |o| {
            figure(o, &figures::picture_file(Path::new(path), 1040, caption)?);
            Ok(())
        });
    }
}

/// Writes `<ws>/report.html` (atomically) and returns its path.
pub fn write_report(plan: &Plan, s: &RunSummary) -> anyhow::Result<PathBuf> {
    let ws = &plan.ws;
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><link rel=\"icon\" href=\"data:,\"><title>fresco report: {}</title><style>{STYLE}</style></head><body>",
        escape(&plan.photos.display().to_string())
    );
    let _ = write!(
        out,
        "<h1>fresco run</h1><p>Photos <code>{}</code>, workspace <code>{}</code>, quality <b>{}</b>, fresco {}{}.</p>",
        escape(&plan.photos.display().to_string()),
        escape(&ws.display().to_string()),
        plan.quality.name(),
        escape(&s.fresco_version),
        if plan.holdout.is_empty() {
            String::new()
        } else {
            format!(", held out: {}", escape(&plan.holdout.join(", ")))
        }
    );
    if let Some(e) = &s.error {
        let _ = write!(
            out,
            r#"<p class="error">The run stopped: {}</p>"#,
            escape(e)
        );
    }
    for w in &s.warnings {
        let _ = write!(out, r#"<p class="warn">{}</p>"#, escape(w));
    }
    out.push_str("<h2>Stages</h2>");
    stage_table(&mut out, s);

    let list = read_images(ws).ok();
    if let Some(list) = &list {
        out.push_str("<h2>Photos</h2><div class=\"thumbs\">");
        for t in figures::thumbnails(list, 72) {
            let _ = write!(
                out,
                r#"<img src="{}" title="{}" alt="{}">"#,
                data_uri(&t),
                escape(&t.caption),
                escape(&t.caption)
            );
        }
        let _ = write!(out, "</div><p>{} photos.</p>", list.images.len());
    }

    if let (Some(list), true) = (&list, ws.join("matches").is_dir()) {
        out.push_str("<h2>Features and matches</h2>");
        attempt(&mut out, "pair picture", |o| {
            if let Some(p) = figures::pair_matches(ws, list, 1040)? {
                figure(o, &p);
            }
            Ok(())
        });
        out.push_str("<h3>View graph</h3>");
        attempt(&mut out, "view graph", |o| {
            if let Some(svg) = figures::view_graph(ws, list)? {
                svg_figure(
                    o,
                    &svg,
                    "Each photo a dot, each verified pair a line (wider: more inliers).",
                );
            }
            Ok(())
        });
    }

    let model = colmap::read_model(&ws.join("sparse").join("0")).ok();
    if let Some(rec) = &model {
        out.push_str("<h2>Cameras and sparse points</h2>");
        if let Some(svg) = figures::top_view(rec) {
            let caption = format!(
                "Seen from above (normal of the cameras' plane): {} cameras (yellow, pointing where they look), {} points in their colours.",
                rec.images.len(),
                rec.points3d.len()
            );
            svg_figure(&mut out, &svg, &caption);
        }
    }

    let depth = pictures_under(&ws.join("dense"), "depth");
    if !depth.is_empty() {
        out.push_str("<h2>Depth maps</h2>");
        attempt(&mut out, "depth map", |o| {
            // Three depth maps spread over the photos, side by side.
            o.push_str(r#"<div class="row">"#);
            let step = (depth.len() / 3).max(1);
            for d in depth.iter().step_by(step).take(3) {
                let name = d
                    .file_name()
                    .map(|n| n.to_string_lossy().to_string())
                    .unwrap_or_default();
                let name = name
                    .trim_end_matches(".png")
                    .trim_end_matches(".photometric");
                let p =
                    figures::picture_file(d, 400, format!("depth map of {name} (false colour)"))?;
                figure(o, &p);
            }
            o.push_str("</div>");
            let conf = pictures_under(&ws.join("dense"), "conf");
            if let Some(c) = conf.first() {
                figure(
                    o,
                    &figures::picture_file(c, 640, format!("{}", c.display()))?,
                );
            }
            Ok(())
        });
    }

    if let (Some(rec), true) = (&model, ws.join("mesh.ply").is_file()) {
        out.push_str("<h2>Mesh</h2>");
        if let Some(note) = stage_summary(s, "mesh").and_then(|st| st.stand_in.clone()) {
            let _ = write!(out, r#"<p class="warn">Stand-in: {}</p>"#, escape(&note));
        }
        attempt(&mut out, "mesh render", |o| {
            let mesh = fresco_core::ply::read_mesh(ws.join("mesh.ply"))?;
            if let Some(p) = figures::mesh_render(&mesh, rec, 800)? {
                figure(o, &p);
            }
            Ok(())
        });
    }

    if ws.join("charts.png").is_file() {
        out.push_str("<h2>Charts</h2>");
        attempt(&mut out, "chart picture", |o| {
            let mut caption = "The unwrapped charts in the atlas (each chart a colour, a 3D checker shows distortion)".to_string();
            if let Some(st) = stage_summary(s, "unwrap")
                && let Some(m) = st.summary.get("metrics")
            {
                let f = |k: &str| m.get(k).and_then(|v| v.as_f64()).unwrap_or(f64::NAN);
                let _ = write!(
                    caption,
                    ": {} charts, L2 stretch {:.3}, angle distortion {:.2} deg, {:.0}% of the atlas used, {} flipped triangles",
                    f("charts"),
                    f("l2_stretch"),
                    f("angle_distortion_deg"),
                    100.0 * f("utilisation"),
                    f("flipped")
                );
            }
            figure(
                o,
                &figures::picture_file(&ws.join("charts.png"), 700, caption)?,
            );
            Ok(())
        });
    }

    let atlases = pictures_under(&ws.join("texture"), "atlas");
    if !atlases.is_empty() {
        out.push_str("<h2>Texture atlas</h2>");
        attempt(&mut out, "atlas", |o| {
            for a in atlases.iter().take(4) {
                figure(
                    o,
                    &figures::picture_file(a, 800, format!("{}", a.display()))?,
                );
            }
            Ok(())
        });
    }

    held_out_section(&mut out, s);

    let glb = ws.join("model.glb");
    if glb.is_file() {
        out.push_str("<h2>Model</h2>");
        let size = std::fs::metadata(&glb).map(|m| m.len()).unwrap_or(0);
        let source = if size <= MAX_EMBEDDED_GLB {
            GlbSource::Embedded(
                std::fs::read(&glb).with_context(|| format!("reading {}", glb.display()))?,
            )
        } else {
            GlbSource::Url("model.glb".into())
        };
        let _ = write!(
            out,
            "<p><code>model.glb</code>, {:.1} MB{}.</p>",
            size as f64 / 1e6,
            if size > MAX_EMBEDDED_GLB {
                " (too large to embed: open the report with `fresco view` to see it)"
            } else {
                ""
            }
        );
        let up = model.as_ref().map(|rec| {
            let up = figures::up_direction(rec);
            [up.x, up.y, up.z]
        });
        viewer_section(&mut out, source, up);
    }
    out.push_str("</body></html>");
    let path = ws.join("report.html");
    fresco_core::atomic_file::write_bytes_atomically(&path, out.as_bytes())?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_rfc_4648_test_vectors() {
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), coded);
        }
    }
}
