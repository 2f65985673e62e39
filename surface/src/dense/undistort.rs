//! Undistortion of the registered photos to pinhole cameras, as COLMAP's `image_undistorter`
//! does with its defaults (`blank_pixels = 0`): the undistorted camera keeps the focal length,
//! and its image is the largest axis-aligned rectangle whose every pixel comes from inside the
//! photo, so no black border ever enters a matching cost. It is then optionally scaled down so
//! that its longer side is at most `max_image_size` pixels.
//!
//! - [`undistorted_camera`]: the PINHOLE camera of a (possibly distorted) camera.
//! - [`undistort_rgb`]: resamples a photo into it (bilinear; a box of `n x n` bilinear
//!   samples per output pixel when scaling down by `1 / n` or more, so that down-scaled
//!   images do not alias).
//! - [`undistort_mask`]: the same mapping for object masks (nearest pixel).
//! - [`undistort_pixel`]: a photo pixel (keypoint) in the undistorted image.

use fresco_core::nalgebra::{Point2, Point3};
use fresco_core::{Camera, CameraModel, Pixel};
use image::{GrayImage, RgbImage};
use rayon::prelude::*;

/// Samples taken along each image border to find the undistorted image's extent.
const BORDER_SAMPLES: usize = 512;

/// The undistorted pinhole camera of `camera`: same focal lengths, the inner rectangle of the
/// undistorted photo (see the module documentation), scaled so that its longer side is at
/// most `max_image_size` (0: no limit). Keeps `camera.id`.
pub fn undistorted_camera(camera: &Camera, max_image_size: u32) -> Camera {
    let (fx, fy) = (camera.focal_x(), camera.focal_y());
    let c = camera.principal_point();
    let (w, h) = (camera.width as f64, camera.height as f64);
    // The undistorted position (pixels of a pinhole camera with the same focal length and
    // principal point) of a photo border point; None where the model cannot invert.
    let undistorted = |x: f64, y: f64| -> Option<Pixel> {
        let n = camera.cam_from_image(&Pixel::new(x, y))?;
        Some(Pixel::new(fx * n.x + c.x, fy * n.y + c.y))
    };
    let (mut left, mut right, mut top, mut bottom) = (0.0f64, w, 0.0f64, h);
    if !matches!(
        camera.model,
        CameraModel::SimplePinhole | CameraModel::Pinhole
    ) {
        left = f64::NEG_INFINITY;
        right = f64::INFINITY;
        top = f64::NEG_INFINITY;
        bottom = f64::INFINITY;
        for i in 0..=BORDER_SAMPLES {
            let t = i as f64 / BORDER_SAMPLES as f64;
            if let Some(p) = undistorted(0.0, t * h) {
                left = left.max(p.x);
            }
            if let Some(p) = undistorted(w, t * h) {
                right = right.min(p.x);
            }
            if let Some(p) = undistorted(t * w, 0.0) {
                top = top.max(p.y);
            }
            if let Some(p) = undistorted(t * w, h) {
                bottom = bottom.min(p.y);
            }
        }
        // A model that cannot invert anywhere on a border keeps the photo's extent there.
        if !left.is_finite() {
            left = 0.0;
        }
        if !right.is_finite() {
            right = w;
        }
        if !top.is_finite() {
            top = 0.0;
        }
        if !bottom.is_finite() {
            bottom = h;
        }
        // Whole pixels only, inside the inner rectangle.
        left = left.ceil();
        top = top.ceil();
        right = right.floor().max(left + 1.0);
        bottom = bottom.floor().max(top + 1.0);
    }
    let (uw, uh) = (right - left, bottom - top);
    let longest = uw.max(uh);
    let scale = if max_image_size > 0 && longest > max_image_size as f64 {
        max_image_size as f64 / longest
    } else {
        1.0
    };
    let (out_w, out_h) = (
        ((uw * scale).round() as u32).max(1),
        ((uh * scale).round() as u32).max(1),
    );
    let (sx, sy) = (out_w as f64 / uw, out_h as f64 / uh);
    Camera {
        id: camera.id,
        model: CameraModel::Pinhole,
        width: out_w,
        height: out_h,
        params: vec![fx * sx, fy * sy, (c.x - left) * sx, (c.y - top) * sy],
    }
}

