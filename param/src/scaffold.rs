//! The scaffold around a flattened chart: a square virtual boundary a margin away from the
//! chart, and the gap between it and the chart's boundary triangulated (constrained Delaunay,
//! spade) with the chart's boundary edges as constraints.
//!
//! Why: with the scaffold triangles kept positively oriented as well as the chart's own, the
//! chart plus scaffold is a locally injective map of a disc whose outer boundary (the square)
//! does not move, hence globally injective. So the chart's boundary vertices can move freely
//! during the stretch optimisation ([`crate::stretch::optimise_free`]) and the boundary still
//! cannot cross itself. This is the scaffold of Jiang, Schaefer and Panozzo, "Simplicial
//! complex augmentation framework for bijective maps" (SIGGRAPH Asia 2017), here with
//! Sander's L2 stretch as the energy, scaffold triangles only kept from flipping, and the
//! scaffold rebuilt around the moved chart before every sweep.

use fresco_core::nalgebra::Point2;
use spade::{ConstrainedDelaunayTriangulation, HasPosition, Triangulation};

use crate::metrics::signed_area;

/// Scaffold of one chart: `points` extends the chart's UVs (indices `n..`, the square's
/// vertices), `faces` index into chart UVs followed by `points`, all counter-clockwise.
#[derive(Clone, Debug)]
pub struct Scaffold {
    pub points: Vec<Point2<f64>>,
    pub faces: Vec<[u32; 3]>,
}

/// Vertices of the square placed on each of its sides (besides the corners): the scaffold
/// triangles then fan out from several points instead of four, so they are less thin.
const SIDE_POINTS: usize = 3;

#[derive(Clone, Copy)]
struct Vertex {
    p: spade::Point2<f64>,
}

impl HasPosition for Vertex {
    type Scalar = f64;
    fn position(&self) -> spade::Point2<f64> {
        self.p
    }
}

