//! The stages of `fresco run`, as a table: each stage names its inputs and outputs in the
//! workspace, the arguments it runs with (those of its `fresco <verb>`, from the quality
//! preset) and the one call that runs it. The runner (`mod.rs`) fingerprints the inputs and
//! outputs, decides what to skip and records what ran (`record.rs`).
//!
//! The chain: `features`, `match`, `sfm` (or `import` of a COLMAP model with `--colmap`),
//! `dense` (depth maps fused into `dense/fused.ply`; `--holdout` photos left out), `mesh`
//! (from `dense/fused.ply`, facing the undistorted cameras of `dense/sparse`; or `import-mesh`
//! with `--mesh`, which skips dense), `unwrap` (`charts.ply`), `texture` (`texture/` and the
//! textured `model.glb`; `--holdout` photos left out) and, with `--holdout`, `holdout` (the
//! model rendered into the held-out photos and compared with them, `holdout.rs`).

use std::fmt::Debug;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::{Args, Parser};

use super::Plan;

/// One stage of the chain.
pub struct Stage {
    /// Name used by `--from`, in the record file name and the summary.
    pub name: &'static str,
    /// What it does, one line for the stage line and the report.
    pub does: &'static str,
    /// Set when the stage stands in for one not built yet: said in the summary and report.
    pub stand_in: Option<&'static str>,
    /// Files and folders it reads.
    pub inputs: fn(&Plan) -> anyhow::Result<Vec<PathBuf>>,
    /// Files and folders it writes (all of them: they are fingerprinted in its record).
    pub outputs: fn(&Plan) -> Vec<PathBuf>,
    /// The arguments it runs with.
    pub argv: fn(&Plan) -> Vec<String>,
    /// Every setting, defaults included, as recorded (the parsed arguments, printed).
    pub settings: fn(&[String]) -> anyhow::Result<String>,
    /// Runs it; returns its summary.
    pub execute: fn(&Plan, &[String], &crate::Context) -> anyhow::Result<serde_json::Value>,
}

/// The stages `plan` runs, in order.
pub fn chain(plan: &Plan) -> Vec<&'static Stage> {
    let mut stages: Vec<&'static Stage> = Vec::new();
    if plan.colmap.is_some() {
        stages.push(&IMPORT);
    } else {
        stages.extend([&FEATURES, &MATCH, &SFM]);
    }
    if plan.mesh.is_some() {
        stages.push(&IMPORT_MESH);
    } else {
        stages.extend([&DENSE, &MESH]);
    }
    stages.extend([&UNWRAP, &TEXTURE]);
    if !plan.holdout.is_empty() {
        stages.push(&HOLDOUT);
    }
    stages
}

/// Every stage name `--from` accepts.
pub const NAMES: &[&str] = &[
    "features",
    "match",
    "sfm",
    "import",
    "dense",
    "mesh",
    "import-mesh",
    "unwrap",
    "texture",
    "holdout",
];

/// A verb's arguments parsed from a list, as its command line would be.
#[derive(Parser, Debug)]
#[command(no_binary_name = true)]
struct Verb<A: Args> {
    #[command(flatten)]
    args: A,
}

fn parse<A: Args + Debug>(argv: &[String]) -> anyhow::Result<A> {
    Verb::<A>::try_parse_from(argv)
        .map(|v| v.args)
        .map_err(|e| anyhow::anyhow!("internal: arguments {argv:?}: {e}"))
}

/// The settings of a verb's stage: its parsed arguments, every field.
fn describe<A: Args + Debug>(argv: &[String]) -> anyhow::Result<String> {
    Ok(format!("{:?}", parse::<A>(argv)?))
}

