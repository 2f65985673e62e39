//! Density trimming of a Poisson surface, as PoissonRecon's SurfaceTrimmer does it: Poisson
//! closes every hole in the samples with a smooth membrane, and the membrane is where the
//! sampling density is low. Each vertex carries the density the reconstruction estimated
//! there (the same scale as PoissonRecon's `--density` output, compared with `--trim`).
//!
//! [`trim_by_density`]:
//! 1. clips every triangle along the iso-line `density = trim` (linear along edges, the
//!    crossing vertex shared by the two faces of an edge, so the cut is crack-free) into a
//!    part above and a part below the threshold;
//! 2. connected parts *below* the threshold whose area is under `hole_area` of the total are
//!    kept anyway: a small low-density patch inside well-sampled surface is a sampling gap,
//!    not a bridged hole;
//! 3. the remaining below part is removed, and then connected *islands* of the kept part with
//!    area under `island_area` of the total are removed too (the fringe of a trimmed membrane).
//!
//! Vertex normals and colours are interpolated onto the new vertices; per-corner UVs are
//! dropped if the mesh had them (Poisson output has none).

use std::collections::HashMap;

use fresco_core::Mesh;
use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::Point3;

use crate::cleanup::face_components;

/// Trimming settings (the area fractions are PoissonRecon's SurfaceTrimmer `--aRatio`).
#[derive(Clone, Debug, PartialEq)]
pub struct TrimConfig {
    /// Density threshold (PoissonRecon's `--trim`; 7 is its usual value at depth 9-10 on
    /// clouds of a few hundred thousand points); finite. Ignored when `below_median` is set.
    /// Default: `7.0`.
    pub trim: f32,
    /// Threshold relative to the sampling: the median vertex density minus this (density is
    /// a log4 scale, so 1 cuts where the density falls to a quarter of the typical one);
    /// finite. An absolute `trim` only suits one point count and depth: the density is
    /// `log4(samples per unit area / samples per node)`, which grows by 1 for every 4x more
    /// points. Default: `None` (the absolute `trim`; `MeshConfig` sets 1).
    pub below_median: Option<f32>,
    /// Below-threshold components smaller than this fraction of the total area are kept;
    /// in [0, 1]. Default: `0.001`.
    pub hole_area: f64,
    /// Kept components smaller than this fraction of the total area are removed; in [0, 1].
    /// Default: `0.001`.
    pub island_area: f64,
}

impl TrimConfig {
    /// Validates every field (see each field's range).
    pub fn check(&self) -> Result<(), ConfigError> {
        require(self.trim.is_finite(), "trim", self.trim, "finite")?;
        if let Some(b) = self.below_median {
            require(b.is_finite(), "below_median", b, "finite")?;
        }
        let fraction = |v: f64| (0.0..=1.0).contains(&v);
        require(
            fraction(self.hole_area),
            "hole_area",
            self.hole_area,
            "in [0, 1]",
        )?;
        require(
            fraction(self.island_area),
            "island_area",
            self.island_area,
            "in [0, 1]",
        )
    }
}

impl Default for TrimConfig {
    fn default() -> Self {
        TrimConfig {
            trim: 7.0,
            below_median: None,
            hole_area: 0.001,
            island_area: 0.001,
        }
    }
}

/// What [`trim_by_density`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TrimReport {
    pub faces_before: usize,
    pub faces_after: usize,
    /// Triangles cut by the iso-line.
    pub faces_clipped: usize,
    /// Small low-density patches kept (step 2).
    pub holes_kept: usize,
    /// Islands removed (step 3).
    pub islands_removed: usize,
    /// Fraction of the area removed.
    pub area_removed: f64,
    /// The density threshold used (`trim`, or the median minus `below_median`).
    pub threshold: f32,
}

/// Why trimming could not run.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrimError {
    #[error("{densities} densities for {vertices} vertices")]
    LengthMismatch { densities: usize, vertices: usize },
    #[error("no vertex has a finite density to take the median of")]
    NoDensity,
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// The trimmed mesh with the density of each of its vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct Trimmed {
    pub mesh: Mesh,
    pub density: Vec<f32>,
    pub report: TrimReport,
}

