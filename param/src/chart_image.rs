//! A picture of an atlas for reports: every chart in its own colour, shaded by a checker of
//! the 3D surface (cells `checker` world units wide) so that stretch shows as cells that are
//! not square and of unequal size, and gutters and empty space stay black.

use fresco_core::Mesh;
use fresco_core::nalgebra::{Point2, Point3};
use image::{Rgb, RgbImage};

/// Renders atlas `atlas` of `mesh` (corner UVs required) at `size` x `size` pixels; `None`
/// when the mesh has no UVs. `checker` is the cell size in world units (e.g. 1/40 of the
/// bounding-box diagonal).
pub fn chart_image(mesh: &Mesh, atlas: u32, size: u32, checker: f64) -> Option<RgbImage> {
    let uvs = mesh.corner_uvs.as_ref()?;
    let mut img = RgbImage::new(size, size);
    let s = size as f64;
    for (f, tri) in mesh.faces.iter().enumerate() {
        if mesh.face_textures.as_ref().is_some_and(|t| t[f] != atlas)
            || (mesh.face_textures.is_none() && atlas != 0)
        {
            continue;
        }
        let chart = mesh.face_groups.as_ref().map_or(0, |g| g[f]);
        let colour = chart_colour(chart);
        let q = uvs[f].map(|c| Point2::new(c[0] as f64 * s, c[1] as f64 * s));
        let p: [Point3<f64>; 3] = tri.map(|v| mesh.positions[v as usize]);
        let den = (q[1] - q[0]).perp(&(q[2] - q[0]));
        if den == 0.0 {
            continue;
        }
        let lo = q[0].inf(&q[1]).inf(&q[2]);
        let hi = q[0].sup(&q[1]).sup(&q[2]);
        let (x0, x1) = (lo.x.floor().max(0.0) as u32, (hi.x.ceil() as u32).min(size));
        let (y0, y1) = (lo.y.floor().max(0.0) as u32, (hi.y.ceil() as u32).min(size));
        for y in y0..y1 {
            for x in x0..x1 {
                let c = Point2::new(x as f64 + 0.5, y as f64 + 0.5);
                let b1 = (c - q[0]).perp(&(q[2] - q[0])) / den;
                let b2 = (q[1] - q[0]).perp(&(c - q[0])) / den;
                let b0 = 1.0 - b1 - b2;
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                let w = p[0].coords * b0 + p[1].coords * b1 + p[2].coords * b2;
                let cell = (w / checker).map(|v| v.floor() as i64);
                let dark = (cell.x + cell.y + cell.z).rem_euclid(2) == 0;
                let k = if dark { 0.6 } else { 1.0 };
                img.put_pixel(x, y, Rgb(colour.map(|c| (c as f64 * k) as u8)));
            }
        }
    }
    Some(img)
}

/// A bright colour per chart id (golden-ratio hue steps so neighbours differ).
fn chart_colour(id: u32) -> [u8; 3] {
    let h = (id as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [r, g, b].map(|c| (60.0 + 195.0 * c) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One triangle covering the lower-left half: pixels inside are coloured, outside black.
    #[test]
    fn triangle_is_drawn_inside_its_uvs_only() {
        let mut m = Mesh::from_triangles(
            vec![
                Point3::origin(),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2]],
        );
        m.corner_uvs = Some(vec![[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]]);
        let img = chart_image(&m, 0, 32, 0.25).unwrap();
        assert_ne!(img.get_pixel(2, 2).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(30, 30).0, [0, 0, 0]);
        // The checker alternates: two pixels one cell (8 px) apart differ.
        assert_ne!(img.get_pixel(2, 2).0, img.get_pixel(10, 2).0);
    }
}
