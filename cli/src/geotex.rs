//! `fresco geotex`: models with geometric texture (paper 002).
//!
//! - `fresco geotex resize <mesh> --scale 2,1,1 -o <out.ply>` (or `--size X,Y,Z`,
//!   `--method texture|kraevoy|uniform`): one call to `fresco_geotex::resize`; optional
//!   `--dump-segmentation` (vertex-coloured PLY of the input's labels) and `--png` (the input
//!   and the output side by side, texture regions coloured). Beside the output it writes
//!   its rest mesh, `<out stem>.rest.<ext>` ([`rest_path`]): the output's faces with each
//!   vertex where it sits on the input, so that `fresco sprites render <out> <scene>
//!   --rest <out stem>.rest.<ext>` keeps a sprite texture on the resized mesh (the texture
//!   method adds vertices; the rest mesh has them too).
//! - `fresco geotex model <threaded-cylinder|bumpy-box|scaly-blob> -o <out.ply>`: writes a
//!   synthetic model of `fresco_datasets::geometric_texture`, its ground-truth labels as
//!   vertex colours, and prints its feature sizes (the truth `resize` is judged against).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::{Args, Subcommand};
use fresco_core::Mesh;
use fresco_datasets::geometric_texture as gt;
use fresco_geotex::{Method, ResizeConfig, Target, picture};

#[derive(Args, Debug)]
pub struct GeotexArgs {
    #[command(subcommand)]
    pub command: GeotexCommand,
}

#[derive(Subcommand, Debug)]
pub enum GeotexCommand {
    /// Resize a mesh along x, y, z keeping its geometric texture at its size.
    Resize(ResizeArgs),
    /// Write a synthetic model with geometric texture and print its feature sizes.
    Model(ModelArgs),
}

