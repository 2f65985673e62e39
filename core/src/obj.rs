//! Wavefront OBJ: reading through tobj, and a simple writer (with UVs and an `.mtl`).
//!
//! - [`read_obj`]: positions, vertex colours (`v x y z r g b`), normals, per-corner UVs (v
//!   flipped to fresco's v-down), materials from the `.mtl` files (`map_Kd` resolved against
//!   the folder of the OBJ). Polygons are fan-triangulated; points and lines are ignored.
//!   `face_groups` holds the object/group index (as tobj splits them, `o` and `g`), and
//!   `face_textures` the material index when the file uses materials. Normals are per
//!   corner in OBJ but per vertex in [`Mesh`]: a vertex whose corners disagree gets their
//!   normalised average. Vertices come out in the order faces first use them (tobj's
//!   numbering), not in file order, and vertices no face uses are dropped; a vertex shared
//!   between objects or material runs is joined by its exact position (see `SceneBuilder`).
//! - [`read_mesh`]: just the mesh.
//! - [`write_obj`]: positions (and colours), per-vertex normals, per-corner UVs (v flipped
//!   back to v-up) and one material per texture image, written atomically with its `.mtl`.
//!
//! tobj reports what went wrong but not where; on a parse error this module scans the file
//! itself for the first offending line so that the message names it.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};

use crate::FormatError;
use crate::atomic_file::write_atomically;
use crate::mesh::Mesh;

/// A material of an OBJ file's `.mtl`.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjMaterial {
    pub name: String,
    /// `map_Kd`, resolved against the OBJ's folder.
    pub diffuse_texture: Option<PathBuf>,
    /// `Kd`.
    pub diffuse_color: Option<[f32; 3]>,
}

/// Everything [`read_obj`] understood.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjScene {
    pub mesh: Mesh,
    /// Indexed by `mesh.face_textures`.
    pub materials: Vec<ObjMaterial>,
    /// Object or group names, indexed by `mesh.face_groups`.
    pub object_names: Vec<String>,
}

/// Reads an OBJ file and its materials; see the module documentation.
pub fn read_obj(path: impl AsRef<Path>) -> Result<ObjScene, FormatError> {
    let path = path.as_ref();
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    // Only a regular file: a device (`/dev/zero`) would be read forever.
    let meta = std::fs::metadata(path).map_err(|e| FormatError::io(path, e))?;
    if !meta.is_file() {
        return Err(FormatError::invalid(path, "not a regular file"));
    }
    let text = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
    check_face_indices(&text).map_err(|(line, m)| FormatError::text(path, line, m))?;
    let folder = path.parent().unwrap_or(Path::new(""));
    let (models, materials) = tobj::load_obj_buf(&mut text.as_slice(), &options, |mtl| {
        load_mtl(&folder.join(mtl))
    })
    .map_err(|e| locate_error(path, e))?;
    let materials = match materials {
        Ok(m) => m,
        Err(e) => {
            tracing::warn!(
                "{}: material library not read ({e}); continuing without materials",
                path.display()
            );
            Vec::new()
        }
    };
    let materials: Vec<ObjMaterial> = materials
        .into_iter()
        .map(|m| ObjMaterial {
            name: m.name,
            diffuse_texture: m.diffuse_texture.map(|t| folder.join(t)),
            diffuse_color: m.diffuse.map(|c| c.map(|x| x as f32)),
        })
        .collect();

    let uses_materials = models.iter().any(|m| m.mesh.material_id.is_some());
    let mut builder = SceneBuilder::default();
    let mut object_names = Vec::with_capacity(models.len());
    for (object, model) in models.iter().enumerate() {
        let material = uses_materials.then(|| model.mesh.material_id.unwrap_or(0) as u32);
        builder.add_model(path, &model.mesh, object as u32, material)?;
        object_names.push(model.name.clone());
    }
    Ok(ObjScene {
        mesh: builder.finish(),
        materials,
        object_names,
    })
}

