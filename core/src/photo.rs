//! Loading photos: PNG (8 or 16 bit; grey, grey+alpha, RGB or RGBA) and JPEG into an RGB8 image
//! and a grey f32 image, with errors that name the file.
//!
//! EXIF orientation is reported ([`Photo::exif_orientation`]) but NOT applied: pixels stay as
//! stored, like COLMAP, so keypoints, cameras and texture lookups all refer to the stored grid.
//! The raw EXIF block is kept ([`Photo::exif`]) for focal-length priors.
//!
//! Grey is the Rec. 601 luma `0.299 R + 0.587 G + 0.114 B` in [0, 1] (what OpenCV's
//! `cvtColor(..., COLOR_RGB2GRAY)` computes, so feature detectors see the same signal as OpenCV's),
//! computed from the full precision of 16-bit files.

use std::path::{Path, PathBuf};

use image::{DynamicImage, ImageDecoder, ImageReader, RgbImage};

/// Why a photo could not be used.
#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    /// The OS error is part of the message, so it is not also the `source` (see `FormatError`).
    #[error("{path}: cannot read: {error}")]
    Unreadable {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: the file is empty (0 bytes)")]
    EmptyFile { path: PathBuf },
    #[error("{path}: not a decodable image: {message}")]
    Decode { path: PathBuf, message: String },
    #[error("{path}: the image has zero size ({width}x{height} pixels)")]
    ZeroSize {
        path: PathBuf,
        width: u32,
        height: u32,
    },
    #[error(
        "{path}: the image is too small ({width}x{height} pixels, needs at least {min_side} on each side)"
    )]
    TooSmall {
        path: PathBuf,
        width: u32,
        height: u32,
        min_side: u32,
    },
}

/// A grey image with f32 samples in row-major order (`data[y * width + x]`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GreyImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl GreyImage {
    pub fn new(width: usize, height: usize) -> Self {
        GreyImage {
            width,
            height,
            data: vec![0.0; width * height],
        }
    }
    /// The sample at column `x`, row `y`.
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }
    /// Row `y` as a slice.
    #[inline]
    pub fn row(&self, y: usize) -> &[f32] {
        &self.data[y * self.width..(y + 1) * self.width]
    }
}

/// A decoded photo.
#[derive(Clone, Debug)]
pub struct Photo {
    /// Where it was read from.
    pub path: PathBuf,
    /// Colour, 8 bits per channel (16-bit files are rounded, alpha is dropped).
    pub rgb: RgbImage,
    /// Rec. 601 luma in [0, 1], same size as `rgb`.
    pub grey: GreyImage,
    /// EXIF orientation tag (1 = as stored, 2..8 = flips and rotations), if present. Not applied.
    pub exif_orientation: Option<u8>,
    /// The raw EXIF block (TIFF layout, as `kamadak-exif`'s `Reader::read_raw` takes it).
    pub exif: Option<Vec<u8>>,
    /// What the file held, e.g. "Rgb8", "L16" (the `image` crate's colour type).
    pub stored_as: String,
}

impl Photo {
    pub fn width(&self) -> u32 {
        self.rgb.width()
    }
    pub fn height(&self) -> u32 {
        self.rgb.height()
    }
    /// Fails with [`PhotoError::TooSmall`] when a side is below `min_side` pixels.
    pub fn require_min_side(&self, min_side: u32) -> Result<(), PhotoError> {
        if self.width() < min_side || self.height() < min_side {
            return Err(PhotoError::TooSmall {
                path: self.path.clone(),
                width: self.width(),
                height: self.height(),
                min_side,
            });
        }
        Ok(())
    }
}

/// Reads and decodes the photo at `path` (format guessed from its bytes, not its extension).
pub fn load_photo(path: &Path) -> Result<Photo, PhotoError> {
    let bytes = std::fs::read(path).map_err(|error| PhotoError::Unreadable {
        path: path.to_path_buf(),
        error,
    })?;
    decode_photo(&bytes, path)
}

