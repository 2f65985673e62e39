//! SIFT phase profile: `cargo run --release -p fresco-sfm --example sift_phases -- <photo>...
//! [--runs N]`. After one untimed warm-up run (thread pool, page faults), for each photo prints
//! one JSON line with the median (over N runs, default 5)
//! seconds of every phase — decode, scale space (up-sampling + blurs), DoG + extrema,
//! orientation, descriptor — and of the whole `extract_features` call (decode excluded), of the
//! up-sampling alone and of writing the feature file, so
//! the per-image figures of bench/sift.sh can be compared phase by phase. `--dump <dir>` also
//! writes each photo's features to `<dir>/<photo file name>.sift` (to check that a change keeps
//! the keypoints and descriptors bit-identical, e.g. with `cmp`).

use std::time::Instant;

use fresco_core::photo::load_photo;
use fresco_sfm::features::descriptor::sift_descriptor;
use fresco_sfm::features::dog::detect_extrema;
use fresco_sfm::features::extract::{SiftConfig, extract_features};
use fresco_sfm::features::feature_file::write_feature_file;
use fresco_sfm::features::orientation::dominant_orientations;
use fresco_sfm::features::scale_space::{build_scale_space, upsample2};
use rayon::prelude::*;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut runs = 5;
    let mut photos = Vec::new();
    let mut dump = None;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--runs" {
            runs = it.next().and_then(|s| s.parse().ok()).unwrap_or(5);
        } else if a == "--dump" {
            dump = it.next().map(std::path::PathBuf::from);
        } else {
            photos.push(a.clone());
        }
    }
    // OpenCV's defaults (bench/sift.sh compares with cv2.SIFT_create()).
    let config = SiftConfig {
        max_features: 0,
        detector: fresco_sfm::features::dog::DetectorConfig::opencv(),
        ..Default::default()
    };
    for path in &photos {
        let mut t = vec![Vec::new(); 8];
        let mut count = 0;
        for run in 0..=runs {
            if run == 0 {
                let photo = load_photo(std::path::Path::new(path)).expect("readable photo");
                let f = extract_features(&photo.grey, &config);
                if let Some(dir) = &dump {
                    let name = std::path::Path::new(path).file_name().expect("a file name");
                    let out = dir.join(format!("{}.sift", name.to_string_lossy()));
                    write_feature_file(&out, &f).expect("writable dump");
                }
                continue;
            }
            let t0 = Instant::now();
            let photo = load_photo(std::path::Path::new(path)).expect("readable photo");
            t[0].push(t0.elapsed().as_secs_f64());
            let grey = photo.grey;
            let t1 = Instant::now();
            let space = build_scale_space(&grey, &config.scale_space);
            t[1].push(t1.elapsed().as_secs_f64());
            let t2 = Instant::now();
            let extrema = detect_extrema(&space, &config.detector);
            t[2].push(t2.elapsed().as_secs_f64());
            let t3 = Instant::now();
            let oriented: Vec<(usize, f32)> = extrema
                .par_iter()
                .enumerate()
                .flat_map_iter(|(i, e)| {
                    let g = &space.octaves[e.octave].gaussians[e.layer];
                    dominant_orientations(g, e.x, e.y, e.sigma_octave, &config.orientation)
                        .into_iter()
                        .map(move |a| (i, a))
                })
                .collect();
            t[3].push(t3.elapsed().as_secs_f64());
            let t4 = Instant::now();
            let descriptors: Vec<[f32; 128]> = oriented
                .par_iter()
                .map(|&(i, a)| {
                    let e = &extrema[i];
                    let g = &space.octaves[e.octave].gaussians[e.layer];
                    sift_descriptor(g, e.x, e.y, e.sigma_octave, a)
                })
                .collect();
            t[4].push(t4.elapsed().as_secs_f64());
            count = descriptors.len();
            drop(space);
            let t5 = Instant::now();
            let f = extract_features(&grey, &config);
            t[5].push(t5.elapsed().as_secs_f64());
            assert_eq!(f.len(), count);
            // Up-sampling alone (part of scale_space; the rest of it is blurring and decimation).
            let t6 = Instant::now();
            let up = upsample2(&grey);
            t[6].push(t6.elapsed().as_secs_f64());
            drop(up);
            // Writing the feature file (what `fresco features` does after extracting).
            let tmp = std::env::temp_dir().join(format!("sift_phases_{}.sift", std::process::id()));
            let t7 = Instant::now();
            write_feature_file(&tmp, &f).expect("writable temporary file");
            t[7].push(t7.elapsed().as_secs_f64());
            std::fs::remove_file(&tmp).ok();
        }
        let m: Vec<f64> = t.into_iter().map(median).collect();
        println!(
            "{{\"photo\": \"{path}\", \"keypoints\": {count}, \"runs\": {runs}, \"decode\": {:.4}, \
             \"scale_space\": {:.4}, \"dog_extrema\": {:.4}, \"orientation\": {:.4}, \
             \"descriptor\": {:.4}, \"extract_features\": {:.4}, \"upsample\": {:.4}, \
             \"write\": {:.4}, \"threads\": {}}}",
            m[0],
            m[1],
            m[2],
            m[3],
            m[4],
            m[5],
            m[6],
            m[7],
            rayon::current_num_threads()
        );
    }
}
