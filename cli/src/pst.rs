//! `fresco pst ...`: point-sampled textures for meshes too large for memory (fresco-pst).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, bail};
use clap::{Args, Subcommand};
use fresco_core::ply::PlyFormat;
use fresco_pst::apply::{ApplyConfig, apply_to_ply};
use fresco_pst::{
    Channel, CreateConfig, FieldConfig, Kernel, PlyPoints, PositionRule, Pst, SamplingConfig,
};
use serde_json::json;

use crate::Context;
use crate::progress::Bars;

#[derive(Args, Debug)]
pub struct PstArgs {
    #[command(subcommand)]
    command: PstCommand,
}

#[derive(Subcommand, Debug)]
enum PstCommand {
    /// Sample a huge PLY (mesh or point cloud) out of core into a PST folder.
    Sample(SampleArgs),
    /// Run an editing script (JSON ops: fill, noise, smooth, project, refine, transfer, ...).
    Paint(PaintArgs),
    /// Up-sample a region from the 1-node files.
    Refine(RefineArgs),
    /// Write the mesh with per-vertex colours evaluated from the PST.
    Apply(ApplyArgs),
    /// Transfer colours from a textured model (GLB or OBJ) into the PST.
    FromModel(FromModelArgs),
    /// Export the PST as an octree texture (.foct).
    ExportOctree(ExportOctreeArgs),
    /// Generate a large test mesh (subdivided, displaced sphere) streamed to a binary PLY.
    GenMesh(GenMeshArgs),
    /// Measure PST lookup throughput at points near the samples.
    Lookups(LookupsArgs),
}

