//! The PST folder: everything a texturing session needs between commands.
//!
//! ```text
//! <pst>/
//!   pst.json        manifest: source, bounding box, level-1 grid, 1-nodes (density, sub-grid,
//!                   residency, last use), channels, in-core budget
//!   samples.bin     the in-core samples (layout in samples.rs)
//!   nodes/<id>.pts  the 1-node files of the first pass (layout in node_files.rs), kept for
//!                   local up-sampling (section 3)
//!   evicted/<id>.bin the edited samples of 1-nodes evicted by the LRU (layout of samples.bin)
//! ```
//!
//! [`Pst::create`] samples an input into a new folder. It works in a staging folder beside the
//! target (and, if asked, writes the 1-node files in a separate temporary folder); only a
//! complete result is renamed into place, and every temporary file is removed on error.

use std::path::{Path, PathBuf};

use fresco_core::Progress;
use fresco_core::config::{ConfigError, require};
use serde::{Deserialize, Serialize};

use crate::error::{PstError, Result};
use crate::input::PointSource;
use crate::mgrid::Level1Grid;
use crate::node_files::{Staging, node_file_name};
use crate::samples::SampleSet;
use crate::sampling::{NodeInfo, Sampling, SamplingConfig, sample};

pub const MANIFEST: &str = "pst.json";
pub const SAMPLES: &str = "samples.bin";
pub const NODES: &str = "nodes";
pub const EVICTED: &str = "evicted";

/// A named group of attribute floats per sample (`rgb`: 3, `specular`: 1, ...).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Channel {
    pub name: String,
    pub width: usize,
    /// Value of samples never painted.
    pub default: Vec<f32>,
}

impl Channel {
    pub fn new(name: &str, default: &[f32]) -> Channel {
        Channel {
            name: name.to_string(),
            width: default.len(),
            default: default.to_vec(),
        }
    }
}

/// A 1-node with its residency (section 3's LRU).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeState {
    #[serde(flatten)]
    pub info: NodeInfo,
    /// False when the LRU replaced the node's samples by one sample and stored them in
    /// `evicted/<id>.bin`.
    pub resident: bool,
    /// Logical time of the last edit or refinement that touched the node.
    pub last_used: u64,
}

/// What the sampling was asked and did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplingRecord {
    pub target: u64,
    pub alpha: f64,
    pub position: crate::cluster::PositionRule,
    pub samples: u64,
    pub paper_size: u64,
    pub input_points: u64,
}

/// `pst.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    /// The sampled file, as given.
    pub source: String,
    pub has_normals: bool,
    /// Bounding box min and max.
    pub bbox: [[f64; 3]; 2],
    pub grid: Level1Grid,
    pub sampling: SamplingRecord,
    pub channels: Vec<Channel>,
    pub nodes: Vec<NodeState>,
    /// Whether `nodes/` holds the 1-node files (needed by refinement).
    pub node_files: bool,
    /// In-core sample budget enforced by the LRU (None: unbounded).
    pub budget: Option<usize>,
    /// Logical clock for `last_used`.
    pub clock: u64,
}

/// Settings of [`Pst::create`].
#[derive(Clone, Debug)]
pub struct CreateConfig {
    /// Default: `SamplingConfig::default()`.
    pub sampling: SamplingConfig,
    /// Channels and their initial values: at least one, none empty.
    /// Default: `vec![Channel::new("rgb", &[0.8, 0.8, 0.8])]` (`rgb`, 0.8 grey).
    pub channels: Vec<Channel>,
    /// Where the 1-node files are written during sampling; they are moved into `<pst>/nodes`
    /// at the end. Default: `None` (inside the staging folder beside the output).
    pub temp_dir: Option<PathBuf>,
    /// Keep the 1-node files for later refinement. Default: `true`.
    pub keep_node_files: bool,
    /// In-core sample budget for the LRU, >= 1. Default: `None` (no budget).
    pub budget: Option<usize>,
}

impl CreateConfig {
    /// Validates every field, the sampling's too (named `sampling.target`, ...).
    pub fn check(&self) -> std::result::Result<(), ConfigError> {
        self.sampling.check().map_err(|e| e.within("sampling"))?;
        require(
            !self.channels.is_empty() && self.channels.iter().all(|c| c.width > 0),
            "channels",
            format!("{} channels", self.channels.len()),
            "at least one channel, none of width 0",
        )?;
        if let Some(budget) = self.budget {
            require(budget >= 1, "budget", budget, ">= 1")?;
        }
        Ok(())
    }
}

