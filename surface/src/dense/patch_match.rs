//! PatchMatch multi-view stereo: a depth and a normal per pixel of a reference view, found by
//! random search over slanted planes (Bleyer, Rhemann and Rother, "PatchMatch Stereo", BMVC
//! 2011), propagated on a red-black checkerboard so that every pixel of one colour updates
//! in parallel (Galliani, Lasinger and Schindler, "Massively Parallel Multiview Stereopsis by
//! Surface Normal Diffusion" (Gipuma), ICCV 2015; Xu and Tao, "Multi-Scale Geometric
//! Consistency Guided Multi-View Stereo" (ACMH/ACMM), CVPR 2019).
//!
//! **Hypothesis.** A pixel `p` holds a plane: its depth `d` (camera-frame `z`) along the ray
//! `K^-1 p` and its normal `n` (reference camera frame, facing the camera: `n . X < 0`). The
//! plane induces, for every source view `s` with `X_s = R X + t`, the homography
//! `H_s = K_s (R - t n^T / delta) K^-1` with `delta = -n . X_p` (Hartley and Zisserman,
//! result 13.1), so that the support window of `p` maps to the source through one 3x3
//! matrix. With `A_s = K_s R K^-1` and `b_s = K_s t` precomputed per source, a hypothesis
//! costs 9 multiply-adds per source: `H_s = A_s - b_s m^T`, `m = K^-T n / delta`.
//!
//! **Matching cost.** `1 - NCC` with bilateral weights (adaptive support weights, Yoon and
//! Kweon 2006, as in Gipuma and ACMM) over a sparsely sampled window: every `window_step`-th
//! pixel of a `(2 r + 1)^2` window (4x4 = 16 samples for r = 3, step 2). The weights
//! `w_k = exp(-|I_k - I_p| / sigma_color - |k - p| / sigma_spatial)`, normalised to sum 1,
//! and the reference's weighted, normalised values `a_k = w_k (I_k - mu) / sigma` are
//! computed once per pixel visit and shared by every hypothesis and source, so that each
//! window sample costs one projective division, one bilinear lookup and three fused
//! multiply-adds: `NCC = sum(a_k s_k) / sqrt(sum(w_k s_k^2) - sum(w_k s_k)^2)`.
//! A source whose warped window leaves its image (checked at the four warped corners: the
//! image of a rectangle under a homography with positive `z` is the convex quadrilateral of
//! its corners) or that is flat there costs [`MAX_COST`].
//!
//! **Multi-view aggregation.** The mean of the `top_k` smallest source costs: occluded or
//! otherwise bad sources are ignored per pixel and per hypothesis (the "best-k" strategy of
//! Kang, Szeliski and Chai 2001).
//!
//! **Search.** Random initial planes (depth uniform in inverse depth over the view's range,
//! normal uniform over the hemisphere facing the camera); then `iterations` times, for each
//! colour: the best hypothesis (lowest stored cost) of each of 8 neighbourhood regions of the
//! other colour (4 strips of 11 pixels along the axes, 4 triangles of 12 pixels towards the
//! diagonals: ACMH's adaptive checkerboard sampling) is transferred to `p` along its plane
//! and evaluated, the best kept; then six random refinements (new or perturbed depth, new or
//! perturbed normal and both; Gipuma/ACMH) with perturbations that shrink each iteration.
//!
//! At full resolution (the finest scale and the geometric pass) a sweep after the first skips
//! the *still* pixels: those whose plane did not move in their last sweep while no pixel of
//! their propagation regions moved since, so that their candidates would be the planes they
//! already judged (only the refinement's fresh perturbations are given up); and a propagation
//! candidate within those tolerances of an earlier one is taken as that one.
//!
//! Work that cannot change the outcome is not done: each pixel keeps the per-source costs of
//! its plane, so the next sweep does not compute them again for candidate 0; and a refinement
//! trial (judged under the view weights, a weighted mean of non-negative costs) stops as soon
//! as its heaviest sources' share alone cannot beat the best plane. Both give the same depth
//! maps bit for bit as computing everything.
//!
//! **Speed.** The window cost (most of the time) runs in AVX2 intrinsics when the CPU has them
//! (detected at run time; the build targets SSE2): the window's samples are packed 8 to a
//! register, row after row (the 36 samples of a 6x6 window in 5 registers instead of 6 rows of
//! 8 lanes; the default 4x4 window fills 2), the four bilinear neighbours of a sample one
//! 16-byte load from a copy of the source image that stores each pixel beside the one below
//! it (eight loads and a transpose per register instead of gathers), with the portable code's
//! operations in the same order and no FMA, so that both give the same depth maps bit for bit
//! ([`Kernel`]).
//!
//! Everything is deterministic: the random draws of pixel `i` in iteration `t` come from
//! `Rng::for_item(seed ^ t, i)`; pixels of one colour read only the other colour.

use fresco_core::Rng;
use fresco_core::nalgebra::{Matrix3, Vector3};
use fresco_core::photo::GreyImage;
use fresco_core::{Camera, Rigid3};
use rayon::prelude::*;
use serde::Serialize;

use super::geometric_consistency::DepthCheck;

/// Most source views a reference view can use.
pub const MAX_SOURCES: usize = 16;
/// Cost of an impossible or unmatched hypothesis (`1 - NCC` lies in [0, 2]).
pub const MAX_COST: f32 = 2.0;
/// Most window samples along one side (radius 7 at step 2).
const LANES: usize = 8;
/// Most window samples (radius 7 at step 2: 8x8).
const MAX_WINDOW: usize = LANES * LANES;

/// PatchMatch settings; see the module documentation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PatchMatchConfig {
    /// Half size of the support window in pixels. Default 3 (7x7 pixels sampled 4x4).
    /// A slanted plane only fits a curved surface to second order, so its depth at the centre
    /// is biased away from the camera on a convex surface by about the window's sagitta,
    /// `(r / f)^2 d^2 / (2 R)` for curvature radius `R` (the front of a cylinder seen across
    /// its axis: it grows with the window's radius squared); and at an occluding edge the
    /// window carries the nearer surface's plane into up to `r` pixels of what lies behind
    /// ("fattening"). Large support for weakly textured surfaces comes from the coarser scales
    /// instead (each doubles the window's reach). COLMAP's and ACMM's radius 5 (11x11) left
    /// the synthetic temple's columns (radius 12 pixels) behind the truth by a median 0.16% of
    /// the scene's diagonal; radius 3 took its 90th-percentile error from 0.47% to 0.30% and
    /// made the weakly textured temple more complete too (issue 13, session 11). Radius 2
    /// (same cost: its 9 samples fill the same two 8-lane registers as radius 3's 16) took
    /// the synthetic temple to 0.039% / 0.214% / 92.2% complete and the weakly textured
    /// one to 0.055% / 0.342% / 92.6%, but cost the smooth blob 0.9 points of completeness
    /// (95.7% -> 94.7%) and real photos their texture: `fresco run` on templeSparseRing with
    /// templeSR0005 / 0013 held out, gain-fitted PSNR 16.33 -> 16.06 and 18.96 -> 18.90 dB
    /// (with fusion's `one_short_if_clear` on in both; a noisier mesh, 2,321 charts against
    /// 2,035), and sceaux 32% fewer fused points (issue 13, session 12).
    pub window_radius: usize,
    /// Distance between window samples in pixels. Default 2 (4x4 samples at radius 3).
    pub window_step: usize,
    /// Colour scale of the bilateral weights (grey levels in [0, 1]). Default 0.05.
    pub sigma_color: f32,
    /// Distance scale of the bilateral weights, pixels. Default 12.
    pub sigma_spatial: f32,
    /// Scales of the coarse-to-fine pyramid (1: full resolution only). Each coarser scale
    /// halves the image; scales whose image would be smaller than 96 pixels on a side are
    /// dropped. Default 3.
    pub scales: usize,
    /// Propagation + refinement sweeps (both colours) at the coarsest scale. Default 6.
    pub iterations: usize,
    /// Sweeps at each finer scale but the finest, which starts from the coarser scale's
    /// planes. Default 1: the finest scale's sweeps follow, and a second sweep here cost the
    /// synthetic temple (24 views at 640x480) 8% more time for a 90th-percentile error 0.006
    /// points of the diagonal lower and 0.08 points more completeness (issue 13).
    pub fine_iterations: usize,
    /// Sweeps at the finest scale (full resolution) when there are coarser ones. Default 2.
    /// Most of the first pass's work is here (a full-resolution sweep costs 4x one at half
    /// resolution): 1 saves about a quarter of the dense stage's time for a slightly less
    /// complete cloud (synthetic temple, 16 views at 640x480: completeness 87.9% instead
    /// of 89.3%, 90th-percentile error 0.39% instead of 0.35% of the diagonal).
    pub finest_iterations: usize,
    /// Sources whose costs are averaged per hypothesis (the best ones), where no adaptive
    /// view weights are known. Default 2.
    pub top_k: usize,
    /// Weigh the sources per pixel by ACMH's multi-hypothesis view selection (see
    /// `view_weights`) instead of averaging the `top_k` best. Default true.
    pub adaptive_views: bool,
    /// Pixels whose window's weighted standard deviation is below this (grey levels in
    /// [0, 1]) carry no texture and get no depth. Default 0.001 (about the quantisation noise
    /// of 8-bit images, 1 / (255 sqrt 12)). A smaller window sees less of a smooth texture's
    /// variation (its spread grows about with the radius), so the threshold follows the
    /// radius: 0.002 suited radius 5; at radius 3 it left 8% of a synthetic blob view's
    /// surface pixels without depth, 0.001 leaves 5% (radius 5: 4%; issue 13).
    pub min_ref_std: f32,
    /// Pixels whose final cost is above this get no depth (`1 - NCC`; in the geometric
    /// pass, plus `geometric_weight`, i.e. a pixel of mean reprojection error). Default 0.5.
    pub max_cost: f32,
    /// Weight of the forward-backward reprojection error (pixels) added to each source's
    /// cost in the geometric pass (`geometric_consistency.rs`). Default 0.2 (ACMM's 0.2;
    /// COLMAP's regulariser is 0.3).
    pub geometric_weight: f32,
    /// Reprojection errors are clamped at this many pixels. Default 3 (COLMAP's).
    pub geometric_max_px: f32,
    /// Sweeps of the geometric pass, at full resolution from the first pass's planes.
    /// Default 1: a second sweep is about a seventh of sceaux_castle's window costs, and
    /// moved the synthetic temple's median and 90th-percentile errors by less than 0.001% of
    /// the diagonal and its completeness by 0.04 points (issue 13).
    pub geometric_iterations: usize,
    /// In the geometric pass, pixels whose first-pass plane reprojects forward and back
    /// within this many pixels through at least two sources' depth maps (every source when
    /// there are fewer) keep their plane and are not swept; they still propagate it. 0: sweep
    /// every pixel. Default 0.5.
    pub settled_px: f32,
    /// At full resolution (the finest scale and the geometric pass), a sweep after the first
    /// skips the pixels whose plane did not move in their last sweep and none of whose
    /// propagation neighbours' planes moved since: their candidates are the planes they
    /// already judged. A plane moved when its depth changed by more than this fraction or
    /// its normal by more than `still_normal_deg`. In the same sweeps, a propagation
    /// candidate within these tolerances of an earlier candidate of the pixel is taken as that
    /// one (its costs are not computed again), and so is a coarse plane in the upsampling.
    /// 0: sweep every pixel, and only exact repeats are merged. Default 0.002, the
    /// full-resolution refinement's smallest depth perturbation (about 0.4 pixel of
    /// disparity at the temple's 30-degree baselines): on sceaux_castle a fifth fewer
    /// propagation candidates are costed at full resolution than with 0.0005 (issue 13).
    pub still_depth: f32,
    /// See `still_depth`, degrees. Default 5.
    pub still_normal_deg: f32,
}

