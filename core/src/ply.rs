//! The one PLY reader and writer: ascii, binary_little_endian and binary_big_endian 1.0.
//!
//! - [`read_mesh`] / [`write_mesh`]: a whole [`Mesh`] (or a point cloud: a file without a
//!   face element), written atomically (temporary name in the same folder, then rename).
//! - [`PlyReader`]: streams a file of any size: the header, then vertices ([`PlyVertex`]) and
//!   faces ([`PlyFace`], or fan-triangulated through [`PlyReader::triangles`]) through a
//!   bounded buffer; memory does not depend on the file's size.
//! - [`PlyWriter`]: writes a header with given counts, then accepts vertices and faces one by
//!   one, and checks the counts at [`PlyWriter::finish`].
//! - [`read_header`]: the header alone.
//!
//! Properties understood (others are read past): vertex `x y z` (required), `nx ny nz`,
//! `red green blue` (uchar 0..255, ushort 0..65535 or float 0..1), per-vertex texture
//! coordinates `s t` / `u v` / `texture_u texture_v` / `texture_s texture_t`; face
//! `vertex_indices` or `vertex_index` (a list, polygons are fan-triangulated), `texcoord` (a
//! list of 2 floats per corner, as MeshLab writes), `texnumber` (texture index) and `group`
//! (fresco's face label). Texture coordinates in PLY files are v-up (OpenGL, MeshLab); they
//! are flipped to fresco's v-down on reading and back on writing, which rounds `v` to the
//! nearest f32 of `1 - v` (exact for v in [0.5, 1]).
//!
//! Errors are [`FormatError`]s naming the file and the line (ascii) or byte offset (binary)
//! of the element that is wrong, and what was expected there.

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};

use crate::FormatError;
use crate::mesh::{Mesh, Rgb8, Uv};

/// How the data after the header is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PlyFormat {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

impl PlyFormat {
    fn name(self) -> &'static str {
        match self {
            PlyFormat::Ascii => "ascii",
            PlyFormat::BinaryLittleEndian => "binary_little_endian",
            PlyFormat::BinaryBigEndian => "binary_big_endian",
        }
    }
}

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarType {
    /// The type named `name`, with the aliases of the PLY specification (char/int8, ...).
    pub fn from_name(name: &str) -> Option<ScalarType> {
        Some(match name {
            "char" | "int8" => ScalarType::I8,
            "uchar" | "uint8" => ScalarType::U8,
            "short" | "int16" => ScalarType::I16,
            "ushort" | "uint16" => ScalarType::U16,
            "int" | "int32" => ScalarType::I32,
            "uint" | "uint32" => ScalarType::U32,
            "float" | "float32" => ScalarType::F32,
            "double" | "float64" => ScalarType::F64,
            _ => return None,
        })
    }

    /// The classic name, as written in headers.
    pub fn name(self) -> &'static str {
        match self {
            ScalarType::I8 => "char",
            ScalarType::U8 => "uchar",
            ScalarType::I16 => "short",
            ScalarType::U16 => "ushort",
            ScalarType::I32 => "int",
            ScalarType::U32 => "uint",
            ScalarType::F32 => "float",
            ScalarType::F64 => "double",
        }
    }

    /// Size in bytes in binary files.
    pub fn size(self) -> usize {
        match self {
            ScalarType::I8 | ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }

    pub fn is_integer(self) -> bool {
        !matches!(self, ScalarType::F32 | ScalarType::F64)
    }

    /// The range of an integer type, as f64 (exact for every PLY integer type).
    fn integer_range(self) -> (f64, f64) {
        match self {
            ScalarType::I8 => (i8::MIN as f64, i8::MAX as f64),
            ScalarType::U8 => (0.0, u8::MAX as f64),
            ScalarType::I16 => (i16::MIN as f64, i16::MAX as f64),
            ScalarType::U16 => (0.0, u16::MAX as f64),
            ScalarType::I32 => (i32::MIN as f64, i32::MAX as f64),
            ScalarType::U32 => (0.0, u32::MAX as f64),
            ScalarType::F32 | ScalarType::F64 => (f64::NEG_INFINITY, f64::INFINITY),
        }
    }
}

/// A property's type: one scalar, or a list (a count, then that many items).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PropertyKind {
    Scalar(ScalarType),
    List { count: ScalarType, item: ScalarType },
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PropertyDef {
    pub name: String,
    pub kind: PropertyKind,
}

/// An element declared in the header (`element vertex 8` and its properties).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ElementDef {
    pub name: String,
    pub count: u64,
    pub properties: Vec<PropertyDef>,
    /// Header line of the `element` declaration (1-based), for error messages.
    pub line: usize,
}

impl ElementDef {
    /// Bytes per item in a binary file when every property is a scalar.
    pub fn fixed_size(&self) -> Option<usize> {
        self.properties
            .iter()
            .map(|p| match p.kind {
                PropertyKind::Scalar(t) => Some(t.size()),
                PropertyKind::List { .. } => None,
            })
            .sum()
    }

    fn property(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p.name == name)
    }
}

/// A parsed PLY header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlyHeader {
    pub format: PlyFormat,
    pub elements: Vec<ElementDef>,
    pub comments: Vec<String>,
    pub obj_info: Vec<String>,
    /// Bytes from the start of the file to the first data byte.
    pub data_offset: u64,
    /// Number of header lines, `ply` to `end_header` inclusive.
    pub lines: usize,
}

impl PlyHeader {
    pub fn element(&self, name: &str) -> Option<&ElementDef> {
        self.elements.iter().find(|e| e.name == name)
    }

    fn element_index(&self, name: &str) -> Option<usize> {
        self.elements.iter().position(|e| e.name == name)
    }
}

/// One vertex as stored in the file. Coordinates are passed through as read: the streaming
/// reader does not reject NaN or infinite values (the caller decides); [`read_mesh`] does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlyVertex {
    pub position: Point3<f64>,
    pub normal: Option<Vector3<f64>>,
    pub color: Option<Rgb8>,
    /// Per-vertex texture coordinate, already flipped to v-down.
    pub uv: Option<Uv>,
}

impl PlyVertex {
    pub fn new(position: Point3<f64>) -> PlyVertex {
        PlyVertex {
            position,
            normal: None,
            color: None,
            uv: None,
        }
    }
}

/// One face (a polygon) as stored in the file. Reused between calls to avoid allocation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyFace {
    /// Vertex indices, checked to be in range.
    pub indices: Vec<u32>,
    /// Per-corner texture coordinates (v-down), empty when the file has none.
    pub texcoords: Vec<Uv>,
    pub texture: Option<u32>,
    pub group: Option<u32>,
}

/// Where an element sits in the file, for messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    Line(usize),
    Byte(u64),
}

fn located(path: &Path, at: Location, message: impl Into<String>) -> FormatError {
    match at {
        Location::Line(line) => FormatError::text(path, line, message),
        Location::Byte(offset) => FormatError::binary(path, offset, message),
    }
}

// ---------------------------------------------------------------------------------------
// Buffered byte source: a window over the file that never grows past the longest line.

const BUFFER_BYTES: usize = 1 << 20;
/// Longest accepted ascii line (a header line or one element): beyond it, the file is not
/// a sensible PLY file and reading on would only consume memory.
const MAX_LINE_BYTES: usize = 64 << 20;
/// Longest accepted list (items), to bound memory on corrupt counts.
const MAX_LIST_ITEMS: u64 = 1 << 24;

struct Source<R> {
    inner: R,
    buf: Vec<u8>,
    pos: usize,
    end: usize,
    /// File offset of `buf[0]`.
    base: u64,
    eof: bool,
}

impl<R: Read> Source<R> {
    fn new(inner: R) -> Self {
        Source {
            inner,
            buf: vec![0; BUFFER_BYTES],
            pos: 0,
            end: 0,
            base: 0,
            eof: false,
        }
    }

    /// File offset of the next unread byte.
    fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }

    fn available(&self) -> &[u8] {
        &self.buf[self.pos..self.end]
    }

    /// Reads more bytes after the unread ones; returns how many were added.
    fn refill(&mut self, want_total: usize) -> io::Result<usize> {
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.end, 0);
            self.base += self.pos as u64;
            self.end -= self.pos;
            self.pos = 0;
        }
        if self.buf.len() < want_total {
            self.buf.resize(want_total, 0);
        }
        if self.end == self.buf.len() {
            // Full buffer: grow (only on long lines, bounded by MAX_LINE_BYTES by callers).
            let len = self.buf.len() * 2;
            self.buf.resize(len, 0);
        }
        loop {
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    return Ok(0);
                }
                Ok(n) => {
                    self.end += n;
                    return Ok(n);
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            }
        }
    }

    /// Makes `n` bytes available at `pos`; false if the file ends first. The buffer grows
    /// (doubling) only as the bytes arrive, so a corrupt count asking for more than the file
    /// holds costs at most twice the rest of the file, not `n`.
    #[inline]
    fn ensure(&mut self, n: usize) -> io::Result<bool> {
        while self.end - self.pos < n {
            if self.eof {
                return Ok(false);
            }
            self.refill(BUFFER_BYTES)?;
        }
        Ok(true)
    }

    #[inline]
    fn consume(&mut self, n: usize) {
        self.pos += n;
    }

    /// The next line without its `\n` (and `\r`), or `None` at the end of the file.
    fn read_line(&mut self) -> io::Result<Option<LineSpan>> {
        let mut searched = 0;
        loop {
            if let Some(i) = self.buf[self.pos + searched..self.end]
                .iter()
                .position(|&b| b == b'\n')
            {
                let start = self.pos;
                let mut stop = self.pos + searched + i;
                self.pos = stop + 1;
                if stop > start && self.buf[stop - 1] == b'\r' {
                    stop -= 1;
                }
                return Ok(Some(LineSpan { start, stop }));
            }
            searched = self.end - self.pos;
            if self.eof {
                if searched == 0 {
                    return Ok(None);
                }
                let start = self.pos;
                let mut stop = self.end;
                self.pos = self.end;
                if self.buf[stop - 1] == b'\r' {
                    stop -= 1;
                }
                return Ok(Some(LineSpan { start, stop }));
            }
            if searched > MAX_LINE_BYTES {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("line longer than {MAX_LINE_BYTES} bytes"),
                ));
            }
            let pos_before = self.pos;
            self.refill(BUFFER_BYTES)?;
            // `refill` moved the unread bytes to the front; `searched` stays relative.
            debug_assert!(self.pos == 0 || self.pos == pos_before);
        }
    }

    fn line(&self, span: LineSpan) -> &[u8] {
        &self.buf[span.start..span.stop]
    }
}

