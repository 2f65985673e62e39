//! One test per input the fuzzers of issue 19 found crashing, or reading into values the rest
//! of sfm cannot use, in sfm's readers (`fuzz/`, `bench/fuzz.sh`), built from the input kept
//! in `tests/data/fuzz/`, so that the stable test suite keeps each fixed without the fuzzer.
//! Each names the fuzz target that found it.

use std::path::{Path, PathBuf};

use fresco_sfm::matching::match_file::decode_matches;
use fresco_sfm::workspace::read_images;

fn input(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(name)
}

/// match_file, crash: a pair record whose relative-pose quaternion is infinite. The decoder
/// normalised it into a NaN rotation and handed the mapper a pose it could not use (and that
/// did not encode back to the same pairs). Now a located error naming the pair.
#[test]
fn match_file_with_a_non_unit_pose_quaternion_is_refused() {
    let path = input("match_infinite_pose.bin");
    let bytes = std::fs::read(&path).unwrap();
    let e = decode_matches(&bytes, &path).unwrap_err().to_string();
    assert!(
        e.contains("match_infinite_pose.bin")
            && e.contains("pair 0")
            && e.contains("not a unit quaternion"),
        "{e}"
    );
}

/// The images.json of the sfm_workspace seed with its one image changed by `edit`.
fn workspace_with(edit: impl FnOnce(&mut serde_json::Value)) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let mut v = serde_json::json!({
        "version": 1,
        "images": [{
            "id": 1, "name": "a.jpg", "path": "photos/a.jpg", "width": 1600, "height": 1200,
            "num_keypoints": 3,
            "prior": {"focal_x": 1920.0, "focal_y": 1920.0, "cx": 800.0, "cy": 600.0,
                      "source": "exif35mm"},
            "exif_orientation": 1, "camera_make": null, "camera_model": null
        }]
    });
    edit(&mut v["images"][0]);
    std::fs::write(dir.path().join("images.json"), v.to_string()).unwrap();
    dir
}

/// sfm_workspace: an image name is a file name in `features/`; a name holding a path
/// (`../../x`) read and wrote feature files outside the workspace, and a zero size or a
/// negative focal prior reached the mapper. Each is now refused with the image named.
#[test]
fn images_json_with_unusable_entries_is_refused() {
    let ok = workspace_with(|_| {});
    assert_eq!(read_images(ok.path()).unwrap().images.len(), 1);
    for (edit, says) in [
        (
            Box::new(|i: &mut serde_json::Value| i["name"] = "../../x.jpg".into())
                as Box<dyn Fn(&mut serde_json::Value)>,
            "not a plain file name",
        ),
        (Box::new(|i| i["name"] = "".into()), "not a plain file name"),
        (Box::new(|i| i["width"] = 0.into()), "size 0x1200"),
        (
            Box::new(|i| i["prior"]["focal_x"] = (-5.0).into()),
            "not positive and finite",
        ),
    ] {
        let ws = workspace_with(edit);
        let e = read_images(ws.path()).unwrap_err().to_string();
        assert!(
            e.contains("images.json") && e.contains("image 1") && e.contains(says),
            "{e}"
        );
    }
}
