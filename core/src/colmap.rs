//! COLMAP sparse models, text and binary, read and written byte for byte as COLMAP does.
//!
//! A model folder holds `cameras`, `images` and `points3D` (`.txt` or `.bin`); COLMAP 4 adds
//! `rigs` and `frames`. What COLMAP writes (checked against COLMAP/pycolmap 4.2.1, see
//! `datasets/reference/make_colmap_fixture.py`), and fresco likewise:
//! - text: `#` header comments (with element counts and means), numbers as C++ streams print
//!   them at precision 17 (`%.17g`), cameras and points in id order, one line per camera /
//!   point, two lines per image (the keypoint line keeps COLMAP's trailing space, and is empty
//!   for an image without keypoints), `-1` for a keypoint without a 3D point;
//! - binary: little endian, a `u64` count, then per camera `u32 id, i32 model, u64 width,
//!   u64 height, f64 params[]`; per image `u32 id, f64 qw qx qy qz tx ty tz, u32 camera_id,
//!   name\0, u64 n, n x (f64 x, f64 y, u64 point3D_id)` with `u64::MAX` for none; per point
//!   `u64 id, f64 xyz, u8 rgb, f64 error, u64 n, n x (u32 image_id, u32 point2D_idx)`;
//! - rigs/frames: fresco has no multi-camera rigs, so it writes what COLMAP writes for a
//!   model without them (one rig per camera with `rig_id = camera_id`, one frame per image
//!   with `frame_id = image_id`). Images are written in id order (COLMAP writes them in
//!   registration order: a model whose images were registered out of id order reads back
//!   equal but not byte-identical).
//!
//! Reading accepts models with or without rigs/frames (COLMAP 3.x writes neither). With
//! them, each image must belong to a frame whose pose agrees with the image's, as COLMAP 4
//! takes poses from frames; multi-camera rigs are read (image poses are the composed
//! `sensor_from_rig * rig_from_world`, which COLMAP also stores in `images.*`) but the rig
//! structure is not kept. Image names may contain spaces in fresco (text: the rest of the
//! line), but COLMAP's text reader stops at the first space: use binary for such names.
//!
//! Every error names the file and the line (text) or byte offset (binary) and what was
//! wrong; a model is checked for consistency ([`Reconstruction::validate`]) before it is
//! returned or written. Writing is atomic per file (temporary name in the folder, then
//! rename) and removes the other format's model files from the folder, so that
//! [`read_model`], which prefers binary as COLMAP does, cannot read a stale model.
//!
//! Functions: [`read_model`], [`read_text`], [`read_binary`], [`detect_format`],
//! [`write_model`], [`write_text`], [`write_binary`].

use std::collections::HashMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Point2, Point3, Quaternion, UnitQuaternion, Vector3};

use crate::reconstruction::ValidationError;
use crate::{
    CamFromWorld, Camera, CameraModel, FormatError, Image, Point3D, Reconstruction, Rigid3,
    TrackElement,
};

/// The two encodings of a COLMAP model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelFormat {
    Text,
    Binary,
}

impl ModelFormat {
    fn extension(self) -> &'static str {
        match self {
            ModelFormat::Text => "txt",
            ModelFormat::Binary => "bin",
        }
    }
}

const MODEL_FILES: [&str; 3] = ["cameras", "images", "points3D"];
const RIG_FILES: [&str; 2] = ["rigs", "frames"];

/// Which model `dir` holds: binary when `cameras.bin`, `images.bin` and `points3D.bin` all
/// exist (COLMAP's preference), else text when the three `.txt` files do.
pub fn detect_format(dir: &Path) -> Result<ModelFormat, FormatError> {
    for format in [ModelFormat::Binary, ModelFormat::Text] {
        let ext = format.extension();
        if MODEL_FILES
            .iter()
            .all(|f| dir.join(format!("{f}.{ext}")).is_file())
        {
            return Ok(format);
        }
    }
    Err(FormatError::invalid(
        dir,
        "not a COLMAP model folder: expected cameras, images and points3D as .bin or .txt files",
    ))
}

/// Reads the model in `dir`, binary or text ([`detect_format`]).
pub fn read_model(dir: &Path) -> Result<Reconstruction, FormatError> {
    match detect_format(dir)? {
        ModelFormat::Text => read_text(dir),
        ModelFormat::Binary => read_binary(dir),
    }
}

/// Reads `cameras.txt`, `images.txt`, `points3D.txt` (and `rigs.txt`, `frames.txt` if present).
pub fn read_text(dir: &Path) -> Result<Reconstruction, FormatError> {
    read_with(dir, ModelFormat::Text)
}

/// Reads `cameras.bin`, `images.bin`, `points3D.bin` (and `rigs.bin`, `frames.bin` if present).
pub fn read_binary(dir: &Path) -> Result<Reconstruction, FormatError> {
    read_with(dir, ModelFormat::Binary)
}

/// Writes `rec` into `dir` (created if missing) in `format`.
pub fn write_model(
    rec: &Reconstruction,
    dir: &Path,
    format: ModelFormat,
) -> Result<(), FormatError> {
    check_writable(rec, dir)?;
    let ext = format.extension();
    let mut files: Vec<(String, FileWriter)> = vec![
        ("rigs".into(), write_rigs),
        ("cameras".into(), write_cameras),
        ("frames".into(), write_frames),
        ("images".into(), write_images),
        ("points3D".into(), write_points),
    ];
    for (name, _) in &mut files {
        name.push('.');
        name.push_str(ext);
    }
    std::fs::create_dir_all(dir).map_err(|e| FormatError::io(dir, e))?;
    let mut done: Vec<(PathBuf, PathBuf)> = Vec::new();
    let result = (|| {
        for (name, write) in &files {
            let target = dir.join(name);
            let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
            done.push((tmp.clone(), target));
            let file = File::create(&tmp).map_err(|e| FormatError::io(&tmp, e))?;
            let mut out = BufWriter::new(file);
            write(rec, format, &mut out).map_err(|e| FormatError::io(&tmp, e))?;
            let file = out
                .into_inner()
                .map_err(|e| FormatError::io(&tmp, e.into_error()))?;
            file.sync_all().map_err(|e| FormatError::io(&tmp, e))?;
        }
        Ok(())
    })();
    if let Err(e) = result {
        for (tmp, _) in &done {
            let _ = std::fs::remove_file(tmp);
        }
        return Err(e);
    }
    for (tmp, target) in &done {
        std::fs::rename(tmp, target).map_err(|e| FormatError::io(target, e))?;
    }
    let other = match format {
        ModelFormat::Text => ModelFormat::Binary,
        ModelFormat::Binary => ModelFormat::Text,
    };
    for f in MODEL_FILES.iter().chain(&RIG_FILES) {
        let stale = dir.join(format!("{f}.{}", other.extension()));
        if stale.is_file() {
            std::fs::remove_file(&stale).map_err(|e| FormatError::io(&stale, e))?;
        }
    }
    Ok(())
}

/// [`write_model`] in text.
pub fn write_text(rec: &Reconstruction, dir: &Path) -> Result<(), FormatError> {
    write_model(rec, dir, ModelFormat::Text)
}

