//! Track refinement by multi-view patch alignment: each track's keypoints are moved so that
//! they show the same surface point as one reference observation, before the final bundle
//! adjustment.
//!
//! Why: a DoG keypoint is the centre of a blob in the image. On a curved surface seen at a
//! slant the blob's image is foreshortened differently in every view, so the detected
//! positions of one track are not the projections of one fixed 3D point; the view-dependent
//! part of that error is structured (issue 18, session 11: on the rendered torus it pulls the
//! self-calibrated focal length 5-12% short, and none of it is the estimator's). Aligning
//! patches instead of detecting blobs ties every observation to the surface point under the
//! reference keypoint, to first order in the surface's curvature over the patch (the local
//! image-to-image map of a smooth surface is affine).
//!
//! Method (the Lucas-Kanade alignment with an affine warp, invariant to a photometric gain
//! and bias, by Baker & Matthews' inverse-compositional algorithm, 2004, "Lucas-Kanade 20
//! years on", section 3.2, with the appearance projected out as in section 7.2; the same
//! multi-view keypoint adjustment as Lindenberger et al. 2021, "Pixel-Perfect
//! Structure-from-Motion", section 4, on intensities instead of dense features):
//! - per track, the reference is the observation of the largest keypoint scale (the view that
//!   sees the surface largest, so it is the nearest or the most frontal); ties by image id;
//! - the reference patch is a (2n+1)^2 grid of samples spanning +-`window_scales` keypoint
//!   scales, read on the image level whose blur is about half the keypoint's scale
//!   ([`ImagePyramid`]), normalised to zero mean and unit variance under a Gaussian window;
//!   its steepest-descent images and their 6x6 Hessian are computed once per track;
//! - for every other observation, the warp `x = c + A u` (u: offset from the reference
//!   keypoint, pixels of the reference image) is estimated from `c` = the current keypoint
//!   and `A` = the similarity of the two keypoints' SIFT scales and orientations; each
//!   iteration only samples the target;
//! - the keypoint moves to `c` (the reference centre's image) when the alignment converged
//!   within `max_iterations`, its normalised cross-correlation is at least `min_ncc`, the
//!   shift is at most `max_shift_scales` keypoint scales and `A` stays a plausible affinity;
//! - otherwise the observation leaves the track (and a point left with fewer than two
//!   observations goes): kept, it would show another surface point than the aligned ones,
//!   the detector's view-dependent error that the refinement removes. Measured on the
//!   rendered torus at 640x480 (session 12, true projections of the reference keypoint's
//!   surface point substituted in turn): with the 9% unaligned observations kept, the focal
//!   length came out 2.7% short; with them exact, +0.7%; with the aligned ones exact, -1.8%;
//!   with the unaligned ones removed, -0.5% (session 11's forward-additive alignment); in
//!   the pipeline (this alignment, 30 iterations), -3.2% kept, -1.4% removed.
//!
//! Tracks are independent: they are refined in parallel (rayon) and the moves applied in
//! point-id order, so the result does not depend on the thread count.

use std::collections::HashMap;

use fresco_core::Reconstruction;
use fresco_core::config::{ConfigError, require};
use fresco_core::photo::GreyImage;
use nalgebra::{Matrix2, Point2, SMatrix, SVector, Vector2};
use rayon::prelude::*;

use crate::features::scale_space::{decimate2, gaussian_blur};

/// When the sfm stage refines the tracks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum TrackRefinementMode {
    /// Never.
    Off,
    /// When some photo gives no focal length (no EXIF, no calibration file: the default prior
    /// or its estimate from the fundamental matrices), so that the adjustment estimates it
    /// from the keypoints alone and their view-dependent error biases it (issue 18). Photo
    /// sets with EXIF or a K file are left as they were, bit for bit.
    WhenFocalEstimated,
    /// Always.
    Always,
}

