//! The tree lookup equals a brute-force evaluation over all sprites (issue 16's first "must
//! show"), for every blend mode and N = 2, 4, 8, one query at a time and in batches in surface
//! order (`lookup_many`), and stays so through deletions and updates;
//! insertion failures are errors that leave the tree unchanged.

mod support;

use fresco_core::Rng;
use fresco_sprites::{
    BlendConfig, BlendMode, Footprint, Pattern, Placement, Query, Sprite, SpriteError, SpriteTree,
    TreeConfig,
};
use image::{Rgba, RgbaImage};
use support::{random_query, unit};

/// A radial-alpha disc with a coloured ring (a tabulated distance in alpha, as blobby and
/// Voronoi patterns are), a hard-edged star and a half-transparent stripe pattern.
fn patterns() -> Vec<Pattern> {
    let disc = RgbaImage::from_fn(32, 32, |x, y| {
        let (dx, dy) = (x as f32 - 15.5, y as f32 - 15.5);
        let r = (dx * dx + dy * dy).sqrt() / 16.0;
        let a = ((1.0 - r).max(0.0) * 255.0) as u8;
        let k = (200.0 * r).min(200.0);
        Rgba([(k + 40.0) as u8, 90, (255.0 - k) as u8, a])
    });
    let star = RgbaImage::from_fn(24, 24, |x, y| {
        let (dx, dy) = (x as f32 - 11.5, y as f32 - 11.5);
        let ang = dy.atan2(dx);
        let r = (dx * dx + dy * dy).sqrt() / 12.0;
        let inside = r < 0.45 + 0.4 * (5.0 * ang).cos().abs();
        Rgba([250, 220, 40, if inside { 255 } else { 0 }])
    });
    let stripes = RgbaImage::from_fn(16, 8, |x, _| {
        Rgba([if x % 4 < 2 { 255 } else { 30 }, 60, 120, 160])
    });
    [disc, star, stripes].iter().map(Pattern::new).collect()
}

/// A sprite on the unit sphere at a random point, random size and rotation.
fn random_sprite(rng: &mut Rng, mode: Option<BlendMode>, order: i64) -> Sprite {
    let n = unit(rng);
    let size = rng.range(0.08, 0.35);
    let blend = mode.unwrap_or(BlendMode::ALL[rng.below(4)]);
    Sprite::placed(
        &Placement {
            center: n,
            normal: n,
            up: [0.0, 0.0, 1.0],
            size: [size, size * rng.range(0.7, 1.3)],
            depth: size * 0.5,
            rotation_deg: rng.range(0.0, 360.0),
        },
        rng.below(3) as u32,
        order,
        blend,
    )
    .unwrap()
}

fn tree(n: u32, o_max: usize) -> SpriteTree {
    let (min, size) = SpriteTree::cube_around([-1.0; 3], [1.0; 3], 0.05);
    SpriteTree::new(
        min,
        size,
        patterns(),
        TreeConfig {
            n,
            o_max,
            max_depth: 32,
        }
        .clamp_depth(),
        &BlendConfig::default(),
    )
    .unwrap()
}

trait ClampDepth {
    fn clamp_depth(self) -> Self;
}
impl ClampDepth for TreeConfig {
    fn clamp_depth(mut self) -> Self {
        self.max_depth = self.max_depth.min(32 / self.n.trailing_zeros());
        self
    }
}

