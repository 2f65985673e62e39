//! The parameterisation pipeline: charts → flattened discs → packed atlas → per-corner UVs.
//!
//! 1. Initial charts: the caller's `face_chart` ([`unwrap_charts`]), or ([`unwrap`]) the
//!    Reeb-graph segmentation [`crate::charts::segment`] (genus reduced, every chart a disc);
//!    for a non-manifold mesh, which that refuses, or with `reeb_charts` off, the connected
//!    components, left to the splitting below.
//! 2. Each chart is cut out ([`ChartMesh`]); a chart that is not a topological disc (closed,
//!    holes, handles, non-manifold, disconnected) is split in two ([`split::split_in_two`])
//!    and each half handled again.
//! 3. A disc is flattened by LSCM ([`lscm::lscm`]); if that folds (a flipped triangle, or a
//!    boundary that crosses itself) the mean-value map onto a circle
//!    ([`harmonic::mean_value`]), which cannot fold, is used instead.
//! 4. The stretch optimisation (Sander et al. 2001) lowers the L2 stretch without flipping a
//!    triangle, the boundary moving too inside a scaffold ([`crate::scaffold`]) that keeps it
//!    from crossing itself.
//! 5. A chart whose L2 stretch is still above `max_stretch`, or which folds whatever we do, is
//!    split in two and both halves start again at 2.
//! 6. Each chart is scaled so its UV area equals its 3D area, then all are packed
//!    ([`pack::pack`]); `corner_uvs` (fresco's v-down convention), `face_groups` (chart id)
//!    and, with several atlases, `face_textures` (atlas index) are written into the mesh.

use fresco_core::config::{ConfigError, require};
use fresco_core::nalgebra::Point2;
use fresco_core::{Mesh, Progress, Topology};
use serde::Serialize;

use crate::ParamError;
use crate::chart_mesh::ChartMesh;
use crate::metrics::{chart_l2_stretch, polygon_is_simple, signed_area};
use crate::pack::{ChartShape, PackConfig, pack};
use crate::{harmonic, lscm, split, stretch};

/// Settings of [`unwrap`]; the defaults suit a mesh of any size.
#[derive(Clone, Debug)]
pub struct UnwrapConfig {
    /// Width and height of each atlas image, texels, in 8..=65536. Default: `4096`.
    pub atlas_size: u32,
    /// Minimum texels between charts and from the atlas border; `2 gutter + 1` below
    /// `atlas_size`. Default: `4`.
    pub gutter: u32,
    /// Texels per world unit, finite and > 0; `None` picks the density that fills one atlas.
    /// Default: `None`.
    pub texels_per_unit: Option<f64>,
    /// Charts whose L2 stretch (normalised by their own area) stays above this are split; at
    /// least 1. Default: `1.02` (a root-mean-square texel-size error of about 2% inside a
    /// chart; the earlier default, 1.1, left a sphere in two hemispheres at 1.03 once their
    /// boundaries move freely; xatlas reaches 1.006 on it).
    pub max_stretch: f64,
    /// Charts covering less than this fraction of their UV convex hull (C shapes, bent
    /// bands, spirals, which pack badly) are split; in [0, 1]. Default: `0.7` (measured on the
    /// five bench meshes at 0.5 / 0.6 / 0.7, utilisation rose on every one of them with it:
    /// torus 0.51 -> 0.69, double torus 0.59 -> 0.69, an earlier Poisson temple 0.64 -> 0.68;
    /// sphere and temple unchanged, for more charts; bench/RESULTS.md, issue 6).
    pub min_hull_fill: f64,
    /// Iterations of the stretch optimisation (0 turns it off). Default: `6`.
    pub stretch_iterations: u32,
    /// Start from the Reeb-graph charts, or (`false`) from connected components and let the
    /// splitting make the charts. Default: `false` (measured on the six bench meshes,
    /// bench/RESULTS.md, issue 6: the Reeb charts give shorter seams on five, but higher
    /// stretch on five and lower utilisation on four, torus 0.54 against 0.69, and
    /// segmenting costs time).
    pub reeb_charts: bool,
    /// Settings of the Reeb-graph segmentation. Default: `ChartConfig::default()`.
    pub charts: crate::charts::ChartConfig,
}

