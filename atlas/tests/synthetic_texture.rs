//! Texture reconstruction on synthetic scenes with exact ground truth (issue 14): held-out
//! PSNR against the per-vertex colour baseline, exposure differences, a painted highlight,
//! determinism, and bad input. The scenes are 24 views on a ring with the generator's
//! exposure differences; views 5 and 17 are held out and the texture is made from the other
//! 22 with the ground-truth mesh and cameras. CI runs them at 320x240; the 640x480 figures
//! of the issue are the ignored tests at the end (bench/texture.sh runs them).

use std::path::{Path, PathBuf};

use fresco_atlas::{
    ImageSource, TextureConfig, TextureError, TextureInputs, TexturedModel, compare_to_photo,
    comparison_mask, render_textured, texture, vertex_colors,
};
use fresco_core::{Mesh, NoProgress, Reconstruction};
use fresco_datasets::{SceneConfig, Shape, build_scene, write_dataset};

const HELD_OUT: [&str; 2] = ["view_0005.png", "view_0017.png"];

struct Dataset {
    dir: tempfile::TempDir,
    mesh: Mesh,
    rec: Reconstruction,
    config: SceneConfig,
}

impl Dataset {
    fn new(config: SceneConfig) -> Dataset {
        let dir = tempfile::tempdir().unwrap();
        write_dataset(&config, dir.path(), &NoProgress).unwrap();
        let mut mesh = build_scene(&config).unwrap().mesh;
        mesh.colors = None;
        let rec = fresco_core::colmap::read_model(&dir.path().join("sparse")).unwrap();
        Dataset {
            dir,
            mesh,
            rec,
            config,
        }
    }
    fn images(&self) -> PathBuf {
        self.dir.path().join("images")
    }
    fn held_out_config(&self) -> TextureConfig {
        TextureConfig {
            exclude_images: HELD_OUT.iter().map(|s| s.to_string()).collect(),
            ..TextureConfig::default()
        }
    }
    /// Gain-fitted PSNR of `model` in each held-out view.
    fn held_out_psnr(&self, model: &TexturedModel) -> Vec<f64> {
        HELD_OUT
            .iter()
            .map(|name| {
                let im = self.rec.image_by_name(name).unwrap();
                let cam = &self.rec.cameras[&im.camera_id];
                let photo = image::open(self.images().join(name)).unwrap().into_rgb8();
                let mask = image::open(self.dir.path().join("masks").join(format!("{name}.png")))
                    .unwrap()
                    .into_luma8();
                let r = render_textured(model, cam, &im.cam_from_world, self.config.supersample)
                    .unwrap();
                let m = comparison_mask(&r, Some(&mask));
                let c = compare_to_photo(&r.image, &photo, &m);
                assert!(c.pixels > 1000, "{name}: {} pixels compared", c.pixels);
                c.psnr_gain
            })
            .collect()
    }
}

fn scene(shape: Shape, detail: u32, width: u32, height: u32) -> SceneConfig {
    SceneConfig {
        shape,
        detail,
        width,
        height,
        ..SceneConfig::default()
    }
}

/// Texture and vertex-colour held-out PSNRs of one scene.
fn texture_and_baseline(d: &Dataset, config: &TextureConfig) -> (Vec<f64>, Vec<f64>) {
    let images = ImageSource::Folder(d.images());
    let inputs = TextureInputs {
        mesh: &d.mesh,
        reconstruction: &d.rec,
        images: &images,
        masks: None,
    };
    let (model, _, summary) = texture(&inputs, config, &NoProgress).unwrap();
    assert_eq!(summary.views_used, 22);
    assert_eq!(summary.atlases, 1);
    let (coloured, _) = vertex_colors(&inputs, config, &NoProgress).unwrap();
    let baseline = TexturedModel {
        mesh: coloured,
        textures: vec![],
    };
    (d.held_out_psnr(&model), d.held_out_psnr(&baseline))
}

fn assert_floor_and_gain(name: &str, tex: &[f64], base: &[f64], floor: f64, gain: f64) {
    for (k, (t, b)) in tex.iter().zip(base).enumerate() {
        assert!(
            *t >= floor && *t >= b + gain,
            "{name} {}: texture {t:.2} dB, vertex colours {b:.2} dB (floor {floor}, gain {gain})",
            HELD_OUT[k]
        );
    }
}

