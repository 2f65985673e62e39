//! Local up-sampling (section 3, figure 3): "the user first selects the area to up-sample, all
//! 1-nodes of G are tested against this selection, the sub-grids of intersected 1-nodes are
//! refined, the files associated to these nodes are streamed through these new sub-grids.
//! Alternatively ... all the samples of the files associated to the intersected 1-nodes are
//! kept. The selection is removed and the set of samples obtained are inserted in the active
//! point cloud and colored by the current PST".

use fresco_core::Progress;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::cluster::PositionRule;
use crate::error::{PstError, Result};
use crate::field::{Field, FieldConfig};
use crate::index::PointIndex;
use crate::input::SourcePoint;
use crate::lru::LruReport;
use crate::region::Region;
use crate::samples::SampleSet;
use crate::sampling::{NodeInput, cluster_at};
use crate::store::Pst;

/// How finely the selection is re-sampled.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Resolution {
    /// The node's sub-grid resolution times this factor (per axis).
    Factor(u32),
    /// 2-nodes of about this side (world units): e.g. a bitmap's pixel size.
    Spacing(f64),
    /// Every input point of the selection (the original resolution).
    Full,
}

#[derive(Clone, Debug, Serialize)]
pub struct RefineReport {
    pub nodes: usize,
    pub removed: usize,
    pub added: usize,
    pub lru: LruReport,
}

/// A new sample: its 1-node, the cluster (in the node's frame) and the node's origin.
type NewSample = (u32, crate::cluster::ClusterSample, [f64; 3]);

/// Up-samples the part of the PST inside `region` from the 1-node files.
pub fn refine(
    pst: &mut Pst,
    region: &Region,
    resolution: Resolution,
    field_cfg: FieldConfig,
    progress: &dyn Progress,
) -> Result<RefineReport> {
    field_cfg.check()?;
    if !pst.manifest.node_files {
        return Err(PstError::store(
            &pst.dir,
            "sampled without keeping the 1-node files: refinement needs them (sample again)",
        ));
    }
    match resolution {
        Resolution::Factor(0) => {
            return Err(PstError::Parameter("refinement factor must be >= 1".into()));
        }
        Resolution::Spacing(h) if h.is_nan() || h <= 0.0 => {
            return Err(PstError::Parameter(format!(
                "refinement spacing must be > 0, got {h}"
            )));
        }
        _ => {}
    }
    let nodes = pst.nodes_in_region(region);
    pst.touch(&nodes)?;
    let grid = pst.manifest.grid;
    let has_normals = pst.manifest.has_normals;
    progress.begin("refining 1-nodes", nodes.len() as u64);
    let inside = |p: &SourcePoint| region.contains(p.position);
    let fresh: Vec<Result<Vec<NewSample>>> = nodes
        .par_iter()
        .map(|&id| {
            let state = &pst.manifest.nodes[id as usize];
            let origin: [f64; 3] = grid.cell_box(state.info.cell).min.coords.into();
            let node = NodeInput {
                path: pst.node_file(id),
                origin,
                has_normals,
                gamma: state.info.gamma,
                cell: state.info.cell,
            };
            let res = match resolution {
                Resolution::Factor(f) if state.info.subgrid > 0 => {
                    state.info.subgrid.saturating_mul(f)
                }
                Resolution::Factor(_) | Resolution::Full => 0,
                // Up-sampling never coarsens: at least the node's own sub-grid.
                Resolution::Spacing(_) if state.info.subgrid == 0 => 0,
                Resolution::Spacing(h) => {
                    ((grid.cell_size / h).ceil() as u32).max(state.info.subgrid)
                }
            };
            let c = cluster_at(&node, &None, &grid, &[res], PositionRule::Centroid, &inside)?;
            progress.advance(1);
            Ok(c.into_iter()
                .next()
                .map(|c| c.samples.into_iter().map(|s| (id, s, origin)).collect())
                .unwrap_or_default())
        })
        .collect();
    progress.end();
    let mut new = SampleSet::with_width(pst.samples.width);
    let mut unknown_normal = Vec::new();
    for r in fresh {
        for (id, s, o) in r? {
            if s.normal.is_none() {
                unknown_normal.push(new.len());
            }
            let p = [
                (o[0] + s.position[0]) as f32,
                (o[1] + s.position[1]) as f32,
                (o[2] + s.position[2]) as f32,
            ];
            new.positions.push(p);
            new.normals.push(s.normal.unwrap_or([0.0; 3]));
            new.nodes.push(id);
        }
    }
    // Colour the new samples by the current PST, and give those without a normal the normal
    // of the nearest current sample (oriented like the input's).
    new.attrs = vec![0.0; new.len() * new.width];
    {
        let field = Field::new(&pst.samples, field_cfg);
        field.eval_many(&new.positions, &mut new.attrs);
        let index: &PointIndex = field.index();
        let mut nb = Vec::new();
        for &i in &unknown_normal {
            index.nearest(&new.positions[i], 1, &mut nb);
            if let Some(&(_, j)) = nb.first() {
                new.normals[i] = pst.samples.normals[j as usize];
            }
        }
        if !has_normals {
            // PCA normals of clusters have an arbitrary sign: agree with the nearest old sample.
            for i in 0..new.len() {
                index.nearest(&new.positions[i], 1, &mut nb);
                if let Some(&(_, j)) = nb.first() {
                    let o = pst.samples.normals[j as usize];
                    let n = &mut new.normals[i];
                    if n[0] * o[0] + n[1] * o[1] + n[2] * o[2] < 0.0 {
                        *n = n.map(|v| -v);
                    }
                }
            }
        }
    }
    let in_nodes: std::collections::HashSet<u32> = nodes.iter().copied().collect();
    let before = pst.samples.len();
    let drop: Vec<bool> = (0..pst.samples.len())
        .map(|i| {
            in_nodes.contains(&pst.samples.nodes[i])
                && region.contains_f32(pst.samples.positions[i])
        })
        .collect();
    pst.samples.retain_indices(|i| !drop[i]);
    let removed = before - pst.samples.len();
    pst.samples.append(&new);
    let lru = pst.enforce_budget(&nodes)?;
    Ok(RefineReport {
        nodes: nodes.len(),
        removed,
        added: new.len(),
        lru,
    })
}
