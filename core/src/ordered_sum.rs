//! Parallel sums whose bits do not depend on the thread count.
//!
//! rayon's `sum` and `reduce` split the work adaptively, so the order in which floating-point
//! partial sums are added (and thus the rounding) changes with the number of threads and with
//! the load: the same input gave a different Poisson mesh with `--threads 1` than with 2.
//! Here the index range is cut into fixed blocks of [`BLOCK`] items; each block is summed in
//! order (in parallel across blocks) and the block sums are added in order. The result is the
//! same on any machine with any thread count.

use rayon::prelude::*;

/// Items per block: large enough that a block is worth a task, small enough to balance.
pub const BLOCK: usize = 4096;

/// `sum_{i < n} f(i)` for `K` quantities at once, in a fixed association order.
pub fn ordered_sum<const K: usize>(n: usize, f: impl Fn(usize) -> [f64; K] + Sync) -> [f64; K] {
    let blocks: Vec<[f64; K]> = (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let mut acc = [0.0; K];
            for i in b * BLOCK..((b + 1) * BLOCK).min(n) {
                let v = f(i);
                for k in 0..K {
                    acc[k] += v[k];
                }
            }
            acc
        })
        .collect();
    let mut total = [0.0; K];
    for b in blocks {
        for k in 0..K {
            total[k] += b[k];
        }
    }
    total
}

/// The dot product of `a` and `b` (equal lengths) in a fixed association order.
pub fn ordered_dot(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    ordered_sum(a.len(), |i| [a[i] * b[i]])[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_bits_whatever_the_thread_count() {
        let a: Vec<f64> = (0..100_003)
            .map(|i| ((i * 7919) % 1000) as f64 * 1e-3 + 1e-9 * i as f64)
            .collect();
        let b: Vec<f64> = a.iter().map(|x| 1.0 / (1.0 + x)).collect();
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| ordered_dot(&a, &b))
        };
        let one = run(1);
        assert_eq!(one.to_bits(), run(2).to_bits());
        assert_eq!(one.to_bits(), run(5).to_bits());
        let exact: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((one - exact).abs() <= 1e-9 * exact.abs());
    }

    #[test]
    fn several_quantities_and_empty_ranges() {
        assert_eq!(ordered_sum(0, |_| [1.0, 2.0]), [0.0, 0.0]);
        let s = ordered_sum(10_000, |i| [1.0, i as f64]);
        assert_eq!(s, [10_000.0, 49_995_000.0]);
    }
}
