//! Section 3: local up-sampling from the 1-node files, LRU down-sampling that keeps edits
//! across eviction and reload, and the scripted editing operations.

use fresco_core::NoProgress;
use fresco_datasets::shapes;
use fresco_pst::paint::{Op, apply_op};
use fresco_pst::refine::{Resolution, refine};
use fresco_pst::region::Region;
use fresco_pst::{CreateConfig, FieldConfig, MemoryPoints, Pst, SamplingConfig};

fn torus_pst(dir: &std::path::Path, budget: Option<usize>) -> Pst {
    let mesh = shapes::torus(0.7, 0.3, 400, 200);
    let points = MemoryPoints::from_mesh_vertices(&mesh);
    let cfg = CreateConfig {
        sampling: SamplingConfig {
            target: 2000,
            ..Default::default()
        },
        budget,
        ..Default::default()
    };
    Pst::create(&points, &cfg, &dir.join("t.pst"), &NoProgress)
        .unwrap()
        .0
}

fn fill(region: &Region, value: [f32; 3]) -> Op {
    Op::Fill {
        region: region.clone(),
        value: value.to_vec(),
        opacity: 1.0,
        channel: "rgb".into(),
    }
}

fn count_in(s: &fresco_pst::SampleSet, r: &Region) -> usize {
    s.positions.iter().filter(|p| r.contains_f32(**p)).count()
}

#[test]
fn refine_adds_samples_only_in_the_region_coloured_by_the_current_pst() {
    let dir = tempfile::tempdir().unwrap();
    let mut pst = torus_pst(dir.path(), None);
    let a = Region::Sphere {
        center: [0.7, 0.0, 0.3],
        radius: 0.25,
    };
    apply_op(
        &mut pst,
        &fill(&a, [1.0, 0.0, 0.0]),
        dir.path(),
        FieldConfig::default(),
        &NoProgress,
    )
    .unwrap();
    let before_in = count_in(&pst.samples, &a);
    let before_out = pst.samples.len() - before_in;
    let r = refine(
        &mut pst,
        &a,
        Resolution::Factor(3),
        FieldConfig::default(),
        &NoProgress,
    )
    .unwrap();
    let after_in = count_in(&pst.samples, &a);
    assert!(after_in > 4 * before_in, "{before_in} -> {after_in}");
    assert_eq!(pst.samples.len() - after_in, before_out);
    assert_eq!(r.removed, before_in);
    // New samples well inside the painted ball are red (coloured by the PST); near its
    // border the PST blends with the grey outside.
    let core = Region::Sphere {
        center: [0.7, 0.0, 0.3],
        radius: 0.15,
    };
    for i in 0..pst.samples.len() {
        if core.contains_f32(pst.samples.positions[i]) {
            let c = pst.samples.attr(i);
            assert!(c[0] > 0.99 && c[1] < 0.01, "{c:?}");
        }
    }
    // Full resolution keeps every input vertex of the region.
    let small = Region::Sphere {
        center: [-0.7, 0.0, 0.3],
        radius: 0.1,
    };
    refine(
        &mut pst,
        &small,
        Resolution::Full,
        FieldConfig::default(),
        &NoProgress,
    )
    .unwrap();
    let mesh = shapes::torus(0.7, 0.3, 400, 200);
    let expected = mesh
        .positions
        .iter()
        .filter(|p| small.contains([p.x, p.y, p.z]))
        .count();
    assert_eq!(count_in(&pst.samples, &small), expected);
}

#[test]
fn lru_keeps_edits_across_eviction_and_reload() {
    let dir = tempfile::tempdir().unwrap();
    let mut pst = torus_pst(dir.path(), Some(700));
    let f = FieldConfig::default();
    let a = Region::Sphere {
        center: [0.7, 0.0, 0.3],
        radius: 0.25,
    };
    let b = Region::Sphere {
        center: [-0.7, 0.0, 0.3],
        radius: 0.25,
    };
    apply_op(
        &mut pst,
        &fill(&a, [1.0, 0.0, 0.0]),
        dir.path(),
        f,
        &NoProgress,
    )
    .unwrap();
    refine(&mut pst, &a, Resolution::Factor(3), f, &NoProgress).unwrap();
    apply_op(
        &mut pst,
        &fill(&a, [0.0, 1.0, 0.0]),
        dir.path(),
        f,
        &NoProgress,
    )
    .unwrap();
    let a_samples: Vec<([f32; 3], Vec<f32>)> = (0..pst.samples.len())
        .filter(|&i| a.contains_f32(pst.samples.positions[i]))
        .map(|i| (pst.samples.positions[i], pst.samples.attr(i).to_vec()))
        .collect();
    // Refining far away overflows the budget: region a, now the least recently used, is evicted.
    let r = refine(&mut pst, &b, Resolution::Factor(3), f, &NoProgress).unwrap();
    assert!(!r.lru.evicted.is_empty());
    assert!(
        pst.samples.len() <= 700 || r.lru.over_budget,
        "{}",
        pst.samples.len()
    );
    let a_nodes = pst.nodes_in_region(&a);
    assert!(
        a_nodes
            .iter()
            .any(|&id| !pst.manifest.nodes[id as usize].resident)
    );
    // The ring around b is never evicted.
    for id in pst.ring(&pst.nodes_in_region(&b)) {
        assert!(!r.lru.evicted.contains(&id));
    }
    // Saved and reopened, then a touches a: the green, refined samples come back exactly.
    pst.save().unwrap();
    let mut pst = Pst::open(&pst.dir).unwrap();
    let all = pst.all_samples().unwrap();
    assert_eq!(count_in(&all, &a), a_samples.len());
    pst.touch(&a_nodes).unwrap();
    let mut back: Vec<([f32; 3], Vec<f32>)> = (0..pst.samples.len())
        .filter(|&i| a.contains_f32(pst.samples.positions[i]))
        .map(|i| (pst.samples.positions[i], pst.samples.attr(i).to_vec()))
        .collect();
    let mut orig = a_samples.clone();
    let key = |x: &([f32; 3], Vec<f32>)| (x.0[0].to_bits(), x.0[1].to_bits(), x.0[2].to_bits());
    back.sort_by_key(key);
    orig.sort_by_key(key);
    assert_eq!(back, orig);
}