/// Settings of [`refine_tracks`].
#[derive(Clone, Debug, PartialEq)]
pub struct TrackRefinementConfig {
    /// When to refine the keypoints of every track and adjust the model again. Default:
    /// `Off` ([`TrackRefinementMode::Off`]). Measured (session 12): `Always` or
    /// `WhenFocalEstimated` brings issue 18's 4x focal within 2% (rendered torus, 640x480,
    /// 6 of 6 seeds; 320x240, the CI scene, 0.04%) and improves every hard case, but
    /// templeSparseRing's default runs have no EXIF and no K file, so `WhenFocalEstimated`
    /// refines them too: median rotation 0.797 -> 0.854 degrees (max 1.040 -> 1.030, focal
    /// 3.6% -> 3.1% off) and the sfm stage +0.5 CPU-s (+12% of the reconstruction), against
    /// the "unchanged or better, within 10%" for the bundled sets.
    pub mode: TrackRefinementMode,
    /// Half-width of the aligned patch, in reference keypoint scales (Gaussian sigmas).
    /// Default: `4.0`: the blob (its Gaussian falls to 1% at 3 scales) and its surroundings.
    /// Measured on the rendered torus of issue 18 at 640x480, focal error over 4 seeds (mean):
    /// 2.5 scales -2.2%, 3: -2.1%, 4: -1.7%, 5: -2.2% (session 12, 30 iterations; without
    /// refinement -3.6% over 6 seeds; the noise-only spread is about 1%).
    pub window_scales: f64,
    /// Samples per half-width of the patch (the patch has (2n+1)^2). Default: `7`.
    pub half_samples: usize,
    /// Smallest normalised cross-correlation of an accepted alignment. Default: `0.8`.
    pub min_ncc: f64,
    /// Largest move of a keypoint, in its keypoint scales. Default: `1.0`.
    pub max_shift_scales: f64,
    /// Most inverse-compositional iterations per observation; an alignment that has not
    /// converged (centre and patch corners still moving by 1/1000 px) is not used and its
    /// observation leaves the track. Default: `10`. Measured (session 12, rendered torus,
    /// focal error, mean over 6 seeds): 640x480 -1.6% with 30, -1.4% with 15, -1.0% with 10;
    /// 320x240 -6.0% / -5.7% / -3.3%; the synthetic temple at 640x480 -2.1% / -0.7% / -0.7%:
    /// leaving out the slowly converging alignments helps on these synthetic scenes (10 leaves
    /// 79% of the observations aligned, 30 leaves 91%), not on the real templeSparseRing
    /// (median rotation 0.854 / 0.821 / 0.817 degrees with 10 / 15 / 30).
    pub max_iterations: usize,
}

impl Default for TrackRefinementConfig {
    fn default() -> Self {
        TrackRefinementConfig {
            mode: TrackRefinementMode::Off,
            window_scales: 4.0,
            half_samples: 7,
            min_ncc: 0.8,
            max_shift_scales: 1.0,
            max_iterations: 10,
        }
    }
}

impl TrackRefinementConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.window_scales.is_finite() && self.window_scales > 0.0,
            "window_scales",
            self.window_scales,
            "finite and > 0",
        )?;
        require(
            self.half_samples >= 2,
            "half_samples",
            self.half_samples,
            ">= 2",
        )?;
        require(
            self.min_ncc.is_finite() && self.min_ncc <= 1.0,
            "min_ncc",
            self.min_ncc,
            "finite and <= 1",
        )?;
        require(
            self.max_shift_scales.is_finite() && self.max_shift_scales > 0.0,
            "max_shift_scales",
            self.max_shift_scales,
            "finite and > 0",
        )?;
        require(
            self.max_iterations >= 1,
            "max_iterations",
            self.max_iterations,
            ">= 1",
        )
    }
}

/// A photo's grey levels at blurs 0.8 * 2^k pixels, level k kept every 2^k pixels (Lowe's
/// octaves without the intervals): level k's pixel i lies at `2^k i + 0.5` in COLMAP's
/// convention (pixel centres at half-integers), since [`decimate2`] keeps pixel 2i.
#[derive(Clone, Debug)]
pub struct ImagePyramid {
    levels: Vec<GreyImage>,
}