/// A line's byte range in the source buffer, valid until the next read.
#[derive(Clone, Copy)]
struct LineSpan {
    start: usize,
    stop: usize,
}

// ---------------------------------------------------------------------------------------
// Header.

/// Reads only the header of `path`.
pub fn read_header(path: impl AsRef<Path>) -> Result<PlyHeader, FormatError> {
    let path = path.as_ref();
    let file = File::open(path).map_err(|e| FormatError::io(path, e))?;
    let mut src = Source::new(file);
    parse_header(&mut src, path)
}

fn parse_header<R: Read>(src: &mut Source<R>, path: &Path) -> Result<PlyHeader, FormatError> {
    let mut format = None;
    let mut elements: Vec<ElementDef> = Vec::new();
    let mut comments = Vec::new();
    let mut obj_info = Vec::new();
    let mut line_no = 0usize;
    loop {
        let span = src.read_line().map_err(|e| FormatError::io(path, e))?;
        line_no += 1;
        let Some(span) = span else {
            return Err(FormatError::text(
                path,
                line_no,
                if line_no == 1 {
                    "empty file: expected a PLY header starting with 'ply'".to_string()
                } else {
                    "file ends inside the header: expected 'end_header'".to_string()
                },
            ));
        };
        let bytes = src.line(span);
        let err = |msg: String| FormatError::text(path, line_no, msg);
        let Ok(text) = std::str::from_utf8(bytes) else {
            return Err(err(if line_no == 1 {
                "not a PLY file: expected 'ply' on the first line".into()
            } else {
                "header line is not text (missing 'end_header'?)".into()
            }));
        };
        if line_no == 1 {
            if text.trim_end() != "ply" {
                return Err(err(format!(
                    "not a PLY file: expected 'ply' on the first line, found '{}'",
                    truncate(text)
                )));
            }
            continue;
        }
        let mut words = text.split_ascii_whitespace();
        let Some(keyword) = words.next() else {
            continue; // tolerate blank header lines
        };
        match keyword {
            "format" => {
                if format.is_some() {
                    return Err(err("second 'format' line".into()));
                }
                let f = match words.next() {
                    Some("ascii") => PlyFormat::Ascii,
                    Some("binary_little_endian") => PlyFormat::BinaryLittleEndian,
                    Some("binary_big_endian") => PlyFormat::BinaryBigEndian,
                    other => {
                        return Err(err(format!(
                            "unknown format '{}': expected ascii, binary_little_endian or binary_big_endian",
                            other.unwrap_or("")
                        )));
                    }
                };
                match words.next() {
                    Some("1.0") | Some("1") => {}
                    other => {
                        return Err(err(format!(
                            "unsupported PLY version '{}': expected 1.0",
                            other.unwrap_or("")
                        )));
                    }
                }
                format = Some(f);
            }
            "comment" => comments.push(rest_after_keyword(text, "comment")),
            "obj_info" => obj_info.push(rest_after_keyword(text, "obj_info")),
            "element" => {
                let (Some(name), Some(count), None) = (words.next(), words.next(), words.next())
                else {
                    return Err(err("expected 'element <name> <count>'".into()));
                };
                let count: u64 = count.parse().map_err(|_| {
                    err(format!(
                        "element '{name}': count '{count}' is not a non-negative integer"
                    ))
                })?;
                if elements.iter().any(|e| e.name == name) {
                    return Err(err(format!("element '{name}' declared twice")));
                }
                elements.push(ElementDef {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                    line: line_no,
                });
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(err("'property' before any 'element'".into()));
                };
                let ty = |name: Option<&str>| -> Result<ScalarType, FormatError> {
                    let name = name.unwrap_or("");
                    ScalarType::from_name(name)
                        .ok_or_else(|| err(format!("unknown property type '{name}'")))
                };
                let first = words.next();
                let kind = if first == Some("list") {
                    let count = ty(words.next())?;
                    let item = ty(words.next())?;
                    if !count.is_integer() {
                        return Err(err(format!(
                            "list count type '{}' must be an integer type",
                            count.name()
                        )));
                    }
                    PropertyKind::List { count, item }
                } else {
                    PropertyKind::Scalar(ty(first)?)
                };
                let (Some(name), None) = (words.next(), words.next()) else {
                    return Err(err(
                        "expected 'property <type> <name>' or 'property list <count type> <item type> <name>'"
                            .into(),
                    ));
                };
                if element.property(name).is_some() {
                    return Err(err(format!(
                        "property '{name}' declared twice in element '{}'",
                        element.name
                    )));
                }
                element.properties.push(PropertyDef {
                    name: name.to_string(),
                    kind,
                });
            }
            "end_header" => break,
            other => {
                return Err(err(format!(
                    "unknown header keyword '{}' (expected format, element, property, comment, obj_info or end_header)",
                    truncate(other)
                )));
            }
        }
    }
    let Some(format) = format else {
        return Err(FormatError::text(path, 2, "header has no 'format' line"));
    };
    Ok(PlyHeader {
        format,
        elements,
        comments,
        obj_info,
        data_offset: src.offset(),
        lines: line_no,
    })
}

fn rest_after_keyword(line: &str, keyword: &str) -> String {
    let rest = line.trim_start().strip_prefix(keyword).unwrap_or("");
    rest.strip_prefix(' ')
        .unwrap_or(rest)
        .trim_end()
        .to_string()
}

fn truncate(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if out.len() < s.len() {
        out.push('…');
    }
    out
}

// ---------------------------------------------------------------------------------------
// Reading plans: what each property of the vertex and face elements feeds.

/// Destinations of vertex properties.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VSlot {
    X,
    Y,
    Z,
    Nx,
    Ny,
    Nz,
    R,
    G,
    B,
    U,
    V,
}
const V_SLOTS: usize = 11;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FSlot {
    Indices,
    Texcoords,
    Texture,
    Group,
}

/// A wanted scalar in a fixed-size record: byte offset, type, destination.
type FieldAt = (usize, ScalarType, VSlot);

#[derive(Clone, Debug)]
struct VertexPlan {
    /// For each property, the slot it fills.
    slots: Vec<Option<VSlot>>,
    normals: bool,
    color: Option<ScalarType>,
    uvs: bool,
    /// Binary fast path: record size and (offset, type, slot) of the wanted scalars.
    fixed: Option<(usize, Vec<FieldAt>)>,
}

#[derive(Clone, Debug)]
struct FacePlan {
    slots: Vec<Option<FSlot>>,
    texcoords: bool,
    texture: bool,
    group: bool,
    /// Binary fast path for triangles when the index list is the only list: bytes of the
    /// scalars before it, its count and item types, bytes of the scalars after it.
    fixed_list: Option<(usize, ScalarType, ScalarType, usize)>,
}