/// [`write_model`] in binary.
pub fn write_binary(rec: &Reconstruction, dir: &Path) -> Result<(), FormatError> {
    write_model(rec, dir, ModelFormat::Binary)
}

// ---------------------------------------------------------------------------------------
// Reading: shared structure.

/// Where an element was read: a line (text, 1-based) or a byte offset (binary).
#[derive(Clone, Copy, Debug)]
enum Loc {
    Line(usize),
    Offset(u64),
}

fn error_at(path: &Path, loc: Loc, message: impl Into<String>) -> FormatError {
    match loc {
        Loc::Line(line) => FormatError::text(path, line, message),
        Loc::Offset(offset) => FormatError::binary(path, offset, message),
    }
}

/// COLMAP's sensor types (`SensorType` enum values).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SensorType {
    Camera,
    Imu,
}

impl SensorType {
    fn from_code(code: i32) -> Option<SensorType> {
        match code {
            0 => Some(SensorType::Camera),
            1 => Some(SensorType::Imu),
            _ => None,
        }
    }
    fn from_name(name: &str) -> Option<SensorType> {
        match name {
            "CAMERA" => Some(SensorType::Camera),
            "IMU" => Some(SensorType::Imu),
            _ => None,
        }
    }
}

type SensorId = (SensorType, u32);

struct RigRecord {
    loc: Loc,
    ref_sensor: Option<SensorId>,
    /// Non-reference sensors with their `sensor_from_rig`, when known.
    sensors: Vec<(SensorId, Option<Rigid3>)>,
}

struct FrameRecord {
    loc: Loc,
    rig_id: u32,
    rig_from_world: Rigid3,
    /// (sensor, data id); for cameras the data id is the image id.
    data: Vec<(SensorId, u64)>,
}

/// Where each element was read, to place consistency errors.
#[derive(Default)]
struct Locations {
    /// Image id -> (its first line / record start, its keypoints line / count).
    images: HashMap<u32, (Loc, Loc)>,
    points: HashMap<u64, Loc>,
}

/// Everything one model folder holds, before the consistency checks.
struct Parsed {
    rec: Reconstruction,
    locs: Locations,
    rigs: Option<HashMap<u32, RigRecord>>,
    frames: Option<HashMap<u32, FrameRecord>>,
}

fn model_path(dir: &Path, name: &str, format: ModelFormat) -> PathBuf {
    dir.join(format!("{name}.{}", format.extension()))
}

fn read_with(dir: &Path, format: ModelFormat) -> Result<Reconstruction, FormatError> {
    let path = |name| model_path(dir, name, format);
    let load = |p: &Path| std::fs::read(p).map_err(|e| FormatError::io(p, e));
    let rigs_path = path("rigs");
    let frames_path = path("frames");
    match (rigs_path.is_file(), frames_path.is_file()) {
        (true, false) => {
            return Err(FormatError::invalid(
                &rigs_path,
                format!("{} is missing: rigs need frames", frames_path.display()),
            ));
        }
        (false, true) => {
            return Err(FormatError::invalid(
                &frames_path,
                format!("{} is missing: frames need rigs", rigs_path.display()),
            ));
        }
        _ => {}
    }
    let has_rigs = rigs_path.is_file();
    let mut parsed = Parsed {
        rec: Reconstruction::default(),
        locs: Locations::default(),
        rigs: None,
        frames: None,
    };
    let (cameras, images, points) = (path("cameras"), path("images"), path("points3D"));
    match format {
        ModelFormat::Text => {
            if has_rigs {
                parsed.rigs = Some(text::rigs(
                    &rigs_path,
                    &text_of(&rigs_path, load(&rigs_path)?)?,
                )?);
                parsed.frames = Some(text::frames(
                    &frames_path,
                    &text_of(&frames_path, load(&frames_path)?)?,
                )?);
            }
            text::cameras(&cameras, &text_of(&cameras, load(&cameras)?)?, &mut parsed)?;
            text::images(&images, &text_of(&images, load(&images)?)?, &mut parsed)?;
            text::points(&points, &text_of(&points, load(&points)?)?, &mut parsed)?;
        }
        ModelFormat::Binary => {
            if has_rigs {
                parsed.rigs = Some(binary::rigs(&rigs_path, &load(&rigs_path)?)?);
                parsed.frames = Some(binary::frames(&frames_path, &load(&frames_path)?)?);
            }
            binary::cameras(&cameras, &load(&cameras)?, &mut parsed)?;
            binary::images(&images, &load(&images)?, &mut parsed)?;
            binary::points(&points, &load(&points)?, &mut parsed)?;
        }
    }
    check_consistency(&parsed, &images, &points)?;
    if let (Some(rigs), Some(frames)) = (&parsed.rigs, &parsed.frames) {
        check_frames(
            &parsed.rec,
            &parsed.locs,
            rigs,
            frames,
            &images,
            &rigs_path,
            &frames_path,
        )?;
    }
    Ok(parsed.rec)
}

fn text_of(path: &Path, bytes: Vec<u8>) -> Result<String, FormatError> {
    String::from_utf8(bytes).map_err(|e| {
        let offset = e.utf8_error().valid_up_to();
        FormatError::binary(path, offset as u64, "text file is not valid UTF-8")
    })
}

/// The reconstruction's own rules, placed at the element that breaks them.
fn check_consistency(parsed: &Parsed, images: &Path, points: &Path) -> Result<(), FormatError> {
    let rec = &parsed.rec;
    for (&id, image) in &rec.images {
        if let Err(e) = rec.validate_image(id, image) {
            let (head, kps) = parsed.locs.images[&id];
            let loc = match e {
                ValidationError::MissingCamera { .. } => head,
                _ => kps,
            };
            return Err(error_at(images, loc, e.to_string()));
        }
    }
    for (&id, point) in &rec.points3d {
        if let Err(e) = rec.validate_point(id, point) {
            return Err(error_at(points, parsed.locs.points[&id], e.to_string()));
        }
    }
    Ok(())
}