/// The blur of level 0 relative to the photo's own (assumed 0.5 px, Lowe's camera blur).
const LEVEL0_BLUR: f64 = 0.8;

impl ImagePyramid {
    /// Levels until the short side falls below 16 pixels.
    pub fn new(grey: &GreyImage) -> ImagePyramid {
        let first = gaussian_blur(grey, (LEVEL0_BLUR * LEVEL0_BLUR - 0.25).sqrt() as f32);
        let mut levels = vec![first];
        loop {
            let last = levels.last().expect("one level");
            if last.width.min(last.height) < 32 {
                break;
            }
            // Level k has blur 0.8 of its own pixels; 1.6 before keeping every second pixel
            // becomes 0.8 after: add sqrt(1.6^2 - 0.8^2).
            let blurred = gaussian_blur(last, (3.0f64 * LEVEL0_BLUR * LEVEL0_BLUR).sqrt() as f32);
            levels.push(decimate2(&blurred));
        }
        ImagePyramid { levels }
    }

    /// The level for a keypoint of scale `sigma` (pixels): the coarsest whose blur
    /// (0.8 * 2^k) is at most half of it, so the patch keeps the blob's detail while its
    /// (2n+1)^2 samples stay at most about one level pixel apart.
    fn level_for(&self, sigma: f64) -> usize {
        let k = (sigma / (2.0 * LEVEL0_BLUR)).log2().floor();
        (k.max(0.0) as usize).min(self.levels.len() - 1)
    }

    /// Grey level at photo position `p` (COLMAP's convention) on `level`, bilinear; None
    /// where [`ImagePyramid::sample`] is None (the same area, so both agree on failures).
    fn value(&self, level: usize, p: Vector2<f64>) -> Option<f64> {
        let (img, x, y, _) = self.level_position(level, p)?;
        Some(bilinear(img, x, y))
    }

    /// `level`'s image, photo position `p` (COLMAP's convention) in that level's pixels, and
    /// the level's pixel size in photo pixels; None unless the bilinear 2x2 cell and a
    /// half-pixel stencil around it lie inside the image.
    fn level_position(&self, level: usize, p: Vector2<f64>) -> Option<(&GreyImage, f64, f64, f64)> {
        let img = &self.levels[level];
        let step = f64::from(1u32 << level);
        let (x, y) = ((p.x - 0.5) / step, (p.y - 0.5) / step);
        let inside = |v: f64, n: usize| v >= 1.0 && v <= n as f64 - 2.0;
        (inside(x, img.width) && inside(y, img.height)).then_some((img, x, y, step))
    }

    /// Grey level and gradient (per photo pixel) at photo position `p` (COLMAP's convention)
    /// on `level`, bilinear; None outside the area where the 2x2 cell and the gradient's
    /// half-pixel stencil are inside the image.
    fn sample(&self, level: usize, p: Vector2<f64>) -> Option<(f64, Vector2<f64>)> {
        let (img, x, y, step) = self.level_position(level, p)?;
        let value = |x: f64, y: f64| bilinear(img, x, y);
        // Central differences over one level pixel, per photo pixel.
        let gx = (value(x + 0.5, y) - value(x - 0.5, y)) / step;
        let gy = (value(x, y + 0.5) - value(x, y - 0.5)) / step;
        Some((value(x, y), Vector2::new(gx, gy)))
    }
}

/// Bilinear interpolation of `img` at level-pixel coordinates `(x, y)` (pixel i at i), inside
/// the image.
fn bilinear(img: &GreyImage, x: f64, y: f64) -> f64 {
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let (x1, y1) = ((x0 + 1).min(img.width - 1), (y0 + 1).min(img.height - 1));
    let at = |i, j| f64::from(img.at(i, j));
    let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
    let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// A keypoint's detection scale (Gaussian sigma, pixels) and orientation (radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeypointShape {
    pub scale: f64,
    pub orientation: f64,
}

