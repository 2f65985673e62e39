//! Keyframed sprites through the tree (issue 16, sprite keyframes): a tree built once and
//! moved from frame to frame by `Scene::update` (one `SpriteTree::update` per changed
//! sprite, section 5.2 of the sprites paper) gives the lookups of a tree built from scratch
//! with that frame's sprites and of the brute-force evaluation, bit for bit, for every blend
//! mode, and stays minimal with the same shape.

mod support;

use fresco_core::Rng;
use fresco_sprites::scene::{Key, Scene, SpriteSpec};
use fresco_sprites::{BlendConfig, BlendMode, Pattern, Query, TreeConfig};
use image::{Rgba, RgbaImage};
use support::{random_query, unit};

/// A radial-alpha disc (tabulated distance, as blobby and Voronoi patterns are), a
/// hard-edged square ring and half-transparent stripes.
fn patterns() -> Vec<Pattern> {
    let disc = RgbaImage::from_fn(32, 32, |x, y| {
        let (dx, dy) = (x as f32 - 15.5, y as f32 - 15.5);
        let r = (dx * dx + dy * dy).sqrt() / 16.0;
        let k = (200.0 * r).min(200.0);
        Rgba([
            (k + 40.0) as u8,
            90,
            (255.0 - k) as u8,
            ((1.0 - r).max(0.0) * 255.0) as u8,
        ])
    });
    let ring = RgbaImage::from_fn(24, 24, |x, y| {
        let edge = x.min(y).min(23 - x).min(23 - y);
        Rgba([250, 220, 40, if (3..8).contains(&edge) { 255 } else { 0 }])
    });
    let stripes = RgbaImage::from_fn(16, 8, |x, _| {
        Rgba([if x % 4 < 2 { 255 } else { 30 }, 60, 120, 160])
    });
    [disc, ring, stripes].iter().map(Pattern::new).collect()
}

/// `p` moved by up to `r` in a random direction, back onto the unit sphere.
fn near(rng: &mut Rng, p: [f64; 3], r: f64) -> [f64; 3] {
    let d = unit(rng);
    let q = [0, 1, 2].map(|a| p[a] + r * rng.uniform() * d[a]);
    let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
    q.map(|v| v / l)
}

/// Sprites on the unit sphere that wander over it: keys at t = 0, 1, 2, 3 with centres,
/// normals (radial, tilted a little), sizes and rotations drawn at random, some fields left
/// out (the sprite's own value), spin and pattern cycling on some.
fn scene(rng: &mut Rng, count: usize, mode: Option<BlendMode>) -> Scene {
    let mut sprites = Vec::new();
    for i in 0..count {
        let c = unit(rng);
        let size = rng.range(0.08, 0.3);
        let mut keys = Vec::new();
        let mut p = c;
        for k in 0..4 {
            p = near(rng, p, 0.25);
            let tilt = unit(rng);
            let s = size * rng.range(0.6, 1.4);
            keys.push(Key {
                t: k as f64 + rng.range(0.0, 0.5),
                center: (rng.below(4) != 0).then_some(p),
                normal: (rng.below(3) != 0).then(|| [0, 1, 2].map(|a| p[a] + 0.2 * tilt[a])),
                size: (rng.below(3) != 0).then(|| [s, s * rng.range(0.7, 1.3)]),
                rotation: (rng.below(2) != 0).then(|| rng.range(-360.0, 360.0)),
            });
        }
        let spec = SpriteSpec {
            center: c,
            normal: c,
            up: None,
            size: [size, size],
            depth: Some(size * 0.5),
            rotation: rng.range(0.0, 360.0),
            pattern: rng.below(3) as u32,
            order: rng.below(20) as i64,
            blend: mode.unwrap_or(BlendMode::ALL[i % 4]),
            attributes: Vec::new(),
            spin: if i.is_multiple_of(3) {
                rng.range(-90.0, 90.0)
            } else {
                0.0
            },
            cycle: if i.is_multiple_of(5) {
                vec![2, 0, 1]
            } else {
                Vec::new()
            },
            cycle_fps: 2.0,
            keys,
        };
        spec.check(i, 3).unwrap();
        sprites.push(spec);
    }
    Scene {
        tree: TreeConfig {
            n: 4,
            o_max: 16,
            max_depth: 16,
        },
        blend: BlendConfig::default(),
        bounds: None,
        pattern_paths: Vec::new(),
        patterns: patterns(),
        sprites,
    }
}