impl Default for CreateConfig {
    fn default() -> Self {
        CreateConfig {
            sampling: SamplingConfig::default(),
            channels: vec![Channel::new("rgb", &[0.8, 0.8, 0.8])],
            temp_dir: None,
            keep_node_files: true,
            budget: None,
        }
    }
}

/// An open PST folder: manifest and in-core samples.
#[derive(Clone, Debug)]
pub struct Pst {
    pub dir: PathBuf,
    pub manifest: Manifest,
    pub samples: SampleSet,
}

impl Pst {
    /// Samples `source` into a new PST folder `out` (replacing an older PST folder there).
    pub fn create(
        source: &dyn PointSource,
        cfg: &CreateConfig,
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<(Pst, Sampling)> {
        cfg.check()?;
        if out.exists() && !out.join(MANIFEST).exists() {
            return Err(PstError::store(
                out,
                "exists and is not a PST folder; refusing to replace it",
            ));
        }
        let parent = out
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "pst".into());
        let stage =
            Staging::create(parent.join(format!(".{name}.partial-{}", std::process::id())))?;
        let scratch = match &cfg.temp_dir {
            Some(t) => Some(Staging::create(
                t.join(format!("fresco-pst-nodes-{}", std::process::id())),
            )?),
            None => None,
        };
        let nodes_dir = stage.path().join(NODES);
        std::fs::create_dir_all(&nodes_dir)
            .map_err(|e| PstError::io(&nodes_dir, "cannot create the nodes folder", e))?;
        let write_dir = scratch
            .as_ref()
            .map_or(nodes_dir.clone(), |s| s.path().to_path_buf());
        let sampling = sample(source, &cfg.sampling, &write_dir, progress)?;

        if let Some(scratch) = &scratch {
            if cfg.keep_node_files {
                for node in &sampling.nodes {
                    let name = node_file_name(node.id);
                    move_file(&scratch.path().join(&name), &nodes_dir.join(&name))?;
                }
            }
        } else if !cfg.keep_node_files {
            std::fs::remove_dir_all(&nodes_dir).ok();
            std::fs::create_dir_all(&nodes_dir).ok();
        }
        drop(scratch);

        let defaults: Vec<f32> = cfg
            .channels
            .iter()
            .flat_map(|c| c.default.clone())
            .collect();
        let mut samples = SampleSet::with_width(0);
        samples.positions = sampling.samples.positions.clone();
        samples.normals = sampling.samples.normals.clone();
        samples.nodes = sampling.samples.nodes.clone();
        samples.add_channel(&defaults);
        let manifest = Manifest {
            format: "fresco-pst".into(),
            version: 1,
            source: source.path().to_string_lossy().into_owned(),
            has_normals: sampling.has_normals,
            bbox: [
                sampling.bbox.min.coords.into(),
                sampling.bbox.max.coords.into(),
            ],
            grid: sampling.grid,
            sampling: SamplingRecord {
                target: cfg.sampling.target,
                alpha: cfg.sampling.alpha,
                position: cfg.sampling.position,
                samples: samples.len() as u64,
                paper_size: sampling.paper_size,
                input_points: sampling.input_points,
            },
            channels: cfg.channels.clone(),
            nodes: sampling
                .nodes
                .iter()
                .map(|info| NodeState {
                    info: info.clone(),
                    resident: true,
                    last_used: 0,
                })
                .collect(),
            node_files: cfg.keep_node_files,
            budget: cfg.budget,
            clock: 0,
        };
        let staged = Pst {
            dir: stage.path().to_path_buf(),
            manifest,
            samples,
        };
        staged.save()?;
        // Swap into place: an older PST folder is moved aside first and removed last.
        let old = parent.join(format!(".{name}.old-{}", std::process::id()));
        if out.exists() {
            std::fs::rename(out, &old)
                .map_err(|e| PstError::io(out, "cannot move the previous PST folder aside", e))?;
        }
        let staged_dir = stage.keep();
        std::fs::rename(&staged_dir, out).map_err(|e| {
            let _ = std::fs::remove_dir_all(&staged_dir);
            PstError::io(out, "cannot move the new PST folder into place", e)
        })?;
        if old.exists() {
            std::fs::remove_dir_all(&old).ok();
        }
        let pst = Pst {
            dir: out.to_path_buf(),
            ..staged
        };
        Ok((pst, sampling))
    }