/// One image's data for [`refine_tracks`]: its pyramid and the shape of each keypoint (by
/// keypoint index, as the model's `point2d_idx`).
#[derive(Clone, Debug)]
pub struct RefinementImage {
    pub pyramid: ImagePyramid,
    pub shapes: Vec<KeypointShape>,
}

/// What [`refine_tracks`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TrackRefinementSummary {
    /// Tracks with a usable reference patch.
    pub tracks: usize,
    /// Observations aligned (every track's but its reference).
    pub observations: usize,
    /// Keypoints moved.
    pub moved: usize,
    /// Kept: the patch left the image, or Gauss-Newton did not converge or degenerated.
    pub failed: usize,
    /// Kept: correlation below `min_ncc`.
    pub low_ncc: usize,
    /// Kept: shift beyond `max_shift_scales` or an implausible affinity.
    pub too_far: usize,
    /// Root mean square of the accepted moves, pixels.
    pub rms_shift_px: f64,
    /// Points removed because fewer than two observations were left: the observations that
    /// could not be aligned are taken out of their tracks (see [`refine_tracks`]).
    pub points_removed: usize,
}

/// The reference patch and what the inverse-compositional alignment needs from it: its offsets
/// `u` (reference photo pixels), weights, normalised values `T(u)`, the steepest-descent
/// images of the six affine parameters with the appearance (constant and `T` itself)
/// projected out, and the Cholesky factor of their Hessian (computed once per track).
struct Template {
    offsets: Vec<Vector2<f64>>,
    weights: Vec<f64>,
    values: Vec<f64>,
    steepest: Vec<SVector<f64, 6>>,
    hessian: nalgebra::Cholesky<f64, nalgebra::Const<6>>,
    /// Half-width of the patch (reference photo pixels), for the convergence test.
    half: f64,
}

/// Samples the reference patch around `centre` at the level of `shape`, normalises it to
/// zero weighted mean and unit weighted variance, and precomputes the inverse-compositional
/// steepest-descent images (Baker & Matthews 2004, section 3.2, eq. 31-36: `∇T ∂W/∂p` at
/// `p = 0`, the affine warp's Jacobian being `[1 0 u_x u_y 0 0; 0 1 0 0 u_x u_y]`) with the
/// linear appearance variation projected out (section 7.2, "project out": the span of the
/// constant image, a bias, and of `T`, a gain; both w-orthogonal since `T` has zero weighted
/// mean) and their Hessian; None when the patch leaves the image, is flat or has no
/// two-dimensional texture.
fn reference_template(
    image: &RefinementImage,
    centre: Vector2<f64>,
    shape: KeypointShape,
    config: &TrackRefinementConfig,
) -> Option<Template> {
    let level = image.pyramid.level_for(shape.scale);
    let n = config.half_samples as i64;
    let half = config.window_scales * shape.scale;
    let step = half / n as f64;
    // Gaussian weights of sigma half/2: the centre, where the surface is nearest to the
    // affine model, counts most.
    let sw = half / 2.0;
    let count = ((2 * n + 1) * (2 * n + 1)) as usize;
    let mut offsets = Vec::with_capacity(count);
    let mut weights = Vec::with_capacity(count);
    let mut values = Vec::with_capacity(count);
    let mut gradients = Vec::with_capacity(count);
    for j in -n..=n {
        for i in -n..=n {
            let u = Vector2::new(i as f64 * step, j as f64 * step);
            let (v, g) = image.pyramid.sample(level, centre + u)?;
            offsets.push(u);
            weights.push((-u.norm_squared() / (2.0 * sw * sw)).exp());
            values.push(v);
            gradients.push(g);
        }
    }
    let (mean, sd) = weighted_moments(&weights, &values);
    if sd < 1e-4 {
        return None;
    }
    for v in &mut values {
        *v = (*v - mean) / sd;
    }
    let mut steepest: Vec<SVector<f64, 6>> = offsets
        .iter()
        .zip(&gradients)
        .map(|(u, g)| {
            let g = g / sd;
            SVector::<f64, 6>::from([g.x, g.y, g.x * u.x, g.x * u.y, g.y * u.x, g.y * u.y])
        })
        .collect();
    // Project out the bias (the constant image) and the gain (T): with weighted mean 0 and
    // weighted variance 1 of T, the projections are the weighted means of SD and of SD T.
    let wsum: f64 = weights.iter().sum();
    let mut along_one = SVector::<f64, 6>::zeros();
    let mut along_t = SVector::<f64, 6>::zeros();
    for ((sd_u, &w), &t) in steepest.iter().zip(&weights).zip(&values) {
        along_one += w * sd_u;
        along_t += w * t * sd_u;
    }
    along_one /= wsum;
    along_t /= wsum;
    let mut h = SMatrix::<f64, 6, 6>::zeros();
    for ((sd_u, &w), &t) in steepest.iter_mut().zip(&weights).zip(&values) {
        *sd_u -= along_one + t * along_t;
        h += w * *sd_u * sd_u.transpose();
    }
    let hessian = h.cholesky()?;
    Some(Template {
        offsets,
        weights,
        values,
        steepest,
        hessian,
        half,
    })
}