/// The photo pixel (COLMAP convention) that the undistorted pixel `p` of `pinhole` sees.
fn distorted_pixel(camera: &Camera, pinhole: &Camera, p: &Pixel) -> Option<Pixel> {
    let n = pinhole.cam_from_image(p)?;
    camera.image_from_cam(&Point3::new(n.x, n.y, 1.0))
}

/// `pixel` of a photo taken with `camera` in the undistorted image of `pinhole`.
pub fn undistort_pixel(camera: &Camera, pinhole: &Camera, pixel: &Pixel) -> Option<Pixel> {
    let n = camera.cam_from_image(pixel)?;
    pinhole.image_from_cam(&Point3::new(n.x, n.y, 1.0))
}

/// Sub-samples per output pixel side when the undistorted image is `scale` times the photo.
fn supersampling(camera: &Camera, pinhole: &Camera) -> usize {
    let scale = (pinhole.width as f64 / camera.width as f64)
        .min(pinhole.height as f64 / camera.height as f64);
    if scale >= 1.0 {
        1
    } else {
        (1.0 / scale).ceil().min(8.0) as usize
    }
}

/// Resamples `photo` (taken with `camera`) into the undistorted image of `pinhole`.
pub fn undistort_rgb(photo: &RgbImage, camera: &Camera, pinhole: &Camera) -> RgbImage {
    let (w, h) = (pinhole.width as usize, pinhole.height as usize);
    let n = supersampling(camera, pinhole);
    let (pw, ph) = (photo.width() as usize, photo.height() as usize);
    let src = photo.as_raw();
    let mut out = vec![0u8; w * h * 3];
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let mut acc = [0.0f64; 3];
            let mut count = 0usize;
            for j in 0..n {
                for i in 0..n {
                    let p = Pixel::new(
                        x as f64 + (i as f64 + 0.5) / n as f64,
                        y as f64 + (j as f64 + 0.5) / n as f64,
                    );
                    if let Some(d) = distorted_pixel(camera, pinhole, &p) {
                        bilinear_rgb(src, pw, ph, d.x - 0.5, d.y - 0.5, &mut acc);
                        count += 1;
                    }
                }
            }
            if count > 0 {
                for c in 0..3 {
                    row[x * 3 + c] = (acc[c] / count as f64).round().clamp(0.0, 255.0) as u8;
                }
            }
        }
    });
    RgbImage::from_raw(w as u32, h as u32, out).expect("buffer sized w * h * 3")
}

/// Adds the bilinear sample of an RGB8 buffer at array position (`x`, `y`) (pixel centres on
/// integers), clamped to the edge, to `acc`.
fn bilinear_rgb(src: &[u8], w: usize, h: usize, x: f64, y: f64, acc: &mut [f64; 3]) {
    let x = x.clamp(0.0, (w - 1) as f64);
    let y = y.clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (ax, ay) = (x - x0 as f64, y - y0 as f64);
    for c in 0..3 {
        let at = |xx: usize, yy: usize| src[(yy * w + xx) * 3 + c] as f64;
        let top = at(x0, y0) * (1.0 - ax) + at(x1, y0) * ax;
        let bottom = at(x0, y1) * (1.0 - ax) + at(x1, y1) * ax;
        acc[c] += top * (1.0 - ay) + bottom * ay;
    }
}

/// Resamples an object mask (taken with `camera`) into the undistorted image of `pinhole`:
/// the photo pixel each undistorted pixel centre falls in.
pub fn undistort_mask(mask: &GrayImage, camera: &Camera, pinhole: &Camera) -> GrayImage {
    let (w, h) = (pinhole.width, pinhole.height);
    let (mw, mh) = (mask.width() as f64, mask.height() as f64);
    GrayImage::from_fn(w, h, |x, y| {
        let p = Pixel::new(x as f64 + 0.5, y as f64 + 0.5);
        let v = distorted_pixel(camera, pinhole, &p)
            .filter(|d| d.x >= 0.0 && d.y >= 0.0 && d.x < mw && d.y < mh)
            .map_or(0, |d| mask.get_pixel(d.x as u32, d.y as u32).0[0]);
        image::Luma([v])
    })
}