impl Default for UnwrapConfig {
    fn default() -> Self {
        UnwrapConfig {
            atlas_size: 4096,
            gutter: 4,
            texels_per_unit: None,
            max_stretch: 1.02,
            stretch_iterations: 6,
            min_hull_fill: 0.7,
            reeb_charts: false,
            charts: crate::charts::ChartConfig::default(),
        }
    }
}

/// What [`unwrap`] did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct UnwrapReport {
    pub charts: usize,
    pub atlases: u32,
    pub texels_per_unit: f64,
    /// Charts split because they were not discs, folded, or were too stretched.
    pub splits: usize,
    /// Charts flattened by the mean-value map because LSCM folded.
    pub harmonic_fallbacks: usize,
    /// Repairs and oddities of the input, one line each (also logged as warnings).
    pub warnings: Vec<String>,
}

/// Unwraps every connected component of `mesh` (see the module documentation).
pub fn unwrap(
    mesh: &mut Mesh,
    cfg: &UnwrapConfig,
    progress: &dyn Progress,
) -> Result<UnwrapReport, ParamError> {
    cfg.check()?;
    check(mesh)?;
    let topo = Topology::build(mesh)?;
    let mut note = None;
    let face_chart: Vec<u32> = if cfg.reeb_charts {
        match crate::charts::segment(mesh, &cfg.charts, progress) {
            Ok(charts) if fragmented(mesh, &charts.face_chart) => {
                note = Some(format!(
                    "the Reeb-graph charts ({}) fall apart into pieces joined only at vertices (mesh too coarse for them): charts start from connected components instead",
                    charts.count
                ));
                topo.face_components().to_vec()
            }
            Ok(charts) => charts.face_chart,
            Err(ParamError::NonManifold { .. }) => {
                note = Some("non-manifold mesh: charts start from connected components instead of the Reeb graph".to_string());
                topo.face_components().to_vec()
            }
            Err(e) => return Err(e),
        }
    } else {
        topo.face_components().to_vec()
    };
    let mut report = unwrap_charts(mesh, &face_chart, cfg, progress)?;
    if let Some(n) = note {
        tracing::warn!("{n}");
        report.warnings.push(n);
    }
    Ok(report)
}

impl UnwrapConfig {
    /// Validates every field, the segmentation's too (named `charts.bands`, ...).
    pub fn check(&self) -> Result<(), ConfigError> {
        self.pack().check()?;
        require(
            self.max_stretch >= 1.0 && self.max_stretch.is_finite(),
            "max_stretch",
            self.max_stretch,
            "finite and >= 1",
        )?;
        require(
            (0.0..=1.0).contains(&self.min_hull_fill),
            "min_hull_fill",
            self.min_hull_fill,
            "in [0, 1]",
        )?;
        self.charts.check().map_err(|e| e.within("charts"))
    }

    /// The packing settings.
    fn pack(&self) -> PackConfig {
        PackConfig {
            atlas_size: self.atlas_size,
            gutter: self.gutter,
            texels_per_unit: self.texels_per_unit,
        }
    }
}

fn check(mesh: &Mesh) -> Result<(), ParamError> {
    mesh.validate()?;
    if mesh.faces.is_empty() {
        return Err(ParamError::EmptyMesh);
    }
    Ok(())
}

/// Whether charts fall apart into more than 1.5 times as many edge-connected pieces as there
/// are charts: on coarse meshes the geodesic splits can leave faces of a chart joined only at
/// vertices, and each such piece would become a chart of its own.
fn fragmented(mesh: &Mesh, face_chart: &[u32]) -> bool {
    let mut groups: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
    for (f, &c) in face_chart.iter().enumerate() {
        groups.entry(c).or_default().push(f as u32);
    }
    let pieces: usize = groups
        .values()
        .map(|faces| ChartMesh::extract(mesh, faces).edge_components().len())
        .sum();
    2 * pieces > 3 * groups.len()
}

