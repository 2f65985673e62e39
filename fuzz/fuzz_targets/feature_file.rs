//! fresco's feature files (`<ws>/features/<image>.sift`): `decode_features`. What decodes
//! encodes back to the same bytes.
#![no_main]
use std::path::Path;

use fresco_sfm::features::feature_file::{decode_features, encode_features};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match decode_features(data, Path::new("fuzz.sift")) {
        Ok(f) => {
            assert_eq!(f.keypoints.len(), f.descriptors.len());
            assert_eq!(
                encode_features(&f),
                data,
                "decode then encode is the identity"
            );
        }
        Err(e) => fresco_fuzz::check_error(&e, "fuzz.sift"),
    }
});
