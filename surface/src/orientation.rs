//! Meshes made from photos face their cameras: a camera can only have seen the outside of a
//! surface, so every pixel of every photo should see a face from the front. The Poisson
//! surface inherits the orientation of its input normals, and normals estimated from a
//! sparse cloud (oriented by a spanning tree, Hoppe et al. 1992) can come out inside-out as a
//! whole or per component, which breaks the back-face tests of later stages.
//!
//! [`face_the_cameras`] renders the mesh into every view with core's rasteriser, counts per
//! connected component the pixels that see a face from the front and from behind, and flips
//! the components seen more from behind. [`back_face_pixels`] is the count itself, for tests
//! and reports.

use fresco_core::raster::{self, NO_FACE, RasterConfig, RasterError, SampleMap};
use fresco_core::{CamFromWorld, Camera, Mesh, Topology};
use serde::Serialize;

/// Pixels that see a face from the front and from behind, over all views.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FacingCount {
    pub front_pixels: u64,
    pub back_pixels: u64,
}

/// What [`face_the_cameras`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct OrientationReport {
    /// Before any flip.
    pub before: FacingCount,
    /// After the flips.
    pub after: FacingCount,
    pub components: usize,
    pub flipped_components: usize,
    pub flipped_faces: usize,
}

/// Front and back pixels per face: `counts[f] = [front, back]`.
fn facing_per_face(
    mesh: &Mesh,
    views: &[(Camera, CamFromWorld)],
) -> Result<Vec<[u64; 2]>, RasterError> {
    let mut counts = vec![[0u64; 2]; mesh.faces.len()];
    let normals = mesh.face_normals();
    let config = RasterConfig::default();
    for (camera, pose) in views {
        let map = SampleMap::new(camera, 1)?;
        let vis = raster::visibility(mesh, &map, pose, &config)?;
        let centre = pose.center();
        for &f in &vis.face_ids {
            if f == NO_FACE {
                continue;
            }
            let corner = mesh.positions[mesh.faces[f as usize][0] as usize];
            let front = normals[f as usize].dot(&(centre - corner)) > 0.0;
            counts[f as usize][usize::from(!front)] += 1;
        }
    }
    Ok(counts)
}

/// Pixels of `views` that see `mesh` from the front and from behind.
pub fn back_face_pixels(
    mesh: &Mesh,
    views: &[(Camera, CamFromWorld)],
) -> Result<FacingCount, RasterError> {
    let counts = facing_per_face(mesh, views)?;
    Ok(FacingCount {
        front_pixels: counts.iter().map(|c| c[0]).sum(),
        back_pixels: counts.iter().map(|c| c[1]).sum(),
    })
}

/// Flips every connected component of `mesh` that `views` see more from behind than from the
/// front (see the module documentation); vertex normals, if any, are recomputed.
pub fn face_the_cameras(
    mesh: &mut Mesh,
    views: &[(Camera, CamFromWorld)],
) -> Result<OrientationReport, RasterError> {
    let counts = facing_per_face(mesh, views)?;
    // Components by shared vertices (a broken topology falls back to one component).
    let components: Vec<u32> = match Topology::build(mesh) {
        Ok(t) => t.face_components().to_vec(),
        Err(_) => vec![0; mesh.faces.len()],
    };
    let n = components
        .iter()
        .map(|&c| c as usize + 1)
        .max()
        .unwrap_or(0);
    let mut per = vec![[0u64; 2]; n];
    for (f, &c) in components.iter().enumerate() {
        per[c as usize][0] += counts[f][0];
        per[c as usize][1] += counts[f][1];
    }
    let flip: Vec<bool> = per.iter().map(|c| c[1] > c[0]).collect();
    let mut report = OrientationReport {
        components: n,
        flipped_components: flip.iter().filter(|&&b| b).count(),
        ..Default::default()
    };
    for (f, &c) in components.iter().enumerate() {
        let (front, back) = (counts[f][0], counts[f][1]);
        report.before.front_pixels += front;
        report.before.back_pixels += back;
        if flip[c as usize] {
            mesh.faces[f].swap(1, 2);
            report.flipped_faces += 1;
            report.after.front_pixels += back;
            report.after.back_pixels += front;
        } else {
            report.after.front_pixels += front;
            report.after.back_pixels += back;
        }
    }
    if report.flipped_faces > 0 {
        if let Some(uvs) = mesh.corner_uvs.as_mut() {
            for (f, &c) in components.iter().enumerate() {
                if flip[c as usize] {
                    uvs[f].swap(1, 2);
                }
            }
        }
        if mesh.normals.is_some() {
            mesh.compute_vertex_normals();
        }
    }
    Ok(report)
}
