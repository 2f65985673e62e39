//! The real photo sets bundled in `datasets/`, with the ground truth each one has.
//!
//! | set | photos | ground truth |
//! |---|---|---|
//! | `templeSparseRing` (Middlebury, Seitz et al. 2006) | 16 PNG, 640x480 | K, R, t per photo (`templeSR_par.txt`) |
//! | `sceaux_castle` (openMVG sample, P. Moulon) | 11 JPEG, 1600x1202 (downscaled by `prepare_sceaux.py`, EXIF kept) | shared K (`images/K.txt`) |
//!
//! Both ground-truth files put pixel centres on integers; the loaders convert to COLMAP's
//! convention (+0.5 on the principal point). Paths are found from this crate's folder.

use std::fs;
use std::path::{Path, PathBuf};

use fresco_core::camera::{Camera, CameraModel};
use fresco_core::nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use fresco_core::reconstruction::{Image, Reconstruction};
use fresco_core::{CamFromWorld, FormatError, Rigid3};

/// A bundled photo set.
#[derive(Clone, Debug)]
pub struct RealDataset {
    pub name: &'static str,
    /// The set's folder.
    pub root: PathBuf,
    /// The photos, sorted by file name.
    pub images: Vec<PathBuf>,
    /// Ground-truth intrinsics and poses (image names as in `images`), where known.
    pub poses: Option<Reconstruction>,
    /// Ground-truth intrinsics shared by every photo, where known (COLMAP pixel convention).
    pub intrinsics: Option<Camera>,
}

/// The folder holding the bundled sets (`datasets/` of the repository).
pub fn datasets_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Middlebury's templeSparseRing: 16 views on a ring around a plaster temple, with
/// calibrated cameras.
pub fn temple_sparse_ring() -> Result<RealDataset, FormatError> {
    let root = datasets_dir().join("templeSparseRing");
    let images = list_images(&root, "png")?;
    let poses = read_middlebury_par(&root.join("templeSR_par.txt"))?;
    let intrinsics = poses.cameras.values().next().cloned();
    Ok(RealDataset {
        name: "templeSparseRing",
        root,
        images,
        poses: Some(poses),
        intrinsics,
    })
}

/// openMVG's Sceaux castle sample: 11 consumer photos (Kodak Z612) with a shared K.
pub fn sceaux_castle() -> Result<RealDataset, FormatError> {
    let root = datasets_dir().join("sceaux_castle");
    let images = list_images(&root.join("images"), "jpg")?;
    let first = images
        .first()
        .ok_or_else(|| FormatError::invalid(root.join("images"), "no JPEG photos in the folder"))?;
    let (width, height) = image_size(first)?;
    let intrinsics = read_k_txt(&root.join("images/K.txt"), width, height)?;
    Ok(RealDataset {
        name: "sceaux_castle",
        root,
        images,
        poses: None,
        intrinsics: Some(intrinsics),
    })
}

/// The files in `dir` with extension `ext` (case-insensitive), sorted by name.
fn list_images(dir: &Path, ext: &str) -> Result<Vec<PathBuf>, FormatError> {
    let mut out = Vec::new();
    for entry in fs::read_dir(dir).map_err(|e| FormatError::io(dir, e))? {
        let path = entry.map_err(|e| FormatError::io(dir, e))?.path();
        let matches = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case(ext));
        if matches {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

fn image_size(path: &Path) -> Result<(u32, u32), FormatError> {
    image::image_dimensions(path)
        .map_err(|e| FormatError::invalid(path, format!("cannot read the image size: {e}")))
}

/// Parses whitespace-separated numbers of one line, naming the line on error.
fn numbers(path: &Path, line_no: usize, fields: &[&str]) -> Result<Vec<f64>, FormatError> {
    fields
        .iter()
        .map(|f| {
            f.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    FormatError::text(path, line_no, format!("`{f}` is not a finite number"))
                })
        })
        .collect()
}

