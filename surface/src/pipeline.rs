//! Points to a clean mesh in one call: the surface stage as `fresco mesh` runs it.
//!
//! [`mesh_from_points`]:
//! 1. drops points with a non-finite coordinate (counted) and, when normals are given, points
//!    whose normal is non-finite or zero (counted); fewer than [`MIN_POINTS`] left is an error;
//! 2. without normals, estimates them (PCA) and orients them (MST), unless the configuration
//!    forbids it, which is then an error saying so;
//! 3. screened Poisson reconstruction (`poisson.rs`);
//! 4. density trimming (`trim.rs`), if a trim value is set;
//! 5. clean-up (`cleanup.rs`): small islands, degenerate faces, non-manifold repair;
//! 6. quadric decimation (`decimate.rs`) to the face budget, if the mesh is larger;
//! 7. orientation (`orientation.rs`): when the cameras that photographed the surface are
//!    given, every component they see more from behind than from the front is flipped, so
//!    that meshes made from photos face their cameras;
//!
//! and returns the mesh with vertex normals and a report of every stage.

use std::time::Instant;

use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{CamFromWorld, Camera, Mesh, Progress};

use crate::cleanup::{CleanupConfig, CleanupReport, cleanup};
use crate::decimate::{DecimateConfig, DecimateError, DecimateReport, decimate};
use crate::normals::{NormalConfig, NormalError, estimate_normals, orient_normals};
use crate::orientation::{OrientationReport, face_the_cameras};
use crate::poisson::{PoissonConfig, PoissonError, reconstruct};
use crate::trim::{TrimConfig, TrimError, TrimReport, trim_by_density};

/// Fewer usable points than this cannot describe a surface.
pub const MIN_POINTS: usize = 10;

/// Settings of every stage; `fresco mesh` takes its defaults from here.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshConfig {
    /// Default: `PoissonConfig::default()`.
    pub poisson: PoissonConfig,
    /// Estimate normals when the points have none (otherwise that is an error).
    /// Default: `true`.
    pub estimate_normals: bool,
    /// Default: `NormalConfig::default()`.
    pub normals: NormalConfig,
    /// Density trimming; `None` keeps the whole Poisson surface. Default:
    /// `Some(TrimConfig { below_median: Some(1.0), ..TrimConfig::default() })`, a cut where
    /// the sampling density falls to a quarter of the median (see `TrimConfig::below_median`).
    pub trim: Option<TrimConfig>,
    /// Default: `CleanupConfig::default()`.
    pub cleanup: CleanupConfig,
    /// Face budget, >= 1; `None` keeps every face. Default: `Some(200_000)`.
    pub target_faces: Option<usize>,
    /// The cameras (intrinsics and pose) the points were photographed from; when given, the
    /// mesh is oriented to face them (step 7). Default: `[]`.
    pub cameras: Vec<(Camera, CamFromWorld)>,
}

impl Default for MeshConfig {
    fn default() -> Self {
        MeshConfig {
            poisson: PoissonConfig::default(),
            estimate_normals: true,
            normals: NormalConfig::default(),
            trim: Some(TrimConfig {
                below_median: Some(1.0),
                ..TrimConfig::default()
            }),
            cleanup: CleanupConfig::default(),
            target_faces: Some(200_000),
            cameras: Vec::new(),
        }
    }
}

impl MeshConfig {
    /// Validates every field, the nested configurations' too (named `poisson.depth`, ...).
    pub fn check(&self) -> Result<(), ConfigError> {
        self.poisson.check().map_err(|e| e.within("poisson"))?;
        self.normals.check().map_err(|e| e.within("normals"))?;
        if let Some(trim) = &self.trim {
            trim.check().map_err(|e| e.within("trim"))?;
        }
        self.cleanup.check().map_err(|e| e.within("cleanup"))?;
        if let Some(faces) = self.target_faces {
            require(faces >= 1, "target_faces", faces, ">= 1")?;
        }
        Ok(())
    }
}

/// What [`mesh_from_points`] did, stage by stage.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct MeshReport {
    pub input_points: usize,
    /// Points dropped for a NaN or infinite coordinate.
    pub non_finite_points: usize,
    /// Points dropped for a NaN, infinite or zero normal.
    pub bad_normals: usize,
    pub points_used: usize,
    pub normals_estimated: bool,
    pub normals_flipped: usize,
    pub poisson_faces: usize,
    pub poisson_vertices: usize,
    pub iso_value: f64,
    pub trim: Option<TrimReport>,
    pub cleanup: CleanupReport,
    pub decimate: Option<DecimateReport>,
    /// Step 7, when cameras were given.
    pub orientation: Option<OrientationReport>,
    pub faces: usize,
    pub vertices: usize,
    pub seconds_normals: f64,
    pub seconds_poisson: f64,
    pub seconds_trim: f64,
    pub seconds_cleanup: f64,
    pub seconds_decimate: f64,
    pub seconds_orientation: f64,
}