impl Default for PatchMatchConfig {
    fn default() -> Self {
        PatchMatchConfig {
            window_radius: 3,
            window_step: 2,
            sigma_color: 0.05,
            sigma_spatial: 12.0,
            scales: 3,
            iterations: 6,
            fine_iterations: 1,
            finest_iterations: 2,
            top_k: 2,
            adaptive_views: true,
            min_ref_std: 0.001,
            max_cost: 0.5,
            geometric_weight: 0.2,
            geometric_max_px: 3.0,
            geometric_iterations: 1,
            settled_px: 0.5,
            still_depth: 0.002,
            still_normal_deg: 5.0,
        }
    }
}

impl PatchMatchConfig {
    /// The first field with an unusable value, by name.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if self.window_step == 0 || self.window_radius == 0 {
            return Err((
                "window_radius",
                format!(
                    "radius {} and step {} must both be positive",
                    self.window_radius, self.window_step
                ),
            ));
        }
        let side = 2 * self.window_radius / self.window_step + 1;
        if side * side > MAX_WINDOW {
            return Err((
                "window_radius",
                format!(
                    "radius {} at step {} samples {side}x{side} pixels, more than {MAX_WINDOW}",
                    self.window_radius, self.window_step
                ),
            ));
        }
        for (name, v) in [
            ("sigma_color", self.sigma_color),
            ("sigma_spatial", self.sigma_spatial),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((name, format!("{v} is not a positive number")));
            }
        }
        if self.iterations == 0 {
            return Err(("iterations", "at least one iteration is needed".into()));
        }
        if self.scales == 0 || self.scales > 6 {
            return Err(("scales", format!("{} is outside 1..=6", self.scales)));
        }
        if self.top_k == 0 || self.top_k > MAX_SOURCES {
            return Err((
                "top_k",
                format!("{} is outside 1..={MAX_SOURCES}", self.top_k),
            ));
        }
        if !(self.min_ref_std.is_finite() && self.min_ref_std >= 0.0) {
            return Err((
                "min_ref_std",
                format!("{} is not a non-negative number", self.min_ref_std),
            ));
        }
        for (name, v) in [
            ("geometric_weight", self.geometric_weight),
            ("geometric_max_px", self.geometric_max_px),
            ("settled_px", self.settled_px),
            ("still_depth", self.still_depth),
            ("still_normal_deg", self.still_normal_deg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err((name, format!("{v} is not a non-negative number")));
            }
        }
        if !(self.max_cost.is_finite() && self.max_cost > 0.0 && self.max_cost <= MAX_COST) {
            return Err((
                "max_cost",
                format!("{} is outside (0, {MAX_COST}]", self.max_cost),
            ));
        }
        Ok(())
    }
}

/// Pinhole intrinsics in array coordinates: the centre of pixel (`i`, `j`) is at (`i`, `j`)
/// (COLMAP's pixel convention minus 0.5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    /// The intrinsics of a pinhole `camera` (its distortion, if any, is ignored).
    pub fn of(camera: &Camera) -> Intrinsics {
        let c = camera.principal_point();
        Intrinsics {
            fx: camera.focal_x(),
            fy: camera.focal_y(),
            cx: c.x - 0.5,
            cy: c.y - 0.5,
        }
    }

    /// The intrinsics of the image down-sampled by `factor` (pixel `i` of the smaller image
    /// covers pixels `factor i .. factor (i + 1)`).
    pub fn downscaled(&self, factor: f64) -> Intrinsics {
        Intrinsics {
            fx: self.fx / factor,
            fy: self.fy / factor,
            cx: (self.cx + 0.5) / factor - 0.5,
            cy: (self.cy + 0.5) / factor - 0.5,
        }
    }

    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    pub fn inverse_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            1.0 / self.fx,
            0.0,
            -self.cx / self.fx,
            0.0,
            1.0 / self.fy,
            -self.cy / self.fy,
            0.0,
            0.0,
            1.0,
        )
    }

    /// The ray `K^-1 (x, y, 1)` through array position (`x`, `y`).
    #[inline]
    fn ray(&self, x: f32, y: f32) -> [f32; 3] {
        [
            (x - self.cx as f32) / self.fx as f32,
            (y - self.cy as f32) / self.fy as f32,
            1.0,
        ]
    }
}

/// One source view of a reference view: its image, intrinsics and pose relative to the
/// reference.
pub struct Source<'a> {
    pub image: &'a GreyImage,
    pub k: Intrinsics,
    pub src_from_ref: Rigid3,
    /// The source's first-pass depth map, for the geometric pass (same size as `image`).
    pub depth: Option<&'a DepthMap>,
}

/// Everything PatchMatch needs for one reference view at one scale.
pub struct Problem<'a> {
    pub image: &'a GreyImage,
    pub k: Intrinsics,
    pub sources: Vec<Source<'a>>,
    /// Nearest and farthest depth to draw hypotheses from.
    pub depth_range: (f32, f32),
    /// Pixels to reconstruct (row-major, non-zero = yes); `None`: all.
    pub mask: Option<&'a [u8]>,
    /// The first pass's depth map of this view: when given, this is the geometric pass
    /// (full resolution only, starting from these planes).
    pub prior: Option<&'a DepthMap>,
}

/// A depth map with normals and costs, row-major. Depth 0 marks pixels without depth.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    pub width: usize,
    pub height: usize,
    /// Camera-frame `z`, world units; 0 where unknown.
    pub depth: Vec<f32>,
    /// Unit normal in the camera frame (facing the camera); zero where unknown.
    pub normal: Vec<[f32; 3]>,
    /// Matching cost `1 - NCC` in [0, 2]; [`MAX_COST`] where unknown.
    pub cost: Vec<f32>,
}

impl DepthMap {
    pub fn empty(width: usize, height: usize) -> DepthMap {
        DepthMap {
            width,
            height,
            depth: vec![0.0; width * height],
            normal: vec![[0.0; 3]; width * height],
            cost: vec![MAX_COST; width * height],
        }
    }

    /// Fraction of pixels with a depth.
    pub fn valid_fraction(&self) -> f64 {
        if self.depth.is_empty() {
            return 0.0;
        }
        self.depth.iter().filter(|&&d| d > 0.0).count() as f64 / self.depth.len() as f64
    }
}

/// A plane hypothesis and its cost.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Hyp {
    depth: f32,
    normal: [f32; 3],
    cost: f32,
}

const INVALID: Hyp = Hyp {
    depth: 0.0,
    normal: [0.0; 3],
    cost: f32::INFINITY,
};

/// Per-source constants of the plane-induced homography (see the module documentation).
struct SourceGeometry<'a> {
    image: &'a GreyImage,
    /// `K_s R K^-1`, row-major.
    a: [f32; 9],
    /// `K_s t`.
    b: [f32; 3],
    /// Largest array coordinate a bilinear lookup may start from (`size - 1`, minus a margin).
    max_x: f32,
    max_y: f32,
    /// The image with each pixel followed by the one below it (see [`stack_rows`]), for the
    /// AVX2 kernel; empty on the portable one.
    stacked: Vec<f32>,
}

/// `image` with each pixel followed by the one below it: element `2 (y w + x)` is `I(x, y)`
/// and `2 (y w + x) + 1` is `I(x, y + 1)` (the last row repeats itself), so that the four
/// bilinear neighbours of (`x`, `y`) are the four consecutive floats at `2 (y w + x)`:
/// `I(x, y), I(x, y + 1), I(x + 1, y), I(x + 1, y + 1)`. One 16-byte load per window sample
/// then replaces the AVX2 kernel's gathers (on the AMD Zen 3 measured in issue 13, the
/// gathers were a third of the window cost; without them a sceaux view is 12% cheaper).
fn stack_rows(image: &GreyImage) -> Vec<f32> {
    let (w, h) = (image.width, image.height);
    let mut out = vec![0.0f32; 2 * w * h];
    for (y, row) in out.chunks_exact_mut(2 * w).enumerate() {
        let below = (y + 1).min(h - 1);
        let (top, bottom) = (&image.data[y * w..(y + 1) * w], &image.data[below * w..]);
        for ((pair, &t), &b) in row.chunks_exact_mut(2).zip(top).zip(bottom) {
            pair[0] = t;
            pair[1] = b;
        }
    }
    out
}

/// The reference window of one pixel: normalised weights and weighted, normalised values.
struct Window {
    w: [f32; MAX_WINDOW],
    a: [f32; MAX_WINDOW],
}

/// Offsets (dx, dy) of the propagation regions: all of the other colour (odd |dx| + |dy|).
fn regions() -> Vec<Vec<(i32, i32)>> {
    let mut out = Vec::new();
    for (sx, sy) in [(0, -1), (0, 1), (-1, 0), (1, 0)] {
        out.push(
            (0..11)
                .map(|k| (sx * (2 * k + 1), sy * (2 * k + 1)))
                .collect(),
        );
    }
    for (sx, sy) in [(-1, -1), (1, -1), (-1, 1), (1, 1)] {
        let mut r = Vec::new();
        for i in 1..7 {
            for j in 1..7 {
                if (i + j) % 2 == 1 && i + j <= 7 {
                    r.push((sx * i, sy * j));
                }
            }
        }
        out.push(r);
    }
    out
}

/// Marks a source cost not computed (costs are never negative).
const UNKNOWN_COST: f32 = -1.0;

/// The checkerboard: hypotheses of the two colours in separate arrays (pixel (x, y) has
/// colour `(x + y) % 2` and index `y * half + x / 2` in its array), so that a parallel pass
/// over one colour borrows it mutably and the other immutably.
struct Board {
    width: usize,
    height: usize,
    half: usize,
    cells: [Vec<Hyp>; 2],
    /// Per cell, the per-source costs of its plane (`sources` of them, [`UNKNOWN_COST`] for
    /// those not computed): the next sweep's propagation starts with the pixel's own plane,
    /// whose costs need not be computed again.
    costs: [Vec<f32>; 2],
    sources: usize,
}

impl Board {
    fn new(width: usize, height: usize, sources: usize) -> Board {
        let half = width.div_ceil(2);
        let sources = sources.max(1);
        Board {
            width,
            height,
            half,
            cells: [vec![INVALID; half * height], vec![INVALID; half * height]],
            costs: [
                vec![UNKNOWN_COST; half * height * sources],
                vec![UNKNOWN_COST; half * height * sources],
            ],
            sources,
        }
    }

    #[inline]
    fn get(&self, x: usize, y: usize) -> &Hyp {
        &self.cells[(x + y) & 1][y * self.half + x / 2]
    }

    fn to_depth_map(&self, max_cost: f32) -> DepthMap {
        let mut map = DepthMap::empty(self.width, self.height);
        for y in 0..self.height {
            for x in 0..self.width {
                let h = self.get(x, y);
                let i = y * self.width + x;
                if h.depth > 0.0 && h.cost <= max_cost {
                    map.depth[i] = h.depth;
                    map.normal[i] = h.normal;
                    map.cost[i] = h.cost;
                }
            }
        }
        map
    }
}

