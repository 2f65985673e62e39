//! Density trimming on meshes with an analytic density field, where the trimmed area and
//! the cut line are known exactly.

use fresco_core::nalgebra::Point3;
use fresco_core::{Mesh, Topology};
use fresco_surface::trim::{TrimConfig, TrimError, trim_by_density};

/// The unit square [0,1]^2 at z = 0 as an n x n grid of quads split in two.
fn grid(n: u32) -> Mesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            positions.push(Point3::new(i as f64 / n as f64, j as f64 / n as f64, 0.0));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut faces = Vec::new();
    for j in 0..n {
        for i in 0..n {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    Mesh::from_triangles(positions, faces)
}

#[test]
fn linear_density_is_cut_exactly_at_the_threshold() {
    let mesh = grid(20);
    // density = 10 - 6 x: below 7 where x > 0.5 + 1/3 / ... i.e. x > 0.5. The iso-line
    // x = 0.5 lies on grid lines; shift it off them with 7.3 (x = 0.45) so faces are cut.
    let density: Vec<f32> = mesh
        .positions
        .iter()
        .map(|p| (10.0 - 6.0 * p.x) as f32)
        .collect();
    let out = trim_by_density(
        &mesh,
        &density,
        &TrimConfig {
            trim: 7.3,
            ..TrimConfig::default()
        },
    )
    .unwrap();
    // Linear interpolation of a linear field is exact: the kept part is x <= 0.45.
    assert!(
        (out.mesh.surface_area() - 0.45).abs() < 1e-6,
        "{}",
        out.mesh.surface_area()
    );
    assert!(out.report.faces_clipped > 0);
    assert!((out.report.area_removed - 0.55).abs() < 1e-6);
    assert!(out.mesh.positions.iter().all(|p| p.x <= 0.45 + 1e-6));
    assert_eq!(out.density.len(), out.mesh.positions.len());
    for (p, d) in out.mesh.positions.iter().zip(&out.density) {
        assert!((*d as f64 - (10.0 - 6.0 * p.x)).abs() < 1e-4);
    }
    // The cut is crack-free: one connected piece with a single boundary loop.
    let topo = Topology::build(&out.mesh).unwrap();
    assert_eq!(topo.components().len(), 1);
    assert_eq!(topo.boundary_loops().len(), 1);
    assert!(topo.non_manifold_edges().is_empty());
}

/// The relative threshold: on the 21 x 21 grid with density 10 - 6 x, the median vertex
/// density is that of the middle column x = 0.5, i.e. 7; 0.7 below it is 6.3, where
/// x = 0.6167. Shifting every density (4x more points: +1 in log4 units) must cut at the
/// same place, which an absolute threshold would not.
#[test]
fn threshold_below_the_median_follows_the_sampling() {
    let mesh = grid(20);
    for shift in [0.0f32, 1.0, -2.5] {
        let density: Vec<f32> = mesh
            .positions
            .iter()
            .map(|p| (10.0 - 6.0 * p.x) as f32 + shift)
            .collect();
        let out = trim_by_density(
            &mesh,
            &density,
            &TrimConfig {
                trim: 100.0, // ignored
                below_median: Some(0.7),
                ..TrimConfig::default()
            },
        )
        .unwrap();
        assert!((out.report.threshold - (6.3 + shift)).abs() < 1e-5);
        let kept = 3.7 / 6.0;
        assert!(
            (out.mesh.surface_area() - kept).abs() < 1e-5,
            "shift {shift}: {}",
            out.mesh.surface_area()
        );
    }
    assert_eq!(
        trim_by_density(
            &mesh,
            &vec![f32::NAN; mesh.positions.len()],
            &TrimConfig {
                below_median: Some(1.0),
                ..TrimConfig::default()
            }
        )
        .unwrap_err(),
        TrimError::NoDensity
    );
}

#[test]
fn small_gaps_are_kept_and_small_islands_removed() {
    let mesh = grid(100);
    // High density everywhere except a tiny gap at (0.5, 0.5) and a low band 0.2 < x < 0.25
    // that cuts off the strip x < 0.2 ... which is not small: keep it. A tiny isolated
    // high-density spot inside a large low region at x > 0.9 becomes an island.
    let density: Vec<f32> = mesh
        .positions
        .iter()
        .map(|p| {
            let gap = (p.x - 0.5).hypot(p.y - 0.5) < 0.015;
            let low_region = p.x > 0.8;
            let spot = (p.x - 0.9).hypot(p.y - 0.5) < 0.015;
            if (gap || low_region) && !spot {
                2.0
            } else {
                9.0
            }
        })
        .collect();
    let cfg = TrimConfig {
        trim: 7.0,
        below_median: None,
        hole_area: 0.002,
        island_area: 0.002,
    };
    let out = trim_by_density(&mesh, &density, &cfg).unwrap();
    assert_eq!(out.report.holes_kept, 1, "{:?}", out.report);
    assert_eq!(out.report.islands_removed, 1, "{:?}", out.report);
    // The gap stays filled: a point at its centre is still covered.
    assert!(
        out.mesh
            .positions
            .iter()
            .any(|p| (p.x - 0.5).abs() < 1e-9 && (p.y - 0.5).abs() < 1e-9)
    );
    // The density falls from 9 at x = 0.80 to 2 at x = 0.81: the iso-line 7 crosses at
    // x = 0.80 + 0.01 * 2 / 7. Nothing is left beyond it, and the kept area is the strip
    // up to it (the gap is filled, the spot's island is gone).
    let cut = 0.80 + 0.01 * 2.0 / 7.0;
    assert!(out.mesh.positions.iter().all(|p| p.x <= cut + 1e-6));
    let area = out.mesh.surface_area();
    assert!((area - cut).abs() < 1e-6, "area {area}");
}

#[test]
fn wrong_density_length_is_an_error() {
    let mesh = grid(2);
    assert_eq!(
        trim_by_density(&mesh, &[1.0; 3], &TrimConfig::default()),
        Err(TrimError::LengthMismatch {
            densities: 3,
            vertices: 9
        })
    );
}