// Floors at 320x240, about 1 dB under what was measured (torus 30.8-31.2, temple 28.4-29.0,
// blob 30.6-31.0 dB; bench/RESULTS.md, issue 14).

#[test]
fn torus_held_out_psnr_beats_vertex_colours() {
    let d = Dataset::new(scene(Shape::Torus, 2, 320, 240));
    let (tex, base) = texture_and_baseline(&d, &d.held_out_config());
    assert_floor_and_gain("torus", &tex, &base, 29.8, 3.0);
}

#[test]
fn temple_held_out_psnr_beats_vertex_colours() {
    let d = Dataset::new(scene(Shape::Temple, 2, 320, 240));
    let (tex, base) = texture_and_baseline(&d, &d.held_out_config());
    assert_floor_and_gain("temple", &tex, &base, 27.4, 3.0);
}

#[test]
fn blob_held_out_psnr_beats_vertex_colours() {
    let d = Dataset::new(scene(Shape::Blob, 2, 320, 240));
    let (tex, base) = texture_and_baseline(&d, &d.held_out_config());
    assert_floor_and_gain("blob", &tex, &base, 29.5, 3.0);
}

#[test]
fn exposure_jitter_of_30_percent_costs_under_1_db() {
    let mild = Dataset::new(scene(Shape::Torus, 2, 320, 240));
    let strong = Dataset::new(SceneConfig {
        exposure_jitter: 0.3,
        ..scene(Shape::Torus, 2, 320, 240)
    });
    let (a, _) = texture_and_baseline(&mild, &mild.held_out_config());
    let (b, _) = texture_and_baseline(&strong, &strong.held_out_config());
    for k in 0..2 {
        assert!(
            b[k] > a[k] - 1.0,
            "{}: {:.2} dB at +-8% exposure, {:.2} dB at +-30%",
            HELD_OUT[k],
            a[k],
            b[k]
        );
    }
}

/// Copies the dataset's photos to `dst`, painting a disc into `view` at `centre`, each pixel
/// coloured by `paint(x, y)`.
fn copy_with_disc(
    src: &Path,
    dst: &Path,
    view: &str,
    centre: (f64, f64),
    radius: f64,
    paint: impl Fn(u32, u32) -> [u8; 3],
) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        let name = e.file_name().to_string_lossy().into_owned();
        let mut img = image::open(e.path()).unwrap().into_rgb8();
        if name == view {
            for (x, y, p) in img.enumerate_pixels_mut() {
                let (dx, dy) = (x as f64 + 0.5 - centre.0, y as f64 + 0.5 - centre.1);
                if dx * dx + dy * dy <= radius * radius {
                    *p = image::Rgb(paint(x, y));
                }
            }
        }
        img.save(dst.join(&name)).unwrap();
    }
}

/// What a disc painted into one view left in the texture, seen from that view inside the
/// disc, against the texture made from the clean photos (the same UVs and atlas): the mean
/// absolute difference (max over channels, /255) and the percentiles 1 and 99 and the mean
/// of the signed change towards the paint (`sign` +1 for a bright paint, -1 for a dark one;
/// mean over channels, /255).
struct Trace {
    mean_abs: f64,
    toward_p1: i32,
    toward_p99: i32,
    toward_mean: f64,
}