/// COLMAP 4 takes image poses from frames: each image must be in a frame of a known rig,
/// and the frame's pose (with the rig's `sensor_from_rig`) must agree with the image's.
fn check_frames(
    rec: &Reconstruction,
    locs: &Locations,
    rigs: &HashMap<u32, RigRecord>,
    frames: &HashMap<u32, FrameRecord>,
    images_path: &Path,
    rigs_path: &Path,
    frames_path: &Path,
) -> Result<(), FormatError> {
    for rig in rigs.values() {
        let sensors = rig
            .ref_sensor
            .iter()
            .chain(rig.sensors.iter().map(|(s, _)| s));
        for &(kind, id) in sensors {
            if kind == SensorType::Camera && !rec.cameras.contains_key(&id) {
                return Err(error_at(
                    rigs_path,
                    rig.loc,
                    format!("rig sensor CAMERA {id} is not in the cameras file"),
                ));
            }
        }
    }
    let mut frame_of_image: HashMap<u32, (u32, u32)> = HashMap::new();
    let mut frame_ids: Vec<&u32> = frames.keys().collect();
    frame_ids.sort();
    for &frame_id in frame_ids {
        let frame = &frames[&frame_id];
        if !rigs.contains_key(&frame.rig_id) {
            return Err(error_at(
                frames_path,
                frame.loc,
                format!(
                    "frame {frame_id} refers to rig {}, which does not exist",
                    frame.rig_id
                ),
            ));
        }
        for &((kind, sensor_id), data_id) in &frame.data {
            if kind == SensorType::Camera {
                let image_id = u32::try_from(data_id).map_err(|_| {
                    error_at(
                        frames_path,
                        frame.loc,
                        format!("image id {data_id} is out of range"),
                    )
                })?;
                frame_of_image.insert(image_id, (frame_id, sensor_id));
            }
        }
    }
    let mut warned = false;
    for (&image_id, image) in &rec.images {
        let (head, _) = locs.images[&image_id];
        let Some(&(frame_id, sensor_id)) = frame_of_image.get(&image_id) else {
            return Err(error_at(
                images_path,
                head,
                format!(
                    "image {image_id} is in no frame of {}",
                    frames_path.display()
                ),
            ));
        };
        let frame = &frames[&frame_id];
        if sensor_id != image.camera_id {
            return Err(error_at(
                frames_path,
                frame.loc,
                format!(
                    "frame {frame_id} lists image {image_id} under camera {sensor_id}, but the image's camera is {}",
                    image.camera_id
                ),
            ));
        }
        let rig = &rigs[&frame.rig_id];
        let sensor = (SensorType::Camera, sensor_id);
        let sensor_from_rig = if rig.ref_sensor == Some(sensor) {
            Some(Rigid3::identity())
        } else {
            match rig.sensors.iter().find(|(s, _)| *s == sensor) {
                Some((_, pose)) => *pose,
                None => {
                    return Err(error_at(
                        rigs_path,
                        rig.loc,
                        format!(
                            "rig {} has no sensor CAMERA {sensor_id} (frame {frame_id}, image {image_id})",
                            frame.rig_id
                        ),
                    ));
                }
            }
        };
        if !rig.sensors.is_empty() && !warned {
            tracing::warn!(
                "{}: multi-camera rigs are read as independent images (the rig structure is not kept)",
                rigs_path.display()
            );
            warned = true;
        }
        let Some(sensor_from_rig) = sensor_from_rig else {
            continue;
        };
        let expected = sensor_from_rig * frame.rig_from_world;
        let actual = image.cam_from_world.0;
        let angle = expected.rotation.angle_to(&actual.rotation);
        let shift = (expected.translation - actual.translation).norm();
        // Both are the same doubles, or the composition COLMAP computed for images.* and
        // ours (rounding ~1e-15 relative); 1e-9 separates that from a different pose.
        if angle > 1e-9 || shift > 1e-9 * (1.0 + actual.translation.norm()) {
            return Err(error_at(
                images_path,
                head,
                format!(
                    "image {image_id} pose differs from its frame {frame_id} in {} ({angle:.3e} rad, {shift:.3e} units)",
                    frames_path.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Rotation from a stored quaternion. Exactly as stored when it is unit to rounding (so that
/// writing it back reproduces the file); normalised when it was written with few digits.
fn rotation_from_wxyz(q: [f64; 4]) -> Result<UnitQuaternion<f64>, String> {
    let quat = Quaternion::new(q[0], q[1], q[2], q[3]);
    let norm = quat.norm();
    if (norm - 1.0).abs() <= 1e-12 {
        Ok(UnitQuaternion::new_unchecked(quat))
    } else if (norm - 1.0).abs() <= 1e-3 {
        Ok(UnitQuaternion::new_normalize(quat))
    } else {
        Err(format!(
            "quaternion ({}, {}, {}, {}) has norm {norm}, not 1",
            q[0], q[1], q[2], q[3]
        ))
    }
}

fn rigid_from_values(v: [f64; 7]) -> Result<Rigid3, String> {
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("pose value {bad} is not finite"));
    }
    Ok(Rigid3::new(
        rotation_from_wxyz([v[0], v[1], v[2], v[3]])?,
        Vector3::new(v[4], v[5], v[6]),
    ))
}

fn insert_camera(
    parsed: &mut Parsed,
    path: &Path,
    loc: Loc,
    camera: Camera,
) -> Result<(), FormatError> {
    camera
        .validate()
        .map_err(|e| error_at(path, loc, format!("camera {}: {e}", camera.id)))?;
    if parsed.rec.cameras.contains_key(&camera.id) {
        return Err(error_at(
            path,
            loc,
            format!("camera id {} appears twice", camera.id),
        ));
    }
    parsed.rec.cameras.insert(camera.id, camera);
    Ok(())
}

fn insert_image(
    parsed: &mut Parsed,
    path: &Path,
    locs: (Loc, Loc),
    image: Image,
) -> Result<(), FormatError> {
    if parsed.rec.images.contains_key(&image.id) {
        return Err(error_at(
            path,
            locs.0,
            format!("image id {} appears twice", image.id),
        ));
    }
    parsed.locs.images.insert(image.id, locs);
    parsed.rec.images.insert(image.id, image);
    Ok(())
}

fn insert_point(
    parsed: &mut Parsed,
    path: &Path,
    loc: Loc,
    point: Point3D,
) -> Result<(), FormatError> {
    if parsed.rec.points3d.contains_key(&point.id) {
        return Err(error_at(
            path,
            loc,
            format!("point3D id {} appears twice", point.id),
        ));
    }
    parsed.locs.points.insert(point.id, loc);
    parsed.rec.points3d.insert(point.id, point);
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Text reading.

mod text {
    use super::*;

    /// The fields of one line, consumed left to right; errors name the line and the field.
    pub(super) struct Fields<'a> {
        path: &'a Path,
        line: usize,
        rest: &'a str,
    }

    impl<'a> Fields<'a> {
        pub(super) fn new(path: &'a Path, line: usize, text: &'a str) -> Fields<'a> {
            Fields {
                path,
                line,
                rest: text.trim(),
            }
        }

        pub(super) fn err(&self, message: impl Into<String>) -> FormatError {
            FormatError::text(self.path, self.line, message)
        }

        pub(super) fn is_empty(&self) -> bool {
            self.rest.is_empty()
        }

        pub(super) fn token(&mut self, what: &str) -> Result<&'a str, FormatError> {
            if self.rest.is_empty() {
                return Err(self.err(format!("line ends before {what}")));
            }
            let end = self
                .rest
                .find(|c: char| c.is_ascii_whitespace())
                .unwrap_or(self.rest.len());
            let (token, rest) = self.rest.split_at(end);
            self.rest = rest.trim_start();
            Ok(token)
        }

        pub(super) fn parse<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, FormatError> {
            let token = self.token(what)?;
            token.parse().map_err(|_| {
                self.err(format!(
                    "{what}: expected {}, found {token:?}",
                    std::any::type_name::<T>()
                ))
            })
        }

        /// A finite number (NaN and infinities are errors).
        pub(super) fn real(&mut self, what: &str) -> Result<f64, FormatError> {
            let token = self.token(what)?;
            match token.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                Ok(_) => Err(self.err(format!("{what} is not a finite number: {token:?}"))),
                Err(_) => Err(self.err(format!("{what}: expected a number, found {token:?}"))),
            }
        }

        pub(super) fn pose(&mut self) -> Result<Rigid3, FormatError> {
            let mut v = [0.0; 7];
            for (x, what) in v.iter_mut().zip(["QW", "QX", "QY", "QZ", "TX", "TY", "TZ"]) {
                *x = self.real(what)?;
            }
            rigid_from_values(v).map_err(|m| self.err(m))
        }

        pub(super) fn sensor(&mut self) -> Result<SensorId, FormatError> {
            let token = self.token("SENSOR_TYPE")?;
            let kind = SensorType::from_name(token).ok_or_else(|| {
                self.err(format!(
                    "unknown sensor type {token:?} (expected CAMERA or IMU)"
                ))
            })?;
            Ok((kind, self.parse("SENSOR_ID")?))
        }

        /// The rest of the line, trimmed (image names may contain spaces).
        pub(super) fn rest(&mut self, what: &str) -> Result<&'a str, FormatError> {
            if self.rest.is_empty() {
                return Err(self.err(format!("line ends before {what}")));
            }
            Ok(std::mem::take(&mut self.rest))
        }

        pub(super) fn end(&self) -> Result<(), FormatError> {
            if self.rest.is_empty() {
                Ok(())
            } else {
                Err(self.err(format!("unexpected trailing values {:?}", self.rest)))
            }
        }
    }

    /// The data lines of a file (not blank, not `#`), with 1-based line numbers, and the
    /// count announced by a `# Number of <what>: N` header line, if any.
    pub(super) struct Lines<'a> {
        path: &'a Path,
        lines: std::iter::Enumerate<std::str::Lines<'a>>,
        announced: Option<(usize, usize)>,
        what: &'static str,
    }

    impl<'a> Lines<'a> {
        pub(super) fn new(path: &'a Path, content: &'a str, what: &'static str) -> Lines<'a> {
            Lines {
                path,
                lines: content.lines().enumerate(),
                announced: None,
                what,
            }
        }

        /// The next data line, skipping comments (and parsing the count header).
        pub(super) fn next_data(&mut self) -> Result<Option<(usize, &'a str)>, FormatError> {
            for (i, line) in self.lines.by_ref() {
                let trimmed = line.trim();
                if trimmed.is_empty() {
                    continue;
                }
                if let Some(comment) = trimmed.strip_prefix('#') {
                    let prefix = format!("Number of {}:", self.what);
                    if let Some(rest) = comment.trim().strip_prefix(&prefix) {
                        let count = rest.split(',').next().unwrap_or("").trim();
                        let n = count.parse::<usize>().map_err(|_| {
                            FormatError::text(
                                self.path,
                                i + 1,
                                format!(
                                    "bad header: number of {} {count:?} is not a count",
                                    self.what
                                ),
                            )
                        })?;
                        self.announced = Some((i + 1, n));
                    }
                    continue;
                }
                return Ok(Some((i + 1, trimmed)));
            }
            Ok(None)
        }

        /// The line right after the previous one, whatever it holds (an image's keypoints).
        pub(super) fn next_raw(&mut self) -> Option<(usize, &'a str)> {
            self.lines.next().map(|(i, l)| (i + 1, l))
        }

        /// Checks the announced count (a file cut at a line boundary shows up here).
        pub(super) fn check_count(&self, found: usize) -> Result<(), FormatError> {
            match self.announced {
                Some((line, n)) if n != found => Err(FormatError::text(
                    self.path,
                    line,
                    format!(
                        "the header announces {n} {} but the file holds {found} (truncated or edited file)",
                        self.what
                    ),
                )),
                _ => Ok(()),
            }
        }
    }

    pub(super) fn rigs(path: &Path, content: &str) -> Result<HashMap<u32, RigRecord>, FormatError> {
        let mut lines = Lines::new(path, content, "rigs");
        let mut rigs = HashMap::new();
        while let Some((line, text)) = lines.next_data()? {
            let mut f = Fields::new(path, line, text);
            let id: u32 = f.parse("RIG_ID")?;
            let n: u32 = f.parse("NUM_SENSORS")?;
            let mut rig = RigRecord {
                loc: Loc::Line(line),
                ref_sensor: None,
                sensors: Vec::new(),
            };
            if n > 0 {
                rig.ref_sensor = Some(f.sensor()?);
            }
            for _ in 1..n.max(1) {
                let sensor = f.sensor()?;
                let has_pose: u8 = f.parse("HAS_POSE")?;
                let pose = match has_pose {
                    0 => None,
                    1 => Some(f.pose()?),
                    _ => return Err(f.err(format!("HAS_POSE must be 0 or 1, found {has_pose}"))),
                };
                rig.sensors.push((sensor, pose));
            }
            f.end()?;
            if rigs.insert(id, rig).is_some() {
                return Err(f.err(format!("rig id {id} appears twice")));
            }
        }
        lines.check_count(rigs.len())?;
        Ok(rigs)
    }

    pub(super) fn frames(
        path: &Path,
        content: &str,
    ) -> Result<HashMap<u32, FrameRecord>, FormatError> {
        let mut lines = Lines::new(path, content, "frames");
        let mut frames = HashMap::new();
        while let Some((line, text)) = lines.next_data()? {
            let mut f = Fields::new(path, line, text);
            let id: u32 = f.parse("FRAME_ID")?;
            let rig_id: u32 = f.parse("RIG_ID")?;
            let rig_from_world = f.pose()?;
            let n: u32 = f.parse("NUM_DATA_IDS")?;
            let mut data = Vec::new();
            for _ in 0..n {
                let sensor = f.sensor()?;
                data.push((sensor, f.parse("DATA_ID")?));
            }
            f.end()?;
            let frame = FrameRecord {
                loc: Loc::Line(line),
                rig_id,
                rig_from_world,
                data,
            };
            if frames.insert(id, frame).is_some() {
                return Err(f.err(format!("frame id {id} appears twice")));
            }
        }
        lines.check_count(frames.len())?;
        Ok(frames)
    }

    pub(super) fn cameras(
        path: &Path,
        content: &str,
        parsed: &mut Parsed,
    ) -> Result<(), FormatError> {
        let mut lines = Lines::new(path, content, "cameras");
        let mut count = 0;
        while let Some((line, text)) = lines.next_data()? {
            let mut f = Fields::new(path, line, text);
            let id: u32 = f.parse("CAMERA_ID")?;
            let name = f.token("MODEL")?;
            let model =
                CameraModel::from_name(name).map_err(|e| f.err(format!("camera {id}: {e}")))?;
            let width: u32 = f.parse("WIDTH")?;
            let height: u32 = f.parse("HEIGHT")?;
            let mut params = Vec::with_capacity(model.num_params());
            while !f.is_empty() {
                params.push(f.real("PARAMS[]")?);
            }
            let camera = Camera {
                id,
                model,
                width,
                height,
                params,
            };
            insert_camera(parsed, path, Loc::Line(line), camera)?;
            count += 1;
        }
        lines.check_count(count)
    }

    pub(super) fn images(
        path: &Path,
        content: &str,
        parsed: &mut Parsed,
    ) -> Result<(), FormatError> {
        let mut lines = Lines::new(path, content, "images");
        let mut count = 0;
        while let Some((line, text)) = lines.next_data()? {
            let mut f = Fields::new(path, line, text);
            let id: u32 = f.parse("IMAGE_ID")?;
            let pose = f.pose()?;
            let camera_id: u32 = f.parse("CAMERA_ID")?;
            let name = f.rest("NAME")?.to_string();
            let Some((kp_line, kp_text)) = lines.next_raw() else {
                return Err(FormatError::text(
                    path,
                    line + 1,
                    format!("file ends before the POINTS2D line of image {id}"),
                ));
            };
            let mut f = Fields::new(path, kp_line, kp_text);
            let mut keypoints = Vec::new();
            let mut point3d_ids = Vec::new();
            while !f.is_empty() {
                let x = f.real("X")?;
                let y = f.real("Y")?;
                let token = f.token("POINT3D_ID (POINTS2D holds X, Y, POINT3D_ID triples)")?;
                let point3d_id = match token {
                    "-1" => None,
                    _ => match token.parse::<u64>() {
                        Ok(u64::MAX) => None,
                        Ok(id) => Some(id),
                        Err(_) => {
                            return Err(f.err(format!(
                                "POINT3D_ID: expected an id or -1, found {token:?}"
                            )));
                        }
                    },
                };
                keypoints.push(Point2::new(x, y));
                point3d_ids.push(point3d_id);
            }
            let image = Image {
                id,
                name,
                camera_id,
                cam_from_world: CamFromWorld(pose),
                keypoints,
                point3d_ids,
            };
            insert_image(parsed, path, (Loc::Line(line), Loc::Line(kp_line)), image)?;
            count += 1;
        }
        lines.check_count(count)
    }

    pub(super) fn points(
        path: &Path,
        content: &str,
        parsed: &mut Parsed,
    ) -> Result<(), FormatError> {
        let mut lines = Lines::new(path, content, "points");
        let mut count = 0;
        while let Some((line, text)) = lines.next_data()? {
            let mut f = Fields::new(path, line, text);
            let id: u64 = f.parse("POINT3D_ID")?;
            let position = Point3::new(f.real("X")?, f.real("Y")?, f.real("Z")?);
            let color = [f.parse("R")?, f.parse("G")?, f.parse("B")?];
            let error = f.real("ERROR")?;
            let mut track = Vec::new();
            while !f.is_empty() {
                let image_id = f.parse("IMAGE_ID")?;
                let point2d_idx =
                    f.parse("POINT2D_IDX (TRACK holds IMAGE_ID, POINT2D_IDX pairs)")?;
                track.push(TrackElement {
                    image_id,
                    point2d_idx,
                });
            }
            let point = Point3D {
                id,
                position,
                color,
                error,
                track,
            };
            insert_point(parsed, path, Loc::Line(line), point)?;
            count += 1;
        }
        lines.check_count(count)
    }
}

// ---------------------------------------------------------------------------------------
// Binary reading.

mod binary {
    use super::*;

    /// A little-endian cursor over a whole file; errors name the byte offset.
    pub(super) struct Bytes<'a> {
        path: &'a Path,
        data: &'a [u8],
        pos: usize,
    }

    impl<'a> Bytes<'a> {
        pub(super) fn new(path: &'a Path, data: &'a [u8]) -> Bytes<'a> {
            Bytes { path, data, pos: 0 }
        }

        pub(super) fn offset(&self) -> u64 {
            self.pos as u64
        }

        pub(super) fn err_at(&self, offset: u64, message: impl Into<String>) -> FormatError {
            FormatError::binary(self.path, offset, message)
        }

        fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], FormatError> {
            let end = self.pos + N;
            if end > self.data.len() {
                return Err(self.err_at(
                    self.offset(),
                    format!(
                        "file is truncated: {what} needs {N} bytes, {} left",
                        self.data.len() - self.pos
                    ),
                ));
            }
            let bytes: [u8; N] = self.data[self.pos..end].try_into().expect("N bytes");
            self.pos = end;
            Ok(bytes)
        }

        pub(super) fn u8(&mut self, what: &str) -> Result<u8, FormatError> {
            Ok(self.take::<1>(what)?[0])
        }
        pub(super) fn u32(&mut self, what: &str) -> Result<u32, FormatError> {
            Ok(u32::from_le_bytes(self.take(what)?))
        }
        pub(super) fn i32(&mut self, what: &str) -> Result<i32, FormatError> {
            Ok(i32::from_le_bytes(self.take(what)?))
        }
        pub(super) fn u64(&mut self, what: &str) -> Result<u64, FormatError> {
            Ok(u64::from_le_bytes(self.take(what)?))
        }

        /// A finite f64 (NaN and infinities are errors).
        pub(super) fn real(&mut self, what: &str) -> Result<f64, FormatError> {
            let at = self.offset();
            let x = f64::from_le_bytes(self.take(what)?);
            if x.is_finite() {
                Ok(x)
            } else {
                Err(self.err_at(at, format!("{what} is not a finite number: {x}")))
            }
        }

        pub(super) fn pose(&mut self) -> Result<Rigid3, FormatError> {
            let at = self.offset();
            let mut v = [0.0; 7];
            for (x, what) in v.iter_mut().zip(["qw", "qx", "qy", "qz", "tx", "ty", "tz"]) {
                *x = self.real(what)?;
            }
            rigid_from_values(v).map_err(|m| self.err_at(at, m))
        }

        pub(super) fn sensor(&mut self) -> Result<SensorId, FormatError> {
            let at = self.offset();
            let code = self.i32("sensor type")?;
            let kind = SensorType::from_code(code)
                .ok_or_else(|| self.err_at(at, format!("unknown sensor type {code}")))?;
            Ok((kind, self.u32("sensor id")?))
        }

        /// A NUL-terminated UTF-8 string.
        pub(super) fn name(&mut self) -> Result<String, FormatError> {
            let at = self.offset();
            let rest = &self.data[self.pos..];
            let Some(len) = rest.iter().position(|&b| b == 0) else {
                return Err(self.err_at(at, "file is truncated: image name has no terminating NUL"));
            };
            let name = std::str::from_utf8(&rest[..len])
                .map_err(|_| self.err_at(at, "image name is not valid UTF-8"))?
                .to_string();
            self.pos += len + 1;
            Ok(name)
        }

        /// A `u64` element count, checked against the bytes left (each element takes at
        /// least `min_size` bytes), so that a corrupt count fails here and nothing is
        /// allocated from it.
        pub(super) fn count(&mut self, what: &str, min_size: usize) -> Result<usize, FormatError> {
            let at = self.offset();
            let n = self.u64(what)?;
            let left = (self.data.len() - self.pos) as u64;
            if n.checked_mul(min_size as u64)
                .is_none_or(|need| need > left)
            {
                return Err(self.err_at(
                    at,
                    format!("{what} is {n}, but only {left} bytes follow (at least {min_size} per element): truncated file or bad header"),
                ));
            }
            Ok(n as usize)
        }

        /// After the last element: nothing may follow.
        pub(super) fn finish(&self, n: usize, what: &str) -> Result<(), FormatError> {
            if self.pos == self.data.len() {
                Ok(())
            } else {
                Err(self.err_at(
                    self.offset(),
                    format!(
                        "{} bytes follow the {n} {what} the header announces (wrong count)",
                        self.data.len() - self.pos
                    ),
                ))
            }
        }
    }

    pub(super) fn rigs(path: &Path, data: &[u8]) -> Result<HashMap<u32, RigRecord>, FormatError> {
        let mut b = Bytes::new(path, data);
        let n = b.count("number of rigs", 8)?;
        let mut rigs = HashMap::with_capacity(n);
        for _ in 0..n {
            let at = b.offset();
            let id = b.u32("rig id")?;
            let num_sensors = b.u32("number of sensors")?;
            let mut rig = RigRecord {
                loc: Loc::Offset(at),
                ref_sensor: None,
                sensors: Vec::new(),
            };
            if num_sensors > 0 {
                rig.ref_sensor = Some(b.sensor()?);
            }
            for _ in 1..num_sensors.max(1) {
                let sensor = b.sensor()?;
                let flag_at = b.offset();
                let pose = match b.u8("has_pose")? {
                    0 => None,
                    1 => Some(b.pose()?),
                    other => {
                        return Err(
                            b.err_at(flag_at, format!("has_pose must be 0 or 1, found {other}"))
                        );
                    }
                };
                rig.sensors.push((sensor, pose));
            }
            if rigs.insert(id, rig).is_some() {
                return Err(b.err_at(at, format!("rig id {id} appears twice")));
            }
        }
        b.finish(n, "rigs")?;
        Ok(rigs)
    }

    pub(super) fn frames(
        path: &Path,
        data: &[u8],
    ) -> Result<HashMap<u32, FrameRecord>, FormatError> {
        let mut b = Bytes::new(path, data);
        let n = b.count("number of frames", 68)?;
        let mut frames = HashMap::with_capacity(n);
        for _ in 0..n {
            let at = b.offset();
            let id = b.u32("frame id")?;
            let rig_id = b.u32("rig id")?;
            let rig_from_world = b.pose()?;
            let num = b.u32("number of data ids")? as usize;
            let mut data = Vec::new();
            for _ in 0..num {
                let sensor = b.sensor()?;
                data.push((sensor, b.u64("data id")?));
            }
            let frame = FrameRecord {
                loc: Loc::Offset(at),
                rig_id,
                rig_from_world,
                data,
            };
            if frames.insert(id, frame).is_some() {
                return Err(b.err_at(at, format!("frame id {id} appears twice")));
            }
        }
        b.finish(n, "frames")?;
        Ok(frames)
    }

    pub(super) fn cameras(
        path: &Path,
        data: &[u8],
        parsed: &mut Parsed,
    ) -> Result<(), FormatError> {
        let mut b = Bytes::new(path, data);
        let n = b.count("number of cameras", 24)?;
        for _ in 0..n {
            let at = b.offset();
            let id = b.u32("camera id")?;
            let model_at = b.offset();
            let code = b.i32("camera model id")?;
            let model = CameraModel::from_id(code)
                .map_err(|e| b.err_at(model_at, format!("camera {id}: {e}")))?;
            let size_at = b.offset();
            let (w, h) = (b.u64("width")?, b.u64("height")?);
            let (Ok(width), Ok(height)) = (u32::try_from(w), u32::try_from(h)) else {
                return Err(b.err_at(
                    size_at,
                    format!("camera {id}: size {w}x{h} is out of range"),
                ));
            };
            let mut params = Vec::with_capacity(model.num_params());
            for name in model.param_names() {
                params.push(b.real(name)?);
            }
            let camera = Camera {
                id,
                model,
                width,
                height,
                params,
            };
            insert_camera(parsed, path, Loc::Offset(at), camera)?;
        }
        b.finish(n, "cameras")
    }

    pub(super) fn images(path: &Path, data: &[u8], parsed: &mut Parsed) -> Result<(), FormatError> {
        let mut b = Bytes::new(path, data);
        // id, pose, camera id, NUL, keypoint count.
        let n = b.count("number of images", 4 + 56 + 4 + 1 + 8)?;
        for _ in 0..n {
            let at = b.offset();
            let id = b.u32("image id")?;
            let pose = b.pose()?;
            let camera_id = b.u32("camera id")?;
            let name = b.name()?;
            let kp_at = b.offset();
            let num = b.count("number of points2D", 24)?;
            let mut keypoints = Vec::with_capacity(num);
            let mut point3d_ids = Vec::with_capacity(num);
            for _ in 0..num {
                keypoints.push(Point2::new(b.real("x")?, b.real("y")?));
                let id = b.u64("point3D id")?;
                point3d_ids.push((id != u64::MAX).then_some(id));
            }
            let image = Image {
                id,
                name,
                camera_id,
                cam_from_world: CamFromWorld(pose),
                keypoints,
                point3d_ids,
            };
            insert_image(parsed, path, (Loc::Offset(at), Loc::Offset(kp_at)), image)?;
        }
        b.finish(n, "images")
    }

    pub(super) fn points(path: &Path, data: &[u8], parsed: &mut Parsed) -> Result<(), FormatError> {
        let mut b = Bytes::new(path, data);
        // id, xyz, rgb, error, track length.
        let n = b.count("number of points3D", 8 + 24 + 3 + 8 + 8)?;
        for _ in 0..n {
            let at = b.offset();
            let id = b.u64("point3D id")?;
            let position = Point3::new(b.real("x")?, b.real("y")?, b.real("z")?);
            let color = [b.u8("r")?, b.u8("g")?, b.u8("b")?];
            let error = b.real("error")?;
            let len = b.count("track length", 8)?;
            let mut track = Vec::with_capacity(len);
            for _ in 0..len {
                track.push(TrackElement {
                    image_id: b.u32("track image id")?,
                    point2d_idx: b.u32("track point2D index")?,
                });
            }
            let point = Point3D {
                id,
                position,
                color,
                error,
                track,
            };
            insert_point(parsed, path, Loc::Offset(at), point)?;
        }
        b.finish(n, "points3D")
    }
}