/// A PatchMatch run on one reference view.
struct Solver<'a> {
    problem: &'a Problem<'a>,
    cfg: &'a PatchMatchConfig,
    sources: Vec<SourceGeometry<'a>>,
    /// Per source, its depth map for the geometric term (geometric pass only).
    checks: Vec<Option<DepthCheck<'a>>>,
    /// Window sample offsets along one axis.
    offsets: Vec<i32>,
    /// The window's samples packed row after row, `LANES` to a register: sample `k` is
    /// (`k % m`, `k / m`) of the `m x m` samples; the lanes past the last sample repeat it
    /// (with weight 0). Its offset from the window's first sample, pixels, in x and y.
    lane_dx: [f32; MAX_WINDOW],
    lane_dy: [f32; MAX_WINDOW],
    /// Registers of `LANES` samples that hold the window.
    registers: usize,
    /// Spatial part of the bilateral weights, per window sample.
    spatial: Vec<f32>,
    regions: Vec<Vec<(i32, i32)>>,
    /// Pixels that are reconstructed (textured, inside the mask, away from the border).
    active: Vec<bool>,
    seed: u64,
    /// The window costs run on AVX2 (detected at run time, and allowed by the caller).
    #[cfg(target_arch = "x86_64")]
    avx2: bool,
}

