//! LRU down-sampling of the in-core set (section 3): "if the in-core model becomes itself too
//! large ..., a down-sampling is performed, again on a per-1-node basis, by replacing the
//! Least Recently Used area by a unique sample, and storing the edited piece of surface on the
//! disk. Later, if the user comes back to this part of the object, the area is reloaded ...
//! it can be useful to maintain a ring of 1-nodes at current resolution around the currently
//! edited piece of surface".
//!
//! Every operation touches the 1-nodes its region meets ([`Pst::touch`]: evicted ones are
//! reloaded, their logical clock advanced); then [`Pst::enforce_budget`] evicts the least
//! recently used resident nodes, never those touched nor their 26 grid neighbours (the ring),
//! until the in-core count is within the budget.

use std::collections::{HashMap, HashSet};

use serde::Serialize;

use crate::error::{PstError, Result};
use crate::region::Region;
use crate::samples::SampleSet;
use crate::store::{EVICTED, Pst};

/// What one budget enforcement did.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct LruReport {
    pub evicted: Vec<u32>,
    pub in_core: usize,
    /// True when the budget could not be met without evicting protected nodes.
    pub over_budget: bool,
}

impl Pst {
    /// The 1-nodes whose cells meet `region`.
    pub fn nodes_in_region(&self, region: &Region) -> Vec<u32> {
        self.manifest
            .nodes
            .iter()
            .filter(|n| region.intersects(&self.manifest.grid.cell_box(n.info.cell)))
            .map(|n| n.info.id)
            .collect()
    }

