//! Ground-truth helpers of the dense diagnostics (`dense_diagnose`, `dense_tune`): the part of
//! the synthetic temple a face belongs to, and each pixel's distance to the nearest depth
//! discontinuity of a rendered ground-truth depth map.

use fresco_core::Mesh;
use fresco_core::nalgebra::Vector3;
use fresco_core::raster::Visibility;

/// A ground-truth depth step larger than this fraction of the depth between neighbouring
/// pixels is a discontinuity (a surface at 85 degrees steps by about 1% per pixel here).
pub const EDGE_STEP: f32 = 0.02;

/// Distance of every pixel to the nearest ground-truth depth discontinuity (two-pass chamfer).
pub fn edge_distance(vis: &Visibility) -> Vec<f32> {
    let (w, h) = (vis.width as usize, vis.height as usize);
    let d = &vis.depth;
    let step = |a: f32, b: f32| {
        (a.is_finite() != b.is_finite()) || (a.is_finite() && (a - b).abs() > EDGE_STEP * a.min(b))
    };
    let mut dist = vec![f32::INFINITY; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut edge = false;
            for (dx, dy) in [(1i32, 0i32), (-1, 0), (0, 1), (0, -1)] {
                let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                    edge |= step(d[i], d[ny as usize * w + nx as usize]);
                }
            }
            if edge {
                dist[i] = 0.0;
            }
        }
    }
    let pass = |dist: &mut Vec<f32>, order: &mut dyn Iterator<Item = usize>, s: i32| {
        for i in order {
            let (x, y) = ((i % w) as i32, (i / w) as i32);
            for (dx, dy, c) in [(-s, 0, 1.0), (0, -s, 1.0), (-s, -s, 1.4), (s, -s, 1.4)] {
                let (nx, ny) = (x + dx, y + dy);
                if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                    let v = dist[ny as usize * w + nx as usize] + c;
                    if v < dist[i] {
                        dist[i] = v;
                    }
                }
            }
        }
    };
    pass(&mut dist, &mut (0..w * h), 1);
    pass(&mut dist, &mut (0..w * h).rev(), -1);
    dist
}

/// The part of the temple a face belongs to, from its centroid and normal (`shapes::temple`).
pub fn part(mesh: &Mesh, normals: &[Vector3<f64>], f: usize) -> &'static str {
    let [a, b, c] = mesh.faces[f];
    let p = (mesh.positions[a as usize].coords
        + mesh.positions[b as usize].coords
        + mesh.positions[c as usize].coords)
        / 3.0;
    let n = normals[f].normalize();
    let inside = p.x.abs() < 0.75 && p.y.abs() < 0.45;
    if p.z < -0.45 + 1e-6 {
        if n.z > 0.9 {
            "lower step, top"
        } else {
            "lower step, side/bottom"
        }
    } else if p.z < -0.35 + 1e-6 {
        match (n.z > 0.9, inside) {
            (true, true) => "upper step top, inside the colonnade",
            (true, false) => "upper step top, outside",
            _ => "upper step, side",
        }
    } else if p.z < 0.45 - 1e-6 {
        if n.z.abs() > 0.9 {
            "column, end"
        } else if n.x * p.x + n.y * p.y > 0.0 {
            "column, outer half"
        } else {
            "column, inner half"
        }
    } else if p.z < 0.58 - 1e-6 {
        if n.z < -0.9 {
            "slab, underside"
        } else {
            "slab, side"
        }
    } else if n.z < -0.9 {
        "roof, underside"
    } else {
        "roof, top/gable"
    }
}
