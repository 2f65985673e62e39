//! Focal-length priors in pixels, from a K file, EXIF, or COLMAP's default, with the source named.
//!
//! In order of trust:
//! 1. a calibration file (`K.txt`, 3x3 matrix as OpenMVG and the sceaux set ship it);
//! 2. EXIF `FocalLengthIn35mmFilm`: the 35 mm equivalent is defined on the diagonal (CIPA
//!    DC-008), so `f_px = f35 / 43.27 * diagonal_px`. For 3:2 photos this is exactly the usual
//!    `f35 / 36 * max(w, h)`; for 4:3 photos it is 4% larger and closer to calibrated values
//!    (sceaux: K.txt 2906 px, diagonal rule 2865, width rule 2753);
//! 3. EXIF `FocalLength` (mm) with the sensor width: from `FocalPlaneXResolution` (pixels per
//!    unit of `FocalPlaneResolutionUnit`, rescaled from `PixelXDimension` to the stored width) or
//!    from a small table of camera models;
//! 4. none of these: `1.2 * max(w, h)`, COLMAP's default, marked as not a real prior.

use std::path::Path;

use exif::{In, Tag, Value};
use serde::{Deserialize, Serialize};

/// Where a focal length came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FocalSource {
    /// A calibration file (`K.txt`).
    CalibrationFile,
    /// EXIF `FocalLengthIn35mmFilm`.
    Exif35mm,
    /// EXIF `FocalLength` with the sensor width from `FocalPlaneXResolution`.
    ExifFocalPlane,
    /// EXIF `FocalLength` with the sensor width from the camera-model table.
    ExifSensorTable,
    /// No information: `1.2 * max(width, height)`.
    Default,
    /// No information in the photos; estimated from the fundamental matrices of the verified
    /// pairs before mapping (`focal_from_f.rs`), because it differed from the default.
    #[serde(rename = "F-estimate")]
    FEstimate,
}

impl FocalSource {
    /// True when the focal length is measured information (everything but [`FocalSource::Default`]):
    /// two-view geometry then uses the essential matrix.
    pub fn is_prior(self) -> bool {
        self != FocalSource::Default
    }
}

/// A pinhole guess for one photo: focal length and principal point in pixels (COLMAP convention:
/// pixel centres at half-integers), and where the focal length came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FocalPrior {
    pub focal_x: f64,
    pub focal_y: f64,
    pub cx: f64,
    pub cy: f64,
    pub source: FocalSource,
}

/// EXIF fields that matter for the prior, as read from a photo.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExifCamera {
    pub make: Option<String>,
    pub model: Option<String>,
    pub focal_length_mm: Option<f64>,
    pub focal_length_35mm: Option<f64>,
    /// Focal-plane pixels per millimetre along x, with the image width it refers to.
    pub focal_plane_px_per_mm: Option<f64>,
    pub exif_width: Option<u32>,
}

/// Reads the fields of [`ExifCamera`] from a raw EXIF block (TIFF layout). A block that does not
/// parse gives an empty `ExifCamera`: EXIF is a hint, never a reason to reject a photo.
pub fn parse_exif(raw: &[u8]) -> ExifCamera {
    let Ok(exif) = exif::Reader::new().read_raw(raw.to_vec()) else {
        return ExifCamera::default();
    };
    let field = |tag| exif.get_field(tag, In::PRIMARY).map(|f| &f.value);
    let number = |tag| -> Option<f64> {
        match field(tag)? {
            Value::Rational(v) => v.first().map(|r| r.to_f64()),
            Value::SRational(v) => v.first().map(|r| r.to_f64()),
            v => v.get_uint(0).map(f64::from),
        }
        .filter(|x| x.is_finite() && *x > 0.0)
    };
    let text = |tag| -> Option<String> {
        match field(tag)? {
            Value::Ascii(v) => v.first().map(|s| {
                String::from_utf8_lossy(s)
                    .trim_matches(|c: char| c == '\0' || c.is_whitespace())
                    .to_string()
            }),
            _ => None,
        }
        .filter(|s| !s.is_empty())
    };
    // FocalPlaneResolutionUnit: 2 = inch (the default), 3 = cm, 4 = mm, 5 = um (some vendors).
    let unit_mm = match field(Tag::FocalPlaneResolutionUnit).and_then(|v| v.get_uint(0)) {
        Some(3) => 10.0,
        Some(4) => 1.0,
        Some(5) => 0.001,
        _ => 25.4,
    };
    ExifCamera {
        make: text(Tag::Make),
        model: text(Tag::Model),
        focal_length_mm: number(Tag::FocalLength),
        focal_length_35mm: number(Tag::FocalLengthIn35mmFilm),
        focal_plane_px_per_mm: number(Tag::FocalPlaneXResolution).map(|r| r / unit_mm),
        exif_width: number(Tag::PixelXDimension).map(|w| w as u32),
    }
}

