//! Models whose headers promise more than they hold are refused quickly and cheaply (issue
//! 19): truncated GLB files and GLB headers claiming gigabytes, as `fresco pst from-model`
//! reads them. Each is a clear error naming the file, within 10 ms and 10 MB of heap,
//! measured by a counting allocator around the call (as in core's `resource_limits.rs`).
//!
//! The tests share the allocator's counters, so they take a lock and run one at a time.

#[path = "../../core/tests/support/refused_cheaply.rs"]
mod refused_cheaply;

use refused_cheaply::{ONE_AT_A_TIME, refused_cheaply};

use fresco_core::Mesh;
use fresco_core::nalgebra::Point3;
use fresco_pst::transfer::TexturedModel;

fn textured_glb() -> Vec<u8> {
    let mut mesh = Mesh::from_triangles(
        vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
        ],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    );
    mesh.corner_uvs = Some(vec![[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]; 4]);
    let texture =
        image::RgbImage::from_fn(64, 64, |x, y| image::Rgb([x as u8 * 4, y as u8 * 4, 7]));
    fresco_core::gltf::encode_glb(&mesh, &[texture]).unwrap()
}

#[test]
fn truncated_glb_is_refused_quickly() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let glb = textured_glb();
    let whole = dir.path().join("whole.glb");
    std::fs::write(&whole, &glb).unwrap();
    TexturedModel::load(&whole).expect("the untruncated model reads");
    // Inside the 12-byte header, the JSON chunk, the BIN chunk's header and its data.
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    for keep in [
        0,
        7,
        12,
        20,
        20 + json_len / 2,
        20 + json_len + 4,
        glb.len() - 1,
    ] {
        let name = format!("cut_at_{keep}.glb");
        let path = dir.path().join(&name);
        std::fs::write(&path, &glb[..keep]).unwrap();
        refused_cheaply(&name, || TexturedModel::load(&path));
    }
}

#[test]
fn glb_headers_claiming_gigabytes_are_refused_quickly() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let glb = textured_glb();
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    // Total length, JSON chunk length, BIN chunk length: each set to 4 GB - 4.
    for (what, at) in [("total", 8), ("json", 12), ("bin", 20 + json_len)] {
        let mut bytes = glb.clone();
        bytes[at..at + 4].copy_from_slice(&(u32::MAX - 3).to_le_bytes());
        let name = format!("claims_4gb_{what}.glb");
        let path = dir.path().join(&name);
        std::fs::write(&path, &bytes).unwrap();
        refused_cheaply(&name, || TexturedModel::load(&path));
    }
}
