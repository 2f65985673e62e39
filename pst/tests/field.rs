//! The PST equals a brute-force evaluation of section 4's formula.

use fresco_core::Rng;
use fresco_pst::{Field, FieldConfig, Kernel, SampleSet};

/// Points on a unit sphere with a 4-float attribute that varies with position.
fn sphere_samples(n: usize, rng: &mut Rng) -> SampleSet {
    let mut s = SampleSet::with_width(4);
    for _ in 0..n {
        let z = 2.0 * rng.uniform() - 1.0;
        let phi = std::f64::consts::TAU * rng.uniform();
        let r = (1.0 - z * z).sqrt();
        let p = [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32];
        let a = [
            p[0] * 0.5 + 0.5,
            rng.uniform() as f32,
            (3.0 * p[2]).sin(),
            7.0,
        ];
        s.push(p, p, 0, &a);
    }
    s
}

/// Section 4's f_S by ranking every sample by distance (f64).
fn brute_force(s: &SampleSet, p: [f32; 3], k: usize, kernel: Kernel) -> Vec<f64> {
    let mut d: Vec<(f64, usize)> = (0..s.len())
        .map(|i| {
            let q = s.positions[i];
            let d2: f64 = (0..3).map(|a| (p[a] as f64 - q[a] as f64).powi(2)).sum();
            (d2.sqrt(), i)
        })
        .collect();
    // The k nearest by selection (a full sort per query made this test slow).
    d.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
    let nb = &d[..k];
    let dmax = nb.iter().fold(0f64, |m, x| m.max(x.0));
    let mut out = vec![0.0; s.width];
    let mut total = 0.0;
    for &(di, i) in nb {
        let t = di / dmax;
        let h = 1.0 - 3.0 * t * t + 2.0 * t * t * t;
        let w = match kernel {
            Kernel::Hermite => h,
            Kernel::Singular { power } => h / t.powf(power as f64),
        };
        total += w;
        for (o, a) in out.iter_mut().zip(s.attr(i)) {
            *o += w * *a as f64;
        }
    }
    out.iter_mut().for_each(|o| *o /= total);
    out
}

#[test]
fn lookups_equal_brute_force_knn_evaluation() {
    let mut rng = Rng::new(7);
    let samples = sphere_samples(20_000, &mut rng);
    // Queries near the surface (as when colouring a mesh) and a few far off it.
    let queries: Vec<[f32; 3]> = (0..1500)
        .map(|i| {
            let z = 2.0 * rng.uniform() - 1.0;
            let phi = std::f64::consts::TAU * rng.uniform();
            let r = (1.0 - z * z).sqrt();
            let scale = if i % 50 == 0 {
                1.5
            } else {
                1.0 + 0.01 * (rng.uniform() - 0.5)
            };
            [
                (scale * r * phi.cos()) as f32,
                (scale * r * phi.sin()) as f32,
                (scale * z) as f32,
            ]
        })
        .collect();
    for (k, kernel) in [
        (8, Kernel::Hermite),
        (3, Kernel::Hermite),
        (16, Kernel::Singular { power: 2.0 }),
    ] {
        let field = Field::new(&samples, FieldConfig { k, kernel });
        let mut batch = vec![0f32; queries.len() * 4];
        field.eval_many(&queries, &mut batch);
        let mut one = [0f32; 4];
        for (i, q) in queries.iter().enumerate() {
            let expected = brute_force(&samples, *q, k, kernel);
            field.eval(q, &mut one);
            for c in 0..4 {
                // f32 positions and sums against an f64 reference: relative 1e-4 covers the
                // rounding of a few dozen products of values below 7 near the surface. Far off
                // the surface (every 50th query, at 1.5 radii) the k distances differ by less
                // than 1e-3 of their size, so t = d / d_max sits near 1 where h(t) ~ 3 (1-t)^2
                // amplifies f32 rounding of d a thousandfold: 1e-2 there.
                let tol = if i % 50 == 0 { 1e-2 } else { 1e-4 } * (1.0 + expected[c].abs());
                assert!(
                    (batch[i * 4 + c] as f64 - expected[c]).abs() < tol,
                    "k = {k}, query {i} channel {c}: batch {} vs brute force {}",
                    batch[i * 4 + c],
                    expected[c]
                );
                assert!((one[c] as f64 - expected[c]).abs() < tol);
            }
        }
    }
}