#[derive(Args, Debug)]
struct SampleArgs {
    /// Input PLY (binary or ascii; mesh or point cloud).
    input: PathBuf,
    /// Target number of samples.
    #[arg(short, long, default_value_t = SamplingConfig::default().target)]
    n: u64,
    /// Adaptivity alpha (samples per 1-node; 0 = uniform).
    #[arg(long, default_value_t = SamplingConfig::default().alpha)]
    alpha: f64,
    /// Position rule: centroid or quadric.
    #[arg(long, default_value_t = position_name(SamplingConfig::default().position).to_string())]
    position: String,
    /// Keep the paper's plain sub-grid sizes (no correction towards n).
    #[arg(long)]
    no_size_correction: bool,
    /// Folder for the 1-node files while sampling (default: beside the output).
    #[arg(long)]
    temp_dir: Option<PathBuf>,
    /// Do not keep the 1-node files (refinement becomes unavailable).
    #[arg(long)]
    no_node_files: bool,
    /// In-core sample budget for the LRU.
    #[arg(long)]
    budget: Option<usize>,
    /// Output PST folder.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args, Debug)]
struct PaintArgs {
    /// PST folder.
    pst: PathBuf,
    /// JSON ops file.
    ops: PathBuf,
    /// Neighbourhood size of the PST (colours of refined samples).
    #[arg(short, default_value_t = FieldConfig::default().k)]
    k: usize,
}

#[derive(Args, Debug)]
struct RefineArgs {
    /// PST folder.
    pst: PathBuf,
    /// box:x0,y0,z0,x1,y1,z1 | sphere:x,y,z,r | all
    #[arg(long)]
    region: String,
    /// Sub-grid resolution factor (default 2).
    #[arg(long, conflicts_with_all = ["spacing", "full"])]
    factor: Option<u32>,
    /// Target sample spacing (world units).
    #[arg(long, conflicts_with = "full")]
    spacing: Option<f64>,
    /// Keep every input point of the region.
    #[arg(long)]
    full: bool,
    #[arg(short, default_value_t = FieldConfig::default().k)]
    k: usize,
}

#[derive(Args, Debug)]
struct FromModelArgs {
    /// Textured model (.glb or .obj with texture or vertex colours).
    model: PathBuf,
    /// PST folder to colour.
    pst: PathBuf,
    /// Leave samples farther than this from the model unchanged.
    #[arg(long)]
    max_distance: Option<f64>,
}

#[derive(Args, Debug)]
struct ExportOctreeArgs {
    /// PST folder.
    pst: PathBuf,
    /// Output .foct file.
    #[arg(short, long)]
    output: PathBuf,
    /// Maximum depth.
    #[arg(long, default_value_t = 8)]
    depth: u32,
    #[arg(short, default_value_t = FieldConfig::default().k)]
    k: usize,
}

#[derive(Args, Debug)]
struct ApplyArgs {
    /// PST folder.
    pst: PathBuf,
    /// The original mesh (PLY).
    input: PathBuf,
    /// Output PLY with per-vertex colours.
    #[arg(short, long)]
    output: PathBuf,
    /// Neighbourhood size of the PST.
    #[arg(short, default_value_t = FieldConfig::default().k)]
    k: usize,
    /// Singular (feature-preserving) kernel with this power instead of the Hermite decay.
    #[arg(long)]
    singular: Option<f32>,
    /// Channel written as colour.
    #[arg(long, default_value_t = ApplyConfig::default().channel)]
    channel: String,
    /// Write ascii instead of binary.
    #[arg(long)]
    ascii: bool,
}

#[derive(Args, Debug)]
struct GenMeshArgs {
    /// Number of triangles (rounded to the subdivision grid).
    #[arg(long, default_value_t = 10_000_000)]
    triangles: u64,
    /// Output PLY.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args, Debug)]
struct LookupsArgs {
    /// PST folder.
    pst: PathBuf,
    /// Query points: the vertices of this PLY mesh or cloud in file order (what `apply`
    /// evaluates). Without it, points scattered around the samples.
    #[arg(long)]
    points: Option<PathBuf>,
    /// Number of lookups (at most the file's vertex count with --points).
    #[arg(long, default_value_t = 10_000_000)]
    count: usize,
    #[arg(short, default_value_t = FieldConfig::default().k)]
    k: usize,
    /// Lookups compared with a brute-force evaluation.
    #[arg(long, default_value_t = 2000)]
    check: usize,
}

pub fn run(args: PstArgs, ctx: &Context) -> anyhow::Result<serde_json::Value> {
    let bars = Bars::new(ctx);
    match args.command {
        PstCommand::Sample(a) => {
            let Some(position) = [PositionRule::Centroid, PositionRule::Quadric]
                .into_iter()
                .find(|&p| position_name(p) == a.position)
            else {
                bail!("--position must be centroid or quadric, not {}", a.position);
            };
            let source = PlyPoints::open(&a.input)?;
            let cfg = CreateConfig {
                sampling: SamplingConfig {
                    target: a.n,
                    alpha: a.alpha,
                    position,
                    correct_size: !a.no_size_correction,
                    ..Default::default()
                },
                channels: vec![Channel::new("rgb", &[0.8, 0.8, 0.8])],
                temp_dir: a.temp_dir,
                keep_node_files: !a.no_node_files,
                budget: a.budget,
            };
            let t = Instant::now();
            let (pst, s) = Pst::create(&source, &cfg, &a.output, &bars)
                .with_context(|| format!("sampling {}", a.input.display()))?;
            let secs = t.elapsed().as_secs_f64();
            for w in &s.warnings {
                eprintln!("warning: {w}");
            }
            Ok(json!({
                "input": a.input,
                "output": pst.dir,
                "input_points": s.input_points,
                "target": a.n,
                "samples": s.samples.len(),
                "size_error_percent": 100.0 * (s.samples.len() as f64 - a.n as f64) / a.n as f64,
                "paper_scheme_samples": s.paper_size,
                "one_nodes": s.nodes.len(),
                "alpha": a.alpha,
                "seconds": secs,
                "points_per_second": s.input_points as f64 / secs,
                "phases": s.phases,
                "warnings": s.warnings,
            }))
        }
        PstCommand::Paint(a) => {
            let mut pst = Pst::open(&a.pst)?;
            let reports =
                fresco_pst::paint::run_script(&mut pst, &a.ops, field_config(a.k, None)?, &bars)?;
            Ok(json!({ "pst": a.pst, "ops": reports, "in_core": pst.samples.len() }))
        }
        PstCommand::Refine(a) => {
            use fresco_pst::refine::Resolution;
            let mut pst = Pst::open(&a.pst)?;
            let region = fresco_pst::region::Region::parse(&a.region)?;
            let res = match (a.factor, a.spacing, a.full) {
                (_, _, true) => Resolution::Full,
                (_, Some(h), _) => Resolution::Spacing(h),
                (f, None, false) => Resolution::Factor(f.unwrap_or(2)),
            };
            let r = fresco_pst::refine::refine(
                &mut pst,
                &region,
                res,
                field_config(a.k, None)?,
                &bars,
            )?;
            pst.save()?;
            Ok(json!({ "pst": a.pst, "refine": r, "in_core": pst.samples.len() }))
        }
        PstCommand::FromModel(a) => {
            let mut pst = Pst::open(&a.pst)?;
            let op = fresco_pst::paint::Op::Transfer {
                model: std::path::absolute(&a.model)?,
                max_distance: a.max_distance,
                region: fresco_pst::region::Region::All,
                channel: "rgb".into(),
            };
            let t = Instant::now();
            let r = fresco_pst::paint::apply_op(
                &mut pst,
                &op,
                std::path::Path::new("."),
                FieldConfig::default(),
                &bars,
            )
            .with_context(|| format!("transferring colours from {}", a.model.display()))?;
            pst.save()?;
            Ok(json!({ "pst": a.pst, "transfer": r, "seconds": t.elapsed().as_secs_f64() }))
        }
        PstCommand::ExportOctree(a) => {
            let pst = Pst::open(&a.pst)?;
            let all = pst.all_samples()?;
            let field = fresco_pst::Field::new(&all, field_config(a.k, None)?);
            let tex = fresco_pst::octree_texture::OctreeTexture::from_field(&field, a.depth)?;
            tex.save(&a.output)?;
            Ok(
                json!({ "output": a.output, "nodes": tex.pool.used_nodes(), "texels": tex.texels, "depth": a.depth }),
            )
        }
        PstCommand::Apply(a) => {
            let pst = Pst::open(&a.pst)?;
            let cfg = ApplyConfig {
                field: field_config(a.k, a.singular)?,
                channel: a.channel,
                format: if a.ascii {
                    PlyFormat::Ascii
                } else {
                    PlyFormat::BinaryLittleEndian
                },
                ..Default::default()
            };
            let t = Instant::now();
            let r = apply_to_ply(&pst, &a.input, &a.output, &cfg, &bars).with_context(|| {
                format!("applying {} to {}", a.pst.display(), a.input.display())
            })?;
            let secs = t.elapsed().as_secs_f64();
            Ok(json!({
                "output": a.output,
                "vertices": r.vertices,
                "faces": r.faces,
                "samples": r.samples,
                "k": r.k,
                "seconds": secs,
                "vertices_per_second": r.vertices as f64 / secs,
            }))
        }
        PstCommand::GenMesh(a) => {
            let lm = fresco_datasets::large_mesh::LargeMesh::with_triangles(a.triangles);
            let t = Instant::now();
            lm.write_ply(&a.output, PlyFormat::BinaryLittleEndian, &bars)?;
            Ok(json!({
                "output": a.output,
                "vertices": lm.vertex_count(),
                "triangles": lm.triangle_count(),
                "seconds": t.elapsed().as_secs_f64(),
            }))
        }
        PstCommand::Lookups(a) => {
            let pst = Pst::open(&a.pst)?;
            let field = fresco_pst::Field::new(&pst.samples, field_config(a.k, None)?);
            let queries = match &a.points {
                Some(path) => fresco_pst::bench::surface_queries(&PlyPoints::open(path)?, a.count)?,
                None => fresco_pst::bench::queries_near_samples(&pst.samples, a.count, 1),
            };
            let mut out = vec![0f32; queries.len() * pst.samples.width];
            // Best of 3 runs: the machine is shared.
            let mut best = f64::INFINITY;
            for _ in 0..3 {
                let t = Instant::now();
                field.eval_many(&queries, &mut out);
                best = best.min(t.elapsed().as_secs_f64());
            }
            // Brute-force check on an evenly spread subset, on the PST's own channels and on
            // positions as attributes (a field that is never constant).
            let stride = (queries.len() / a.check.max(1)).max(1);
            let subset: Vec<[f32; 3]> = queries.iter().step_by(stride).copied().collect();
            let own = fresco_pst::bench::brute_force_agreement(&field, &subset);
            let xyz = fresco_pst::bench::with_position_attributes(&pst.samples);
            let xyz_field = fresco_pst::Field::new(&xyz, field_config(a.k, None)?);
            let pos = fresco_pst::bench::brute_force_agreement(&xyz_field, &subset);
            Ok(json!({
                "samples": pst.samples.len(),
                "lookups": queries.len(),
                "queries": a.points.as_ref().map_or("near the samples".to_string(), |p| {
                    format!("vertices of {} in file order", p.display())
                }),
                "k": a.k,
                "threads": rayon::current_num_threads(),
                "seconds": best,
                "lookups_per_second": queries.len() as f64 / best,
                "brute_force_channels": own,
                "brute_force_positions": pos,
            }))
        }
    }
}

/// The name of a position rule on the command line.
fn position_name(rule: PositionRule) -> &'static str {
    match rule {
        PositionRule::Centroid => "centroid",
        PositionRule::Quadric => "quadric",
    }
}

/// The PST settings of `-k` and `--singular`, checked by the library (`Field::new`, which the
/// export and lookups call, takes any `k`).
fn field_config(k: usize, singular: Option<f32>) -> anyhow::Result<FieldConfig> {
    let cfg = FieldConfig {
        k,
        kernel: match singular {
            Some(power) => Kernel::Singular { power },
            None => Kernel::Hermite,
        },
    };
    cfg.check()?;
    Ok(cfg)
}
