//! Sparse bundle adjustment: Levenberg–Marquardt over camera poses, 3D points and camera
//! intrinsics, minimising the (robust) reprojection error (paper 003, section 3: "refining
//! the solution using Bundle Adjustment ... minimizes the reprojection error").
//!
//! The normal equations `[U W; W^T V] [dc; dp] = [bc; bp]` are reduced to the camera system
//! with the Schur complement on the points (Triggs et al. 2000, section 6.1):
//! `(U - W V^-1 W^T) dc = bc - W V^-1 bp`, where `V` is block diagonal with one 3x3 block per
//! point, so the elimination runs point by point in parallel. The reduced camera system is
//! assembled block-sparse (only pairs of cameras that see a common point have a block) and
//! factored with faer's sparse Cholesky (AMD ordering; the symbolic factorisation is computed
//! once per adjustment). The points follow by back-substitution. Memory is proportional to the
//! observations (one 2-row Jacobian per observation) plus the reduced system.
//!
//! Parameterisation: rotations are updated on the left, `R <- exp([dw]x) R`; translations,
//! points and intrinsics additively. Damping is Marquardt's, `lambda * diag(J^T J)` (clamped),
//! with Nielsen's update of lambda. Robust losses enter by IRLS weights (`loss.rs`).
//!
//! Gauge freedom (7 dof: rotation, translation, scale) is removed by fixing one pose entirely
//! and one translation coordinate of a second camera (the coordinate most sensitive to the
//! scale), as COLMAP does, unless enough poses are constant already.

use fresco_core::config::{ConfigError, require};
use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

use fresco_core::{CameraModel, Reconstruction};
use nalgebra::{Matrix2x3, Matrix3, SMatrix, SVector, UnitQuaternion, Vector2, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::bundle::loss::Loss;
use fresco_core::camera::MAX_PARAMS;

/// Most camera-side unknowns one observation touches: a pose (6) and all intrinsics.
const MAX_DC: usize = 6 + MAX_PARAMS;
type CamJacobian = SMatrix<f64, 2, MAX_DC>;
type CamVector = SVector<f64, MAX_DC>;

/// How the reduced camera system is solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum LinearSolver {
    /// Sparse Cholesky (faer, AMD ordering) of the block-sparse reduced camera system.
    SparseCholesky,
    /// Dense Cholesky of the reduced camera system: fastest for a few dozen cameras.
    DenseCholesky,
    /// Dense below `dense_limit` unknowns, sparse above.
    Auto { dense_limit: usize },
}

/// Bundle adjustment settings.
#[derive(Clone, Debug, Serialize)]
pub struct BundleConfig {
    /// Robust loss on the reprojection error, scale in pixels. Default: `Huber(2.0)` (2 px):
    /// residuals of a well-matched feature (about 1 px) stay quadratic, mismatches pull
    /// linearly.
    pub loss: Loss,
    /// Refine focal lengths. Default: `true`.
    pub refine_focal: bool,
    /// Refine the principal point. Default: `false`: it is poorly constrained without a
    /// calibration pattern and trades off against the pose (COLMAP's default too).
    pub refine_principal_point: bool,
    /// Refine distortion parameters (k1, k2, p1, p2 as the model has them). Default: `true`.
    pub refine_distortion: bool,
    /// Most Levenberg–Marquardt iterations (accepted or rejected steps). Default: `100`.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction. Default: `1e-6`.
    pub function_tolerance: f64,
    /// Stop when the largest gradient entry falls below this. Default: `1e-10`.
    pub gradient_tolerance: f64,
    /// Stop when the step is smaller than this fraction of the parameter norm. Default: `1e-8`.
    pub parameter_tolerance: f64,
    /// Reduced camera system solver. Default `Auto { dense_limit: 300 }`.
    /// Default: `Auto { dense_limit: 300 }`.
    pub linear_solver: LinearSolver,
}

impl Default for BundleConfig {
    fn default() -> Self {
        BundleConfig {
            loss: Loss::Huber(2.0),
            refine_focal: true,
            refine_principal_point: false,
            refine_distortion: true,
            max_iterations: 100,
            function_tolerance: 1e-6,
            gradient_tolerance: 1e-10,
            parameter_tolerance: 1e-8,
            linear_solver: LinearSolver::Auto { dense_limit: 300 },
        }
    }
}

impl BundleConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        for (name, value) in [
            ("function_tolerance", self.function_tolerance),
            ("gradient_tolerance", self.gradient_tolerance),
            ("parameter_tolerance", self.parameter_tolerance),
        ] {
            require(
                value.is_finite() && value >= 0.0,
                name,
                value,
                "finite and >= 0",
            )?;
        }
        if let LinearSolver::Auto { dense_limit } = self.linear_solver {
            require(
                dense_limit >= 1,
                "linear_solver.dense_limit",
                dense_limit,
                ">= 1",
            )?;
        }
        Ok(())
    }
}

/// How the gauge (global rotation, translation and scale) is fixed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gauge {
    /// Fix the pose of the first image entirely and, of the second, the translation
    /// coordinate most sensitive to the scale (7 dof, like COLMAP).
    Pair(u32, u32),
    /// `Pair` over two images picked automatically (the two variable images with the most
    /// observations), unless the problem has at least two constant poses already.
    Auto,
    /// Nothing fixed beyond `constant_poses` (the damping keeps the system solvable).
    Free,
}

/// Which parts of a reconstruction one adjustment moves.
///
/// The problem holds every 3D point seen by an image of `images`, with all observations of
/// those points: observations from images outside `images` enter with their poses constant
/// (this is how a local adjustment keeps its neighbourhood in place).
#[derive(Clone, Debug)]
pub struct BundleSetup {
    /// Images whose observations (and poses, unless in `constant_poses`) are adjusted.
    pub images: BTreeSet<u32>,
    /// Images of `images` whose poses stay fixed.
    pub constant_poses: BTreeSet<u32>,
    /// Cameras whose intrinsics stay fixed even when the config refines intrinsics.
    pub constant_cameras: BTreeSet<u32>,
    /// Points that stay fixed.
    pub constant_points: BTreeSet<u64>,
    pub gauge: Gauge,
}

impl BundleSetup {
    /// Every registered image, gauge chosen automatically.
    pub fn global(rec: &Reconstruction) -> Self {
        BundleSetup {
            images: rec.images.keys().copied().collect(),
            constant_poses: BTreeSet::new(),
            constant_cameras: BTreeSet::new(),
            constant_points: BTreeSet::new(),
            gauge: Gauge::Auto,
        }
    }

    /// Local adjustment around `image_id`: that image and the `neighbours` registered images
    /// sharing the most 3D points with it (COLMAP's local BA uses 6).
    pub fn local(rec: &Reconstruction, image_id: u32, neighbours: usize) -> Self {
        let mut shared: BTreeMap<u32, usize> = BTreeMap::new();
        if let Some(image) = rec.images.get(&image_id) {
            for pid in image.point3d_ids.iter().flatten() {
                if let Some(p) = rec.points3d.get(pid) {
                    for el in &p.track {
                        if el.image_id != image_id {
                            *shared.entry(el.image_id).or_default() += 1;
                        }
                    }
                }
            }
        }
        let mut ranked: Vec<(u32, usize)> = shared.into_iter().collect();
        ranked.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        let mut images: BTreeSet<u32> = ranked.iter().take(neighbours).map(|r| r.0).collect();
        images.insert(image_id);
        BundleSetup {
            images,
            constant_poses: BTreeSet::new(),
            constant_cameras: BTreeSet::new(),
            constant_points: BTreeSet::new(),
            gauge: Gauge::Auto,
        }
    }
}

/// Why an adjustment stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Termination {
    /// The relative cost decrease fell below `function_tolerance`.
    FunctionTolerance,
    /// The gradient fell below `gradient_tolerance`.
    GradientTolerance,
    /// The step fell below `parameter_tolerance`.
    ParameterTolerance,
    /// `max_iterations` reached.
    MaxIterations,
    /// The damping grew without finding a decrease (a minimum to machine precision).
    NoProgress,
    /// Nothing to adjust.
    Empty,
}

