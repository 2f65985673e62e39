//! `fresco mesh <ws>`: oriented points to `<ws>/mesh.ply` through
//! `fresco_surface::pipeline::mesh_from_points` (Poisson, trimming, clean-up, decimation,
//! orientation towards the workspace's cameras when it has a model).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_core::colmap;
use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::ply::{PlyFormat, PlyReader, write_mesh};
use fresco_core::{CamFromWorld, Camera};
use fresco_surface::pipeline::{MeshConfig, mesh_from_points};
use fresco_surface::trim::TrimConfig;

#[derive(Args, Debug)]
pub struct MeshArgs {
    /// Workspace folder: reads <ws>/dense/fused.ply (unless --points), writes <ws>/mesh.ply.
    pub workspace: PathBuf,
    /// Read the points from this PLY instead (vertices with or without nx ny nz).
    #[arg(long)]
    pub points: Option<PathBuf>,
    /// Octree depth of the Poisson reconstruction (2-12).
    #[arg(long, default_value_t = MeshConfig::default().poisson.depth)]
    pub depth: u32,
    /// Screening weight of the samples (PoissonRecon's --pointWeight).
    #[arg(long, default_value_t = MeshConfig::default().poisson.point_weight)]
    pub point_weight: f64,
    /// Trim the surface where the sampling density (PoissonRecon's log4 scale) is below this
    /// absolute value (0 keeps everything). Without it, --trim-below-median applies.
    #[arg(long)]
    pub trim: Option<f32>,
    /// Trim where the density is this far below the median vertex density (1: a quarter of
    /// the typical sampling density), whatever the point count and depth.
    #[arg(long, default_value_t = default_below_median())]
    pub trim_below_median: f32,
    /// Face budget of the output (0 keeps every face).
    #[arg(long, default_value_t = MeshConfig::default().target_faces.unwrap_or(0))]
    pub faces: usize,
    /// Fail on points without normals instead of estimating them.
    #[arg(long)]
    pub no_normal_estimation: bool,
    /// Write ASCII PLY instead of binary.
    #[arg(long)]
    pub ascii: bool,
    /// The cameras the points were photographed from (a COLMAP model folder); the mesh is
    /// turned to face them. Default: <ws>/dense/sparse, else <ws>/sparse/0, if present.
    #[arg(long)]
    pub cameras: Option<PathBuf>,
    /// Keep the orientation Poisson gives, even when cameras are known.
    #[arg(long)]
    pub no_orient: bool,
}

/// The library's default trimming, relative to the median density.
fn default_below_median() -> f32 {
    MeshConfig::default()
        .trim
        .and_then(|t| t.below_median)
        .expect("MeshConfig trims relative to the median by default")
}

pub fn run(args: MeshArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let input = args
        .points
        .clone()
        .unwrap_or_else(|| args.workspace.join("dense").join("fused.ply"));
    let output = args.workspace.join("mesh.ply");
    if !args.workspace.is_dir() {
        bail!("workspace {} is not a folder", args.workspace.display());
    }
    if same_file(&input, &output) {
        bail!(
            "the input {} is the output mesh.ply: it would be overwritten",
            input.display()
        );
    }
    let (points, normals) = read_points(&input)?;
    let mut cfg = MeshConfig {
        estimate_normals: !args.no_normal_estimation,
        trim: match args.trim {
            Some(t) if t <= 0.0 => None,
            Some(t) => Some(TrimConfig {
                trim: t,
                ..TrimConfig::default()
            }),
            None => Some(TrimConfig {
                below_median: Some(args.trim_below_median),
                ..TrimConfig::default()
            }),
        },
        target_faces: (args.faces > 0).then_some(args.faces),
        ..MeshConfig::default()
    };
    cfg.cameras = cameras(&args)?;
    cfg.poisson.depth = args.depth;
    cfg.poisson.point_weight = args.point_weight;
    let bars = crate::progress::Bars::new(ctx);
    let (mesh, report) = mesh_from_points(&points, normals.as_deref(), &cfg, &bars)
        .with_context(|| format!("meshing the points of {}", input.display()))?;
    let format = if args.ascii {
        PlyFormat::Ascii
    } else {
        PlyFormat::BinaryLittleEndian
    };
    write_mesh(&output, &mesh, format)?;
    let mut summary = serde_json::to_value(&report)?;
    if let serde_json::Value::Object(map) = &mut summary {
        map.insert("input".into(), input.display().to_string().into());
        map.insert("output".into(), output.display().to_string().into());
    }
    Ok(summary)
}

/// The cameras of `--cameras` or of the workspace's model (dense first), unless --no-orient.
fn cameras(args: &MeshArgs) -> anyhow::Result<Vec<(Camera, CamFromWorld)>> {
    if args.no_orient {
        return Ok(Vec::new());
    }
    let dir = match &args.cameras {
        Some(dir) => dir.clone(),
        None => {
            let found = [
                args.workspace.join("dense").join("sparse"),
                args.workspace.join("sparse").join("0"),
            ]
            .into_iter()
            .find(|d| colmap::detect_format(d).is_ok());
            match found {
                Some(dir) => dir,
                None => return Ok(Vec::new()),
            }
        }
    };
    let rec = colmap::read_model(&dir).context("reading the cameras")?;
    Ok(rec
        .images
        .values()
        .filter_map(|im| Some((rec.cameras.get(&im.camera_id)?.clone(), im.cam_from_world)))
        .collect())
}

/// Points and, if the file has them, their normals.
type Cloud = (Vec<Point3<f64>>, Option<Vec<Vector3<f64>>>);

/// All vertices of a PLY, with their normals if the file has them. NaN coordinates are
/// passed through: the library drops and counts them.
fn read_points(path: &Path) -> anyhow::Result<Cloud> {
    let mut reader = PlyReader::open(path)?;
    if reader.vertex_count() == 0 {
        bail!("{}: no vertices", path.display());
    }
    let has_normals = reader.has_normals();
    let mut points = Vec::with_capacity(reader.vertex_count().min(1 << 24) as usize);
    let mut normals = has_normals.then(|| Vec::with_capacity(points.capacity()));
    while let Some(v) = reader.next_vertex()? {
        points.push(v.position);
        if let (Some(ns), Some(n)) = (normals.as_mut(), v.normal) {
            ns.push(n);
        }
    }
    Ok((points, normals))
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}
