//! Writes the seed corpora of the fuzz targets into `fuzz/seeds/<target>/`: the readers' test
//! fixtures and bundled data, cut small, and files written by fresco's own writers (every
//! format, attribute and option they produce). Deterministic: rerunning gives the same bytes.
//!
//!   cd fuzz && cargo +nightly run --example make_seeds
use std::fs;
use std::path::{Path, PathBuf};

use fresco_core::NoProgress;
use fresco_core::mesh::Mesh;
use fresco_core::nalgebra::{Point2, Point3, UnitQuaternion, Vector3};
use fresco_core::ply::{PlyFormat, write_mesh};
use fresco_core::{
    CamFromWorld, Camera, CameraModel, Image, Point3D, Reconstruction, Rigid3, TrackElement,
};
use fresco_fuzz::FILE_SEPARATOR;
use fresco_pst::{CreateConfig, MemoryPoints, Pst};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn repo(rel: &str) -> PathBuf {
    Path::new(ROOT).join("..").join(rel)
}

fn seeds(target: &str) -> PathBuf {
    let d = Path::new(ROOT).join("seeds").join(target);
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

fn join(parts: &[&[u8]]) -> Vec<u8> {
    let mut out = Vec::new();
    for (k, p) in parts.iter().enumerate() {
        if k > 0 {
            out.extend_from_slice(FILE_SEPARATOR);
        }
        out.extend_from_slice(p);
    }
    out
}

/// A tetrahedron with normals, colours, corner UVs, groups and textures.
fn tetra(attributes: bool) -> Mesh {
    let mut m = Mesh {
        positions: vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
        ],
        faces: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        ..Mesh::default()
    };
    if attributes {
        m.normals = Some(
            m.positions
                .iter()
                .map(|p| (p.coords - Vector3::repeat(0.25)).normalize())
                .collect(),
        );
        m.colors = Some(vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]]);
        m.corner_uvs = Some(
            (0..4)
                .map(|f| {
                    let u = f as f32 * 0.25;
                    [[u, 0.0], [u + 0.2, 0.0], [u, 0.5]]
                })
                .collect(),
        );
        m.face_groups = Some(vec![0, 0, 1, 1]);
        m.face_textures = Some(vec![0, 0, 0, 0]);
    }
    m
}

fn tiny_image() -> image::RgbImage {
    image::ImageBuffer::from_fn(4, 4, |x, y| {
        image::Rgb([(x * 60) as u8, (y * 60) as u8, 90])
    })
}

fn png(img: image::DynamicImage) -> Vec<u8> {
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

fn jpeg(img: image::DynamicImage) -> Vec<u8> {
    let mut out = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut out),
        image::ImageFormat::Jpeg,
    )
    .unwrap();
    out
}

/// The APP1 (EXIF) segment of a JPEG, marker included.
fn exif_segment(jpeg: &[u8]) -> Option<Vec<u8>> {
    let mut i = 2;
    while i + 4 <= jpeg.len() && jpeg[i] == 0xFF {
        let marker = jpeg[i + 1];
        let len = u16::from_be_bytes([jpeg[i + 2], jpeg[i + 3]]) as usize;
        if marker == 0xE1 {
            return Some(jpeg[i..i + 2 + len].to_vec());
        }
        i += 2 + len;
    }
    None
}

fn ply(tmp: &Path) {
    let out = seeds("ply_bytes");
    let points = seeds("pst_ply_points");
    for entry in fs::read_dir(repo("core/tests/data")).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "ply") {
            let name = p.file_name().unwrap();
            fs::copy(&p, out.join(name)).unwrap();
            fs::copy(&p, points.join(name)).unwrap();
        }
    }
    for (name, format) in [
        ("ascii", PlyFormat::Ascii),
        ("le", PlyFormat::BinaryLittleEndian),
        ("be", PlyFormat::BinaryBigEndian),
    ] {
        for attributes in [false, true] {
            let f = tmp.join("t.ply");
            write_mesh(&f, &tetra(attributes), format).unwrap();
            let seed = format!(
                "fresco_{name}_{}.ply",
                if attributes { "attributes" } else { "plain" }
            );
            fs::copy(&f, out.join(&seed)).unwrap();
            fs::copy(&f, points.join(&seed)).unwrap();
        }
    }
}

