//! Topology of the shared test shapes (`fresco_datasets::shapes`) against their known genus
//! and component counts, plus geometric sanity of the mesh methods on them.

use fresco_core::{Mesh, Topology};
use fresco_datasets::shapes::{self, Shape};

fn topology(mesh: &Mesh) -> Topology {
    mesh.validate().expect("shape is a valid mesh");
    Topology::build(mesh).expect("shape has valid faces")
}

#[test]
fn closed_shapes_have_their_known_genus() {
    for shape in [Shape::Sphere, Shape::Torus, Shape::DoubleTorus, Shape::Blob] {
        for detail in 0..2 {
            let mesh = shape.mesh(detail);
            let t = topology(&mesh);
            assert_eq!(t.components().len(), 1, "{} detail {detail}", shape.name());
            let c = &t.components()[0];
            assert!(t.is_closed_manifold(), "{}: not closed", shape.name());
            assert!(c.orientable && c.consistently_oriented, "{}", shape.name());
            assert_eq!(c.boundary_loops, 0);
            // Closed orientable surface: chi = 2 - 2g.
            assert_eq!(
                c.euler_characteristic,
                2 - 2 * shape.genus() as i64,
                "{}",
                shape.name()
            );
            assert_eq!(c.genus, Some(shape.genus()), "{}", shape.name());
            // Every half-edge has a twin that points back.
            for h in 0..3 * mesh.faces.len() as u32 {
                let o = t.opposite(h).expect("closed: every half-edge has a twin");
                assert_eq!(t.opposite(o), Some(h));
            }
        }
    }
}

#[test]
fn temple_is_separate_closed_components() {
    for columns in [4, 8, 12] {
        let mesh = shapes::temple(columns);
        let t = topology(&mesh);
        // Two plinth steps, the columns, the roof slab and the pediment prism.
        assert_eq!(t.components().len(), columns as usize + 4);
        for c in t.components() {
            assert_eq!(c.genus, Some(0));
            assert_eq!(c.euler_characteristic, 2);
            assert!(c.manifold && c.consistently_oriented);
        }
        assert!(t.is_closed_manifold());
    }
}

#[test]
fn cutting_a_sphere_open_gives_boundary_loops() {
    // Removing the faces with z > 0.5 from the sphere leaves a disc with one boundary loop;
    // removing also z < -0.5 leaves an annulus: two loops, still genus 0.
    let mut mesh = Shape::Sphere.mesh(1);
    let centroid_z = |m: &Mesh, f: usize| m.triangle(f).iter().map(|p| p.z).sum::<f64>() / 3.0;
    let keep: Vec<bool> = (0..mesh.faces.len())
        .map(|f| centroid_z(&mesh, f) <= 0.5)
        .collect();
    mesh.retain_faces(&keep);
    mesh.remove_unreferenced_vertices();
    let t = topology(&mesh);
    assert_eq!(t.boundary_loops().len(), 1);
    assert_eq!(t.components()[0].genus, Some(0));
    assert_eq!(t.components()[0].euler_characteristic, 1);
    let keep: Vec<bool> = (0..mesh.faces.len())
        .map(|f| centroid_z(&mesh, f) >= -0.5)
        .collect();
    mesh.retain_faces(&keep);
    mesh.remove_unreferenced_vertices();
    let t = topology(&mesh);
    assert_eq!(t.boundary_loops().len(), 2);
    assert_eq!(t.components()[0].genus, Some(0));
    // Every boundary vertex sits on the cut: its z is near +-0.5 (within one edge length,
    // about 0.35 at this resolution).
    for lp in t.boundary_loops() {
        for &v in lp {
            assert!((mesh.positions[v as usize].z.abs() - 0.5).abs() < 0.35);
        }
    }
    // The torus cut along one meridian ring is a cylinder: genus 0, two loops.
    let torus = Shape::Torus.mesh(0);
    let mut cut = torus.clone();
    let keep: Vec<bool> = (0..cut.faces.len()).map(|f| f >= 2 * 12).collect();
    cut.retain_faces(&keep);
    cut.remove_unreferenced_vertices();
    let t = topology(&cut);
    assert_eq!(t.components()[0].genus, Some(0));
    assert_eq!(t.boundary_loops().len(), 2);
}

#[test]
fn sphere_area_and_normals_approach_the_smooth_sphere() {
    // A subdivided icosahedron inscribed in the unit sphere: area below 4 pi, converging as
    // the faces shrink (relative deficit about 1% at 1280 faces, 0.3% at 5120).
    let mut prev_err = f64::INFINITY;
    for detail in 0..3 {
        let mut mesh = Shape::Sphere.mesh(detail);
        let err = 4.0 * std::f64::consts::PI - mesh.surface_area();
        assert!(err > 0.0 && err < prev_err, "detail {detail}: {err}");
        prev_err = err;
        mesh.compute_vertex_normals();
        // Area-weighted normals of a sphere are radial within the tessellation's angle.
        for (p, n) in mesh.positions.iter().zip(mesh.normals.as_ref().unwrap()) {
            assert!(p.coords.normalize().dot(n) > 0.995);
        }
    }
    assert!(prev_err / (4.0 * std::f64::consts::PI) < 0.01);
}

#[test]
fn welding_a_split_mesh_restores_its_topology() {
    // Give each face its own three vertices (a "triangle soup"), then weld: the torus is back.
    let mesh = Shape::Torus.mesh(0);
    let mut soup = Mesh::default();
    for f in 0..mesh.faces.len() {
        let base = soup.positions.len() as u32;
        soup.positions.extend(mesh.triangle(f));
        soup.faces.push([base, base + 1, base + 2]);
    }
    assert_eq!(topology(&soup).components().len(), mesh.faces.len());
    let diag = mesh.bounding_box().unwrap().diagonal();
    let report = soup.weld_vertices(1e-9 * diag);
    assert_eq!(report.removed_faces, 0);
    assert_eq!(soup.positions.len(), mesh.positions.len());
    let t = topology(&soup);
    assert_eq!(t.components().len(), 1);
    assert_eq!(t.components()[0].genus, Some(1));
}