fn vertex_plan(path: &Path, e: &ElementDef) -> Result<VertexPlan, FormatError> {
    let header_err = |msg: String| FormatError::text(path, e.line, msg);
    let scalar = |name: &str| -> Result<Option<(usize, ScalarType)>, FormatError> {
        match e.property(name) {
            None => Ok(None),
            Some(i) => match e.properties[i].kind {
                PropertyKind::Scalar(t) => Ok(Some((i, t))),
                PropertyKind::List { .. } => Err(header_err(format!(
                    "element 'vertex': property '{name}' must be a scalar, not a list"
                ))),
            },
        }
    };
    let mut slots = vec![None; e.properties.len()];
    for (name, slot) in [("x", VSlot::X), ("y", VSlot::Y), ("z", VSlot::Z)] {
        match scalar(name)? {
            Some((i, _)) => slots[i] = Some(slot),
            None => {
                return Err(header_err(format!(
                    "element 'vertex' has no property '{name}': expected x, y and z"
                )));
            }
        }
    }
    let triple = |names: [&str; 3]| -> Result<Option<[(usize, ScalarType); 3]>, FormatError> {
        let a = scalar(names[0])?;
        let b = scalar(names[1])?;
        let c = scalar(names[2])?;
        Ok(match (a, b, c) {
            (Some(a), Some(b), Some(c)) => Some([a, b, c]),
            _ => None,
        })
    };
    let normals = triple(["nx", "ny", "nz"])?;
    if let Some(n) = normals {
        for ((i, _), slot) in n.iter().zip([VSlot::Nx, VSlot::Ny, VSlot::Nz]) {
            slots[*i] = Some(slot);
        }
    }
    let colors = triple(["red", "green", "blue"])?;
    if let Some(c) = colors {
        for ((i, _), slot) in c.iter().zip([VSlot::R, VSlot::G, VSlot::B]) {
            slots[*i] = Some(slot);
        }
    }
    let mut uvs = false;
    for [un, vn] in [
        ["s", "t"],
        ["u", "v"],
        ["texture_u", "texture_v"],
        ["texture_s", "texture_t"],
    ] {
        if let (Some((iu, _)), Some((iv, _))) = (scalar(un)?, scalar(vn)?) {
            slots[iu] = Some(VSlot::U);
            slots[iv] = Some(VSlot::V);
            uvs = true;
            break;
        }
    }
    let fixed = e.fixed_size().map(|size| {
        let mut offset = 0;
        let mut wanted = Vec::new();
        for (p, slot) in e.properties.iter().zip(&slots) {
            let PropertyKind::Scalar(t) = p.kind else {
                unreachable!("fixed_size() is Some only for all-scalar elements")
            };
            if let Some(s) = slot {
                wanted.push((offset, t, *s));
            }
            offset += t.size();
        }
        (size, wanted)
    });
    Ok(VertexPlan {
        slots,
        normals: normals.is_some(),
        color: colors.map(|c| c[0].1),
        uvs,
        fixed,
    })
}

fn face_plan(path: &Path, e: &ElementDef) -> Result<FacePlan, FormatError> {
    let header_err = |msg: String| FormatError::text(path, e.line, msg);
    let mut slots = vec![None; e.properties.len()];
    let index_prop = e
        .property("vertex_indices")
        .or_else(|| e.property("vertex_index"));
    match index_prop.map(|i| (i, e.properties[i].kind)) {
        Some((i, PropertyKind::List { item, .. })) if item.is_integer() => {
            slots[i] = Some(FSlot::Indices)
        }
        Some(_) => {
            return Err(header_err(
                "element 'face': vertex_indices must be a list of an integer type".into(),
            ));
        }
        None => {
            return Err(header_err(
                "element 'face' has no list property 'vertex_indices' (or 'vertex_index')".into(),
            ));
        }
    }
    let mut texcoords = false;
    if let Some(i) = e.property("texcoord")
        && let PropertyKind::List { .. } = e.properties[i].kind
    {
        slots[i] = Some(FSlot::Texcoords);
        texcoords = true;
    }
    let mut scalar_slot = |name: &str, slot: FSlot| {
        if let Some(i) = e.property(name)
            && let PropertyKind::Scalar(t) = e.properties[i].kind
            && t.is_integer()
        {
            slots[i] = Some(slot);
            return true;
        }
        false
    };
    let texture = scalar_slot("texnumber", FSlot::Texture);
    let group = scalar_slot("group", FSlot::Group);
    let mut fixed_list = None;
    let lists = e
        .properties
        .iter()
        .filter(|p| matches!(p.kind, PropertyKind::List { .. }))
        .count();
    if lists == 1 {
        let i = slots
            .iter()
            .position(|s| *s == Some(FSlot::Indices))
            .unwrap_or(0);
        let bytes = |props: &[PropertyDef]| -> usize {
            props
                .iter()
                .map(|p| match p.kind {
                    PropertyKind::Scalar(t) => t.size(),
                    PropertyKind::List { .. } => 0,
                })
                .sum()
        };
        if let PropertyKind::List { count, item } = e.properties[i].kind {
            fixed_list = Some((
                bytes(&e.properties[..i]),
                count,
                item,
                bytes(&e.properties[i + 1..]),
            ));
        }
    }
    Ok(FacePlan {
        slots,
        texcoords,
        texture,
        group,
        fixed_list,
    })
}

/// The scalar of type `ty` at the start of `b` (big-endian when `BIG`), as f64: the one
/// binary decoder, shared by the streaming reader and memory-mapped readers (fresco-pst).
#[inline(always)]
pub fn decode_scalar<const BIG: bool>(b: &[u8], ty: ScalarType) -> f64 {
    macro_rules! get {
        ($t:ty, $n:expr) => {{
            let mut a = [0u8; $n];
            a.copy_from_slice(&b[..$n]);
            (if BIG {
                <$t>::from_be_bytes(a)
            } else {
                <$t>::from_le_bytes(a)
            }) as f64
        }};
    }
    match ty {
        ScalarType::I8 => b[0] as i8 as f64,
        ScalarType::U8 => b[0] as f64,
        ScalarType::I16 => get!(i16, 2),
        ScalarType::U16 => get!(u16, 2),
        ScalarType::I32 => get!(i32, 4),
        ScalarType::U32 => get!(u32, 4),
        ScalarType::F32 => get!(f32, 4),
        ScalarType::F64 => get!(f64, 8),
    }
}

fn color_channel(value: f64, ty: ScalarType) -> u8 {
    let scaled = match ty {
        ScalarType::F32 | ScalarType::F64 => value * 255.0,
        ScalarType::U16 => value / 257.0,
        _ => value,
    };
    // NaN becomes 0 through the saturating cast.
    scaled.round().clamp(0.0, 255.0) as u8
}

fn vertex_from_slots(vals: &[f64; V_SLOTS], plan: &VertexPlan) -> PlyVertex {
    PlyVertex {
        position: Point3::new(vals[0], vals[1], vals[2]),
        normal: plan
            .normals
            .then(|| Vector3::new(vals[3], vals[4], vals[5])),
        color: plan.color.map(|t| {
            [
                color_channel(vals[6], t),
                color_channel(vals[7], t),
                color_channel(vals[8], t),
            ]
        }),
        uv: plan.uvs.then(|| [vals[9] as f32, (1.0 - vals[10]) as f32]),
    }
}

// ---------------------------------------------------------------------------------------
// Streaming reader.

/// Streams a PLY file: header first, then vertices and faces in file order, through a
/// buffer of about 1 MiB. Elements other than `vertex` and `face` are read past.
///
/// Vertex values are passed through raw: NaN and infinite coordinates are not rejected here
/// (use [`read_mesh`] for a checked mesh). Face indices are checked against the vertex count.
pub struct PlyReader<R: Read = File> {
    path: PathBuf,
    header: PlyHeader,
    src: Source<R>,
    /// Ascii: number of the last line read.
    line: usize,
    /// The element being read and how many of its items are done.
    element: usize,
    done: u64,
    vertex_element: Option<usize>,
    face_element: Option<usize>,
    vertex_plan: Option<VertexPlan>,
    face_plan: Option<FacePlan>,
    /// Where the last returned item started.
    last: Location,
    scratch_face: PlyFace,
}

impl PlyReader<File> {
    /// Opens `path` and reads its header.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, FormatError> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|e| FormatError::io(path, e))?;
        PlyReader::from_reader(file, path)
    }
}

impl<R: Read> PlyReader<R> {
    /// Reads the header from `reader`; `path` names the source in error messages.
    pub fn from_reader(reader: R, path: impl Into<PathBuf>) -> Result<Self, FormatError> {
        let path = path.into();
        let mut src = Source::new(reader);
        let header = parse_header(&mut src, &path)?;
        let vertex_element = header.element_index("vertex");
        let face_element = header.element_index("face");
        let vertex_plan = vertex_element
            .map(|i| vertex_plan(&path, &header.elements[i]))
            .transpose()?;
        let face_plan = match face_element {
            Some(i)
                if header.elements[i].count > 0 || !header.elements[i].properties.is_empty() =>
            {
                Some(face_plan(&path, &header.elements[i])?)
            }
            _ => None,
        };
        if face_plan.is_some() && vertex_element.is_none() {
            return Err(FormatError::text(
                &path,
                header.elements[face_element.unwrap_or(0)].line,
                "element 'face' without an element 'vertex'",
            ));
        }
        let line = header.lines;
        let last = Location::Byte(header.data_offset);
        Ok(PlyReader {
            path,
            header,
            src,
            line,
            element: 0,
            done: 0,
            vertex_element,
            face_element,
            vertex_plan,
            face_plan,
            last,
            scratch_face: PlyFace::default(),
        })
    }