// ---------------------------------------------------------------------------------------
// Writing.

type FileWriter = fn(&Reconstruction, ModelFormat, &mut dyn Write) -> std::io::Result<()>;

/// What the writer refuses: inconsistent models and names the formats cannot hold.
fn check_writable(rec: &Reconstruction, dir: &Path) -> Result<(), FormatError> {
    rec.validate().map_err(|e| {
        FormatError::invalid(dir, format!("cannot write an inconsistent model: {e}"))
    })?;
    for image in rec.images.values() {
        let name = &image.name;
        if name.is_empty() || name.trim() != name || name.contains(['\n', '\r', '\0']) {
            return Err(FormatError::invalid(
                dir,
                format!(
                    "image {}: name {name:?} cannot be stored (empty, surrounding whitespace, line break or NUL)",
                    image.id
                ),
            ));
        }
        let t = &image.cam_from_world.0;
        if !t
            .translation
            .iter()
            .chain(t.rotation.coords.iter())
            .all(|x| x.is_finite())
        {
            return Err(FormatError::invalid(
                dir,
                format!("image {}: pose is not finite", image.id),
            ));
        }
    }
    if let Some(p) = rec.points3d.values().find(|p| !p.error.is_finite()) {
        return Err(FormatError::invalid(
            dir,
            format!("point3D {}: error {} is not finite", p.id, p.error),
        ));
    }
    Ok(())
}

