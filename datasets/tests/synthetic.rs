//! Properties of the synthetic datasets, checked on what `write_dataset` wrote to disk.

use std::fs;
use std::path::Path;

use fresco_core::camera::{Camera, CameraModel};
use fresco_core::nalgebra::{Point3, Quaternion, UnitQuaternion, Vector3};
use fresco_core::raster::{self, RasterConfig, SampleMap};
use fresco_core::{CamFromWorld, NoProgress, Rigid3};
use fresco_datasets::{SceneConfig, Shape, build_scene, write_dataset};

/// Small and fast: 160x120, 6 views.
fn small(shape: Shape, seed: u64) -> SceneConfig {
    SceneConfig {
        shape,
        views: 6,
        width: 160,
        height: 120,
        detail: 1,
        surface_points: 300,
        seed,
        ..SceneConfig::default()
    }
}

/// Reads cameras.txt and images.txt of a COLMAP text model: the camera and (name, pose).
fn read_cameras(sparse: &Path) -> (Camera, Vec<(String, CamFromWorld)>) {
    let cameras = fs::read_to_string(sparse.join("cameras.txt")).unwrap();
    let line = cameras.lines().find(|l| !l.starts_with('#')).unwrap();
    let f: Vec<&str> = line.split_whitespace().collect();
    let model = match f[1] {
        "SIMPLE_PINHOLE" => CameraModel::SimplePinhole,
        "SIMPLE_RADIAL" => CameraModel::SimpleRadial,
        "RADIAL" => CameraModel::Radial,
        other => panic!("unexpected model {other}"),
    };
    let camera = Camera {
        id: f[0].parse().unwrap(),
        model,
        width: f[2].parse().unwrap(),
        height: f[3].parse().unwrap(),
        params: f[4..].iter().map(|v| v.parse().unwrap()).collect(),
    };
    let images = fs::read_to_string(sparse.join("images.txt")).unwrap();
    let lines: Vec<&str> = images.lines().filter(|l| !l.starts_with('#')).collect();
    let poses = lines
        .chunks(2)
        .map(|pair| {
            let f: Vec<&str> = pair[0].split_whitespace().collect();
            let v: Vec<f64> = f[1..8].iter().map(|x| x.parse().unwrap()).collect();
            let rotation = UnitQuaternion::from_quaternion(Quaternion::new(v[0], v[1], v[2], v[3]));
            let pose = CamFromWorld(Rigid3 {
                rotation,
                translation: Vector3::new(v[4], v[5], v[6]),
            });
            (f[9].to_string(), pose)
        })
        .collect();
    (camera, poses)
}

/// Depth and pixel of a world point through the camera model.
fn project(camera: &Camera, pose: &CamFromWorld, p: &Point3<f64>) -> Option<(f64, [f64; 2])> {
    let z = pose.0.transform_point(p).z;
    let pixel = camera.image_from_world(pose, p)?;
    Some((z, [pixel.x, pixel.y]))
}

#[test]
fn synth_torus_writes_images_masks_cameras_and_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("torus");
    let summary = write_dataset(&small(Shape::Torus, 1), &out, &NoProgress).unwrap();
    assert_eq!(summary.views, 6);
    for i in 0..6 {
        let image = image::open(out.join(format!("images/view_{i:04}.png"))).unwrap();
        assert_eq!((image.width(), image.height()), (160, 120));
        let mask = image::open(out.join(format!("masks/view_{i:04}.png.png"))).unwrap();
        assert_eq!((mask.width(), mask.height()), (160, 120));
    }
    for file in [
        "sparse/cameras.txt",
        "sparse/images.txt",
        "sparse/points3D.txt",
        "torus_par.txt",
        "mesh.ply",
        "scene.json",
    ] {
        assert!(out.join(file).is_file(), "{file}");
    }
    // The object fills a good part of each photo (the bounding sphere spans 80% of the
    // half field of view), and at least 50 surface points are seen twice or more.
    assert!(
        summary.mean_mask_fraction > 0.15 && summary.mean_mask_fraction < 0.8,
        "{summary:?}"
    );
    assert!(summary.points3d > 50, "{summary:?}");
    // No temporary files are left behind.
    for sub in ["", "images", "masks", "sparse"] {
        for entry in fs::read_dir(out.join(sub)).unwrap() {
            let name = entry.unwrap().file_name().into_string().unwrap();
            assert!(!name.ends_with(".tmp"), "{name}");
        }
    }
}