/// `K.txt`: a 3x3 calibration matrix, rows on three lines, pixel centres on integers.
/// Gives a PINHOLE camera in COLMAP's convention for images of `width` x `height`.
pub fn read_k_txt(path: &Path, width: u32, height: u32) -> Result<Camera, FormatError> {
    let text = fs::read_to_string(path).map_err(|e| FormatError::io(path, e))?;
    let rows: Vec<(usize, Vec<&str>)> = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.split_whitespace().collect::<Vec<_>>()))
        .filter(|(_, f)| !f.is_empty())
        .collect();
    if rows.len() != 3 {
        return Err(FormatError::invalid(
            path,
            format!("expected 3 rows of a 3x3 matrix, found {}", rows.len()),
        ));
    }
    let mut k = [[0.0; 3]; 3];
    for (r, (line, fields)) in rows.iter().enumerate() {
        if fields.len() != 3 {
            return Err(FormatError::text(
                path,
                *line,
                format!("expected 3 numbers, found {}", fields.len()),
            ));
        }
        let v = numbers(path, *line, fields)?;
        k[r] = [v[0], v[1], v[2]];
    }
    if k[0][0] <= 0.0 || k[1][1] <= 0.0 || k[1][0] != 0.0 || k[2] != [0.0, 0.0, 1.0] {
        return Err(FormatError::invalid(
            path,
            "not a calibration matrix (positive focal lengths, last row 0 0 1)",
        ));
    }
    Ok(Camera {
        id: 1,
        model: CameraModel::Pinhole,
        width,
        height,
        params: vec![k[0][0], k[1][1], k[0][2] + 0.5, k[1][2] + 0.5],
    })
}