/// Undistorted keypoints, for the model written beside the undistorted images.
pub fn undistort_keypoints(
    keypoints: &[Point2<f64>],
    camera: &Camera,
    pinhole: &Camera,
) -> Vec<Point2<f64>> {
    keypoints
        .iter()
        .map(|k| undistort_pixel(camera, pinhole, k).unwrap_or(*k))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn radial(k: f64) -> Camera {
        Camera {
            id: 3,
            model: CameraModel::SimpleRadial,
            width: 640,
            height: 480,
            params: vec![768.0, 320.0, 240.0, k],
        }
    }

    #[test]
    fn pinhole_cameras_are_kept_as_they_are() {
        let c = Camera {
            id: 1,
            model: CameraModel::SimplePinhole,
            width: 640,
            height: 480,
            params: vec![700.0, 321.0, 239.0],
        };
        let u = undistorted_camera(&c, 0);
        assert_eq!(u.model, CameraModel::Pinhole);
        assert_eq!((u.width, u.height), (640, 480));
        assert_eq!(u.params, vec![700.0, 700.0, 321.0, 239.0]);
    }

    #[test]
    fn undistorted_images_hold_only_pixels_from_inside_the_photo() {
        for k in [-0.05, 0.05] {
            let c = radial(k);
            let u = undistorted_camera(&c, 0);
            let (w, h) = (u.width as f64, u.height as f64);
            // Every border point of the undistorted image maps inside the photo, and the
            // rectangle is the largest such: somewhere on each side it touches the photo's
            // border within a pixel.
            let mut closest = [f64::INFINITY; 4];
            for i in 0..=200 {
                let t = i as f64 / 200.0;
                for (side, (x, y)) in [(0.0, t * h), (w, t * h), (t * w, 0.0), (t * w, h)]
                    .into_iter()
                    .enumerate()
                {
                    let d = distorted_pixel(&c, &u, &Pixel::new(x, y)).unwrap();
                    assert!(
                        d.x >= -1e-6 && d.y >= -1e-6 && d.x <= 640.0 + 1e-6 && d.y <= 480.0 + 1e-6,
                        "k {k}: ({x}, {y}) -> {d:?}"
                    );
                    let gap = [d.x, 640.0 - d.x, d.y, 480.0 - d.y][side];
                    closest[side] = closest[side].min(gap);
                }
            }
            assert!(closest.iter().all(|&g| g < 1.5), "k {k}: {closest:?} {u:?}");
            // Barrel distortion (k < 0) pushes the border outwards, pincushion inwards.
            assert_eq!(u.width > 640, k < 0.0, "{u:?}");
            // A keypoint maps back to where it came from.
            let p = Pixel::new(100.25, 400.5);
            let back = distorted_pixel(&c, &u, &undistort_pixel(&c, &u, &p).unwrap()).unwrap();
            assert!((back - p).norm() < 1e-6);
        }
    }

    #[test]
    fn down_scaling_keeps_the_field_of_view() {
        let c = radial(0.0);
        let u = undistorted_camera(&c, 320);
        assert_eq!((u.width, u.height), (320, 240));
        // The corner rays are the same.
        let full = c.cam_from_image(&Pixel::new(640.0, 480.0)).unwrap();
        let half = u.cam_from_image(&Pixel::new(320.0, 240.0)).unwrap();
        assert!((full - half).norm() < 1e-12);
    }

    #[test]
    fn undistorting_a_distorted_rendering_of_a_grid_straightens_it() {
        // A photo of vertical stripes through a distorted lens: after undistortion, each
        // stripe edge is a straight vertical line (same column in every row).
        let c = radial(-0.05);
        let u = undistorted_camera(&c, 0);
        let stripe = |x: f64| ((x / 40.0).floor() as i64 % 2 == 0) as u8 * 255;
        // Ideal (undistorted) x of each photo pixel decides its colour.
        let photo = RgbImage::from_fn(640, 480, |x, y| {
            let n = c
                .cam_from_image(&Pixel::new(x as f64 + 0.5, y as f64 + 0.5))
                .unwrap();
            let v = stripe(768.0 * n.x + 320.0);
            image::Rgb([v, v, v])
        });
        let out = undistort_rgb(&photo, &c, &u);
        let cx = u.params[2];
        // Column of the first black-to-white edge right of the centre, per row.
        let edge = |y: u32| {
            (0..u.width - 1).find(|&x| {
                let ideal = x as f64 + 0.5 - cx + 320.0;
                ideal > 330.0
                    && out.get_pixel(x, y).0[0] < 128
                    && out.get_pixel(x + 1, y).0[0] >= 128
            })
        };
        let first = edge(5).unwrap();
        for y in (5..u.height - 5).step_by(37) {
            assert!(edge(y).unwrap().abs_diff(first) <= 1, "row {y}");
        }
    }
}