fn trace_of_painted_disc(
    view: &str,
    (cx, cy, r): (f64, f64, f64),
    sign: i32,
    paint: impl Fn(u32, u32) -> [u8; 3],
) -> Trace {
    let d = Dataset::new(scene(Shape::Torus, 2, 320, 240));
    let images = ImageSource::Folder(d.images());
    // The fused colour, before the playback sharpening: that filter is the same linear
    // function of the texels in both runs, so it adds no trace, but it scales the symmetric
    // differences between two blends of the other views by up to 1 + 8a (a ~ 0.3 here).
    let config = TextureConfig {
        playback_sharpening: 0.0,
        ..TextureConfig::default()
    };
    let inputs = TextureInputs {
        mesh: &d.mesh,
        reconstruction: &d.rec,
        images: &images,
        masks: None,
    };
    let (clean, _, _) = texture(&inputs, &config, &NoProgress).unwrap();
    let painted_dir = d.dir.path().join("painted");
    copy_with_disc(&d.images(), &painted_dir, view, (cx, cy), r, paint);
    let painted_images = ImageSource::Folder(painted_dir);
    let inputs = TextureInputs {
        mesh: &clean.mesh,
        reconstruction: &d.rec,
        images: &painted_images,
        masks: None,
    };
    let (painted, _, summary) = texture(&inputs, &config, &NoProgress).unwrap();
    assert!(summary.outlier_texels > 0);
    let im = d.rec.image_by_name(view).unwrap();
    let cam = &d.rec.cameras[&im.camera_id];
    let a = render_textured(&clean, cam, &im.cam_from_world, 1).unwrap();
    let b = render_textured(&painted, cam, &im.cam_from_world, 1).unwrap();
    let (mut diffs, mut toward) = (Vec::new(), Vec::new());
    for y in 0..cam.height {
        for x in 0..cam.width {
            let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
            if dx * dx + dy * dy <= r * r && a.visibility.face_at(x, y) != u32::MAX {
                let (p, q) = (a.image.get_pixel(x, y), b.image.get_pixel(x, y));
                let d = (0..3)
                    .map(|c| (p[c] as i32 - q[c] as i32).abs())
                    .max()
                    .unwrap();
                diffs.push(d);
                toward.push(sign * (0..3).map(|c| q[c] as i32 - p[c] as i32).sum::<i32>() / 3);
            }
        }
    }
    assert!(
        diffs.len() > 300,
        "the disc covers the object ({} px)",
        diffs.len()
    );
    toward.sort();
    Trace {
        mean_abs: diffs.iter().sum::<i32>() as f64 / diffs.len() as f64,
        toward_p1: toward[toward.len() / 100],
        toward_p99: toward[toward.len() * 99 / 100],
        toward_mean: toward.iter().sum::<i32>() as f64 / toward.len() as f64,
    }
}

/// The line: the fused colour where a painted highlight or occluder was is within
/// 3/255 of the other views' (mean absolute difference), with no trace of the paint: the
/// change towards it averages under 1/255 and its 99th percentile stays under 10/255 (the
/// level of the symmetric view-change differences before views were blended: 1st / 99th
/// percentiles -10 / +10; the blend averages them away in both directions).
fn assert_no_trace(what: &str, t: &Trace) {
    assert!(
        t.mean_abs <= 3.0 && t.toward_p99 <= 10 && t.toward_mean <= 1.0,
        "inside the {what}: mean difference {:.2}/255, change towards the paint: mean {:.2}, 1st percentile {}, 99th {} (/255)",
        t.mean_abs,
        t.toward_mean,
        t.toward_p1,
        t.toward_p99
    );
}

#[test]
fn a_highlight_painted_into_one_view_leaves_no_trace() {
    // A saturated disc, more than 100/255 brighter than the surface.
    let t = trace_of_painted_disc("view_0003.png", (160.0, 125.0, 14.0), 1, |_, _| {
        [255, 250, 235]
    });
    assert_no_trace("highlight", &t);
}

#[test]
fn an_occluder_painted_into_one_view_leaves_no_trace() {
    // A dark, striped object in front of the surface (its own detail, so that it is not a
    // flat colour a gain could explain), larger than the highlight.
    let t = trace_of_painted_disc("view_0010.png", (160.0, 120.0, 20.0), -1, |x, y| {
        if (x + y) / 3 % 2 == 0 {
            [20, 60, 25]
        } else {
            [70, 35, 30]
        }
    });
    assert_no_trace("occluder", &t);
}

