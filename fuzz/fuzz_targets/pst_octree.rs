//! Octree textures (`*.foct`, `fresco pst export`): `fresco_pst::octree_texture::OctreeTexture::load`,
//! then lookups at every depth. Input: eight bytes choosing the lookup point, then the file.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, write_file};
use fresco_pst::octree_texture::OctreeTexture;

fuzz_target!(|data: &[u8]| {
    if data.len() < 6 {
        return;
    }
    let p = [data[0], data[1], data[2]].map(|b| b as f32 / 64.0 - 1.0);
    let path = write_file("fuzz.foct", Some(&data[6..]));
    match OctreeTexture::load(&path) {
        Ok(tex) => {
            for depth in 0..=tex.max_depth.min(16) + 1 {
                assert_eq!(tex.lookup(p, depth).len(), tex.width);
            }
        }
        Err(e) => check_error(&e, "fuzz.foct"),
    }
});