/// Weighted mean and standard deviation.
fn weighted_moments(weights: &[f64], values: &[f64]) -> (f64, f64) {
    let wsum: f64 = weights.iter().sum();
    let mean = weights.iter().zip(values).map(|(w, v)| w * v).sum::<f64>() / wsum;
    let var = weights
        .iter()
        .zip(values)
        .map(|(w, v)| w * (v - mean) * (v - mean))
        .sum::<f64>()
        / wsum;
    (mean, var.max(0.0).sqrt())
}

/// Outcome of one alignment.
enum Alignment {
    Moved(Vector2<f64>),
    Failed,
    LowNcc,
    TooFar,
}

/// Aligns `template` into `image` over the warp `x = c + A u`, invariant to a gain and bias
/// (see the module documentation), by Baker & Matthews' inverse-compositional algorithm
/// (2004, section 3.2): every iteration samples the target only (values, no gradients),
/// normalises the samples to the template's weighted mean and variance (so that the step,
/// computed in the template's units, is not scaled by the photometric gain), solves with the
/// template's precomputed Hessian and composes the warp with the inverse of the step,
/// `W <- W o W(dp)^-1` (eq. 33). At the fixed point the projected-out steepest-descent
/// images are uncorrelated with the target's samples, which holds at the true warp for any
/// gain and bias. `start` is the keypoint, `shape` its shape, `a0` the initial affinity.
fn align(
    template: &Template,
    image: &RefinementImage,
    start: Vector2<f64>,
    shape: KeypointShape,
    a0: Matrix2<f64>,
    config: &TrackRefinementConfig,
) -> Alignment {
    let level = image.pyramid.level_for(shape.scale);
    let mut c = start;
    let mut a = a0;
    let mut samples = vec![0.0; template.offsets.len()];
    let mut converged = false;
    let mut ncc = f64::NEG_INFINITY;
    for _ in 0..config.max_iterations {
        for (s, u) in samples.iter_mut().zip(&template.offsets) {
            match image.pyramid.value(level, c + a * u) {
                Some(v) => *s = v,
                None => return Alignment::Failed,
            }
        }
        let (mean, sd) = weighted_moments(&template.weights, &samples);
        if sd < 1e-4 {
            return Alignment::Failed;
        }
        let mut rhs = SVector::<f64, 6>::zeros();
        let mut correlation = 0.0;
        for (((s, &w), &t), sd_u) in samples
            .iter()
            .zip(&template.weights)
            .zip(&template.values)
            .zip(&template.steepest)
        {
            let v = (s - mean) / sd;
            rhs += w * (v - t) * sd_u;
            correlation += w * v * t;
        }
        ncc = correlation / template.weights.iter().sum::<f64>();
        let delta = template.hessian.solve(&rhs);
        if !delta.iter().all(|d| d.is_finite()) {
            return Alignment::Failed;
        }
        let dc = Vector2::new(delta[0], delta[1]);
        let da = Matrix2::new(delta[2], delta[3], delta[4], delta[5]);
        // W(u) o W(u; dp)^-1 = c + A (I + dA)^-1 (u - dc).
        let Some(inv) = (Matrix2::identity() + da).try_inverse() else {
            return Alignment::Failed;
        };
        let a_new = a * inv;
        let c_step = a_new * dc;
        c -= c_step;
        a = a_new;
        // Converged when the centre and the patch's corners move by under 1/1000 px.
        if c_step.norm() < 1e-3 && (a * da).norm() * template.half < 1e-3 {
            converged = true;
            break;
        }
    }
    if !converged {
        return Alignment::Failed;
    }
    // The affinity must stay near the scale ratio the detector saw (within 2x either way per
    // direction) and keep the orientation of the plane (no mirror).
    let expected = a0.determinant().abs().sqrt();
    let sv = a.singular_values();
    if a.determinant() <= 0.0 || sv[0] > 2.0 * expected || sv[1] < 0.5 * expected {
        return Alignment::TooFar;
    }
    if (c - start).norm() > config.max_shift_scales * shape.scale {
        return Alignment::TooFar;
    }
    // Normalised cross-correlation under the window, of the last samples (the final step
    // moved them by under 1/1000 px).
    if ncc < config.min_ncc {
        return Alignment::LowNcc;
    }
    Alignment::Moved(c)
}