/// The settings of a stage without a verb: its arguments.
fn literal(argv: &[String]) -> anyhow::Result<String> {
    Ok(argv.join(" "))
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

fn strings(items: &[&str]) -> Vec<String> {
    items.iter().map(|a| a.to_string()).collect()
}

// --- features ------------------------------------------------------------------------------

pub static FEATURES: Stage = Stage {
    name: "features",
    does: "SIFT keypoints of every photo",
    stand_in: None,
    inputs: |p| {
        let mut v = super::inputs::list_photos(&p.photos)?;
        v.extend(p.focal_file.clone());
        Ok(v)
    },
    outputs: |p| {
        vec![
            p.ws.join("images.json"),
            p.ws.join("features.json"),
            p.ws.join("features"),
        ]
    },
    argv: |p| {
        let mut v = vec![s(&p.photos), "-o".into(), s(&p.ws)];
        v.extend(strings(p.quality.features()));
        if let Some(k) = &p.focal_file {
            v.extend(["--focal-file".into(), s(k)]);
        }
        v
    },
    settings: describe::<crate::features::FeaturesArgs>,
    execute: |_, argv, ctx| {
        let summary = crate::features::run(parse(argv)?, ctx)?;
        let usable = summary["images"].as_u64().unwrap_or(0);
        if usable < 2 {
            bail!(
                "only {usable} of the photos could be used ({} skipped, see above); fresco needs at least two overlapping photos of the object",
                summary["skipped"]
            );
        }
        Ok(summary)
    },
};

// --- match ---------------------------------------------------------------------------------

pub static MATCH: Stage = Stage {
    name: "match",
    does: "matches between every pair of photos, verified by two-view geometry",
    stand_in: None,
    inputs: |p| Ok(vec![p.ws.join("images.json"), p.ws.join("features")]),
    outputs: |p| vec![p.ws.join("matches")],
    argv: |p| vec![s(&p.ws)],
    settings: describe::<crate::matching::MatchArgs>,
    execute: |_, argv, ctx| {
        let summary = crate::matching::run(parse(argv)?, ctx)?;
        if summary["pairs_verified"].as_u64() == Some(0) {
            bail!(
                "no pair of the {} photos could be matched ({} pairs tried): the photos do not overlap or show too little texture. Try photos taken closer together (60-80% overlap between neighbours), of a textured object, or --quality high for more keypoints",
                summary["images"],
                summary["pairs_tried"]
            );
        }
        Ok(summary)
    },
};

// --- sfm -----------------------------------------------------------------------------------

pub static SFM: Stage = Stage {
    name: "sfm",
    does: "camera poses and sparse points (incremental mapping, bundle adjustment)",
    stand_in: None,
    inputs: |p| {
        let mut v = vec![
            p.ws.join("images.json"),
            p.ws.join("features"),
            p.ws.join("matches"),
        ];
        v.extend(p.masks.clone());
        Ok(v)
    },
    outputs: |p| vec![p.ws.join("sparse")],
    argv: |p| {
        let mut v = vec![s(&p.ws)];
        if let Some(m) = &p.masks {
            v.extend(["--masks".into(), s(m)]);
        }
        v
    },
    settings: describe::<crate::sfm::SfmArgs>,
    execute: |_, argv, ctx| {
        crate::sfm::run(parse(argv)?, ctx).map_err(|e| {
            anyhow::anyhow!(
                "{e:#}. Try photos with more overlap (60-80% between neighbours) and texture, or --quality high for more keypoints"
            )
        })
    },
};

// --- import (--colmap) ---------------------------------------------------------------------

pub static IMPORT: Stage = Stage {
    name: "import",
    does: "cameras and sparse points from an existing COLMAP model (--colmap)",
    stand_in: None,
    inputs: |p| {
        let dir = p
            .colmap
            .clone()
            .context("internal: import without --colmap")?;
        let mut v = vec![dir.clone()];
        v.extend(super::inputs::colmap_photos(&dir, &p.photos)?);
        Ok(v)
    },
    outputs: |p| vec![p.ws.join("images.json"), p.ws.join("sparse")],
    argv: |p| {
        vec![
            p.colmap.as_deref().map(s).unwrap_or_default(),
            s(&p.photos),
            s(&p.ws),
        ]
    },
    settings: literal,
    execute: |p, _, _| {
        let dir = p
            .colmap
            .as_deref()
            .context("internal: import without --colmap")?;
        super::inputs::import_colmap(dir, &p.photos, &p.ws)
    },
};

// --- dense ---------------------------------------------------------------------------------

/// Removes a folder a stage rewrites whole, so no file of an earlier run with other settings
/// (an image held out since, a depth map of a killed run) stays among its outputs.
fn clear(dir: &Path) -> anyhow::Result<()> {
    match std::fs::remove_dir_all(dir) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("cannot remove {}", dir.display())),
    }
}