/// Names the first few elements of a list for a warning.
fn first_few<T: std::fmt::Debug>(items: &[T]) -> String {
    let shown: Vec<String> = items.iter().take(8).map(|x| format!("{x:?}")).collect();
    if items.len() > 8 {
        format!("{} ...", shown.join(", "))
    } else {
        shown.join(", ")
    }
}

/// Input problems that are repaired rather than refused, as warnings naming the elements.
fn input_warnings(mesh: &Mesh, topo: &Topology) -> Vec<String> {
    let mut out = Vec::new();
    let nm: Vec<[u32; 2]> = topo
        .non_manifold_edges()
        .iter()
        .map(|&e| topo.edges()[e as usize])
        .collect();
    if !nm.is_empty() {
        out.push(format!(
            "{} non-manifold edge(s) (vertex pairs {}): cut, their faces go to different charts",
            nm.len(),
            first_few(&nm)
        ));
    }
    if !topo.non_manifold_vertices().is_empty() {
        out.push(format!(
            "{} non-manifold vertex(es) ({}): split between charts",
            topo.non_manifold_vertices().len(),
            first_few(topo.non_manifold_vertices())
        ));
    }
    if !topo.isolated_vertices().is_empty() {
        out.push(format!(
            "{} isolated vertex(es) ({}): no face uses them, they get no texture coordinates",
            topo.isolated_vertices().len(),
            first_few(topo.isolated_vertices())
        ));
    }
    // Zero-area: below 1e-12 of the squared bounding-box diagonal (float noise on any scale).
    let scale = mesh.bounding_box().map_or(1.0, |b| b.diagonal().powi(2));
    let zero: Vec<usize> = (0..mesh.faces.len())
        .filter(|&f| mesh.face_area(f) <= 1e-12 * scale)
        .collect();
    if !zero.is_empty() {
        out.push(format!(
            "{} zero-area face(s) ({}): flattened with bounded weights, they have no orientation",
            zero.len(),
            first_few(&zero)
        ));
    }
    if !topo.inconsistently_oriented_edges().is_empty() {
        out.push(format!(
            "{} edge(s) with inconsistently oriented faces ({}): cut",
            topo.inconsistently_oriented_edges().len(),
            first_few(topo.inconsistently_oriented_edges())
        ));
    }
    out
}

/// A flattened chart: UVs in world units (area equal to the 3D area), counter-clockwise.
struct Flat {
    chart: ChartMesh,
    uv: Vec<Point2<f64>>,
    area: f64,
    splits: usize,
    fallback: bool,
}

