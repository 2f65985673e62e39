//! The 1-node files of the PST's first pass (`nodes/<id>.pts`):
//! `fresco_pst::node_files::read_node_file`, with and without normals.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{check_error, write_file};
use fresco_pst::node_files::{read_node_file, record_size};

fuzz_target!(|data: &[u8]| {
    let path = write_file("fuzz.pts", Some(data));
    for normals in [false, true] {
        let mut seen = 0u64;
        match read_node_file(&path, normals, [1.0, -2.0, 0.5], &mut |pts| {
            seen += pts.len() as u64
        }) {
            Ok(n) => {
                assert_eq!(n, seen);
                assert_eq!(n * record_size(normals) as u64, data.len() as u64);
            }
            Err(e) => check_error(&e, "fuzz.pts"),
        }
    }
});
