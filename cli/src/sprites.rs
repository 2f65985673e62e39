//! `fresco sprites`: texture sprites (paper 001). `render` draws a mesh decorated by a sprite
//! scene, `bake` writes the scene into a model's UV atlas (GLB out), `octree` builds an
//! octree texture (marble or from a textured model). One `fresco_sprites::pipeline` call each.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::{Args, Subcommand};
use fresco_sprites::bake::BakeConfig;
use fresco_sprites::octree::OctreeConfig;
use fresco_sprites::pipeline::{self, OctreeSource, View};
use fresco_sprites::render::RenderConfig;
use fresco_sprites::scene::Scene;

#[derive(Args, Debug)]
pub struct SpritesArgs {
    #[command(subcommand)]
    command: SpritesCommand,
}

#[derive(Subcommand, Debug)]
enum SpritesCommand {
    /// Render a mesh decorated by a sprite scene (JSON) to a PNG.
    Render(RenderArgs),
    /// Bake a sprite scene into a model's UV atlas; writes the decorated model as GLB.
    Bake(BakeArgs),
    /// Build an octree texture (.foct) of a mesh's surface: Perlin marble or a model's colours.
    Octree(OctreeArgs),
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// Mesh (.ply, .obj or .glb).
    mesh: PathBuf,
    /// Sprite scene (JSON; see the README).
    scene: PathBuf,
    /// Orbit camera: azimuth,elevation,fov in degrees.
    #[arg(long, default_value = "30,20,40")]
    camera: String,
    /// Camera distance as a multiple of the one framing the mesh (above 1: a distant view).
    #[arg(long, default_value_t = View::default().distance)]
    distance: f64,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "640x480")]
    size: String,
    /// Rest-state mesh (same vertices and faces) the texture is attached to.
    #[arg(long)]
    rest: Option<PathBuf>,
    /// Animation time in seconds (keys, spin, pattern cycling); with --frames, the first
    /// frame's.
    #[arg(long, default_value_t = 0.0)]
    time: f64,
    /// Render N frames, at --time + k / --fps, to <output stem>_0000.png, _0001.png, ...
    /// (the tree is built once and its sprites updated from frame to frame).
    #[arg(long)]
    frames: Option<usize>,
    /// Frames per second of --frames.
    #[arg(long, default_value_t = 24.0, requires = "frames")]
    fps: f64,
    /// Headlight shading.
    #[arg(long)]
    shaded: bool,
    /// Plain lookups only: no tree mip-mapping (cell means) for pixels whose footprint is
    /// wider than the sprites or leaf cells they fall in.
    #[arg(long)]
    no_tree_mip: bool,
    /// Surface samples of the rest mesh the tree's cell means are taken over.
    #[arg(long, default_value_t = RenderConfig::default().mip_samples)]
    mip_samples: usize,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args, Debug)]
struct BakeArgs {
    /// Model with UVs (.glb, .obj, .ply; e.g. `fresco unwrap` output or model.glb).
    model: PathBuf,
    /// Sprite scene (JSON).
    scene: PathBuf,
    /// Output GLB.
    #[arg(short, long)]
    output: PathBuf,
    /// Also write the (first) baked atlas as PNG.
    #[arg(long)]
    png: Option<PathBuf>,
    /// Atlas size for models without a texture.
    #[arg(long, default_value_t = BakeConfig::default().size)]
    atlas: u32,
    /// Texels of dilation around charts.
    #[arg(long, default_value_t = BakeConfig::default().padding)]
    padding: u32,
    /// Animation time in seconds.
    #[arg(long, default_value_t = 0.0)]
    time: f64,
}

#[derive(Args, Debug)]
struct OctreeArgs {
    /// Mesh whose surface the octree covers (.ply, .obj or .glb).
    mesh: PathBuf,
    /// Levels of cells (finest cells: cube / N^depth).
    #[arg(long, default_value_t = OctreeConfig::default().depth)]
    depth: u32,
    /// Cells per node axis (2: an octree).
    #[arg(long, default_value_t = OctreeConfig::default().n)]
    n: u32,
    /// Colour by a Perlin marble.
    #[arg(long, conflicts_with = "from_model")]
    marble: bool,
    /// Veins per world unit of the marble.
    #[arg(long, default_value_t = 2.0)]
    marble_scale: f64,
    /// Colour from a textured model (.glb or .obj): its closest surface point.
    #[arg(long)]
    from_model: Option<PathBuf>,
    /// Store node means for tree mip-mapping (about 0.25 byte more per texel).
    #[arg(long)]
    mip: bool,
    /// Output octree texture (.foct).
    #[arg(short, long)]
    output: PathBuf,
}

fn parse_list<const K: usize>(s: &str, sep: char, what: &str) -> anyhow::Result<[f64; K]> {
    let v: Vec<f64> = s
        .split(sep)
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{what}: {s:?} is not {K} numbers separated by {sep:?}"))?;
    v.try_into()
        .map_err(|_| anyhow::anyhow!("{what}: {s:?} is not {K} numbers separated by {sep:?}"))
}