/// What an adjustment did.
#[derive(Clone, Debug, Serialize)]
pub struct BundleSummary {
    pub images: usize,
    pub points: usize,
    pub observations: usize,
    /// Unknowns of the reduced camera system.
    pub camera_unknowns: usize,
    pub iterations: usize,
    pub accepted_steps: usize,
    /// Robust cost `sum rho(|r|^2) / 2`, before and after.
    pub initial_cost: f64,
    pub final_cost: f64,
    /// Root mean square reprojection error in pixels, before and after.
    pub initial_rms_px: f64,
    pub final_rms_px: f64,
    pub termination: Termination,
    pub seconds: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    #[error("bundle adjustment: image {0} is not in the reconstruction")]
    UnknownImage(u32),
    #[error(
        "bundle adjustment: image {image} uses camera {camera}, which is not in the reconstruction"
    )]
    UnknownCamera { image: u32, camera: u32 },
    #[error(
        "bundle adjustment: camera {camera} has {got} parameters, model {model:?} needs {want}"
    )]
    BadCamera {
        camera: u32,
        model: CameraModel,
        got: usize,
        want: usize,
    },
    #[error(
        "bundle adjustment: point {point} has an observation of image {image} keypoint {keypoint}, which does not exist"
    )]
    BadObservation {
        point: u64,
        image: u32,
        keypoint: u32,
    },
    #[error("bundle adjustment: the reduced camera system could not be factored: {0}")]
    Solver(String),
}

// ---------------------------------------------------------------------------------------
// The problem in flat arrays.

struct PoseBlock {
    image_id: u32,
    camera: usize,
    rotation: UnitQuaternion<f64>,
    translation: Vector3<f64>,
    /// Indices (0..3 rotation, 3..6 translation) of the free pose parameters.
    free: Vec<usize>,
    /// Group index in the reduced system, if any parameter is free.
    group: Option<usize>,
}

pub(super) struct CameraBlock {
    pub(super) camera_id: u32,
    model: CameraModel,
    params: Vec<f64>,
    pub(super) free: Vec<usize>,
    pub(super) group: Option<usize>,
}

pub(super) struct Observation {
    point: usize,
    pose: usize,
    pixel: Vector2<f64>,
}

pub(super) struct Problem {
    poses: Vec<PoseBlock>,
    pub(super) cameras: Vec<CameraBlock>,
    point_ids: Vec<u64>,
    points: Vec<Vector3<f64>>,
    /// Variable point index (into the point blocks of the Schur complement), if variable.
    point_var: Vec<Option<usize>>,
    /// The inverse map: point index of each variable point.
    pub(super) var_points: Vec<usize>,
    /// Observations sorted by point; `point_obs[p]..point_obs[p+1]` are point p's.
    pub(super) obs: Vec<Observation>,
    point_obs: Vec<usize>,
    /// Group sizes and scalar offsets of the reduced camera system.
    group_size: Vec<usize>,
    pub(super) group_offset: Vec<usize>,
    pub(super) n_camera_unknowns: usize,
}

/// The camera-side column blocks an observation touches: (group, first column in the
/// observation's camera Jacobian, width).
fn obs_parts(problem: &Problem, o: &Observation) -> ([(usize, usize, usize); 2], usize) {
    let pose = &problem.poses[o.pose];
    let cam = &problem.cameras[pose.camera];
    let mut parts = [(0, 0, 0); 2];
    let mut n = 0;
    if let Some(g) = pose.group {
        parts[n] = (g, 0, pose.free.len());
        n += 1;
    }
    if let Some(g) = cam.group {
        parts[n] = (g, pose.free.len(), cam.free.len());
        n += 1;
    }
    (parts, n)
}

pub(super) fn build_problem(
    rec: &Reconstruction,
    setup: &BundleSetup,
    config: &BundleConfig,
) -> Result<Problem, BundleError> {
    // Points seen by the setup's images.
    let mut point_set: BTreeSet<u64> = BTreeSet::new();
    for &id in &setup.images {
        let image = rec.images.get(&id).ok_or(BundleError::UnknownImage(id))?;
        point_set.extend(image.point3d_ids.iter().flatten().copied());
    }
    let mut poses: Vec<PoseBlock> = Vec::new();
    let mut pose_index: BTreeMap<u32, usize> = BTreeMap::new();
    let mut cameras: Vec<CameraBlock> = Vec::new();
    let mut camera_index: BTreeMap<u32, usize> = BTreeMap::new();
    let mut point_ids = Vec::new();
    let mut points = Vec::new();
    let mut obs = Vec::new();
    let mut point_obs = vec![0];
    for &pid in &point_set {
        let Some(point) = rec.points3d.get(&pid) else {
            continue;
        };
        for el in &point.track {
            let image = rec
                .images
                .get(&el.image_id)
                .ok_or(BundleError::UnknownImage(el.image_id))?;
            let kp = image.keypoints.get(el.point2d_idx as usize).ok_or(
                BundleError::BadObservation {
                    point: pid,
                    image: el.image_id,
                    keypoint: el.point2d_idx,
                },
            )?;
            let pose = match pose_index.get(&el.image_id) {
                Some(&i) => i,
                None => {
                    let cam = match camera_index.get(&image.camera_id) {
                        Some(&c) => c,
                        None => {
                            let camera = rec.cameras.get(&image.camera_id).ok_or(
                                BundleError::UnknownCamera {
                                    image: image.id,
                                    camera: image.camera_id,
                                },
                            )?;
                            let want = camera.model.num_params();
                            if camera.params.len() != want {
                                return Err(BundleError::BadCamera {
                                    camera: camera.id,
                                    model: camera.model,
                                    got: camera.params.len(),
                                    want,
                                });
                            }
                            cameras.push(CameraBlock {
                                camera_id: camera.id,
                                model: camera.model,
                                params: camera.params.clone(),
                                free: Vec::new(),
                                group: None,
                            });
                            camera_index.insert(camera.id, cameras.len() - 1);
                            cameras.len() - 1
                        }
                    };
                    let variable = setup.images.contains(&image.id)
                        && !setup.constant_poses.contains(&image.id);
                    poses.push(PoseBlock {
                        image_id: image.id,
                        camera: cam,
                        rotation: image.cam_from_world.0.rotation,
                        translation: image.cam_from_world.0.translation,
                        free: if variable {
                            (0..6).collect()
                        } else {
                            Vec::new()
                        },
                        group: None,
                    });
                    pose_index.insert(image.id, poses.len() - 1);
                    poses.len() - 1
                }
            };
            obs.push(Observation {
                point: point_ids.len(),
                pose,
                pixel: Vector2::new(kp.x, kp.y),
            });
        }
        point_ids.push(pid);
        points.push(point.position.coords);
        point_obs.push(obs.len());
    }

    // Intrinsics are free for cameras used by a variable image, unless held constant.
    let mut used_by_variable = vec![false; cameras.len()];
    for p in &poses {
        if !p.free.is_empty() {
            used_by_variable[p.camera] = true;
        }
    }
    for (c, cam) in cameras.iter_mut().enumerate() {
        if !used_by_variable[c] || setup.constant_cameras.contains(&cam.camera_id) {
            continue;
        }
        if config.refine_focal {
            cam.free.extend_from_slice(cam.model.focal_idxs());
        }
        if config.refine_principal_point {
            cam.free
                .extend_from_slice(&cam.model.principal_point_idxs());
        }
        if config.refine_distortion {
            cam.free.extend_from_slice(cam.model.extra_idxs());
        }
        cam.free.sort_unstable();
    }

    fix_gauge(&mut poses, &pose_index, &obs, setup.gauge);

    // Variable points: not constant and observed at least twice (one view does not fix depth).
    let mut point_var = Vec::with_capacity(point_ids.len());
    let mut n_var = 0;
    for (p, pid) in point_ids.iter().enumerate() {
        let n_obs = point_obs[p + 1] - point_obs[p];
        if n_obs >= 2 && !setup.constant_points.contains(pid) {
            point_var.push(Some(n_var));
            n_var += 1;
        } else {
            point_var.push(None);
        }
    }

    let var_points = (0..point_ids.len())
        .filter(|&p| point_var[p].is_some())
        .collect();
    let mut group_size = Vec::new();
    for pose in &mut poses {
        if !pose.free.is_empty() {
            pose.group = Some(group_size.len());
            group_size.push(pose.free.len());
        }
    }
    for cam in &mut cameras {
        if !cam.free.is_empty() {
            cam.group = Some(group_size.len());
            group_size.push(cam.free.len());
        }
    }
    let mut group_offset = Vec::with_capacity(group_size.len());
    let mut n = 0;
    for &s in &group_size {
        group_offset.push(n);
        n += s;
    }
    Ok(Problem {
        poses,
        cameras,
        point_ids,
        points,
        point_var,
        var_points,
        obs,
        point_obs,
        group_size,
        group_offset,
        n_camera_unknowns: n,
    })
}