fn obj(tmp: &Path) {
    let out = seeds("obj");
    let t = png(image::DynamicImage::ImageRgb8(tiny_image()));
    for (dir, obj, mtl) in [
        ("trimesh_obj", "square.obj", "material.mtl"),
        ("open3d_obj", "square.obj", "square.mtl"),
    ] {
        let d = repo("core/tests/data").join(dir);
        let o = fs::read_to_string(d.join(obj))
            .unwrap()
            .replace(mtl, "m.mtl");
        let m = fs::read_to_string(d.join(mtl)).unwrap();
        let m = m
            .lines()
            .map(|l| {
                if l.trim_start().starts_with("map_Kd") {
                    "map_Kd t.png"
                } else {
                    l
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        fs::write(
            out.join(format!("{dir}.bin")),
            join(&[o.as_bytes(), m.as_bytes(), &t]),
        )
        .unwrap();
    }
    let f = tmp.join("m.obj");
    fresco_core::obj::write_obj(&f, &tetra(true), &["t.png"]).unwrap();
    let o = fs::read(&f).unwrap();
    let m = fs::read(tmp.join("m.mtl")).unwrap();
    fs::write(out.join("fresco_textured.bin"), join(&[&o, &m, &t])).unwrap();
    let mut plain = tetra(false);
    plain.colors = Some(vec![[10, 20, 30]; 4]);
    fresco_core::obj::write_obj(&f, &plain, &[]).unwrap();
    fs::write(out.join("fresco_colours.bin"), fs::read(&f).unwrap()).unwrap();
    // Polygons, negative indices, groups, normals.
    let text = "mtllib m.mtl\no a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\ng b\nusemtl x\nf 1/1/1 2/2/1 3/3/1 4/1/1\nf -4 -3 -2\n";
    fs::write(
        out.join("polygons.bin"),
        join(&[text.as_bytes(), b"newmtl x\nKd 1 0 0\nmap_Kd t.png\n", &t]),
    )
    .unwrap();
}

fn colmap() {
    let txt = seeds("colmap_text");
    let bin = seeds("colmap_binary");
    for model in ["colmap_tiny", "colmap_rig"] {
        for (out, kind, ext) in [(&txt, "text", "txt"), (&bin, "binary", "bin")] {
            let d = repo("core/tests/data").join(model).join(kind);
            let read = |n: &str| fs::read(d.join(format!("{n}.{ext}"))).ok();
            let files: Vec<Vec<u8>> = ["cameras", "images", "points3D", "rigs", "frames"]
                .iter()
                .filter_map(|n| read(n))
                .collect();
            let parts: Vec<&[u8]> = files.iter().map(|f| f.as_slice()).collect();
            fs::write(out.join(format!("{model}.{ext}")), join(&parts)).unwrap();
        }
    }
    // A model with every camera model, written by fresco.
    let mut rec = Reconstruction::default();
    let models = [
        (CameraModel::SimplePinhole, vec![500.0, 320.0, 240.0]),
        (CameraModel::Pinhole, vec![500.0, 510.0, 320.0, 240.0]),
        (CameraModel::SimpleRadial, vec![500.0, 320.0, 240.0, 0.01]),
        (CameraModel::Radial, vec![500.0, 320.0, 240.0, 0.01, -0.001]),
        (
            CameraModel::OpenCv,
            vec![500.0, 510.0, 320.0, 240.0, 0.01, -0.001, 0.0001, 0.0002],
        ),
    ];
    for (k, (model, params)) in models.into_iter().enumerate() {
        let id = k as u32 + 1;
        rec.cameras
            .insert(id, Camera::new(id, model, 640, 480, params).unwrap());
        rec.images.insert(
            id,
            Image {
                id,
                name: format!("im {id}.png"),
                camera_id: id,
                cam_from_world: CamFromWorld(Rigid3::new(
                    UnitQuaternion::from_euler_angles(0.1 * k as f64, 0.2, 0.0),
                    Vector3::new(0.0, 0.0, 4.0),
                )),
                keypoints: vec![Point2::new(10.5, 20.25), Point2::new(300.0, 200.0)],
                point3d_ids: vec![Some(7), None],
            },
        );
    }
    rec.points3d.insert(
        7,
        Point3D {
            id: 7,
            position: Point3::new(0.1, 0.2, 0.3),
            color: [1, 2, 3],
            error: 0.5,
            track: (1..=5)
                .map(|image_id| TrackElement {
                    image_id,
                    point2d_idx: 0,
                })
                .collect(),
        },
    );
    let tmp = tempdir("colmap");
    for (out, format, ext) in [
        (&txt, fresco_core::colmap::ModelFormat::Text, "txt"),
        (&bin, fresco_core::colmap::ModelFormat::Binary, "bin"),
    ] {
        fresco_core::colmap::write_model(&rec, &tmp, format).unwrap();
        let files: Vec<Vec<u8>> = ["cameras", "images", "points3D", "rigs", "frames"]
            .iter()
            .map(|n| fs::read(tmp.join(format!("{n}.{ext}"))).unwrap())
            .collect();
        let parts: Vec<&[u8]> = files.iter().map(|f| f.as_slice()).collect();
        fs::write(out.join(format!("fresco_models.{ext}")), join(&parts)).unwrap();
        fs::write(out.join(format!("fresco_no_rigs.{ext}")), join(&parts[..3])).unwrap();
    }
}

fn middlebury() {
    let out = seeds("middlebury");
    let text = fs::read_to_string(repo("core/tests/data/middlebury_templeSR_par.txt")).unwrap();
    let mut size = Vec::new();
    size.extend_from_slice(&640u16.to_le_bytes());
    size.extend_from_slice(&480u16.to_le_bytes());
    let mut whole = size.clone();
    whole.extend_from_slice(text.as_bytes());
    fs::write(out.join("templeSR_par.txt"), &whole).unwrap();
    // Two views only.
    let lines: Vec<&str> = text.lines().collect();
    let mut two = size;
    two.extend_from_slice(format!("2\n{}\n{}\n", lines[1], lines[2]).as_bytes());
    fs::write(out.join("two_views.txt"), two).unwrap();
}

fn photo() {
    let out = seeds("photo");
    let rgb = tiny_image();
    let dy = image::DynamicImage::ImageRgb8(rgb.clone());
    fs::write(out.join("rgb8.png"), png(dy.clone())).unwrap();
    fs::write(
        out.join("rgba8.png"),
        png(image::DynamicImage::ImageRgba8(dy.to_rgba8())),
    )
    .unwrap();
    fs::write(
        out.join("l8.png"),
        png(image::DynamicImage::ImageLuma8(dy.to_luma8())),
    )
    .unwrap();
    fs::write(
        out.join("l16.png"),
        png(image::DynamicImage::ImageLuma16(dy.to_luma16())),
    )
    .unwrap();
    fs::write(
        out.join("la8.png"),
        png(image::DynamicImage::ImageLumaA8(dy.to_luma_alpha8())),
    )
    .unwrap();
    fs::write(
        out.join("rgb16.png"),
        png(image::DynamicImage::ImageRgb16(dy.to_rgb16())),
    )
    .unwrap();
    let j = jpeg(dy.clone());
    fs::write(out.join("rgb.jpg"), &j).unwrap();
    fs::write(
        out.join("grey.jpg"),
        jpeg(image::DynamicImage::ImageLuma8(dy.to_luma8())),
    )
    .unwrap();
    // The EXIF block of a real camera (sceaux_castle) in a tiny JPEG: make, model, focal lengths.
    let camera = fs::read(repo("datasets/sceaux_castle/images/100_7100.JPG")).unwrap();
    if let Some(app1) = exif_segment(&camera) {
        let mut with = j[..2].to_vec();
        with.extend_from_slice(&app1);
        with.extend_from_slice(&j[2..]);
        fs::write(out.join("exif.jpg"), with).unwrap();
        fs::write(out.join("exif_block.bin"), &app1[10..]).unwrap();
    }
}

fn glb() {
    for target in ["glb", "core_glb"] {
        glb_into(&seeds(target));
    }
}

/// GLBs written by fresco's writer: textured, plain, vertex-coloured.
fn glb_into(out: &Path) {
    fs::write(
        out.join("textured.glb"),
        fresco_core::gltf::encode_glb(&tetra(true), &[tiny_image()]).unwrap(),
    )
    .unwrap();
    fs::write(
        out.join("plain.glb"),
        fresco_core::gltf::encode_glb(&tetra(false), &[]).unwrap(),
    )
    .unwrap();
    let mut coloured = tetra(false);
    coloured.colors = Some(vec![[200, 10, 10]; 4]);
    fs::write(
        out.join("colours.glb"),
        fresco_core::gltf::encode_glb(&coloured, &[]).unwrap(),
    )
    .unwrap();
}

fn sfm_files() {
    use fresco_sfm::features::feature_file::{Features, Keypoint, encode_features};
    use fresco_sfm::matching::match_file::encode_matches;
    use fresco_sfm::geometry::two_view::{PairKind, TwoViewGeometry, VerifiedPair};
    let out = seeds("feature_file");
    let mut f = Features {
        width: 640,
        height: 480,
        root_sift: true,
        ..Features::default()
    };
    for i in 0..3 {
        f.keypoints.push(Keypoint {
            x: 10.0 * i as f32,
            y: 5.5,
            scale: 1.6,
            orientation: 0.5,
        });
        f.descriptors.push([i as u8 * 40; 128]);
    }
    fs::write(out.join("three.sift"), encode_features(&f)).unwrap();
    fs::write(
        out.join("empty.sift"),
        encode_features(&Features::default()),
    )
    .unwrap();

    let out = seeds("match_file");
    let m =
        fresco_core::nalgebra::Matrix3::new(0.0, -1e-4, 0.02, 1e-4, 0.0, -0.03, -0.02, 0.03, 1.0);
    let pairs = vec![
        VerifiedPair {
            image1: 1,
            image2: 2,
            num_matches: 40,
            geometry: TwoViewGeometry {
                kind: PairKind::Calibrated,
                fundamental: Some(m),
                essential: Some(m),
                homography: None,
                cam2_from_cam1: Some(Rigid3::new(
                    UnitQuaternion::from_euler_angles(0.0, 0.1, 0.0),
                    Vector3::new(1.0, 0.0, 0.0),
                )),
                inliers: vec![[0, 1], [2, 3], [4, 5]],
            },
        },
        VerifiedPair {
            image1: 2,
            image2: 3,
            num_matches: 5,
            geometry: TwoViewGeometry::degenerate(),
        },
    ];
    fs::write(out.join("two_pairs.bin"), encode_matches(&pairs)).unwrap();
    fs::write(out.join("none.bin"), encode_matches(&[])).unwrap();

    let out = seeds("sfm_workspace");
    let k = fs::read(repo("datasets/sceaux_castle/images/K.txt")).unwrap();
    let images = r#"{
  "version": 1,
  "images": [
    {
      "id": 1,
      "name": "a.jpg",
      "path": "photos/a.jpg",
      "width": 1600,
      "height": 1200,
      "num_keypoints": 3,
      "prior": { "focal_x": 1920.0, "focal_y": 1920.0, "cx": 800.0, "cy": 600.0, "source": "exif35mm" },
      "exif_orientation": 1,
      "camera_make": "Canon",
      "camera_model": "EOS 5D"
    }
  ]
}"#;
    fs::write(out.join("workspace.bin"), join(&[images.as_bytes(), &k])).unwrap();
    fs::write(
        out.join("k_commas.bin"),
        join(&[b"{}", b"1000, 0, 800\n0, 1000, 600\n0, 0, 1\n"]),
    )
    .unwrap();
}

/// Depth, normal and cost maps of a 5x4 view as the dense stage writes them, and a `.vis`.
fn dense(tmp: &Path) {
    use fresco_surface::dense::DepthMap;
    use fresco_surface::dense::depth_map_file::write_depth_map;
    let out = seeds("dense_maps");
    let (w, h) = (5, 4);
    let map = DepthMap {
        width: w,
        height: h,
        depth: (0..w * h)
            .map(|i| {
                if i % 7 == 0 {
                    0.0
                } else {
                    2.0 + i as f32 * 0.01
                }
            })
            .collect(),
        normal: vec![[0.0, 0.0, -1.0]; w * h],
        cost: (0..w * h).map(|i| (i % 5) as f32 * 0.1).collect(),
    };
    let (d, n, c) = (tmp.join("d.bin"), tmp.join("n.bin"), tmp.join("c.bin"));
    write_depth_map(&d, &n, &c, &map).unwrap();
    let mut vis = 3u64.to_le_bytes().to_vec();
    for list in [&[0u32, 1][..], &[2], &[0, 1, 2]] {
        vis.extend_from_slice(&(list.len() as u32).to_le_bytes());
        for v in list {
            vis.extend_from_slice(&v.to_le_bytes());
        }
    }
    let (d, n, c) = (
        fs::read(d).unwrap(),
        fs::read(n).unwrap(),
        fs::read(c).unwrap(),
    );
    fs::write(out.join("maps.bin"), join(&[&d, &n, &c, &vis])).unwrap();
    fs::write(out.join("no_cost.bin"), join(&[&d, &n])).unwrap();
}

/// The bundled gears scene cut to its first 4 sprites, with a small pattern image.
fn sprites() {
    let out = seeds("sprite_scene");
    let text = fs::read_to_string(repo("datasets/sprites/gears.json")).unwrap();
    let mut scene: serde_json::Value = serde_json::from_str(&text).unwrap();
    scene["patterns"] = serde_json::json!(["p.png"]);
    let sprites = scene["sprites"].as_array_mut().unwrap();
    sprites.truncate(4);
    for s in sprites.iter_mut() {
        s["pattern"] = 0.into();
    }
    sprites[1]["blend"] = "add".into();
    sprites[2]["cycle"] = serde_json::json!([0, 0]);
    sprites[2]["cycle_fps"] = 2.0.into();
    let img = image::RgbaImage::from_fn(4, 4, |x, y| {
        image::Rgba([x as u8 * 60, y as u8 * 60, 9, 200])
    });
    let p = png(image::DynamicImage::ImageRgba8(img));
    let json = serde_json::to_string_pretty(&scene).unwrap();
    fs::write(out.join("gears4.bin"), join(&[json.as_bytes(), &p])).unwrap();
}

fn tempdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("fresco-seeds-{}-{name}", std::process::id()));
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

fn pst() {
    // A small PST of points on a sphere, with a budget that evicts some 1-nodes.
    let positions: Vec<[f64; 3]> = (0..300)
        .map(|i| {
            let t = i as f64 * 0.37;
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / 300.0;
            let r = (1.0 - z * z).sqrt();
            [r * t.cos(), r * t.sin(), z]
        })
        .collect();
    let src = MemoryPoints::from_positions(&positions);
    let tmp = tempdir("pst");
    let dir = tmp.join("p");
    let mut cfg = CreateConfig::default();
    cfg.sampling.target = 40;
    cfg.budget = Some(20);
    let (mut pst, _) = Pst::create(&src, &cfg, &dir, &NoProgress).unwrap();
    let out = seeds("pst_store");
    let manifest = fs::read(dir.join("pst.json")).unwrap();
    let samples = fs::read(dir.join("samples.bin")).unwrap();
    fs::write(out.join("resident.bin"), join(&[&manifest, &samples])).unwrap();
    let report = pst.enforce_budget(&[0]).unwrap();
    pst.save().unwrap();
    let manifest = fs::read(dir.join("pst.json")).unwrap();
    let samples = fs::read(dir.join("samples.bin")).unwrap();
    let evicted: Vec<Vec<u8>> = report
        .evicted
        .iter()
        .take(2)
        .map(|&id| fs::read(pst.evicted_path(id)).unwrap())
        .collect();
    // The target stores these as the files of the first two evicted nodes of the manifest.
    let mut parts: Vec<&[u8]> = vec![&manifest, &samples];
    parts.extend(evicted.iter().map(|e| e.as_slice()));
    fs::write(out.join("evicted.bin"), join(&parts)).unwrap();

    let out = seeds("pst_octree");
    let field = fresco_pst::Field::new(&pst.samples, fresco_pst::FieldConfig::default());
    let tex = fresco_pst::octree_texture::OctreeTexture::from_field(&field, 3).unwrap();
    tex.save(&tmp.join("t.foct")).unwrap();
    let mut seed = vec![64, 70, 80, 0, 0, 0];
    seed.extend_from_slice(&fs::read(tmp.join("t.foct")).unwrap());
    fs::write(out.join("depth3.foct"), seed).unwrap();

    let out = seeds("pst_node_file");
    let mut rec = Vec::new();
    for (k, p) in positions.iter().take(5).enumerate() {
        let sp = fresco_pst::SourcePoint {
            position: *p,
            normal: [0.0, 0.0, 1.0],
        };
        fresco_pst::node_files::encode_record(&sp, [0.0; 3], k % 2 == 0, &mut rec);
    }
    fs::write(out.join("records.pts"), rec).unwrap();

    let out = seeds("pst_script");
    let script = r#"{"ops": [
  {"op": "fill", "region": {"sphere": {"center": [0, 0, 0], "radius": 0.5}}, "value": [1, 0, 0]},
  {"op": "noise", "a": [0, 0, 0], "b": [1, 1, 1], "scale": 0.2, "octaves": 3, "seed": 7},
  {"op": "smooth", "iterations": 2, "k": 6},
  {"op": "add_channel", "name": "spec", "default": [0.5]},
  {"op": "fill", "region": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}, "value": [0.2], "channel": "spec", "opacity": 0.5},
  {"op": "refine", "region": "all", "factor": 2},
  {"op": "project", "image": "t.png", "origin": [0, 0, 0], "u": [1, 0, 0], "v": [0, 1, 0], "depth": 1.0}
]}"#;
    fs::write(out.join("ops.json"), script).unwrap();
    fs::write(out.join("box.txt"), "box:0,0,0,1,1,1").unwrap();
    fs::write(out.join("sphere.txt"), "sphere:0.5,0.5,0.5,0.25").unwrap();
    let _ = fs::remove_dir_all(&tmp);
}

fn main() {
    let tmp = tempdir("meshes");
    ply(&tmp);
    obj(&tmp);
    colmap();
    middlebury();
    photo();
    glb();
    sfm_files();
    pst();
    dense(&tmp);
    sprites();
    let _ = fs::remove_dir_all(&tmp);
    println!("seeds written under {}/seeds", ROOT);
}
