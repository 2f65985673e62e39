//! The dense stage's files (`<ws>/dense/`): COLMAP-format depth, normal and cost maps
//! (`fresco_surface::dense::depth_map_file::read_depth_map`, `read_float_map`) and the
//! visibility lists of `fused.ply.vis` (`fusion::read_vis`). Input: `depth @@FILE@@ normal
//! @@FILE@@ cost @@FILE@@ vis` (a missing cost map is allowed, as for COLMAP's maps).
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, split_files, write_file};
use fresco_surface::dense::depth_map_file::{read_depth_map, read_float_map};
use fresco_surface::dense::fusion::read_vis;

fuzz_target!(|data: &[u8]| {
    let parts = split_files(data, 4);
    let depth = write_file("dense/d.geometric.bin", parts[0]);
    let normal = write_file("dense/n.geometric.bin", parts[1]);
    let cost = write_file("dense/c.geometric.bin", parts[2]);
    let vis = write_file("dense/fused.ply.vis", parts[3]);
    match read_float_map(&depth) {
        Ok(m) => assert_eq!(m.data.len(), m.width * m.height * m.channels),
        Err(e) => check_error(&e, "d.geometric.bin"),
    }
    match read_depth_map(&depth, &normal, &cost) {
        Ok(m) => {
            let n = m.width * m.height;
            assert_eq!(m.depth.len(), n);
            assert_eq!(m.normal.len(), n);
            assert_eq!(m.cost.len(), n);
        }
        Err(e) => {
            let s = e.to_string();
            assert!(s.contains(".geometric.bin"), "error names no map: {s}");
        }
    }
    if parts[3].is_some() {
        match read_vis(&vis) {
            Ok(lists) => assert!(lists.len() <= data.len() / 4),
            Err(e) => check_error(&e, "fused.ply.vis"),
        }
    }
});
