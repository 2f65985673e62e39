//! Geodesics, AGD, Reeb graph and genus reduction checked against known geometry.

use fresco_core::nalgebra::Point3;
use fresco_datasets::shapes::{self, Shape};
use fresco_param::agd::average_geodesic_distance;
use fresco_param::genus::reduce_genus;
use fresco_param::geodesic::{Method, SurfaceGraph};
use fresco_param::reeb::ReebGraph;

#[test]
fn fast_marching_follows_great_circles() {
    let mesh = shapes::icosphere(1.0, 4); // 5120 faces, edges about 0.06
    let g = SurfaceGraph::new(&mesh.positions, &mesh.faces);
    let src = 0u32;
    let ps = mesh.positions[0].coords.normalize();
    let fm = g.distances(&[src], Method::FastMarching);
    let dj = g.distances(&[src], Method::Dijkstra);
    let (mut e_fm, mut e_dj) = (0.0f64, 0.0f64);
    for (v, p) in mesh.positions.iter().enumerate() {
        let truth = ps.dot(&p.coords.normalize()).clamp(-1.0, 1.0).acos();
        if truth < 0.3 {
            continue; // a few edges from the source a point source is poorly resolved
        }
        e_fm = e_fm.max((fm[v] - truth).abs() / truth);
        e_dj = e_dj.max((dj[v] - truth).abs() / truth);
    }
    // The polyhedron is inscribed in the sphere (chords shorter than arcs, by < 0.1% at
    // this edge length), so the residual is the scheme's own error: a few percent for
    // first-order fast marching, clearly less than edge paths.
    assert!(e_fm < 0.04, "fast marching error {e_fm}");
    assert!(e_fm < e_dj, "fm {e_fm} dijkstra {e_dj}");
}

/// An ellipsoid with semi-axes 3, 1, 1 (a stretched icosphere).
fn ellipsoid() -> fresco_core::Mesh {
    let mut m = shapes::icosphere(1.0, 3);
    for p in &mut m.positions {
        p.x *= 3.0;
    }
    m
}

#[test]
fn agd_is_largest_at_the_ends_of_an_ellipsoid() {
    let m = ellipsoid();
    let g = SurfaceGraph::new(&m.positions, &m.faces);
    let agd = average_geodesic_distance(&g, 0, 24, Method::FastMarching);
    let vmax = (0..m.positions.len())
        .max_by(|&a, &b| agd.raw[a].total_cmp(&agd.raw[b]))
        .unwrap();
    let vmin = (0..m.positions.len())
        .min_by(|&a, &b| agd.raw[a].total_cmp(&agd.raw[b]))
        .unwrap();
    // Farthest from everything: the tips at x = +-3; the centre is the waist x = 0.
    assert!(
        m.positions[vmax].x.abs() > 2.7,
        "max at {:?}",
        m.positions[vmax]
    );
    assert!(
        m.positions[vmin].x.abs() < 0.5,
        "min at {:?}",
        m.positions[vmin]
    );
    assert!((agd.normalised[vmin] - 1.0).abs() < 1e-12);
    // Voronoi weights cover the surface.
    let area: f64 = m.face_areas().iter().sum();
    assert!((agd.weights.iter().sum::<f64>() - area).abs() < 1e-9 * area);
    // Sphere: AGD nearly constant (symmetric), within the sampling's unevenness.
    let s = shapes::icosphere(1.0, 3);
    let gs = SurfaceGraph::new(&s.positions, &s.faces);
    let a = average_geodesic_distance(&gs, 0, 32, Method::FastMarching);
    let max = a.normalised.iter().copied().fold(0.0, f64::max);
    assert!(max < 1.06, "sphere AGD varies by {max}");
}

#[test]
fn reeb_graph_sees_tips_and_handles() {
    let m = ellipsoid();
    let g = SurfaceGraph::new(&m.positions, &m.faces);
    let agd = average_geodesic_distance(&g, 0, 24, Method::FastMarching);
    let r = ReebGraph::build(&m.positions, &m.faces, &agd.normalised, 16).unwrap();
    assert_eq!(r.loop_count(), 0);
    let tips = r.tips();
    assert_eq!(tips.len(), 2, "tips {tips:?}");
    for t in tips {
        let x = m.positions[r.graph[t].max_vertex as usize].x;
        assert!(x.abs() > 2.7);
    }
    let t = Shape::Torus.mesh(0);
    let gt = SurfaceGraph::new(&t.positions, &t.faces);
    let at = average_geodesic_distance(&gt, 0, 32, Method::FastMarching);
    let rt = ReebGraph::build(&t.positions, &t.faces, &at.normalised, 16).unwrap();
    assert_eq!(rt.loop_count(), 1);
    assert_eq!(rt.loops().len(), 1);
    // Genus 2: two loops (at this resolution; finer meshes can show spurious loops from
    // jagged level sets, which is why genus reduction verifies by Euler characteristic).
    let d = Shape::DoubleTorus.mesh(0);
    let gd = SurfaceGraph::new(&d.positions, &d.faces);
    let ad = average_geodesic_distance(&gd, 0, 32, Method::FastMarching);
    let rd = ReebGraph::build(&d.positions, &d.faces, &ad.normalised, 24).unwrap();
    assert_eq!(rd.loop_count(), 2);
}

#[test]
fn torus_is_cut_around_its_tube() {
    let t = shapes::torus(0.7, 0.3, 48, 24);
    let r = reduce_genus(&t.positions, &t.faces, &[0]).unwrap();
    assert_eq!((r.genus_before, r.handles_cut), (1, 1));
    let cyc = &r.cycles[0];
    let len: f64 = (0..cyc.len())
        .map(|i| {
            let a: Point3<f64> = t.positions[cyc[i] as usize];
            (a - t.positions[cyc[(i + 1) % cyc.len()] as usize]).norm()
        })
        .sum();
    // The tube circumference is 2 pi 0.3 = 1.88 (polygon: a bit less); any loop around the
    // hole is at least 2 pi 0.4 = 2.51.
    assert!(len < 2.2, "cut length {len}");
}
