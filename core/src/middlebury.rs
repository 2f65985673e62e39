//! Middlebury multi-view stereo camera files, `*_par.txt` (Seitz et al. 2006): the number of
//! images on the first line, then one line per image,
//! `name k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 r12 r13 r21 r22 r23 r31 r32 r33 t1 t2 t3`,
//! with the projection `K [R | t]` (world to image; so `R, t` are camera-from-world), the
//! image origin at the top-left and pixel centres on integers.
//!
//! fresco puts pixel centres at +0.5 (COLMAP's convention, `camera.rs`): reading adds 0.5 to
//! the principal point, writing subtracts it. Each view becomes a PINHOLE camera; the file
//! has no image size, so the caller gives it (Middlebury sets use one size for all views).
//!
//! Functions: [`read_par`], [`write_par`], [`views_to_reconstruction`].

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Matrix3, Matrix3x4};

use crate::{CamFromWorld, Camera, CameraModel, FormatError, Image, Reconstruction, Rigid3};

/// One calibrated view of a `*_par.txt` file.
#[derive(Clone, Debug, PartialEq)]
pub struct ParView {
    /// Image file name as written in the file (relative to the file's folder).
    pub name: String,
    /// PINHOLE, id = 1-based position in the file, principal point in fresco's convention.
    pub camera: Camera,
    pub cam_from_world: CamFromWorld,
}

/// Largest entry of `R^T R - I` accepted for the rotation (the Middlebury files are
/// orthonormal to ~1e-15; this admits rotations printed with about 7 digits).
const ROTATION_TOLERANCE: f64 = 1e-6;

/// Reads a `*_par.txt` file whose images are all `width` x `height` pixels.
pub fn read_par(path: &Path, width: u32, height: u32) -> Result<Vec<ParView>, FormatError> {
    let text = std::fs::read_to_string(path).map_err(|e| FormatError::io(path, e))?;
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty());
    let Some((count_line, count_text)) = lines.next() else {
        return Err(FormatError::text(
            path,
            1,
            "empty file: expected the number of images",
        ));
    };
    let count: usize = count_text.parse().map_err(|_| {
        FormatError::text(
            path,
            count_line,
            format!("bad header: expected the number of images, found {count_text:?}"),
        )
    })?;
    // A view line holds a name and 21 numbers: at least 44 bytes. Reserve no more views
    // than the file can hold, whatever its first line says.
    let mut views: Vec<ParView> = Vec::with_capacity(count.min(text.len() / 44));
    let mut names = std::collections::HashSet::new();
    for (line, l) in lines {
        let err = |message: String| FormatError::text(path, line, message);
        let fields: Vec<&str> = l.split_ascii_whitespace().collect();
        if fields.len() != 22 {
            return Err(err(format!(
                "expected an image name and 21 numbers (K, R, t), found {} fields",
                fields.len()
            )));
        }
        let mut v = [0.0; 21];
        for (i, (x, token)) in v.iter_mut().zip(&fields[1..]).enumerate() {
            *x = match token.parse::<f64>() {
                Ok(x) if x.is_finite() => x,
                _ => {
                    return Err(err(format!(
                        "value {} ({token:?}) is not a finite number",
                        i + 1
                    )));
                }
            };
        }
        let name = fields[0].to_string();
        // What `write_par` can store again; the fields are split at ASCII whitespace only,
        // so a name could hold a vertical tab or a Unicode space (found by the middlebury
        // fuzz target: such a file read, but could not be written back).
        if name.chars().any(|c| c.is_whitespace() || c.is_control()) {
            return Err(err(format!(
                "image name {name:?} contains whitespace or a control character"
            )));
        }
        if !names.insert(name.clone()) {
            return Err(err(format!("image {name} appears twice")));
        }
        let k = Matrix3::from_row_slice(&v[0..9]);
        // PINHOLE has no skew; the last row of K must be (0, 0, 1).
        let fx = k[(0, 0)];
        if k[(0, 1)].abs() > 1e-9 * fx.abs()
            || k[(1, 0)] != 0.0
            || k[(2, 0)] != 0.0
            || k[(2, 1)] != 0.0
            || k[(2, 2)] != 1.0
        {
            return Err(err(format!(
                "K = {:?} is not a calibration matrix without skew (k12 = k21 = k31 = k32 = 0, k33 = 1)",
                &v[0..9]
            )));
        }
        let id = views.len() as u32 + 1;
        let camera = Camera::new(
            id,
            CameraModel::Pinhole,
            width,
            height,
            vec![fx, k[(1, 1)], k[(0, 2)] + 0.5, k[(1, 2)] + 0.5],
        )
        .map_err(|e| err(format!("image {name}: {e}")))?;
        let mut rt = Matrix3x4::zeros();
        rt.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::from_row_slice(&v[9..18]));
        rt[(0, 3)] = v[18];
        rt[(1, 3)] = v[19];
        rt[(2, 3)] = v[20];
        let pose = Rigid3::from_matrix(&rt, ROTATION_TOLERANCE)
            .ok_or_else(|| err(format!("image {name}: R is not a rotation matrix (R^T R = I to {ROTATION_TOLERANCE:e}, det R = +1)")))?;
        views.push(ParView {
            name,
            camera,
            cam_from_world: CamFromWorld(pose),
        });
    }
    if views.len() != count {
        return Err(FormatError::text(
            path,
            count_line,
            format!(
                "the header announces {count} images but the file holds {}",
                views.len()
            ),
        ));
    }
    Ok(views)
}