/// Decodes an encoded photo held in memory; `path` names it in errors and in [`Photo::path`].
pub fn decode_photo(bytes: &[u8], path: &Path) -> Result<Photo, PhotoError> {
    let decode_error = |e: &dyn std::fmt::Display| PhotoError::Decode {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    if bytes.is_empty() {
        return Err(PhotoError::EmptyFile {
            path: path.to_path_buf(),
        });
    }
    let reader = ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| decode_error(&e))?;
    if reader.format().is_none() {
        return Err(PhotoError::Decode {
            path: path.to_path_buf(),
            message: "unknown image format (fresco reads PNG and JPEG)".into(),
        });
    }
    let mut decoder = reader.into_decoder().map_err(|e| decode_error(&e))?;
    let (width, height) = decoder.dimensions();
    if width == 0 || height == 0 {
        return Err(PhotoError::ZeroSize {
            path: path.to_path_buf(),
            width,
            height,
        });
    }
    // Metadata errors must not make a readable photo unusable: a broken EXIF block is ignored.
    let exif = decoder.exif_metadata().ok().flatten();
    let exif_orientation = exif
        .as_deref()
        .and_then(image::metadata::Orientation::from_exif_chunk)
        .map(orientation_tag);
    let image = DynamicImage::from_decoder(decoder).map_err(|e| decode_error(&e))?;
    let stored_as = format!("{:?}", image.color());
    let grey = luma_f32(&image);
    let rgb = image.into_rgb8();
    Ok(Photo {
        path: path.to_path_buf(),
        rgb,
        grey,
        exif_orientation,
        exif,
        stored_as,
    })
}

/// The EXIF tag value (1..8) of an orientation.
fn orientation_tag(o: image::metadata::Orientation) -> u8 {
    use image::metadata::Orientation::*;
    match o {
        NoTransforms => 1,
        FlipHorizontal => 2,
        Rotate180 => 3,
        FlipVertical => 4,
        Rotate90FlipH => 5,
        Rotate90 => 6,
        Rotate270FlipH => 7,
        Rotate270 => 8,
    }
}