/// Middlebury's `*_par.txt`: the image count, then per image `name k11..k33 r11..r33 t1..t3`
/// (the projection is K [R t], pixel centres on integers). One PINHOLE camera per image
/// (ids from 1 in file order), image sizes read from the photos beside the file.
pub fn read_middlebury_par(path: &Path) -> Result<Reconstruction, FormatError> {
    let text = fs::read_to_string(path).map_err(|e| FormatError::io(path, e))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty());
    let (count_line, count) = lines
        .next()
        .ok_or_else(|| FormatError::text(path, 1, "empty file: expected the image count"))?;
    let count: usize = count.parse().map_err(|_| {
        FormatError::text(path, count_line, format!("`{count}` is not an image count"))
    })?;
    let mut rec = Reconstruction::default();
    for (line, l) in lines {
        let fields: Vec<&str> = l.split_whitespace().collect();
        if fields.len() != 22 {
            return Err(FormatError::text(
                path,
                line,
                format!(
                    "expected a name and 21 numbers, found {} fields",
                    fields.len()
                ),
            ));
        }
        let v = numbers(path, line, &fields[1..])?;
        let id = rec.images.len() as u32 + 1;
        let (width, height) = image_size(&dir.join(fields[0]))?;
        let r = Matrix3::from_row_slice(&v[9..18]);
        // The calibration's rotations are orthonormal to about 1e-7; project onto SO(3).
        let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
        if (rotation.to_rotation_matrix().matrix() - r).amax() > 1e-4 {
            return Err(FormatError::text(path, line, "R is not a rotation matrix"));
        }
        rec.cameras.insert(
            id,
            Camera {
                id,
                model: CameraModel::Pinhole,
                width,
                height,
                params: vec![v[0], v[4], v[2] + 0.5, v[5] + 0.5],
            },
        );
        rec.images.insert(
            id,
            Image {
                id,
                name: fields[0].to_string(),
                camera_id: id,
                cam_from_world: CamFromWorld(Rigid3 {
                    rotation,
                    translation: Vector3::new(v[18], v[19], v[20]),
                }),
                keypoints: Vec::new(),
                point3d_ids: Vec::new(),
            },
        );
    }
    if rec.images.len() != count {
        return Err(FormatError::invalid(
            path,
            format!(
                "the header announces {count} images but {} follow",
                rec.images.len()
            ),
        ));
    }
    Ok(rec)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temple_loads_with_ground_truth_that_projects_the_object_into_the_photos() {
        let set = temple_sparse_ring().unwrap();
        assert_eq!(set.images.len(), 16);
        let rec = set.poses.as_ref().unwrap();
        assert_eq!(rec.images.len(), 16);
        // The README's tight bounding box of the temple: its centre must project inside
        // every photo, in front of the camera.
        let centre = Vector3::new(
            (-0.073568 + 0.028855) / 2.0,
            (0.021728 + 0.181892) / 2.0,
            (-0.012445 + 0.062736) / 2.0,
        );
        for image in rec.images.values() {
            let cam = &rec.cameras[&image.camera_id];
            assert_eq!((cam.width, cam.height), (640, 480));
            let x = image.cam_from_world.0.rotation * centre + image.cam_from_world.0.translation;
            assert!(x.z > 0.0);
            let (u, v) = (
                cam.params[0] * x.x / x.z + cam.params[2],
                cam.params[1] * x.y / x.z + cam.params[3],
            );
            assert!(
                (0.0..640.0).contains(&u) && (0.0..480.0).contains(&v),
                "{}: ({u}, {v})",
                image.name
            );
        }
        // Same intrinsics as the file's first line, shifted to COLMAP's convention.
        let k = set.intrinsics.unwrap();
        assert_eq!(k.params, vec![1520.4, 1525.9, 302.82, 247.37]);
    }

    #[test]
    fn sceaux_loads_with_scaled_intrinsics_and_exif_focal() {
        let set = sceaux_castle().unwrap();
        assert_eq!(set.images.len(), 11);
        let k = set.intrinsics.unwrap();
        assert_eq!((k.width, k.height), (1600, 1202));
        // The original K (2832x2128: f 2905.88, c (1416, 1064)) scaled by 1600/2832 and
        // 1202/2128 with integer pixel centres, then +0.5: c' = (c + 0.5) s.
        assert!((k.params[0] - 2905.88 * 1600.0 / 2832.0).abs() < 1e-3);
        assert!((k.params[1] - 2905.88 * 1202.0 / 2128.0).abs() < 1e-3);
        assert!((k.params[2] - 1416.5 * 1600.0 / 2832.0).abs() < 1e-3);
        assert!((k.params[3] - 1064.5 * 1202.0 / 2128.0).abs() < 1e-3);
        // The EXIF block survived the downscaling (focal priors need it).
        for path in &set.images {
            let file = fs::File::open(path).unwrap();
            let exif = exif::Reader::new()
                .read_from_container(&mut std::io::BufReader::new(file))
                .unwrap();
            let focal = exif
                .get_field(exif::Tag::FocalLength, exif::In::PRIMARY)
                .unwrap();
            let f35 = exif
                .get_field(exif::Tag::FocalLengthIn35mmFilm, exif::In::PRIMARY)
                .unwrap();
            assert_eq!(focal.display_value().to_string(), "5.85");
            assert_eq!(f35.value.get_uint(0), Some(35));
        }
    }

    #[test]
    fn malformed_ground_truth_files_give_located_errors() {
        let dir = tempfile::tempdir().unwrap();
        let k = dir.path().join("K.txt");
        fs::write(&k, "100 0 50\n0 abc 40\n0 0 1\n").unwrap();
        let e = read_k_txt(&k, 100, 80).unwrap_err().to_string();
        assert!(e.contains("K.txt:2") && e.contains("abc"), "{e}");
        fs::write(&k, "100 0 50\n0 100 40\n").unwrap();
        assert!(
            read_k_txt(&k, 100, 80)
                .unwrap_err()
                .to_string()
                .contains("3 rows")
        );
        let par = dir.path().join("x_par.txt");
        fs::write(&par, "2\na.png 1 2 3\n").unwrap();
        let e = read_middlebury_par(&par).unwrap_err().to_string();
        assert!(e.contains("x_par.txt:2") && e.contains("21 numbers"), "{e}");
        fs::write(&par, "").unwrap();
        assert!(read_middlebury_par(&par).is_err());
    }
}
