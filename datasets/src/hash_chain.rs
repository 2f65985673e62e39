//! The draws of the synthetic scenes and the procedural albedo: a chain of core's SplitMix64
//! hash, `x <- splitmix64(x)`, not `fresco_core::Rng`'s stream (`x <- x + gamma`, output
//! `mix(x)`). Kept because every camera layout, exposure and palette of the synthetic scenes
//! (which the sfm, dense and atlas tests and the bench/RESULTS.md figures on synthetic scenes
//! are tuned on) comes from these bits; switching to `Rng` would redraw every scene. The hash
//! itself is the one in `fresco_core::rng`.

use fresco_core::rng::splitmix64;

pub(crate) struct HashChain(u64);

impl HashChain {
    /// The chain whose first draw is `splitmix64(start)`.
    pub(crate) fn starting_at(start: u64) -> HashChain {
        HashChain(start)
    }

    /// Stream `stream` of `seed`: the chain starting at `splitmix64(seed ^ splitmix64(stream))`.
    pub(crate) fn stream(seed: u64, stream: u64) -> HashChain {
        HashChain(splitmix64(seed ^ splitmix64(stream)))
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub(crate) fn unit(&mut self) -> f64 {
        self.0 = splitmix64(self.0);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [-1, 1).
    pub(crate) fn signed(&mut self) -> f64 {
        2.0 * self.unit() - 1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chain_feeds_each_hash_into_the_next() {
        let mut chain = HashChain::starting_at(42);
        let first = splitmix64(42);
        let second = splitmix64(first);
        assert_eq!(chain.unit(), (first >> 11) as f64 / (1u64 << 53) as f64);
        assert_eq!(
            chain.signed(),
            2.0 * ((second >> 11) as f64 / (1u64 << 53) as f64) - 1.0
        );
        let s = HashChain::stream(7, 1).unit();
        assert_eq!(
            s,
            HashChain::starting_at(splitmix64(7 ^ splitmix64(1))).unit()
        );
    }
}
