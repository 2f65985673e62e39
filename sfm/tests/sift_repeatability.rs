//! fresco's SIFT against OpenCV's (reference outputs from datasets/reference/opencv_sift.py,
//! OpenCV 5.0 `cv2.SIFT_create()` defaults, committed under datasets/reference/opencv/).
//!
//! * `keypoints_agree_with_opencv`: on 3 templeSparseRing photos, most OpenCV keypoints have a
//!   fresco keypoint at the same place and a similar scale.
//! * `repeatability_and_precision_match_opencv`: the warped images are rebuilt here exactly as
//!   the script built them (same u8 grey, same float64 bilinear inverse warp, same rounding), so
//!   both detectors see the same pixels; fresco's repeatability and matching precision at 1.5 px
//!   (definitions in the script's docstring, reimplemented below) are compared with OpenCV's
//!   committed figures.
//! * `localisation_per_octave_at_least_opencvs`: the same images under four warps with
//!   sub-pixel translations (shift, scale 0.7 and 1.4, rotation 17 deg; reference from
//!   datasets/reference/opencv_localisation.py, definitions in its docstring): per octave, the
//!   median position error of repeated keypoints matched through the known homography is at
//!   most OpenCV's (+10%), with no systematic offset of fresco's own.
//!
//! Coordinates: OpenCV puts pixel centres at integers, fresco's feature files at half-integers
//! (COLMAP), so fresco positions are shifted by -0.5 here. (OpenCV also reports positions from
//! its 2x up-sampled octave without the -0.25 px centre correction, a constant bias well inside
//! the 1.5 px tolerance.)

use std::path::{Path, PathBuf};

use fresco_core::photo::{GreyImage, load_photo};
use fresco_sfm::features::dog::DetectorConfig;
use fresco_sfm::features::extract::{SiftConfig, extract_features};
use fresco_sfm::features::feature_file::Features;
use rayon::prelude::*;
use serde::Deserialize;

const TOLERANCE: f64 = 1.5;
const MARGIN: f64 = 4.0;
const RATIO: f32 = 0.8;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// u8 grey as the script computes it: round(0.299 R + 0.587 G + 0.114 B), optional crop.
fn grey_u8(path: &Path, crop: Option<[usize; 4]>) -> (Vec<u8>, usize, usize) {
    let photo = load_photo(path).unwrap_or_else(|e| panic!("{e}"));
    let (w, h) = (photo.width() as usize, photo.height() as usize);
    let [x0, y0, cw, ch] = crop.unwrap_or([0, 0, w, h]);
    let mut out = Vec::with_capacity(cw * ch);
    for y in y0..y0 + ch {
        for x in x0..x0 + cw {
            let p = photo.rgb.get_pixel(x as u32, y as u32).0;
            let v = 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64;
            out.push(v.round().clamp(0.0, 255.0) as u8);
        }
    }
    (out, cw, ch)
}

fn to_grey(img: &[u8], w: usize, h: usize) -> GreyImage {
    GreyImage {
        width: w,
        height: h,
        data: img.iter().map(|&v| v as f32 / 255.0).collect(),
    }
}

fn invert(h: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let m = fresco_core::nalgebra::Matrix3::from_fn(|r, c| h[r][c]);
    let inv = m.try_inverse().expect("invertible homography");
    std::array::from_fn(|r| std::array::from_fn(|c| inv[(r, c)]))
}

fn apply(h: &[[f64; 3]; 3], x: f64, y: f64) -> (f64, f64) {
    let d = h[2][0] * x + h[2][1] * y + h[2][2];
    (
        (h[0][0] * x + h[0][1] * y + h[0][2]) / d,
        (h[1][0] * x + h[1][1] * y + h[1][2]) / d,
    )
}