impl<'a> Solver<'a> {
    fn new(
        problem: &'a Problem<'a>,
        cfg: &'a PatchMatchConfig,
        seed: u64,
        kernel: Kernel,
    ) -> Solver<'a> {
        #[cfg(target_arch = "x86_64")]
        let avx2 = kernel == Kernel::Fastest && std::arch::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        let k_inv = problem.k.inverse_matrix();
        let sources = problem
            .sources
            .iter()
            .map(|s| {
                let r = s.src_from_ref.rotation.to_rotation_matrix().into_inner();
                let ks = s.k.matrix();
                let a = ks * r * k_inv;
                let b = ks * s.src_from_ref.translation;
                let mut af = [0.0f32; 9];
                for i in 0..3 {
                    for j in 0..3 {
                        af[i * 3 + j] = a[(i, j)] as f32;
                    }
                }
                SourceGeometry {
                    image: s.image,
                    a: af,
                    b: [b.x as f32, b.y as f32, b.z as f32],
                    max_x: s.image.width as f32 - 1.001,
                    max_y: s.image.height as f32 - 1.001,
                    stacked: if avx2 {
                        stack_rows(s.image)
                    } else {
                        Vec::new()
                    },
                }
            })
            .collect();
        let r = cfg.window_radius as i32;
        let step = cfg.window_step as i32;
        let offsets: Vec<i32> = (0..)
            .map(|k| -r + k * step)
            .take_while(|&o| o <= r)
            .collect();
        let m = offsets.len();
        let mut spatial = vec![0.0f32; MAX_WINDOW];
        for (j, &dy) in offsets.iter().enumerate() {
            for (i, &dx) in offsets.iter().enumerate() {
                let dist = ((dx * dx + dy * dy) as f32).sqrt();
                spatial[j * m + i] = (-dist / cfg.sigma_spatial).exp();
            }
        }
        let registers = (m * m).div_ceil(LANES);
        let (mut lane_dx, mut lane_dy) = ([0.0f32; MAX_WINDOW], [0.0f32; MAX_WINDOW]);
        for k in 0..registers * LANES {
            let k_in = k.min(m * m - 1);
            lane_dx[k] = (k_in % m) as f32 * step as f32;
            lane_dy[k] = (k_in / m) as f32 * step as f32;
        }
        let checks = problem
            .sources
            .iter()
            .map(|s| {
                s.depth
                    .map(|d| DepthCheck::new(d, &s.k, &s.src_from_ref, &problem.k))
            })
            .collect();
        let mut solver = Solver {
            problem,
            cfg,
            sources,
            checks,
            offsets,
            lane_dx,
            lane_dy,
            registers,
            spatial,
            regions: regions(),
            active: Vec::new(),
            seed,
            #[cfg(target_arch = "x86_64")]
            avx2,
        };
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (kernel, avx2);
        solver.active = solver.active_pixels();
        solver
    }

    fn width(&self) -> usize {
        self.problem.image.width
    }
    fn height(&self) -> usize {
        self.problem.image.height
    }

    /// Pixels inside the mask, at least a window radius from the border, whose window
    /// carries texture.
    fn active_pixels(&self) -> Vec<bool> {
        let (w, h) = (self.width(), self.height());
        let r = self.cfg.window_radius;
        let mut active = vec![false; w * h];
        if w <= 2 * r || h <= 2 * r || self.sources.is_empty() {
            return active;
        }
        active.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            if y < r || y + r >= h {
                return;
            }
            for (x, a) in row.iter_mut().enumerate().take(w - r).skip(r) {
                if let Some(mask) = self.problem.mask
                    && mask[y * w + x] == 0
                {
                    continue;
                }
                *a = self.window(x, y).is_some();
            }
        });
        active
    }

    /// The reference window at (`x`, `y`), or `None` when it is flat.
    #[inline]
    fn window(&self, x: usize, y: usize) -> Option<Window> {
        let img = self.problem.image;
        let w = img.width;
        let centre = img.data[y * w + x];
        let mut win = Window {
            w: [0.0; MAX_WINDOW],
            a: [0.0; MAX_WINDOW],
        };
        let mut values = [0.0f32; MAX_WINDOW];
        let inv_sigma_color = 1.0 / self.cfg.sigma_color;
        let mut total = 0.0f32;
        // Sample (i, j) of the window lives at j * m + i; the unused lanes keep weight 0.
        let m = self.offsets.len();
        for (j, &dy) in self.offsets.iter().enumerate() {
            let row = ((y as i32 + dy) as usize) * w;
            for (i, &dx) in self.offsets.iter().enumerate() {
                let k = j * m + i;
                let v = img.data[row + (x as i32 + dx) as usize];
                let weight = self.spatial[k] * (-(v - centre).abs() * inv_sigma_color).exp();
                values[k] = v;
                win.w[k] = weight;
                total += weight;
            }
        }
        let inv_total = 1.0 / total;
        let mut mean = 0.0f32;
        for (w, v) in win.w.iter_mut().zip(&values) {
            *w *= inv_total;
            mean += *w * v;
        }
        let var: f32 = win
            .w
            .iter()
            .zip(&values)
            .map(|(w, v)| w * (v - mean) * (v - mean))
            .sum();
        let std = var.sqrt();
        if std.is_nan() || std <= self.cfg.min_ref_std || std <= 1e-6 {
            return None;
        }
        let inv_std = 1.0 / std;
        for ((a, w), v) in win.a.iter_mut().zip(&win.w).zip(&values) {
            *a = w * (v - mean) * inv_std;
        }
        Some(win)
    }

    /// `1 - NCC` of the window at (`x`, `y`) against one source through homography `h`.
    #[inline(always)]
    fn source_cost(
        &self,
        src: &SourceGeometry,
        h: &[f32; 9],
        x: usize,
        y: usize,
        win: &Window,
    ) -> f32 {
        let Some((x0, y0)) = self.warped_window_inside(src, h, x, y) else {
            return MAX_COST;
        };
        // LANES samples at a time (the window's rows packed one after the other): the
        // projective divisions and the sums vectorise; the lanes past the last sample repeat
        // it and carry weight 0.
        let img = &src.image.data;
        let iw = src.image.width;
        let (mut sa, mut sw, mut sww) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        for r in 0..self.registers {
            let lanes = r * LANES..(r + 1) * LANES;
            let (dx, dy) = (&self.lane_dx[lanes.clone()], &self.lane_dy[lanes.clone()]);
            let (mut us, mut vs) = ([0.0f32; LANES], [0.0f32; LANES]);
            for i in 0..LANES {
                let (xx, yy) = (x0 + dx[i], y0 + dy[i]);
                let iz = 1.0 / (h[6] * xx + (h[7] * yy + h[8]));
                us[i] = (h[0] * xx + (h[1] * yy + h[2])) * iz;
                vs[i] = (h[3] * xx + (h[4] * yy + h[5])) * iz;
            }
            // Integer and fractional parts lane-wise: truncation to i32 is one vector
            // instruction (to usize it is a branchy sequence per sample on x86-64).
            let (mut ui, mut vi) = ([0i32; LANES], [0i32; LANES]);
            let (mut fu, mut fv) = ([0.0f32; LANES], [0.0f32; LANES]);
            for i in 0..LANES {
                // SAFETY: the four corners of the warped window lie in
                // [0, width - 1.001] x [0, height - 1.001] with positive z, so every sample
                // (a point of their convex hull up to rounding far below the 0.001 margin;
                // the lanes past the last sample repeat it) is finite and truncates to
                // 0 <= ui <= width - 2 and 0 <= vi <= height - 2.
                unsafe {
                    ui[i] = us[i].to_int_unchecked();
                    vi[i] = vs[i].to_int_unchecked();
                }
                fu[i] = us[i] - ui[i] as f32;
                fv[i] = vs[i] - vi[i] as f32;
            }
            let (mut p00, mut p01, mut p10, mut p11) = (
                [0.0f32; LANES],
                [0.0f32; LANES],
                [0.0f32; LANES],
                [0.0f32; LANES],
            );
            for i in 0..LANES {
                let base = vi[i] as usize * iw + ui[i] as usize;
                // SAFETY: as above, base + iw + 1 < width * height.
                unsafe {
                    p00[i] = *img.get_unchecked(base);
                    p01[i] = *img.get_unchecked(base + 1);
                    p10[i] = *img.get_unchecked(base + iw);
                    p11[i] = *img.get_unchecked(base + iw + 1);
                }
            }
            let mut s = [0.0f32; LANES];
            for i in 0..LANES {
                let top = p00[i] + (p01[i] - p00[i]) * fu[i];
                let bottom = p10[i] + (p11[i] - p10[i]) * fu[i];
                s[i] = top + (bottom - top) * fv[i];
            }
            let (wr, ar) = (&win.w[lanes.clone()], &win.a[lanes]);
            for i in 0..LANES {
                sa[i] += ar[i] * s[i];
                sw[i] += wr[i] * s[i];
                sww[i] += wr[i] * s[i] * s[i];
            }
        }
        ncc_cost(&sa, &sw, &sww)
    }

    /// The window's first sample (`x0`, `y0`) when the window at (`x`, `y`) warped by `h`
    /// lies inside the source image (its four corners do, with positive `z`); `None` when it
    /// leaves it.
    #[inline(always)]
    fn warped_window_inside(
        &self,
        src: &SourceGeometry,
        h: &[f32; 9],
        x: usize,
        y: usize,
    ) -> Option<(f32, f32)> {
        let r = self.cfg.window_radius as f32;
        let last = *self.offsets.last().unwrap_or(&0) as f32;
        let (x0, y0) = (x as f32 - r, y as f32 - r);
        let (x1, y1) = (x as f32 + last, y as f32 + last);
        // The four corners side by side and without early exits, so that the compiler
        // evaluates them in one vector register (a division per corner and coordinate).
        let (cx, cy) = ([x0, x1, x0, x1], [y0, y0, y1, y1]);
        let mut inside = true;
        for i in 0..4 {
            let z = h[6] * cx[i] + h[7] * cy[i] + h[8];
            let u = (h[0] * cx[i] + h[1] * cy[i] + h[2]) / z;
            let v = (h[3] * cx[i] + h[4] * cy[i] + h[5]) / z;
            // Also rejects NaN.
            inside &= z > 1e-6 && u >= 0.0 && v >= 0.0 && u <= src.max_x && v <= src.max_y;
        }
        inside.then_some((x0, y0))
    }

    /// [`Solver::source_cost`] in AVX2 intrinsics: 8 window samples to a register, their
    /// bilinear neighbours loaded from the stacked image ([`stack_rows`]). The same operations
    /// in the same order as the portable code (no FMA; lanes past the window's last sample
    /// repeat it, inside the image, and carry weight 0 as there), so the same cost bit for bit.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn source_cost_avx2(
        &self,
        src: &SourceGeometry,
        h: &[f32; 9],
        x: usize,
        y: usize,
        win: &Window,
    ) -> f32 {
        use std::arch::x86_64::*;
        let Some((x0, y0)) = self.warped_window_inside(src, h, x, y) else {
            return MAX_COST;
        };
        let stacked = src.stacked.as_ptr();
        let iw = src.image.width;
        let hv = h.map(|c| _mm256_set1_ps(c));
        let (x0, y0) = (_mm256_set1_ps(x0), _mm256_set1_ps(y0));
        let one = _mm256_set1_ps(1.0);
        let width = _mm256_set1_epi32(iw as i32);
        let (mut sa, mut sw, mut sww) = (
            _mm256_setzero_ps(),
            _mm256_setzero_ps(),
            _mm256_setzero_ps(),
        );
        for r in 0..self.registers {
            // SAFETY (loads): `lane_dx`, `lane_dy`, `win.w` and `win.a` hold
            // MAX_WINDOW >= registers * LANES floats.
            let (dx, dy) = unsafe {
                (
                    _mm256_loadu_ps(self.lane_dx.as_ptr().add(r * LANES)),
                    _mm256_loadu_ps(self.lane_dy.as_ptr().add(r * LANES)),
                )
            };
            let (xx, yy) = (_mm256_add_ps(x0, dx), _mm256_add_ps(y0, dy));
            // h[a] x + (h[b] y + h[c]), as the portable code.
            let lin = |a: usize, b: usize, c: usize| {
                _mm256_add_ps(
                    _mm256_mul_ps(hv[a], xx),
                    _mm256_add_ps(_mm256_mul_ps(hv[b], yy), hv[c]),
                )
            };
            let iz = _mm256_div_ps(one, lin(6, 7, 8));
            let us = _mm256_mul_ps(lin(0, 1, 2), iz);
            let vs = _mm256_mul_ps(lin(3, 4, 5), iz);
            let ui = _mm256_cvttps_epi32(us);
            let vi = _mm256_cvttps_epi32(vs);
            let fu = _mm256_sub_ps(us, _mm256_cvtepi32_ps(ui));
            let fv = _mm256_sub_ps(vs, _mm256_cvtepi32_ps(vi));
            let base = _mm256_add_epi32(_mm256_mullo_epi32(vi, width), ui);
            // Each lane's four bilinear neighbours are 16 consecutive bytes of the stacked
            // image, [p00 p10 p01 p11]: eight loads, lanes i and i + 4 in one register, then
            // a 4x4 transpose within each 128-bit half. SAFETY: as in the portable code,
            // every lane's 0 <= ui <= width - 2 and 0 <= vi <= height - 2, so
            // 2 base + 3 < 2 width height, the stacked image's length.
            let (p00, p01, p10, p11) = unsafe {
                let mut at = [0i32; LANES];
                _mm256_storeu_si256(at.as_mut_ptr() as *mut __m256i, base);
                let quad = |i: usize| _mm_loadu_ps(stacked.add(2 * at[i] as usize));
                let r0 = _mm256_set_m128(quad(4), quad(0));
                let r1 = _mm256_set_m128(quad(5), quad(1));
                let r2 = _mm256_set_m128(quad(6), quad(2));
                let r3 = _mm256_set_m128(quad(7), quad(3));
                // [p00 of lanes 0, 1; p10 of lanes 0, 1], [p01 ...; p11 ...] for lanes 0, 1
                // (and 4, 5 in the upper half), likewise for lanes 2, 3 (6, 7).
                let (lo01, hi01) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
                let (lo23, hi23) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
                (
                    _mm256_shuffle_ps::<0b01_00_01_00>(lo01, lo23),
                    _mm256_shuffle_ps::<0b01_00_01_00>(hi01, hi23),
                    _mm256_shuffle_ps::<0b11_10_11_10>(lo01, lo23),
                    _mm256_shuffle_ps::<0b11_10_11_10>(hi01, hi23),
                )
            };
            let top = _mm256_add_ps(p00, _mm256_mul_ps(_mm256_sub_ps(p01, p00), fu));
            let bottom = _mm256_add_ps(p10, _mm256_mul_ps(_mm256_sub_ps(p11, p10), fu));
            let s = _mm256_add_ps(top, _mm256_mul_ps(_mm256_sub_ps(bottom, top), fv));
            let (wr, ar) = unsafe {
                (
                    _mm256_loadu_ps(win.w.as_ptr().add(r * LANES)),
                    _mm256_loadu_ps(win.a.as_ptr().add(r * LANES)),
                )
            };
            sa = _mm256_add_ps(sa, _mm256_mul_ps(ar, s));
            let ws = _mm256_mul_ps(wr, s);
            sw = _mm256_add_ps(sw, ws);
            sww = _mm256_add_ps(sww, _mm256_mul_ps(ws, s));
        }
        let (mut a, mut b, mut c) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        // SAFETY: each array holds 8 floats.
        unsafe {
            _mm256_storeu_ps(a.as_mut_ptr(), sa);
            _mm256_storeu_ps(b.as_mut_ptr(), sw);
            _mm256_storeu_ps(c.as_mut_ptr(), sww);
        }
        ncc_cost(&a, &b, &c)
    }

    /// The cost of hypothesis (`depth`, `normal`) at (`x`, `y`) against every source
    /// (photometric, plus the geometric term in the geometric pass); `MAX_COST` beyond the
    /// sources and, when `weights` are given, for the sources of weight 0 (which a weighted
    /// mean ignores: not evaluating them saves most of the refinement's work once ACMH's
    /// selection has settled on a few views).
    fn source_costs(
        &self,
        x: usize,
        y: usize,
        depth: f32,
        normal: &[f32; 3],
        win: &Window,
        weights: Option<&[f32; MAX_SOURCES]>,
    ) -> [f32; MAX_SOURCES] {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: the CPU supports AVX2 (`Solver::new` checked it).
            return unsafe { self.source_costs_avx2(x, y, depth, normal, win, weights) };
        }
        self.source_costs_on::<false>(x, y, depth, normal, win, weights)
    }

    /// [`Solver::source_costs`] compiled for AVX2 (the crate is built for SSE2 only): the
    /// window's 8-lane rows on one register instead of two. No FMA, and the same operations
    /// in the same order, so the same costs bit for bit (a test compares both paths).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn source_costs_avx2(
        &self,
        x: usize,
        y: usize,
        depth: f32,
        normal: &[f32; 3],
        win: &Window,
        weights: Option<&[f32; MAX_SOURCES]>,
    ) -> [f32; MAX_SOURCES] {
        self.source_costs_on::<true>(x, y, depth, normal, win, weights)
    }

    /// [`Solver::source_costs`] with the window cost in AVX2 intrinsics (`AVX2`) or portable
    /// code.
    #[inline(always)]
    fn source_costs_on<const AVX2: bool>(
        &self,
        x: usize,
        y: usize,
        depth: f32,
        normal: &[f32; 3],
        win: &Window,
        weights: Option<&[f32; MAX_SOURCES]>,
    ) -> [f32; MAX_SOURCES] {
        let mut costs = [MAX_COST; MAX_SOURCES];
        let k = &self.problem.k;
        let ray = k.ray(x as f32, y as f32);
        let delta = -depth * dot(normal, &ray);
        if delta.is_nan() || delta <= 0.0 {
            return costs;
        }
        // m = K^-T n / delta.
        let fx = k.fx as f32;
        let fy = k.fy as f32;
        let m = [
            normal[0] / fx / delta,
            normal[1] / fy / delta,
            (normal[2] - normal[0] * k.cx as f32 / fx - normal[1] * k.cy as f32 / fy) / delta,
        ];
        let point = [depth * ray[0], depth * ray[1], depth];
        let (weight, max_px) = (self.cfg.geometric_weight, self.cfg.geometric_max_px);
        for (j, ((c, src), check)) in costs
            .iter_mut()
            .zip(&self.sources)
            .zip(&self.checks)
            .enumerate()
        {
            if weights.is_some_and(|w| w[j] == 0.0) {
                continue;
            }
            let mut h = src.a;
            for i in 0..3 {
                for j in 0..3 {
                    h[i * 3 + j] -= src.b[i] * m[j];
                }
            }
            *c = {
                #[cfg(target_arch = "x86_64")]
                if AVX2 {
                    // SAFETY: `AVX2` is only set by `source_costs_avx2`, which runs on CPUs
                    // with AVX2.
                    unsafe { self.source_cost_avx2(src, &h, x, y, win) }
                } else {
                    self.source_cost(src, &h, x, y, win)
                }
                #[cfg(not(target_arch = "x86_64"))]
                self.source_cost(src, &h, x, y, win)
            };
            if let Some(check) = check {
                let error = check
                    .error(&point, x as f32, y as f32)
                    .map_or(max_px, |e| e.min(max_px));
                *c += weight * error;
            }
        }
        costs
    }

    /// Hypothesis (`depth`, `normal`) at (`x`, `y`) with its multi-view cost (the mean of
    /// the `top_k` best sources), and its per-source costs.
    fn costed(
        &self,
        x: usize,
        y: usize,
        depth: f32,
        normal: [f32; 3],
        win: &Window,
    ) -> (Hyp, [f32; MAX_SOURCES]) {
        let costs = self.source_costs(x, y, depth, &normal, win, None);
        let mut sorted = costs;
        let cost = aggregate(&mut sorted[..self.sources.len()], self.cfg.top_k);
        (
            Hyp {
                depth,
                normal,
                cost,
            },
            costs,
        )
    }

    /// The per-source costs of the pixel's own plane from `stored` (its costs of the last
    /// visit), computing only those marked [`UNKNOWN_COST`].
    fn complete_costs(
        &self,
        x: usize,
        y: usize,
        depth: f32,
        normal: &[f32; 3],
        win: &Window,
        stored: &[f32],
    ) -> [f32; MAX_SOURCES] {
        let mut missing = [0.0f32; MAX_SOURCES];
        let mut any = false;
        for (m, &c) in missing.iter_mut().zip(stored) {
            if c == UNKNOWN_COST {
                *m = 1.0;
                any = true;
            }
        }
        let mut costs = if any {
            self.source_costs(x, y, depth, normal, win, Some(&missing))
        } else {
            [MAX_COST; MAX_SOURCES]
        };
        for (c, &s) in costs.iter_mut().zip(stored) {
            if s != UNKNOWN_COST {
                *c = s;
            }
        }
        costs
    }

    /// The per-source costs of a refinement trial under view `weights`, the sources of weight
    /// 0 marked [`UNKNOWN_COST`]; `None` as soon as the weighted mean cannot fall below
    /// `best` (costs are never negative: the sum of the sources seen so far bounds it from
    /// below). The heaviest sources go first. A trial that could still win is costed in full,
    /// so the choice is the one the full weighted mean makes (a margin of 1e-4 covers the
    /// rounding of sums taken in another order).
    #[allow(clippy::too_many_arguments)]
    fn bounded_costs(
        &self,
        x: usize,
        y: usize,
        depth: f32,
        normal: &[f32; 3],
        win: &Window,
        weights: &[f32; MAX_SOURCES],
        best: f32,
    ) -> Option<[f32; MAX_SOURCES]> {
        let n = self.sources.len();
        let mut order = [0usize; MAX_SOURCES];
        let mut m = 0;
        for (j, &w) in weights.iter().enumerate().take(n) {
            if w != 0.0 {
                order[m] = j;
                m += 1;
            }
        }
        order[..m].sort_by(|&a, &b| weights[b].total_cmp(&weights[a]).then(a.cmp(&b)));
        let total: f32 = weights.iter().sum();
        let limit = best * total * (1.0 + 1e-4);
        let mut costs = [MAX_COST; MAX_SOURCES];
        for c in costs.iter_mut().take(n) {
            *c = UNKNOWN_COST;
        }
        let mut partial = 0.0f32;
        for (k, &j) in order[..m].iter().enumerate() {
            let mut only = [0.0f32; MAX_SOURCES];
            only[j] = 1.0;
            costs[j] = self.source_costs(x, y, depth, normal, win, Some(&only))[j];
            partial += costs[j] * weights[j];
            if k + 1 < m && partial > limit {
                return None;
            }
        }
        Some(costs)
    }

    /// ACMH's view weights (Xu and Tao 2019, section 3.2) from the per-source costs of the
    /// candidate hypotheses of one pixel: a source is selected when more than 2 candidates
    /// match in it well (cost below `0.8 exp(-t^2 / 90)` at sweep `t`) and fewer than 3 badly
    /// (above 1.2); its weight is the mean confidence `exp(-c^2 / (2 0.3^2))` of its good
    /// matches. `None` when no source is selected.
    fn view_weights(&self, matrix: &[[f32; MAX_SOURCES]], step: i32) -> Option<[f32; MAX_SOURCES]> {
        let good = 0.8 * (-((step * step) as f32) / 90.0).exp();
        let mut weights = [0.0f32; MAX_SOURCES];
        let mut any = false;
        for (j, w) in weights.iter_mut().enumerate().take(self.sources.len()) {
            let (mut n_good, mut n_bad, mut conf) = (0, 0, 0.0f32);
            for row in matrix {
                let c = row[j];
                if c < good {
                    n_good += 1;
                    conf += (-c * c / (2.0 * 0.09)).exp();
                } else if c > 1.2 {
                    n_bad += 1;
                }
            }
            if n_good > 2 && n_bad < 3 {
                *w = conf / n_good as f32;
                any = true;
            }
        }
        any.then_some(weights)
    }

    /// The depth at (`x`, `y`) of the plane that `h` holds at (`hx`, `hy`).
    #[inline]
    fn transfer(&self, h: &Hyp, hx: usize, hy: usize, x: usize, y: usize) -> Option<f32> {
        let k = &self.problem.k;
        let from = k.ray(hx as f32, hy as f32);
        let to = k.ray(x as f32, y as f32);
        let denom = dot(&h.normal, &to);
        if denom >= -1e-6 {
            return None;
        }
        let d = h.depth * dot(&h.normal, &from) / denom;
        (d.is_finite() && d > 0.0).then_some(d)
    }

    fn random_depth(&self, rng: &mut Rng) -> f32 {
        let (lo, hi) = self.problem.depth_range;
        let (a, b) = (1.0 / hi as f64, 1.0 / lo as f64);
        (1.0 / rng.range(a, b)) as f32
    }

    fn random_normal(&self, rng: &mut Rng, ray: &[f32; 3]) -> [f32; 3] {
        loop {
            let v = [
                rng.normal() as f32,
                rng.normal() as f32,
                rng.normal() as f32,
            ];
            let len = dot(&v, &v).sqrt();
            if len < 1e-3 {
                continue;
            }
            let mut n = v.map(|c| c / len);
            if dot(&n, ray) > 0.0 {
                n = n.map(|c| -c);
            }
            // Planes almost along the ray are useless (and ill-conditioned).
            if -dot(&n, ray) / dot(ray, ray).sqrt() > 0.1 {
                return n;
            }
        }
    }

    fn perturb_normal(&self, rng: &mut Rng, n: &[f32; 3], ray: &[f32; 3], amount: f32) -> [f32; 3] {
        for _ in 0..8 {
            let v = [
                n[0] + amount * rng.normal() as f32,
                n[1] + amount * rng.normal() as f32,
                n[2] + amount * rng.normal() as f32,
            ];
            let len = dot(&v, &v).sqrt();
            if len < 1e-6 {
                continue;
            }
            let p = v.map(|c| c / len);
            if -dot(&p, ray) / dot(ray, ray).sqrt() > 0.1 {
                return p;
            }
        }
        *n
    }

    /// The geometric pass's pixels whose plane already agrees with the sources' depth maps:
    /// its point reprojects forward and back within `settled_px` pixels through at least
    /// two sources (every source when there are fewer). Sweeping them would cost as much as
    /// any other pixel for a change below the depth maps' own disagreement.
    fn settled(&self, board: &Board) -> Vec<bool> {
        let (w, h) = (self.width(), self.height());
        let mut settled = vec![false; w * h];
        let limit = self.cfg.settled_px;
        let checks: Vec<&DepthCheck> = self.checks.iter().flatten().collect();
        if limit <= 0.0 || checks.is_empty() {
            return settled;
        }
        let needed = checks.len().min(2);
        settled.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, s) in row.iter_mut().enumerate() {
                let hyp = board.get(x, y);
                if hyp.depth <= 0.0 {
                    continue;
                }
                let ray = self.problem.k.ray(x as f32, y as f32);
                let point = ray.map(|c| c * hyp.depth);
                let agreeing = checks
                    .iter()
                    .filter(|c| {
                        c.error(&point, x as f32, y as f32)
                            .is_some_and(|e| e <= limit)
                    })
                    .count();
                *s = agreeing >= needed;
            }
        });
        settled
    }

    /// Per pixel of `colour`, whether its plane moved (see `PatchMatchConfig::still_depth`)
    /// between `before` (its cells before a sweep) and `board`; written into `moved`.
    fn mark_moved(&self, before: &[Hyp], board: &Board, colour: usize, moved: &mut [bool]) {
        let (w, half) = (self.width(), board.half);
        let cos_limit = self.cfg.still_normal_deg.to_radians().cos();
        let tolerance = self.cfg.still_depth;
        moved.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for i in 0..half {
                let x = 2 * i + ((colour + y) & 1);
                if x >= w {
                    continue;
                }
                let (a, b) = (&before[y * half + i], &board.cells[colour][y * half + i]);
                // Cells without a plane (depth 0, normal 0) that stay so did not move.
                row[x] = (a.depth != b.depth || a.normal != b.normal)
                    && ((a.depth - b.depth).abs() > tolerance * a.depth.max(b.depth)
                        || dot(&a.normal, &b.normal) < cos_limit);
            }
        });
    }

    /// The pixels of `colour` that a sweep may skip: `settled` ones, and those that did not
    /// move in their last sweep while no pixel of their propagation regions moved since.
    fn still(&self, moved: &[bool], colour: usize, settled: Option<&[bool]>) -> Vec<bool> {
        let (w, h) = (self.width(), self.height());
        let mut skip = vec![false; w * h];
        skip.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for x in (((colour + y) & 1)..w).step_by(2) {
                let p = y * w + x;
                if settled.is_some_and(|s| s[p]) {
                    row[x] = true;
                    continue;
                }
                if moved[p] {
                    continue;
                }
                row[x] = self.regions.iter().flatten().all(|&(dx, dy)| {
                    let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                    nx < 0
                        || ny < 0
                        || nx >= w as i32
                        || ny >= h as i32
                        || !moved[ny as usize * w + nx as usize]
                });
            }
        });
        skip
    }

    /// `sweeps` propagation + refinement passes over both colours at full resolution,
    /// starting at refinement `first_step`: after the first, the still pixels (and the
    /// `settled` ones throughout) are skipped.
    fn sweeps(&self, board: &mut Board, sweeps: usize, first_step: i32, settled: Option<&[bool]>) {
        let still = self.cfg.still_depth > 0.0;
        let mut moved = vec![true; self.width() * self.height()];
        for iteration in 0..sweeps {
            for colour in 0..2 {
                let skip = if iteration > 0 && still {
                    Some(self.still(&moved, colour, settled))
                } else {
                    settled.map(|s| s.to_vec())
                };
                let before = still.then(|| board.cells[colour].clone());
                self.sweep(
                    board,
                    colour,
                    iteration,
                    first_step + iteration as i32,
                    Pass::FullResolution,
                    skip.as_deref(),
                );

                if let Some(before) = before {
                    self.mark_moved(&before, board, colour, &mut moved);
                }
            }
        }
    }

    /// Sets every active pixel of `board` to `plane(x, y, window)` (left invalid where it
    /// gives `None`), both colours, rows in parallel: the one loop of `initialise` and
    /// `upsample`.
    fn fill(
        &self,
        board: &mut Board,
        plane: impl Fn(usize, usize, &Window) -> Option<(Hyp, [f32; MAX_SOURCES])> + Sync,
    ) {
        let (w, half, n) = (self.width(), board.half, board.sources);
        for colour in 0..2 {
            board.cells[colour]
                .par_chunks_mut(half)
                .zip(board.costs[colour].par_chunks_mut(half * n))
                .enumerate()
                .for_each(|(y, (row, costs))| {
                    for (i, cell) in row.iter_mut().enumerate() {
                        let x = 2 * i + ((colour + y) & 1);
                        if x >= w || !self.active[y * w + x] {
                            continue;
                        }
                        let Some(win) = self.window(x, y) else {
                            continue;
                        };
                        if let Some((h, c)) = plane(x, y, &win) {
                            *cell = h;
                            costs[i * n..(i + 1) * n].copy_from_slice(&c[..n]);
                        }
                    }
                });
        }
    }

    /// A random plane (inverse depth uniform over the depth range, normal over the hemisphere
    /// facing the camera) at (`x`, `y`), with its cost.
    fn random_plane(&self, x: usize, y: usize, win: &Window) -> (Hyp, [f32; MAX_SOURCES]) {
        let mut rng = Rng::for_item(self.seed, (y * self.width() + x) as u64);
        let ray = self.problem.k.ray(x as f32, y as f32);
        let depth = self.random_depth(&mut rng);
        let normal = self.random_normal(&mut rng, &ray);
        self.costed(x, y, depth, normal, win)
    }

    /// Planes with their costs at every active pixel: those of `prior`, a previous pass's
    /// depth map at the same resolution, where it has one; random ones elsewhere.
    fn initialise(&self, prior: Option<&DepthMap>, board: &mut Board) {
        let w = self.width();
        self.fill(board, |x, y, win| {
            let k = y * w + x;
            Some(match prior {
                Some(p) if p.depth[k] > 0.0 => self.costed(x, y, p.depth[k], p.normal[k], win),
                _ => self.random_plane(x, y, win),
            })
        });
    }

    /// Planes from the coarser scale's `coarse` board (image half the size): each pixel
    /// evaluates the planes of the (up to) four nearest coarse pixels, moved to its own ray,
    /// and keeps the cheapest (an upsampling guided by the matching cost, in the spirit of
    /// ACMM's joint bilateral upsampling); a random plane where none has a depth. With
    /// `nearest_only` (full resolution, where it is most of the upsampling's work) only the
    /// nearest coarse pixel's plane is costed (the next one where it has none): the next sweep
    /// propagates the neighbours' planes anyway.
    fn upsample(
        &self,
        coarse: &Board,
        coarse_k: &Intrinsics,
        board: &mut Board,
        nearest_only: bool,
    ) {
        let k = self.problem.k;
        let near = (self.cfg.still_depth > 0.0).then(|| {
            (
                self.cfg.still_depth,
                self.cfg.still_normal_deg.to_radians().cos(),
            )
        });
        self.fill(board, |x, y, win| {
            let to = k.ray(x as f32, y as f32);
            let (cx, cy) = ((x as f32 + 0.5) / 2.0 - 0.5, (y as f32 + 0.5) / 2.0 - 0.5);
            let (x0, y0) = (cx.floor().max(0.0) as usize, cy.floor().max(0.0) as usize);
            let mut neighbours = [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)];
            if nearest_only {
                // The nearest coarse pixel first, the others where it has no plane.
                let nearest = (cx.round().max(0.0) as usize, cy.round().max(0.0) as usize);
                if let Some(at) = neighbours.iter().position(|&n| n == nearest) {
                    neighbours.swap(0, at);
                }
            }
            let mut best = (INVALID, [UNKNOWN_COST; MAX_SOURCES]);
            // Coarse neighbours often hold one plane (propagation copies planes): a plane
            // within the still tolerances of one already costed is not costed again.
            let mut tried: [(f32, [f32; 3]); 4] = [(0.0, [0.0; 3]); 4];
            let mut n_tried = 0;
            for (nx, ny) in neighbours {
                if nx >= coarse.width || ny >= coarse.height || (nearest_only && n_tried > 0) {
                    continue;
                }
                let h = coarse.get(nx, ny);
                if h.depth <= 0.0 {
                    continue;
                }
                let from = coarse_k.ray(nx as f32, ny as f32);
                let denom = dot(&h.normal, &to);
                if denom >= -1e-6 {
                    continue;
                }
                let depth = h.depth * dot(&h.normal, &from) / denom;
                if !(depth.is_finite() && depth > 0.0) {
                    continue;
                }
                if let Some((tolerance, cos_limit)) = near
                    && tried[..n_tried].iter().any(|(d, n)| {
                        (d - depth).abs() <= tolerance * depth && dot(n, &h.normal) >= cos_limit
                    })
                {
                    continue;
                }
                tried[n_tried] = (depth, h.normal);
                n_tried += 1;
                let candidate = self.costed(x, y, depth, h.normal, win);
                if candidate.0.cost < best.0.cost {
                    best = candidate;
                }
            }
            Some(if best.0.depth > 0.0 {
                best
            } else {
                self.random_plane(x, y, win)
            })
        });
    }

    /// One propagation + refinement pass over the pixels of `colour` (what it tries depends on
    /// `pass`, see [`Pass`]); `skip`:
    /// pixels that keep their plane (settled or still; they still propagate it).
    fn sweep(
        &self,
        board: &mut Board,
        colour: usize,
        iteration: usize,
        step: i32,
        pass: Pass,
        skip: Option<&[bool]>,
    ) {
        let near = (pass == Pass::FullResolution && self.cfg.still_depth > 0.0).then(|| {
            (
                self.cfg.still_depth.max(1e-5),
                self.cfg.still_normal_deg.to_radians().cos(),
            )
        });
        let (w, h, half, n) = (self.width(), self.height(), board.half, board.sources);
        let [red, black] = &mut board.cells;
        let (current, other): (&mut Vec<Hyp>, &Vec<Hyp>) = if colour == 0 {
            (red, black)
        } else {
            (black, red)
        };
        let current_costs = &mut board.costs[colour];
        let seed = self.seed ^ (0x5EED_0000 + (2 * iteration + colour + 1) as u64);
        // Perturbations shrink by half per step (Gipuma's refinement schedule).
        let scale = 0.5f32.powi(step);
        let depth_amount = (0.05 * scale).max(0.002);
        let normal_amount = (0.5 * scale).max(0.02);
        current
            .par_chunks_mut(half)
            .zip(current_costs.par_chunks_mut(half * n))
            .enumerate()
            .for_each(|(y, (row, row_costs))| {
                for (i, cell) in row.iter_mut().enumerate() {
                    let stored = &mut row_costs[i * n..(i + 1) * n];
                    let x = 2 * i + ((colour + y) & 1);
                    if x >= w || !self.active[y * w + x] || skip.is_some_and(|s| s[y * w + x]) {
                        continue;
                    }
                    let Some(win) = self.window(x, y) else {
                        continue;
                    };
                    // Propagation: the cheapest hypothesis of each region, moved along its
                    // plane, plus the current one.
                    let mut candidates = [(0.0f32, [0.0f32; 3]); 9];
                    let mut count = 0;
                    if cell.depth > 0.0 {
                        candidates[0] = (cell.depth, cell.normal);
                        count = 1;
                    }
                    for region in &self.regions {
                        let mut pick: Option<(Hyp, usize, usize)> = None;
                        for &(dx, dy) in region {
                            let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                            if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                                continue;
                            }
                            let (nx, ny) = (nx as usize, ny as usize);
                            let cand = &other[ny * half + nx / 2];
                            if cand.depth > 0.0 && pick.is_none_or(|(p, _, _)| cand.cost < p.cost) {
                                pick = Some((*cand, nx, ny));
                            }
                        }
                        if let Some((cand, nx, ny)) = pick
                            && let Some(depth) = self.transfer(&cand, nx, ny, x, y)
                        {
                            candidates[count] = (depth, cand.normal);
                            count += 1;
                        }
                    }
                    // Neighbours often hold the same plane (propagation copies planes, and
                    // the upsampling gives a 2x2 block one coarse plane): a plane moved to `p`
                    // again costs what it cost the first time.
                    // At full resolution, a plane within the still tolerances of an earlier
                    // candidate is taken as that candidate (its costs and its plane).
                    let mut matrix = [[MAX_COST; MAX_SOURCES]; 9];
                    for c in 0..count {
                        let (depth, normal) = candidates[c];
                        let same = (0..c).find(|&e| {
                            let (d, n) = candidates[e];
                            match near {
                                Some((tolerance, cos_limit)) => {
                                    (d - depth).abs() <= tolerance * depth
                                        && dot(&n, &normal) >= cos_limit
                                }
                                None => n == normal && (d - depth).abs() <= 1e-5 * depth,
                            }
                        });
                        matrix[c] = match same {
                            Some(e) => {
                                candidates[c] = candidates[e];
                                matrix[e]
                            }
                            // The pixel's own plane: its costs are stored, but for the
                            // sources its last refinement left out.
                            None if c == 0 && cell.depth > 0.0 => {
                                self.complete_costs(x, y, depth, &normal, &win, stored)
                            }
                            None => self.source_costs(x, y, depth, &normal, &win, None),
                        };
                    }
                    let weights = if self.cfg.adaptive_views {
                        self.view_weights(&matrix[..count], step)
                    } else {
                        None
                    };
                    let top_k = self.cfg.top_k;
                    let combine = |mut c: [f32; MAX_SOURCES]| match &weights {
                        Some(wts) => weighted(&c, wts),
                        None => aggregate(&mut c[..n], top_k),
                    };
                    // Without weights the current cost stands as stored; with them every
                    // candidate, the current one included, is judged under the same weights.
                    let mut best = if weights.is_some() { INVALID } else { *cell };
                    // The per-source costs of `best` (without weights and no better
                    // candidate, `best` is the pixel's own plane, candidate 0).
                    let mut best_costs = matrix[0];
                    for (row, (depth, normal)) in matrix.iter().zip(&candidates[..count]) {
                        let cost = combine(*row);
                        if cost < best.cost {
                            best = Hyp {
                                depth: *depth,
                                normal: *normal,
                                cost,
                            };
                            best_costs = *row;
                        }
                    }
                    if best.depth <= 0.0 {
                        continue;
                    }
                    // Refinement: new and perturbed depths and normals.
                    let mut rng = Rng::for_item(seed, (y * w + x) as u64);
                    let ray = self.problem.k.ray(x as f32, y as f32);
                    let (lo, hi) = self.problem.depth_range;
                    // Planes drawn at random only help while the search is coarse: a finer
                    // scale or the geometric pass starts from a solution and only perturbs
                    // (and draws no random plane).
                    let coarsest = pass == Pass::Coarsest;
                    let random = coarsest.then(|| {
                        (
                            self.random_depth(&mut rng),
                            self.random_normal(&mut rng, &ray),
                        )
                    });
                    let perturbed_depth = (best.depth
                        * (1.0 + depth_amount * (2.0 * rng.uniform() as f32 - 1.0)))
                        .clamp(lo, hi);
                    let perturbed_normal =
                        self.perturb_normal(&mut rng, &best.normal, &ray, normal_amount);
                    let (d0, n0) = (best.depth, best.normal);
                    let (random_depth, random_normal) = random.unwrap_or((d0, n0));
                    let trials = [
                        (perturbed_depth, n0),
                        (d0, perturbed_normal),
                        (perturbed_depth, perturbed_normal),
                        (random_depth, n0),
                        (d0, random_normal),
                        (random_depth, random_normal),
                    ];
                    let trials = if coarsest { &trials[..] } else { &trials[..3] };
                    for &(depth, normal) in trials {
                        if depth <= 0.0 || (depth == best.depth && normal == best.normal) {
                            continue;
                        }
                        let costs = match &weights {
                            // A trial that cannot beat `best` is dropped as soon as its
                            // heaviest sources show it.
                            Some(wts) => match self
                                .bounded_costs(x, y, depth, &normal, &win, wts, best.cost)
                            {
                                Some(c) => c,
                                None => continue,
                            },
                            None => self.source_costs(x, y, depth, &normal, &win, None),
                        };
                        let cost = combine(costs);
                        if cost < best.cost {
                            best = Hyp {
                                depth,
                                normal,
                                cost,
                            };
                            best_costs = costs;
                        }
                    }
                    *cell = best;
                    stored.copy_from_slice(&best_costs[..n]);
                }
            });
    }
}