/// Removes the 7-dof gauge freedom (see `Gauge`).
fn fix_gauge(
    poses: &mut [PoseBlock],
    pose_index: &BTreeMap<u32, usize>,
    obs: &[Observation],
    gauge: Gauge,
) {
    let constant: Vec<usize> = (0..poses.len())
        .filter(|&i| poses[i].free.is_empty())
        .collect();
    let (first, second) = match gauge {
        Gauge::Free => return,
        Gauge::Pair(a, b) => match (pose_index.get(&a), pose_index.get(&b)) {
            (Some(&a), Some(&b)) if a != b => (Some(a), b),
            _ => return,
        },
        Gauge::Auto => {
            if constant.len() >= 2 {
                return;
            }
            let mut count = vec![0usize; poses.len()];
            for o in obs {
                count[o.pose] += 1;
            }
            let mut variable: Vec<usize> = (0..poses.len())
                .filter(|&i| !poses[i].free.is_empty())
                .collect();
            variable.sort_by(|&a, &b| count[b].cmp(&count[a]).then(a.cmp(&b)));
            match (constant.first(), variable.as_slice()) {
                (Some(&c), [v, ..]) => {
                    let _ = c;
                    (None, *v)
                }
                (None, [a, b, ..]) => (Some(*a), *b),
                _ => return,
            }
        }
    };
    let anchor = match first {
        Some(a) => {
            poses[a].free.clear();
            a
        }
        None => constant[0],
    };
    // The scale moves camera `second`'s centre along the baseline to the anchor; in its own
    // frame that is the direction R_b (c_b - c_a). Fix its largest coordinate of t.
    let centre = |p: &PoseBlock| -(p.rotation.inverse() * p.translation);
    let d = poses[second].rotation * (centre(&poses[second]) - centre(&poses[anchor]));
    let axis = d.iamax();
    poses[second].free.retain(|&k| k != 3 + axis);
}

// ---------------------------------------------------------------------------------------
// Block-sparse pattern of the reduced camera system (upper triangle of blocks).

pub(super) struct BlockPattern {
    /// For each row group `a`: sorted column groups `b >= a` and the offset of block (a, b)
    /// (row-major, size_a x size_b) in the value array.
    rows: Vec<Vec<(usize, usize)>>,
    len: usize,
    /// With few groups, a dense `n_groups^2` table of slots (`usize::MAX` where no block):
    /// the lookup is the innermost operation of the Schur complement.
    table: Vec<usize>,
    n_groups: usize,
}

/// Largest group count for the dense slot table (2048^2 entries = 32 MB).
const DENSE_SLOT_TABLE_MAX_GROUPS: usize = 2048;

impl BlockPattern {
    pub(super) fn build(problem: &Problem) -> Self {
        let n_groups = problem.group_size.len();
        let chunks = chunk_ranges(problem.points.len(), rayon::current_num_threads() * 4);
        let mut pairs: Vec<(usize, usize)> = chunks
            .into_par_iter()
            .flat_map_iter(|range| {
                let mut local = Vec::new();
                let mut groups = Vec::new();
                for p in range {
                    groups.clear();
                    for o in &problem.obs[problem.point_obs[p]..problem.point_obs[p + 1]] {
                        let (parts, n) = obs_parts(problem, o);
                        let og: Vec<usize> = parts[..n].iter().map(|q| q.0).collect();
                        // Blocks within one observation (pose-pose, pose-intrinsics, ...).
                        for &a in &og {
                            for &b in &og {
                                if a <= b {
                                    local.push((a, b));
                                }
                            }
                        }
                        groups.extend(og);
                    }
                    if problem.point_var[p].is_some() {
                        groups.sort_unstable();
                        groups.dedup();
                        for (i, &a) in groups.iter().enumerate() {
                            for &b in &groups[i..] {
                                local.push((a, b));
                            }
                        }
                    }
                }
                local.sort_unstable();
                local.dedup();
                local
            })
            .collect();
        pairs.par_sort_unstable();
        pairs.dedup();
        let mut rows = vec![Vec::new(); n_groups];
        let mut len = 0;
        for (a, b) in pairs {
            rows[a].push((b, len));
            len += problem.group_size[a] * problem.group_size[b];
        }
        let mut table = Vec::new();
        if n_groups <= DENSE_SLOT_TABLE_MAX_GROUPS {
            table = vec![usize::MAX; n_groups * n_groups];
            for (a, row) in rows.iter().enumerate() {
                for &(b, slot) in row {
                    table[a * n_groups + b] = slot;
                }
            }
        }
        BlockPattern {
            rows,
            len,
            table,
            n_groups,
        }
    }

    #[inline]
    fn slot(&self, a: usize, b: usize) -> usize {
        if !self.table.is_empty() {
            return self.table[a * self.n_groups + b];
        }
        let row = &self.rows[a];
        let i = row
            .binary_search_by(|e| e.0.cmp(&b))
            .expect("block pattern holds every co-observed pair");
        row[i].1
    }
}

/// Chunks of points whose camera-side sums (`J^T J`, the Schur complement) are accumulated
/// separately and then added in chunk order: a fixed count, not the thread count, so the
/// floating-point sums, and every result, are the same whatever the number of threads.
const SUM_CHUNKS: usize = 8;

/// `n` items split into about `parts` contiguous ranges.
fn chunk_ranges(n: usize, parts: usize) -> Vec<std::ops::Range<usize>> {
    let parts = parts.max(1);
    let step = n.div_ceil(parts).max(1);
    (0..n).step_by(step).map(|s| s..(s + step).min(n)).collect()
}

// ---------------------------------------------------------------------------------------
// Linearisation.

/// One observation's weighted residual and Jacobians at the current estimate.
#[derive(Clone, Copy)]
pub(super) struct ObsLinear {
    /// Camera-side Jacobian: free pose columns then free intrinsic columns.
    jc: CamJacobian,
    jp: Matrix2x3<f64>,
    pub(super) r: Vector2<f64>,
}

pub(super) struct Linear {
    pub(super) obs: Vec<ObsLinear>,
    /// Per variable point: `V = sum Jp^T Jp`, `bp = -sum Jp^T r`.
    v: Vec<Matrix3<f64>>,
    bp: Vec<Vector3<f64>>,
    /// Camera blocks `U = sum Jc^T Jc` in the block pattern, and `bc = -sum Jc^T r`.
    u: Vec<f64>,
    bc: Vec<f64>,
    /// Largest absolute gradient entry.
    gradient_max: f64,
}

/// Residual of one observation (projection minus measurement), unweighted.
fn residual(problem: &Problem, state: &State, p: usize, o: &Observation) -> Option<Vector2<f64>> {
    let pose = &state.poses[o.pose];
    let cam = &problem.cameras[problem.poses[o.pose].camera];
    let params = &state.params[problem.poses[o.pose].camera];
    let x_cam = pose.0 * state.points[p] + pose.1;
    project_any_depth(cam.model, params, &x_cam).map(|j| j.pixel.coords - o.pixel)
}