/// Builds the scaffold of the chart whose UVs are `uv` (`n` vertices) and whose boundary loop
/// is `boundary` (counter-clockwise). `None` when the gap cannot be triangulated with the
/// boundary as it is (coincident boundary vertices, crossing edges, non-finite positions).
pub fn build(uv: &[Point2<f64>], boundary: &[u32]) -> Option<Scaffold> {
    let n = uv.len();
    if boundary.len() < 3 {
        return None;
    }
    let (mut lo, mut hi) = (uv[boundary[0] as usize], uv[boundary[0] as usize]);
    for &v in boundary {
        let p = uv[v as usize];
        if !p.x.is_finite() || !p.y.is_finite() {
            return None;
        }
        lo = lo.inf(&p);
        hi = hi.sup(&p);
    }
    // Square around the chart's box, a margin of half its larger side on every side: room for
    // the boundary to move in one sweep (it is rebuilt before the next).
    let side = (hi - lo).x.max((hi - lo).y);
    if side <= 0.0 || !side.is_finite() {
        return None;
    }
    let centre = Point2::from((lo.coords + hi.coords) * 0.5);
    let half = side;
    let mut square = Vec::with_capacity(4 * (SIDE_POINTS + 1));
    let corners = [
        Point2::new(centre.x - half, centre.y - half),
        Point2::new(centre.x + half, centre.y - half),
        Point2::new(centre.x + half, centre.y + half),
        Point2::new(centre.x - half, centre.y + half),
    ];
    for k in 0..4 {
        let (a, b) = (corners[k], corners[(k + 1) % 4]);
        for s in 0..=SIDE_POINTS {
            let t = s as f64 / (SIDE_POINTS + 1) as f64;
            square.push(a + (b - a) * t);
        }
    }
    // CDT vertices: the boundary loop, then the square.
    let mut verts: Vec<Vertex> = boundary
        .iter()
        .map(|&v| Vertex {
            p: spade::Point2::new(uv[v as usize].x, uv[v as usize].y),
        })
        .collect();
    verts.extend(square.iter().map(|p| Vertex {
        p: spade::Point2::new(p.x, p.y),
    }));
    let nb = boundary.len();
    let edges: Vec<[usize; 2]> = (0..nb).map(|k| [k, (k + 1) % nb]).collect();
    let total = verts.len();
    let mut conflict = false;
    let cdt: ConstrainedDelaunayTriangulation<Vertex> =
        ConstrainedDelaunayTriangulation::try_bulk_load_cdt(verts, edges, |_| conflict = true)
            .ok()?;
    // Duplicates are dropped by spade (the indices would shift): refuse them.
    if conflict || cdt.num_vertices() != total || cdt.num_constraints() != nb {
        return None;
    }
    // Index of a CDT vertex among the chart's UVs followed by the square's points.
    let index = |h: spade::handles::FixedVertexHandle| -> u32 {
        let i = h.index();
        if i < nb {
            boundary[i]
        } else {
            (n + i - nb) as u32
        }
    };
    // Flood fill from the faces touching the square, never across a constraint (the chart's
    // boundary): what is reached is the gap.
    let nfaces = cdt.num_all_faces();
    let mut gap = vec![false; nfaces];
    let mut stack = Vec::new();
    for f in cdt.inner_faces() {
        if f.vertices().iter().any(|v| v.fix().index() >= nb) {
            gap[f.fix().index()] = true;
            stack.push(f.fix());
        }
    }
    while let Some(fh) = stack.pop() {
        let f = cdt.face(fh);
        for e in f.adjacent_edges() {
            if cdt.is_constraint_edge(e.as_undirected().fix()) {
                continue;
            }
            if let Some(g) = e.rev().face().as_inner() {
                let gi = g.fix().index();
                if !gap[gi] {
                    gap[gi] = true;
                    stack.push(g.fix());
                }
            }
        }
    }
    let mut points = Vec::with_capacity(square.len());
    points.extend_from_slice(&square);
    let at = |i: u32| {
        if (i as usize) < n {
            uv[i as usize]
        } else {
            points[i as usize - n]
        }
    };
    let mut faces = Vec::new();
    for f in cdt.inner_faces() {
        if !gap[f.fix().index()] {
            continue;
        }
        let t = f.vertices().map(|v| index(v.fix()));
        // spade's faces are counter-clockwise; keep only those f64 also sees as positive.
        if signed_area(t.map(at)) <= 0.0 {
            return None;
        }
        faces.push(t);
    }
    Some(Scaffold { points, faces })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An L-shaped chart boundary: the gap triangles plus the chart's area fill the square.
    #[test]
    fn gap_fills_the_square_around_a_concave_chart() {
        let uv = vec![
            Point2::new(0.0, 0.0),
            Point2::new(2.0, 0.0),
            Point2::new(2.0, 1.0),
            Point2::new(1.0, 1.0),
            Point2::new(1.0, 2.0),
            Point2::new(0.0, 2.0),
        ];
        let boundary = [0u32, 1, 2, 3, 4, 5];
        let s = build(&uv, &boundary).unwrap();
        let at = |i: u32| {
            if (i as usize) < uv.len() {
                uv[i as usize]
            } else {
                s.points[i as usize - uv.len()]
            }
        };
        let gap: f64 = s.faces.iter().map(|t| signed_area(t.map(at))).sum();
        // Square of side 4 (twice the chart's larger side) minus the L's area 3.
        assert!((gap - (16.0 - 3.0)).abs() < 1e-9, "{gap}");
        // The concave corner's pocket is part of the gap: some face uses only chart vertices.
        assert!(
            s.faces
                .iter()
                .any(|t| t.iter().all(|&v| (v as usize) < uv.len()))
        );
    }

    #[test]
    fn coincident_boundary_vertices_are_refused() {
        let uv = vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(1.0, 0.0),
        ];
        assert!(build(&uv, &[0, 1, 2, 3]).is_none());
    }
}