#[test]
fn updated_tree_equals_a_tree_built_at_each_frame_and_brute_force() {
    let (lo, hi) = ([-1.1; 3], [1.1; 3]);
    for mode in [None]
        .into_iter()
        .chain(BlendMode::ALL.into_iter().map(Some))
    {
        let mut rng = Rng::new(7 + mode.map_or(0, |m| 1 + m as u64));
        let scene = scene(&mut rng, 150, mode);
        let mut tree = scene.build(lo, hi, 0.0).unwrap();
        let (mut updated, mut repatterned, mut covered) = (0, 0, 0);
        // 4 frames a second over the keys (0 to 3.5 s), then past the last key (spin only).
        for k in 1..=18 {
            let t = k as f64 / 4.0;
            let report = scene.update(&mut tree, t).unwrap();
            assert!(
                !report.rebuilt,
                "{mode:?} t = {t}: the update path was taken"
            );
            updated += report.updated;
            repatterned += report.repatterned;
            let fresh = scene.build(lo, hi, t).unwrap();
            assert!(tree.is_minimal(), "{mode:?} t = {t}");
            // The minimal tree of a set of sprites is unique: same shape as the fresh one.
            let (a, b) = (tree.memory(), fresh.memory());
            assert_eq!(
                (a.nodes_used, a.leaf_vectors_used, a.depth, a.fullest_leaf),
                (b.nodes_used, b.leaf_vectors_used, b.depth, b.fullest_leaf),
                "{mode:?} t = {t}"
            );
            for id in 0..scene.sprites.len() {
                assert_eq!(tree.sprite(id), fresh.sprite(id), "{mode:?} t = {t}");
            }
            let order = tree.user_order();
            assert_eq!(order, fresh.user_order());
            let queries: Vec<Query> = (0..3000).map(|_| random_query(&mut rng, 0.03)).collect();
            let mut many = vec![[0f32; 4]; queries.len()];
            tree.lookup_many(&queries, &mut many);
            for (q, m) in queries.iter().zip(&many) {
                let bits = |c: [f32; 4]| c.map(f32::to_bits);
                let (a, b, c) = (tree.lookup(q), fresh.lookup(q), tree.brute_force(&order, q));
                assert_eq!(bits(a), bits(b), "{mode:?} t = {t} {q:?}: updated vs fresh");
                assert_eq!(bits(a), bits(c), "{mode:?} t = {t} {q:?}: vs brute force");
                assert_eq!(bits(*m), bits(c), "{mode:?} t = {t} {q:?}: lookup_many");
                covered += usize::from(a[3] > 0.0);
            }
        }
        // Every frame moves most sprites (and only the cycling ones change pattern alone).
        assert!(updated > 18 * 100, "{mode:?}: {updated} updates");
        assert!(covered > 18 * 500, "{mode:?}: {covered} points covered");
        // Past the last key the cycling sprites that do not spin change pattern alone.
        assert!(repatterned > 0, "{mode:?}: no pattern-only change");
    }
}

/// Moving the tree back and forth in time (frames out of order, a jump back to t = 0)
/// returns the very sprites of each time.
#[test]
fn updates_in_any_time_order_give_the_sprites_of_that_time() {
    let mut rng = Rng::new(99);
    let scene = scene(&mut rng, 80, None);
    let (lo, hi) = ([-1.1; 3], [1.1; 3]);
    let mut tree = scene.build(lo, hi, 1.3).unwrap();
    for t in [2.9, 0.0, 0.4, 5.0, 1.3] {
        scene.update(&mut tree, t).unwrap();
        let want = scene.sprites_at(t).unwrap();
        for (id, s) in want.iter().enumerate() {
            assert_eq!(tree.sprite(id), Some(s), "t = {t}");
        }
        assert!(tree.is_minimal());
    }
    // A tree of another scene is refused, not scrambled.
    let other = fresco_sprites::scene::Scene {
        sprites: scene.sprites[..10].to_vec(),
        ..scene.clone()
    };
    let mut small = other.build(lo, hi, 0.0).unwrap();
    assert!(scene.update(&mut small, 1.0).is_err());
}