/// `1 - NCC` from the lane sums of `a_k s_k`, `w_k s_k` and `w_k s_k^2` (see the module
/// documentation); [`MAX_COST`] when the source's window is flat.
#[inline(always)]
fn ncc_cost(sa: &[f32; LANES], sw: &[f32; LANES], sww: &[f32; LANES]) -> f32 {
    let (sa, sw, sww): (f32, f32, f32) = (sa.iter().sum(), sw.iter().sum(), sww.iter().sum());
    let var = sww - sw * sw;
    if var <= 1e-10 {
        return MAX_COST;
    }
    (1.0 - sa / var.sqrt()).clamp(0.0, MAX_COST)
}

/// The `weights`-weighted mean of `costs`.
#[inline]
fn weighted(costs: &[f32; MAX_SOURCES], weights: &[f32; MAX_SOURCES]) -> f32 {
    let (mut sum, mut total) = (0.0, 0.0);
    for (c, w) in costs.iter().zip(weights) {
        sum += c * w;
        total += w;
    }
    sum / total
}

/// The mean of the `k` smallest costs (all of them when fewer).
#[inline]
fn aggregate(costs: &mut [f32], k: usize) -> f32 {
    if costs.is_empty() {
        return MAX_COST;
    }
    let k = k.min(costs.len());
    // Partial selection sort: k is small.
    let mut sum = 0.0;
    for i in 0..k {
        let mut m = i;
        for j in i + 1..costs.len() {
            if costs[j] < costs[m] {
                m = j;
            }
        }
        costs.swap(i, m);
        sum += costs[i];
    }
    sum / k as f32
}