/// The similarity that maps the reference keypoint's frame onto another's: scale ratio and
/// orientation difference (SIFT's affine-covariant frame reduced to a similarity).
fn similarity_between(reference: KeypointShape, other: KeypointShape) -> Matrix2<f64> {
    let s = other.scale / reference.scale;
    let (sin, cos) = (other.orientation - reference.orientation).sin_cos();
    Matrix2::new(s * cos, -s * sin, s * sin, s * cos)
}

/// Moves the keypoints of every track of `rec` onto the image of its reference keypoint (see
/// the module documentation). `images` by image id; observations of images missing from it,
/// or whose keypoint index has no shape, are left alone.
pub fn refine_tracks(
    rec: &mut Reconstruction,
    images: &HashMap<u32, RefinementImage>,
    config: &TrackRefinementConfig,
) -> TrackRefinementSummary {
    let tracks: Vec<(u64, Vec<(u32, u32)>)> = rec
        .points3d
        .values()
        .map(|p| {
            (
                p.id,
                p.track
                    .iter()
                    .map(|el| (el.image_id, el.point2d_idx))
                    .collect(),
            )
        })
        .collect();
    let keypoint = |image_id: u32, idx: u32| -> Option<(Vector2<f64>, KeypointShape)> {
        let shape = *images.get(&image_id)?.shapes.get(idx as usize)?;
        let p = rec.images.get(&image_id)?.keypoints.get(idx as usize)?;
        Some((p.coords, shape))
    };
    type Outcome = (bool, Vec<(u32, u32, Alignment)>);
    let outcomes: Vec<Outcome> = tracks
        .par_iter()
        .map(|(_, track)| {
            let observed: Vec<(u32, u32, Vector2<f64>, KeypointShape)> = track
                .iter()
                .filter_map(|&(im, idx)| keypoint(im, idx).map(|(p, s)| (im, idx, p, s)))
                .collect();
            let Some(reference) = observed.iter().max_by(|a, b| {
                a.3.scale
                    .total_cmp(&b.3.scale)
                    .then(b.0.cmp(&a.0))
                    .then(b.1.cmp(&a.1))
            }) else {
                return (false, Vec::new());
            };
            let Some(template) =
                reference_template(&images[&reference.0], reference.2, reference.3, config)
            else {
                return (false, Vec::new());
            };
            let moves = observed
                .iter()
                .filter(|o| (o.0, o.1) != (reference.0, reference.1))
                .map(|o| {
                    let a0 = similarity_between(reference.3, o.3);
                    (
                        o.0,
                        o.1,
                        align(&template, &images[&o.0], o.2, o.3, a0, config),
                    )
                })
                .collect();
            (true, moves)
        })
        .collect();
    let mut summary = TrackRefinementSummary::default();
    let mut sum_sq = 0.0;
    for ((point_id, _), (usable, moves)) in tracks.iter().zip(outcomes) {
        summary.tracks += usize::from(usable);
        let mut unaligned = Vec::new();
        for (image_id, idx, outcome) in moves {
            summary.observations += 1;
            match outcome {
                Alignment::Moved(c) => {
                    let p = &mut rec
                        .images
                        .get_mut(&image_id)
                        .expect("track image")
                        .keypoints[idx as usize];
                    sum_sq += (c - p.coords).norm_squared();
                    *p = Point2::from(c);
                    summary.moved += 1;
                    continue;
                }
                Alignment::Failed => summary.failed += 1,
                Alignment::LowNcc => summary.low_ncc += 1,
                Alignment::TooFar => summary.too_far += 1,
            }
            unaligned.push((image_id, idx));
        }
        if !unaligned.is_empty() {
            summary.points_removed += usize::from(remove_observations(rec, *point_id, &unaligned));
        }
    }
    if summary.moved > 0 {
        summary.rms_shift_px = (sum_sq / summary.moved as f64).sqrt();
    }
    summary
}