#[test]
fn visible_mesh_vertices_reproject_inside_the_masks() {
    // Every ground-truth vertex that the written cameras see (by a depth buffer rendered
    // independently here, at pixel centres) must project into the written object mask. A
    // vertex on the silhouette may project into a pixel whose centre just misses the object,
    // so the 3x3 neighbourhood counts. At 160x120 about a tenth of the visible vertices lie
    // within a pixel of the silhouette; the others must hit their own pixel: at least 80%.
    for (shape, layout) in [
        (Shape::Torus, fresco_datasets::Layout::Ring),
        (Shape::Temple, fresco_datasets::Layout::Hemisphere),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join(shape.name());
        let config = SceneConfig {
            layout,
            distortion: fresco_datasets::Distortion::Radial {
                k1: -0.05,
                k2: 0.01,
            },
            ..small(shape, 5)
        };
        write_dataset(&config, &out, &NoProgress).unwrap();
        let mesh = fresco_core::ply::read_mesh(out.join("mesh.ply")).unwrap();
        // The written mesh is the generator's, with its albedo colours.
        let scene = build_scene(&config).unwrap();
        assert_eq!(mesh.positions, scene.mesh.positions);
        assert_eq!(mesh.faces, scene.mesh.faces);
        assert_eq!(mesh.colors, scene.mesh.colors);
        let (camera, poses) = read_cameras(&out.join("sparse"));
        let map = SampleMap::new(&camera, 1).unwrap();
        let (mut checked, mut exact) = (0, 0);
        for (name, pose) in &poses {
            let mask = image::open(out.join(format!("masks/{name}.png")))
                .unwrap()
                .to_luma8();
            let vis = raster::visibility(&mesh, &map, pose, &RasterConfig::default()).unwrap();
            for p in &mesh.positions {
                let Some((z, [u, v])) = project(&camera, pose, p) else {
                    continue;
                };
                if !(0.0..160.0).contains(&u) || !(0.0..120.0).contains(&v) {
                    continue;
                }
                let (x, y) = (u as u32, v as u32);
                // Visible: nothing nearer at its pixel than its own depth, up to the depth
                // change across one pixel on a surface inclined by up to ~80 degrees.
                let tolerance = 6.0 * z / camera.params[0];
                if (vis.depth_at(x, y) as f64) < z - tolerance {
                    continue;
                }
                checked += 1;
                let hit = |x: i64, y: i64| {
                    x >= 0
                        && y >= 0
                        && x < 160
                        && y < 120
                        && mask.get_pixel(x as u32, y as u32)[0] == 255
                };
                exact += hit(x as i64, y as i64) as usize;
                let near = (-1..=1).any(|dy| (-1..=1).any(|dx| hit(x as i64 + dx, y as i64 + dy)));
                assert!(
                    near,
                    "{}: {name}: vertex {p} at ({u}, {v}) is outside the mask",
                    shape.name()
                );
            }
        }
        assert!(
            checked > 200,
            "{}: {checked} visible vertices",
            shape.name()
        );
        assert!(
            exact as f64 >= 0.8 * checked as f64,
            "{}: {exact} of {checked}",
            shape.name()
        );
    }
}

#[test]
fn the_dataset_is_deterministic_from_the_seed() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        dir.path().join("a"),
        dir.path().join("b"),
        dir.path().join("c"),
    );
    let config = SceneConfig {
        backdrop: true,
        ..small(Shape::Blob, 9)
    };
    write_dataset(&config, &a, &NoProgress).unwrap();
    // A different thread count must not change a bit.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| write_dataset(&config, &b, &NoProgress))
        .unwrap();
    write_dataset(
        &SceneConfig {
            seed: 10,
            ..config.clone()
        },
        &c,
        &NoProgress,
    )
    .unwrap();
    let files = |root: &Path| {
        let mut out = Vec::new();
        for sub in ["", "images", "masks", "sparse"] {
            for entry in fs::read_dir(root.join(sub)).unwrap() {
                let path = entry.unwrap().path();
                if path.is_file() {
                    out.push(path.strip_prefix(root).unwrap().to_path_buf());
                }
            }
        }
        out.sort();
        out
    };
    assert_eq!(files(&a), files(&b));
    for f in files(&a) {
        assert_eq!(
            fs::read(a.join(&f)).unwrap(),
            fs::read(b.join(&f)).unwrap(),
            "{f:?}"
        );
    }
    // Another seed changes the photos.
    assert_ne!(
        fs::read(a.join("images/view_0000.png")).unwrap(),
        fs::read(c.join("images/view_0000.png")).unwrap()
    );
}
