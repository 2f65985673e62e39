//! Photos as fresco loads them: `fresco_core::photo::decode_photo_within` (PNG or JPEG, EXIF
//! block kept), the EXIF fields and focal prior of `fresco_sfm::focal_prior`, and
//! `decode_rgba_within` (textures, bitmaps to project). The limit is 2^22 pixels here so that
//! a photo within it decodes under libFuzzer's 512 MB; the size check is the same code at
//! any limit.
#![no_main]
use std::path::Path;

use fresco_core::photo::{PhotoLimits, decode_photo_within, decode_rgba_within};
use fresco_fuzz::check_error;
use fresco_sfm::focal_prior::{focal_from_exif, parse_exif};
use libfuzzer_sys::fuzz_target;

const LIMITS: PhotoLimits = PhotoLimits {
    max_pixels: 1 << 22,
};

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.jpg");
    match decode_photo_within(data, path, &LIMITS) {
        Ok(photo) => {
            let (w, h) = (photo.width(), photo.height());
            assert!(w > 0 && h > 0 && w as u64 * h as u64 <= LIMITS.max_pixels);
            assert_eq!(photo.grey.data.len(), (w * h) as usize);
            assert!(photo.grey.data.iter().all(|g| (0.0..=1.0).contains(g)));
            if let Some(raw) = &photo.exif {
                let exif = parse_exif(raw);
                let prior = focal_from_exif(&exif, w, h);
                assert!(
                    prior.focal_x.is_finite() && prior.focal_x > 0.0,
                    "{prior:?}"
                );
            }
            let rgba =
                decode_rgba_within(data, path, &LIMITS).expect("decoded once, decodes again");
            assert_eq!(rgba.dimensions(), (w, h));
        }
        Err(e) => check_error(&e, "fuzz.jpg"),
    }
    // The EXIF parser on its own, on arbitrary bytes (a block cut from any file).
    let _ = parse_exif(data);
});
