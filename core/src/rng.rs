//! The one seeded random generator of fresco: SplitMix64 (Steele, Lea and Flood, "Fast
//! splittable pseudorandom number generators", OOPSLA 2014).
//!
//! Why SplitMix64 and not a crate: every draw fresco makes (RANSAC samples, PatchMatch
//! initialisation, synthetic scenes, test data) must give the same bits on every machine and
//! every version of the dependencies, so the generator is written down here, eight lines of
//! arithmetic, and pinned by a test. It passes BigCrush and is more than enough for sampling;
//! it is not for cryptography.
//!
//! Parallel loops must not share one generator (the result would depend on the scheduling):
//! derive one per item with [`Rng::for_item`], which hashes the seed with the item's index.

/// SplitMix64's golden-ratio increment.
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function applied to `x + golden gamma`: a good 64-bit hash of `x`
/// (used to derive seeds and to hash lattice coordinates in procedural noise).
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(GOLDEN_GAMMA);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A seeded SplitMix64 stream.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// The stream that starts from `seed`.
    pub fn new(seed: u64) -> Rng {
        Rng { state: seed }
    }

    /// An independent stream for item `index` of a parallel loop seeded by `seed`: the same
    /// draws whatever the thread count or the order the items run in.
    pub fn for_item(seed: u64, index: u64) -> Rng {
        Rng::new(splitmix64(seed ^ splitmix64(index)))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN_GAMMA);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Uniform integer in `0..n` (`n > 0`) by Lemire's multiply-shift (bias below 2^-32 for
    /// any `n` below 2^32).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.next_u64() as u128 * n as u128) >> 64) as usize
    }

    /// Standard normal by Box–Muller (one value of the pair; `1 - u` keeps the logarithm finite).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_matches_the_published_reference_stream() {
        // First outputs of SplitMix64 seeded with 1234567 (the reference C implementation
        // by Vigna, splitmix64.c).
        let mut rng = Rng::new(1234567);
        let expected = [
            6457827717110365317u64,
            3203168211198807973,
            9817491932198370423,
            4593380528125082431,
            16408922859458223821,
        ];
        for e in expected {
            assert_eq!(rng.next_u64(), e);
        }
    }

    #[test]
    fn uniform_below_and_normal_stay_in_their_ranges_with_the_right_moments() {
        let mut rng = Rng::new(7);
        let n = 200_000;
        let (mut sum, mut sum_sq) = (0.0, 0.0);
        let mut counts = [0usize; 10];
        for _ in 0..n {
            let u = rng.uniform();
            assert!((0.0..1.0).contains(&u));
            counts[rng.below(10)] += 1;
            let g = rng.normal();
            sum += g;
            sum_sq += g * g;
        }
        let mean = sum / n as f64;
        let var = sum_sq / n as f64 - mean * mean;
        // Standard error of the mean is 1/sqrt(n) = 0.0022; of the variance about 0.0032.
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.015, "variance {var}");
        for c in counts {
            // Expected 20000 each, standard deviation about 134.
            assert!((c as i64 - 20_000).abs() < 700, "{counts:?}");
        }
    }

    #[test]
    fn item_streams_differ_and_repeat() {
        let a: Vec<u64> = (0..4).map(|i| Rng::for_item(3, i).next_u64()).collect();
        let b: Vec<u64> = (0..4).map(|i| Rng::for_item(3, i).next_u64()).collect();
        assert_eq!(a, b);
        for i in 0..4 {
            for j in i + 1..4 {
                assert_ne!(a[i], a[j]);
            }
        }
    }
}
