//! A PST folder as `fresco pst` commands open it: `pst.json` and `samples.bin`
//! (`fresco_pst::Pst::open`), then the stored samples of evicted 1-nodes
//! (`evicted/<id>.bin` of the first two nodes the manifest marks evicted, else nodes 0 and 1)
//! through `all_samples`, reloading
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
    // The evicted files belong to the first two nodes the manifest says are not resident.
    let evicted = evicted_ids(parts[0].unwrap_or_default());
    write_file(&format!("pst/evicted/{:07}.bin", evicted[0]), parts[2]);
    write_file(&format!("pst/evicted/{:07}.bin", evicted[1]), parts[3]);
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

/// Ids of the first two nodes marked `"resident": false` in the manifest, else 0 and 1.
fn evicted_ids(manifest: &[u8]) -> [u64; 2] {
    let mut ids = [0, 1];
    if let Ok(v) = serde_json::from_slice::<serde_json::Value>(manifest)
        && let Some(nodes) = v["nodes"].as_array()
    {
        let found: Vec<u64> = nodes
            .iter()
            .filter(|n| n["resident"] == false)
            .filter_map(|n| n["id"].as_u64())
            .take(2)
            .collect();
        for (k, id) in found.into_iter().enumerate() {
            ids[k] = id.min(9_999_999);
        }
    }
    ids
}