/// Asserts bit equality on `count` random queries; returns how many were covered.
fn assert_equal(tree: &SpriteTree, rng: &mut Rng, count: usize) -> usize {
    let order = tree.user_order();
    let mut covered = 0;
    for _ in 0..count {
        let q = random_query(rng, 0.02);
        let a = tree.lookup(&q);
        let b = tree.brute_force(&order, &q);
        assert_eq!(
            a.map(f32::to_bits),
            b.map(f32::to_bits),
            "{q:?}: {a:?} vs {b:?}"
        );
        covered += (a[3] > 0.0) as usize;
    }
    // Surface order through lookup_many: walks of small steps over the sphere, so that
    // consecutive queries share cells (and the descent), crossing cell borders now and then.
    let mut walk = Vec::new();
    for _ in 0..count / 200 {
        let mut q = random_query(rng, 0.02);
        let step = unit(rng).map(|v| v as f32 * 2e-3);
        for _ in 0..200 {
            q.p = [0, 1, 2].map(|a| q.p[a] + step[a]);
            walk.push(q);
        }
    }
    let mut out = vec![[0f32; 4]; walk.len()];
    tree.lookup_many(&walk, &mut out);
    // The baseline-instruction version too (lookup_many runs the AVX2 one where the CPU has
    // it).
    let mut baseline = vec![[0f32; 4]; walk.len()];
    tree.lookup_many_baseline(&walk, &mut baseline);
    for ((q, a), c) in walk.iter().zip(&out).zip(&baseline) {
        let b = tree.brute_force(&order, q);
        assert_eq!(
            a.map(f32::to_bits),
            b.map(f32::to_bits),
            "lookup_many {q:?}: {a:?} vs {b:?}"
        );
        assert_eq!(
            c.map(f32::to_bits),
            b.map(f32::to_bits),
            "lookup_many_baseline {q:?}: {c:?} vs {b:?}"
        );
    }
    covered
}

#[test]
fn lookups_equal_brute_force_for_every_blend_mode_and_n() {
    for n in [2, 4, 8] {
        for mode in [None]
            .into_iter()
            .chain(BlendMode::ALL.into_iter().map(Some))
        {
            let mut rng = Rng::new(n as u64 * 31 + mode.map_or(9, |m| m as u64));
            let mut t = tree(n, 16);
            let mut added = 0;
            for k in 0..400 {
                let order = rng.below(50) as i64 - k % 3;
                let s = random_sprite(&mut rng, mode, order);
                if t.add(s).is_ok() {
                    added += 1;
                }
            }
            assert!(added >= 380, "N={n} {mode:?}: {added} sprites inserted");
            let covered = assert_equal(&t, &mut rng, 20_000);
            assert!(
                covered > 10_000,
                "N={n} {mode:?}: only {covered} points covered"
            );
            assert!(t.is_minimal());
            let m = t.memory();
            assert!(m.depth >= 2, "the tree splits: {m:?}");
        }
    }
}

#[test]
fn deletions_and_updates_keep_lookups_exact_and_the_tree_minimal() {
    for n in [2, 4, 8] {
        let mut rng = Rng::new(100 + n as u64);
        let mut t = tree(n, 8);
        let mut ids = Vec::new();
        for k in 0..200 {
            if let Ok(id) = t.add(random_sprite(&mut rng, None, k)) {
                ids.push(id);
            }
        }
        let before = t.memory();
        // Lookups before the changes (the lookup layout is built), then after them.
        assert_equal(&t, &mut rng, 1_000);
        // Delete every third sprite, move or rescale every other one.
        for (k, &id) in ids.iter().enumerate() {
            if k % 3 == 0 {
                t.remove(id).unwrap();
            } else if k % 2 == 0 {
                let s = random_sprite(&mut rng, None, k as i64);
                let cells = t.pool().cells().to_vec();
                if t.update(id, s).is_err() {
                    assert_eq!(
                        t.pool().cells(),
                        &cells[..],
                        "a failed update changes nothing"
                    );
                }
            }
        }
        assert!(t.is_minimal(), "N={n}");
        assert_equal(&t, &mut rng, 5_000);
        // Re-adding into freed ids and removing everything gives back the empty root.
        for id in t.ids().collect::<Vec<_>>() {
            t.remove(id).unwrap();
        }
        let m = t.memory();
        assert_eq!(
            (m.nodes_used, m.leaf_vectors_used, m.sprites),
            (1, 0, 0),
            "{before:?}"
        );
        assert!(
            t.pool().cells()[..t.pool().cells_per_node()]
                .iter()
                .all(|&c| c == 0)
        );
    }
}

