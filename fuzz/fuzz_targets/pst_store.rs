//! A PST folder as `fresco pst` commands open it: `pst.json` and `samples.bin`
//! (`fresco_pst::Pst::open`), then the stored samples of evicted 1-nodes
//! (`evicted/0000000.bin`, `evicted/0000001.bin`) through `all_samples`, reloading
//! (`touch`) and the LRU budget. Input: the four files cut at `@@FILE@@`.
#![no_main]
use libfuzzer_sys::fuzz_target;

use fresco_fuzz::{scratch, split_files, write_file};
use fresco_pst::Pst;

fuzz_target!(|data: &[u8]| {
    let parts = split_files(data, 4);
    let dir = scratch().join("pst");
    let _ = std::fs::remove_dir_all(&dir);
    write_file("pst/pst.json", parts[0]);
    write_file("pst/samples.bin", parts[1]);
    write_file("pst/evicted/0000000.bin", parts[2]);
    write_file("pst/evicted/0000001.bin", parts[3]);
    let mut pst = match Pst::open(&dir) {
        Ok(p) => p,
        Err(e) => {
            let m = e.to_string();
            assert!(m.contains("pst"), "{m}");
            return;
        }
    };
    let nodes = pst.manifest.nodes.len();
    assert!(pst.samples.nodes.iter().all(|&n| (n as usize) < nodes));
    if let Ok(all) = pst.all_samples() {
        assert_eq!(all.attrs.len(), all.len() * all.width);
    }
    let ids: Vec<u32> = (0..nodes as u32).collect();
    let _ = pst.ring(&ids);
    if pst.touch(&ids).is_ok() {
        assert!(pst.samples.nodes.iter().all(|&n| (n as usize) < nodes));
        let _ = pst.enforce_budget(&[]);
    }
});