#[test]
fn same_inputs_give_the_same_atlas_whatever_the_thread_count() {
    let d = Dataset::new(SceneConfig {
        views: 8,
        ..scene(Shape::Blob, 1, 200, 150)
    });
    let images = ImageSource::Folder(d.images());
    let inputs = TextureInputs {
        mesh: &d.mesh,
        reconstruction: &d.rec,
        images: &images,
        masks: None,
    };
    let config = TextureConfig::default();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| texture(&inputs, &config, &NoProgress).unwrap())
    };
    let (a, ma, _) = run(1);
    let (b, mb, _) = run(3);
    assert_eq!(a.mesh.corner_uvs, b.mesh.corner_uvs);
    assert!(
        a.textures == b.textures,
        "atlases differ between 1 and 3 threads"
    );
    assert_eq!(ma, mb);
}

#[test]
fn a_missing_photo_is_skipped_with_a_warning_and_the_rest_used() {
    let d = Dataset::new(SceneConfig {
        views: 8,
        ..scene(Shape::Sphere, 0, 200, 150)
    });
    std::fs::remove_file(d.images().join("view_0002.png")).unwrap();
    std::fs::write(d.images().join("view_0004.png"), b"not a png").unwrap();
    let images = ImageSource::Folder(d.images());
    let inputs = TextureInputs {
        mesh: &d.mesh,
        reconstruction: &d.rec,
        images: &images,
        masks: None,
    };
    let (_, _, s) = texture(&inputs, &TextureConfig::default(), &NoProgress).unwrap();
    assert_eq!((s.views_used, s.views_skipped), (6, 2));
    assert!(
        s.warnings.iter().any(|w| w.contains("view_0002.png")),
        "{:?}",
        s.warnings
    );
    assert!(
        s.warnings.iter().any(|w| w.contains("view_0004.png")),
        "{:?}",
        s.warnings
    );
    assert!(
        s.unwrapped
            && s.warnings
                .iter()
                .any(|w| w.contains("no texture coordinates"))
    );
}

#[test]
fn cameras_that_see_nothing_of_the_mesh_are_a_clear_error() {
    let d = Dataset::new(SceneConfig {
        views: 4,
        ..scene(Shape::Sphere, 0, 160, 120)
    });
    let mut far = d.mesh.clone();
    for p in &mut far.positions {
        p.z += 1000.0;
    }
    let images = ImageSource::Folder(d.images());
    let inputs = TextureInputs {
        mesh: &far,
        reconstruction: &d.rec,
        images: &images,
        masks: None,
    };
    let e = texture(&inputs, &TextureConfig::default(), &NoProgress).unwrap_err();
    assert!(matches!(e, TextureError::NothingSeen { views: 4 }), "{e}");
    assert!(e.to_string().contains("see nothing"));
}

#[test]
fn an_atlas_too_small_for_the_photos_lowers_the_density_with_a_warning() {
    let d = Dataset::new(SceneConfig {
        views: 8,
        ..scene(Shape::Sphere, 1, 320, 240)
    });
    let images = ImageSource::Folder(d.images());
    let inputs = TextureInputs {
        mesh: &d.mesh,
        reconstruction: &d.rec,
        images: &images,
        masks: None,
    };
    let config = TextureConfig {
        max_atlas_size: 128,
        ..TextureConfig::default()
    };
    let (model, _, s) = texture(&inputs, &config, &NoProgress).unwrap();
    assert_eq!((s.atlases, s.atlas_size), (1, 128));
    assert_eq!(model.textures.len(), 1);
    assert!(s.texels_per_unit < s.target_texels_per_unit);
    assert!(
        s.warnings.iter().any(|w| w.contains("density reduced")),
        "{:?}",
        s.warnings
    );
}

// The figures: 640x480, default detail (torus 4 is the 147k-face case).

#[test]
#[ignore = "heavy: bench/texture.sh runs it"]
fn full_size_held_out_psnr_floor_and_gain_over_vertex_colours() {
    for (shape, detail) in [
        (Shape::Torus, 2),
        (Shape::Temple, 2),
        (Shape::Blob, 2),
        (Shape::Torus, 4),
    ] {
        let d = Dataset::new(scene(shape, detail, 640, 480));
        let (tex, base) = texture_and_baseline(&d, &d.held_out_config());
        println!(
            "{} detail {detail}: texture {tex:.2?} dB, vertex colours {base:.2?} dB",
            shape.name()
        );
        assert_floor_and_gain(shape.name(), &tex, &base, 34.0, 3.0);
    }
}