#[test]
fn insertion_failures_are_errors_that_leave_the_tree_unchanged() {
    let mut t = tree(4, 2);
    let mut rng = Rng::new(5);
    let s = random_sprite(&mut rng, Some(BlendMode::Over), 0);
    t.add(s.clone()).unwrap();
    t.add(s.clone()).unwrap();
    let cells = t.pool().cells().to_vec();
    let err = t.add(s.clone()).unwrap_err();
    assert!(
        matches!(
            err,
            SpriteError::OmaxTooSmall {
                index: 2,
                o_max: 2,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("O_max too small"));
    assert_eq!(t.pool().cells(), &cells[..]);
    assert_eq!(t.len(), 2);
    // Two sprites side by side that a third overlaps both of, but not together inside
    // any cell deep enough: with max_depth 1 the split is refused.
    let t = TreeConfig {
        n: 2,
        o_max: 1,
        max_depth: 1,
    };
    t.check().unwrap();
    let mut t = SpriteTree::new([-2.0; 3], 4.0, patterns(), t, &BlendConfig::default()).unwrap();
    let place = |x: f64| {
        Sprite::placed(
            &Placement {
                center: [x, 0.5, 0.5],
                normal: [0.0, 0.0, 1.0],
                up: [0.0, 1.0, 0.0],
                size: [0.2, 0.2],
                depth: 0.1,
                rotation_deg: 0.0,
            },
            0,
            0,
            BlendMode::Over,
        )
        .unwrap()
    };
    t.add(place(0.5)).unwrap();
    let err = t.add(place(0.9)).unwrap_err();
    assert!(err.to_string().contains("max depth reached"), "{err}");
    assert_eq!(t.len(), 1);
    assert!(t.is_minimal());
    // A NaN frame is refused naming the sprite.
    let mut bad = place(0.0);
    bad.l[0] = f64::NAN;
    let err = t.add(bad).unwrap_err();
    assert!(err.to_string().starts_with("sprite 1:"), "{err}");
}

/// Tree mip-mapping (section 6): every cell's mean, at every level, equals the mean of the
/// brute-force composite over the samples in that cell; a footprint wider than the cube
/// reads the root cell's mean, a zero footprint the full lookup.
#[test]
fn tree_mip_means_equal_brute_force_cell_averages() {
    use fresco_sprites::tree_mip::TreeMip;
    use std::collections::HashMap;
    let mut rng = Rng::new(77);
    let mut t = tree(2, 8);
    for k in 0..200 {
        let _ = t.add(random_sprite(&mut rng, None, k));
    }
    let samples: Vec<Query> = (0..20_000).map(|_| random_query(&mut rng, 0.02)).collect();
    let mip = TreeMip::new(&t, &samples);
    let order = t.user_order();
    let e = t.config().n.trailing_zeros();
    let depth = t.memory().depth;
    assert!(depth >= 3, "{depth}");
    for level in 0..depth {
        let shift = 32 - e * (level + 1);
        let mut groups: HashMap<[u32; 3], ([f64; 4], usize)> = HashMap::new();
        for q in &samples {
            let Some(f) = t.fixed_inside(q.p) else {
                continue;
            };
            let c = t.brute_force(&order, q);
            let g = groups.entry(f.map(|v| v >> shift)).or_default();
            for (s, v) in g.0.iter_mut().zip(c) {
                *s += v as f64;
            }
            g.1 += 1;
        }
        let mut checked = 0;
        for q in samples.iter().take(3000) {
            let f = t.fixed_inside(q.p).unwrap();
            // None: the descent ends above this level here.
            let Some(m) = mip.mean_at(&t, q.p, level) else {
                continue;
            };
            let g = groups[&f.map(|v| v >> shift)];
            for k in 0..4 {
                let want = g.0[k] / g.1 as f64;
                assert!(
                    (m[k] as f64 - want).abs() < 1e-6,
                    "level {level}: {m:?} vs {want} ({} samples)",
                    g.1
                );
            }
            checked += 1;
        }
        assert!(checked > 50, "level {level}: {checked} cells checked");
    }
    let q = samples[0];
    let root = mip.lookup(&t, &q, 100.0);
    assert_eq!(Some(root), mip.mean_at(&t, q.p, 0));
    assert_eq!(mip.lookup(&t, &q, 0.0), t.lookup(&q));
    // The filtered lookup (the render's): footprints an eighth of the finest cells (below
    // the plain lookup's sqrt(3) c_L / N) or none give the plain lookup bit for bit; a
    // footprint wider than the cube gives a convex mix of root-level means, so a
    // premultiplied colour (within [0, 1], alpha at least each channel).
    let k = (t.cube().1 / 2f64.powi(depth as i32) / 8.0) as f32;
    let near: Vec<Query> = samples[..2000]
        .iter()
        .map(|q| Query {
            footprint: q.footprint.map(|f| Footprint {
                dpdx: f.dpdx.map(|v| v.clamp(-k, k) / 2.0),
                dpdy: f.dpdy.map(|v| v.clamp(-k, k) / 2.0),
            }),
            ..*q
        })
        .collect();
    let mut out = vec![[0f32; 4]; near.len()];
    mip.lookup_many(&t, &near, &mut out);
    for (q, o) in near.iter().zip(&out) {
        assert_eq!(o.map(f32::to_bits), t.lookup(q).map(f32::to_bits));
    }
    let far: Vec<Query> = near
        .iter()
        .map(|q| Query {
            footprint: Some(Footprint {
                dpdx: [100.0, 0.0, 0.0],
                dpdy: [0.0, 0.0, 0.0],
            }),
            ..*q
        })
        .collect();
    mip.lookup_many(&t, &far, &mut out);
    let mut changed = 0;
    for (q, o) in far.iter().zip(&out) {
        assert!(o.iter().all(|v| (0.0..=1.0 + 1e-6).contains(v)), "{o:?}");
        assert!(o[..3].iter().all(|&v| v <= o[3] + 1e-6), "{o:?}");
        changed += usize::from(*o != t.lookup(q));
    }
    assert!(changed > 1000, "{changed}");
}

/// The memory report against the 2D texture of the same resolution: three sprites with
/// densities 32 / 0.1, 24 / 0.2 and 32 / 0.4 texels per unit (median 120) over an area of
/// 2.5 give 2.5 x 120^2 RGBA8 texels; without an area the tree reports none.
#[test]
fn memory_report_sets_the_sprites_against_the_2d_texture() {
    let mut t = tree(4, 8);
    for (k, (size, pattern)) in [(0.1, 0), (0.2, 1), (0.4, 0)].into_iter().enumerate() {
        let s = Sprite::placed(
            &Placement {
                center: [0.3 * k as f64, 0.0, 0.5],
                normal: [0.0, 0.0, 1.0],
                up: [0.0, 1.0, 0.0],
                size: [size, 0.1],
                depth: 0.1,
                rotation_deg: 0.0,
            },
            pattern,
            0,
            BlendMode::Over,
        )
        .unwrap();
        t.add(s).unwrap();
    }
    assert_eq!(t.memory().texture_2d_bytes, None);
    let m = t.memory_on(2.5);
    let want = 2.5 * 120.0f64 * 120.0 * 4.0;
    let got = m.texture_2d_bytes.unwrap() as f64;
    assert!((got - want).abs() <= 1.0, "{got} vs {want}");
    assert!(m.structure_bytes > 0 && m.pattern_bytes > 0);
}
