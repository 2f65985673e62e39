//! The mapper alone on a workspace that `fresco features` and `fresco match` (or `fresco
//! reconstruct`) filled, for profiling and accuracy work without rebuilding the CLI:
//! `cargo run --release -p fresco-sfm --example sfm_workspace -- <ws> <CAMERA_MODEL>
//! <single|auto> [reference: par file or COLMAP model] [runs] [COLMAP model]`; with the last
//! argument the pose figures are also given on the images that model registered
//! (`*_common`), so two tools can be compared on the images both registered.
//! Prints one JSON line per run: registered images, points, mean track length, the phase
//! seconds of `run_sfm` and, with a reference, the pose figures of `evaluate_poses`.

use std::path::PathBuf;

use fresco_core::{CameraModel, NoProgress};
use fresco_sfm::evaluate::evaluate_poses;
use fresco_sfm::mapping::reconstruct::{
    CameraMode, SfmConfig, read_model_or_workspace, read_reference, run_sfm,
};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!("usage: sfm_workspace <ws> <CAMERA_MODEL> <single|auto> [reference] [runs]");
        std::process::exit(2);
    }
    let ws = PathBuf::from(&args[1]);
    let model = CameraModel::from_name(&args[2]).unwrap_or_else(|_| {
        eprintln!("unknown camera model {}", args[2]);
        std::process::exit(2)
    });
    let mut config = SfmConfig {
        camera_model: model,
        camera_mode: if args[3] == "single" {
            CameraMode::Single
        } else {
            CameraMode::Auto
        },
        colours: false,
        ..Default::default()
    };
    // FOCAL_FROM_F=0: the default focal prior even when the fundamental matrices disagree.
    config.focal_from_f.enabled = std::env::var("FOCAL_FROM_F").map_or(true, |v| v != "0");
    let reference = args.get(4).map(PathBuf::from);
    let runs: usize = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(1);
    let common = args.get(6).map(|p| {
        read_model_or_workspace(std::path::Path::new(p))
            .expect("COLMAP model")
            .images
            .values()
            .map(|im| im.name.clone())
            .collect::<std::collections::BTreeSet<String>>()
    });
    for _ in 0..runs {
        let summary = match run_sfm(&ws, &config, &NoProgress) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        };
        let mut line = serde_json::json!({
            "registered": summary.registered,
            "points": summary.points,
            "mean_track_length": summary.mean_track_length,
            "mean_reprojection_px": summary.mean_reprojection_px,
            "seconds_map": summary.seconds_map,
            "seconds_total": summary.seconds_total,
            "mapper_seconds": summary.mapper_seconds,
        });
        if let Some(r) = &reference {
            let m = read_model_or_workspace(&ws).expect("model just written");
            let e =
                evaluate_poses(&m, &read_reference(r, &m).expect("reference")).expect("evaluation");
            line["median_rotation_deg"] = e.median_rotation_deg.into();
            line["median_centre_frac"] = e.median_centre_frac.into();
            line["max_rotation_deg"] = e.max_rotation_deg.into();
            if let Some(names) = &common {
                let mut sub = m.clone();
                sub.images.retain(|_, im| names.contains(&im.name));
                let e = evaluate_poses(&sub, &read_reference(r, &sub).expect("reference"))
                    .expect("evaluation");
                line["registered_common"] = e.registered.into();
                line["median_rotation_deg_common"] = e.median_rotation_deg.into();
                line["median_centre_frac_common"] = e.median_centre_frac.into();
            }
        }
        println!("{line}");
    }
}