    pub fn header(&self) -> &PlyHeader {
        &self.header
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Vertices declared in the header (0 without a vertex element).
    pub fn vertex_count(&self) -> u64 {
        self.vertex_element
            .map_or(0, |i| self.header.elements[i].count)
    }

    /// Faces (polygons) declared in the header (0 for a point cloud).
    pub fn face_count(&self) -> u64 {
        self.face_element
            .map_or(0, |i| self.header.elements[i].count)
    }

    pub fn has_normals(&self) -> bool {
        self.vertex_plan.as_ref().is_some_and(|p| p.normals)
    }

    pub fn has_colors(&self) -> bool {
        self.vertex_plan.as_ref().is_some_and(|p| p.color.is_some())
    }

    pub fn has_vertex_uvs(&self) -> bool {
        self.vertex_plan.as_ref().is_some_and(|p| p.uvs)
    }

    pub fn has_face_texcoords(&self) -> bool {
        self.face_plan.as_ref().is_some_and(|p| p.texcoords)
    }

    pub fn has_face_textures(&self) -> bool {
        self.face_plan.as_ref().is_some_and(|p| p.texture)
    }

    pub fn has_face_groups(&self) -> bool {
        self.face_plan.as_ref().is_some_and(|p| p.group)
    }

    /// Where the last vertex or face returned starts: a line (ascii) or a byte offset.
    pub fn last_location(&self) -> Location {
        self.last
    }

    fn is_ascii(&self) -> bool {
        self.header.format == PlyFormat::Ascii
    }

    fn here(&self) -> Location {
        if self.is_ascii() {
            Location::Line(self.line + 1)
        } else {
            Location::Byte(self.src.offset())
        }
    }

    fn io_err(&self, e: io::Error) -> FormatError {
        FormatError::io(&self.path, e)
    }

    /// Moves past exhausted elements.
    fn settle(&mut self) {
        while self.element < self.header.elements.len()
            && self.done >= self.header.elements[self.element].count
        {
            self.element += 1;
            self.done = 0;
        }
    }

    /// Positions the reader at the next item of element `target`; false if that element is
    /// behind us or exhausted.
    fn seek_element(&mut self, target: usize) -> Result<bool, FormatError> {
        self.settle();
        while self.element < target {
            if !self.is_ascii() && self.header.elements[self.element].fixed_size() == Some(0) {
                // Items without properties take no bytes: skipping them one by one would
                // loop `count` times (2^64 for a corrupt header) without reading anything.
                self.done = self.header.elements[self.element].count;
                self.settle();
                continue;
            }
            self.skip_item()?;
            self.done += 1;
            self.settle();
        }
        Ok(self.element == target)
    }

    fn truncated(&self, what: &str) -> FormatError {
        let e = &self.header.elements[self.element];
        let msg = format!(
            "file ends inside the data: expected {} {} of {} ({})",
            e.name, self.done, e.count, what
        );
        located(&self.path, self.here(), msg)
    }

    /// Reads past one item of the current element.
    fn skip_item(&mut self) -> Result<(), FormatError> {
        if self.is_ascii() {
            self.next_data_line()?;
            return Ok(());
        }
        let e = &self.header.elements[self.element];
        if let Some(size) = e.fixed_size() {
            if !self.src.ensure(size).map_err(|e| self.io_err(e))? {
                return Err(self.truncated(&format!("{size} bytes each")));
            }
            self.src.consume(size);
            return Ok(());
        }
        let kinds: Vec<PropertyKind> = e.properties.iter().map(|p| p.kind).collect();
        let big = self.header.format == PlyFormat::BinaryBigEndian;
        for kind in kinds {
            match kind {
                PropertyKind::Scalar(t) => self.binary_bytes(t.size())?,
                PropertyKind::List { count, item } => {
                    let n = self.binary_count(count, big)?;
                    self.binary_bytes(n as usize * item.size())?;
                }
            }
        }
        Ok(())
    }

    fn binary_bytes(&mut self, n: usize) -> Result<(), FormatError> {
        if !self.src.ensure(n).map_err(|e| self.io_err(e))? {
            return Err(self.truncated(&format!("{n} more bytes")));
        }
        self.src.consume(n);
        Ok(())
    }

    fn binary_value(&mut self, t: ScalarType, big: bool) -> Result<f64, FormatError> {
        if !self.src.ensure(t.size()).map_err(|e| self.io_err(e))? {
            return Err(self.truncated(&format!("a {}", t.name())));
        }
        let b = self.src.available();
        let v = if big {
            decode_scalar::<true>(b, t)
        } else {
            decode_scalar::<false>(b, t)
        };
        self.src.consume(t.size());
        Ok(v)
    }

    fn binary_count(&mut self, t: ScalarType, big: bool) -> Result<u64, FormatError> {
        let at = self.src.offset();
        let v = self.binary_value(t, big)?;
        if v < 0.0 || v > MAX_LIST_ITEMS as f64 {
            return Err(self.binary_count_error(at, v));
        }
        Ok(v as u64)
    }

    fn binary_count_error(&self, at: u64, v: f64) -> FormatError {
        FormatError::binary(
            &self.path,
            at,
            format!(
                "{} {}: list length {v} is negative or larger than {MAX_LIST_ITEMS}",
                self.header.elements[self.element].name, self.done
            ),
        )
    }

    /// The next non-blank ascii line; error at the end of the file.
    fn next_data_line(&mut self) -> Result<LineSpan, FormatError> {
        loop {
            let span = self.src.read_line().map_err(|e| self.io_err(e))?;
            self.line += 1;
            let Some(span) = span else {
                return Err(self.truncated("one per line"));
            };
            if !self.src.line(span).iter().all(u8::is_ascii_whitespace) {
                return Ok(span);
            }
        }
    }

    /// Reads the next vertex; `None` once all vertices are read (or there is no vertex
    /// element). Skips over elements declared before `vertex`.
    pub fn next_vertex(&mut self) -> Result<Option<PlyVertex>, FormatError> {
        let Some(ve) = self.vertex_element else {
            return Ok(None);
        };
        if !self.seek_element(ve)? {
            return Ok(None);
        }
        let mut vals = [0.0f64; V_SLOTS];
        if self.is_ascii() {
            self.read_ascii_vertex(&mut vals)?;
        } else {
            self.read_binary_vertex(&mut vals)?;
        }
        self.done += 1;
        let plan = self
            .vertex_plan
            .as_ref()
            .expect("vertex element has a plan");
        Ok(Some(vertex_from_slots(&vals, plan)))
    }

    /// Reads up to `max` vertices into `out` (cleared first); returns how many. Zero means
    /// all vertices are read. The fastest way through a binary file.
    pub fn read_vertices(
        &mut self,
        out: &mut Vec<PlyVertex>,
        max: usize,
    ) -> Result<usize, FormatError> {
        out.clear();
        let Some(ve) = self.vertex_element else {
            return Ok(0);
        };
        if !self.seek_element(ve)? {
            return Ok(0);
        }
        let remaining = (self.header.elements[ve].count - self.done).min(max as u64) as usize;
        let fixed = self
            .vertex_plan
            .as_ref()
            .and_then(|p| p.fixed.as_ref())
            .is_some();
        if self.is_ascii() || !fixed {
            while out.len() < remaining {
                match self.next_vertex()? {
                    Some(v) => out.push(v),
                    None => break,
                }
            }
            return Ok(out.len());
        }
        let big = self.header.format == PlyFormat::BinaryBigEndian;
        let plan = self
            .vertex_plan
            .as_ref()
            .expect("vertex element has a plan");
        let (size, wanted) = plan.fixed.as_ref().expect("checked above");
        let size = *size;
        out.reserve(remaining);
        for k in 0..remaining {
            let at = self.src.offset();
            if !self
                .src
                .ensure(size)
                .map_err(|e| FormatError::io(&self.path, e))?
            {
                self.done += k as u64;
                return Err(self.truncated(&format!("{size} bytes each")));
            }
            let rec = &self.src.available()[..size];
            let mut vals = [0.0f64; V_SLOTS];
            if big {
                for &(off, t, slot) in wanted {
                    vals[slot as usize] = decode_scalar::<true>(&rec[off..], t);
                }
            } else {
                for &(off, t, slot) in wanted {
                    vals[slot as usize] = decode_scalar::<false>(&rec[off..], t);
                }
            }
            self.src.consume(size);
            out.push(vertex_from_slots(&vals, plan));
            self.last = Location::Byte(at);
        }
        self.done += remaining as u64;
        Ok(remaining)
    }

    /// Reads up to `max` faces and appends their fan triangulation to `out` (not cleared);
    /// returns how many faces were read, zero once all are. On an error, `out` keeps the
    /// triangles of the faces before the bad one.
    pub fn read_triangles(
        &mut self,
        out: &mut Vec<[u32; 3]>,
        max: usize,
    ) -> Result<usize, FormatError> {
        let (Some(fe), Some(plan)) = (self.face_element, self.face_plan.as_ref()) else {
            return Ok(0);
        };
        let fast = plan.fixed_list;
        if !self.seek_element(fe)? {
            return Ok(0);
        }
        let remaining = (self.header.elements[fe].count - self.done).min(max as u64) as usize;
        let (Some((before, count_t, item_t, after)), false) = (fast, self.is_ascii()) else {
            let mut face = std::mem::take(&mut self.scratch_face);
            let result = (|| {
                for _ in 0..remaining {
                    if !self.next_face(&mut face)? {
                        break;
                    }
                    let n = face.indices.len();
                    if n < 3 {
                        return Err(self.too_few_corners(self.done - 1, n));
                    }
                    let i = &face.indices;
                    out.extend((1..n - 1).map(|k| [i[0], i[k], i[k + 1]]));
                }
                Ok(())
            })();
            self.scratch_face = face;
            result?;
            return Ok(remaining);
        };
        if self.big_endian() {
            self.read_triangles_fixed::<true>(out, remaining, before, count_t, item_t, after)?;
        } else {
            self.read_triangles_fixed::<false>(out, remaining, before, count_t, item_t, after)?;
        }
        Ok(remaining)
    }

    fn big_endian(&self) -> bool {
        self.header.format == PlyFormat::BinaryBigEndian
    }

    fn too_few_corners(&self, face: u64, n: usize) -> FormatError {
        located(
            &self.path,
            self.last,
            format!("face {face}: {n} vertex indices; a face needs at least 3"),
        )
    }

    /// Binary faces whose only list is the index list: one bounds check per face, indices
    /// decoded straight from the buffer.
    fn read_triangles_fixed<const BIG: bool>(
        &mut self,
        out: &mut Vec<[u32; 3]>,
        faces: usize,
        before: usize,
        count_t: ScalarType,
        item_t: ScalarType,
        after: usize,
    ) -> Result<(), FormatError> {
        let nv = self.vertex_count() as f64;
        let head = before + count_t.size();
        let isize = item_t.size();
        for _ in 0..faces {
            let at = self.src.offset();
            self.last = Location::Byte(at);
            if !self
                .src
                .ensure(head)
                .map_err(|e| FormatError::io(&self.path, e))?
            {
                return Err(self.truncated("a face"));
            }
            let n = decode_scalar::<BIG>(&self.src.available()[before..], count_t);
            if !(3.0..=MAX_LIST_ITEMS as f64).contains(&n) {
                if (0.0..3.0).contains(&n) {
                    return Err(self.too_few_corners(self.done, n as usize));
                }
                return Err(self.binary_count_error(at + before as u64, n));
            }
            let n = n as usize;
            let total = head + n * isize + after;
            if !self
                .src
                .ensure(total)
                .map_err(|e| FormatError::io(&self.path, e))?
            {
                return Err(self.truncated(&format!("{n} vertex indices")));
            }
            let rec = &self.src.available()[head..head + n * isize];
            let mut bad = None;
            let mut index = |k: usize| {
                let v = decode_scalar::<BIG>(&rec[k * isize..], item_t);
                if v >= 0.0 && v < nv {
                    v as u32
                } else {
                    bad.get_or_insert(v);
                    0
                }
            };
            let first = index(0);
            let mut prev = index(1);
            for k in 2..n {
                let cur = index(k);
                out.push([first, prev, cur]);
                prev = cur;
            }
            if let Some(v) = bad {
                out.truncate(out.len() - (n - 2));
                return Err(self.index_error(v, Location::Byte(at)));
            }
            self.src.consume(total);
            self.done += 1;
        }
        Ok(())
    }

    fn read_binary_vertex(&mut self, vals: &mut [f64; V_SLOTS]) -> Result<(), FormatError> {
        let big = self.header.format == PlyFormat::BinaryBigEndian;
        self.last = Location::Byte(self.src.offset());
        let plan = self
            .vertex_plan
            .as_ref()
            .expect("vertex element has a plan");
        if let Some((size, wanted)) = &plan.fixed {
            let size = *size;
            if !self.src.ensure(size).map_err(|e| self.io_err(e))? {
                return Err(self.truncated(&format!("{size} bytes each")));
            }
            let rec = &self.src.available()[..size];
            // Monomorphised per byte order: no dispatch but the (predictable) type match.
            if big {
                for &(off, t, slot) in wanted {
                    vals[slot as usize] = decode_scalar::<true>(&rec[off..], t);
                }
            } else {
                for &(off, t, slot) in wanted {
                    vals[slot as usize] = decode_scalar::<false>(&rec[off..], t);
                }
            }
            self.src.consume(size);
            return Ok(());
        }
        // Lists inside the vertex element: walk the properties.
        let ve = self.element;
        for p in 0..self.header.elements[ve].properties.len() {
            let kind = self.header.elements[ve].properties[p].kind;
            let slot = self.vertex_plan.as_ref().and_then(|pl| pl.slots[p]);
            match kind {
                PropertyKind::Scalar(t) => {
                    let v = self.binary_value(t, big)?;
                    if let Some(s) = slot {
                        vals[s as usize] = v;
                    }
                }
                PropertyKind::List { count, item } => {
                    let n = self.binary_count(count, big)?;
                    self.binary_bytes(n as usize * item.size())?;
                }
            }
        }
        Ok(())
    }

    fn read_ascii_vertex(&mut self, vals: &mut [f64; V_SLOTS]) -> Result<(), FormatError> {
        let span = self.next_data_line()?;
        let line_no = self.line;
        self.last = Location::Line(line_no);
        let path = &self.path;
        let e = &self.header.elements[self.element];
        let plan = self
            .vertex_plan
            .as_ref()
            .expect("vertex element has a plan");
        let mut tokens = AsciiTokens::new(self.src.line(span), path, line_no, &e.name, self.done)?;
        for (p, slot) in e.properties.iter().zip(&plan.slots) {
            match p.kind {
                PropertyKind::Scalar(t) => {
                    let v = tokens.value(&p.name, t)?;
                    if let Some(s) = slot {
                        vals[*s as usize] = v;
                    }
                }
                PropertyKind::List { count, item } => {
                    let n = tokens.count(&p.name, count)?;
                    for _ in 0..n {
                        tokens.value(&p.name, item)?;
                    }
                }
            }
        }
        tokens.finish()
    }

    /// Reads the next face into `face`; false once all faces are read (or there is no face
    /// element). Indices are checked against the vertex count.
    pub fn next_face(&mut self, face: &mut PlyFace) -> Result<bool, FormatError> {
        let (Some(fe), Some(_)) = (self.face_element, self.face_plan.as_ref()) else {
            return Ok(false);
        };
        if !self.seek_element(fe)? {
            return Ok(false);
        }
        face.indices.clear();
        face.texcoords.clear();
        face.texture = None;
        face.group = None;
        if self.is_ascii() {
            self.read_ascii_face(face)?;
        } else {
            self.read_binary_face(face)?;
        }
        let nv = self.vertex_count();
        if let Some(&bad) = face.indices.iter().find(|&&i| i as u64 >= nv) {
            return Err(located(
                &self.path,
                self.last,
                format!(
                    "face {}: vertex index {bad} out of range ({nv} vertices)",
                    self.done
                ),
            ));
        }
        if !face.texcoords.is_empty() && face.texcoords.len() != face.indices.len() {
            return Err(located(
                &self.path,
                self.last,
                format!(
                    "face {}: {} texture coordinates for {} corners (texcoord needs 2 values per corner)",
                    self.done,
                    face.texcoords.len(),
                    face.indices.len()
                ),
            ));
        }
        self.done += 1;
        Ok(true)
    }

    fn index_error(&self, v: f64, at: Location) -> FormatError {
        located(
            &self.path,
            at,
            format!(
                "face {}: vertex index {v} out of range ({} vertices)",
                self.done,
                self.vertex_count()
            ),
        )
    }

    fn read_binary_face(&mut self, face: &mut PlyFace) -> Result<(), FormatError> {
        let big = self.header.format == PlyFormat::BinaryBigEndian;
        let at = Location::Byte(self.src.offset());
        self.last = at;
        let fe = self.element;
        let nprops = self.header.elements[fe].properties.len();
        for p in 0..nprops {
            let kind = self.header.elements[fe].properties[p].kind;
            let slot = self.face_plan.as_ref().and_then(|pl| pl.slots[p]);
            match (kind, slot) {
                (PropertyKind::List { count, item }, Some(FSlot::Indices)) => {
                    let n = self.binary_count(count, big)? as usize;
                    let bytes = n * item.size();
                    if !self.src.ensure(bytes).map_err(|e| self.io_err(e))? {
                        return Err(self.truncated(&format!("{n} vertex indices")));
                    }
                    let data = &self.src.available()[..bytes];
                    let mut bad = None;
                    for k in 0..n {
                        let b = &data[k * item.size()..];
                        let v = if big {
                            decode_scalar::<true>(b, item)
                        } else {
                            decode_scalar::<false>(b, item)
                        };
                        if v < 0.0 || v >= u32::MAX as f64 {
                            bad = Some(v);
                            break;
                        }
                        face.indices.push(v as u32);
                    }
                    self.src.consume(bytes);
                    if let Some(v) = bad {
                        return Err(self.index_error(v, at));
                    }
                }
                (PropertyKind::List { count, item }, Some(FSlot::Texcoords)) => {
                    let n = self.binary_count(count, big)?;
                    let mut pair = [0.0f64; 2];
                    for k in 0..n {
                        pair[(k % 2) as usize] = self.binary_value(item, big)?;
                        if k % 2 == 1 {
                            face.texcoords
                                .push([pair[0] as f32, (1.0 - pair[1]) as f32]);
                        }
                    }
                    if n % 2 == 1 {
                        return Err(located(
                            &self.path,
                            at,
                            format!("face {}: texcoord list has an odd length {n}", self.done),
                        ));
                    }
                }
                (PropertyKind::Scalar(t), Some(s @ (FSlot::Texture | FSlot::Group))) => {
                    let v = self.binary_value(t, big)?;
                    if v < 0.0 {
                        let name = if s == FSlot::Texture {
                            "texnumber"
                        } else {
                            "group"
                        };
                        return Err(self.label_error(v, at, name));
                    }
                    let label = v as u32;
                    if s == FSlot::Texture {
                        face.texture = Some(label);
                    } else {
                        face.group = Some(label);
                    }
                }
                (PropertyKind::Scalar(t), _) => self.binary_bytes(t.size())?,
                (PropertyKind::List { count, item }, _) => {
                    let n = self.binary_count(count, big)?;
                    self.binary_bytes(n as usize * item.size())?;
                }
            }
        }
        Ok(())
    }

    fn label_error(&self, v: f64, at: Location, name: &str) -> FormatError {
        located(
            &self.path,
            at,
            format!("face {}: {name} {v} is negative", self.done),
        )
    }

    fn read_ascii_face(&mut self, face: &mut PlyFace) -> Result<(), FormatError> {
        let span = self.next_data_line()?;
        let line_no = self.line;
        let at = Location::Line(line_no);
        self.last = at;
        let path = &self.path;
        let e = &self.header.elements[self.element];
        let plan = self.face_plan.as_ref().expect("face element has a plan");
        let mut tokens = AsciiTokens::new(self.src.line(span), path, line_no, &e.name, self.done)?;
        let mut bad_index = None;
        let mut bad_label = None;
        for (p, slot) in e.properties.iter().zip(&plan.slots) {
            match (p.kind, slot) {
                (PropertyKind::List { count, item }, Some(FSlot::Indices)) => {
                    let n = tokens.count(&p.name, count)?;
                    for _ in 0..n {
                        let v = tokens.value(&p.name, item)?;
                        if v < 0.0 || v >= u32::MAX as f64 {
                            bad_index.get_or_insert(v);
                        } else {
                            face.indices.push(v as u32);
                        }
                    }
                }
                (PropertyKind::List { count, item }, Some(FSlot::Texcoords)) => {
                    let n = tokens.count(&p.name, count)?;
                    if n % 2 == 1 {
                        return Err(FormatError::text(
                            path,
                            line_no,
                            format!("face {}: texcoord list has an odd length {n}", self.done),
                        ));
                    }
                    for _ in 0..n / 2 {
                        let u = tokens.value(&p.name, item)?;
                        let v = tokens.value(&p.name, item)?;
                        face.texcoords.push([u as f32, (1.0 - v) as f32]);
                    }
                }
                (PropertyKind::Scalar(t), Some(s @ (FSlot::Texture | FSlot::Group))) => {
                    let v = tokens.value(&p.name, t)?;
                    if v < 0.0 {
                        bad_label.get_or_insert((p.name.clone(), v));
                    } else if *s == FSlot::Texture {
                        face.texture = Some(v as u32);
                    } else {
                        face.group = Some(v as u32);
                    }
                }
                (PropertyKind::Scalar(t), _) => {
                    tokens.value(&p.name, t)?;
                }
                (PropertyKind::List { count, item }, _) => {
                    let n = tokens.count(&p.name, count)?;
                    for _ in 0..n {
                        tokens.value(&p.name, item)?;
                    }
                }
            }
        }
        tokens.finish()?;
        if let Some(v) = bad_index {
            return Err(self.index_error(v, at));
        }
        if let Some((name, v)) = bad_label {
            return Err(self.label_error(v, at, &name));
        }
        Ok(())
    }

    /// An iterator over the remaining vertices.
    pub fn vertices(&mut self) -> Vertices<'_, R> {
        Vertices { reader: self }
    }

