//! Unwrapping the shared test shapes and discs: zero flipped triangles, zero overlaps, every
//! face in exactly one chart, bounded stretch, texture not mirrored; bad input repaired with
//! warnings naming the elements or refused with an error naming them.

use fresco_core::nalgebra::{Point2, Point3};
use fresco_core::{Mesh, NoProgress};
use fresco_datasets::Shape;
use fresco_datasets::shapes::grid_patch;
use fresco_param::metrics::signed_area;
use fresco_param::{UnwrapConfig, measure, unwrap};

fn config() -> UnwrapConfig {
    UnwrapConfig {
        atlas_size: 1024,
        gutter: 2,
        ..UnwrapConfig::default()
    }
}

/// Unwraps `mesh` and checks every property the issue asks for; returns the metrics.
fn check(mut mesh: Mesh, name: &str) -> fresco_param::UvMetrics {
    let cfg = config();
    let report = unwrap(&mut mesh, &cfg, &NoProgress).unwrap();
    let m = measure(&mesh).unwrap();
    eprintln!("{name}: {report:?}\n{m:?}");
    assert_eq!(m.flipped, 0, "{name}: flipped");
    assert_eq!(m.degenerate_uv, 0, "{name}: degenerate UV triangles");
    assert_eq!(m.overlapping_pairs, 0, "{name}: overlaps");
    // Every face has a chart, and a chart id names one UV-connected piece or more (a chart
    // is never spread over two ids): the chart count by UV connectivity equals the ids'.
    let groups = mesh.face_groups.as_ref().unwrap();
    assert_eq!(groups.len(), mesh.faces.len());
    let ids: std::collections::BTreeSet<u32> = groups.iter().copied().collect();
    assert_eq!(ids.len(), report.charts, "{name}");
    assert_eq!(
        m.charts, report.charts,
        "{name}: every chart one UV-connected piece"
    );
    // Every chart's normalised stretch is at most max_stretch and all charts share one
    // density, so the mesh's L2 stretch is at most max_stretch too (f32 UVs: +1e-3).
    assert!(
        m.l2_stretch.is_finite() && m.l2_stretch <= cfg.max_stretch + 1e-3,
        "{name}: {}",
        m.l2_stretch
    );
    assert!(m.linf_stretch.is_finite(), "{name}");
    // UVs inside the atlas, at least the gutter from the border.
    let uvs = mesh.corner_uvs.as_ref().unwrap();
    let margin = cfg.gutter as f32 / cfg.atlas_size as f32 - 1e-6;
    for c in uvs.iter().flatten() {
        assert!(
            c[0] >= margin && c[1] >= margin && c[0] <= 1.0 - margin && c[1] <= 1.0 - margin,
            "{name}: {c:?}"
        );
    }
    // Not mirrored: counter-clockwise faces seen from outside are clockwise in (u, v-down).
    for (f, c) in uvs.iter().enumerate() {
        if mesh.face_area(f) > 1e-14 {
            let t = c.map(|x| Point2::new(x[0] as f64, x[1] as f64));
            assert!(signed_area(t) < 0.0, "{name}: face {f} mirrored");
        }
    }
    // Genus reduced to 0 per chart: every chart is a topological disc (one edge-connected
    // piece, one boundary loop, Euler characteristic 1).
    let mut by_chart: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
    for (f, &g) in groups.iter().enumerate() {
        by_chart.entry(g).or_default().push(f as u32);
    }
    for (g, faces) in &by_chart {
        let c = fresco_param::chart_mesh::ChartMesh::extract(&mesh, faces);
        assert!(
            c.disc_boundary().is_ok(),
            "{name}: chart {g} is not a disc: {:?}",
            c.disc_boundary()
        );
    }
    assert!(m.utilisation > 0.3, "{name}: utilisation {}", m.utilisation);
    m
}

#[test]
fn sphere() {
    check(Shape::Sphere.mesh(0), "sphere");
}

#[test]
fn torus() {
    check(Shape::Torus.mesh(0), "torus");
}

#[test]
fn double_torus() {
    check(Shape::DoubleTorus.mesh(0), "double torus");
}

#[test]
fn temple() {
    check(Shape::Temple.mesh(0), "temple");
}

