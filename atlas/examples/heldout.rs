//! Held-out PSNR of fresco's texture and of the per-vertex colour baseline on a synthetic
//! scene: `cargo run --release -p fresco-atlas --example heldout -- <shape> [detail] [exposure_jitter]`.
//! Views 5 and 17 of 24 are held out; the texture is made from the other 22 with the
//! ground-truth mesh and cameras. With COLMAP=<model dir> IMAGES=<dir> MESH=<ply> HELD=a,b
//! a real scene's named photos are held out instead; SEAMS=a.glb,b.glb prints the seam colour
//! discrepancy of textured GLBs. Environment: WIDTH (640), VIEWS (24), K1 (distortion, 0 for
//! none), TPP, QW, MIPBIAS, BILINEAR, NOOUT, OUTSIG, OUTMIN, OUTWIN, OUTNEAR, OUTPATCH, LEVEL, LEVELSMOOTH, STRIP (seam strip width, 0 off), DETAIL (seam detail passes), STRIPCREASE (degrees), SHARPEN (playback sharpening), DIAG (error split by cause), GLB (score that model instead), NOGAIN, NOBLEND, BLENDQ, BLENDTOL, BLENDSIGMA, BLENDFADE, SAVE (renders and diff to /tmp).

use std::path::Path;
use std::time::Instant;

use fresco_atlas::{
    ImageSource, TextureConfig, TextureInputs, TexturedModel, compare_to_photo, comparison_mask,
    render_textured, texture, vertex_colors,
};
use fresco_core::NoProgress;
use fresco_datasets::{SceneConfig, Shape, write_dataset};

