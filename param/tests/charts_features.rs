//! Feature identification: the area function, its separating band, and protrusions cut
//! off as disc charts.

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Mesh, NoProgress, Topology};
use fresco_datasets::shapes;
use fresco_param::charts::{ChartConfig, segment, sub_mesh};
use fresco_param::features::{gaussian_smooth, separating_band};

#[test]
fn gaussian_keeps_area_and_flattens_noise() {
    let mut a: Vec<f64> = (0..40)
        .map(|i| if i % 2 == 0 { 1.0 } else { 3.0 })
        .collect();
    let sum: f64 = a.iter().sum();
    gaussian_smooth(&mut a, 30);
    // Replicated ends keep the mean up to the end effects; alternation (the highest
    // frequency) is removed by the first pass already.
    assert!((a.iter().sum::<f64>() - sum).abs() < 0.05 * sum);
    assert!(a[10..30].iter().all(|&x| (x - 2.0).abs() < 0.01), "{a:?}");
}

#[test]
fn separating_band_finds_the_jump_after_a_cone_and_a_tube() {
    // Cone (A grows like x) for 5 bands, tube (constant) up to band 19, then the body:
    // A jumps by 6x at band 20.
    let a: Vec<f64> = (0..40)
        .map(|j| {
            if j < 5 {
                (j as f64 + 0.5) / 5.5
            } else if j < 20 {
                1.0
            } else {
                6.0
            }
        })
        .collect();
    let (j, s) = separating_band(&a).unwrap();
    assert_eq!(j, 19);
    assert!(s > 10.0);
    let mut sm = a.clone();
    gaussian_smooth(&mut sm, 10);
    let (j, _) = separating_band(&sm).unwrap();
    // Smoothing (sigma ~ 2.2 bands) may move the steepest point by a few bands only.
    assert!((16..=22).contains(&j), "j = {j}");
    // A pure cone never separates: slope 1.
    let cone: Vec<f64> = (0..40).map(|j| j as f64 + 0.5).collect();
    assert!(separating_band(&cone).unwrap().1 < 1.01);
}

/// A sphere with `n` long fingers (the example's shape at a test resolution).
fn fingered(levels: u32, n: u32) -> (Mesh, Vec<Vector3<f64>>) {
    let mut mesh = shapes::icosphere(1.0, levels);
    let dirs = shapes::spiral_directions(n);
    for p in &mut mesh.positions {
        let d = p.coords.normalize();
        let r: f64 = 1.0
            + dirs
                .iter()
                .map(|w| 0.8 * (-(1.0 - d.dot(w)) / 0.015).exp())
                .sum::<f64>();
        *p = Point3::from(d * r);
    }
    (mesh, dirs)
}

#[test]
fn fingers_become_their_own_disc_charts() {
    let (mesh, dirs) = fingered(4, 4);
    let charts = segment(&mesh, &ChartConfig::default(), &NoProgress).unwrap();
    // Every finger tip (radius 1.8) lies in a chart that is a disc and that does not reach
    // the body far from that finger: the chart of the tip stays within the finger's cone.
    for w in &dirs {
        let tip = (0..mesh.positions.len())
            .max_by(|&a, &b| {
                mesh.positions[a]
                    .coords
                    .dot(w)
                    .total_cmp(&mesh.positions[b].coords.dot(w))
            })
            .unwrap() as u32;
        let f = (0..mesh.faces.len())
            .find(|&f| mesh.faces[f].contains(&tip))
            .unwrap();
        let c = charts.face_chart[f];
        let set: Vec<u32> = (0..mesh.faces.len() as u32)
            .filter(|&g| charts.face_chart[g as usize] == c)
            .collect();
        let (faces, global) = sub_mesh(&mesh.faces, &set);
        let t = Topology::from_faces(&faces, global.len()).unwrap();
        assert_eq!(t.components()[0].euler_characteristic, 1);
        // All of the chart within 60 degrees of the finger axis: it did not swallow the body.
        for &v in &global {
            let d = mesh.positions[v as usize].coords.normalize();
            assert!(d.dot(w) > 0.5, "tip chart of {w:?} reaches {d:?}");
        }
    }
}

#[test]
fn each_finger_is_found_from_its_agd_maximum() {
    use fresco_param::agd::average_geodesic_distance;
    use fresco_param::features::{FeatureParams, find_features};
    use fresco_param::geodesic::{Method, SurfaceGraph};
    let (m, dirs) = fingered(4, 4);
    let g = SurfaceGraph::new(&m.positions, &m.faces);
    let agd = average_geodesic_distance(&g, 0, 32, Method::FastMarching);
    let tips = fresco_param::reeb::local_maxima(&g, &agd.raw, 3);
    // The four highest maxima are the finger tips.
    for &t in &tips[..4] {
        let p = m.positions[t as usize].coords;
        assert!(p.norm() > 1.7 && dirs.iter().any(|w| p.normalize().dot(w) > 0.99));
    }
    let radius = agd.raw.iter().copied().fold(f64::INFINITY, f64::min);
    let d = ChartConfig::default();
    let params = FeatureParams {
        isovalue: d.isovalue,
        bands: d.bands,
        gaussian_steps: d.gaussian_steps,
        sharpness: d.sharpness,
        min_area_fraction: d.min_feature_area,
        method: Method::FastMarching,
    };
    let features = find_features(
        &m.positions,
        &m.faces,
        &tips,
        &Default::default(),
        radius,
        &params,
    );
    assert_eq!(features.len(), 4);
    for f in &features {
        let t = m.positions[f.tip as usize].coords.normalize();
        // The finger's angular radius is about 0.17 rad; the cut lies a little beyond its
        // base on the body, well inside 45 degrees.
        for &face in &f.faces {
            for v in m.faces[face as usize] {
                assert!(m.positions[v as usize].coords.normalize().dot(&t) > 0.7);
            }
        }
        assert!(f.slope > d.sharpness);
    }
}