#[test]
fn edits_reach_evicted_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let mut pst = torus_pst(dir.path(), Some(1000));
    let f = FieldConfig::default();
    let a = Region::Sphere {
        center: [0.7, 0.0, 0.3],
        radius: 0.3,
    };
    // Painting a touches it; budget 1000 < 2000 evicts other nodes.
    apply_op(
        &mut pst,
        &fill(&a, [0.0, 0.0, 1.0]),
        dir.path(),
        f,
        &NoProgress,
    )
    .unwrap();
    assert!(pst.samples.len() <= 1000 || pst.enforce_budget(&[]).unwrap().over_budget);
    assert!(pst.manifest.nodes.iter().any(|n| !n.resident));
    // A global fill edits the evicted nodes' files too.
    apply_op(
        &mut pst,
        &fill(&Region::All, [0.25, 0.5, 0.75]),
        dir.path(),
        f,
        &NoProgress,
    )
    .unwrap();
    let all = pst.all_samples().unwrap();
    assert!(all.len() >= 1990);
    for i in 0..all.len() {
        assert_eq!(all.attr(i), &[0.25f32, 0.5, 0.75][..]);
    }
}

#[test]
fn scripted_noise_smooth_and_projection() {
    let dir = tempfile::tempdir().unwrap();
    let mut pst = torus_pst(dir.path(), None);
    // A 4x4 bitmap: left half red, right half blue, projected from above (+z looking down).
    let mut img = image::RgbaImage::new(4, 4);
    for (x, _, p) in img.enumerate_pixels_mut() {
        *p = if x < 2 {
            image::Rgba([255, 0, 0, 255])
        } else {
            image::Rgba([0, 0, 255, 255])
        };
    }
    img.save(dir.path().join("lr.png")).unwrap();
    let script = r#"{"ops": [
        {"op": "noise", "a": [0, 0, 0], "b": [1, 1, 1], "scale": 4, "seed": 3},
        {"op": "add_channel", "name": "specular", "default": [0.25]},
        {"op": "project", "image": "lr.png", "origin": [-1, 1, 1], "u": [2, 0, 0], "v": [0, -2, 0], "upsample": true},
        {"op": "smooth", "region": {"sphere": {"center": [0, -0.7, -0.3], "radius": 0.2}}, "iterations": 2}
    ]}"#;
    let path = dir.path().join("ops.json");
    std::fs::write(&path, script).unwrap();
    let before = pst.samples.len();
    let reports =
        fresco_pst::paint::run_script(&mut pst, &path, FieldConfig::default(), &NoProgress)
            .unwrap();
    assert_eq!(reports.len(), 4);
    // The projector's pixel is 0.5 wide, coarser than the samples: up-sampling keeps the count.
    assert!(pst.samples.len() >= before - 10);
    let reopened = Pst::open(&pst.dir).unwrap();
    assert_eq!(reopened.manifest.channels.len(), 2);
    for i in 0..reopened.samples.len() {
        let p = reopened.samples.positions[i];
        let n = reopened.samples.normals[i];
        let c = reopened.samples.attr(i);
        // New samples of the up-sampling are interpolated by the PST: equal up to rounding.
        assert!((c[3] - 0.25).abs() < 1e-6);
        if n[2] > 0.2 && p[0].abs() > 0.05 {
            // Upward-facing: painted by the projector, red on x < 0, blue on x > 0.
            let expected = if p[0] < 0.0 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            };
            // Bilinear filtering blends across the middle column only.
            if p[0].abs() > 0.5 {
                for k in 0..3 {
                    assert!((c[k] - expected[k]).abs() < 1e-5, "at {p:?}: {c:?}");
                }
            }
        }
        if n[2] < -0.2 {
            // Downward-facing: noise, grey levels in [0, 1].
            assert!(c[0] == c[1] && c[1] == c[2] && (0.0..=1.0).contains(&c[0]));
        }
    }
    // Bad ops: a clear error naming the op.
    std::fs::write(&path, r#"{"ops": [{"op": "fill", "value": [1, 0]}]}"#).unwrap();
    let err = fresco_pst::paint::run_script(&mut pst, &path, FieldConfig::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("operation 0") && err.contains("3 values"),
        "{err}"
    );
}
