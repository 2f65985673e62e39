//! GLB (glTF 2.0 binary) as `fresco pst from-model` reads it:
//! `fresco_pst::transfer::TexturedModel::load` (meshes, UVs, colours, materials, embedded
//! PNG/JPEG textures). A model read can be coloured at every face.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, write_file};
use fresco_pst::transfer::TexturedModel;

fuzz_target!(|data: &[u8]| {
    let path = write_file("fuzz.glb", Some(data));
    match TexturedModel::load(&path) {
        Ok(model) => {
            if let Err(e) = model.mesh.validate() {
                panic!("a GLB read gives an invalid mesh: {e}");
            }
            for f in 0..model.mesh.faces.len().min(64) {
                let c = model.color_at(f, [0.2, 0.3, 0.5]);
                assert!(c.iter().all(|x| x.is_finite()), "{c:?}");
            }
        }
        Err(e) => check_error(&e, "fuzz.glb"),
    }
});