/// Checks the vertex indices of face, line and point records before tobj 4.0.5 reads them:
/// it adds a negative (relative) index to the count so far and computes `3 * index + 2`
/// unchecked, so `-21474836481` or an index past the end overflowed (found by the obj fuzz
/// target). A relative index may go back at most to the first element of its kind; an
/// absolute one past the end is left to tobj's own check, below 2^40 (no file holds more
/// elements) so that its arithmetic cannot overflow. Returns the 1-based line.
fn check_face_indices(text: &[u8]) -> Result<(), (usize, String)> {
    // Positions, texture coordinates and normals read so far.
    let mut counts = [0i64; 3];
    for (n, line) in text.split(|&b| b == b'\n').enumerate() {
        let line = String::from_utf8_lossy(line);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("f" | "l" | "p") => {
                for word in words {
                    for (k, part) in word.split('/').enumerate().take(3) {
                        let Ok(i) = part.parse::<i64>() else { continue };
                        if (i < 0 && -i > counts[k]) || i > 1 << 40 {
                            let kind = ["vertex", "texture coordinate", "normal"][k];
                            return Err((
                                n + 1,
                                format!("{kind} index {i} refers to no {kind} of the file"),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// A material library named by an OBJ file (`mtllib`), for tobj. The name comes from the
/// file, so only a regular file is read (`mtllib /dev/zero` made tobj read forever), and
/// colour lines are checked before tobj parses them: tobj 4.0.5 panics on a `Ka`, `Kd`, `Ks`
/// or `Ke` line with fewer than three numbers (found by the obj fuzz target). A library
/// that fails either check is reported as unreadable, and the OBJ is read without it.
fn load_mtl(path: &Path) -> tobj::MTLLoadResult {
    let regular = std::fs::metadata(path).is_ok_and(|m| m.is_file());
    if !regular {
        return Err(tobj::LoadError::OpenFileFailed);
    }
    let text = std::fs::read(path).map_err(|_| tobj::LoadError::ReadError)?;
    for line in text.split(|&b| b == b'\n') {
        let line = String::from_utf8_lossy(line);
        let mut words = line.split_whitespace();
        if matches!(words.next(), Some("Ka" | "Kd" | "Ks" | "Ke")) && words.count() < 3 {
            return Err(tobj::LoadError::MaterialParseError);
        }
    }
    tobj::load_mtl_buf(&mut text.as_slice())
}

/// Reads only the mesh of an OBJ file.
pub fn read_mesh(path: impl AsRef<Path>) -> Result<Mesh, FormatError> {
    read_obj(path).map(|s| s.mesh)
}

/// Joins tobj's models into one mesh. tobj gives each model (object, group, or run of faces
/// with one material) its own copy of the vertices it uses, numbered by first use; a vertex
/// that the file shares between models is joined again here by its exact position, so that
/// faces on either side of a material change stay connected. Vertices of one model are
/// never joined.
#[derive(Default)]
struct SceneBuilder {
    mesh: Mesh,
    /// Exact position -> (vertex, model that created it).
    by_position: HashMap<[u64; 3], (u32, u32)>,
    colors: Vec<[u8; 3]>,
    any_colors: bool,
    corner_uvs: Vec<[[f32; 2]; 3]>,
    any_uvs: bool,
    face_textures: Vec<u32>,
    any_textures: bool,
    face_groups: Vec<u32>,
    /// Per vertex: first normal seen, whether all its corners agree, and their sum.
    normal_first: Vec<Option<Vector3<f64>>>,
    normal_agree: Vec<bool>,
    normal_sum: Vec<Vector3<f64>>,
    any_normals: bool,
}

impl SceneBuilder {
    fn add_model(
        &mut self,
        path: &Path,
        m: &tobj::Mesh,
        object: u32,
        material: Option<u32>,
    ) -> Result<(), FormatError> {
        let nv = m.positions.len() / 3;
        let has_colors = m.vertex_color.len() == 3 * nv && nv > 0;
        let mut map = Vec::with_capacity(nv);
        for (k, p) in m.positions.chunks_exact(3).enumerate() {
            let p = Point3::new(p[0], p[1], p[2]);
            if !p.iter().all(|c| c.is_finite()) {
                let v = self.mesh.positions.len();
                let message = format!("vertex {v}: non-finite coordinate");
                // tobj numbers vertices by first use; the n-th `v` line is the right one
                // when the file lists vertices in the order faces use them (the usual case).
                return Err(statement_error(path, "v", v, message));
            }
            let key = [p.x, p.y, p.z].map(|c| (c + 0.0).to_bits());
            let existing = self.by_position.get(&key).copied();
            let global = match existing {
                Some((v, owner)) if owner != object => v,
                _ => {
                    let v = self.mesh.positions.len() as u32;
                    self.mesh.positions.push(p);
                    self.colors.push(if has_colors {
                        let c = &m.vertex_color[3 * k..3 * k + 3];
                        [c[0], c[1], c[2]].map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8)
                    } else {
                        [128; 3]
                    });
                    self.normal_first.push(None);
                    self.normal_agree.push(true);
                    self.normal_sum.push(Vector3::zeros());
                    if existing.is_none() {
                        self.by_position.insert(key, (v, object));
                    }
                    v
                }
            };
            map.push(global);
        }
        self.any_colors |= has_colors;

        let corners = m.indices.len();
        let face_base = self.mesh.faces.len();
        for (f, t) in m.indices.chunks_exact(3).enumerate() {
            let mut face = [0u32; 3];
            for c in 0..3 {
                face[c] = *map.get(t[c] as usize).ok_or_else(|| {
                    FormatError::invalid(
                        path,
                        format!("object {object}: face {f} refers to a vertex that does not exist"),
                    )
                })?;
            }
            self.mesh.faces.push(face);
        }
        let nf = self.mesh.faces.len() - face_base;

        let has_uvs = !m.texcoords.is_empty() && m.texcoord_indices.len() == corners;
        if has_uvs {
            let nt = m.texcoords.len() / 2;
            for (f, tri) in m.texcoord_indices.chunks_exact(3).enumerate() {
                let mut corner = [[0.0f32; 2]; 3];
                for (c, &t) in tri.iter().enumerate() {
                    let t = t as usize;
                    if t >= nt {
                        return Err(FormatError::invalid(
                            path,
                            format!(
                                "object {object}: face {f} refers to a texture coordinate that does not exist"
                            ),
                        ));
                    }
                    // tobj parses "inf", "nan" and out-of-range exponents (found by the obj
                    // fuzz target): refuse them at their `vt` line.
                    let (u, v) = (m.texcoords[2 * t], m.texcoords[2 * t + 1]);
                    if !(u.is_finite()
                        && v.is_finite()
                        && (u as f32).is_finite()
                        && (v as f32).is_finite())
                    {
                        let message = format!("texture coordinate {t}: non-finite component");
                        return Err(statement_error(path, "vt", t, message));
                    }
                    // OBJ's v points up; fresco's down.
                    corner[c] = [
                        m.texcoords[2 * t] as f32,
                        (1.0 - m.texcoords[2 * t + 1]) as f32,
                    ];
                }
                self.corner_uvs.push(corner);
            }
        } else {
            self.corner_uvs
                .extend(std::iter::repeat_n([[0.0; 2]; 3], nf));
        }
        self.any_uvs |= has_uvs;

        if !m.normals.is_empty() && m.normal_indices.len() == corners {
            let nn = m.normals.len() / 3;
            for (k, (&v, &n)) in m.indices.iter().zip(&m.normal_indices).enumerate() {
                let n = n as usize;
                if n >= nn {
                    return Err(FormatError::invalid(
                        path,
                        format!(
                            "object {object}: face {} refers to a normal that does not exist",
                            k / 3
                        ),
                    ));
                }
                let normal =
                    Vector3::new(m.normals[3 * n], m.normals[3 * n + 1], m.normals[3 * n + 2]);
                // tobj parses "inf" and "nan" (found by the obj fuzz target): refuse them
                // here, at their line, rather than hand on a mesh that fails validation.
                if !normal.iter().all(|c| c.is_finite()) {
                    let message = format!("normal {n}: non-finite component");
                    return Err(statement_error(path, "vn", n, message));
                }
                let v = map[v as usize] as usize;
                match self.normal_first[v] {
                    None => self.normal_first[v] = Some(normal),
                    Some(first) if first != normal => self.normal_agree[v] = false,
                    _ => {}
                }
                self.normal_sum[v] += normal.try_normalize(0.0).unwrap_or_else(Vector3::zeros);
            }
            self.any_normals = true;
        }
        self.face_textures
            .extend(std::iter::repeat_n(material.unwrap_or(0), nf));
        self.any_textures |= material.is_some();
        self.face_groups.extend(std::iter::repeat_n(object, nf));
        Ok(())
    }

    fn finish(mut self) -> Mesh {
        if self.any_colors {
            self.mesh.colors = Some(self.colors);
        }
        if self.any_uvs {
            self.mesh.corner_uvs = Some(self.corner_uvs);
        }
        if self.any_textures {
            self.mesh.face_textures = Some(self.face_textures);
        }
        self.mesh.face_groups = Some(self.face_groups);
        if self.any_normals {
            // Vertices whose corners disagree (or that no corner gave a normal) get the
            // normalised average of their corner normals.
            let normals = (0..self.mesh.positions.len())
                .map(|v| match self.normal_first[v] {
                    Some(n) if self.normal_agree[v] => n,
                    _ => self.normal_sum[v]
                        .try_normalize(0.0)
                        .unwrap_or_else(Vector3::zeros),
                })
                .collect();
            self.mesh.normals = Some(normals);
        }
        self.mesh
    }
}

/// An error located at the `n`-th (0-based) statement starting with `keyword`, or at the
/// file when that line cannot be found.
fn statement_error(path: &Path, keyword: &str, n: usize, message: String) -> FormatError {
    match nth_statement_line(path, keyword, n) {
        Some(line) => FormatError::text(path, line, message),
        None => FormatError::invalid(path, message),
    }
}

/// Line number (1-based) of the `n`-th (0-based) statement starting with `keyword`.
fn nth_statement_line(path: &Path, keyword: &str, n: usize) -> Option<usize> {
    let file = File::open(path).ok()?;
    let mut seen = 0;
    for (i, line) in BufReader::new(file).lines().enumerate() {
        let line = line.ok()?;
        if line.split_ascii_whitespace().next() == Some(keyword) {
            if seen == n {
                return Some(i + 1);
            }
            seen += 1;
        }
    }
    None
}

/// Turns a tobj error into one naming the file and, where the file shows it, the line.
fn locate_error(path: &Path, e: tobj::LoadError) -> FormatError {
    use tobj::LoadError as E;
    let what = match e {
        E::PositionParseError => "a vertex position 'v x y z' with numbers",
        E::NormalParseError => "a normal 'vn x y z' with three numbers",
        E::TexcoordParseError => "a texture coordinate 'vt u [v [w]]' with numbers",
        E::ColorParseError => "a vertex colour of three numbers after the position",
        E::FaceParseError | E::InvalidPolygon => {
            "a face 'f v[/vt][/vn] ...' with at least three corners"
        }
        E::FaceVertexOutOfBounds => "face vertex indices that refer to existing vertices",
        E::FaceTexCoordOutOfBounds => "face texture indices that refer to existing 'vt' lines",
        E::FaceNormalOutOfBounds => "face normal indices that refer to existing 'vn' lines",
        E::FaceColorOutOfBounds => {
            "colours on every vertex or on none (tobj cannot read files that mix them)"
        }
        _ => "",
    };
    if let Some(line) = find_bad_line(path, &e) {
        return FormatError::text(path, line, format!("{e}: expected {what}"));
    }
    if what.is_empty() {
        FormatError::invalid(path, format!("not a readable OBJ file: {e}"))
    } else {
        FormatError::invalid(path, format!("{e}: expected {what}"))
    }
}

/// Scans for the first line that tobj's `e` is about.
fn find_bad_line(path: &Path, e: &tobj::LoadError) -> Option<usize> {
    use tobj::LoadError as E;
    let file = File::open(path).ok()?;
    let (mut nv, mut nt, mut nn) = (0usize, 0usize, 0usize);
    let numbers = |words: &[&str]| words.iter().all(|w| w.parse::<f64>().is_ok());
    for (i, line) in BufReader::new(file).lines().enumerate() {
        let line = line.ok()?;
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        let Some((&key, args)) = words.split_first() else {
            continue;
        };
        let bad = match key {
            "v" => {
                nv += 1;
                let position = args.len() >= 3 && numbers(&args[..3]);
                match e {
                    E::PositionParseError => !position,
                    E::ColorParseError => {
                        position && args.len() != 3 && args.len() != 4 && args.len() != 6
                    }
                    _ => false,
                }
            }
            "vt" => {
                nt += 1;
                matches!(e, E::TexcoordParseError) && (args.is_empty() || !numbers(args))
            }
            "vn" => {
                nn += 1;
                matches!(e, E::NormalParseError) && (args.len() < 3 || !numbers(&args[..3]))
            }
            "f" => {
                let resolve = |s: &str, count: usize| -> Option<bool> {
                    if s.is_empty() {
                        return Some(true);
                    }
                    let i: i64 = s.parse().ok()?;
                    Some(if i > 0 {
                        i as usize <= count
                    } else {
                        i < 0 && (-i) as usize <= count
                    })
                };
                let mut parse_ok = args.len() >= 3;
                let (mut v_ok, mut t_ok, mut n_ok) = (true, true, true);
                for a in args {
                    let mut parts = a.split('/');
                    let v = parts.next().unwrap_or("");
                    let t = parts.next().unwrap_or("");
                    let n = parts.next().unwrap_or("");
                    match (resolve(v, nv), resolve(t, nt), resolve(n, nn)) {
                        (Some(a), Some(b), Some(c)) => {
                            v_ok &= a && !v.is_empty();
                            t_ok &= b;
                            n_ok &= c;
                        }
                        _ => parse_ok = false,
                    }
                }
                match e {
                    E::FaceParseError | E::InvalidPolygon => !parse_ok,
                    E::FaceVertexOutOfBounds => !v_ok,
                    E::FaceTexCoordOutOfBounds => !t_ok,
                    E::FaceNormalOutOfBounds => !n_ok,
                    _ => false,
                }
            }
            _ => false,
        };
        if bad {
            return Some(i + 1);
        }
    }
    None
}

/// Writes `mesh` as an OBJ file with a `.mtl` beside it (same stem) when the mesh has UVs
/// or `textures` is not empty: one material `material_<k>` per texture image `textures[k]`
/// (written as given, normally a path relative to the OBJ), selected per face by
/// `face_textures` (texture 0 when absent). Texture coordinates are de-duplicated; v is
/// flipped back to OBJ's v-up. Vertex colours go after the position (`v x y z r g b`).
pub fn write_obj(
    path: impl AsRef<Path>,
    mesh: &Mesh,
    textures: &[&str],
) -> Result<(), FormatError> {
    let path = path.as_ref();
    mesh.validate()
        .map_err(|e| FormatError::invalid(path, format!("cannot write an invalid mesh: {e}")))?;
    let with_materials = mesh.corner_uvs.is_some() || !textures.is_empty();
    let mtl_path = path.with_extension("mtl");
    let mtl_name = mtl_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if let Some(t) = &mesh.face_textures
        && let Some(&bad) = t.iter().find(|&&t| t as usize >= textures.len().max(1))
    {
        return Err(FormatError::invalid(
            path,
            format!(
                "face_textures refers to texture {bad} but {} texture(s) were given",
                textures.len()
            ),
        ));
    }
    if with_materials {
        write_atomically(&mtl_path, |w| {
            writeln!(w, "# written by fresco")?;
            for k in 0..textures.len().max(1) {
                writeln!(w, "newmtl material_{k}")?;
                writeln!(w, "Ka 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1")?;
                if let Some(t) = textures.get(k) {
                    writeln!(w, "map_Kd {t}")?;
                }
                writeln!(w)?;
            }
            Ok(())
        })?;
    }
    write_atomically(path, |w| {
        writeln!(w, "# written by fresco")?;
        if with_materials {
            writeln!(w, "mtllib {mtl_name}")?;
        }
        for (i, p) in mesh.positions.iter().enumerate() {
            match &mesh.colors {
                Some(c) => {
                    let c = c[i].map(|x| x as f32 / 255.0);
                    writeln!(
                        w,
                        "v {:?} {:?} {:?} {:?} {:?} {:?}",
                        p.x, p.y, p.z, c[0], c[1], c[2]
                    )?
                }
                None => writeln!(w, "v {:?} {:?} {:?}", p.x, p.y, p.z)?,
            }
        }
        if let Some(normals) = &mesh.normals {
            for n in normals {
                writeln!(w, "vn {:?} {:?} {:?}", n.x, n.y, n.z)?;
            }
        }
        // Unique texture coordinates, in first-use order.
        let mut uv_index: HashMap<[u32; 2], usize> = HashMap::new();
        let mut corner_vt: Vec<[usize; 3]> = Vec::new();
        if let Some(uvs) = &mesh.corner_uvs {
            corner_vt.reserve(uvs.len());
            for tri in uvs {
                let mut ids = [0; 3];
                for (c, uv) in tri.iter().enumerate() {
                    let key = uv.map(f32::to_bits);
                    let next = uv_index.len();
                    ids[c] = *uv_index.entry(key).or_insert_with(|| {
                        let _ = writeln!(w, "vt {:?} {:?}", uv[0], 1.0 - uv[1]);
                        next
                    });
                }
                corner_vt.push(ids);
            }
        }
        let mut current_material = None;
        for (f, tri) in mesh.faces.iter().enumerate() {
            if with_materials {
                let m = mesh.face_textures.as_ref().map_or(0, |t| t[f]);
                if current_material != Some(m) {
                    writeln!(w, "usemtl material_{m}")?;
                    current_material = Some(m);
                }
            }
            write!(w, "f")?;
            for c in 0..3 {
                let v = tri[c] + 1;
                let has_n = mesh.normals.is_some();
                match (corner_vt.get(f), has_n) {
                    (Some(t), true) => write!(w, " {v}/{}/{v}", t[c] + 1)?,
                    (Some(t), false) => write!(w, " {v}/{}", t[c] + 1)?,
                    (None, true) => write!(w, " {v}//{v}")?,
                    (None, false) => write!(w, " {v}")?,
                }
            }
            writeln!(w)?;
        }
        Ok(())
    })
}