fn main() {
    // SEAMS=a.glb,b.glb: only print the seam colour discrepancy of textured GLBs.
    if let Ok(list) = std::env::var("SEAMS") {
        for path in list.split(',') {
            let (mesh, textures) = fresco_core::gltf::read_glb(Path::new(path)).unwrap();
            let s = fresco_atlas::seam_discrepancy(&mesh, &textures);
            println!("{path}: {} faces, {s:?}", mesh.faces.len());
        }
        return;
    }
    let args: Vec<String> = std::env::args().collect();
    let shape = Shape::from_name(args.get(1).map_or("torus", String::as_str)).expect("shape");
    let detail: u32 = args
        .get(2)
        .map_or(SceneConfig::default().detail, |s| s.parse().unwrap());
    let jitter: f64 = args.get(3).map_or(0.08, |s| s.parse().unwrap());
    let dir = tempfile::tempdir().unwrap();
    let var = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    let width = var("WIDTH").map_or(640, |w| w as u32);
    let cfg = SceneConfig {
        shape,
        detail,
        exposure_jitter: jitter,
        width,
        height: width * 3 / 4,
        views: var("VIEWS").map_or(SceneConfig::default().views, |v| v as u32),
        distortion: match var("K1") {
            Some(0.0) => fresco_datasets::Distortion::None,
            Some(k) => fresco_datasets::Distortion::SimpleRadial { k },
            None => SceneConfig::default().distortion,
        },
        ..SceneConfig::default()
    };
    // A real scene instead of a synthetic one: COLMAP=<model dir> IMAGES=<dir> MESH=<ply>
    // HELD=a.png,b.png (no masks: the model's silhouette is compared).
    let real = std::env::var("COLMAP").ok();
    let (mesh, rec, images_dir, masks_dir, held): (
        _,
        _,
        std::path::PathBuf,
        Option<std::path::PathBuf>,
        Vec<String>,
    ) = if let Some(model) = &real {
        let env =
            |k: &str| std::env::var(k).unwrap_or_else(|_| panic!("{k} is needed with COLMAP"));
        let mut mesh = fresco_core::ply::read_mesh(env("MESH")).unwrap();
        mesh.colors = None;
        (
            mesh,
            fresco_core::colmap::read_model(Path::new(model)).unwrap(),
            env("IMAGES").into(),
            None,
            env("HELD").split(',').map(str::to_string).collect(),
        )
    } else {
        let t = Instant::now();
        write_dataset(&cfg, dir.path(), &NoProgress).unwrap();
        eprintln!("dataset {:.2} s", t.elapsed().as_secs_f64());
        let scene = fresco_datasets::build_scene(&cfg).unwrap();
        let mut mesh = scene.mesh.clone();
        mesh.colors = None;
        (
            mesh,
            fresco_core::colmap::read_model(&dir.path().join("sparse")).unwrap(),
            dir.path().join("images"),
            Some(dir.path().join("masks")),
            vec!["view_0005.png".into(), "view_0017.png".into()],
        )
    };
    let images = ImageSource::Folder(images_dir.clone());
    let config = TextureConfig {
        exclude_images: held.clone(),
        texels_per_pixel: var("TPP").unwrap_or(TextureConfig::default().texels_per_pixel),
        quality_weight: var("QW").unwrap_or(TextureConfig::default().quality_weight),
        outlier_rejection: var("NOOUT").is_none(),
        outlier_sigmas: var("OUTSIG").unwrap_or(TextureConfig::default().outlier_sigmas),
        outlier_min_difference: var("OUTMIN")
            .unwrap_or(TextureConfig::default().outlier_min_difference),
        outlier_window: var("OUTWIN").map_or(TextureConfig::default().outlier_window, |v| v as u32),
        outlier_neighbour_deg: var("OUTNEAR")
            .unwrap_or(TextureConfig::default().outlier_neighbour_deg),
        outlier_patch_fraction: var("OUTPATCH")
            .unwrap_or(TextureConfig::default().outlier_patch_fraction),
        seam_leveling: var("LEVEL").is_some(),
        seam_leveling_smoothness: var("LEVELSMOOTH")
            .unwrap_or(TextureConfig::default().seam_leveling_smoothness),
        seam_strip_texels: var("STRIP").unwrap_or(TextureConfig::default().seam_strip_texels),
        seam_detail_passes: var("DETAIL")
            .map_or(TextureConfig::default().seam_detail_passes, |v| v as u32),
        exposure_gains: var("NOGAIN").is_none(),
        bicubic: var("BILINEAR").is_none(),
        mip_bias: var("MIPBIAS").unwrap_or(TextureConfig::default().mip_bias),
        blend_views: var("NOBLEND").is_none(),
        blend_min_quality: var("BLENDQ").unwrap_or(TextureConfig::default().blend_min_quality),
        blend_tolerance: var("BLENDTOL").unwrap_or(TextureConfig::default().blend_tolerance),
        blend_sigmas: var("BLENDSIGMA").unwrap_or(TextureConfig::default().blend_sigmas),
        blend_fade_texels: var("BLENDFADE").unwrap_or(TextureConfig::default().blend_fade_texels),
        unwrap_stretch_iterations: var("SWEEPS")
            .map_or(TextureConfig::default().unwrap_stretch_iterations, |v| {
                v as u32
            }),
        seam_strip_crease_deg: var("STRIPCREASE")
            .unwrap_or(TextureConfig::default().seam_strip_crease_deg),
        playback_sharpening: var("SHARPEN").unwrap_or(TextureConfig::default().playback_sharpening),
        ..TextureConfig::default()
    };
    let inputs = TextureInputs {
        mesh: &mesh,
        reconstruction: &rec,
        images: &images,
        masks: None,
    };
    let t = Instant::now();
    let cpu0 = cpu_seconds();
    let (mut model, _masks, summary) = texture(&inputs, &config, &NoProgress).unwrap();
    // GLB=<path>: score that textured model (e.g. MeshLab's, on the same scene) instead.
    if let Ok(glb) = std::env::var("GLB") {
        let (mesh, textures) = fresco_core::gltf::read_glb(Path::new(&glb)).unwrap();
        model = TexturedModel { mesh, textures };
    }
    let secs = t.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - cpu0;
    let (vmesh, _) = vertex_colors(&inputs, &config, &NoProgress).unwrap();
    let baseline = TexturedModel {
        mesh: vmesh,
        textures: vec![],
    };
    println!(
        "{} detail {detail}: {} faces, {} charts, seam discrepancy {:.2} (p90 {:.2}) over {:.3} of {:.3}, atlas {} ({} tpu, target {:.1}), coverage {:.4}, outliers {}, misregistration {:.4} texels^2, sharpening {:.4}, {secs:.2} s wall, {cpu:.2} CPU-s, load {} {:?}",
        shape.name(),
        summary.faces,
        summary.charts,
        summary.seams.mean,
        summary.seams.p90,
        summary.seams.seam_length,
        summary.seams.edge_length,
        summary.atlas_size,
        summary.texels_per_unit,
        summary.target_texels_per_unit,
        summary.coverage,
        summary.outlier_texels,
        summary.misregistration_texels2,
        summary.sharpening,
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .split(' ')
            .next()
            .unwrap_or("?"),
        summary.seconds
    );
    for h in &held {
        let h = h.as_str();
        let im = rec.image_by_name(h).unwrap();
        let cam = &rec.cameras[&im.camera_id];
        let photo = image::open(images_dir.join(h)).unwrap().into_rgb8();
        let mask = masks_dir.as_ref().map(|d| {
            image::open(d.join(format!("{h}.png")))
                .unwrap()
                .into_luma8()
        });
        for (name, m) in [("texture", &model), ("vertex", &baseline)] {
            let r = render_textured(m, cam, &im.cam_from_world, cfg.supersample).unwrap();
            let cm = comparison_mask(&r, mask.as_ref());
            let c = compare_to_photo(&r.image, &photo, &cm);
            let cmp_gains = c.gains;
            fn c_gain(c: &usize, g: &[f64; 3]) -> f64 {
                g[*c]
            }
            println!(
                "  {h} {name:8} psnr {:.2} gain-fitted {:.2} ssim {:.4} 1-ncc {:.5} px {}",
                c.psnr, c.psnr_gain, c.ssim_gain, c.one_minus_ncc, c.pixels
            );
            if std::env::var("DIAG").is_ok() {
                diagnose(&r, &photo, &cm, &c.gains, &m.mesh);
            }
            if std::env::var("SAVE").is_ok() && name == "texture" {
                let diff = image::RgbImage::from_fn(photo.width(), photo.height(), |x, y| {
                    let (a, b) = (r.image.get_pixel(x, y), photo.get_pixel(x, y));
                    let k = (y * photo.width() + x) as usize;
                    if !cm[k] {
                        return image::Rgb([0, 0, 60]);
                    }
                    image::Rgb([0, 1, 2].map(|c| {
                        ((a[c] as f64 * c_gain(&c, &cmp_gains) - b[c] as f64).abs() * 6.0)
                            .min(255.0) as u8
                    }))
                });
                diff.save(Path::new("/tmp").join(format!("{}_{h}_diff.png", shape.name())))
                    .unwrap();
            }
            if std::env::var("SAVE").is_ok() {
                r.image
                    .save(Path::new("/tmp").join(format!("{}_{h}_{name}.png", shape.name())))
                    .unwrap();
            }
        }
    }
    if std::env::var("SAVE").is_ok() {
        model.textures[0]
            .save(format!("/tmp/{}_atlas.png", shape.name()))
            .unwrap();
    }
}

