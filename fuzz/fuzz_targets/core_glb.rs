//! GLB as `fresco eval texture` reads a textured model back: `fresco_core::gltf::read_glb`
//! (triangle primitives, UVs, COLOR_0, embedded PNG/JPEG base-colour images). What it returns
//! is a mesh that passes `Mesh::validate`, its face textures within its images.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, write_file};

fuzz_target!(|data: &[u8]| {
    let path = write_file("fuzz_core.glb", Some(data));
    match fresco_core::gltf::read_glb(&path) {
        Ok((mesh, textures)) => {
            if let Err(e) = mesh.validate() {
                panic!("read_glb returned an invalid mesh: {e}");
            }
            if let Some(t) = &mesh.face_textures {
                assert!(t.iter().all(|&i| (i as usize) < textures.len().max(1)));
            }
        }
        Err(e) => check_error(&e, "fuzz_core.glb"),
    }
});
