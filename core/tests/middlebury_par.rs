//! Middlebury `*_par.txt`: the templeSparseRing calibration read into fresco's conventions
//! (projections equal Middlebury's K [R t] plus half a pixel; the cameras form the ring
//! around the object's bounding box that the README describes), round trips, and errors
//! naming file and line.

use std::fs;
use std::path::{Path, PathBuf};

use fresco_core::FormatError;
use fresco_core::middlebury::{read_par, views_to_reconstruction, write_par};
use fresco_core::nalgebra::{Matrix3, Point3, Vector3, Vector4};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/middlebury_templeSR_par.txt")
}

/// The tight bounding box of the temple given in the set's README.
const BBOX: [[f64; 3]; 2] = [
    [-0.073568, 0.021728, -0.012445],
    [0.028855, 0.181892, 0.062736],
];

fn bbox_corners() -> Vec<Point3<f64>> {
    (0..8)
        .map(|i| Point3::new(BBOX[i & 1][0], BBOX[(i >> 1) & 1][1], BBOX[(i >> 2) & 1][2]))
        .collect()
}

/// The raw numbers of data line `n` (1-based, after the count) of a par file.
fn raw_line(path: &Path, n: usize) -> Vec<f64> {
    let text = fs::read_to_string(path).unwrap();
    let line = text.lines().nth(n).unwrap();
    line.split_whitespace()
        .skip(1)
        .map(|x| x.parse().unwrap())
        .collect()
}

#[test]
fn fixture_reads_into_fresco_conventions() {
    let views = read_par(&fixture(), 640, 480).unwrap();
    assert_eq!(views.len(), 4);
    assert_eq!(views[0].name, "templeSR0001.png");
    for (i, view) in views.iter().enumerate() {
        assert_eq!(view.camera.id, i as u32 + 1);
        assert_eq!((view.camera.width, view.camera.height), (640, 480));
        assert_eq!(
            view.camera.params,
            vec![1520.4, 1525.9, 302.32 + 0.5, 246.87 + 0.5]
        );
        // Projecting with fresco's camera gives Middlebury's K [R t] projection + 0.5 px.
        let v = raw_line(&fixture(), i + 1);
        let k = Matrix3::from_row_slice(&v[0..9]);
        let mut p = fresco_core::nalgebra::Matrix3x4::zeros();
        p.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::from_row_slice(&v[9..18]));
        p.set_column(3, &Vector3::new(v[18], v[19], v[20]));
        let p = k * p;
        for x in bbox_corners() {
            let h = p * Vector4::new(x.x, x.y, x.z, 1.0);
            let expected = (h.x / h.z + 0.5, h.y / h.z + 0.5);
            let got = view
                .camera
                .image_from_world(&view.cam_from_world, &x)
                .unwrap();
            // Same projection up to rounding of R's orthonormalisation (~1e-15 relative).
            assert!((got.x - expected.0).abs() < 1e-9 && (got.y - expected.1).abs() < 1e-9);
        }
    }
}

#[test]
fn temple_cameras_form_a_ring_around_the_bounding_box() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../datasets/templeSparseRing/templeSR_par.txt");
    let views = read_par(&path, 640, 480).unwrap();
    assert_eq!(views.len(), 16);
    let c = Point3::from((Vector3::from(BBOX[0]) + Vector3::from(BBOX[1])) / 2.0);
    let centres: Vec<Point3<f64>> = views.iter().map(|v| v.cam_from_world.center()).collect();
    let dists: Vec<f64> = centres.iter().map(|p| (p - c).norm()).collect();
    let mean = dists.iter().sum::<f64>() / dists.len() as f64;
    // A ring: every centre at the same distance (about 0.57 m, the gantry's radius) to
    // within a few percent, far outside the 0.2 m box.
    for d in &dists {
        assert!((d / mean - 1.0).abs() < 0.05, "{dists:?}");
    }
    assert!(mean > 0.4 && mean < 0.8, "{mean}");
    // ... in one plane: the centres' covariance has one vanishing axis.
    let centroid = centres.iter().map(|p| p.coords).sum::<Vector3<f64>>() / centres.len() as f64;
    let mut cov = Matrix3::zeros();
    for p in &centres {
        let d = p.coords - centroid;
        cov += d * d.transpose();
    }
    let mut eig: Vec<f64> = cov.symmetric_eigenvalues().iter().copied().collect();
    eig.sort_by(f64::total_cmp);
    assert!(eig[0] < 1e-4 * eig[2], "{eig:?}");
    // ... and every camera looks at the object: the whole box projects inside the image.
    for v in &views {
        let to_object = (c - v.cam_from_world.center()).normalize();
        assert!(v.cam_from_world.viewing_direction().dot(&to_object) > 0.95);
        for x in bbox_corners() {
            let pixel = v.camera.image_from_world(&v.cam_from_world, &x).unwrap();
            assert!(v.camera.contains(&pixel), "{}: {pixel}", v.name);
        }
    }
    let rec = views_to_reconstruction(&views);
    assert_eq!(rec.images.len(), 16);
    assert_eq!(rec.image_by_name("templeSR0016.png").unwrap().camera_id, 16);
    assert!(rec.validate().is_ok());
}