#[test]
fn dense_lookups_equal_brute_force() {
    // 3000 samples and 60k queries within a sample spacing of them: ~20 queries per sample,
    // some hundred per tile (a fine mesh over a coarse PST, the apply case): every lookup
    // must equal section 4's formula evaluated over all samples.
    let mut rng = Rng::new(11);
    let samples = sphere_samples(3000, &mut rng);
    let spacing = (4.0 * std::f64::consts::PI / 3000.0).sqrt();
    let queries: Vec<[f32; 3]> = (0..60_000)
        .map(|i| {
            let p = samples.positions[i % samples.len()];
            let mut jitter = || (spacing * (rng.uniform() - 0.5)) as f32;
            [p[0] + jitter(), p[1] + jitter(), p[2] + jitter()]
        })
        .collect();
    for (k, kernel) in [(8, Kernel::Hermite), (12, Kernel::Singular { power: 1.5 })] {
        let cfg = FieldConfig { k, kernel };
        let field = Field::new(&samples, cfg);
        let mut batch = vec![0f32; queries.len() * 4];
        field.eval_many(&queries, &mut batch);
        for (i, q) in queries.iter().enumerate() {
            let expected = fresco_pst::bench::brute_force_eval(&samples, q, &cfg);
            for c in 0..4 {
                // As above: f32 against f64 near the surface, relative 1e-4.
                let tol = 1e-4 * (1.0 + expected[c].abs());
                assert!(
                    (batch[i * 4 + c] as f64 - expected[c]).abs() < tol,
                    "k = {k}, query {i} channel {c}: batch {} vs brute force {}",
                    batch[i * 4 + c],
                    expected[c]
                );
            }
        }
    }
}

#[test]
fn coherent_stream_lookups_equal_brute_force() {
    // Queries in the order a mesh's vertex stream gives them: rows of a latitude-longitude
    // grid, alternately just inside and outside the sphere, so that consecutive queries share
    // grid cells and each query's candidate bound comes from the previous one's k-th
    // distance. Also k larger than the sample count (every sample is a neighbour).
    let mut rng = Rng::new(5);
    let samples = sphere_samples(4000, &mut rng);
    let (rows, cols) = (120, 240);
    let mut queries: Vec<[f32; 3]> = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        let theta = std::f64::consts::PI * (r as f64 + 0.5) / rows as f64;
        for c in 0..cols {
            let phi = std::f64::consts::TAU * c as f64 / cols as f64;
            let radius = if (r + c) % 2 == 0 { 0.997 } else { 1.003 };
            queries.push([
                (radius * theta.sin() * phi.cos()) as f32,
                (radius * theta.sin() * phi.sin()) as f32,
                (radius * theta.cos()) as f32,
            ]);
        }
    }
    for k in [1, 8, 24] {
        let cfg = FieldConfig {
            k,
            kernel: Kernel::Hermite,
        };
        let field = Field::new(&samples, cfg);
        let mut batch = vec![0f32; queries.len() * 4];
        field.eval_many(&queries, &mut batch);
        for (i, q) in queries.iter().enumerate().step_by(7) {
            let expected = fresco_pst::bench::brute_force_eval(&samples, q, &cfg);
            for c in 0..4 {
                // f32 against f64 near the surface, relative 1e-4 (as above).
                let tol = 1e-4 * (1.0 + expected[c].abs());
                assert!(
                    (batch[i * 4 + c] as f64 - expected[c]).abs() < tol,
                    "k = {k}, query {i} channel {c}: batch {} vs brute force {}",
                    batch[i * 4 + c],
                    expected[c]
                );
            }
        }
    }
    // Fewer samples than k: the average over all of them, weighted by h.
    let few = sphere_samples(10, &mut rng);
    let cfg = FieldConfig {
        k: 20,
        kernel: Kernel::Hermite,
    };
    let field = Field::new(&few, cfg);
    let mut batch = vec![0f32; 200 * 4];
    field.eval_many(&queries[..200], &mut batch);
    for (i, q) in queries[..200].iter().enumerate() {
        let expected = fresco_pst::bench::brute_force_eval(&few, q, &cfg);
        for c in 0..4 {
            assert!(
                (batch[i * 4 + c] as f64 - expected[c]).abs() < 1e-4 * (1.0 + expected[c].abs())
            );
        }
    }
}