/// Projection and its Jacobians without the cheirality test, so that the cost stays smooth
/// if an iterate moves a point across a camera's image plane (the mapper filters points
/// behind cameras afterwards, as COLMAP does). The pixel depends on `x / z` only, so a point
/// behind the camera projects like its mirror `-x`, with the point derivative negated.
fn project_any_depth(
    model: CameraModel,
    params: &[f64],
    x_cam: &Vector3<f64>,
) -> Option<fresco_core::camera::CamProjection> {
    if x_cam.z >= 0.0 {
        model.image_from_cam_jacobian(params, &(*x_cam).into())
    } else {
        let mut j = model.image_from_cam_jacobian(params, &(-*x_cam).into())?;
        j.d_point = -j.d_point;
        Some(j)
    }
}

/// The parameters that change during the optimisation.
#[derive(Clone)]
pub(super) struct State {
    poses: Vec<(UnitQuaternion<f64>, Vector3<f64>)>,
    params: Vec<Vec<f64>>,
    points: Vec<Vector3<f64>>,
}

impl State {
    pub(super) fn of(problem: &Problem) -> Self {
        State {
            poses: problem
                .poses
                .iter()
                .map(|p| (p.rotation, p.translation))
                .collect(),
            params: problem.cameras.iter().map(|c| c.params.clone()).collect(),
            points: problem.points.clone(),
        }
    }
}

/// Robust cost and sum of squared residuals.
fn evaluate(problem: &Problem, state: &State, loss: Loss) -> (f64, f64) {
    (0..problem.points.len())
        .into_par_iter()
        .map(|p| {
            let mut cost = 0.0;
            let mut sq = 0.0;
            for o in &problem.obs[problem.point_obs[p]..problem.point_obs[p + 1]] {
                if let Some(r) = residual(problem, state, p, o) {
                    let s = r.norm_squared();
                    cost += 0.5 * loss.rho(s);
                    sq += s;
                }
            }
            (cost, sq)
        })
        .collect::<Vec<_>>()
        // Summed in point order: rayon's reduction tree depends on the thread count.
        .into_iter()
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
}

fn linearise_obs(
    problem: &Problem,
    state: &State,
    p: usize,
    o: &Observation,
    loss: Loss,
) -> ObsLinear {
    let zero = ObsLinear {
        jc: CamJacobian::zeros(),
        jp: Matrix2x3::zeros(),
        r: Vector2::zeros(),
    };
    let pb = &problem.poses[o.pose];
    let cam = &problem.cameras[pb.camera];
    let (rot, t) = &state.poses[o.pose];
    let rx = rot * state.points[p];
    let x_cam = rx + t;
    if x_cam.z.abs() < 1e-12 {
        return zero;
    }
    let Some((pix, d_x, d_params)) = project_any_depth(cam.model, &state.params[pb.camera], &x_cam)
        .map(|j| (j.pixel.coords, j.d_point, j.d_params))
    else {
        return zero;
    };
    let r = pix - o.pixel;
    let sw = loss.weight(r.norm_squared()).sqrt();
    let mut jc = CamJacobian::zeros();
    // d x_cam / d(dw) = -[R X]x ; d x_cam / dt = I.
    let skew = Matrix3::new(0.0, -rx.z, rx.y, rx.z, 0.0, -rx.x, -rx.y, rx.x, 0.0);
    let d_rot = -(d_x * skew);
    for (col, &k) in pb.free.iter().enumerate() {
        let c = if k < 3 {
            d_rot.column(k).into_owned()
        } else {
            d_x.column(k - 3).into_owned()
        };
        jc.set_column(col, &(c * sw));
    }
    let off = pb.free.len();
    for (col, &k) in cam.free.iter().enumerate() {
        jc.set_column(off + col, &(d_params.column(k) * sw));
    }
    let jp = d_x * rot.to_rotation_matrix().matrix() * sw;
    ObsLinear { jc, jp, r: r * sw }
}

pub(super) fn linearise(
    problem: &Problem,
    pattern: &BlockPattern,
    state: &State,
    loss: Loss,
) -> Linear {
    let n_points = problem.points.len();
    let obs: Vec<ObsLinear> = problem
        .obs
        .par_iter()
        .map(|o| linearise_obs(problem, state, o.point, o, loss))
        .collect();
    let (v, bp): (Vec<Matrix3<f64>>, Vec<Vector3<f64>>) = problem
        .var_points
        .par_iter()
        .map(|&p| {
            let mut v = Matrix3::zeros();
            let mut b = Vector3::zeros();
            for l in &obs[problem.point_obs[p]..problem.point_obs[p + 1]] {
                v += l.jp.transpose() * l.jp;
                b -= l.jp.transpose() * l.r;
            }
            (v, b)
        })
        .unzip();
    // Camera blocks, accumulated per chunk of points and summed.
    let chunks = chunk_ranges(n_points, SUM_CHUNKS);
    let n = problem.n_camera_unknowns;
    let (u, bc) = chunks
        .into_par_iter()
        .map(|range| {
            let mut u = vec![0.0; pattern.len];
            let mut bc = vec![0.0; n];
            for p in range {
                for (o, l) in problem.obs[problem.point_obs[p]..problem.point_obs[p + 1]]
                    .iter()
                    .zip(&obs[problem.point_obs[p]..problem.point_obs[p + 1]])
                {
                    let (parts, np) = obs_parts(problem, o);
                    let jt = l.jc.transpose();
                    let jtr = jt * l.r;
                    for &(ga, ca, wa) in &parts[..np] {
                        for i in 0..wa {
                            bc[problem.group_offset[ga] + i] -= jtr[ca + i];
                        }
                        for &(gb, cb, wb) in &parts[..np] {
                            if ga <= gb {
                                let slot = pattern.slot(ga, gb);
                                let (ra, rb) = (rows(&jt, ca, wa), rows(&jt, cb, wb));
                                accumulate(&mut u, slot, ra, rb, 1.0);
                            }
                        }
                    }
                }
            }
            (u, bc)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .reduce(|mut a, b| {
            a.0.iter_mut().zip(&b.0).for_each(|(x, y)| *x += y);
            a.1.iter_mut().zip(&b.1).for_each(|(x, y)| *x += y);
            a
        })
        .unwrap_or_else(|| (vec![0.0; pattern.len], vec![0.0; n]));
    let gradient_max = bc
        .iter()
        .map(|x| x.abs())
        .chain(bp.iter().map(|b| b.amax()))
        .fold(0.0, f64::max);
    Linear {
        obs,
        v,
        bp,
        u,
        bc,
        gradient_max,
    }
}

/// Rows `first..first + count` of a Jacobian-shaped matrix: one parameter block's columns of an
/// observation (see [`obs_parts`]).
#[derive(Clone, Copy)]
struct Rows<'m, const K: usize> {
    m: &'m SMatrix<f64, MAX_DC, K>,
    first: usize,
    count: usize,
}

/// `values[slot..]` (a row-major `a.count x b.count` block) += `sign * A[a rows, :] B[b rows, :]^T`:
/// one block of `J^T J` or of `W V^-1 W^T`, computed only for the columns an observation
/// really has.
#[inline]
fn accumulate<const K: usize>(values: &mut [f64], slot: usize, a: Rows<K>, b: Rows<K>, sign: f64) {
    // The common block shapes (a pose has 6 free parameters, 5 for the gauge camera; a
    // shared camera 1-2) with their sizes known at compile time, so that the loops unroll;
    // the same operations in the same order as the general loop.
    match (a.count, b.count) {
        (6, 6) => accumulate_fixed::<K, 6, 6>(values, slot, a, b, sign),
        (6, 2) => accumulate_fixed::<K, 6, 2>(values, slot, a, b, sign),
        (2, 6) => accumulate_fixed::<K, 2, 6>(values, slot, a, b, sign),
        (2, 2) => accumulate_fixed::<K, 2, 2>(values, slot, a, b, sign),
        (6, 1) => accumulate_fixed::<K, 6, 1>(values, slot, a, b, sign),
        (1, 6) => accumulate_fixed::<K, 1, 6>(values, slot, a, b, sign),
        (1, 1) => accumulate_fixed::<K, 1, 1>(values, slot, a, b, sign),
        (wa, wb) => {
            for i in 0..wa {
                let row = &mut values[slot + i * wb..slot + i * wb + wb];
                for (j, x) in row.iter_mut().enumerate() {
                    let mut dot = 0.0;
                    for k in 0..K {
                        dot += a.m[(a.first + i, k)] * b.m[(b.first + j, k)];
                    }
                    *x += sign * dot;
                }
            }
        }
    }
}

fn rows<const K: usize>(m: &SMatrix<f64, MAX_DC, K>, first: usize, count: usize) -> Rows<'_, K> {
    Rows { m, first, count }
}