/// The focal prior of a `width` x `height` photo from its EXIF fields (steps 2-4 of the module
/// documentation). The principal point is the image centre.
pub fn focal_from_exif(exif: &ExifCamera, width: u32, height: u32) -> FocalPrior {
    let (w, h) = (width as f64, height as f64);
    let centred = |f: f64, source| FocalPrior {
        focal_x: f,
        focal_y: f,
        cx: w / 2.0,
        cy: h / 2.0,
        source,
    };
    // The 35 mm frame is 36 x 24 mm; its diagonal is 43.267 mm.
    const FULL_FRAME_DIAGONAL_MM: f64 = 43.266_615;
    if let Some(f35) = exif.focal_length_35mm {
        return centred(
            f35 / FULL_FRAME_DIAGONAL_MM * w.hypot(h),
            FocalSource::Exif35mm,
        );
    }
    if let Some(f_mm) = exif.focal_length_mm {
        if let Some(px_per_mm) = exif.focal_plane_px_per_mm {
            // The resolution refers to the sensor read-out of `exif_width` pixels; a resized photo
            // has proportionally fewer pixels per mm.
            let rescale = exif
                .exif_width
                .filter(|&ew| ew > 0)
                .map_or(1.0, |ew| w.max(h) / f64::from(ew).max(1.0));
            let f = f_mm * px_per_mm * rescale;
            if f.is_finite() && f > 0.05 * w.max(h) && f < 50.0 * w.max(h) {
                return centred(f, FocalSource::ExifFocalPlane);
            }
        }
        if let Some(sensor_mm) = sensor_width_mm(exif.make.as_deref(), exif.model.as_deref()) {
            return centred(f_mm / sensor_mm * w.max(h), FocalSource::ExifSensorTable);
        }
    }
    centred(1.2 * w.max(h), FocalSource::Default)
}

/// Sensor widths (mm) of some camera models: (make prefix, model substring, width).
/// A small table in the spirit of COLMAP's, enough for the bundled data and common phones.
const SENSOR_WIDTHS: &[(&str, &str, f64)] = &[
    ("eastman kodak", "z612", 5.75),
    ("canon", "eos 5d", 36.0),
    ("canon", "eos 6d", 35.8),
    ("canon", "eos 7d", 22.3),
    ("canon", "eos 40d", 22.2),
    ("canon", "eos 450d", 22.2),
    ("canon", "powershot g12", 7.44),
    ("nikon", "d700", 36.0),
    ("nikon", "d800", 35.9),
    ("nikon", "d90", 23.6),
    ("nikon", "d7000", 23.6),
    ("sony", "nex-5", 23.4),
    ("sony", "dsc-rx100", 13.2),
    ("panasonic", "dmc-gh2", 17.3),
    ("olympus", "e-m5", 17.3),
    ("apple", "iphone 4", 4.54),
    ("apple", "iphone 5", 4.54),
    ("apple", "iphone 6", 4.8),
    ("samsung", "gt-i9300", 4.54),
    ("gopro", "hero3", 6.17),
];

/// The sensor width of a camera model from [`SENSOR_WIDTHS`], matched case-insensitively.
pub fn sensor_width_mm(make: Option<&str>, model: Option<&str>) -> Option<f64> {
    let make = make?.to_lowercase();
    let model = model?.to_lowercase();
    SENSOR_WIDTHS
        .iter()
        .find(|(mk, md, _)| make.starts_with(mk) && model.contains(md))
        .map(|&(_, _, w)| w)
}

/// Why a calibration file was not usable.
pub type CalibrationError = fresco_core::FormatError;

