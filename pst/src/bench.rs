//! Query sets for measuring lookups: points scattered around the samples, as the vertices of
//! a finer mesh of the same surface would be.

use crate::samples::SampleSet;

/// `count` points near the samples: each a sample moved by up to half the typical sample
/// spacing (estimated from the bounding box and the count), in sample order (coherent, like a
/// mesh's vertex stream). Deterministic from `seed` (SplitMix64).
pub fn queries_near_samples(samples: &SampleSet, count: usize, seed: u64) -> Vec<[f32; 3]> {
    if samples.is_empty() {
        return Vec::new();
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &samples.positions {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let diag = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    let spacing = diag / (samples.len() as f32).sqrt();
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32) - 0.5
    };
    (0..count)
        .map(|i| {
            let p = samples.positions[i * samples.len() / count.max(1)];
            [
                p[0] + spacing * next(),
                p[1] + spacing * next(),
                p[2] + spacing * next(),
            ]
        })
        .collect()
}