/// Why no mesh could be made.
#[derive(Debug, thiserror::Error)]
pub enum MeshFromPointsError {
    #[error(
        "{usable} usable points ({non_finite} with NaN/infinite coordinates, {bad_normals} with \
         bad normals dropped); at least {MIN_POINTS} are needed"
    )]
    TooFewPoints {
        usable: usize,
        non_finite: usize,
        bad_normals: usize,
    },
    #[error("{points} points but {normals} normals")]
    LengthMismatch { points: usize, normals: usize },
    #[error("the points have no normals and normal estimation is disabled")]
    MissingNormals,
    // The stage errors below are shown in the message after the stage's name, so they are
    // not also exposed as `source` (anyhow's `{:#}` would print them twice).
    #[error("normal estimation: {0}")]
    Normals(NormalError),
    #[error("Poisson reconstruction: {0}")]
    Poisson(PoissonError),
    #[error("trimming: {0}")]
    Trim(TrimError),
    #[error("decimation: {0}")]
    Decimate(DecimateError),
    #[error("orienting the mesh towards its cameras: {0}")]
    Orientation(fresco_core::raster::RasterError),
    #[error(
        "nothing is left after trimming at density {0}: lower --trim (or raise --trim-below-median)"
    )]
    TrimmedAway(f32),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// Oriented (or bare, if `normals` is `None`) points to a clean mesh; see the module
/// documentation.
pub fn mesh_from_points(
    points: &[Point3<f64>],
    normals: Option<&[Vector3<f64>]>,
    cfg: &MeshConfig,
    progress: &dyn Progress,
) -> Result<(Mesh, MeshReport), MeshFromPointsError> {
    cfg.check()?;
    if let Some(n) = normals
        && n.len() != points.len()
    {
        return Err(MeshFromPointsError::LengthMismatch {
            points: points.len(),
            normals: n.len(),
        });
    }
    let mut report = MeshReport {
        input_points: points.len(),
        ..MeshReport::default()
    };
    let mut pts = Vec::with_capacity(points.len());
    let mut nrm = Vec::with_capacity(if normals.is_some() { points.len() } else { 0 });
    for (i, p) in points.iter().enumerate() {
        if !p.coords.iter().all(|c| c.is_finite()) {
            report.non_finite_points += 1;
            continue;
        }
        if let Some(ns) = normals {
            let n = ns[i];
            if !(n.iter().all(|c| c.is_finite()) && n.norm_squared() > 0.0) {
                report.bad_normals += 1;
                continue;
            }
            nrm.push(n);
        }
        pts.push(*p);
    }
    report.points_used = pts.len();
    if pts.len() < MIN_POINTS {
        return Err(MeshFromPointsError::TooFewPoints {
            usable: pts.len(),
            non_finite: report.non_finite_points,
            bad_normals: report.bad_normals,
        });
    }

    let t = Instant::now();
    if normals.is_none() {
        if !cfg.estimate_normals {
            return Err(MeshFromPointsError::MissingNormals);
        }
        progress.begin("normals", 0);
        nrm = estimate_normals(&pts, &cfg.normals).map_err(MeshFromPointsError::Normals)?;
        let o =
            orient_normals(&pts, &mut nrm, &cfg.normals).map_err(MeshFromPointsError::Normals)?;
        progress.end();
        report.normals_estimated = true;
        report.normals_flipped = o.flipped;
    }
    report.seconds_normals = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let out =
        reconstruct(&pts, &nrm, &cfg.poisson, progress).map_err(MeshFromPointsError::Poisson)?;
    report.seconds_poisson = t.elapsed().as_secs_f64();
    report.poisson_faces = out.mesh.faces.len();
    report.poisson_vertices = out.mesh.positions.len();
    report.iso_value = out.stats.iso_value;
    let mut mesh = out.mesh;

    let t = Instant::now();
    if let Some(trim) = &cfg.trim {
        let trimmed =
            trim_by_density(&mesh, &out.vertex_density, trim).map_err(MeshFromPointsError::Trim)?;
        if trimmed.mesh.faces.is_empty() {
            return Err(MeshFromPointsError::TrimmedAway(trimmed.report.threshold));
        }
        mesh = trimmed.mesh;
        report.trim = Some(trimmed.report);
    }
    report.seconds_trim = t.elapsed().as_secs_f64();

    let t = Instant::now();
    report.cleanup = cleanup(&mut mesh, &cfg.cleanup)?;
    report.seconds_cleanup = t.elapsed().as_secs_f64();

    let t = Instant::now();
    if let Some(target) = cfg.target_faces
        && mesh.faces.len() > target
    {
        progress.begin("decimate", 0);
        let (m, r) = decimate(
            &mesh,
            &DecimateConfig {
                target_faces: target,
                ..DecimateConfig::default()
            },
        )
        .map_err(MeshFromPointsError::Decimate)?;
        progress.end();
        mesh = m;
        report.decimate = Some(r);
    }
    report.seconds_decimate = t.elapsed().as_secs_f64();

    let t = Instant::now();
    if !cfg.cameras.is_empty() {
        progress.begin("orientation", 0);
        report.orientation = Some(
            face_the_cameras(&mut mesh, &cfg.cameras).map_err(MeshFromPointsError::Orientation)?,
        );
        progress.end();
    }
    report.seconds_orientation = t.elapsed().as_secs_f64();
    mesh.compute_vertex_normals();
    report.faces = mesh.faces.len();
    report.vertices = mesh.positions.len();
    Ok((mesh, report))
}