/// Rec. 601 luma in [0, 1] at the precision of the stored samples.
fn luma_f32(image: &DynamicImage) -> GreyImage {
    use rayon::prelude::*;
    let (w, h) = (image.width() as usize, image.height() as usize);
    let mut grey = GreyImage::new(w, h);
    const R: f32 = 0.299;
    const G: f32 = 0.587;
    const B: f32 = 0.114;
    match image {
        DynamicImage::ImageLuma8(img) => {
            for (g, p) in grey.data.iter_mut().zip(img.as_raw()) {
                *g = *p as f32 / 255.0;
            }
        }
        DynamicImage::ImageLuma16(img) => {
            for (g, p) in grey.data.iter_mut().zip(img.as_raw()) {
                *g = *p as f32 / 65535.0;
            }
        }
        DynamicImage::ImageRgb8(img) => {
            grey.data
                .par_chunks_mut(w)
                .zip(img.as_raw().par_chunks(3 * w))
                .for_each(|(out, row)| {
                    for (g, p) in out.iter_mut().zip(row.chunks_exact(3)) {
                        *g = (R * p[0] as f32 + G * p[1] as f32 + B * p[2] as f32) / 255.0;
                    }
                });
        }
        _ => {
            // Every other layout (alpha, 16-bit colour, float) through 32-bit float RGB.
            let rgb = image.to_rgb32f();
            grey.data
                .par_chunks_mut(w)
                .zip(rgb.as_raw().par_chunks(3 * w))
                .for_each(|(out, row)| {
                    for (g, p) in out.iter_mut().zip(row.chunks_exact(3)) {
                        *g = R * p[0] + G * p[1] + B * p[2];
                    }
                });
        }
    }
    debug_assert_eq!(grey.data.len(), w * h);
    grey
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageBuffer, Luma, Rgb, Rgba};

    fn encode_png(img: DynamicImage) -> Vec<u8> {
        let mut out = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .unwrap();
        out
    }

    #[test]
    fn grey_16_bit_png_keeps_its_precision() {
        let img = ImageBuffer::from_fn(40, 30, |x, y| Luma([(x * 1000 + y * 7) as u16]));
        let bytes = encode_png(DynamicImage::ImageLuma16(img));
        let p = decode_photo(&bytes, Path::new("grey16.png")).unwrap();
        assert_eq!((p.width(), p.height()), (40, 30));
        assert_eq!(p.stored_as, "L16");
        // 16-bit value 39*1000+29*7 = 39203, exactly representable as a ratio in f32 to 1e-7.
        assert!((p.grey.at(39, 29) - 39203.0 / 65535.0).abs() < 1e-6);
        // RGB8 is the 8-bit rounding of the same value in every channel.
        let expect = (39203.0f64 / 65535.0 * 255.0).round() as u8;
        assert_eq!(p.rgb.get_pixel(39, 29).0, [expect; 3]);
    }

    #[test]
    fn rgb_and_rgba_png_give_rec601_luma() {
        let rgb = ImageBuffer::from_fn(20, 20, |x, y| Rgb([x as u8 * 10, y as u8 * 10, 100]));
        let p = decode_photo(
            &encode_png(DynamicImage::ImageRgb8(rgb)),
            Path::new("c.png"),
        )
        .unwrap();
        let expect = (0.299 * 50.0 + 0.587 * 70.0 + 0.114 * 100.0) / 255.0;
        assert!((p.grey.at(5, 7) - expect).abs() < 1e-6);
        let rgba = ImageBuffer::from_fn(20, 20, |x, y| Rgba([x as u8 * 10, y as u8 * 10, 100, 7]));
        let q = decode_photo(
            &encode_png(DynamicImage::ImageRgba8(rgba)),
            Path::new("d.png"),
        )
        .unwrap();
        assert!((q.grey.at(5, 7) - expect).abs() < 1e-6);
        assert_eq!(q.rgb.get_pixel(5, 7).0, [50, 70, 100]);
    }

    #[test]
    fn jpeg_decodes_and_reports_no_orientation_without_exif() {
        let rgb = ImageBuffer::from_fn(32, 24, |x, y| Rgb([x as u8 * 8, y as u8 * 8, 128]));
        let mut bytes = Vec::new();
        DynamicImage::ImageRgb8(rgb)
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Jpeg,
            )
            .unwrap();
        let p = decode_photo(&bytes, Path::new("a.jpg")).unwrap();
        assert_eq!((p.width(), p.height()), (32, 24));
        assert_eq!(p.exif_orientation, None);
    }

    #[test]
    fn bad_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let empty = dir.path().join("empty.png");
        std::fs::write(&empty, b"").unwrap();
        let e = load_photo(&empty).unwrap_err();
        assert!(matches!(e, PhotoError::EmptyFile { .. }));
        assert!(e.to_string().contains("empty.png"));

        let junk = dir.path().join("junk.jpg");
        std::fs::write(&junk, b"this is not an image at all").unwrap();
        let e = load_photo(&junk).unwrap_err();
        assert!(matches!(e, PhotoError::Decode { .. }), "{e}");
        assert!(e.to_string().contains("junk.jpg"));

        // A PNG cut in the middle of its pixel data.
        let img = ImageBuffer::from_fn(64, 64, |x, y| Luma([(x ^ y) as u8]));
        let png = encode_png(DynamicImage::ImageLuma8(img));
        let cut = dir.path().join("cut.png");
        std::fs::write(&cut, &png[..png.len() / 2]).unwrap();
        let e = load_photo(&cut).unwrap_err();
        assert!(e.to_string().contains("cut.png"), "{e}");

        let missing = load_photo(&dir.path().join("missing.png")).unwrap_err();
        assert!(matches!(missing, PhotoError::Unreadable { .. }));

        let tiny = ImageBuffer::from_fn(10, 10, |x, _| Luma([x as u8]));
        let p = decode_photo(
            &encode_png(DynamicImage::ImageLuma8(tiny)),
            Path::new("tiny.png"),
        )
        .unwrap();
        let e = p.require_min_side(16).unwrap_err();
        assert!(e.to_string().contains("tiny.png") && e.to_string().contains("10x10"));
    }
}
