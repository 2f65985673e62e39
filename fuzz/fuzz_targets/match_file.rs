//! fresco's match file (`<ws>/matches/two_view.bin`): `decode_matches`. What decodes is
//! usable geometry (finite matrices, a unit quaternion) and encodes to bytes that decode to
//! the same pairs.
#![no_main]
use std::path::Path;

use fresco_sfm::matching::match_file::{decode_matches, encode_matches};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("two_view.bin");
    match decode_matches(data, path) {
        Ok(pairs) => {
            for p in &pairs {
                let g = &p.geometry;
                for m in [g.fundamental, g.essential, g.homography]
                    .into_iter()
                    .flatten()
                {
                    assert!(
                        m.iter().all(|x| x.is_finite()),
                        "non-finite matrix read: {m}"
                    );
                }
                if let Some(pose) = g.cam2_from_cam1 {
                    let q = pose.rotation.quaternion();
                    assert!(
                        (q.norm() - 1.0).abs() < 1e-6,
                        "pose rotation not a unit quaternion: {q:?}"
                    );
                    assert!(pose.translation.iter().all(|x| x.is_finite()));
                }
            }
            let again =
                decode_matches(&encode_matches(&pairs), path).expect("encoded pairs decode");
            assert_eq!(again, pairs);
        }
        Err(e) => fresco_fuzz::check_error(&e, "two_view.bin"),
    }
});
