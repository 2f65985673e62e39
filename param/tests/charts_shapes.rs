//! Charting of the shared test shapes: every face in exactly one chart, every chart a
//! topological disc, the surface cut along the seams has genus 0, and the number of handles
//! cut equals the genus the shapes are built with.

use fresco_core::nalgebra::Point3;
use fresco_core::{Mesh, NoProgress, Topology};
use fresco_datasets::shapes::{self, Shape};
use fresco_param::ParamError;
use fresco_param::charts::{ChartConfig, Charts, segment};
use fresco_param::genus::{cut_surface, genus_and_components};

/// Checks the contract of [`Charts`] against `mesh` with core's Topology only.
fn check(mesh: &Mesh, charts: &Charts) {
    assert_eq!(charts.face_chart.len(), mesh.faces.len());
    let mut sets = vec![Vec::new(); charts.count as usize];
    for (f, &c) in charts.face_chart.iter().enumerate() {
        assert!(
            c < charts.count,
            "face {f} has chart {c} of {}",
            charts.count
        );
        sets[c as usize].push(f);
    }
    for (c, set) in sets.iter().enumerate() {
        assert!(!set.is_empty(), "chart {c} is empty");
        // The chart as its own mesh, vertices shared within it.
        let faces: Vec<[u32; 3]> = set.iter().map(|&f| mesh.faces[f]).collect();
        let sub = Mesh::from_triangles(mesh.positions.clone(), faces);
        let topo = Topology::build(&sub).unwrap();
        let comps = topo.components();
        assert_eq!(comps.len(), 1, "chart {c} has {} components", comps.len());
        assert!(comps[0].manifold, "chart {c} is not manifold");
        assert_eq!(comps[0].boundary_loops, 1, "chart {c}: {:?}", comps[0]);
        assert_eq!(
            comps[0].euler_characteristic, 1,
            "chart {c}: {:?}",
            comps[0]
        );
    }
    // Seams: exactly the edges between different charts.
    let topo = Topology::build(mesh).unwrap();
    for (e, edge) in topo.edges().iter().enumerate() {
        let fs: Vec<u32> = topo.edge_faces(e as u32).collect();
        let seam =
            fs.len() == 2 && charts.face_chart[fs[0] as usize] != charts.face_chart[fs[1] as usize];
        assert_eq!(
            seam,
            charts.cut_edges.binary_search(edge).is_ok(),
            "edge {edge:?}"
        );
    }
    // The whole surface cut along the seams: one genus-0 piece per chart.
    let cut = cut_surface(
        &mesh.faces,
        mesh.positions.len(),
        &charts.cut_edges.iter().copied().collect(),
    )
    .unwrap();
    let (genus, components) = genus_and_components(&cut.faces, cut.original.len()).unwrap();
    assert_eq!(genus, 0);
    assert_eq!(components, charts.count as usize);
}

fn run(shape: Shape) -> (Mesh, Charts) {
    let mesh = shape.mesh(0);
    let charts = segment(&mesh, &ChartConfig::default(), &NoProgress).unwrap();
    check(&mesh, &charts);
    (mesh, charts)
}

#[test]
fn sphere_charts_are_discs() {
    let (_, c) = run(Shape::Sphere);
    assert_eq!((c.genus_before, c.handles_cut), (0, 0));
    // A closed sphere cannot be one disc.
    assert!(c.count >= 2);
}

#[test]
fn torus_one_handle_cut() {
    let (_, c) = run(Shape::Torus);
    assert_eq!((c.genus_before, c.handles_cut), (1, 1));
}

#[test]
fn double_torus_two_handles_cut() {
    let (_, c) = run(Shape::DoubleTorus);
    assert_eq!((c.genus_before, c.handles_cut), (2, 2));
}

#[test]
fn temple_every_component_charted() {
    let (mesh, c) = run(Shape::Temple);
    let comps = Topology::build(&mesh).unwrap().components().len() as u32;
    assert_eq!(c.genus_before, 0);
    // Each closed component needs at least two discs; the coarse columns (64 faces) must
    // not fall apart into single triangles either: a few discs per component at most.
    assert!(c.count >= 2 * comps);
    assert!(
        c.count <= 6 * comps,
        "{} charts for {comps} components",
        c.count
    );
}

#[test]
fn blob_charts_are_discs() {
    run(Shape::Blob);
}

#[test]
fn open_disc_stays_one_chart() {
    // A hemisphere is already a disc: nothing to cut.
    let mut mesh = shapes::icosphere(1.0, 2);
    let keep: Vec<bool> = (0..mesh.faces.len())
        .map(|f| mesh.triangle(f).iter().all(|p| p.z > -1e-9))
        .collect();
    mesh.retain_faces(&keep);
    mesh.remove_unreferenced_vertices();
    let c = segment(&mesh, &ChartConfig::default(), &NoProgress).unwrap();
    check(&mesh, &c);
    assert_eq!(c.count, 1);
    assert!(c.cut_edges.is_empty());
}

#[test]
fn bad_input_is_named() {
    // Three triangles on one edge (0, 1).
    let p = vec![
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(1.0, 0.0, 0.0),
        Point3::new(0.0, 1.0, 0.0),
        Point3::new(0.0, -1.0, 0.0),
        Point3::new(0.0, 0.0, 1.0),
    ];
    let mesh = Mesh::from_triangles(p, vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]]);
    match segment(&mesh, &ChartConfig::default(), &NoProgress) {
        Err(ParamError::NonManifold { edges, .. }) => assert_eq!(edges, vec![[0, 1]]),
        other => panic!("expected a non-manifold error, got {other:?}"),
    }
    let empty = Mesh::default();
    assert!(matches!(
        segment(&empty, &ChartConfig::default(), &NoProgress),
        Err(ParamError::EmptyMesh)
    ));
    let mut nan = shapes::icosphere(1.0, 1);
    nan.positions[3].x = f64::NAN;
    assert!(matches!(
        segment(&nan, &ChartConfig::default(), &NoProgress),
        Err(ParamError::NonFinitePosition { vertex: 3 })
    ));
}