/// `x` as C++ streams print a double at precision 17 (`%.17g`): 17 significant digits,
/// fixed notation for decimal exponents in [-4, 17), else `d.ddde±XX`; trailing zeros (and
/// a trailing point) removed. This is what makes text files byte-identical to COLMAP's.
fn push_g17(out: &mut String, x: f64) {
    if x == 0.0 {
        out.push_str(if x.is_sign_negative() { "-0" } else { "0" });
        return;
    }
    if !x.is_finite() {
        out.push_str(if x.is_nan() {
            "nan"
        } else if x > 0.0 {
            "inf"
        } else {
            "-inf"
        });
        return;
    }
    // Rust's `{:.16e}` rounds correctly to 17 significant digits, as glibc's printf does.
    let mut sci = String::with_capacity(32);
    let _ = write!(sci, "{:.16e}", x.abs());
    let (mantissa, exp) = sci.split_once('e').expect("exponent");
    let exp: i32 = exp.parse().expect("integer exponent");
    let digits: Vec<u8> = mantissa.bytes().filter(u8::is_ascii_digit).collect();
    if x < 0.0 {
        out.push('-');
    }
    let start = out.len();
    if (-4..17).contains(&exp) {
        if exp >= 0 {
            let int_len = exp as usize + 1;
            out.extend(digits[..int_len].iter().map(|&d| d as char));
            out.push('.');
            out.extend(digits[int_len..].iter().map(|&d| d as char));
        } else {
            out.push_str("0.");
            out.extend(std::iter::repeat_n('0', (-exp - 1) as usize));
            out.extend(digits.iter().map(|&d| d as char));
        }
        trim_fraction(out, start);
    } else {
        out.push(digits[0] as char);
        out.push('.');
        out.extend(digits[1..].iter().map(|&d| d as char));
        trim_fraction(out, start);
        let _ = write!(out, "e{}{:02}", if exp < 0 { '-' } else { '+' }, exp.abs());
    }
}