/// The Poisson mesh of templeSparseRing's sparse SfM points (datasets/poisson, made by
/// make_temple_sparse_poisson.sh: dense stereo does not exist yet): real, noisy, open, with
/// holes and handles.
#[test]
fn temple_sparse_poisson() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../datasets/poisson/temple_sparse_poisson.ply"
    );
    let mesh = fresco_core::ply::read_mesh(path).unwrap();
    assert!(mesh.faces.len() > 20_000);
    check(mesh, "temple sparse Poisson");
}

#[test]
fn blob() {
    check(Shape::Blob.mesh(0), "blob");
}

/// A displaced grid: an open disc that must stay one chart if its stretch allows.
#[test]
fn displaced_grid_disc() {
    let mesh = grid_patch(24, |x, y| {
        Point3::new(x, y, 0.08 * (6.0 * x).sin() * (5.0 * y).cos())
    });
    let m = check(mesh, "displaced grid");
    assert_eq!(m.charts, 1, "a gently displaced disc is one chart");
}

/// A hemisphere (an open disc of high curvature).
#[test]
fn hemisphere() {
    let mut mesh = fresco_datasets::shapes::icosphere(1.0, 3);
    let keep: Vec<bool> = (0..mesh.faces.len())
        .map(|f| mesh.triangle(f).iter().all(|p| p.z >= -1e-9))
        .collect();
    mesh.retain_faces(&keep);
    mesh.remove_unreferenced_vertices();
    check(mesh, "hemisphere");
}

/// Non-manifold edge, isolated vertex and zero-area face: repaired, with warnings naming them.
#[test]
fn bad_input_is_repaired_with_warnings() {
    let mut positions: Vec<Point3<f64>> = vec![
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(1.0, 0.0, 0.0),
        Point3::new(0.5, 1.0, 0.0),
        Point3::new(0.5, -1.0, 0.0),
        Point3::new(0.5, 0.0, 1.0),
        Point3::new(9.0, 9.0, 9.0), // 5: isolated
        Point3::new(2.0, 0.0, 0.0), // 6: collinear with 0 and 1
    ];
    // Three faces on edge 0-1 (non-manifold), and a zero-area face (0, 1, 6).
    let faces = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 6, 2], [0, 6, 1]];
    positions.truncate(7);
    let mesh = Mesh::from_triangles(positions, faces);
    let mut m = mesh.clone();
    let report = unwrap(&mut m, &config(), &NoProgress).unwrap();
    let all = report.warnings.join("\n");
    assert!(
        all.contains("non-manifold edge") && all.contains("[0, 1]"),
        "{all}"
    );
    assert!(
        all.contains("isolated vertex") && all.contains('5'),
        "{all}"
    );
    assert!(all.contains("zero-area face") && all.contains('4'), "{all}");
    let metrics = measure(&m).unwrap();
    assert_eq!(metrics.flipped, 0);
    assert_eq!(metrics.overlapping_pairs, 0);
    // With Reeb-graph charts asked for: the segmentation refuses the non-manifold mesh, the
    // unwrap says so and starts from components instead, with the same repairs.
    let mut m = mesh.clone();
    let cfg = UnwrapConfig {
        reeb_charts: true,
        ..config()
    };
    let report = unwrap(&mut m, &cfg, &NoProgress).unwrap();
    let all = report.warnings.join("\n");
    assert!(
        all.contains("non-manifold mesh: charts start from connected components"),
        "{all}"
    );
    assert!(
        all.contains("isolated vertex") && all.contains("zero-area face"),
        "{all}"
    );
    let metrics = measure(&m).unwrap();
    assert_eq!((metrics.flipped, metrics.overlapping_pairs), (0, 0));
    assert_eq!(m.face_groups.as_ref().unwrap().len(), mesh.faces.len());
}

/// A face that repeats a vertex cannot be a triangle: a clear error naming it.
#[test]
fn repeated_vertex_is_an_error_naming_the_face() {
    let mut mesh = Mesh::from_triangles(
        vec![
            Point3::origin(),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ],
        vec![[0, 1, 2], [0, 2, 2]],
    );
    let e = unwrap(&mut mesh, &config(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("face 1"), "{e}");
    let mut empty = Mesh::default();
    assert!(unwrap(&mut empty, &config(), &NoProgress).is_err());
}