    /// An iterator over the remaining faces, fan-triangulated: polygon `v0 v1 ... vn` gives
    /// `(v0 v1 v2), (v0 v2 v3), ...`. A face with fewer than 3 vertices is an error.
    pub fn triangles(&mut self) -> Triangles<'_, R> {
        Triangles {
            reader: self,
            buf: Vec::new(),
            pos: 0,
            error: None,
            done: false,
        }
    }

    /// Reads past whatever is left and checks that the file ends where the header says.
    pub fn finish(mut self) -> Result<(), FormatError> {
        let n = self.header.elements.len();
        self.seek_element(n)?;
        if self.is_ascii() {
            loop {
                let span = self.src.read_line().map_err(|e| self.io_err(e))?;
                self.line += 1;
                let Some(span) = span else { break };
                if !self.src.line(span).iter().all(u8::is_ascii_whitespace) {
                    return Err(FormatError::text(
                        &self.path,
                        self.line,
                        "data after the last element: the header's element counts are too small",
                    ));
                }
            }
        } else {
            let at = self.src.offset();
            if self.src.ensure(1).map_err(|e| self.io_err(e))? {
                return Err(FormatError::binary(
                    &self.path,
                    at,
                    "data after the last element: the header's element counts are too small",
                ));
            }
        }
        Ok(())
    }
}