/// Unwraps `mesh` starting from the charts `face_chart` (a label per face; labels need not be
/// contiguous). Charts that are not discs or are too stretched are split further.
pub fn unwrap_charts(
    mesh: &mut Mesh,
    face_chart: &[u32],
    cfg: &UnwrapConfig,
    progress: &dyn Progress,
) -> Result<UnwrapReport, ParamError> {
    cfg.check()?;
    check(mesh)?;
    if face_chart.len() != mesh.faces.len() {
        return Err(ParamError::ChartLength {
            len: face_chart.len(),
            faces: mesh.faces.len(),
        });
    }
    let topo = Topology::build(mesh)?;
    let warnings = input_warnings(mesh, &topo);
    for w in &warnings {
        tracing::warn!("{w}");
    }
    let mut groups: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
    for (f, &c) in face_chart.iter().enumerate() {
        groups.entry(c).or_default().push(f as u32);
    }
    let groups: Vec<Vec<u32>> = groups.into_values().collect();
    progress.begin("flattening charts", mesh.faces.len() as u64);
    let m: &Mesh = mesh;
    let flats: Vec<Flat> = {
        use rayon::prelude::*;
        groups
            .par_iter()
            .flat_map_iter(|faces| flatten(m, faces.clone(), cfg, progress))
            .collect()
    };
    progress.end();
    progress.begin("packing charts", 0);
    let shapes: Vec<ChartShape> = flats
        .iter()
        .map(|f| ChartShape {
            uv: &f.uv,
            faces: &f.chart.faces,
            area: f.area,
        })
        .collect();
    let packing = pack(&shapes, &cfg.pack())?;
    progress.end();
    let nf = mesh.faces.len();
    let mut corner_uvs = vec![[[0f32; 2]; 3]; nf];
    let mut groups_out = vec![0u32; nf];
    let mut textures = vec![0u32; nf];
    for (id, (flat, pl)) in flats.iter().zip(&packing.placements).enumerate() {
        for (lf, tri) in flat.chart.faces.iter().enumerate() {
            let g = flat.chart.global_face[lf] as usize;
            corner_uvs[g] = tri.map(|v| {
                let p = pl.apply(flat.uv[v as usize], cfg.atlas_size);
                [p.x as f32, p.y as f32]
            });
            groups_out[g] = id as u32;
            textures[g] = pl.atlas;
        }
    }
    mesh.corner_uvs = Some(corner_uvs);
    mesh.face_groups = Some(groups_out);
    mesh.face_textures = (packing.atlases > 1).then_some(textures);
    Ok(UnwrapReport {
        charts: flats.len(),
        atlases: packing.atlases,
        texels_per_unit: packing.texels_per_unit,
        splits: flats.iter().map(|f| f.splits).sum(),
        harmonic_fallbacks: flats.iter().filter(|f| f.fallback).count(),
        warnings,
    })
}

/// Whether `uv` is a valid flattening of the disc: every triangle of positive 3D area keeps
/// its orientation and the boundary does not cross itself.
fn folds(chart: &ChartMesh, uv: &[Point2<f64>], boundary: &[u32]) -> bool {
    if uv.iter().any(|p| !p.x.is_finite() || !p.y.is_finite()) {
        return true;
    }
    let flipped =
        chart.faces.iter().enumerate().any(|(f, t)| {
            chart.face_area(f) > 0.0 && signed_area(t.map(|v| uv[v as usize])) <= 0.0
        });
    flipped || !polygon_is_simple(uv, boundary)
}

/// Flattens the chart made of `faces`, splitting as needed (see the module documentation).
fn flatten(mesh: &Mesh, faces: Vec<u32>, cfg: &UnwrapConfig, progress: &dyn Progress) -> Vec<Flat> {
    let chart = ChartMesh::extract(mesh, &faces);
    let parts = chart.edge_components();
    if parts.len() > 1 {
        return parts
            .into_iter()
            .flat_map(|p| flatten(mesh, p, cfg, progress))
            .collect();
    }
    if chart.faces.len() == 1 {
        progress.advance(1);
        return vec![single_triangle(chart)];
    }
    let mut fallback = false;
    let flat = chart.disc_boundary().ok().and_then(|boundary| {
        let mut uv = lscm::lscm(&chart, &boundary)
            .ok()
            .filter(|uv| !folds(&chart, uv, &boundary));
        if uv.is_none() {
            fallback = true;
            uv = harmonic::mean_value(&chart, &boundary)
                .ok()
                .filter(|uv| !folds(&chart, uv, &boundary));
        }
        let mut uv = uv?;
        // Hopeless charts are split without optimising: the optimisation removes well under
        // 8/9 of the conformal map's excess stretch (a hemisphere: 1.074 -> 1.020), so a chart
        // whose excess is above 8 times the allowed one would be split anyway.
        let s0 = chart_l2_stretch(&chart.positions, &chart.faces, &uv);
        if s0 - 1.0 > 8.0 * (cfg.max_stretch - 1.0) {
            return None;
        }
        if cfg.stretch_iterations > 0 {
            let before = uv.clone();
            stretch::optimise_free(&chart, &mut uv, &boundary, cfg.stretch_iterations);
            // The scaffold rules folds out; checked anyway, as it is cheap.
            if folds(&chart, &uv, &boundary) {
                uv = before;
            }
        }
        let s = chart_l2_stretch(&chart.positions, &chart.faces, &uv);
        let fill = hull_fill(&chart, &uv);
        (s <= cfg.max_stretch && fill >= cfg.min_hull_fill).then_some(uv)
    });
    match flat {
        Some(uv) => {
            progress.advance(chart.faces.len() as u64);
            vec![normalise(chart, uv, 0, fallback)]
        }
        None => {
            let (a, b) = split::split_in_two(&chart);
            let (mut x, y) = rayon::join(
                || flatten(mesh, a, cfg, progress),
                || flatten(mesh, b, cfg, progress),
            );
            x.extend(y);
            if let Some(first) = x.first_mut() {
                first.splits += 1;
            }
            x
        }
    }
}

