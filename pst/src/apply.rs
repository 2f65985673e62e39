//! Section 5's feedback on the original model: stream the huge mesh again, evaluate the PST at
//! every vertex and write the mesh with per-vertex colours.
//!
//! Memory: the edited samples (every node's, evicted ones included) and one chunk of
//! vertices (default 1M); the faces are copied through as they are read. The PST lookups of a
//! chunk run in parallel (rayon); reading and writing go through core's streaming PLY
//! reader and writer, and the output appears atomically.

use std::path::Path;

use fresco_core::Progress;
use fresco_core::config::{ConfigError, require};
use fresco_core::ply::{PlyFace, PlyFormat, PlyLayout, PlyReader, PlyVertex, PlyWriter};
use serde::Serialize;

use crate::error::{PstError, Result};
use crate::field::{Field, FieldConfig};
use crate::store::Pst;

/// Settings of [`apply_to_ply`].
#[derive(Clone, Debug)]
pub struct ApplyConfig {
    /// Default: `FieldConfig::default()`.
    pub field: FieldConfig,
    /// The channel written as vertex colour (width 3, or 1 for grey). Default: `"rgb"`.
    pub channel: String,
    /// Vertices evaluated per batch, >= 1. Default: `1_048_576` (1M).
    pub chunk: usize,
    /// Output encoding. Default: `PlyFormat::BinaryLittleEndian`.
    pub format: PlyFormat,
}

impl ApplyConfig {
    /// Validates every field, the field's too (named `field.k`, ...). The channel is checked
    /// against the PST by [`apply_to_ply`].
    pub fn check(&self) -> std::result::Result<(), ConfigError> {
        self.field.check().map_err(|e| e.within("field"))?;
        require(self.chunk >= 1, "chunk", self.chunk, ">= 1")
    }
}

impl Default for ApplyConfig {
    fn default() -> Self {
        ApplyConfig {
            field: FieldConfig::default(),
            channel: "rgb".into(),
            chunk: 1 << 20,
            format: PlyFormat::BinaryLittleEndian,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct ApplyReport {
    pub vertices: u64,
    pub faces: u64,
    pub samples: usize,
    pub k: usize,
}

/// A channel value in [0, 1] to an 8-bit colour component.
#[inline]
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Writes `input` (any PLY mesh or point cloud) to `output` with per-vertex colours from the
/// PST's `cfg.channel`.
pub fn apply_to_ply(
    pst: &Pst,
    input: &Path,
    output: &Path,
    cfg: &ApplyConfig,
    progress: &dyn Progress,
) -> Result<ApplyReport> {
    cfg.check()?;
    if same_file(input, output) {
        return Err(PstError::Parameter(format!(
            "output {} is the input: refusing to write over it",
            output.display()
        )));
    }
    let (offset, width) = pst
        .channel(&cfg.channel)
        .ok_or_else(|| PstError::Parameter(format!("the PST has no channel {}", cfg.channel)))?;
    if width != 3 && width != 1 {
        return Err(PstError::Parameter(format!(
            "channel {} has {width} values per sample: colours need 3 (or 1 for grey)",
            cfg.channel
        )));
    }
    let samples = pst.all_samples()?;
    let field = Field::new(&samples, cfg.field);
    let w = samples.width;

    let mut reader = PlyReader::open(input)?;
    let (nv, nf) = (reader.vertex_count(), reader.face_count());
    let mut layout = PlyLayout::new(cfg.format, nv, nf);
    layout.normals = reader.has_normals();
    layout.colors = true;
    layout.comments.push(format!(
        "fresco pst apply: channel {} from {} samples, k = {}",
        cfg.channel,
        samples.len(),
        cfg.field.k
    ));
    let mut writer = PlyWriter::create(output, layout)?;
    progress.begin("colouring vertices", nv);
    let mut raw: Vec<PlyVertex> = Vec::with_capacity(cfg.chunk.min(1 << 22));
    let mut pts: Vec<[f32; 3]> = Vec::new();
    let mut vals: Vec<f32> = Vec::new();
    loop {
        let got = reader.read_vertices(&mut raw, cfg.chunk.max(1))?;
        if got == 0 {
            break;
        }
        pts.clear();
        pts.extend(raw.iter().map(|v| {
            [
                v.position.x as f32,
                v.position.y as f32,
                v.position.z as f32,
            ]
        }));
        vals.resize(pts.len() * w, 0.0);
        field.eval_many(&pts, &mut vals);
        for (i, v) in raw.iter_mut().enumerate() {
            let c = &vals[i * w + offset..i * w + offset + width];
            v.color = Some(if width == 3 {
                [to_u8(c[0]), to_u8(c[1]), to_u8(c[2])]
            } else {
                [to_u8(c[0]); 3]
            });
            v.uv = None;
            writer.write_vertex(v)?;
        }
        progress.advance(got as u64);
    }
    progress.end();
    progress.begin("copying faces", nf);
    let mut face = PlyFace::default();
    let mut out_face = PlyFace::default();
    let mut count = 0u64;
    while reader.next_face(&mut face)? {
        out_face.indices.clear();
        out_face.indices.extend_from_slice(&face.indices);
        writer.write_face(&out_face)?;
        count += 1;
        if count.is_multiple_of(1 << 20) {
            progress.advance(1 << 20);
        }
    }
    progress.end();
    reader.finish()?;
    writer.finish()?;
    Ok(ApplyReport {
        vertices: nv,
        faces: nf,
        samples: samples.len(),
        k: cfg.field.k,
    })
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}
