//! PLY as the PST sampler reads it (`fresco_pst::PlyPoints`): binary files with fixed-size
//! vertex records go through a memory map, the rest through core's reader. Both must give the
//! same points as core's streaming reader, or both refuse the file.
#![no_main]
use std::io::Cursor;

use fresco_core::ply::PlyReader;
use fresco_fuzz::{check_error, write_file};
use fresco_pst::{PlyPoints, PointSource, SourcePoint};
use libfuzzer_sys::fuzz_target;

fn bits(p: &SourcePoint) -> [u64; 3] {
    p.position.map(f64::to_bits)
}

fuzz_target!(|data: &[u8]| {
    let path = write_file("points.ply", Some(data));
    let src = match PlyPoints::open(&path) {
        Ok(s) => s,
        Err(e) => return check_error(&e, "points.ply"),
    };
    let mut mapped = Vec::new();
    let streamed = src.stream_batches(&mut |batch| {
        for chunk in batch {
            mapped.extend(chunk.iter().map(bits));
        }
        Ok(())
    });
    // Core's reader over the vertices alone.
    let mut core = Vec::new();
    let core_result = (|| {
        let mut r = PlyReader::from_reader(Cursor::new(data), "points.ply")?;
        let mut batch = Vec::new();
        while r.read_vertices(&mut batch, 4096)? > 0 {
            core.extend(
                batch
                    .iter()
                    .map(|v| [v.position.x, v.position.y, v.position.z].map(f64::to_bits)),
            );
        }
        Ok::<_, fresco_core::FormatError>(())
    })();
    match (streamed, core_result) {
        (Ok(()), Ok(())) => {
            assert_eq!(mapped, core, "the memory-mapped and streamed points differ")
        }
        (Err(e), Err(_)) => check_error(&e, "points.ply"),
        (a, b) => panic!(
            "PlyPoints and core disagree: {:?} vs {:?}",
            a.err().map(|e| e.to_string()),
            b.err().map(|e| e.to_string())
        ),
    }
});