/// UV area of the chart over the area of its UV convex hull.
fn hull_fill(chart: &ChartMesh, uv: &[Point2<f64>]) -> f64 {
    let area: f64 = chart
        .faces
        .iter()
        .map(|t| signed_area(t.map(|v| uv[v as usize])).abs())
        .sum();
    let hull = crate::pack::convex_hull(uv);
    let mut twice = 0.0;
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        twice += a.x * b.y - b.x * a.y;
    }
    if twice > 0.0 {
        (2.0 * area / twice).min(1.0)
    } else {
        1.0
    }
}

/// A lone triangle laid flat isometrically.
fn single_triangle(chart: ChartMesh) -> Flat {
    let [a, b, c] = chart.faces[0].map(|v| chart.positions[v as usize]);
    let (e1, e2) = (b - a, c - a);
    let l = e1.norm();
    let x = if l > 0.0 { e1 / l } else { e1 };
    let px = e2.dot(&x);
    let py = (e2 - x * px).norm();
    let mut uv = vec![Point2::origin(); chart.vertex_count()];
    let t = chart.faces[0];
    uv[t[1] as usize] = Point2::new(l, 0.0);
    uv[t[2] as usize] = Point2::new(px, py);
    let area = chart.area();
    Flat {
        chart,
        uv,
        area,
        splits: 0,
        fallback: false,
    }
}

/// Scales `uv` so that its area equals the chart's 3D area (one texel density for all).
fn normalise(chart: ChartMesh, mut uv: Vec<Point2<f64>>, splits: usize, fallback: bool) -> Flat {
    let area = chart.area();
    let uv_area: f64 = chart
        .faces
        .iter()
        .map(|t| signed_area(t.map(|v| uv[v as usize])).abs())
        .sum();
    if uv_area > 0.0 && area > 0.0 {
        let s = (area / uv_area).sqrt();
        for p in &mut uv {
            *p = Point2::from(p.coords * s);
        }
    }
    Flat {
        chart,
        uv,
        area,
        splits,
        fallback,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::nalgebra::Point3;

    /// Pieces are counted through edges, not vertices: two triangles joined at a vertex are
    /// two pieces, joined at an edge one.
    #[test]
    fn fragmented_counts_edge_connected_pieces() {
        let p = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(-1.0, 0.0, 0.0),
            Point3::new(0.0, -1.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
        ];
        // Two faces sharing only vertex 0, then two sharing edge 1-2, each as one chart.
        let at_vertex = Mesh::from_triangles(p.clone(), vec![[0, 1, 2], [0, 3, 4]]);
        assert!(fragmented(&at_vertex, &[0, 0]));
        assert!(!fragmented(&at_vertex, &[0, 1]));
        let at_edge = Mesh::from_triangles(p, vec![[0, 1, 2], [1, 5, 2]]);
        assert!(!fragmented(&at_edge, &[0, 0]));
    }
}