/// Removes trailing zeros of a fraction written from `start` on, and the point if bare.
fn trim_fraction(out: &mut String, start: usize) {
    if out[start..].contains('.') {
        let trimmed = out.trim_end_matches('0').len();
        out.truncate(trimmed);
        if out.ends_with('.') {
            out.pop();
        }
    }
}

fn push_pose_g17(line: &mut String, pose: &Rigid3) {
    let q = pose.rotation.quaternion();
    for v in [q.w, q.i, q.j, q.k] {
        push_g17(line, v);
        line.push(' ');
    }
    let t = pose.translation;
    for v in [t.x, t.y, t.z] {
        push_g17(line, v);
        line.push(' ');
    }
}

fn put_pose(out: &mut dyn Write, pose: &Rigid3) -> std::io::Result<()> {
    let q = pose.rotation.quaternion();
    for v in [
        q.w,
        q.i,
        q.j,
        q.k,
        pose.translation.x,
        pose.translation.y,
        pose.translation.z,
    ] {
        out.write_all(&v.to_le_bytes())?;
    }
    Ok(())
}

/// COLMAP's `CAMERA` sensor type.
const SENSOR_CAMERA: i32 = 0;

fn write_rigs(
    rec: &Reconstruction,
    format: ModelFormat,
    out: &mut dyn Write,
) -> std::io::Result<()> {
    match format {
        ModelFormat::Text => {
            let mut s = String::new();
            s.push_str("# Rig calib list with one line of data per calib:\n");
            s.push_str("#   RIG_ID, NUM_SENSORS, REF_SENSOR_TYPE, REF_SENSOR_ID, SENSORS[] as (SENSOR_TYPE, SENSOR_ID, HAS_POSE, [QW, QX, QY, QZ, TX, TY, TZ])\n");
            let _ = writeln!(s, "# Number of rigs: {}", rec.cameras.len());
            for &id in rec.cameras.keys() {
                let _ = writeln!(s, "{id} 1 CAMERA {id}");
            }
            out.write_all(s.as_bytes())
        }
        ModelFormat::Binary => {
            out.write_all(&(rec.cameras.len() as u64).to_le_bytes())?;
            for &id in rec.cameras.keys() {
                out.write_all(&id.to_le_bytes())?;
                out.write_all(&1u32.to_le_bytes())?;
                out.write_all(&SENSOR_CAMERA.to_le_bytes())?;
                out.write_all(&id.to_le_bytes())?;
            }
            Ok(())
        }
    }
}

