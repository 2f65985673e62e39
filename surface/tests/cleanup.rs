//! Clean-up: each defect is planted in a known clean mesh and must be repaired back to a
//! closed manifold with the original topology.

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Mesh, Topology};
use fresco_datasets::shapes::{icosphere, torus};
use fresco_surface::cleanup::{CleanupConfig, cleanup};

fn closed_manifold_genus(mesh: &Mesh) -> Vec<Option<u32>> {
    let t = Topology::build(mesh).unwrap();
    assert!(t.is_closed_manifold(), "not a closed manifold");
    t.components().iter().map(|c| c.genus).collect()
}

fn shifted(mut m: Mesh, by: Vector3<f64>) -> Mesh {
    for p in &mut m.positions {
        *p += by;
    }
    m
}

#[test]
fn unwelded_soup_is_welded_back() {
    let sphere = icosphere(1.0, 3);
    let mut soup = Mesh::default();
    for t in &sphere.faces {
        let base = soup.positions.len() as u32;
        soup.positions
            .extend(t.iter().map(|&v| sphere.positions[v as usize]));
        soup.faces.push([base, base + 1, base + 2]);
    }
    let report = cleanup(&mut soup, &CleanupConfig::default()).unwrap();
    assert_eq!(soup.positions.len(), sphere.positions.len());
    assert_eq!(soup.faces.len(), sphere.faces.len());
    assert_eq!(
        report.welded_vertices,
        3 * sphere.faces.len() - sphere.positions.len()
    );
    assert_eq!(closed_manifold_genus(&soup), vec![Some(0)]);
}

#[test]
fn degenerate_duplicate_and_tiny_parts_are_removed() {
    let clean = torus(0.7, 0.3, 32, 16);
    let mut mesh = clean.clone();
    mesh.faces.push([0, 0, 5]); // repeats a vertex
    mesh.faces
        .push([mesh.faces[3][1], mesh.faces[3][2], mesh.faces[3][0]]); // duplicate, rotated
    // A far-away lone triangle: a component of 1 face.
    let base = mesh.positions.len() as u32;
    mesh.positions.extend([
        Point3::new(5.0, 0.0, 0.0),
        Point3::new(5.1, 0.0, 0.0),
        Point3::new(5.0, 0.1, 0.0),
    ]);
    mesh.faces.push([base, base + 1, base + 2]);
    mesh.positions.push(Point3::new(9.0, 9.0, 9.0)); // unreferenced
    let report = cleanup(&mut mesh, &CleanupConfig::default()).unwrap();
    assert_eq!(report.degenerate_faces, 1);
    assert_eq!(report.duplicate_faces, 1);
    assert_eq!(report.small_components_removed, 1);
    assert_eq!(report.unreferenced_vertices, 4);
    assert_eq!(mesh.faces.len(), clean.faces.len());
    assert_eq!(mesh.positions, clean.positions);
    assert_eq!(closed_manifold_genus(&mesh), vec![Some(1)]);
    assert!(report.manifold);
}

#[test]
fn fin_on_an_edge_is_removed() {
    // A third face on an edge of a closed sphere makes the edge non-manifold; the two
    // consistently oriented sphere faces are kept (the fin is the smallest face there).
    let clean = icosphere(1.0, 3);
    let mut mesh = clean.clone();
    let [a, b, _] = mesh.faces[0];
    let apex = mesh.positions.len() as u32;
    let mid = nalgebra_center(&mesh.positions[a as usize], &mesh.positions[b as usize]);
    mesh.positions.push(Point3::from(mid.coords * 1.05));
    mesh.faces.push([a, b, apex]);
    let report = cleanup(
        &mut mesh,
        &CleanupConfig {
            min_component_faces: 0,
            min_component_area: 0.0,
            ..CleanupConfig::default()
        },
    )
    .unwrap();
    assert_eq!(report.non_manifold_edges, 1);
    assert_eq!(report.non_manifold_edge_faces_removed, 1);
    assert_eq!(mesh.faces, clean.faces);
    assert_eq!(closed_manifold_genus(&mesh), vec![Some(0)]);
}

fn nalgebra_center(a: &Point3<f64>, b: &Point3<f64>) -> Point3<f64> {
    Point3::from((a.coords + b.coords) * 0.5)
}

#[test]
fn spheres_touching_at_a_vertex_are_split() {
    // Two spheres sharing one vertex: a non-manifold vertex joining two closed fans.
    let a = icosphere(1.0, 2);
    let top = a
        .positions
        .iter()
        .enumerate()
        .max_by(|x, y| x.1.x.total_cmp(&y.1.x))
        .unwrap()
        .0 as u32;
    // The second sphere is the first mirrored through the plane x = x_top, with its top
    // vertex replaced by the first sphere's (orientation restored by reversing faces).
    let xt = a.positions[top as usize].x;
    let mut b = a.clone();
    for p in &mut b.positions {
        p.x = 2.0 * xt - p.x;
    }
    for f in &mut b.faces {
        f.swap(1, 2);
    }
    let n = a.positions.len() as u32;
    let mut mesh = a.clone();
    mesh.positions.extend(b.positions.iter().cloned());
    mesh.faces.extend(
        b.faces
            .iter()
            .map(|f| f.map(|v| if v == top { top } else { v + n })),
    );
    mesh.remove_unreferenced_vertices();
    let before = Topology::build(&mesh).unwrap();
    assert_eq!(before.non_manifold_vertices().len(), 1);
    let faces = mesh.faces.len();
    let report = cleanup(&mut mesh, &CleanupConfig::default()).unwrap();
    assert_eq!(report.non_manifold_vertices_split, 1);
    assert_eq!(mesh.faces.len(), faces, "splitting keeps every face");
    assert_eq!(closed_manifold_genus(&mesh), vec![Some(0), Some(0)]);
}

#[test]
fn keep_largest_component() {
    let mut mesh = icosphere(1.0, 3);
    let small = shifted(icosphere(0.5, 3), Vector3::new(5.0, 0.0, 0.0));
    mesh.append(&small);
    let report = cleanup(
        &mut mesh,
        &CleanupConfig {
            keep_largest_component: true,
            ..CleanupConfig::default()
        },
    )
    .unwrap();
    assert_eq!(report.small_components_removed, 1);
    assert_eq!(mesh.faces.len(), icosphere(1.0, 3).faces.len());
    assert!(mesh.positions.iter().all(|p| p.x < 2.0));
}