pub static DENSE: Stage = Stage {
    name: "dense",
    does: "depth maps of the photos (PatchMatch stereo), fused into an oriented point cloud",
    stand_in: None,
    inputs: |p| {
        let mut v = vec![p.ws.join("images.json"), p.ws.join("sparse")];
        v.extend(super::inputs::list_photos(&p.photos)?);
        v.extend(p.masks.clone());
        Ok(v)
    },
    outputs: |p| vec![p.ws.join("dense")],
    argv: |p| {
        let mut v = vec![s(&p.ws)];
        v.extend(strings(p.quality.dense()));
        for name in &p.holdout {
            v.extend(["--exclude".into(), name.clone()]);
        }
        if let Some(m) = &p.masks {
            v.extend(["--masks".into(), s(m)]);
        }
        v
    },
    settings: describe::<crate::dense::DenseArgs>,
    execute: |p, argv, ctx| {
        clear(&p.ws.join("dense"))?;
        crate::dense::run(parse(argv)?, ctx)
    },
};

// --- mesh ----------------------------------------------------------------------------------

pub static MESH: Stage = Stage {
    name: "mesh",
    does: "surface from the fused points: screened Poisson, trimming, clean-up, decimation, facing the cameras",
    stand_in: None,
    inputs: |p| {
        let dense = p.ws.join("dense");
        Ok(vec![dense.join("fused.ply"), dense.join("sparse")])
    },
    outputs: |p| vec![p.ws.join("mesh.ply")],
    argv: |p| {
        let mut v = vec![
            s(&p.ws),
            "--points".into(),
            s(&p.ws.join("dense").join("fused.ply")),
            "--cameras".into(),
            s(&p.ws.join("dense").join("sparse")),
        ];
        v.extend(strings(p.quality.mesh()));
        v
    },
    settings: describe::<crate::mesh::MeshArgs>,
    execute: |_, argv, ctx| crate::mesh::run(parse(argv)?, ctx),
};

pub static IMPORT_MESH: Stage = Stage {
    name: "import-mesh",
    does: "the user's mesh (--mesh), in the cameras' frame, as mesh.ply",
    stand_in: None,
    inputs: |p| Ok(p.mesh.iter().cloned().collect()),
    outputs: |p| vec![p.ws.join("mesh.ply")],
    argv: |p| vec![p.mesh.as_deref().map(s).unwrap_or_default(), s(&p.ws)],
    settings: literal,
    execute: |p, _, _| {
        let path = p
            .mesh
            .as_deref()
            .context("internal: import-mesh without --mesh")?;
        super::inputs::import_mesh(path, &p.ws)
    },
};

// --- unwrap --------------------------------------------------------------------------------

pub static UNWRAP: Stage = Stage {
    name: "unwrap",
    does: "charts, conformal flattening and packing of the mesh's texture coordinates",
    stand_in: None,
    inputs: |p| Ok(vec![p.ws.join("mesh.ply")]),
    outputs: |p| vec![p.ws.join("charts.ply"), p.ws.join("charts.png")],
    argv: |p| {
        let mut v = vec![
            s(&p.ws.join("mesh.ply")),
            "-o".into(),
            s(&p.ws.join("charts.ply")),
            "--png".into(),
            s(&p.ws.join("charts.png")),
        ];
        v.extend(strings(p.quality.unwrap()));
        v
    },
    settings: describe::<crate::unwrap::UnwrapArgs>,
    execute: |_, argv, ctx| crate::unwrap::run(parse(argv)?, ctx),
};

