//! `fresco unwrap <mesh> -o <charts.ply|.obj|.glb>`: charts, flattens and packs a mesh's
//! texture coordinates (`fresco_param::unwrap`), optionally draws the atlas as a PNG, and
//! reports the quality figures of `fresco_param::metrics`. `--measure` only scores the UVs
//! the input already has (used by bench/param.sh on xatlas's output).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use clap::Args;
use fresco_core::Mesh;
use fresco_param::UnwrapConfig;

#[derive(Args, Debug)]
pub struct UnwrapArgs {
    /// Input mesh (.ply or .obj).
    pub input: PathBuf,
    /// Output mesh with per-corner UVs and chart ids (.ply, .obj or .glb).
    #[arg(short, long, required_unless_present = "measure")]
    pub output: Option<PathBuf>,
    /// Atlas width and height in texels.
    #[arg(long, default_value_t = UnwrapConfig::default().atlas_size)]
    pub atlas: u32,
    /// Texels between charts and from the atlas border.
    #[arg(long, default_value_t = UnwrapConfig::default().gutter)]
    pub gutter: u32,
    /// Texels per world unit (default: the density that fills one atlas).
    #[arg(long)]
    pub texels_per_unit: Option<f64>,
    /// Charts whose L2 stretch stays above this are split.
    #[arg(long, default_value_t = UnwrapConfig::default().max_stretch)]
    pub max_stretch: f64,
    /// Start from the Reeb-graph segmentation instead of connected components.
    #[arg(long)]
    pub reeb: bool,
    /// Write a picture of the atlas (each chart a colour, a 3D checker showing distortion).
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Only measure the UVs the input already has (no output written).
    #[arg(long)]
    pub measure: bool,
}

fn read_mesh(path: &Path) -> anyhow::Result<Mesh> {
    let ext = extension(path);
    let mesh = match ext.as_str() {
        "ply" => fresco_core::ply::read_mesh(path)?,
        "obj" => fresco_core::obj::read_mesh(path)?,
        _ => bail!(
            "{}: unknown mesh format (expected .ply or .obj)",
            path.display()
        ),
    };
    Ok(mesh)
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

pub fn run(args: UnwrapArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let mut mesh = read_mesh(&args.input)?;
    if args.measure {
        // Files written per corner (OBJ with seams, xatlas) repeat vertices: weld exact
        // duplicates so that seams are seen as edges between charts.
        mesh.weld_vertices(0.0);
        let m = fresco_param::measure(&mesh)
            .with_context(|| format!("measuring the UVs of {}", args.input.display()))?;
        return Ok(serde_json::json!({ "input": args.input, "metrics": m }));
    }
    let output = args.output.clone().expect("clap requires --output");
    if same_file(&args.input, &output) {
        bail!("{}: the output would overwrite the input", output.display());
    }
    let out_ext = extension(&output);
    if !["ply", "obj", "glb"].contains(&out_ext.as_str()) {
        bail!(
            "{}: unknown output format (expected .ply, .obj or .glb)",
            output.display()
        );
    }
    let cfg = UnwrapConfig {
        atlas_size: args.atlas,
        gutter: args.gutter,
        texels_per_unit: args.texels_per_unit,
        max_stretch: args.max_stretch,
        reeb_charts: args.reeb,
        ..UnwrapConfig::default()
    };
    let bars = crate::progress::Bars::new(ctx);
    let start = Instant::now();
    let report = fresco_param::unwrap(&mut mesh, &cfg, &bars)
        .with_context(|| format!("unwrapping {}", args.input.display()))?;
    let seconds = start.elapsed().as_secs_f64();
    match out_ext.as_str() {
        "ply" => fresco_core::ply::write_mesh(
            &output,
            &mesh,
            fresco_core::ply::PlyFormat::BinaryLittleEndian,
        )?,
        "obj" => fresco_core::obj::write_obj(&output, &mesh, &[])?,
        _ => fresco_core::gltf::write_glb(&output, &mesh, &[])?,
    }
    if let Some(png) = &args.png {
        let diag = mesh.bounding_box().map_or(1.0, |b| b.diagonal());
        let size = args.atlas.min(2048);
        let img = fresco_param::chart_image::chart_image(&mesh, 0, size, diag / 40.0)
            .context("the unwrapped mesh has no UVs")?;
        let mut bytes = Vec::new();
        img.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .with_context(|| format!("encoding {}", png.display()))?;
        fresco_core::atomic_file::write_bytes_atomically(png, &bytes)?;
    }
    let metrics = fresco_param::measure(&mesh)?;
    Ok(serde_json::json!({
        "input": args.input,
        "output": output,
        "faces": mesh.faces.len(),
        "seconds": seconds,
        "report": report,
        "metrics": metrics,
    }))
}