/// Writes `views` as a `*_par.txt` file (atomically: temporary name, then rename). Numbers
/// are written in Rust's shortest round-trip form, so [`read_par`] gives back the same K and
/// t; R goes through the quaternion and comes back to ~1e-16. Fails for cameras that are
/// not PINHOLE (or the pinhole special cases without distortion).
pub fn write_par(path: &Path, views: &[ParView]) -> Result<(), FormatError> {
    let mut s = String::new();
    let _ = writeln!(s, "{}", views.len());
    for view in views {
        let cam = &view.camera;
        let undistorted = match cam.model {
            CameraModel::SimplePinhole | CameraModel::Pinhole => true,
            _ => cam
                .model
                .extra_idxs()
                .iter()
                .all(|&i| cam.params.get(i) == Some(&0.0)),
        };
        if cam.validate().is_err() || !undistorted {
            return Err(FormatError::invalid(
                path,
                format!(
                    "view {}: camera {} ({}) is not a valid camera without distortion",
                    view.name,
                    cam.id,
                    cam.model.name()
                ),
            ));
        }
        if view.name.is_empty() || view.name.contains(char::is_whitespace) {
            return Err(FormatError::invalid(
                path,
                format!(
                    "view name {:?} cannot be stored (empty or whitespace)",
                    view.name
                ),
            ));
        }
        let c = cam.principal_point();
        let k = [
            cam.focal_x(),
            0.0,
            c.x - 0.5,
            0.0,
            cam.focal_y(),
            c.y - 0.5,
            0.0,
            0.0,
            1.0,
        ];
        let rt = view.cam_from_world.0.to_matrix();
        s.push_str(&view.name);
        let r = (0..3)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| rt[(i, j)]);
        let t = (0..3).map(|i| rt[(i, 3)]);
        for x in k.into_iter().chain(r).chain(t) {
            if !x.is_finite() {
                return Err(FormatError::invalid(
                    path,
                    format!("view {}: value {x} is not finite", view.name),
                ));
            }
            let _ = write!(s, " {x}");
        }
        s.push('\n');
    }
    crate::atomic_file::write_bytes_atomically(path, s.as_bytes())
}

/// The views as a reconstruction without points: camera and image ids = 1-based file order.
pub fn views_to_reconstruction(views: &[ParView]) -> Reconstruction {
    let mut rec = Reconstruction::default();
    for (i, view) in views.iter().enumerate() {
        let id = i as u32 + 1;
        rec.cameras.insert(
            id,
            Camera {
                id,
                ..view.camera.clone()
            },
        );
        rec.images.insert(
            id,
            Image {
                id,
                name: view.name.clone(),
                camera_id: id,
                cam_from_world: view.cam_from_world,
                keypoints: Vec::new(),
                point3d_ids: Vec::new(),
            },
        );
    }
    rec
}
