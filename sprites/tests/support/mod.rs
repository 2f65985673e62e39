//! Random sampling shared by the sprites tests that compare the tree against brute force.

use fresco_core::Rng;
use fresco_sprites::{Footprint, Query};

/// A uniformly random unit vector (rejection sampling in the unit ball).
pub fn unit(rng: &mut Rng) -> [f64; 3] {
    loop {
        let v = [0; 3].map(|_| rng.range(-1.0, 1.0));
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if l > 0.1 && l <= 1.0 {
            return v.map(|c| c / l);
        }
    }
}

/// A point within `shell` of the unit sphere with a normal (mostly) and a footprint (half
/// the time).
pub fn random_query(rng: &mut Rng, shell: f64) -> Query {
    let n = unit(rng);
    let r = 1.0 + rng.range(-shell, shell);
    let tilt = unit(rng);
    let normal = [0, 1, 2].map(|a| (n[a] + 0.3 * tilt[a]) as f32);
    let l = (normal.iter().map(|v| v * v).sum::<f32>()).sqrt();
    let k = 10f64.powf(rng.range(-4.0, -1.0)) as f32;
    Query {
        p: n.map(|v| (v * r) as f32),
        normal: (rng.below(4) != 0).then(|| normal.map(|v| v / l)),
        footprint: (rng.below(2) == 0).then(|| Footprint {
            dpdx: unit(rng).map(|v| v as f32 * k),
            dpdy: unit(rng).map(|v| v as f32 * k * 0.5),
        }),
    }
}
