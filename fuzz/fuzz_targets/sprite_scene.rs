//! Sprite-scene JSON (`fresco sprites render/bake/octree --scene`): `fresco_sprites::scene::
//! Scene::load`, with a pattern image `p.png` beside it, then every sprite placed at time 0
//! and 1.5. Input: `scene.json @@FILE@@ p.png`.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, split_files, write_file};
use fresco_sprites::scene::Scene;

fuzz_target!(|data: &[u8]| {
    let parts = split_files(data, 2);
    let path = write_file("sprites/scene.json", parts[0]);
    write_file("sprites/p.png", parts[1]);
    match Scene::load(&path) {
        Ok(scene) => {
            assert_eq!(scene.patterns.len(), scene.pattern_paths.len());
            for s in &scene.sprites {
                assert!((s.pattern as usize) < scene.patterns.len());
                for t in [0.0, 1.5] {
                    let _ = s.at_time(t);
                }
            }
        }
        Err(e) => check_error(&e, "scene.json"),
    }
});
