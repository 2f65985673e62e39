//! `mesh_from_points` end to end on a small cloud, and its bad-input handling.

use fresco_core::nalgebra::{Point3, Vector3};
use fresco_core::{NoProgress, Topology};
use fresco_datasets::point_clouds::{SampleConfig, sample_points};
use fresco_datasets::shapes::torus;
use fresco_surface::metrics::{DistanceConfig, mesh_distance};
use fresco_surface::pipeline::{MeshConfig, MeshFromPointsError, mesh_from_points};

/// Depth 7 keeps the test fast; the torus tube (0.3) spans ~20 cells of the 2.2-wide cube.
/// 30k samples on the torus give a density of log4(samples per cell area / 1.5) ~ 6.8
/// everywhere: an absolute trim of 7 (PoissonRecon's usual value for ~200k points at depth
/// 9) would remove most of the surface; the default trim, one below the median density,
/// keeps all of a uniformly sampled closed surface.
fn config() -> MeshConfig {
    let mut cfg = MeshConfig {
        target_faces: Some(10_000),
        ..MeshConfig::default()
    };
    cfg.poisson.depth = 7;
    cfg
}

#[test]
fn torus_without_normals_with_nans() {
    let gt = torus(0.7, 0.3, 128, 64);
    let cloud = sample_points(
        &gt,
        &SampleConfig {
            count: 30_000,
            ..SampleConfig::default()
        },
    )
    .unwrap();
    let mut points = cloud.points.clone();
    points[7] = Point3::new(f64::NAN, 0.0, 0.0);
    points[99] = Point3::new(0.0, f64::INFINITY, 0.0);
    let (mesh, report) = mesh_from_points(&points, None, &config(), &NoProgress).unwrap();
    assert_eq!(report.non_finite_points, 2);
    assert!(report.normals_estimated);
    assert!(
        report.faces <= 10_000 && report.faces >= 9_990,
        "{report:?}"
    );
    let topo = Topology::build(&mesh).unwrap();
    assert!(topo.is_closed_manifold(), "{report:?}");
    assert_eq!(
        topo.components()
            .iter()
            .map(|c| c.genus)
            .collect::<Vec<_>>(),
        vec![Some(1)]
    );
    // Depth 7: cells of 2.2 / 128 = 0.017; the surface is within a fraction of a cell.
    let d = mesh_distance(&mesh, &gt, &DistanceConfig::default()).unwrap();
    assert!(d.chamfer_relative < 0.001, "{d:?}");
    // Outward: the mesh encloses positive volume (divergence theorem).
    assert!(mesh.signed_volume() > 0.0);
}

#[test]
fn bad_input_is_reported() {
    let few: Vec<Point3<f64>> = (0..9).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
    let err = mesh_from_points(&few, None, &config(), &NoProgress).unwrap_err();
    assert!(
        matches!(err, MeshFromPointsError::TooFewPoints { usable: 9, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("at least 10"));

    let mut nan = few.clone();
    nan.extend([Point3::new(f64::NAN, 1.0, 1.0); 5]);
    let err = mesh_from_points(&nan, None, &config(), &NoProgress).unwrap_err();
    assert!(
        matches!(
            err,
            MeshFromPointsError::TooFewPoints {
                usable: 9,
                non_finite: 5,
                ..
            }
        ),
        "{err}"
    );

    let pts: Vec<Point3<f64>> = (0..50)
        .map(|i| Point3::new((i % 7) as f64, (i / 7) as f64, 0.0))
        .collect();
    let cfg = MeshConfig {
        estimate_normals: false,
        ..config()
    };
    let err = mesh_from_points(&pts, None, &cfg, &NoProgress).unwrap_err();
    assert!(matches!(err, MeshFromPointsError::MissingNormals), "{err}");

    let normals = vec![Vector3::z(); 49];
    let err = mesh_from_points(&pts, Some(&normals), &config(), &NoProgress).unwrap_err();
    assert!(
        matches!(err, MeshFromPointsError::LengthMismatch { .. }),
        "{err}"
    );
}

#[test]
fn the_mesh_has_the_same_bits_whatever_the_thread_count() {
    let gt = torus(0.7, 0.3, 96, 48);
    let cloud = sample_points(
        &gt,
        &SampleConfig {
            count: 20_000,
            ..SampleConfig::default()
        },
    )
    .unwrap();
    let mut cfg = config();
    cfg.poisson.depth = 6;
    cfg.target_faces = Some(4_000);
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                mesh_from_points(&cloud.points, None, &cfg, &NoProgress)
                    .unwrap()
                    .0
            })
    };
    let one = run(1);
    for threads in [2, 3] {
        let other = run(threads);
        assert_eq!(one.faces, other.faces, "{threads} threads: other faces");
        let same_bits = one.positions.iter().zip(&other.positions).all(|(a, b)| {
            a.coords
                .iter()
                .zip(b.coords.iter())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        });
        assert!(same_bits, "{threads} threads: other vertex positions");
    }
}