#[derive(Args, Debug)]
pub struct ResizeArgs {
    /// Input mesh (.ply or .obj).
    pub input: PathBuf,
    /// Output mesh (.ply or .obj).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Scale factors along x, y, z of the bounding box ("2,1,1").
    #[arg(long, conflicts_with = "size", required_unless_present = "size")]
    pub scale: Option<String>,
    /// New bounding-box size along x, y, z (world units).
    #[arg(long)]
    pub size: Option<String>,
    /// texture (paper 002), kraevoy (protective grid on the textured mesh) or uniform.
    #[arg(long, default_value_t = ResizeConfig::default().method.name().to_string())]
    pub method: String,
    /// Seed of every random draw.
    #[arg(long, default_value_t = ResizeConfig::default().seed)]
    pub seed: u64,
    /// Skip fairing input and output to measure feature sizes and the base-shape error.
    #[arg(long)]
    pub no_measure: bool,
    /// Write the input's segmentation as a vertex-coloured PLY.
    #[arg(long)]
    pub dump_segmentation: Option<PathBuf>,
    /// Write a PNG of the input (left) and the output (right).
    #[arg(long)]
    pub png: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ModelArgs {
    /// threaded-cylinder, bumpy-box or scaly-blob.
    pub name: String,
    /// Output mesh (.ply or .obj); ground-truth labels as vertex colours.
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run(args: GeotexArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    match args.command {
        GeotexCommand::Resize(a) => resize(a, ctx),
        GeotexCommand::Model(a) => model(a),
    }
}

/// "2,1,1" as three numbers (checked for range by the library).
fn triple(option: &str, text: &str) -> anyhow::Result<[f64; 3]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        bail!("--{option} {text:?}: expected three numbers x,y,z");
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse()
            .with_context(|| format!("--{option} {text:?}: {p:?} is not a number"))?;
    }
    Ok(out)
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn check_mesh_path(path: &Path) -> anyhow::Result<()> {
    if !["ply", "obj"].contains(&extension(path).as_str()) {
        bail!(
            "{}: unknown mesh format (expected .ply or .obj)",
            path.display()
        );
    }
    Ok(())
}

fn read_mesh(path: &Path) -> anyhow::Result<Mesh> {
    check_mesh_path(path)?;
    Ok(match extension(path).as_str() {
        "ply" => fresco_core::ply::read_mesh(path)?,
        _ => fresco_core::obj::read_mesh(path)?,
    })
}

fn write_mesh(path: &Path, mesh: &Mesh) -> anyhow::Result<()> {
    match extension(path).as_str() {
        "ply" => fresco_core::ply::write_mesh(
            path,
            mesh,
            fresco_core::ply::PlyFormat::BinaryLittleEndian,
        )?,
        _ => fresco_core::obj::write_obj(path, mesh, &[])?,
    }
    Ok(())
}

/// Where the rest mesh of `output` goes: `dir/stem.ply` -> `dir/stem.rest.ply`.
pub fn rest_path(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    output.with_file_name(format!("{stem}.rest.{}", extension(output)))
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// `mesh` with each vertex coloured by its label (0 grey).
fn coloured(mesh: &Mesh, labels: &[u32]) -> Mesh {
    let mut out = Mesh::from_triangles(mesh.positions.clone(), mesh.faces.clone());
    out.colors = Some(
        labels
            .iter()
            .map(|&l| picture::label_colour(l).map(|c| (c * 255.0).round() as u8))
            .collect(),
    );
    out
}

fn resize(args: ResizeArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let target = match (&args.scale, &args.size) {
        (Some(s), _) => Target::Scale(triple("scale", s)?),
        (None, Some(s)) => Target::Size(triple("size", s)?),
        (None, None) => bail!("give --scale or --size"),
    };
    let Some(method) = Method::from_name(&args.method) else {
        bail!(
            "--method {:?}: expected texture, kraevoy or uniform",
            args.method
        );
    };
    check_mesh_path(&args.output)?;
    let rest = rest_path(&args.output);
    let mut outputs = vec![&args.output, &rest];
    outputs.extend(args.dump_segmentation.as_ref());
    outputs.extend(args.png.as_ref());
    for out in outputs {
        if same_file(&args.input, out) {
            bail!("{}: the output would overwrite the input", out.display());
        }
    }
    if let Some(seg) = &args.dump_segmentation
        && extension(seg) != "ply"
    {
        bail!("{}: the segmentation is written as .ply", seg.display());
    }
    let cfg = ResizeConfig {
        method,
        seed: args.seed,
        measure: !args.no_measure,
        ..ResizeConfig::default()
    };
    let mesh = read_mesh(&args.input)?;
    let bars = crate::progress::Bars::new(ctx);
    let out = fresco_geotex::resize(&mesh, &target, &cfg, &bars)
        .with_context(|| format!("resizing {}", args.input.display()))?;
    write_mesh(&args.output, &out.mesh)?;
    write_mesh(&rest, &out.rest_mesh())?;
    if let Some(seg) = &args.dump_segmentation {
        write_mesh(seg, &coloured(&mesh, &out.input_labels))?;
    }
    if let Some(png) = &args.png {
        let img = picture::before_after(&mesh, &out.input_labels, &out.mesh, &out.labels, 640)?;
        let mut bytes = Vec::new();
        img.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )?;
        fresco_core::atomic_file::write_bytes_atomically(png, &bytes)?;
    }
    if !ctx.json
        && let Some(notice) = &out.report.notice
    {
        eprintln!("notice: {notice}");
    }
    Ok(serde_json::json!({
        "input": args.input,
        "output": args.output,
        "rest": rest,
        "report": out.report,
    }))
}

fn model(args: ModelArgs) -> anyhow::Result<serde_json::Value> {
    check_mesh_path(&args.output)?;
    let m = match args.name.as_str() {
        "threaded-cylinder" => gt::threaded_cylinder(&gt::ThreadedCylinderConfig::default()),
        "bumpy-box" => gt::bumpy_box(&gt::BumpyBoxConfig::default()),
        "scaly-blob" => gt::scaly_blob(&gt::ScalyBlobConfig::default()),
        other => {
            bail!("unknown model {other:?}: expected threaded-cylinder, bumpy-box or scaly-blob")
        }
    };
    let labels: Vec<u32> = m.labels.iter().map(|&l| l as u32).collect();
    write_mesh(&args.output, &coloured(&m.mesh, &labels))?;
    let textures: Vec<serde_json::Value> = m
        .textures
        .iter()
        .map(|t| {
            let kind = match &t.kind {
                gt::TextureKind::Thread { pitch, depth } => {
                    serde_json::json!({"thread": {"pitch": pitch, "depth": depth}})
                }
                gt::TextureKind::Bumps {
                    radius,
                    height,
                    spacing,
                    hexagonal,
                } => serde_json::json!({"bumps": {"radius": radius, "height": height,
                    "spacing": spacing, "hexagonal": hexagonal}}),
                gt::TextureKind::Scales {
                    spacing,
                    groove,
                    height,
                } => serde_json::json!({"scales": {"spacing": spacing, "groove": groove,
                    "height": height}}),
            };
            serde_json::json!({"label": t.label, "kind": kind})
        })
        .collect();
    Ok(serde_json::json!({
        "model": m.name,
        "output": args.output,
        "vertices": m.mesh.positions.len(),
        "faces": m.mesh.faces.len(),
        "mean_edge": m.mean_edge_length(),
        "textures": textures,
    }))
}