/// DIAG=1: splits the gain-fitted squared error of a rendering by cause: low against high
/// spatial frequency (a 9x9 masked box mean of the signed error: exposure and leveling
/// differences are smooth, blur and misregistration are not), pixels on the photo's edges
/// (top 10% of the luma gradient), pixels within 3 pixels of the silhouette, and pixels of
/// faces that touch a chart boundary (seam).
fn diagnose(
    r: &fresco_core::raster::Render,
    photo: &image::RgbImage,
    mask: &[bool],
    gains: &[f64; 3],
    mesh: &fresco_core::Mesh,
) {
    let (w, h) = (photo.width() as usize, photo.height() as usize);
    let d: Vec<[f64; 3]> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as u32, (i / w) as u32);
            let (a, b) = (r.image.get_pixel(x, y), photo.get_pixel(x, y));
            [0, 1, 2].map(|c| (a[c] as f64 * gains[c]).clamp(0.0, 255.0) - b[c] as f64)
        })
        .collect();
    let se = |v: &[f64; 3]| v.iter().map(|x| x * x).sum::<f64>();
    let idx: Vec<usize> = (0..w * h).filter(|&i| mask[i]).collect();
    let total: f64 = idx.iter().map(|&i| se(&d[i])).sum();
    let psnr = |s: f64, n: usize| 10.0 * (255.0f64.powi(2) / (s / (3.0 * n as f64))).log10();
    // Low-frequency part: masked 9x9 mean.
    let rad = 4i64;
    let mut low = 0.0;
    for &i in &idx {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        let (mut s, mut n) = ([0.0; 3], 0.0);
        for yy in (y - rad).max(0)..=(y + rad).min(h as i64 - 1) {
            for xx in (x - rad).max(0)..=(x + rad).min(w as i64 - 1) {
                let j = yy as usize * w + xx as usize;
                if mask[j] {
                    for c in 0..3 {
                        s[c] += d[j][c];
                    }
                    n += 1.0;
                }
            }
        }
        low += se(&s.map(|v| v / n));
    }
    // Photo edges: luma gradient (central differences).
    let luma = |x: usize, y: usize| {
        let p = photo.get_pixel(x as u32, y as u32);
        0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64
    };
    let grad: Vec<f64> = idx
        .iter()
        .map(|&i| {
            let (x, y) = (i % w, i / w);
            let gx = luma((x + 1).min(w - 1), y) - luma(x.saturating_sub(1), y);
            let gy = luma(x, (y + 1).min(h - 1)) - luma(x, y.saturating_sub(1));
            (gx * gx + gy * gy).sqrt()
        })
        .collect();
    let mut sorted = grad.clone();
    sorted.sort_by(f64::total_cmp);
    let cut = sorted[sorted.len() * 9 / 10];
    let edge_se: f64 = idx
        .iter()
        .zip(&grad)
        .filter(|&(_, &g)| g >= cut)
        .map(|(&i, _)| se(&d[i]))
        .sum();
    // Silhouette band.
    let near_sil = |i: usize| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        (-3..=3).any(|dy: i64| {
            (-3..=3).any(|dx: i64| {
                let (xx, yy) = (x + dx, y + dy);
                xx < 0
                    || yy < 0
                    || xx >= w as i64
                    || yy >= h as i64
                    || r.visibility.face_ids[yy as usize * w + xx as usize]
                        == fresco_core::raster::NO_FACE
            })
        })
    };
    let sil: Vec<usize> = idx.iter().copied().filter(|&i| near_sil(i)).collect();
    let sil_se: f64 = sil.iter().map(|&i| se(&d[i])).sum();
    // Pixels within 2 pixels of a seam: a pixel of another chart (charts: faces joined
    // across edges, by position, whose two sides carry the same UVs).
    let nf = mesh.faces.len();
    let mut parent: Vec<usize> = (0..nf).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    if let Some(uvs) = &mesh.corner_uvs {
        let key = |v: u32| {
            let c = mesh.positions[v as usize].coords;
            (c.x.to_bits(), c.y.to_bits(), c.z.to_bits())
        };
        type Side = (usize, [f32; 2], [f32; 2]);
        let mut edges: std::collections::HashMap<_, Vec<Side>> = Default::default();
        for (f, face) in mesh.faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (k, (k + 1) % 3);
                let (ka, kb) = (key(face[a]), key(face[b]));
                let (ua, ub) = (uvs[f][a], uvs[f][b]);
                let (lo, hi, ul, uh) = if ka < kb {
                    (ka, kb, ua, ub)
                } else {
                    (kb, ka, ub, ua)
                };
                edges.entry((lo, hi)).or_default().push((f, ul, uh));
            }
        }
        for list in edges.values() {
            if list.len() == 2 && list[0].1 == list[1].1 && list[0].2 == list[1].2 {
                let (a, b) = (root(&mut parent, list[0].0), root(&mut parent, list[1].0));
                parent[a] = b;
            }
        }
    }
    let chart: Vec<usize> = (0..nf).map(|f| root(&mut parent, f)).collect();
    let chart_at = |i: usize| {
        let f = r.visibility.face_ids[i];
        ((f as usize) < nf).then(|| chart[f as usize])
    };
    let seam: Vec<usize> = idx
        .iter()
        .copied()
        .filter(|&i| {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            let own = chart_at(i);
            (-2..=2).any(|dy: i64| {
                (-2..=2).any(|dx: i64| {
                    let (xx, yy) = (x + dx, y + dy);
                    xx >= 0 && yy >= 0 && xx < w as i64 && yy < h as i64 && {
                        let o = chart_at(yy as usize * w + xx as usize);
                        o.is_some() && o != own
                    }
                })
            })
        })
        .collect();
    let seam_se: f64 = seam.iter().map(|&i| se(&d[i])).sum();
    let n = idx.len();
    println!(
        "    diag: psnr {:.2}; low-frequency {:.1}% of the SE (psnr of the low part alone {:.2}, high part alone {:.2}); photo edges (top 10% gradient) {:.1}%; silhouette band (3 px, {:.1}% of pixels) {:.1}%, psnr without it {:.2}; seam band (2 px, {:.1}% of pixels) {:.1}%, psnr without them {:.2}",
        psnr(total, n),
        100.0 * low / total,
        psnr(low, n),
        psnr(total - low, n),
        100.0 * edge_se / total,
        100.0 * sil.len() as f64 / n as f64,
        100.0 * sil_se / total,
        psnr(total - sil_se, n - sil.len()),
        100.0 * seam.len() as f64 / n as f64,
        100.0 * seam_se / total,
        psnr(total - seam_se, n - seam.len()),
    );
}

/// User + system CPU seconds of this process so far, all threads (Linux /proc; 0 elsewhere).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which ends with ')'): utime and stime are the 12th and
    // 13th, in clock ticks (100 per second on Linux).
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    if f.len() > 12 {
        (f[11] + f[12]) / 100.0
    } else {
        0.0
    }
}
