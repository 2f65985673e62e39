//! The text inputs of `fresco pst` editing: ops files (`fresco_pst::paint::Script`, JSON),
//! applied one by one (`apply_op`) to a small PST (200 samples on a sphere, node files kept,
//! a 4x4 texture `t.png` and a model `m.glb` beside it), and region arguments
//! (`fresco_pst::region::Region::parse`).
#![no_main]
use std::path::PathBuf;
use std::sync::OnceLock;

use fresco_core::NoProgress;
use fresco_pst::paint::{Script, apply_op};
use fresco_pst::{CreateConfig, FieldConfig, MemoryPoints, Pst};
use libfuzzer_sys::fuzz_target;

/// The PST every input starts from, and the folder its ops' relative paths resolve in.
fn base() -> &'static (Pst, PathBuf) {
    static BASE: OnceLock<(Pst, PathBuf)> = OnceLock::new();
    BASE.get_or_init(|| {
        let dir = fresco_fuzz::scratch().join("ops");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let positions: Vec<[f64; 3]> = (0..400)
            .map(|i| {
                let t = i as f64 * 0.37;
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / 400.0;
                let r = (1.0 - z * z).sqrt();
                [r * t.cos(), r * t.sin(), z]
            })
            .collect();
        let mut cfg = CreateConfig::default();
        cfg.sampling.target = 200;
        let (pst, _) = Pst::create(
            &MemoryPoints::from_positions(&positions),
            &cfg,
            &dir.join("p"),
            &NoProgress,
        )
        .unwrap();
        let img =
            image::RgbImage::from_fn(4, 4, |x, y| image::Rgb([x as u8 * 60, y as u8 * 60, 9]));
        img.save(dir.join("t.png")).unwrap();
        let mesh = fresco_core::Mesh::from_triangles(
            vec![
                fresco_core::nalgebra::Point3::new(-1.0, -1.0, 0.0),
                fresco_core::nalgebra::Point3::new(1.0, -1.0, 0.0),
                fresco_core::nalgebra::Point3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2]],
        );
        fresco_core::gltf::write_glb(&dir.join("m.glb"), &mesh, &[]).unwrap();
        (pst, dir)
    })
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(region) = fresco_pst::region::Region::parse(text) {
        let _ = region.contains([0.0, 0.0, 0.0]);
    }
    let Ok(script) = serde_json::from_str::<Script>(text) else {
        return;
    };
    let (pst0, dir) = base();
    let mut pst = pst0.clone();
    for op in script.ops.iter().take(8) {
        match apply_op(&mut pst, op, dir, FieldConfig::default(), &NoProgress) {
            Ok(_) => {
                assert_eq!(
                    pst.samples.attrs.len(),
                    pst.samples.len() * pst.samples.width
                );
                assert!(
                    pst.samples
                        .nodes
                        .iter()
                        .all(|&n| (n as usize) < pst.manifest.nodes.len())
                );
            }
            Err(e) => {
                assert!(!e.to_string().is_empty());
                break;
            }
        }
    }
});