/// The script's `warp_bilinear`: inverse mapping, centres at integers, 0 where the 2x2
/// neighbourhood leaves the image, rounded half up to u8.
fn warp_bilinear(
    img: &[u8],
    w: usize,
    h: usize,
    hom: &[[f64; 3]; 3],
    ow: usize,
    oh: usize,
) -> Vec<u8> {
    let hinv = invert(hom);
    let mut out = vec![0u8; ow * oh];
    for y in 0..oh {
        for x in 0..ow {
            let (xs, ys) = (x as f64, y as f64);
            let den = hinv[2][0] * xs + hinv[2][1] * ys + hinv[2][2];
            let sx = (hinv[0][0] * xs + hinv[0][1] * ys + hinv[0][2]) / den;
            let sy = (hinv[1][0] * xs + hinv[1][1] * ys + hinv[1][2]) / den;
            let (x0, y0) = (sx.floor(), sy.floor());
            if !(x0 >= 0.0 && y0 >= 0.0 && x0 + 1.0 <= (w - 1) as f64 && y0 + 1.0 <= (h - 1) as f64)
            {
                continue;
            }
            let (fx, fy) = (sx - x0, sy - y0);
            let (xi, yi) = (x0 as usize, y0 as usize);
            let f = |xx: usize, yy: usize| img[yy * w + xx] as f64;
            let v = (1.0 - fx) * (1.0 - fy) * f(xi, yi)
                + fx * (1.0 - fy) * f(xi + 1, yi)
                + (1.0 - fx) * fy * f(xi, yi + 1)
                + fx * fy * f(xi + 1, yi + 1);
            out[y * ow + x] = (v + 0.5).floor().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// All keypoints (no limit, like OpenCV's default) at OpenCV's contrast threshold, in
/// OpenCV's coordinates.
fn detect(img: &[u8], w: usize, h: usize) -> (Vec<(f64, f64)>, Features) {
    let mut config = SiftConfig {
        max_features: 0,
        // OpenCV's detector has one fixed threshold: no adaptive detection.
        min_features_per_megapixel: 0,
        detector: DetectorConfig::opencv(),
        ..Default::default()
    };
    // OpenCV keeps keypoints on an outline against a black background (the warped images'
    // black margins): so does the comparison.
    config.plain_background.drop_on_smooth_outline = false;
    let f = extract_features(&to_grey(img, w, h), &config);
    let pts = f
        .keypoints
        .iter()
        .map(|k| (k.x as f64 - 0.5, k.y as f64 - 0.5))
        .collect();
    (pts, f)
}

fn visible(p: (f64, f64), hom: &[[f64; 3]; 3], src: (usize, usize), dst: (usize, usize)) -> bool {
    let inside = |(x, y): (f64, f64), (w, h): (usize, usize)| {
        x >= MARGIN && x <= (w - 1) as f64 - MARGIN && y >= MARGIN && y <= (h - 1) as f64 - MARGIN
    };
    inside(p, src) && inside(apply(hom, p.0, p.1), dst)
}

fn unique(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut keys: Vec<(i64, i64)> = points
        .iter()
        .map(|p| ((p.0 * 1000.0).round() as i64, (p.1 * 1000.0).round() as i64))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys.into_iter()
        .map(|(x, y)| (x as f64 / 1000.0, y as f64 / 1000.0))
        .collect()
}

/// (repeatability, precision, ratio-test matches), the script's definitions.
fn scores(
    k1: &[(f64, f64)],
    f1: &Features,
    k2: &[(f64, f64)],
    f2: &Features,
    hom: &[[f64; 3]; 3],
    size1: (usize, usize),
    size2: (usize, usize),
) -> (f64, f64, usize) {
    let hinv = invert(hom);
    let v1: Vec<usize> = (0..k1.len())
        .filter(|&i| visible(k1[i], hom, size1, size2))
        .collect();
    let v2: Vec<usize> = (0..k2.len())
        .filter(|&i| visible(k2[i], &hinv, size2, size1))
        .collect();
    let u1 = unique(&v1.iter().map(|&i| k1[i]).collect::<Vec<_>>());
    let u2 = unique(&v2.iter().map(|&i| k2[i]).collect::<Vec<_>>());
    if u1.is_empty() || u2.is_empty() {
        return (0.0, 0.0, 0);
    }
    let repeated = u1
        .iter()
        .filter(|p| {
            let m = apply(hom, p.0, p.1);
            u2.iter().any(|q| (m.0 - q.0).hypot(m.1 - q.1) <= TOLERANCE)
        })
        .count();
    let repeatability = repeated as f64 / u1.len().min(u2.len()) as f64;
    // Brute-force ratio test on the u8 descriptors (L2, like cv2.BFMatcher on OpenCV's floats).
    let d2: Vec<[f32; 128]> = v2
        .iter()
        .map(|&j| f2.descriptors[j].map(|v| v as f32))
        .collect();
    let outcomes: Vec<Option<bool>> = v1
        .par_iter()
        .map(|&i| {
            let a = f1.descriptors[i].map(|v| v as f32);
            let (mut best, mut second, mut arg) = (f32::MAX, f32::MAX, 0);
            for (j, b) in d2.iter().enumerate() {
                let d: f32 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
                if d < best {
                    second = best;
                    best = d;
                    arg = j;
                } else if d < second {
                    second = d;
                }
            }
            if d2.len() < 2 || best.sqrt() >= RATIO * second.sqrt() {
                return None;
            }
            let m = apply(hom, k1[i].0, k1[i].1);
            let q = k2[v2[arg]];
            Some((m.0 - q.0).hypot(m.1 - q.1) <= TOLERANCE)
        })
        .collect();
    let total = outcomes.iter().flatten().count();
    let correct = outcomes.iter().flatten().filter(|&&c| c).count();
    let precision = if total > 0 {
        correct as f64 / total as f64
    } else {
        0.0
    };
    (repeatability, precision, total)
}

#[derive(Deserialize)]
struct Record {
    images: Vec<ImageRecord>,
}

#[derive(Deserialize)]
struct ImageRecord {
    name: String,
    path: String,
    crop: Option<[usize; 4]>,
    warps: Vec<WarpRecord>,
}

#[derive(Deserialize)]
struct WarpRecord {
    name: String,
    homography: [[f64; 3]; 3],
    width: usize,
    height: usize,
    brightness: bool,
    repeatability: f64,
    precision: f64,
}

#[test]
fn repeatability_and_precision_match_opencv() {
    let text = std::fs::read_to_string(root().join("datasets/reference/opencv/sift_warps.json"))
        .expect("reference file");
    let record: Record = serde_json::from_str(&text).expect("reference json");
    let mut rows = Vec::new();
    for image in &record.images {
        let (g, w, h) = grey_u8(&root().join(&image.path), image.crop);
        let (k1, f1) = detect(&g, w, h);
        for warp in &image.warps {
            let mut img = warp_bilinear(&g, w, h, &warp.homography, warp.width, warp.height);
            if warp.brightness {
                for v in &mut img {
                    *v = (0.7 * *v as f64 + 20.0 + 0.5).floor().clamp(0.0, 255.0) as u8;
                }
            }
            let (k2, f2) = detect(&img, warp.width, warp.height);
            let (rep, prec, n) = scores(
                &k1,
                &f1,
                &k2,
                &f2,
                &warp.homography,
                (w, h),
                (warp.width, warp.height),
            );
            println!(
                "{} {:<12} repeatability {:.3} (OpenCV {:.3})  precision {:.3} (OpenCV {:.3})  \
                 {} matches",
                image.name, warp.name, rep, warp.repeatability, prec, warp.precision, n
            );
            // Each figure is a proportion over 300-2000 keypoints or matches, so one keypoint
            // moves it by 0.0005-0.003 and two faithful implementations of the same detector
            // differ by about that much per warp (fresco and OpenCV differ in the up-sampling
            // centre offset, fast-atan2/exp details, border handling). Per warp fresco must be
            // within 0.02 (about ten keypoints) of OpenCV; on the mean over all warps within
            // 0.002, i.e. at least OpenCV's up to about one keypoint per warp.
            assert!(
                rep >= warp.repeatability - 0.02 && prec >= warp.precision - 0.02,
                "{} {}: repeatability {rep:.3} (OpenCV {:.3}), precision {prec:.3} (OpenCV {:.3})",
                image.name,
                warp.name,
                warp.repeatability,
                warp.precision
            );
            rows.push([rep, prec, warp.repeatability, warp.precision]);
        }
    }
    let mean = |i: usize| rows.iter().map(|r| r[i]).sum::<f64>() / rows.len() as f64;
    let (rep, prec, cv_rep, cv_prec) = (mean(0), mean(1), mean(2), mean(3));
    println!(
        "mean repeatability {rep:.4} (OpenCV {cv_rep:.4}), precision {prec:.4} (OpenCV {cv_prec:.4})"
    );
    assert!(
        rep >= cv_rep - 0.002,
        "mean repeatability {rep:.4} < OpenCV {cv_rep:.4} - 0.002"
    );
    assert!(
        prec >= cv_prec - 0.002,
        "mean precision {prec:.4} < OpenCV {cv_prec:.4} - 0.002"
    );
}

#[test]
fn keypoints_agree_with_opencv() {
    for name in ["templeSR0001", "templeSR0005", "templeSR0009"] {
        let text = std::fs::read_to_string(root().join(format!(
            "datasets/reference/opencv/sift_keypoints_{name}.txt"
        )))
        .expect("reference keypoints");
        // (x, y, sigma) with sigma = size / 2.
        let cv: Vec<(f64, f64, f64)> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| {
                let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
                (v[0], v[1], v[2] / 2.0)
            })
            .collect();
        let (g, w, h) = grey_u8(
            &root().join(format!("datasets/templeSparseRing/{name}.png")),
            None,
        );
        let (pts, f) = detect(&g, w, h);
        // Same place (1.5 px) and similar scale (within a factor 1.5, i.e. about one interval
        // of 2^(1/3) either way plus refinement noise).
        let found = cv
            .iter()
            .filter(|c| {
                pts.iter().zip(&f.keypoints).any(|(p, k)| {
                    let ratio = k.scale as f64 / c.2;
                    (p.0 - c.0).hypot(p.1 - c.1) <= TOLERANCE && (1.0 / 1.5..=1.5).contains(&ratio)
                })
            })
            .count();
        let share = found as f64 / cv.len() as f64;
        println!(
            "{name}: OpenCV {} keypoints, fresco {}, {:.1}% of OpenCV's found by fresco",
            cv.len(),
            f.len(),
            100.0 * share
        );
        assert!(share >= 0.6, "{name}: only {:.1}% found", 100.0 * share);
        // Comparable counts: within a factor 1.5 of OpenCV's.
        let ratio = f.len() as f64 / cv.len() as f64;
        assert!(
            (1.0 / 1.5..=1.5).contains(&ratio),
            "{name}: count ratio {ratio:.2}"
        );
    }
}

#[derive(Deserialize)]
struct LocalisationRecord {
    images: Vec<LocalisationImage>,
    pooled: Vec<OctaveStats>,
}

#[derive(Deserialize)]
struct LocalisationImage {
    path: String,
    crop: Option<[usize; 4]>,
    warps: Vec<LocalisationWarp>,
}

#[derive(Deserialize)]
struct LocalisationWarp {
    homography: [[f64; 3]; 3],
    width: usize,
    height: usize,
}

#[derive(Deserialize)]
struct OctaveStats {
    octave: usize,
    repeats: usize,
    median_error_px: Option<f64>,
    mean_dx_px: Option<f64>,
    mean_dy_px: Option<f64>,
}

/// `(octave, error, dx, dy)` of each visible source keypoint with a repeat, the definitions of
/// datasets/reference/opencv_localisation.py: nearest warped keypoint of a consistent scale
/// (factor 1.3 of sigma times the warp's scale) within max(1.5, 0.75 sigma) source pixels,
/// errors measured after mapping it back by H⁻¹.
fn localisation_errors(
    k1: &[(f64, f64)],
    s1: &[f64],
    k2: &[(f64, f64)],
    s2: &[f64],
    hom: &[[f64; 3]; 3],
    size1: (usize, usize),
    size2: (usize, usize),
) -> Vec<(usize, f64, f64, f64)> {
    let hinv = invert(hom);
    let sh = (hom[0][0] * hom[1][1] - hom[0][1] * hom[1][0]).abs().sqrt();
    let back: Vec<(f64, f64)> = k2.iter().map(|p| apply(&hinv, p.0, p.1)).collect();
    let mut out = Vec::new();
    for (i, &p) in k1.iter().enumerate() {
        if !visible(p, hom, size1, size2) {
            continue;
        }
        let mut best: Option<(f64, f64, f64)> = None;
        for (q, &sq) in back.iter().zip(s2) {
            let ratio = sq / (s1[i] * sh);
            if !(1.0 / 1.3..=1.3).contains(&ratio) {
                continue;
            }
            let (dx, dy) = (q.0 - p.0, q.1 - p.1);
            let d = dx.hypot(dy);
            if best.is_none_or(|b| d < b.0) {
                best = Some((d, dx, dy));
            }
        }
        let Some((d, dx, dy)) = best else { continue };
        if d > (0.75 * s1[i]).max(1.5) {
            continue;
        }
        let octave = (s1[i] / 0.8).log2().floor().clamp(0.0, 4.0) as usize;
        out.push((octave, d, dx, dy));
    }
    out
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[test]
fn localisation_per_octave_at_least_opencvs() {
    let text =
        std::fs::read_to_string(root().join("datasets/reference/opencv/sift_localisation.json"))
            .expect("reference file");
    let record: LocalisationRecord = serde_json::from_str(&text).expect("reference json");
    let mut rows = Vec::new();
    for image in &record.images {
        let (g, w, h) = grey_u8(&root().join(&image.path), image.crop);
        let (k1, f1) = detect(&g, w, h);
        let s1: Vec<f64> = f1.keypoints.iter().map(|k| k.scale as f64).collect();
        for warp in &image.warps {
            let img = warp_bilinear(&g, w, h, &warp.homography, warp.width, warp.height);
            let (k2, f2) = detect(&img, warp.width, warp.height);
            let s2: Vec<f64> = f2.keypoints.iter().map(|k| k.scale as f64).collect();
            rows.extend(localisation_errors(
                &k1,
                &s1,
                &k2,
                &s2,
                &warp.homography,
                (w, h),
                (warp.width, warp.height),
            ));
        }
    }
    for cv in &record.pooled {
        let mut e: Vec<f64> = rows
            .iter()
            .filter(|r| r.0 == cv.octave)
            .map(|r| r.1)
            .collect();
        let n = e.len();
        let bias = |k: usize| {
            rows.iter()
                .filter(|r| r.0 == cv.octave)
                .map(|r| if k == 0 { r.2 } else { r.3 })
                .sum::<f64>()
                / n.max(1) as f64
        };
        let (bx, by) = (bias(0), bias(1));
        let ours = if n > 0 { median(&mut e) } else { f64::NAN };
        let theirs = cv.median_error_px.unwrap_or(f64::NAN);
        println!(
            "octave {}: fresco {n} repeats, median error {ours:.3} px, mean error ({bx:+.3}, \
             {by:+.3}); OpenCV {} repeats, median {theirs:.3} px",
            cv.octave, cv.repeats
        );
        // Octaves with at least 300 repeats on both sides (0-3 here): the median of n
        // errors with this spread has a relative standard error of about 1.25 / sqrt(n), under
        // 7% at n = 300; fresco must be within 10% of OpenCV's median (the coarsest octave,
        // ~200 repeats of a few large blobs, is printed only).
        if n >= 300 && cv.repeats >= 300 {
            assert!(
                ours <= 1.1 * theirs,
                "octave {}: fresco median error {ours:.3} px, OpenCV {theirs:.3} px",
                cv.octave
            );
            // No systematic offset of fresco's own: a half-pixel convention slip between
            // octaves shows as a mean error of 0.25-0.5 px. Measured: under 0.04 px in octaves
            // 0-2; octave 3 has (+0.10, -0.03) px and OpenCV (+0.12, -0.03), an offset both
            // detectors share, so it comes from the images (a few hundred coarse blobs), not
            // from a convention: fresco's may exceed 0.1 px only as far as OpenCV's does, plus
            // 0.03 px (twice the standard error of a mean of 500 errors of ~0.3 px).
            let cv_bias = cv
                .mean_dx_px
                .unwrap_or(0.0)
                .hypot(cv.mean_dy_px.unwrap_or(0.0));
            assert!(
                bx.hypot(by) < cv_bias.max(0.07) + 0.03,
                "octave {}: bias ({bx}, {by}), OpenCV's {cv_bias}",
                cv.octave
            );
        }
    }
    let mut all: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let ours = median(&mut all);
    println!(
        "all octaves: fresco {} repeats, median error {ours:.3} px",
        all.len()
    );
}