/// [`accumulate`] for a `WA x WB` block.
#[inline(always)]
fn accumulate_fixed<const K: usize, const WA: usize, const WB: usize>(
    values: &mut [f64],
    slot: usize,
    a: Rows<K>,
    b: Rows<K>,
    sign: f64,
) {
    let mut block = [[0.0f64; WB]; WA];
    for (i, out) in block.iter_mut().enumerate() {
        for (j, x) in out.iter_mut().enumerate() {
            let mut dot = 0.0;
            for k in 0..K {
                dot += a.m[(a.first + i, k)] * b.m[(b.first + j, k)];
            }
            *x = sign * dot;
        }
    }
    for (i, out) in block.iter().enumerate() {
        let row = &mut values[slot + i * WB..slot + i * WB + WB];
        for (x, v) in row.iter_mut().zip(out) {
            *x += v;
        }
    }
}

// ---------------------------------------------------------------------------------------
// Damped Schur complement, solve, back-substitution.

const MIN_DIAGONAL: f64 = 1e-6;
const MAX_DIAGONAL: f64 = 1e32;

fn damped_inverse(v: &Matrix3<f64>, lambda: f64) -> Option<Matrix3<f64>> {
    let mut m = *v;
    for k in 0..3 {
        m[(k, k)] += lambda * v[(k, k)].clamp(MIN_DIAGONAL, MAX_DIAGONAL);
    }
    m.try_inverse()
}

