//! Quadric decimation: face budget met, topology kept (closed manifold, genus), boundaries
//! kept, no flipped faces, and a geometric error measured against the input.

use std::time::Instant;

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{Mesh, Topology};
use fresco_datasets::shapes::{blob, grid_patch, icosphere, torus};
use fresco_surface::decimate::{DecimateConfig, decimate};
use fresco_surface::metrics::{DistanceConfig, mesh_distance};

fn genera(mesh: &Mesh) -> Vec<Option<u32>> {
    let t = Topology::build(mesh).unwrap();
    assert!(t.non_manifold_edges().is_empty() && t.non_manifold_vertices().is_empty());
    t.components().iter().map(|c| c.genus).collect()
}

fn run(mesh: &Mesh, target: usize) -> Mesh {
    let (out, report) = decimate(
        mesh,
        &DecimateConfig {
            target_faces: target,
            ..DecimateConfig::default()
        },
    )
    .unwrap();
    // Each collapse of an interior edge removes 2 faces, so the count lands on the target or
    // one below it.
    assert!(
        report.faces_after <= target && report.faces_after + 2 >= target,
        "{report:?}"
    );
    assert_eq!(out.faces.len(), report.faces_after);
    out
}

#[test]
fn sphere_stays_a_sphere() {
    let mesh = icosphere(1.0, 5); // 20480 faces
    let out = run(&mesh, 2000);
    assert_eq!(genera(&out), vec![Some(0)]);
    assert!(Topology::build(&out).unwrap().is_closed_manifold());
    // No face flipped: every normal points away from the centre.
    for f in 0..out.faces.len() {
        let c = out
            .triangle(f)
            .iter()
            .fold(Vector3::zeros(), |s, p| s + p.coords)
            / 3.0;
        assert!(out.face_normal(f).dot(&c.normalize()) > 0.5);
    }
    // 2000 faces on the unit sphere: edge ~0.1, chord sag ~0.1^2 / 8 ~ 1.3e-3. The Hausdorff
    // error must be of that order (3x for uneven triangles), far below the diagonal (3.46).
    let d = mesh_distance(
        &out,
        &mesh,
        &DistanceConfig {
            samples: 100_000,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(d.hausdorff < 5e-3, "{d:?}");
    assert!(d.chamfer < 1.5e-3, "{d:?}");
}

#[test]
fn torus_and_blob_keep_their_genus() {
    let t = run(&torus(0.7, 0.3, 96, 48), 1500);
    assert_eq!(genera(&t), vec![Some(1)]);
    let b = blob(4, 7);
    let out = run(&b, 1500);
    assert_eq!(genera(&out), vec![Some(0)]);
    let d = mesh_distance(&out, &b, &DistanceConfig::default()).unwrap();
    // A 1500-face blob of ~2.4 units: features are ~0.3 wide; 0.5 % of the diagonal.
    assert!(d.hausdorff_relative < 0.005, "{d:?}");
}

#[test]
fn boundary_of_an_open_mesh_is_kept() {
    // A bumpy square patch: z = 0.1 sin(3x) cos(2y) over [-1,1]^2, 60x60 quads.
    let mesh = grid_patch(60, |u, v| {
        let (x, y) = (2.0 * u - 1.0, 2.0 * v - 1.0);
        Point3::new(x, y, 0.1 * (3.0 * x).sin() * (2.0 * y).cos())
    });
    let out = run(&mesh, 800);
    let topo = Topology::build(&out).unwrap();
    assert_eq!(topo.boundary_loops().len(), 1);
    assert_eq!(genera(&out), vec![Some(0)]);
    // Boundary vertices stay on the square's outline (the constraint planes pin them to it
    // up to the trade-off against the face quadrics, 1000:1).
    let on_outline =
        |p: &Point3<f64>| (p.x.abs() - 1.0).abs() < 1e-3 || (p.y.abs() - 1.0).abs() < 1e-3;
    for l in topo.boundary_loops() {
        for &v in l {
            assert!(
                on_outline(&out.positions[v as usize]),
                "{}",
                out.positions[v as usize]
            );
        }
    }
    // The four corners survive, within the same trade-off.
    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        assert!(
            out.positions
                .iter()
                .any(|p| (p.x - x).abs() < 1e-3 && (p.y - y).abs() < 1e-3),
            "corner ({x}, {y}) lost"
        );
    }
}

#[test]
fn flat_grid_decimates_without_error() {
    let side = 40.0;
    let mesh = grid_patch(40, |u, v| Point3::new(side * u, side * v, 0.0));
    let (out, report) = decimate(
        &mesh,
        &DecimateConfig {
            target_faces: 50,
            ..DecimateConfig::default()
        },
    )
    .unwrap();
    assert!(report.faces_after <= 50);
    assert!(report.max_cost < 1e-9, "a plane costs nothing: {report:?}");
    assert!(out.positions.iter().all(|p| p.z.abs() < 1e-12));
    assert!((out.surface_area() - side * side).abs() < 1e-6);
}

/// The size: 1.31M faces to 100k, topology kept. The time budget (under 5 s)
/// is measured in release by bench/mesh.sh through the `decimate_bench` example (same input,
/// with the Hausdorff error); run this one with
/// `cargo test --release -p fresco-surface --test decimate -- --ignored`.
#[test]
#[ignore]
fn million_faces_to_100k_timing() {
    let mesh = blob(8, 7); // 20 * 4^8 = 1.31M faces
    let t = Instant::now();
    let out = run(&mesh, 100_000);
    let secs = t.elapsed().as_secs_f64();
    // 1M samples a side, as decimate_bench measures it: the distance to a mesh is exact
    // against the triangles of the nearest samples, so sparse samples on the decimated
    // mesh's large triangles overstate the Hausdorff distance (200k: 0.028% of the diagonal).
    let d = mesh_distance(
        &out,
        &mesh,
        &DistanceConfig {
            samples: 1_000_000,
            ..DistanceConfig::default()
        },
    )
    .unwrap();
    println!(
        "decimate {} -> {} faces: {secs:.2} s, Hausdorff {:.3e} ({:.4} % of diagonal)",
        mesh.faces.len(),
        out.faces.len(),
        d.hausdorff,
        100.0 * d.hausdorff_relative
    );
    assert_eq!(genera(&out), vec![Some(0)]);
}