/// Reads a 3x3 intrinsic matrix (OpenMVG/OpenCV `K.txt`: three rows of three numbers) for a
/// `width` x `height` photo. OpenCV puts pixel centres on integers, so 0.5 is added to the
/// principal point (house convention). A matrix whose principal point is more than a quarter of
/// the photo's size from its centre, or with a non-positive focal length, is an error: it most
/// likely belongs to photos of another size (a downscaled copy of the set).
pub fn read_calibration_file(
    path: &Path,
    width: u32,
    height: u32,
) -> Result<FocalPrior, CalibrationError> {
    use fresco_core::FormatError;
    let text = std::fs::read_to_string(path).map_err(|e| FormatError::io(path, e))?;
    let mut values = Vec::with_capacity(9);
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        for token in line.split(|c: char| c.is_whitespace() || c == ',') {
            if token.is_empty() {
                continue;
            }
            let v: f64 = token.parse().map_err(|_| {
                FormatError::text(path, i + 1, format!("'{token}' is not a number"))
            })?;
            values.push(v);
        }
    }
    if values.len() != 9 {
        return Err(FormatError::invalid(
            path,
            format!("expected 9 numbers (a 3x3 matrix), found {}", values.len()),
        ));
    }
    let (fx, fy, cx, cy) = (values[0], values[4], values[2] + 0.5, values[5] + 0.5);
    if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite()) {
        return Err(FormatError::invalid(path, "focal lengths must be positive"));
    }
    let (w, h) = (width as f64, height as f64);
    if !((cx - w / 2.0).abs() <= 0.25 * w && (cy - h / 2.0).abs() <= 0.25 * h) {
        return Err(FormatError::invalid(
            path,
            format!(
                "principal point ({cx}, {cy}) is far from the centre of the {width}x{height} \
                 photo: the matrix belongs to photos of another size"
            ),
        ));
    }
    Ok(FocalPrior {
        focal_x: fx,
        focal_y: fy,
        cx,
        cy,
        source: FocalSource::CalibrationFile,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thirty_five_mm_rule_on_3_2_and_4_3_photos() {
        let exif = ExifCamera {
            focal_length_35mm: Some(50.0),
            ..Default::default()
        };
        // 3:2: the diagonal rule equals f35 / 36 * width.
        let p = focal_from_exif(&exif, 3000, 2000);
        assert!(
            (p.focal_x - 50.0 / 36.0 * 3000.0).abs() < 0.1,
            "{}",
            p.focal_x
        );
        assert_eq!(p.source, FocalSource::Exif35mm);
        assert_eq!((p.cx, p.cy), (1500.0, 1000.0));
        // 4:3, 2832x2128 (diagonal 3542.4): 35 mm -> 2865.6 px.
        let q = focal_from_exif(
            &ExifCamera {
                focal_length_35mm: Some(35.0),
                ..Default::default()
            },
            2832,
            2128,
        );
        assert!((q.focal_x - 2865.6).abs() < 0.5, "{}", q.focal_x);
    }

    #[test]
    fn focal_plane_resolution_and_table_and_default() {
        // 5 mm lens, 200 px/mm at 4000 px read-out, photo resized to 2000 px: 500 px.
        let exif = ExifCamera {
            focal_length_mm: Some(5.0),
            focal_plane_px_per_mm: Some(200.0),
            exif_width: Some(4000),
            ..Default::default()
        };
        let p = focal_from_exif(&exif, 2000, 1500);
        assert!((p.focal_x - 500.0).abs() < 1e-9);
        assert_eq!(p.source, FocalSource::ExifFocalPlane);

        let table = ExifCamera {
            make: Some("EASTMAN KODAK COMPANY".into()),
            model: Some("KODAK Z612 ZOOM DIGITAL CAMERA".into()),
            focal_length_mm: Some(5.85),
            ..Default::default()
        };
        let q = focal_from_exif(&table, 2832, 2128);
        assert_eq!(q.source, FocalSource::ExifSensorTable);
        assert!((q.focal_x - 5.85 / 5.75 * 2832.0).abs() < 1e-9);

        let none = focal_from_exif(&ExifCamera::default(), 640, 480);
        assert_eq!(none.source, FocalSource::Default);
        assert_eq!(none.focal_x, 768.0);
        assert!(!none.source.is_prior());
    }

    #[test]
    fn sceaux_photo_exif_gives_a_focal_near_its_calibration() {
        let path = Path::new("/work/shared/datasets/sceaux_castle/images/100_7100.JPG");
        let Ok(photo) = fresco_core::photo::load_photo(path) else {
            eprintln!("skipped: {} not present", path.display());
            return;
        };
        assert_eq!(photo.exif_orientation, Some(1));
        let exif = parse_exif(photo.exif.as_deref().expect("sceaux photos carry EXIF"));
        assert_eq!(exif.focal_length_35mm, Some(35.0));
        assert!(exif.model.as_deref().unwrap().contains("Z612"));
        let prior = focal_from_exif(&exif, photo.width(), photo.height());
        // K.txt says 2905.88 px; the 35 mm equivalent is rounded to whole mm by the camera
        // (35 could be 34.5..35.5, ±1.4%), and the equivalent itself is approximate: 3% is
        // what a prior can promise.
        assert!(
            (prior.focal_x / 2905.88 - 1.0).abs() < 0.03,
            "{}",
            prior.focal_x
        );
    }

    #[test]
    fn calibration_file_is_read_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let k = dir.path().join("K.txt");
        std::fs::write(&k, "2905.88 0 1416 \n0 2905.88 1064\n0 0 1\n").unwrap();
        let p = read_calibration_file(&k, 2832, 2128).unwrap();
        assert_eq!(p.source, FocalSource::CalibrationFile);
        assert_eq!((p.focal_x, p.cx, p.cy), (2905.88, 1416.5, 1064.5));
        // The same matrix for photos downscaled to 1600 px is rejected, not silently used.
        assert!(read_calibration_file(&k, 1600, 1202).is_err());
        std::fs::write(&k, "1 0 1\n0 x 1\n0 0 1\n").unwrap();
        let e = read_calibration_file(&k, 10, 10).unwrap_err().to_string();
        assert!(e.contains("K.txt:2") && e.contains("'x'"), "{e}");
    }
}