    /// `nodes` and their 26 neighbours in the level-1 grid.
    pub fn ring(&self, nodes: &[u32]) -> HashSet<u32> {
        let by_cell: HashMap<[u32; 3], u32> = self
            .manifest
            .nodes
            .iter()
            .map(|n| (n.info.cell, n.info.id))
            .collect();
        let mut out = HashSet::new();
        for &id in nodes {
            let c = self.manifest.nodes[id as usize].info.cell;
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let n = [c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz];
                        if n.iter().any(|&v| v < 0) {
                            continue;
                        }
                        if let Some(&j) = by_cell.get(&[n[0] as u32, n[1] as u32, n[2] as u32]) {
                            out.insert(j);
                        }
                    }
                }
            }
        }
        out
    }

    /// Marks `nodes` as just used and reloads the evicted ones.
    pub fn touch(&mut self, nodes: &[u32]) -> Result<()> {
        self.manifest.clock += 1;
        let now = self.manifest.clock;
        for &id in nodes {
            if !self.manifest.nodes[id as usize].resident {
                self.reload(id)?;
            }
            self.manifest.nodes[id as usize].last_used = now;
        }
        Ok(())
    }

    /// Replaces node `id`'s samples by one (their average) and stores them on disk.
    pub fn evict(&mut self, id: u32) -> Result<()> {
        let node = &self.manifest.nodes[id as usize];
        if !node.resident {
            return Ok(());
        }
        let mut own = SampleSet::with_width(self.samples.width);
        for i in 0..self.samples.len() {
            if self.samples.nodes[i] == id {
                own.push(
                    self.samples.positions[i],
                    self.samples.normals[i],
                    id,
                    self.samples.attr(i),
                );
            }
        }
        let dir = self.dir.join(EVICTED);
        std::fs::create_dir_all(&dir)
            .map_err(|e| PstError::io(&dir, "cannot create the evicted-nodes folder", e))?;
        own.save(&self.evicted_path(id))?;
        let keep: Vec<bool> = self.samples.nodes.iter().map(|&n| n != id).collect();
        self.samples.retain_indices(|i| keep[i]);
        if let Some(rep) = representative(&own) {
            self.samples.append(&rep);
        }
        self.manifest.nodes[id as usize].resident = false;
        Ok(())
    }

    /// Brings an evicted node's samples back in core (replacing its single stand-in).
    pub fn reload(&mut self, id: u32) -> Result<()> {
        if self.manifest.nodes[id as usize].resident {
            return Ok(());
        }
        let path = self.evicted_path(id);
        let own = self.load_evicted(id, self.samples.width)?;
        let keep: Vec<bool> = self.samples.nodes.iter().map(|&n| n != id).collect();
        self.samples.retain_indices(|i| keep[i]);
        self.samples.append(&own);
        self.manifest.nodes[id as usize].resident = true;
        std::fs::remove_file(&path).ok();
        Ok(())
    }

    /// Evicts least recently used nodes, never those in `protect` nor their ring, until the
    /// in-core set fits the manifest's budget (if any).
    pub fn enforce_budget(&mut self, protect: &[u32]) -> Result<LruReport> {
        let mut report = LruReport::default();
        let Some(budget) = self.manifest.budget else {
            report.in_core = self.samples.len();
            return Ok(report);
        };
        let safe = self.ring(protect);
        let mut counts = vec![0usize; self.manifest.nodes.len()];
        for &n in &self.samples.nodes {
            counts[n as usize] += 1;
        }
        let mut candidates: Vec<(u64, u32)> = self
            .manifest
            .nodes
            .iter()
            .filter(|n| n.resident && !safe.contains(&n.info.id) && counts[n.info.id as usize] > 1)
            .map(|n| (n.last_used, n.info.id))
            .collect();
        candidates.sort_unstable();
        let mut total = self.samples.len();
        for (_, id) in candidates {
            if total <= budget {
                break;
            }
            total -= counts[id as usize] - 1;
            report.evicted.push(id);
        }
        for &id in &report.evicted {
            self.evict(id)?;
        }
        report.in_core = self.samples.len();
        report.over_budget = report.in_core > budget;
        Ok(report)
    }

    /// Applies a per-sample edit to the stored samples of evicted nodes meeting `region`
    /// (so that reloading them later brings the edit back), refreshing their stand-ins.
    pub fn edit_evicted(
        &mut self,
        region: &Region,
        edit: &dyn Fn(&mut SampleSet),
    ) -> Result<usize> {
        let ids: Vec<u32> = self
            .nodes_in_region(region)
            .into_iter()
            .filter(|&id| !self.manifest.nodes[id as usize].resident)
            .collect();
        for &id in &ids {
            let path = self.evicted_path(id);
            let mut own = self.load_evicted(id, self.samples.width)?;
            edit(&mut own);
            own.save(&path)?;
            let keep: Vec<bool> = self.samples.nodes.iter().map(|&n| n != id).collect();
            self.samples.retain_indices(|i| keep[i]);
            if let Some(rep) = representative(&own) {
                self.samples.append(&rep);
            }
        }
        Ok(ids.len())
    }
}

/// One sample standing for a set: mean position, mean normal, mean attributes.
fn representative(own: &SampleSet) -> Option<SampleSet> {
    let n = own.len();
    if n == 0 {
        return None;
    }
    let mut p = [0f64; 3];
    let mut nr = [0f64; 3];
    let mut a = vec![0f64; own.width];
    for i in 0..n {
        for k in 0..3 {
            p[k] += own.positions[i][k] as f64;
            nr[k] += own.normals[i][k] as f64;
        }
        for (s, v) in a.iter_mut().zip(own.attr(i)) {
            *s += *v as f64;
        }
    }
    let len = (nr[0] * nr[0] + nr[1] * nr[1] + nr[2] * nr[2])
        .sqrt()
        .max(1e-12);
    let mut rep = SampleSet::with_width(own.width);
    let attrs: Vec<f32> = a.iter().map(|v| (v / n as f64) as f32).collect();
    rep.push(
        p.map(|v| (v / n as f64) as f32),
        nr.map(|v| (v / len) as f32),
        own.nodes[0],
        &attrs,
    );
    Some(rep)
}