/// Whitespace-separated values of one ascii line, with messages naming the element and the
/// property that is missing or wrong.
struct AsciiTokens<'a> {
    words: std::str::SplitAsciiWhitespace<'a>,
    path: &'a Path,
    line: usize,
    element: &'a str,
    index: u64,
}

impl<'a> AsciiTokens<'a> {
    fn new(
        bytes: &'a [u8],
        path: &'a Path,
        line: usize,
        element: &'a str,
        index: u64,
    ) -> Result<Self, FormatError> {
        let text = std::str::from_utf8(bytes).map_err(|_| {
            FormatError::text(path, line, format!("{element} {index}: line is not text"))
        })?;
        Ok(AsciiTokens {
            words: text.split_ascii_whitespace(),
            path,
            line,
            element,
            index,
        })
    }

    fn err(&self, msg: String) -> FormatError {
        FormatError::text(
            self.path,
            self.line,
            format!("{} {}: {msg}", self.element, self.index),
        )
    }

    fn value(&mut self, property: &str, t: ScalarType) -> Result<f64, FormatError> {
        let Some(word) = self.words.next() else {
            return Err(self.err(format!(
                "expected a value for property '{property}', found the end of the line"
            )));
        };
        let v: f64 = word.parse().map_err(|_| {
            self.err(format!(
                "property '{property}': '{}' is not a number",
                truncate(word)
            ))
        })?;
        if t.is_integer() {
            let (lo, hi) = t.integer_range();
            if v.fract() != 0.0 || v < lo || v > hi {
                return Err(self.err(format!(
                    "property '{property}': '{}' is not a {} ({lo}..{hi})",
                    truncate(word),
                    t.name()
                )));
            }
        }
        Ok(v)
    }

    fn count(&mut self, property: &str, t: ScalarType) -> Result<u64, FormatError> {
        let v = self.value(property, t)?;
        if v < 0.0 || v > MAX_LIST_ITEMS as f64 {
            return Err(self.err(format!(
                "property '{property}': list length {v} is negative or larger than {MAX_LIST_ITEMS}"
            )));
        }
        Ok(v as u64)
    }

    fn finish(mut self) -> Result<(), FormatError> {
        match self.words.next() {
            None => Ok(()),
            Some(w) => Err(self.err(format!(
                "unexpected value '{}' after the last property (wrong property list or counts?)",
                truncate(w)
            ))),
        }
    }
}

/// Iterator over the remaining vertices of a [`PlyReader`].
pub struct Vertices<'a, R: Read> {
    reader: &'a mut PlyReader<R>,
}

impl<R: Read> Iterator for Vertices<'_, R> {
    type Item = Result<PlyVertex, FormatError>;
    fn next(&mut self) -> Option<Self::Item> {
        self.reader.next_vertex().transpose()
    }
}

/// Iterator over the remaining faces of a [`PlyReader`], fan-triangulated, read in batches
/// through [`PlyReader::read_triangles`]. After an error it yields nothing more.
pub struct Triangles<'a, R: Read> {
    reader: &'a mut PlyReader<R>,
    buf: Vec<[u32; 3]>,
    pos: usize,
    error: Option<FormatError>,
    done: bool,
}

impl<R: Read> Iterator for Triangles<'_, R> {
    type Item = Result<[u32; 3], FormatError>;
    fn next(&mut self) -> Option<Self::Item> {
        if self.pos == self.buf.len() {
            if let Some(e) = self.error.take() {
                self.done = true;
                return Some(Err(e));
            }
            if self.done {
                return None;
            }
            self.buf.clear();
            self.pos = 0;
            match self.reader.read_triangles(&mut self.buf, 4096) {
                Ok(0) => {
                    self.done = true;
                    return None;
                }
                Ok(_) => {}
                Err(e) => self.error = Some(e),
            }
            if self.buf.is_empty() {
                return self.error.take().map(|e| {
                    self.done = true;
                    Err(e)
                });
            }
        }
        let t = self.buf[self.pos];
        self.pos += 1;
        Some(Ok(t))
    }
}

// ---------------------------------------------------------------------------------------
// Whole meshes.

/// The fewest bytes one item of `e` takes in the data: its scalars and list counts in a
/// binary file, a digit and a separator per property in an ascii one.
fn min_item_bytes(e: &ElementDef, format: PlyFormat) -> u64 {
    match format {
        PlyFormat::Ascii => 2 * e.properties.len() as u64,
        _ => e
            .properties
            .iter()
            .map(|p| match p.kind {
                PropertyKind::Scalar(t) => t.size() as u64,
                PropertyKind::List { count, .. } => count.size() as u64,
            })
            .sum(),
    }
}