#[test]
fn write_then_read_gives_the_same_views() {
    let views = read_par(&fixture(), 640, 480).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("copy_par.txt");
    write_par(&out, &views).unwrap();
    let back = read_par(&out, 640, 480).unwrap();
    assert_eq!(
        fs::read_dir(dir.path()).unwrap().count(),
        1,
        "no temporary file is left"
    );
    for (a, b) in views.iter().zip(&back) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.camera, b.camera);
        assert_eq!(
            a.cam_from_world.0.translation,
            b.cam_from_world.0.translation
        );
        assert!(
            a.cam_from_world
                .0
                .rotation
                .angle_to(&b.cam_from_world.0.rotation)
                < 1e-15
        );
    }
    // Written K is Middlebury's again (principal point without the half pixel).
    assert_eq!(raw_line(&out, 1)[..9], raw_line(&fixture(), 1)[..9]);
    // A camera with distortion cannot be stored.
    let mut distorted = views.clone();
    distorted[0].camera =
        fresco_core::Camera::simple_radial(1, 640, 480, 1500.0, 320.0, 240.0, 0.1).unwrap();
    assert!(write_par(&out, &distorted).is_err());
}

// ---------------------------------------------------------------------------------------
// Malformed files: file and line.

/// The fixture with data line `n` (1-based, 0 = the count) replaced by `f(line)`.
fn broken(n: usize, f: impl Fn(&str) -> String) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad_par.txt");
    let text = fs::read_to_string(fixture()).unwrap();
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| if i == n { f(l) } else { l.to_string() })
        .collect();
    fs::write(&path, lines.join("\n") + "\n").unwrap();
    (dir, path)
}

fn line_error(path: &Path) -> (usize, String) {
    match read_par(path, 640, 480).unwrap_err() {
        FormatError::Text {
            path: p,
            line,
            message,
        } => {
            assert_eq!(p, path);
            (line, message)
        }
        other => panic!("expected an error with a line, got {other:?}"),
    }
}

/// Replaces field `i` (0 = name) of a line.
fn set_field(line: &str, i: usize, value: &str) -> String {
    let mut f: Vec<&str> = line.split_whitespace().collect();
    f[i] = value;
    f.join(" ")
}

#[test]
fn count_mismatch_and_bad_header() {
    let (_d, path) = broken(0, |_| "5".into());
    let (line, msg) = line_error(&path);
    assert_eq!(line, 1);
    assert!(
        msg.contains("announces 5 images but the file holds 4"),
        "{msg}"
    );
    let (_d, path) = broken(0, |_| "four".into());
    let (line, msg) = line_error(&path);
    assert_eq!(line, 1);
    assert!(msg.contains("bad header"), "{msg}");
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty_par.txt");
    fs::write(&empty, "").unwrap();
    assert!(line_error(&empty).1.contains("empty file"));
    let missing = dir.path().join("missing_par.txt");
    assert!(matches!(
        read_par(&missing, 640, 480),
        Err(FormatError::Io { .. })
    ));
}

#[test]
fn wrong_field_count_nan_skew_rotation_and_duplicates() {
    let (_d, path) = broken(3, |l| l.rsplit_once(' ').unwrap().0.to_string());
    let (line, msg) = line_error(&path);
    assert_eq!(line, 4);
    assert!(
        msg.contains("21 numbers") && msg.contains("found 21 fields"),
        "{msg}"
    );
    let (_d, path) = broken(2, |l| set_field(l, 20, "nan"));
    let (line, msg) = line_error(&path);
    assert_eq!(line, 3);
    assert!(
        msg.contains("value 20") && msg.contains("not a finite number"),
        "{msg}"
    );
    let (_d, path) = broken(1, |l| set_field(l, 2, "3.5"));
    let (line, msg) = line_error(&path);
    assert_eq!(line, 2);
    assert!(msg.contains("without skew"), "{msg}");
    let (_d, path) = broken(1, |l| set_field(l, 10, "0.5"));
    let (line, msg) = line_error(&path);
    assert_eq!(line, 2);
    assert!(msg.contains("not a rotation"), "{msg}");
    let (_d, path) = broken(1, |l| set_field(l, 1, "-1520.4"));
    let (line, msg) = line_error(&path);
    assert_eq!(line, 2);
    assert!(msg.contains("focal"), "{msg}");
    let (_d, path) = broken(4, |l| set_field(l, 0, "templeSR0001.png"));
    let (line, msg) = line_error(&path);
    assert_eq!(line, 5);
    assert!(msg.contains("appears twice"), "{msg}");
}
