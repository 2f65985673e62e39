//! OBJ with its MTL and a texture image: `fresco_core::obj::read_obj` and, for the textured
//! model pst transfers colours from, `fresco_pst::transfer::TexturedModel::load`.
//! Input: `obj @@FILE@@ mtl @@FILE@@ png` (the seeds name `m.mtl` and `t.png`).
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, split_files, write_file};

fuzz_target!(|data: &[u8]| {
    let parts = split_files(data, 3);
    let obj = write_file("obj/fuzz.obj", parts[0]);
    write_file("obj/m.mtl", parts[1]);
    write_file("obj/t.png", parts[2]);
    match fresco_core::obj::read_obj(&obj) {
        Ok(scene) => {
            if let Err(e) = scene.mesh.validate() {
                panic!("read_obj returned an invalid mesh: {e}");
            }
            let n = scene.mesh.faces.len();
            if let Some(t) = &scene.mesh.face_textures {
                assert!(
                    t.iter()
                        .all(|&m| (m as usize) < scene.materials.len().max(1))
                );
                assert_eq!(t.len(), n);
            }
            match fresco_pst::transfer::TexturedModel::load(&obj) {
                Ok(model) => {
                    // Every face can be coloured.
                    for f in 0..model.mesh.faces.len().min(64) {
                        let c = model.color_at(f, [1.0 / 3.0; 3]);
                        assert!(c.iter().all(|x| x.is_finite()));
                    }
                }
                Err(e) => {
                    let m = e.to_string();
                    assert!(
                        m.contains("fuzz.obj")
                            || m.contains(".png")
                            || m.contains("t.png")
                            || m.contains('/'),
                        "{m}"
                    );
                }
            }
        }
        Err(e) => check_error(&e, "fuzz.obj"),
    }
});