fn write_cameras(
    rec: &Reconstruction,
    format: ModelFormat,
    out: &mut dyn Write,
) -> std::io::Result<()> {
    match format {
        ModelFormat::Text => {
            let mut s = String::new();
            s.push_str("# Camera list with one line of data per camera:\n");
            s.push_str("#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
            let _ = writeln!(s, "# Number of cameras: {}", rec.cameras.len());
            for (id, cam) in &rec.cameras {
                let _ = write!(s, "{id} {} {} {}", cam.model.name(), cam.width, cam.height);
                for &p in &cam.params {
                    s.push(' ');
                    push_g17(&mut s, p);
                }
                s.push('\n');
            }
            out.write_all(s.as_bytes())
        }
        ModelFormat::Binary => {
            out.write_all(&(rec.cameras.len() as u64).to_le_bytes())?;
            for (id, cam) in &rec.cameras {
                out.write_all(&id.to_le_bytes())?;
                out.write_all(&cam.model.id().to_le_bytes())?;
                out.write_all(&(cam.width as u64).to_le_bytes())?;
                out.write_all(&(cam.height as u64).to_le_bytes())?;
                for &p in &cam.params {
                    out.write_all(&p.to_le_bytes())?;
                }
            }
            Ok(())
        }
    }
}

fn write_frames(
    rec: &Reconstruction,
    format: ModelFormat,
    out: &mut dyn Write,
) -> std::io::Result<()> {
    match format {
        ModelFormat::Text => {
            let mut s = String::new();
            s.push_str("# Frame list with one line of data per frame:\n");
            s.push_str("#   FRAME_ID, RIG_ID, RIG_FROM_WORLD[QW, QX, QY, QZ, TX, TY, TZ], NUM_DATA_IDS, DATA_IDS[] as (SENSOR_TYPE, SENSOR_ID, DATA_ID)\n");
            let _ = writeln!(s, "# Number of frames: {}", rec.images.len());
            for (id, im) in &rec.images {
                let _ = write!(s, "{id} {} ", im.camera_id);
                push_pose_g17(&mut s, &im.cam_from_world.0);
                let _ = writeln!(s, "1 CAMERA {} {id}", im.camera_id);
                if s.len() > 1 << 16 {
                    out.write_all(s.as_bytes())?;
                    s.clear();
                }
            }
            out.write_all(s.as_bytes())
        }
        ModelFormat::Binary => {
            out.write_all(&(rec.images.len() as u64).to_le_bytes())?;
            for (id, im) in &rec.images {
                out.write_all(&id.to_le_bytes())?;
                out.write_all(&im.camera_id.to_le_bytes())?;
                put_pose(out, &im.cam_from_world.0)?;
                out.write_all(&1u32.to_le_bytes())?;
                out.write_all(&SENSOR_CAMERA.to_le_bytes())?;
                out.write_all(&im.camera_id.to_le_bytes())?;
                out.write_all(&(*id as u64).to_le_bytes())?;
            }
            Ok(())
        }
    }
}

fn write_images(
    rec: &Reconstruction,
    format: ModelFormat,
    out: &mut dyn Write,
) -> std::io::Result<()> {
    match format {
        ModelFormat::Text => {
            let mut s = String::new();
            s.push_str("# Image list with two lines of data per image:\n");
            s.push_str("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
            s.push_str("#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
            let mean = if rec.images.is_empty() {
                0.0
            } else {
                rec.num_observations() as f64 / rec.images.len() as f64
            };
            let _ = write!(
                s,
                "# Number of images: {}, mean observations per image: ",
                rec.images.len()
            );
            push_g17(&mut s, mean);
            s.push('\n');
            for (id, im) in &rec.images {
                let _ = write!(s, "{id} ");
                push_pose_g17(&mut s, &im.cam_from_world.0);
                let _ = writeln!(s, "{} {}", im.camera_id, im.name);
                // COLMAP ends a non-empty keypoint line with a space.
                for (kp, p3d) in im.keypoints.iter().zip(&im.point3d_ids) {
                    push_g17(&mut s, kp.x);
                    s.push(' ');
                    push_g17(&mut s, kp.y);
                    match p3d {
                        Some(p) => {
                            let _ = write!(s, " {p} ");
                        }
                        None => s.push_str(" -1 "),
                    }
                    if s.len() > 1 << 16 {
                        out.write_all(s.as_bytes())?;
                        s.clear();
                    }
                }
                s.push('\n');
            }
            out.write_all(s.as_bytes())
        }
        ModelFormat::Binary => {
            out.write_all(&(rec.images.len() as u64).to_le_bytes())?;
            for (id, im) in &rec.images {
                out.write_all(&id.to_le_bytes())?;
                put_pose(out, &im.cam_from_world.0)?;
                out.write_all(&im.camera_id.to_le_bytes())?;
                out.write_all(im.name.as_bytes())?;
                out.write_all(&[0])?;
                out.write_all(&(im.keypoints.len() as u64).to_le_bytes())?;
                for (kp, p3d) in im.keypoints.iter().zip(&im.point3d_ids) {
                    out.write_all(&kp.x.to_le_bytes())?;
                    out.write_all(&kp.y.to_le_bytes())?;
                    out.write_all(&p3d.unwrap_or(u64::MAX).to_le_bytes())?;
                }
            }
            Ok(())
        }
    }
}

fn write_points(
    rec: &Reconstruction,
    format: ModelFormat,
    out: &mut dyn Write,
) -> std::io::Result<()> {
    match format {
        ModelFormat::Text => {
            let mut s = String::new();
            s.push_str("# 3D point list with one line of data per point:\n");
            s.push_str(
                "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
            );
            let mean = if rec.points3d.is_empty() {
                0.0
            } else {
                rec.num_observations() as f64 / rec.points3d.len() as f64
            };
            let _ = write!(
                s,
                "# Number of points: {}, mean track length: ",
                rec.points3d.len()
            );
            push_g17(&mut s, mean);
            s.push('\n');
            for (id, p) in &rec.points3d {
                let _ = write!(s, "{id} ");
                for v in [p.position.x, p.position.y, p.position.z] {
                    push_g17(&mut s, v);
                    s.push(' ');
                }
                let _ = write!(s, "{} {} {} ", p.color[0], p.color[1], p.color[2]);
                push_g17(&mut s, p.error);
                // COLMAP writes "ERROR " and then the track without its trailing space.
                s.push(' ');
                for (i, el) in p.track.iter().enumerate() {
                    if i > 0 {
                        s.push(' ');
                    }
                    let _ = write!(s, "{} {}", el.image_id, el.point2d_idx);
                }
                s.push('\n');
                if s.len() > 1 << 16 {
                    out.write_all(s.as_bytes())?;
                    s.clear();
                }
            }
            out.write_all(s.as_bytes())
        }
        ModelFormat::Binary => {
            out.write_all(&(rec.points3d.len() as u64).to_le_bytes())?;
            for (id, p) in &rec.points3d {
                out.write_all(&id.to_le_bytes())?;
                for v in [p.position.x, p.position.y, p.position.z] {
                    out.write_all(&v.to_le_bytes())?;
                }
                out.write_all(&p.color)?;
                out.write_all(&p.error.to_le_bytes())?;
                out.write_all(&(p.track.len() as u64).to_le_bytes())?;
                for el in &p.track {
                    out.write_all(&el.image_id.to_le_bytes())?;
                    out.write_all(&el.point2d_idx.to_le_bytes())?;
                }
            }
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::push_g17;

    /// Expected strings from C's `printf("%.17g")` (Python's `'%.17g' % x`).
    #[test]
    fn numbers_print_like_cpp_streams_at_precision_17() {
        let cases: [(f64, &str); 21] = [
            (0.1, "0.10000000000000001"),
            (-0.0, "-0"),
            (0.0, "0"),
            (1e-05, "1.0000000000000001e-05"),
            (1e20, "1e+20"),
            (1.5e17, "1.5e+17"),
            (1e17, "1e+17"),
            (1e16, "10000000000000000"),
            (1.2345678901234568e17, "1.2345678901234568e+17"),
            (0.0001, "0.0001"),
            (0.00012345, "0.00012344999999999999"),
            (-2.0, "-2"),
            (5.115384615384615, "5.115384615384615"),
            (1.0 / 3.0, "0.33333333333333331"),
            (5e-324, "4.9406564584124654e-324"),
            (1.7976931348623157e308, "1.7976931348623157e+308"),
            (-1e-300, "-1e-300"),
            (100.0, "100"),
            (0.00030000000000000003, "0.00030000000000000003"),
            (12345.678, "12345.678"),
            (0.5, "0.5"),
        ];
        for (x, expected) in cases {
            let mut s = String::new();
            push_g17(&mut s, x);
            assert_eq!(s, expected, "{x:e}");
            // And it reads back to the same bits.
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits());
        }
    }
}