/// Trims `mesh` where `density` (one per vertex) is below `cfg.trim` (or the median density
/// minus `cfg.below_median`); see the module documentation.
pub fn trim_by_density(
    mesh: &Mesh,
    density: &[f32],
    cfg: &TrimConfig,
) -> Result<Trimmed, TrimError> {
    cfg.check()?;
    if density.len() != mesh.positions.len() {
        return Err(TrimError::LengthMismatch {
            densities: density.len(),
            vertices: mesh.positions.len(),
        });
    }
    let t = match cfg.below_median {
        Some(delta) => {
            let mut finite: Vec<f32> = density.iter().copied().filter(|d| d.is_finite()).collect();
            if finite.is_empty() {
                return Err(TrimError::NoDensity);
            }
            let mid = finite.len() / 2;
            *finite.select_nth_unstable_by(mid, f32::total_cmp).1 - delta
        }
        None => cfg.trim,
    };
    let mut out = Mesh {
        positions: mesh.positions.clone(),
        normals: mesh.normals.clone(),
        colors: mesh.colors.clone(),
        ..Mesh::default()
    };
    let mut dens = density.to_vec();
    let mut groups = mesh.face_groups.as_ref().map(|_| Vec::new());
    let mut textures = mesh.face_textures.as_ref().map(|_| Vec::new());
    // For each output face: is it above the threshold?
    let mut above_face: Vec<bool> = Vec::with_capacity(mesh.faces.len());
    let mut crossing: HashMap<(u32, u32), u32> = HashMap::new();
    let mut report = TrimReport {
        faces_before: mesh.faces.len(),
        threshold: t,
        ..TrimReport::default()
    };
    // NaN densities count as below: nothing vouches for that vertex.
    let is_above = |d: f32| d >= t;

    for (f, tri) in mesh.faces.iter().enumerate() {
        let above = tri.map(|v| is_above(density[v as usize]));
        let push = |out: &mut Mesh,
                    above_face: &mut Vec<bool>,
                    groups: &mut Option<Vec<u32>>,
                    textures: &mut Option<Vec<u32>>,
                    face: [u32; 3],
                    up: bool| {
            out.faces.push(face);
            above_face.push(up);
            if let (Some(g), Some(src)) = (groups.as_mut(), &mesh.face_groups) {
                g.push(src[f]);
            }
            if let (Some(x), Some(src)) = (textures.as_mut(), &mesh.face_textures) {
                x.push(src[f]);
            }
        };
        if above.iter().all(|&a| a) || above.iter().all(|&a| !a) {
            push(
                &mut out,
                &mut above_face,
                &mut groups,
                &mut textures,
                *tri,
                above[0],
            );
            continue;
        }
        report.faces_clipped += 1;
        // Walk the corners, splitting into the polygon above and the polygon below.
        let mut up: Vec<u32> = Vec::with_capacity(4);
        let mut down: Vec<u32> = Vec::with_capacity(4);
        for c in 0..3 {
            let (a, b) = (tri[c], tri[(c + 1) % 3]);
            if above[c] {
                up.push(a);
            } else {
                down.push(a);
            }
            if above[c] != above[(c + 1) % 3] {
                let key = (a.min(b), a.max(b));
                let x = *crossing.entry(key).or_insert_with(|| {
                    let (lo, hi) = key;
                    let (dl, dh) = (dens[lo as usize], dens[hi as usize]);
                    // A NaN end is below: cut at the finite end's side, mid-edge.
                    let s = if dl.is_finite() && dh.is_finite() && dh != dl {
                        ((t - dl) / (dh - dl)).clamp(0.0, 1.0) as f64
                    } else {
                        0.5
                    };
                    let (pl, ph) = (out.positions[lo as usize], out.positions[hi as usize]);
                    out.positions
                        .push(Point3::from(pl.coords * (1.0 - s) + ph.coords * s));
                    if let Some(n) = &mut out.normals {
                        let m = n[lo as usize] * (1.0 - s) + n[hi as usize] * s;
                        n.push(m.try_normalize(1e-12).unwrap_or(n[lo as usize]));
                    }
                    if let Some(col) = &mut out.colors {
                        let (cl, ch) = (col[lo as usize], col[hi as usize]);
                        col.push(std::array::from_fn(|k| {
                            (cl[k] as f64 * (1.0 - s) + ch[k] as f64 * s).round() as u8
                        }));
                    }
                    dens.push(t);
                    (out.positions.len() - 1) as u32
                });
                up.push(x);
                down.push(x);
            }
        }
        for (poly, is_up) in [(&up, true), (&down, false)] {
            for k in 1..poly.len() - 1 {
                push(
                    &mut out,
                    &mut above_face,
                    &mut groups,
                    &mut textures,
                    [poly[0], poly[k], poly[k + 1]],
                    is_up,
                );
            }
        }
    }
    out.face_groups = groups;
    out.face_textures = textures;

    let areas = out.face_areas();
    let total: f64 = areas.iter().sum();
    // Step 2: small below-threshold patches are kept.
    let mut keep = above_face.clone();
    report.holes_kept = small_parts(&out, &above_face, false, &areas, cfg.hole_area * total)
        .into_iter()
        .map(|faces| {
            for f in faces {
                keep[f] = true;
            }
        })
        .count();
    // Step 3: small islands of what is kept are removed.
    report.islands_removed = small_parts(&out, &keep, true, &areas, cfg.island_area * total)
        .into_iter()
        .map(|faces| {
            for f in faces {
                keep[f] = false;
            }
        })
        .count();
    let removed_area: f64 = areas
        .iter()
        .zip(&keep)
        .filter(|(_, k)| !**k)
        .map(|(a, _)| a)
        .sum();
    report.area_removed = if total > 0.0 {
        removed_area / total
    } else {
        0.0
    };
    out.retain_faces(&keep);
    let map = out.remove_unreferenced_vertices();
    let density: Vec<f32> = dens
        .iter()
        .zip(&map)
        .filter(|(_, m)| m.is_some())
        .map(|(d, _)| *d)
        .collect();
    report.faces_after = out.faces.len();
    Ok(Trimmed {
        mesh: out,
        density,
        report,
    })
}

/// Connected components (through shared edges) of the faces with `select[f] == which`
/// whose area is below `max_area`; each as its list of faces.
fn small_parts(
    mesh: &Mesh,
    select: &[bool],
    which: bool,
    areas: &[f64],
    max_area: f64,
) -> Vec<Vec<usize>> {
    let ids: Vec<usize> = (0..mesh.faces.len())
        .filter(|&f| select[f] == which)
        .collect();
    let sub = Mesh {
        positions: Vec::new(),
        faces: ids.iter().map(|&f| mesh.faces[f]).collect(),
        ..Mesh::default()
    };
    let labels = face_components(&sub);
    let count = labels.iter().max().map_or(0, |&m| m as usize + 1);
    let mut area = vec![0.0; count];
    for (i, &l) in labels.iter().enumerate() {
        area[l as usize] += areas[ids[i]];
    }
    let mut parts: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (i, &l) in labels.iter().enumerate() {
        if area[l as usize] < max_area {
            parts[l as usize].push(ids[i]);
        }
    }
    parts.retain(|p| !p.is_empty());
    parts
}