#[inline]
fn dot(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Smallest image side a coarser scale may have.
const MIN_SCALE_SIDE: usize = 96;

/// `image` halved: each pixel the mean of a 2x2 block (a last odd row or column is dropped).
fn halve(image: &GreyImage) -> GreyImage {
    let (w, h) = (image.width / 2, image.height / 2);
    let mut out = GreyImage::new(w, h);
    out.data
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let (r0, r1) = (image.row(2 * y), image.row(2 * y + 1));
            for (x, v) in row.iter_mut().enumerate() {
                *v = 0.25 * (r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1]);
            }
        });
    out
}

/// A mask halved: a coarse pixel is in when any of its 2x2 block is.
fn halve_mask(mask: &[u8], width: usize, height: usize) -> Vec<u8> {
    let (w, h) = (width / 2, height / 2);
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let at = |xx: usize, yy: usize| mask[yy * width + xx];
            out[y * w + x] = (at(2 * x, 2 * y)
                | at(2 * x + 1, 2 * y)
                | at(2 * x, 2 * y + 1)
                | at(2 * x + 1, 2 * y + 1)
                != 0) as u8;
        }
    }
    out
}

/// Where a sweep runs, which decides what it tries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pass {
    /// The coarsest scale: the refinement also tries random depths and normals.
    Coarsest,
    /// A finer scale but the finest: the refinement only perturbs.
    Finer,
    /// Full resolution (the finest scale, the geometric pass): as `Finer`, and propagation
    /// candidates within the still tolerances of an earlier one are taken as that one.
    FullResolution,
}