    /// Opens a PST folder.
    pub fn open(dir: &Path) -> Result<Pst> {
        let mpath = dir.join(MANIFEST);
        let text = std::fs::read_to_string(&mpath)
            .map_err(|e| PstError::io(&mpath, "cannot read the PST manifest", e))?;
        let manifest: Manifest = serde_json::from_str(&text)
            .map_err(|e| PstError::store(dir, format!("{MANIFEST}: {e}")))?;
        if manifest.format != "fresco-pst" || manifest.version != 1 {
            return Err(PstError::store(
                dir,
                format!(
                    "{MANIFEST}: format {} version {} (expected fresco-pst 1)",
                    manifest.format, manifest.version
                ),
            ));
        }
        let samples = SampleSet::load(&dir.join(SAMPLES))?;
        let width: usize = manifest.channels.iter().map(|c| c.width).sum();
        if samples.width != width {
            return Err(PstError::store(
                dir,
                format!(
                    "samples have {} attribute floats, the channels need {width}",
                    samples.width
                ),
            ));
        }
        if let Some(bad) = samples
            .nodes
            .iter()
            .find(|&&n| n as usize >= manifest.nodes.len())
        {
            return Err(PstError::store(
                dir,
                format!("a sample names 1-node {bad}, which does not exist"),
            ));
        }
        Ok(Pst {
            dir: dir.to_path_buf(),
            manifest,
            samples,
        })
    }

    /// Writes the manifest and the samples (each atomically).
    pub fn save(&self) -> Result<()> {
        self.samples.save(&self.dir.join(SAMPLES))?;
        let text = serde_json::to_string_pretty(&self.manifest)
            .map_err(|e| PstError::store(&self.dir, format!("cannot encode the manifest: {e}")))?;
        Ok(fresco_core::atomic_file::write_bytes_atomically(
            &self.dir.join(MANIFEST),
            text.as_bytes(),
        )?)
    }

    /// Offset and width of a channel in the attributes.
    pub fn channel(&self, name: &str) -> Option<(usize, usize)> {
        let mut offset = 0;
        for c in &self.manifest.channels {
            if c.name == name {
                return Some((offset, c.width));
            }
            offset += c.width;
        }
        None
    }

    /// Adds a channel (its default everywhere, evicted nodes included).
    pub fn add_channel(&mut self, channel: Channel) -> Result<()> {
        if self.channel(&channel.name).is_some() {
            return Err(PstError::Parameter(format!(
                "channel {} exists already",
                channel.name
            )));
        }
        self.samples.add_channel(&channel.default);
        for node in self.manifest.nodes.iter().filter(|n| !n.resident) {
            let path = self.evicted_path(node.info.id);
            let mut s = SampleSet::load(&path)?;
            s.add_channel(&channel.default);
            s.save(&path)?;
        }
        self.manifest.channels.push(channel);
        Ok(())
    }

    pub fn node_file(&self, id: u32) -> PathBuf {
        self.dir.join(NODES).join(node_file_name(id))
    }

    pub fn evicted_path(&self, id: u32) -> PathBuf {
        self.dir.join(EVICTED).join(format!("{id:07}.bin"))
    }

    /// Every edited sample: the in-core ones of resident nodes and those stored for evicted
    /// nodes (what apply and exports must use, not the evicted nodes' single stand-ins).
    pub fn all_samples(&self) -> Result<SampleSet> {
        let evicted: Vec<u32> = self
            .manifest
            .nodes
            .iter()
            .filter(|n| !n.resident)
            .map(|n| n.info.id)
            .collect();
        if evicted.is_empty() {
            return Ok(self.samples.clone());
        }
        let mut all = self.samples.clone();
        let is_evicted = {
            let mut v = vec![false; self.manifest.nodes.len()];
            for &id in &evicted {
                v[id as usize] = true;
            }
            v
        };
        all.retain_indices(|i| !is_evicted[self.samples.nodes[i] as usize]);
        for id in evicted {
            all.append(&SampleSet::load(&self.evicted_path(id))?);
        }
        Ok(all)
    }
}

/// Moves a file, copying when the two paths are on different file systems.
fn move_file(from: &Path, to: &Path) -> Result<()> {
    if std::fs::rename(from, to).is_ok() {
        return Ok(());
    }
    std::fs::copy(from, to).map_err(|e| PstError::io(to, "cannot copy a 1-node file", e))?;
    std::fs::remove_file(from).ok();
    Ok(())
}