/// Removes the observations `(image id, keypoint index)` from the track of point `point_id`,
/// and the point itself when fewer than two observations are left; true when the point went.
fn remove_observations(
    rec: &mut Reconstruction,
    point_id: u64,
    observations: &[(u32, u32)],
) -> bool {
    let Some(point) = rec.points3d.get_mut(&point_id) else {
        return false;
    };
    point
        .track
        .retain(|el| !observations.contains(&(el.image_id, el.point2d_idx)));
    let gone: Vec<(u32, u32)> = if point.track.len() < 2 {
        let track = std::mem::take(&mut point.track);
        rec.points3d.remove(&point_id);
        observations
            .iter()
            .copied()
            .chain(track.iter().map(|el| (el.image_id, el.point2d_idx)))
            .collect()
    } else {
        observations.to_vec()
    };
    for (image_id, idx) in &gone {
        if let Some(im) = rec.images.get_mut(image_id) {
            im.point3d_ids[*idx as usize] = None;
        }
    }
    !rec.points3d.contains_key(&point_id)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::{CamFromWorld, Image, Point3D, Rigid3, Rng, TrackElement};
    use nalgebra::Point3;

    /// A smooth random texture: Gaussian blobs of 1.5-4 px sigma, grey levels in about [0, 1].
    fn texture(seed: u64) -> impl Fn(Vector2<f64>) -> f64 {
        let mut rng = Rng::new(seed);
        let blobs: Vec<(Vector2<f64>, f64, f64)> = (0..600)
            .map(|_| {
                (
                    Vector2::new(rng.range(-20.0, 180.0), rng.range(-20.0, 180.0)),
                    rng.range(1.5, 4.0),
                    rng.range(-0.5, 0.5),
                )
            })
            .collect();
        move |p| {
            0.5 + blobs
                .iter()
                .map(|(c, s, a)| a * (-(p - c).norm_squared() / (2.0 * s * s)).exp())
                .sum::<f64>()
        }
    }

    /// A 160x160 photo whose pixel (i, j) is `f` at its centre (i + 0.5, j + 0.5).
    fn photo(f: impl Fn(Vector2<f64>) -> f64) -> GreyImage {
        let mut img = GreyImage::new(160, 160);
        for j in 0..160 {
            for i in 0..160 {
                img.data[j * 160 + i] = f(Vector2::new(i as f64 + 0.5, j as f64 + 0.5)) as f32;
            }
        }
        img
    }

    /// A model of two images and one point observed by keypoint 0 of each.
    fn two_view_model(k1: Vector2<f64>, k2: Vector2<f64>) -> Reconstruction {
        let mut rec = Reconstruction::default();
        for (id, k) in [(1u32, k1), (2, k2)] {
            rec.images.insert(
                id,
                Image {
                    id,
                    name: format!("{id}"),
                    camera_id: 1,
                    cam_from_world: CamFromWorld(Rigid3::identity()),
                    keypoints: vec![Point2::from(k)],
                    point3d_ids: vec![Some(1)],
                },
            );
        }
        rec.points3d.insert(
            1,
            Point3D {
                id: 1,
                position: Point3::origin(),
                color: [0; 3],
                error: 0.0,
                track: vec![
                    TrackElement {
                        image_id: 1,
                        point2d_idx: 0,
                    },
                    TrackElement {
                        image_id: 2,
                        point2d_idx: 0,
                    },
                ],
            },
        );
        rec
    }

    fn refinement_image(grey: &GreyImage, scale: f64) -> RefinementImage {
        RefinementImage {
            pyramid: ImagePyramid::new(grey),
            shapes: vec![KeypointShape {
                scale,
                orientation: 0.0,
            }],
        }
    }

    /// The second photo is the first under a known affinity (rotation 8 degrees, anisotropic
    /// scale, shear) with a gain and bias; its keypoint starts 0.72 px off the true image of
    /// the reference keypoint and must land on it. The tolerance, 0.03 px, is a tenth of the
    /// keypoint noise this step is meant to remove; what is left is the extra level-0 blur,
    /// which is isotropic in the second photo rather than warped with the texture.
    #[test]
    fn a_keypoint_moves_onto_the_image_of_the_reference_keypoint() {
        let t = texture(7);
        let (s, c) = 8f64.to_radians().sin_cos();
        let m = Matrix2::new(c, -s, s, c) * Matrix2::new(1.15, 0.12, 0.0, 0.9);
        let d = Vector2::new(6.0, -4.0);
        let m_inv = m.try_inverse().unwrap();
        let first = photo(&t);
        let second = photo(|p| 0.7 * t(m_inv * (p - d)) + 0.1);
        let k1 = Vector2::new(80.3, 77.6);
        let truth = m * k1 + d;
        let start = truth + Vector2::new(0.6, -0.4);
        let images = HashMap::from([
            (1, refinement_image(&first, 3.0)),
            (
                2,
                refinement_image(&second, 3.0 * m.determinant().sqrt() * 0.98),
            ),
        ]);
        let mut rec = two_view_model(k1, start);
        let summary = refine_tracks(&mut rec, &images, &TrackRefinementConfig::default());
        assert_eq!(
            (summary.tracks, summary.observations, summary.moved),
            (1, 1, 1)
        );
        let moved = rec.images[&2].keypoints[0].coords;
        assert!((moved - truth).norm() < 0.03, "{moved} vs {truth}");
        // The reference (the larger scale) stays where it was.
        assert_eq!(rec.images[&1].keypoints[0].coords, k1);
    }

    /// A second photo of another texture: the alignment cannot reach a good correlation (or
    /// runs away), so the keypoint is not moved; its observation leaves the track, and the
    /// point, left with one observation, goes.
    #[test]
    fn a_keypoint_on_unrelated_texture_leaves_its_track() {
        let first = photo(texture(7));
        let second = photo(texture(8));
        let k = Vector2::new(80.0, 80.0);
        let images = HashMap::from([
            (1, refinement_image(&first, 3.0)),
            (2, refinement_image(&second, 2.9)),
        ]);
        let mut rec = two_view_model(k, k);
        let summary = refine_tracks(&mut rec, &images, &TrackRefinementConfig::default());
        assert_eq!(
            (summary.observations, summary.moved, summary.points_removed),
            (1, 0, 1)
        );
        assert_eq!(rec.images[&2].keypoints[0].coords, k);
        assert!(rec.points3d.is_empty());
        assert_eq!(rec.images[&1].point3d_ids[0], None);
        assert_eq!(rec.images[&2].point3d_ids[0], None);
    }
}