/// Reads a mesh (or a point cloud: no face element) from a PLY file. Polygons are
/// fan-triangulated (per-face attributes repeat on each triangle). Rejects NaN or infinite
/// positions, normals and texture coordinates, naming the vertex or face and its line or
/// byte offset: what it returns passes [`Mesh::validate`].
pub fn read_mesh(path: impl AsRef<Path>) -> Result<Mesh, FormatError> {
    let path = path.as_ref();
    let mut r = PlyReader::open(path)?;
    let mut mesh = Mesh::default();
    // Reserve from the header, but never more items than the rest of the file can hold: a
    // 1 kB file announcing 4 billion vertices must not allocate for them.
    let data_bytes = std::fs::metadata(path)
        .map(|m| m.len().saturating_sub(r.header.data_offset))
        .unwrap_or(0);
    let format = r.header.format;
    let reserve = |e: Option<usize>, r: &PlyReader<File>| {
        e.map_or(0, |i| {
            let e = &r.header.elements[i];
            let fit = data_bytes / min_item_bytes(e, format).max(1);
            e.count.min(fit).min(1 << 22) as usize
        })
    };
    mesh.positions.reserve(reserve(r.vertex_element, &r));
    let mut normals = r.has_normals().then(Vec::new);
    let mut colors = r.has_colors().then(Vec::new);
    let mut vertex_uvs = r.has_vertex_uvs().then(Vec::new);
    let mut corner_uvs = (r.has_face_texcoords() || r.has_vertex_uvs()).then(Vec::new);
    let mut textures = r.has_face_textures().then(Vec::new);
    let mut groups = r.has_face_groups().then(Vec::new);
    let mut face = PlyFace::default();

    // Elements in file order: vertices may come after faces in a legal file.
    let order: Vec<&str> = r.header.elements.iter().map(|e| e.name.as_str()).collect();
    let vertices_first = order.iter().position(|&n| n == "vertex")
        < order.iter().position(|&n| n == "face")
        || r.face_element.is_none();
    let mut read_vertices = |r: &mut PlyReader<File>, mesh: &mut Mesh| -> Result<(), FormatError> {
        let mut index = 0u64;
        while let Some(v) = r.next_vertex()? {
            let p = v.position;
            if let Some(axis) = (0..3).find(|&k| !p[k].is_finite()) {
                return Err(located(
                    path,
                    r.last_location(),
                    format!(
                        "vertex {index}: coordinate {} is {} (positions must be finite)",
                        ["x", "y", "z"][axis],
                        p[axis]
                    ),
                ));
            }
            // Normals and texture coordinates too: the mesh must pass `Mesh::validate`, or
            // it cannot be written back (found by the ply_bytes fuzz target: NaN normals).
            let normal_ok = v.normal.is_none_or(|n| n.iter().all(|x| x.is_finite()));
            let uv_ok = v.uv.is_none_or(|uv| uv.iter().all(|x| x.is_finite()));
            if !(normal_ok && uv_ok) {
                return Err(located(
                    path,
                    r.last_location(),
                    format!(
                        "vertex {index}: {} is not finite",
                        if normal_ok {
                            "texture coordinate"
                        } else {
                            "normal"
                        }
                    ),
                ));
            }
            mesh.positions.push(p);
            if let (Some(ns), Some(n)) = (normals.as_mut(), v.normal) {
                ns.push(n);
            }
            if let (Some(cs), Some(c)) = (colors.as_mut(), v.color) {
                cs.push(c);
            }
            if let (Some(us), Some(uv)) = (vertex_uvs.as_mut(), v.uv) {
                us.push(uv);
            }
            index += 1;
        }
        Ok(())
    };
    let mut read_faces = |r: &mut PlyReader<File>, mesh: &mut Mesh| -> Result<(), FormatError> {
        mesh.faces.reserve(reserve(r.face_element, r));
        let mut index = 0u64;
        while r.next_face(&mut face)? {
            let n = face.indices.len();
            if n < 3 {
                return Err(located(
                    path,
                    r.last_location(),
                    format!("face {index}: {n} vertex indices; a face needs at least 3"),
                ));
            }
            if face.texcoords.iter().flatten().any(|x| !x.is_finite()) {
                return Err(located(
                    path,
                    r.last_location(),
                    format!("face {index}: a texture coordinate is not finite"),
                ));
            }
            for k in 1..n - 1 {
                mesh.faces
                    .push([face.indices[0], face.indices[k], face.indices[k + 1]]);
                if let Some(uvs) = corner_uvs.as_mut() {
                    if face.texcoords.is_empty() {
                        // Per-vertex UVs: filled in once vertices are known.
                        uvs.push([[f32::NAN; 2]; 3]);
                    } else {
                        uvs.push([face.texcoords[0], face.texcoords[k], face.texcoords[k + 1]]);
                    }
                }
                if let Some(t) = textures.as_mut() {
                    t.push(face.texture.unwrap_or(0));
                }
                if let Some(g) = groups.as_mut() {
                    g.push(face.group.unwrap_or(0));
                }
            }
            index += 1;
        }
        Ok(())
    };
    if vertices_first {
        read_vertices(&mut r, &mut mesh)?;
        read_faces(&mut r, &mut mesh)?;
    } else {
        read_faces(&mut r, &mut mesh)?;
        read_vertices(&mut r, &mut mesh)?;
    }
    r.finish()?;
    mesh.normals = normals;
    mesh.colors = colors;
    if let (Some(uvs), Some(vuv)) = (corner_uvs.as_mut(), vertex_uvs.as_ref()) {
        for (corners, f) in uvs.iter_mut().zip(&mesh.faces) {
            if corners[0][0].is_nan() {
                *corners = f.map(|v| vuv[v as usize]);
            }
        }
    }
    mesh.corner_uvs = corner_uvs;
    mesh.face_textures = textures;
    mesh.face_groups = groups;
    Ok(mesh)
}

/// Writes `mesh` to `path` atomically: positions as double (lossless), normals as float,
/// colours as uchar, per-corner UVs as a MeshLab `texcoord` list (v flipped to v-up), texture
/// indices as `texnumber` and face groups as `group`. A mesh without faces is written as a
/// point cloud (no face element). The mesh is validated first.
pub fn write_mesh(
    path: impl AsRef<Path>,
    mesh: &Mesh,
    format: PlyFormat,
) -> Result<(), FormatError> {
    let path = path.as_ref();
    mesh.validate()
        .map_err(|e| FormatError::invalid(path, format!("cannot write an invalid mesh: {e}")))?;
    let mut layout = PlyLayout::new(format, mesh.positions.len() as u64, mesh.faces.len() as u64);
    layout.position_type = ScalarType::F64;
    layout.normals = mesh.normals.is_some();
    layout.colors = mesh.colors.is_some();
    layout.face_texcoords = mesh.corner_uvs.is_some();
    layout.face_textures = mesh.face_textures.is_some();
    layout.face_groups = mesh.face_groups.is_some();
    layout.comments.push("written by fresco".into());
    let mut w = PlyWriter::create(path, layout)?;
    for (i, p) in mesh.positions.iter().enumerate() {
        w.write_vertex(&PlyVertex {
            position: *p,
            normal: mesh.normals.as_ref().map(|n| n[i]),
            color: mesh.colors.as_ref().map(|c| c[i]),
            uv: None,
        })?;
    }
    let mut face = PlyFace::default();
    for (f, tri) in mesh.faces.iter().enumerate() {
        face.indices.clear();
        face.indices.extend_from_slice(tri);
        face.texcoords.clear();
        if let Some(uvs) = &mesh.corner_uvs {
            face.texcoords.extend_from_slice(&uvs[f]);
        }
        face.texture = mesh.face_textures.as_ref().map(|t| t[f]);
        face.group = mesh.face_groups.as_ref().map(|g| g[f]);
        w.write_face(&face)?;
    }
    w.finish()
}

// ---------------------------------------------------------------------------------------
// Streaming writer.

/// What a [`PlyWriter`] writes: the format, the counts and which attributes each vertex and
/// face carries.
#[derive(Clone, Debug, PartialEq)]
pub struct PlyLayout {
    pub format: PlyFormat,
    pub vertex_count: u64,
    /// Faces (polygons). 0 writes a point cloud: no face element at all.
    pub face_count: u64,
    /// `F32` (compact, what most tools write) or `F64` (lossless for fresco's f64 positions).
    pub position_type: ScalarType,
    pub normals: bool,
    pub colors: bool,
    /// Per-corner texture coordinates as a `texcoord` list (MeshLab's convention).
    pub face_texcoords: bool,
    pub face_textures: bool,
    pub face_groups: bool,
    pub comments: Vec<String>,
}

impl PlyLayout {
    /// Positions as float, no other attribute.
    pub fn new(format: PlyFormat, vertex_count: u64, face_count: u64) -> PlyLayout {
        PlyLayout {
            format,
            vertex_count,
            face_count,
            position_type: ScalarType::F32,
            normals: false,
            colors: false,
            face_texcoords: false,
            face_textures: false,
            face_groups: false,
            comments: Vec::new(),
        }
    }

    fn index_type(&self) -> ScalarType {
        if self.vertex_count > i32::MAX as u64 {
            ScalarType::U32
        } else {
            ScalarType::I32
        }
    }

    fn header(&self) -> String {
        let mut h = format!("ply\nformat {} 1.0\n", self.format.name());
        for c in &self.comments {
            // A comment cannot span lines.
            h.push_str(&format!("comment {}\n", c.replace(['\n', '\r'], " ")));
        }
        h.push_str(&format!("element vertex {}\n", self.vertex_count));
        let pt = self.position_type.name();
        h.push_str(&format!(
            "property {pt} x\nproperty {pt} y\nproperty {pt} z\n"
        ));
        if self.normals {
            h.push_str("property float nx\nproperty float ny\nproperty float nz\n");
        }
        if self.colors {
            h.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
        }
        if self.face_count > 0 {
            h.push_str(&format!("element face {}\n", self.face_count));
            h.push_str(&format!(
                "property list uchar {} vertex_indices\n",
                self.index_type().name()
            ));
            if self.face_texcoords {
                h.push_str("property list uchar float texcoord\n");
            }
            if self.face_textures {
                h.push_str("property int texnumber\n");
            }
            if self.face_groups {
                h.push_str("property uint group\n");
            }
        }
        h.push_str("end_header\n");
        h
    }
}