/// The reduced camera system `S dc = g` for damping `lambda`, in the block pattern.
pub(super) fn schur(
    problem: &Problem,
    pattern: &BlockPattern,
    lin: &Linear,
    lambda: f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = problem.n_camera_unknowns;
    let chunks = chunk_ranges(problem.points.len(), SUM_CHUNKS);
    let (mut s, mut g) = chunks
        .into_par_iter()
        .map(|range| {
            let mut s = vec![0.0; pattern.len];
            let mut g = vec![0.0; n];
            let mut w: Vec<SMatrix<f64, MAX_DC, 3>> = Vec::new();
            let mut y: Vec<SMatrix<f64, MAX_DC, 3>> = Vec::new();
            for p in range {
                let Some(vi) = problem.point_var[p] else {
                    continue;
                };
                let Some(v_inv) = damped_inverse(&lin.v[vi], lambda) else {
                    continue;
                };
                let range = problem.point_obs[p]..problem.point_obs[p + 1];
                w.clear();
                y.clear();
                for l in &lin.obs[range.clone()] {
                    let wi = l.jc.transpose() * l.jp;
                    y.push(wi * v_inv);
                    w.push(wi);
                }
                let obs = &problem.obs[range];
                let parts: Vec<_> = obs.iter().map(|o| obs_parts(problem, o)).collect();
                let vb = lin.bp[vi];
                for i in 0..obs.len() {
                    let (pi, ni) = parts[i];
                    let yb = y[i] * vb;
                    for &(ga, ca, wa) in &pi[..ni] {
                        for k in 0..wa {
                            g[problem.group_offset[ga] + k] -= yb[ca + k];
                        }
                    }
                    for j in i..obs.len() {
                        let (pj, nj) = parts[j];
                        for &(ga, ca, wa) in &pi[..ni] {
                            for &(gb, cb, wb) in &pj[..nj] {
                                if ga <= gb {
                                    let slot = pattern.slot(ga, gb);
                                    let (ra, rb) = (rows(&y[i], ca, wa), rows(&w[j], cb, wb));
                                    accumulate(&mut s, slot, ra, rb, -1.0);
                                }
                                // The (j, i) term, Y_j W_i^T = (Y_i W_j^T)^T, lands in block (gb, ga).
                                if i != j && gb <= ga {
                                    let slot = pattern.slot(gb, ga);
                                    let (ra, rb) = (rows(&y[j], cb, wb), rows(&w[i], ca, wa));
                                    accumulate(&mut s, slot, ra, rb, -1.0);
                                }
                            }
                        }
                    }
                }
            }
            (s, g)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .reduce(|mut a, b| {
            a.0.iter_mut().zip(&b.0).for_each(|(x, y)| *x += y);
            a.1.iter_mut().zip(&b.1).for_each(|(x, y)| *x += y);
            a
        })
        .unwrap_or_else(|| (vec![0.0; pattern.len], vec![0.0; n]));
    s.iter_mut().zip(&lin.u).for_each(|(x, y)| *x += y);
    g.iter_mut().zip(&lin.bc).for_each(|(x, y)| *x += y);
    // Damping of the camera diagonal.
    for (a, &size) in problem.group_size.iter().enumerate() {
        let slot = pattern.slot(a, a);
        for k in 0..size {
            let d = lin.u[slot + k * size + k].clamp(MIN_DIAGONAL, MAX_DIAGONAL);
            s[slot + k * size + k] += lambda * d;
        }
    }
    (s, g)
}

/// Solves the reduced camera system; reuses the symbolic factorisation across iterations.
pub(super) struct ReducedSolver {
    /// Scalar upper-triangular CSC pattern and, per entry, its index in the block values.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    gather: Vec<usize>,
    symbolic: Option<faer::sparse::linalg::solvers::SymbolicLlt<usize>>,
}

impl ReducedSolver {
    pub(super) fn new(
        problem: &Problem,
        pattern: &BlockPattern,
        kind: LinearSolver,
    ) -> Result<Self, BundleError> {
        let n = problem.n_camera_unknowns;
        let kind = match kind {
            LinearSolver::Auto { dense_limit } => {
                if n <= dense_limit {
                    LinearSolver::DenseCholesky
                } else {
                    LinearSolver::SparseCholesky
                }
            }
            k => k,
        };
        // Columns of blocks: for each column group b, the row groups a <= b.
        let n_groups = problem.group_size.len();
        let mut cols: Vec<Vec<(usize, usize)>> = vec![Vec::new(); n_groups];
        for (a, row) in pattern.rows.iter().enumerate() {
            for &(b, slot) in row {
                cols[b].push((a, slot));
            }
        }
        let mut col_ptr = vec![0];
        let mut row_idx = Vec::new();
        let mut gather = Vec::new();
        for (b, col_blocks) in cols.iter().enumerate() {
            let wb = problem.group_size[b];
            for k in 0..wb {
                for &(a, slot) in col_blocks {
                    let wa = problem.group_size[a];
                    let rows = if a == b { k + 1 } else { wa };
                    for i in 0..rows {
                        row_idx.push(problem.group_offset[a] + i);
                        gather.push(slot + i * wb + k);
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        let symbolic = if kind == LinearSolver::SparseCholesky && n > 0 {
            let sym = faer::sparse::SymbolicSparseColMat::<usize>::new_checked(
                n,
                n,
                col_ptr.clone(),
                None,
                row_idx.clone(),
            );
            Some(
                faer::sparse::linalg::solvers::SymbolicLlt::try_new(
                    sym.as_ref(),
                    faer::Side::Upper,
                )
                .map_err(|e| BundleError::Solver(format!("{e:?}")))?,
            )
        } else {
            None
        };
        Ok(ReducedSolver {
            col_ptr,
            row_idx,
            gather,
            symbolic,
        })
    }

    /// Solves `S x = g`; `None` if `S` is not positive definite (more damping needed).
    fn solve(&self, s: &[f64], g: &[f64]) -> Option<Vec<f64>> {
        self.solve_columns(s, g.to_vec(), 1)
    }

    /// Solves `S X = B` for the `k` columns of `b` (column-major, `n x k`) with one
    /// factorisation of `S`; `None` if `S` is not positive definite.
    pub(super) fn solve_columns(&self, s: &[f64], b: Vec<f64>, k: usize) -> Option<Vec<f64>> {
        use faer::prelude::Solve;
        let n = b.len() / k.max(1);
        if n == 0 {
            return Some(Vec::new());
        }
        let values: Vec<f64> = self.gather.iter().map(|&i| s[i]).collect();
        let mut x = b;
        match &self.symbolic {
            Some(symbolic) => {
                // The pattern is rebuilt per solve (cheap) because faer's sparse matrix
                // borrows it; the symbolic factorisation is shared.
                let sym = faer::sparse::SymbolicSparseColMatRef::new_checked(
                    n,
                    n,
                    &self.col_ptr,
                    None,
                    &self.row_idx,
                );
                let mat = faer::sparse::SparseColMatRef::new(sym, &values);
                let llt = faer::sparse::linalg::solvers::Llt::try_new_with_symbolic(
                    symbolic.clone(),
                    mat,
                    faer::Side::Upper,
                )
                .ok()?;
                llt.solve_in_place(faer::MatMut::from_column_major_slice_mut(&mut x, n, k));
            }
            None => {
                let mut dense = faer::Mat::<f64>::zeros(n, n);
                for c in 0..n {
                    let entries = self.col_ptr[c]..self.col_ptr[c + 1];
                    for (&r, &v) in self.row_idx[entries.clone()].iter().zip(&values[entries]) {
                        dense[(r, c)] = v;
                        dense[(c, r)] = v;
                    }
                }
                let llt = dense.llt(faer::Side::Lower).ok()?;
                llt.solve_in_place(faer::MatMut::from_column_major_slice_mut(&mut x, n, k));
            }
        }
        x.iter().all(|v| v.is_finite()).then_some(x)
    }
}

/// Point updates `dp = V*^-1 (bp - W^T dc)` for the camera step `dc`, and the predicted
/// cost decrease `(h^T b + lambda h^T D h) / 2` of the whole step.
fn back_substitute(
    problem: &Problem,
    lin: &Linear,
    lambda: f64,
    dc: &[f64],
) -> (Vec<Vector3<f64>>, f64) {
    let n_var = lin.v.len();
    let results: Vec<(Vector3<f64>, f64)> = problem
        .var_points
        .par_iter()
        .enumerate()
        .map(|(vi, &p)| {
            let Some(v_inv) = damped_inverse(&lin.v[vi], lambda) else {
                return (Vector3::zeros(), 0.0);
            };
            let mut rhs = lin.bp[vi];
            for (o, l) in problem.obs[problem.point_obs[p]..problem.point_obs[p + 1]]
                .iter()
                .zip(&lin.obs[problem.point_obs[p]..problem.point_obs[p + 1]])
            {
                let (parts, np) = obs_parts(problem, o);
                let mut d = CamVector::zeros();
                for &(g, c, w) in &parts[..np] {
                    for k in 0..w {
                        d[c + k] = dc[problem.group_offset[g] + k];
                    }
                }
                rhs -= l.jp.transpose() * (l.jc * d);
            }
            let dp = v_inv * rhs;
            let mut pred = dp.dot(&lin.bp[vi]);
            for k in 0..3 {
                pred +=
                    lambda * lin.v[vi][(k, k)].clamp(MIN_DIAGONAL, MAX_DIAGONAL) * dp[k] * dp[k];
            }
            (dp, pred)
        })
        .collect();
    let mut dp = vec![Vector3::zeros(); n_var];
    let mut pred = 0.0;
    for (k, (d, pr)) in results.into_iter().enumerate() {
        dp[k] = d;
        pred += pr;
    }
    (dp, pred)
}

fn camera_predicted(
    problem: &Problem,
    pattern: &BlockPattern,
    lin: &Linear,
    lambda: f64,
    dc: &[f64],
) -> f64 {
    let mut pred: f64 = dc.iter().zip(&lin.bc).map(|(a, b)| a * b).sum();
    for (a, &size) in problem.group_size.iter().enumerate() {
        let slot = pattern.slot(a, a);
        for k in 0..size {
            let d = lin.u[slot + k * size + k].clamp(MIN_DIAGONAL, MAX_DIAGONAL);
            let x = dc[problem.group_offset[a] + k];
            pred += lambda * d * x * x;
        }
    }
    pred
}

/// The state after the step (dc, dp).
fn apply_step(problem: &Problem, state: &State, dc: &[f64], dp: &[Vector3<f64>]) -> State {
    let mut next = state.clone();
    for (i, pose) in problem.poses.iter().enumerate() {
        let Some(g) = pose.group else { continue };
        let mut d = [0.0; 6];
        for (col, &k) in pose.free.iter().enumerate() {
            d[k] = dc[problem.group_offset[g] + col];
        }
        let (rot, t) = &mut next.poses[i];
        *rot = UnitQuaternion::from_scaled_axis(Vector3::new(d[0], d[1], d[2])) * *rot;
        *t += Vector3::new(d[3], d[4], d[5]);
    }
    for (c, cam) in problem.cameras.iter().enumerate() {
        let Some(g) = cam.group else { continue };
        for (col, &k) in cam.free.iter().enumerate() {
            next.params[c][k] += dc[problem.group_offset[g] + col];
        }
    }
    for (p, var) in problem.point_var.iter().enumerate() {
        if let Some(vi) = var {
            next.points[p] += dp[*vi];
        }
    }
    next
}

fn state_norm(state: &State) -> f64 {
    let mut s = 0.0;
    for (_, t) in &state.poses {
        s += t.norm_squared() + 3.0;
    }
    for p in &state.params {
        s += p.iter().map(|x| x * x).sum::<f64>();
    }
    for p in &state.points {
        s += p.norm_squared();
    }
    s.sqrt()
}

/// Adjusts the poses, points and intrinsics that `setup` names so that the robust
/// reprojection error is least, and writes them back into `rec` (points also get their mean
/// reprojection error).
pub fn bundle_adjust(
    rec: &mut Reconstruction,
    setup: &BundleSetup,
    config: &BundleConfig,
) -> Result<BundleSummary, BundleError> {
    let start = Instant::now();
    let problem = build_problem(rec, setup, config)?;
    let mut state = State::of(&problem);
    let (initial_cost, initial_sq) = evaluate(&problem, &state, config.loss);
    let n_obs = problem.obs.len();
    let rms = |sq: f64| {
        if n_obs > 0 {
            (sq / n_obs as f64).sqrt()
        } else {
            0.0
        }
    };
    let mut summary = BundleSummary {
        images: problem.poses.iter().filter(|p| !p.free.is_empty()).count(),
        points: problem.point_var.iter().flatten().count(),
        observations: n_obs,
        camera_unknowns: problem.n_camera_unknowns,
        iterations: 0,
        accepted_steps: 0,
        initial_cost,
        final_cost: initial_cost,
        initial_rms_px: rms(initial_sq),
        final_rms_px: rms(initial_sq),
        termination: Termination::Empty,
        seconds: 0.0,
    };
    if n_obs == 0 || (problem.n_camera_unknowns == 0 && summary.points == 0) {
        summary.seconds = start.elapsed().as_secs_f64();
        return Ok(summary);
    }
    let pattern = BlockPattern::build(&problem);
    let solver = ReducedSolver::new(&problem, &pattern, config.linear_solver)?;

    let mut cost = initial_cost;
    let mut sq = initial_sq;
    let mut lambda = 1e-4;
    let mut nu = 2.0;
    let mut lin = linearise(&problem, &pattern, &state, config.loss);
    let mut termination = Termination::MaxIterations;
    while summary.iterations < config.max_iterations {
        if lin.gradient_max < config.gradient_tolerance {
            termination = Termination::GradientTolerance;
            break;
        }
        summary.iterations += 1;
        let (s, g) = schur(&problem, &pattern, &lin, lambda);
        let Some(dc) = solver.solve(&s, &g) else {
            lambda *= nu;
            nu *= 2.0;
            if lambda > 1e16 {
                termination = Termination::NoProgress;
                break;
            }
            continue;
        };
        let (dp, point_pred) = back_substitute(&problem, &lin, lambda, &dc);
        let predicted =
            0.5 * (point_pred + camera_predicted(&problem, &pattern, &lin, lambda, &dc));
        let step_norm = (dc.iter().map(|x| x * x).sum::<f64>()
            + dp.iter().map(|d| d.norm_squared()).sum::<f64>())
        .sqrt();
        let x_norm = state_norm(&state);
        if step_norm <= config.parameter_tolerance * (x_norm + config.parameter_tolerance) {
            termination = Termination::ParameterTolerance;
            break;
        }
        let next = apply_step(&problem, &state, &dc, &dp);
        let (next_cost, next_sq) = evaluate(&problem, &next, config.loss);
        let gain = if predicted > 0.0 {
            (cost - next_cost) / predicted
        } else {
            -1.0
        };
        if next_cost < cost && gain > 0.0 {
            let decrease = (cost - next_cost) / cost.max(f64::MIN_POSITIVE);
            state = next;
            cost = next_cost;
            sq = next_sq;
            summary.accepted_steps += 1;
            lambda *= (1.0 - (2.0 * gain - 1.0).powi(3)).max(1.0 / 3.0);
            lambda = lambda.max(1e-12);
            nu = 2.0;
            if decrease < config.function_tolerance {
                termination = Termination::FunctionTolerance;
                break;
            }
            lin = linearise(&problem, &pattern, &state, config.loss);
        } else {
            lambda *= nu;
            nu *= 2.0;
            if lambda > 1e16 {
                termination = Termination::NoProgress;
                break;
            }
        }
    }
    write_back(rec, &problem, &state);
    summary.final_cost = cost;
    summary.final_rms_px = rms(sq);
    summary.termination = termination;
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

fn write_back(rec: &mut Reconstruction, problem: &Problem, state: &State) {
    for (i, pose) in problem.poses.iter().enumerate() {
        if pose.free.is_empty() {
            continue;
        }
        if let Some(image) = rec.images.get_mut(&pose.image_id) {
            image.cam_from_world.0.rotation = state.poses[i].0;
            image.cam_from_world.0.translation = state.poses[i].1;
        }
    }
    for (c, cam) in problem.cameras.iter().enumerate() {
        if cam.free.is_empty() {
            continue;
        }
        if let Some(camera) = rec.cameras.get_mut(&cam.camera_id) {
            camera.params = state.params[c].clone();
        }
    }
    for (p, pid) in problem.point_ids.iter().enumerate() {
        let mut err = 0.0;
        let mut n = 0;
        for o in &problem.obs[problem.point_obs[p]..problem.point_obs[p + 1]] {
            if let Some(r) = residual(problem, state, p, o) {
                err += r.norm();
                n += 1;
            }
        }
        if let Some(point) = rec.points3d.get_mut(pid) {
            if problem.point_var[p].is_some() {
                point.position = state.points[p].into();
            }
            if n > 0 {
                point.error = err / n as f64;
            }
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::evaluate::evaluate_poses;
    use crate::synthetic::{SyntheticConfig, perturb, synthetic_reconstruction};

    fn rotation_error_deg(a: &Reconstruction, b: &Reconstruction) -> f64 {
        a.images
            .iter()
            .map(|(id, im)| {
                im.cam_from_world
                    .0
                    .rotation
                    .angle_to(&b.images[id].cam_from_world.0.rotation)
                    .to_degrees()
            })
            .fold(0.0, f64::max)
    }

    fn max_centre_error(a: &Reconstruction, b: &Reconstruction) -> f64 {
        let c = |im: &fresco_core::Image| {
            -(im.cam_from_world.0.rotation.inverse() * im.cam_from_world.0.translation)
        };
        a.images
            .iter()
            .map(|(id, im)| (c(im) - c(&b.images[id])).norm())
            .fold(0.0, f64::max)
    }

    /// Perturbs everything but the gauge images 1 (whole pose) and 2 (its centre): the
    /// optimum is then the ground truth itself, not a similarity of it.
    pub(crate) fn perturbed(truth: &Reconstruction, seed: u64) -> Reconstruction {
        let mut rec = truth.clone();
        perturb(&mut rec, 2.0, 0.1, 0.05, 0.03, seed);
        rec.images.get_mut(&1).unwrap().cam_from_world = truth.images[&1].cam_from_world;
        // Keep image 2's translation vector (so its fixed coordinate is exact), not its rotation.
        rec.images.get_mut(&2).unwrap().cam_from_world.0.translation =
            truth.images[&2].cam_from_world.0.translation;
        rec
    }

    pub(crate) fn adjust_pair(rec: &mut Reconstruction, config: &BundleConfig) -> BundleSummary {
        let setup = setup_pair(rec);
        bundle_adjust(rec, &setup, config).unwrap()
    }

    pub(crate) fn setup_pair(rec: &Reconstruction) -> BundleSetup {
        BundleSetup {
            gauge: Gauge::Pair(1, 2),
            ..BundleSetup::global(rec)
        }
    }

    /// Noise-free observations: LM converges to the ground truth (rotation to 1e-6 deg,
    /// centres and intrinsics to 1e-6 relative), from 2 deg / 10% of the baseline away and a
    /// 3% wrong focal length and distortion.
    #[test]
    fn noise_free_converges_to_ground_truth() {
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig::default());
        let mut rec = perturbed(&truth, 7);
        let config = BundleConfig {
            loss: Loss::Squared,
            function_tolerance: 1e-14,
            parameter_tolerance: 1e-14,
            ..Default::default()
        };
        let summary = adjust_pair(&mut rec, &config);
        assert!(summary.initial_rms_px > 10.0, "{summary:?}");
        assert!(summary.final_rms_px < 1e-6, "{summary:?}");
        assert!(rotation_error_deg(&rec, &truth) < 1e-6);
        assert!(max_centre_error(&rec, &truth) < 1e-6);
        for (a, b) in rec.cameras[&1].params.iter().zip(&truth.cameras[&1].params) {
            assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{a} vs {b}");
        }
    }

    /// Gaussian noise of 0.5 px: the final RMS reprojection error is the noise level (up to
    /// the degrees of freedom absorbed by the fit: sqrt(1 - params / residuals) > 0.9 here),
    /// and poses land near the truth.
    #[test]
    fn noisy_converges_to_noise_level() {
        let sigma = 0.5;
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig {
            noise_px: sigma,
            ..Default::default()
        });
        let mut rec = perturbed(&truth, 3);
        let summary = adjust_pair(&mut rec, &BundleConfig::default());
        // RMS of a 2-D residual whose coordinates have std sigma is sqrt(2) sigma.
        let expected = sigma * 2f64.sqrt();
        assert!(
            summary.final_rms_px > 0.85 * expected && summary.final_rms_px < 1.05 * expected,
            "{summary:?}"
        );
        // Starting from the ground truth reaches the same minimum: the perturbed start
        // converged to the least-squares optimum, not to a nearby stationary point.
        let mut from_truth = truth.clone();
        adjust_pair(&mut from_truth, &BundleConfig::default());
        assert!(rotation_error_deg(&rec, &from_truth) < 1e-4);
        // After a similarity alignment, the optimum's own error: this geometry (a unit ball
        // seen from 5 units, 0.5 px noise) leaves an "orbit" mode (rotate a camera by d and
        // shift it by 5 d sideways) constrained only by the depth parallax, about
        // 0.5 px / (600 px * 0.1 * sqrt(270)) = 0.03 deg per camera (1 sigma); 0.2 deg bounds it.
        let e = evaluate_poses(&rec, &truth).unwrap();
        assert!(e.max_rotation_deg < 0.2, "{e:?}");
        assert!(e.max_centre_frac < 0.003, "{e:?}");
        let f = rec.cameras[&1].params[0];
        assert!((f - 600.0).abs() < 2.0, "focal {f}");
    }

    /// 10% gross outliers: with a robust loss the poses still land near the truth, and much
    /// nearer than plain least squares does.
    #[test]
    fn robust_loss_handles_outliers() {
        let (truth, outliers) = synthetic_reconstruction(&SyntheticConfig {
            noise_px: 0.5,
            outlier_fraction: 0.1,
            points: 600,
            ..Default::default()
        });
        assert!(outliers.len() > 100);
        let start = perturbed(&truth, 5);
        let mut errors = Vec::new();
        for loss in [Loss::Squared, Loss::Huber(2.0), Loss::Cauchy(1.0)] {
            let mut rec = start.clone();
            let config = BundleConfig {
                loss,
                ..Default::default()
            };
            adjust_pair(&mut rec, &config);
            errors.push(evaluate_poses(&rec, &truth).unwrap().max_rotation_deg);
        }
        // Robust errors at the level of the outlier-free case (see the test above: about
        // 0.1 deg at most for this geometry), plain least squares degrades by far more.
        assert!(errors[1] < 0.25 && errors[2] < 0.25, "{errors:?}");
        assert!(
            errors[1] * 20.0 < errors[0] && errors[2] * 20.0 < errors[0],
            "{errors:?}"
        );
    }

    /// The sparse and dense solvers of the reduced camera system give the same steps, so the
    /// same result to rounding; also with one camera per image.
    #[test]
    fn sparse_and_dense_solvers_agree() {
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig {
            noise_px: 0.3,
            shared_camera: false,
            ..Default::default()
        });
        let start = perturbed(&truth, 11);
        let mut results = Vec::new();
        for solver in [LinearSolver::SparseCholesky, LinearSolver::DenseCholesky] {
            let mut rec = start.clone();
            let config = BundleConfig {
                linear_solver: solver,
                ..Default::default()
            };
            let s = adjust_pair(&mut rec, &config);
            results.push((rec, s));
        }
        assert!(rotation_error_deg(&results[0].0, &results[1].0) < 1e-7);
        assert!(max_centre_error(&results[0].0, &results[1].0) < 1e-7);
        assert!(
            (results[0].1.final_cost - results[1].1.final_cost).abs()
                < 1e-6 * results[0].1.final_cost
        );
    }

    /// A local adjustment moves only the chosen image and its neighbours; images outside stay
    /// bit-identical, and the chosen image's perturbed pose is repaired.
    #[test]
    fn local_adjustment_moves_only_its_images() {
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig::default());
        let mut rec = truth.clone();
        // Perturb image 5 only.
        let im = rec.images.get_mut(&5).unwrap();
        im.cam_from_world.0.rotation =
            UnitQuaternion::from_scaled_axis(Vector3::new(0.02, -0.01, 0.015))
                * im.cam_from_world.0.rotation;
        im.cam_from_world.0.translation += Vector3::new(0.05, 0.0, -0.03);
        let setup = BundleSetup::local(&rec, 5, 3);
        assert_eq!(setup.images.len(), 4);
        let config = BundleConfig {
            loss: Loss::Squared,
            refine_focal: false,
            refine_distortion: false,
            function_tolerance: 1e-14,
            parameter_tolerance: 1e-14,
            ..Default::default()
        };
        bundle_adjust(&mut rec, &setup, &config).unwrap();
        for (id, im) in &rec.images {
            if !setup.images.contains(id) {
                assert_eq!(im.cam_from_world, truth.images[id].cam_from_world);
            }
        }
        let err = rec.images[&5]
            .cam_from_world
            .0
            .rotation
            .angle_to(&truth.images[&5].cam_from_world.0.rotation);
        assert!(err.to_degrees() < 1e-6, "{}", err.to_degrees());
    }

    /// The Jacobians BA builds from core's camera derivatives (pose in this module's
    /// parameterisation, point, free intrinsics) agree with central finite differences of the
    /// residual, for every camera model, also for a point behind the camera (mirrored
    /// projection). Tolerance 1e-5 relative: steps of 1e-6 leave O(1e-12) truncation.
    #[test]
    fn jacobians_match_finite_differences() {
        let models = [
            (CameraModel::SimplePinhole, vec![500.0, 320.0, 240.0]),
            (CameraModel::Pinhole, vec![500.0, 520.0, 320.0, 240.0]),
            (CameraModel::SimpleRadial, vec![500.0, 320.0, 240.0, -0.08]),
            (CameraModel::Radial, vec![500.0, 320.0, 240.0, -0.08, 0.02]),
            (
                CameraModel::OpenCv,
                vec![500.0, 520.0, 320.0, 240.0, -0.08, 0.02, 0.001, -0.002],
            ),
        ];
        for (model, params) in models {
            let (mut rec, _) = synthetic_reconstruction(&SyntheticConfig {
                cameras: 3,
                points: 5,
                model,
                params,
                ..Default::default()
            });
            // One point behind image 1.
            let c1 = rec.images[&1].cam_from_world.center().coords;
            let p1 = rec.points3d.get_mut(&1).unwrap();
            p1.position = (2.0 * c1 - p1.position.coords).into();
            let config = BundleConfig {
                refine_principal_point: true,
                loss: Loss::Squared,
                ..Default::default()
            };
            let setup = BundleSetup {
                gauge: Gauge::Free,
                ..BundleSetup::global(&rec)
            };
            let problem = build_problem(&rec, &setup, &config).unwrap();
            let state = State::of(&problem);
            for o in &problem.obs {
                let lin = linearise_obs(&problem, &state, o.point, o, Loss::Squared);
                let r0 = residual(&problem, &state, o.point, o).unwrap();
                assert!((lin.r - r0).norm() < 1e-12);
                let pb = &problem.poses[o.pose];
                let cam = &problem.cameras[pb.camera];
                let h = 1e-6;
                let check = |col: usize, fd: Vector2<f64>, analytic: Vector2<f64>| {
                    assert!(
                        (fd - analytic).norm() < 1e-5 * (1.0 + fd.norm()),
                        "{model:?} col {col}: {fd} vs {analytic}"
                    );
                };
                for (col, &k) in pb.free.iter().enumerate() {
                    let mut d = vec![0.0; problem.n_camera_unknowns];
                    let g = pb.group.unwrap();
                    d[problem.group_offset[g] + col] = h;
                    let dp = vec![Vector3::zeros(); problem.var_points.len()];
                    let plus = apply_step(&problem, &state, &d, &dp);
                    d[problem.group_offset[g] + col] = -h;
                    let minus = apply_step(&problem, &state, &d, &dp);
                    let fd = (residual(&problem, &plus, o.point, o).unwrap()
                        - residual(&problem, &minus, o.point, o).unwrap())
                        / (2.0 * h);
                    check(k, fd, lin.jc.column(col).into_owned());
                }
                for (col, &k) in cam.free.iter().enumerate() {
                    let hk = h * state.params[pb.camera][k].abs().max(1e-3);
                    let mut plus = state.clone();
                    plus.params[pb.camera][k] += hk;
                    let mut minus = state.clone();
                    minus.params[pb.camera][k] -= hk;
                    let fd = (residual(&problem, &plus, o.point, o).unwrap()
                        - residual(&problem, &minus, o.point, o).unwrap())
                        / (2.0 * hk);
                    check(100 + k, fd, lin.jc.column(pb.free.len() + col).into_owned());
                }
                for k in 0..3 {
                    let mut plus = state.clone();
                    plus.points[o.point][k] += h;
                    let mut minus = state.clone();
                    minus.points[o.point][k] -= h;
                    let fd = (residual(&problem, &plus, o.point, o).unwrap()
                        - residual(&problem, &minus, o.point, o).unwrap())
                        / (2.0 * h);
                    check(200 + k, fd, lin.jp.column(k).into_owned());
                }
            }
        }
    }

    /// Bad input gives errors naming what is wrong, not panics.
    #[test]
    fn bad_input_is_reported() {
        let (truth, _) = synthetic_reconstruction(&SyntheticConfig::default());
        let mut rec = truth.clone();
        let mut setup = BundleSetup::global(&rec);
        setup.images.insert(999);
        assert!(matches!(
            bundle_adjust(&mut rec, &setup, &BundleConfig::default()),
            Err(BundleError::UnknownImage(999))
        ));
        let mut rec = truth.clone();
        rec.cameras.get_mut(&1).unwrap().params.pop();
        let setup = BundleSetup::global(&rec);
        assert!(matches!(
            bundle_adjust(&mut rec, &setup, &BundleConfig::default()),
            Err(BundleError::BadCamera { .. })
        ));
    }
}