// --- texture -------------------------------------------------------------------------------

pub static TEXTURE: Stage = Stage {
    name: "texture",
    does: "texture atlas from the photos (views per face, graph-cut seams, exposure gains) and model.glb",
    stand_in: None,
    inputs: |p| {
        let mut v = vec![
            p.ws.join("charts.ply"),
            p.ws.join("images.json"),
            p.ws.join("sparse"),
        ];
        v.extend(super::inputs::list_photos(&p.photos)?);
        v.extend(p.masks.clone());
        Ok(v)
    },
    outputs: |p| vec![p.ws.join("texture"), p.ws.join("model.glb")],
    argv: |p| {
        let mut v = vec![s(&p.ws), "--mesh".into(), s(&p.ws.join("charts.ply"))];
        v.extend(strings(p.quality.texture()));
        if !p.holdout.is_empty() {
            v.extend(["--exclude".into(), p.holdout.join(",")]);
        }
        if let Some(m) = &p.masks {
            v.extend(["--masks".into(), s(m)]);
        }
        v
    },
    settings: describe::<crate::texture::TextureArgs>,
    execute: |p, argv, ctx| {
        clear(&p.ws.join("texture"))?;
        crate::texture::run(parse(argv)?, ctx)
    },
};

// --- holdout -------------------------------------------------------------------------------

pub static HOLDOUT: Stage = Stage {
    name: "holdout",
    does: "model.glb rendered into the held-out photos' cameras and compared with them (PSNR, SSIM)",
    stand_in: None,
    inputs: |p| {
        let mut v = vec![
            p.ws.join("model.glb"),
            p.ws.join("images.json"),
            p.ws.join("sparse"),
        ];
        v.extend(p.holdout.iter().map(|h| p.photos.join(h)));
        v.extend(p.masks.clone());
        Ok(v)
    },
    outputs: |p| vec![p.ws.join("holdout")],
    argv: |p| {
        let mut v = vec![s(&p.ws), p.holdout.join(",")];
        if let Some(m) = &p.masks {
            v.push(s(m));
        }
        v
    },
    settings: literal,
    execute: |p, _, _| {
        let out = p.ws.join("holdout");
        clear(&out)?;
        super::holdout::compare_held_out(&p.ws, &p.holdout, p.masks.as_deref(), &out)
    },
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stage_of_every_chain_is_a_from_name_and_its_arguments_parse() {
        for (colmap, mesh) in [(false, false), (true, false), (false, true), (true, true)] {
            let plan = Plan {
                photos: PathBuf::from("/p"),
                ws: PathBuf::from("/w"),
                quality: super::super::quality::Quality::Draft,
                colmap: colmap.then(|| PathBuf::from("/c")),
                mesh: mesh.then(|| PathBuf::from("/m.ply")),
                masks: Some(PathBuf::from("/masks")),
                holdout: vec!["a.png".into(), "b.png".into()],
                focal_file: Some(PathBuf::from("/K.txt")),
            };
            for stage in chain(&plan) {
                assert!(NAMES.contains(&stage.name), "{}", stage.name);
                let argv = (stage.argv)(&plan);
                (stage.settings)(&argv).unwrap_or_else(|e| panic!("{}: {e}", stage.name));
            }
        }
    }

    #[test]
    fn presets_reach_the_stage_settings() {
        let mut plan = Plan {
            photos: PathBuf::from("/p"),
            ws: PathBuf::from("/w"),
            quality: super::super::quality::Quality::Draft,
            colmap: None,
            mesh: None,
            masks: None,
            holdout: vec![],
            focal_file: None,
        };
        let draft = (MESH.settings)(&(MESH.argv)(&plan)).unwrap();
        assert!(draft.contains("depth: 7"), "{draft}");
        plan.quality = super::super::quality::Quality::High;
        let high = (MESH.settings)(&(MESH.argv)(&plan)).unwrap();
        assert!(high.contains("depth: 10"), "{high}");
    }
}