/// Writes a PLY file item by item, to a temporary file renamed over `path` by
/// [`PlyWriter::finish`] once the counts match the header. Dropped without `finish`, it
/// removes the temporary file and leaves `path` untouched.
pub struct PlyWriter {
    path: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
    layout: PlyLayout,
    index_type: ScalarType,
    vertices: u64,
    faces: u64,
    scratch: Vec<u8>,
}

pub(crate) use crate::atomic_file::temporary_path;

impl PlyWriter {
    /// Creates the temporary file and writes the header.
    pub fn create(path: impl AsRef<Path>, layout: PlyLayout) -> Result<PlyWriter, FormatError> {
        let path = path.as_ref().to_path_buf();
        if !matches!(layout.position_type, ScalarType::F32 | ScalarType::F64) {
            return Err(FormatError::invalid(
                &path,
                "positions must be written as float or double",
            ));
        }
        if layout.face_count > 0 && layout.vertex_count > u32::MAX as u64 {
            return Err(FormatError::invalid(
                &path,
                "more than 2^32 vertices cannot be indexed by faces",
            ));
        }
        let tmp = temporary_path(&path);
        let file = File::create(&tmp).map_err(|e| FormatError::io(&tmp, e))?;
        let mut out = BufWriter::with_capacity(BUFFER_BYTES, file);
        out.write_all(layout.header().as_bytes())
            .map_err(|e| FormatError::io(&tmp, e))?;
        Ok(PlyWriter {
            index_type: layout.index_type(),
            path,
            tmp,
            out: Some(out),
            layout,
            vertices: 0,
            faces: 0,
            scratch: Vec::with_capacity(256),
        })
    }

    pub fn layout(&self) -> &PlyLayout {
        &self.layout
    }

    fn misuse(&self, msg: String) -> FormatError {
        FormatError::invalid(&self.path, msg)
    }

    fn flush_scratch(&mut self) -> Result<(), FormatError> {
        let out = self.out.as_mut().expect("writer is open until finish");
        out.write_all(&self.scratch)
            .map_err(|e| FormatError::io(&self.tmp, e))?;
        self.scratch.clear();
        Ok(())
    }

    /// Appends one vertex; it must carry exactly the attributes the layout declares.
    pub fn write_vertex(&mut self, v: &PlyVertex) -> Result<(), FormatError> {
        let i = self.vertices;
        if i >= self.layout.vertex_count {
            return Err(self.misuse(format!(
                "vertex {i}: the header declares only {} vertices",
                self.layout.vertex_count
            )));
        }
        let (normal, color) = match (self.layout.normals, v.normal, self.layout.colors, v.color) {
            (false, _, false, _) => (None, None),
            (true, Some(n), false, _) => (Some(n), None),
            (false, _, true, Some(c)) => (None, Some(c)),
            (true, Some(n), true, Some(c)) => (Some(n), Some(c)),
            _ => {
                return Err(self.misuse(format!(
                    "vertex {i}: the layout declares normals={} colors={} but the vertex lacks one",
                    self.layout.normals, self.layout.colors
                )));
            }
        };
        let s = &mut self.scratch;
        let p = v.position;
        match self.layout.format {
            PlyFormat::Ascii => {
                if self.layout.position_type == ScalarType::F64 {
                    let _ = write!(s, "{:?} {:?} {:?}", p.x, p.y, p.z);
                } else {
                    let _ = write!(s, "{:?} {:?} {:?}", p.x as f32, p.y as f32, p.z as f32);
                }
                if let Some(n) = normal {
                    let _ = write!(s, " {:?} {:?} {:?}", n.x as f32, n.y as f32, n.z as f32);
                }
                if let Some(c) = color {
                    let _ = write!(s, " {} {} {}", c[0], c[1], c[2]);
                }
                s.push(b'\n');
            }
            format => {
                let big = format == PlyFormat::BinaryBigEndian;
                macro_rules! put {
                    ($x:expr) => {
                        if big {
                            s.extend_from_slice(&$x.to_be_bytes())
                        } else {
                            s.extend_from_slice(&$x.to_le_bytes())
                        }
                    };
                }
                if self.layout.position_type == ScalarType::F64 {
                    put!(p.x);
                    put!(p.y);
                    put!(p.z);
                } else {
                    put!(p.x as f32);
                    put!(p.y as f32);
                    put!(p.z as f32);
                }
                if let Some(n) = normal {
                    put!(n.x as f32);
                    put!(n.y as f32);
                    put!(n.z as f32);
                }
                if let Some(c) = color {
                    s.extend_from_slice(&c);
                }
            }
        }
        self.vertices += 1;
        self.flush_scratch()
    }

    /// Appends one triangle (layouts without per-face attributes).
    pub fn write_triangle(&mut self, t: [u32; 3]) -> Result<(), FormatError> {
        let face = PlyFace {
            indices: t.to_vec(),
            ..PlyFace::default()
        };
        self.write_face(&face)
    }

    /// Appends one polygon with 3 to 255 corners, after all vertices. Its attributes must
    /// match the layout; indices must be below the vertex count.
    pub fn write_face(&mut self, face: &PlyFace) -> Result<(), FormatError> {
        let f = self.faces;
        if self.vertices < self.layout.vertex_count {
            return Err(self.misuse(format!(
                "face {f} written after {} of {} vertices: write all vertices first",
                self.vertices, self.layout.vertex_count
            )));
        }
        if f >= self.layout.face_count {
            return Err(self.misuse(format!(
                "face {f}: the header declares only {} faces",
                self.layout.face_count
            )));
        }
        let n = face.indices.len();
        if !(3..=255).contains(&n) {
            return Err(self.misuse(format!("face {f}: {n} corners (3 to 255 allowed)")));
        }
        if let Some(&bad) = face
            .indices
            .iter()
            .find(|&&i| i as u64 >= self.layout.vertex_count)
        {
            return Err(self.misuse(format!(
                "face {f}: vertex index {bad} out of range ({} vertices)",
                self.layout.vertex_count
            )));
        }
        if self.layout.face_texcoords && face.texcoords.len() != n {
            return Err(self.misuse(format!(
                "face {f}: {} texture coordinates for {n} corners",
                face.texcoords.len()
            )));
        }
        if (self.layout.face_textures && face.texture.is_none())
            || (self.layout.face_groups && face.group.is_none())
        {
            return Err(self.misuse(format!(
                "face {f}: the layout declares texnumber={} group={} but the face lacks one",
                self.layout.face_textures, self.layout.face_groups
            )));
        }
        let texture = face.texture.unwrap_or(0).min(i32::MAX as u32) as i32;
        let group = face.group.unwrap_or(0);
        let s = &mut self.scratch;
        match self.layout.format {
            PlyFormat::Ascii => {
                let _ = write!(s, "{n}");
                for i in &face.indices {
                    let _ = write!(s, " {i}");
                }
                if self.layout.face_texcoords {
                    let _ = write!(s, " {}", 2 * n);
                    for uv in &face.texcoords {
                        let _ = write!(s, " {:?} {:?}", uv[0], 1.0 - uv[1]);
                    }
                }
                if self.layout.face_textures {
                    let _ = write!(s, " {texture}");
                }
                if self.layout.face_groups {
                    let _ = write!(s, " {group}");
                }
                s.push(b'\n');
            }
            format => {
                let big = format == PlyFormat::BinaryBigEndian;
                macro_rules! put {
                    ($x:expr) => {
                        if big {
                            s.extend_from_slice(&$x.to_be_bytes())
                        } else {
                            s.extend_from_slice(&$x.to_le_bytes())
                        }
                    };
                }
                s.push(n as u8);
                if self.index_type == ScalarType::I32 {
                    for &i in &face.indices {
                        put!(i as i32);
                    }
                } else {
                    for &i in &face.indices {
                        put!(i);
                    }
                }
                if self.layout.face_texcoords {
                    s.push((2 * n) as u8);
                    for uv in &face.texcoords {
                        put!(uv[0]);
                        put!(1.0f32 - uv[1]);
                    }
                }
                if self.layout.face_textures {
                    put!(texture);
                }
                if self.layout.face_groups {
                    put!(group);
                }
            }
        }
        self.faces += 1;
        self.flush_scratch()
    }

    /// Checks that every declared vertex and face was written, flushes, and renames the
    /// temporary file over `path`.
    pub fn finish(mut self) -> Result<(), FormatError> {
        if self.vertices != self.layout.vertex_count || self.faces != self.layout.face_count {
            return Err(self.misuse(format!(
                "wrote {} of {} vertices and {} of {} faces: the file would not match its header",
                self.vertices, self.layout.vertex_count, self.faces, self.layout.face_count
            )));
        }
        let out = self.out.take().expect("writer is open until finish");
        let file = out
            .into_inner()
            .map_err(|e| FormatError::io(&self.tmp, e.into_error()))?;
        file.sync_all().map_err(|e| FormatError::io(&self.tmp, e))?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path).map_err(|e| {
            let _ = std::fs::remove_file(&self.tmp);
            FormatError::io(&self.path, e)
        })
    }
}

impl Drop for PlyWriter {
    fn drop(&mut self) {
        if self.out.take().is_some() {
            // Not finished: the partial file must not be mistaken for output.
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}