fn refuse_overwrite(input: &std::path::Path, output: &std::path::Path) -> anyhow::Result<()> {
    if let (Ok(a), Ok(b)) = (input.canonicalize(), output.canonicalize())
        && a == b
    {
        bail!("{}: the output would overwrite the input", output.display());
    }
    Ok(())
}

/// `<output stem>_<k, 4 digits>.png` beside `output`.
fn frame_path(output: &std::path::Path, k: usize) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or_else(|| "frame".into(), |s| s.to_string_lossy());
    output.with_file_name(format!("{stem}_{k:04}.png"))
}

/// Encodes `img` as PNG and writes it atomically (a reader never sees half a file).
fn write_png(img: &image::RgbImage, path: &std::path::Path) -> anyhow::Result<()> {
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )?;
    fresco_core::atomic_file::write_bytes_atomically(path, &bytes)?;
    Ok(())
}

pub fn run(args: SpritesArgs, _ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    match args.command {
        SpritesCommand::Render(a) => {
            let [az, el, fov] = parse_list::<3>(&a.camera, ',', "--camera")?;
            let [w, h] = parse_list::<2>(&a.size, 'x', "--size")?;
            for p in [&a.mesh, &a.scene] {
                refuse_overwrite(p, &a.output)?;
            }
            let scene = Scene::load(&a.scene)?;
            let mesh = pipeline::load_model(&a.mesh)?.mesh;
            let rest = match &a.rest {
                Some(p) => Some(pipeline::load_model(p)?.mesh),
                None => None,
            };
            let view = View {
                width: w as u32,
                height: h as u32,
                azimuth_deg: az,
                elevation_deg: el,
                fov_deg: fov,
                distance: a.distance,
            };
            let cfg = RenderConfig {
                shaded: a.shaded,
                tree_mip: !a.no_tree_mip,
                mip_samples: a.mip_samples,
                ..RenderConfig::default()
            };
            if let Some(frames) = a.frames {
                if frames == 0 {
                    bail!("--frames 0: nothing to render");
                }
                if !(a.fps > 0.0 && a.fps.is_finite()) {
                    bail!("--fps {} must be positive", a.fps);
                }
                let outputs: Vec<PathBuf> = (0..frames).map(|k| frame_path(&a.output, k)).collect();
                for o in &outputs {
                    for p in [&a.mesh, &a.scene] {
                        refuse_overwrite(p, o)?;
                    }
                }
                let times: Vec<f64> = (0..frames).map(|k| a.time + k as f64 / a.fps).collect();
                let report = pipeline::render_frames(
                    &mesh,
                    rest.as_ref(),
                    &scene,
                    &view,
                    &cfg,
                    &times,
                    |k, img| {
                        write_png(&img, &outputs[k])
                            .map_err(|e| fresco_sprites::SpriteError::Input(format!("{e:#}")))
                    },
                )
                .with_context(|| format!("rendering {}", a.scene.display()))?;
                return Ok(
                    serde_json::json!({ "outputs": outputs, "times": times, "frames": report }),
                );
            }
            let (img, memory) =
                pipeline::render_scene(&mesh, rest.as_ref(), &scene, &view, &cfg, a.time)
                    .with_context(|| format!("rendering {}", a.scene.display()))?;
            write_png(&img, &a.output)?;
            Ok(serde_json::json!({ "output": a.output, "memory": memory }))
        }
        SpritesCommand::Bake(a) => {
            for p in [&a.model, &a.scene] {
                refuse_overwrite(p, &a.output)?;
            }
            let scene = Scene::load(&a.scene)?;
            let cfg = BakeConfig {
                size: a.atlas,
                padding: a.padding,
                ..BakeConfig::default()
            };
            let s =
                pipeline::bake_scene(&a.model, &scene, &a.output, a.png.as_deref(), &cfg, a.time)
                    .with_context(|| {
                    format!("baking {} into {}", a.scene.display(), a.model.display())
                })?;
            Ok(serde_json::to_value(s)?)
        }
        SpritesCommand::Octree(a) => {
            refuse_overwrite(&a.mesh, &a.output)?;
            let source = match (&a.from_model, a.marble) {
                (Some(m), _) => OctreeSource::Model(m),
                (None, true) => OctreeSource::Marble {
                    scale: a.marble_scale,
                    seed: 1,
                },
                (None, false) => bail!("say where colours come from: --marble or --from-model"),
            };
            let mesh = pipeline::load_model(&a.mesh)?.mesh;
            let cfg = OctreeConfig {
                n: a.n,
                depth: a.depth,
                ..OctreeConfig::default()
            };
            let (_, memory) = pipeline::octree_texture(&mesh, &source, &cfg, a.mip, &a.output)
                .with_context(|| format!("octree texture of {}", a.mesh.display()))?;
            Ok(serde_json::json!({ "output": a.output, "memory": memory }))
        }
    }
}
