//! The text files of an sfm workspace: `<ws>/images.json` (`fresco_sfm::workspace::read_images`)
//! and a calibration matrix `K.txt` (`fresco_sfm::focal_prior::read_calibration_file`, for a
//! 1600x1200 photo). Input: `images.json @@FILE@@ K.txt`.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, scratch, split_files, write_file};

fuzz_target!(|data: &[u8]| {
    let parts = split_files(data, 2);
    write_file("ws/images.json", parts[0]);
    let k = write_file("ws/K.txt", parts[1]);
    match fresco_sfm::workspace::read_images(&scratch().join("ws")) {
        Ok(list) => {
            let mut ids: Vec<u32> = list.images.iter().map(|i| i.id).collect();
            ids.sort_unstable();
            ids.dedup();
            assert_eq!(ids.len(), list.images.len(), "image ids are unique");
        }
        Err(e) => check_error(&e, "images.json"),
    }
    if parts[1].is_some() {
        match fresco_sfm::focal_prior::read_calibration_file(&k, 1600, 1200) {
            Ok(prior) => {
                assert!(prior.focal_x > 0.0 && prior.focal_y > 0.0 && prior.cx.is_finite())
            }
            Err(e) => check_error(&e, "K.txt"),
        }
    }
});
