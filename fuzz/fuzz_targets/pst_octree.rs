//! Octree textures (`*.foct`, format `FOCTTEX2`, shared by `fresco pst export` and `fresco
//! sprites octree`): `fresco_pst::octree_texture::OctreeTexture::load`, then lookups of texels
//! and of every mip level at a point, and a round trip through `to_bytes`. Input: three bytes
//! choosing the lookup point, three spare, then the file.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, write_file};
use fresco_pst::octree_texture::OctreeTexture;

fuzz_target!(|data: &[u8]| {
    if data.len() < 6 {
        return;
    }
    let path = write_file("fuzz.foct", Some(&data[6..]));
    match OctreeTexture::load(&path) {
        Ok(tex) => {
            let p = [data[0], data[1], data[2]].map(|b| (b as u32) << 24 | (b as u32) * 0x10101);
            if let Some(t) = tex.texel(p) {
                assert_eq!(t.len(), tex.channels as usize);
            }
            for level in 0..=tex.depth {
                let _ = tex.value_at_level(p, level);
            }
            let world = tex.min.map(|v| v as f64 + 0.5);
            let _ = tex.texel(tex.fixed(world));
            let again = OctreeTexture::from_bytes(&tex.to_bytes()).expect("a loaded texture saves");
            assert_eq!(again.to_bytes(), tex.to_bytes());
        }
        Err(e) => check_error(&e, "fuzz.foct"),
    }
});
