//! Middlebury `*_par.txt`: `fresco_core::middlebury::read_par`. Input: image width and height
//! (u16 little-endian each), then the file. A file read gives a consistent reconstruction and
//! writes back to a file that reads the same.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_core::middlebury::{read_par, views_to_reconstruction, write_par};
use fresco_fuzz::{check_error, write_file};

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let width = u16::from_le_bytes([data[0], data[1]]) as u32;
    let height = u16::from_le_bytes([data[2], data[3]]) as u32;
    let path = write_file("fuzz_par.txt", Some(&data[4..]));
    match read_par(&path, width, height) {
        Ok(views) => {
            let rec = views_to_reconstruction(&views);
            if let Err(e) = rec.validate() {
                panic!("read_par gave an inconsistent model: {e}");
            }
            let again = fresco_fuzz::scratch().join("again_par.txt");
            write_par(&again, &views).expect("views read can be written");
            let back = read_par(&again, width, height).expect("a written file reads back");
            assert_eq!(back.len(), views.len());
        }
        Err(e) => check_error(&e, "fuzz_par.txt"),
    }
});