/// Which code the window costs run on. Both give the same depth map bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// The widest registers the CPU has (AVX2 when detected at run time).
    Fastest,
    /// The build's baseline instructions (SSE2 on x86-64).
    Portable,
}

/// Runs PatchMatch on `problem` with `seed`, coarse to fine, and returns its depth map at full
/// resolution (pixels above `cfg.max_cost` cleared).
pub fn patch_match(problem: &Problem, cfg: &PatchMatchConfig, seed: u64) -> DepthMap {
    patch_match_on(problem, cfg, seed, Kernel::Fastest)
}

/// [`patch_match`] with the window costs on `kernel`.
pub fn patch_match_on(
    problem: &Problem,
    cfg: &PatchMatchConfig,
    seed: u64,
    kernel: Kernel,
) -> DepthMap {
    let (w, h) = (problem.image.width, problem.image.height);
    if problem.sources.is_empty() {
        return Board::new(w, h, 0).to_depth_map(cfg.max_cost);
    }
    if let Some(prior) = problem.prior {
        // The geometric pass: full resolution, from the first pass's planes.
        let solver = Solver::new(problem, cfg, seed ^ 0x6E0_u64, kernel);
        let mut board = Board::new(w, h, problem.sources.len());
        solver.initialise(Some(prior), &mut board);
        let settled = solver.settled(&board);
        solver.sweeps(&mut board, cfg.geometric_iterations, 4, Some(&settled));
        return board.to_depth_map(cfg.max_cost + cfg.geometric_weight);
    }
    // The pyramid: level 0 is the full resolution.
    let mut levels = 1;
    while levels < cfg.scales && (w >> levels).min(h >> levels) >= MIN_SCALE_SIDE {
        levels += 1;
    }
    let mut refs = vec![problem.image.clone()];
    let mut srcs: Vec<Vec<GreyImage>> = vec![Vec::new()];
    let mut masks: Vec<Option<Vec<u8>>> = vec![problem.mask.map(|m| m.to_vec())];
    for l in 1..levels {
        let r = halve(&refs[l - 1]);
        let s: Vec<GreyImage> = if l == 1 {
            problem.sources.iter().map(|s| halve(s.image)).collect()
        } else {
            srcs[l - 1].iter().map(halve).collect()
        };
        let m = masks[l - 1]
            .as_ref()
            .map(|m| halve_mask(m, refs[l - 1].width, refs[l - 1].height));
        refs.push(r);
        srcs.push(s);
        masks.push(m);
    }
    let mut coarse: Option<(Board, Intrinsics)> = None;
    for level in (0..levels).rev() {
        let factor = (1usize << level) as f64;
        let k = problem.k.downscaled(factor);
        let sources = problem
            .sources
            .iter()
            .enumerate()
            .map(|(i, s)| Source {
                image: if level == 0 { s.image } else { &srcs[level][i] },
                k: s.k.downscaled(factor),
                src_from_ref: s.src_from_ref,
                depth: None,
            })
            .collect();
        let lp = Problem {
            image: &refs[level],
            k,
            sources,
            depth_range: problem.depth_range,
            mask: masks[level].as_deref(),
            prior: None,
        };
        let level_seed = seed ^ (level as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let solver = Solver::new(&lp, cfg, level_seed, kernel);
        let mut board = Board::new(lp.image.width, lp.image.height, lp.sources.len());
        let coarsest = coarse.is_none();
        let (iterations, first_step) = match &coarse {
            None => {
                solver.initialise(None, &mut board);
                (cfg.iterations, 0)
            }
            Some((c, ck)) => {
                solver.upsample(c, ck, &mut board, level == 0);
                // Finer scales refine: their perturbations start where the coarse ones ended.
                let sweeps = if level == 0 {
                    cfg.finest_iterations
                } else {
                    cfg.fine_iterations
                };
                (sweeps, cfg.iterations.min(4) as i32)
            }
        };
        if level == 0 && !coarsest {
            solver.sweeps(&mut board, iterations, first_step, None);
        }
        for iteration in (0..iterations).filter(|_| level > 0 || coarsest) {
            for colour in 0..2 {
                solver.sweep(
                    &mut board,
                    colour,
                    iteration,
                    first_step + iteration as i32,
                    if coarsest {
                        Pass::Coarsest
                    } else {
                        Pass::Finer
                    },
                    None,
                );
            }
        }
        coarse = Some((board, k));
    }
    let (board, _) = coarse.expect("at least one level");
    board.to_depth_map(cfg.max_cost)
}

/// The camera-frame point of array position (`x`, `y`) at `depth`.
pub fn backproject(k: &Intrinsics, x: f64, y: f64, depth: f64) -> Vector3<f64> {
    Vector3::new((x - k.cx) / k.fx * depth, (y - k.cy) / k.fy * depth, depth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::{UnitQuaternion, Vector3};

    /// A procedural texture on the world plane z = 0 (a sum of sines: smooth but rich).
    fn texture(x: f64, y: f64) -> f32 {
        let v = 0.5
            + 0.2 * (7.1 * x + 1.3 * y).sin()
            + 0.15 * (3.7 * y - 5.3 * x).sin() * (11.0 * x).cos()
            + 0.1 * (17.0 * y + 2.0 * x).sin();
        v as f32
    }

    /// Renders the textured plane z = 0 into a camera at `cam_from_world` (ray casting).
    fn render(k: &Intrinsics, w: usize, h: usize, cam_from_world: &Rigid3) -> GreyImage {
        let world_from_cam = cam_from_world.inverse();
        let mut img = GreyImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let d = world_from_cam.transform_vector(&backproject(k, x as f64, y as f64, 1.0));
                let c = world_from_cam.translation;
                let t = -c.z / d.z;
                let p = c + d * t;
                img.data[y * w + x] = texture(p.x, p.y);
            }
        }
        img
    }

    /// A camera at `eye` looking down at the plane z = 0 (tilted by `tilt` about x).
    fn camera_at(eye: Vector3<f64>, tilt: f64) -> Rigid3 {
        // Camera looking along -z world: rotate 180 degrees about x, then tilt.
        let r = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI + tilt);
        let world_from_cam = Rigid3::new(r, eye);
        world_from_cam.inverse()
    }

    /// The plane scene's problem: the reference view `reference` with its image, and each
    /// source camera with its image and, for a geometric pass, its depth map; all with
    /// intrinsics `k`, depths drawn from [1, 4].
    /// The 64x48 plane scene of the kernel comparisons: a reference camera and two sources
    /// (the second tilted by `second_tilt`), rendered.
    struct KernelScene {
        w: usize,
        h: usize,
        k: Intrinsics,
        reference: Rigid3,
        cams: [Rigid3; 2],
        ref_img: GreyImage,
        imgs: Vec<GreyImage>,
    }

    fn kernel_scene(second_tilt: f64) -> KernelScene {
        let (w, h) = (64, 48);
        let k = Intrinsics {
            fx: 60.0,
            fy: 60.0,
            cx: 31.5,
            cy: 23.5,
        };
        let reference = camera_at(Vector3::new(0.0, 0.0, 2.0), 0.2);
        let cams = [
            camera_at(Vector3::new(0.3, 0.0, 2.0), 0.2),
            camera_at(Vector3::new(-0.25, 0.1, 2.1), second_tilt),
        ];
        let ref_img = render(&k, w, h, &reference);
        let imgs = cams.iter().map(|c| render(&k, w, h, c)).collect();
        KernelScene {
            w,
            h,
            k,
            reference,
            cams,
            ref_img,
            imgs,
        }
    }

    fn plane_problem<'a>(
        ref_img: &'a GreyImage,
        k: Intrinsics,
        reference: &Rigid3,
        sources: impl IntoIterator<Item = (&'a Rigid3, &'a GreyImage, Option<&'a DepthMap>)>,
        prior: Option<&'a DepthMap>,
    ) -> Problem<'a> {
        Problem {
            image: ref_img,
            k,
            sources: sources
                .into_iter()
                .map(|(c, image, depth)| Source {
                    image,
                    k,
                    src_from_ref: *c * reference.inverse(),
                    depth,
                })
                .collect(),
            depth_range: (1.0, 4.0),
            mask: None,
            prior,
        }
    }

    #[test]
    fn stacked_rows_hold_each_pixel_and_the_one_below() {
        let (w, h) = (7, 5);
        let mut img = GreyImage::new(w, h);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i * 37 % 101) as f32 / 100.0;
        }
        let stacked = stack_rows(&img);
        assert_eq!(stacked.len(), 2 * w * h);
        let at = |x: usize, y: usize| img.data[y.min(h - 1) * w + x];
        for y in 0..h {
            for x in 0..w {
                let i = 2 * (y * w + x);
                assert_eq!([stacked[i], stacked[i + 1]], [at(x, y), at(x, y + 1)]);
                // The four bilinear neighbours are consecutive, as the AVX2 kernel loads them.
                if x + 1 < w && y + 1 < h {
                    assert_eq!(
                        stacked[i..i + 4],
                        [at(x, y), at(x, y + 1), at(x + 1, y), at(x + 1, y + 1)]
                    );
                }
            }
        }
    }

    /// The AVX2 window cost is the portable one bit for bit: on random planes at random
    /// pixels, and on warps (translations) whose samples reach the source's last row and
    /// column, where the stacked image's neighbours end.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_and_portable_window_costs_agree_bit_for_bit() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let KernelScene {
            w,
            h,
            k,
            reference,
            cams,
            ref_img,
            imgs,
        } = kernel_scene(0.25);
        let sources = cams.iter().zip(&imgs).map(|(c, img)| (c, img, None));
        let problem = plane_problem(&ref_img, k, &reference, sources, None);
        let cfg = PatchMatchConfig::default();
        let fast = Solver::new(&problem, &cfg, 3, Kernel::Fastest);
        let portable = Solver::new(&problem, &cfg, 3, Kernel::Portable);
        assert!(fast.avx2 && !portable.avx2);
        let mut rng = Rng::new(11);
        let mut matched = 0;
        for _ in 0..3000 {
            let x = 5 + (rng.uniform() * (w - 10) as f64) as usize;
            let y = 5 + (rng.uniform() * (h - 10) as f64) as usize;
            let Some(win) = fast.window(x, y) else {
                continue;
            };
            let ray = k.ray(x as f32, y as f32);
            let depth = fast.random_depth(&mut rng);
            let normal = fast.random_normal(&mut rng, &ray);
            let a = fast.source_costs(x, y, depth, &normal, &win, None);
            let b = portable.source_costs(x, y, depth, &normal, &win, None);
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "({x}, {y})");
            matched += a.iter().filter(|&&c| c < MAX_COST).count();
        }
        assert!(matched > 500, "{matched} costs inside the sources");
        // Translations putting the window's last samples on the last pixel a lookup may start
        // from (and just past it, which must be refused by both).
        let src = &fast.sources[0];
        let (x, y) = (20, 20);
        let win = fast.window(x, y).expect("textured");
        let last = (2 * cfg.window_radius) as f32;
        for (tx, ty) in [
            (src.max_x - (x as f32 + 5.0), src.max_y - (y as f32 + 5.0)),
            (-(x as f32 - 5.0), -(y as f32 - 5.0)),
            (src.max_x - (x as f32 + 5.0) + 0.01, 0.0),
            (0.0, src.max_y - (y as f32 - 5.0 + last) + 0.5),
        ] {
            let hom = [1.0, 0.0, tx, 0.0, 1.0, ty, 0.0, 0.0, 1.0];
            let slow = portable.source_cost(src, &hom, x, y, &win);
            // SAFETY: the CPU has AVX2 (checked above).
            let quick = unsafe { fast.source_cost_avx2(src, &hom, x, y, &win) };
            assert_eq!(slow.to_bits(), quick.to_bits(), "translation ({tx}, {ty})");
        }
    }

    #[test]
    fn recovers_a_slanted_plane_to_a_fraction_of_a_pixel() {
        let (w, h) = (96, 80);
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 47.5,
            cy: 39.5,
        };
        let reference = camera_at(Vector3::new(0.0, 0.0, 2.0), 0.35);
        let sources: Vec<Rigid3> = [(-0.4, 0.0), (0.4, 0.0), (0.0, 0.3), (0.0, -0.3)]
            .iter()
            .map(|&(dx, dy)| camera_at(Vector3::new(dx, dy, 2.0), 0.35))
            .collect();
        let ref_img = render(&k, w, h, &reference);
        let src_imgs: Vec<GreyImage> = sources.iter().map(|p| render(&k, w, h, p)).collect();
        let views = sources.iter().zip(&src_imgs).map(|(p, img)| (p, img, None));
        let problem = plane_problem(&ref_img, k, &reference, views, None);
        let cfg = PatchMatchConfig::default();
        let map = patch_match(&problem, &cfg, 7);
        // Ground truth: the depth of the plane z = 0 along each ray.
        let world_from_cam = reference.inverse();
        let mut errors = Vec::new();
        let mut normal_errors = Vec::new();
        let n_true = reference.transform_vector(&Vector3::z());
        let n_true = if n_true.z > 0.0 { -n_true } else { n_true };
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if map.depth[i] <= 0.0 {
                    continue;
                }
                let d = world_from_cam.transform_vector(&backproject(&k, x as f64, y as f64, 1.0));
                let t = -world_from_cam.translation.z / d.z;
                errors.push((map.depth[i] as f64 - t).abs() / t);
                let n = Vector3::new(
                    map.normal[i][0] as f64,
                    map.normal[i][1] as f64,
                    map.normal[i][2] as f64,
                );
                normal_errors.push(n.angle(&n_true).to_degrees());
            }
        }
        let valid = errors.len() as f64 / ((w - 10) * (h - 10)) as f64;
        errors.sort_by(f64::total_cmp);
        normal_errors.sort_by(f64::total_cmp);
        let median = errors[errors.len() / 2];
        let p90 = errors[errors.len() * 9 / 10];
        // One pixel of disparity at this baseline (0.4 at depth ~2, f = 100) is about 5% of
        // the depth; a median error of 0.1% is a 50th of a pixel.
        assert!(valid > 0.7, "valid fraction {valid}");
        assert!(median < 1e-3 && p90 < 5e-3, "median {median}, p90 {p90}");
        assert!(normal_errors[normal_errors.len() / 2] < 3.0);
    }

    /// The true depth map of the plane z = 0 seen from `cam_from_world`.
    fn plane_depths(k: &Intrinsics, w: usize, h: usize, cam_from_world: &Rigid3) -> DepthMap {
        let world_from_cam = cam_from_world.inverse();
        let n = cam_from_world.transform_vector(&Vector3::z());
        let n = if n.z > 0.0 { -n } else { n };
        let mut map = DepthMap::empty(w, h);
        for y in 0..h {
            for x in 0..w {
                let d = world_from_cam.transform_vector(&backproject(k, x as f64, y as f64, 1.0));
                let i = y * w + x;
                map.depth[i] = (-world_from_cam.translation.z / d.z) as f32;
                map.normal[i] = [n.x as f32, n.y as f32, n.z as f32];
                map.cost[i] = 0.0;
            }
        }
        map
    }

    #[test]
    fn geometric_pass_keeps_settled_planes_and_mends_the_others() {
        let (w, h) = (64, 56);
        let k = Intrinsics {
            fx: 70.0,
            fy: 70.0,
            cx: 31.5,
            cy: 27.5,
        };
        let reference = camera_at(Vector3::new(0.0, 0.0, 2.0), 0.3);
        let sources: Vec<Rigid3> = [(-0.4, 0.0), (0.4, 0.0), (0.0, 0.3)]
            .iter()
            .map(|&(dx, dy)| camera_at(Vector3::new(dx, dy, 2.0), 0.3))
            .collect();
        let ref_img = render(&k, w, h, &reference);
        let src_imgs: Vec<GreyImage> = sources.iter().map(|p| render(&k, w, h, p)).collect();
        let src_maps: Vec<DepthMap> = sources.iter().map(|p| plane_depths(&k, w, h, p)).collect();
        let truth = plane_depths(&k, w, h, &reference);
        // The first pass got a block 10% too far: those pixels disagree with every source.
        let mut prior = truth.clone();
        let wrong = |x: usize, y: usize| (20..36).contains(&x) && (20..36).contains(&y);
        for y in 0..h {
            for x in 0..w {
                if wrong(x, y) {
                    prior.depth[y * w + x] *= 1.1;
                }
            }
        }
        let views = sources
            .iter()
            .zip(&src_imgs)
            .zip(&src_maps)
            .map(|((p, img), map)| (p, img, Some(map)));
        let problem = plane_problem(&ref_img, k, &reference, views, Some(&prior));
        let cfg = PatchMatchConfig::default();
        let map = patch_match(&problem, &cfg, 5);
        let (mut kept, mut right, mut mended, mut wrong_total) = (0, 0, 0, 0);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if map.depth[i] <= 0.0 {
                    continue;
                }
                let error = (map.depth[i] - truth.depth[i]).abs() / truth.depth[i];
                if wrong(x, y) {
                    wrong_total += 1;
                    mended += (error < 0.01) as usize;
                } else {
                    right += 1;
                    kept += (map.depth[i] == prior.depth[i] && map.normal[i] == prior.normal[i])
                        as usize;
                }
            }
        }
        // Settled pixels are not swept: their plane stays the prior's, bit for bit (all but
        // those near the border, which fewer than two sources see).
        assert!(
            right > 1000 && kept as f64 > 0.95 * right as f64,
            "{kept} of {right} kept"
        );
        // The wrong block is swept: its neighbours' (true) planes propagate into it.
        assert!(
            wrong_total > 150 && mended as f64 > 0.9 * wrong_total as f64,
            "{mended} of {wrong_total} mended"
        );
    }

    #[test]
    fn same_seed_same_map_whatever_the_thread_count() {
        let (w, h) = (48, 40);
        let k = Intrinsics {
            fx: 50.0,
            fy: 50.0,
            cx: 23.5,
            cy: 19.5,
        };
        let reference = camera_at(Vector3::new(0.0, 0.0, 2.0), 0.2);
        let source = camera_at(Vector3::new(0.3, 0.0, 2.0), 0.2);
        let ref_img = render(&k, w, h, &reference);
        let src_img = render(&k, w, h, &source);
        let problem = plane_problem(&ref_img, k, &reference, [(&source, &src_img, None)], None);
        let cfg = PatchMatchConfig {
            iterations: 2,
            ..Default::default()
        };
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| patch_match(&problem, &cfg, 3))
        };
        assert_eq!(run(1), run(3));
    }

    /// The AVX2 window costs are the portable ones bit for bit (no FMA, same order): the
    /// depth maps of both kernels are equal, first and geometric pass. (On a CPU without AVX2
    /// both run the portable code.)
    #[test]
    fn avx2_and_portable_kernels_give_the_same_map() {
        let KernelScene {
            w,
            h,
            k,
            reference,
            cams,
            ref_img,
            imgs,
        } = kernel_scene(0.2);
        let maps: Vec<DepthMap> = cams.iter().map(|c| plane_depths(&k, w, h, c)).collect();
        let cfg = PatchMatchConfig {
            iterations: 2,
            scales: 1,
            settled_px: 0.0,
            ..Default::default()
        };
        let problem = |geometric: bool, prior: Option<&'_ DepthMap>| -> DepthMap {
            let sources = cams
                .iter()
                .zip(&imgs)
                .zip(&maps)
                .map(|((c, img), map)| (c, img, geometric.then_some(map)));
            let p = plane_problem(&ref_img, k, &reference, sources, prior);
            let fast = patch_match_on(&p, &cfg, 5, Kernel::Fastest);
            let portable = patch_match_on(&p, &cfg, 5, Kernel::Portable);
            assert_eq!(fast, portable);
            fast
        };
        let first = problem(false, None);
        assert!(first.valid_fraction() > 0.5, "{}", first.valid_fraction());
        let second = problem(true, Some(&first));
        assert!(second.valid_fraction() > 0.5, "{}", second.valid_fraction());
    }
}
