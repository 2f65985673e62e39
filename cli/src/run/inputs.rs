//! What `fresco run` is given, checked before anything is written, and the two entry points
//! for users' own data: a COLMAP model (`--colmap`) and a mesh (`--mesh`).
//!
//! Checks, each a clear error naming the path: the photo folder exists and holds at least two
//! photos; the workspace is not the photo folder nor inside it, is a new or empty folder or an
//! earlier workspace of `fresco run`, and can be written; `--colmap`, `--mesh`, `--masks`,
//! `--focal-file` exist; `--holdout` names photos of the folder. The photo folder is only ever
//! read.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use fresco_core::ply::PlyFormat;
use fresco_core::{Mesh, colmap};
use fresco_sfm::focal_prior::{FocalPrior, FocalSource};
use fresco_sfm::workspace::{IMAGES_VERSION, ImageEntry, ImageList, write_images};

/// File extensions read as photos (lower case).
const PHOTO_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg"];

fn is_photo(path: &Path) -> bool {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    path.is_file() && PHOTO_EXTENSIONS.contains(&ext.as_str())
}

/// The photos of `dir` (by extension, as `fresco features` takes them), sorted.
pub fn list_photos(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut photos = Vec::new();
    for entry in std::fs::read_dir(dir)
        .with_context(|| format!("cannot list the photo folder {}", dir.display()))?
    {
        let path = entry
            .with_context(|| format!("cannot list the photo folder {}", dir.display()))?
            .path();
        if is_photo(&path) {
            photos.push(path);
        }
    }
    photos.sort();
    Ok(photos)
}

/// The photos a COLMAP model refers to, in `photos`, each checked to exist.
pub fn colmap_photos(model: &Path, photos: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let rec = colmap::read_model(model)?;
    rec.images
        .values()
        .map(|im| {
            let p = photos.join(&im.name);
            if !p.is_file() {
                bail!(
                    "the COLMAP model {} has image {}, which is not in {}",
                    model.display(),
                    im.name,
                    photos.display()
                );
            }
            Ok(p)
        })
        .collect()
}

/// The canonical form of a folder that may not exist yet: its nearest existing ancestor made
/// canonical, with the rest appended.
fn canonical_maybe_new(path: &Path) -> PathBuf {
    let abs = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(path)
    };
    let mut rest = Vec::new();
    let mut cur = abs.as_path();
    loop {
        if let Ok(c) = cur.canonicalize() {
            let mut out = c;
            for part in rest.iter().rev() {
                out.push(part);
            }
            return out;
        }
        match (cur.parent(), cur.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                cur = parent;
            }
            _ => return abs,
        }
    }
}

/// The photo folder, checked, made canonical.
pub fn check_photos(photos: &Path) -> anyhow::Result<PathBuf> {
    if !photos.is_dir() {
        bail!("{} is not a folder of photos", photos.display());
    }
    let dir = photos
        .canonicalize()
        .with_context(|| format!("cannot read {}", photos.display()))?;
    let found = list_photos(&dir)?;
    if found.is_empty() {
        let others = std::fs::read_dir(&dir).map(|d| d.count()).unwrap_or(0);
        bail!(
            "no photos (.png, .jpg, .jpeg) in {}{}",
            photos.display(),
            if others > 0 {
                format!(" ({others} other files or folders)")
            } else {
                " (the folder is empty)".to_string()
            }
        );
    }
    if found.len() == 1 {
        bail!(
            "{} holds one photo ({}): a model needs at least two overlapping photos, better 10 or more taken around the object",
            photos.display(),
            found[0].file_name().unwrap_or_default().to_string_lossy()
        );
    }
    Ok(dir)
}

/// The workspace folder, checked and created, made canonical. It must not be (or be inside)
/// the photo folder, must be new, empty or an earlier `fresco run` workspace, and writable.
pub fn prepare_workspace(ws: &Path, photos: &Path) -> anyhow::Result<PathBuf> {
    let target = canonical_maybe_new(ws);
    if target == photos {
        bail!(
            "the output folder {} is the photo folder: fresco never writes into its input; choose another folder with -o",
            ws.display()
        );
    }
    if target.starts_with(photos) {
        bail!(
            "the output folder {} is inside the photo folder {}: fresco never writes into its input; choose a folder outside it",
            ws.display(),
            photos.display()
        );
    }
    if target.exists() && !target.is_dir() {
        bail!("the output {} exists and is not a folder", ws.display());
    }
    if target.is_dir() {
        let mut entries =
            std::fs::read_dir(&target).with_context(|| format!("cannot read {}", ws.display()))?;
        let empty = entries.next().is_none();
        if !empty && !target.join("stages").is_dir() {
            bail!(
                "the output folder {} is not empty and is not a workspace of `fresco run`; choose a new or empty folder",
                ws.display()
            );
        }
    }
    std::fs::create_dir_all(&target)
        .with_context(|| format!("cannot create the output folder {}", ws.display()))?;
    // Try a write now rather than fail after minutes of work.
    let probe = target.join(format!(".fresco-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("cannot write into the output folder {}", ws.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(target)
}

/// Removes the temporaries an interrupted run left (hidden `.*.tmp*` / `.*.old-*` entries)
/// in the workspace and its stage folders.
pub fn remove_temporaries(ws: &Path, folders: &[PathBuf]) {
    let mut dirs = vec![ws.to_path_buf()];
    dirs.extend(folders.iter().filter(|f| f.is_dir()).cloned());
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let path = entry.path();
            let stale = name.starts_with('.') && (name.contains(".tmp") || name.contains(".old-"));
            if stale {
                let _ = if path.is_dir() {
                    std::fs::remove_dir_all(&path)
                } else {
                    std::fs::remove_file(&path)
                };
            } else if path.is_dir() && dir != ws {
                dirs.push(path);
            }
        }
    }
}

/// `--holdout a.png,b.png`: the names, each checked to be a photo of the folder.
pub fn check_holdout(names: &[String], photos: &Path) -> anyhow::Result<Vec<String>> {
    let mut out: Vec<String> = Vec::new();
    for name in names.iter().map(|n| n.trim()).filter(|n| !n.is_empty()) {
        if !is_photo(&photos.join(name)) {
            bail!(
                "--holdout {name}: there is no photo of that name in {}",
                photos.display()
            );
        }
        if !out.iter().any(|o| o == name) {
            out.push(name.to_string());
        }
    }
    Ok(out)
}

/// An optional input path, checked to exist, made canonical.
pub fn check_path(
    option: &str,
    path: Option<&Path>,
    folder: bool,
) -> anyhow::Result<Option<PathBuf>> {
    let Some(p) = path else { return Ok(None) };
    let ok = if folder { p.is_dir() } else { p.is_file() };
    if !ok {
        bail!(
            "{option} {}: no such {}",
            p.display(),
            if folder { "folder" } else { "file" }
        );
    }
    Ok(Some(
        p.canonicalize()
            .with_context(|| format!("{option} {}", p.display()))?,
    ))
}

/// `--colmap`: reads a COLMAP model (text or binary), checks its photos against `photos`, and
/// writes the workspace's `images.json`, `sparse/0` (COLMAP text) and `sparse/points.ply` as
/// the sfm stage would.
pub fn import_colmap(model: &Path, photos: &Path, ws: &Path) -> anyhow::Result<serde_json::Value> {
    let rec = colmap::read_model(model)?;
    if rec.images.len() < 2 {
        bail!(
            "the COLMAP model {} has {} registered image(s); at least two are needed",
            model.display(),
            rec.images.len()
        );
    }
    let mut images = Vec::new();
    for im in rec.images.values() {
        let path = photos.join(&im.name);
        let cam = &rec.cameras[&im.camera_id];
        let (w, h) = image::image_dimensions(&path).with_context(|| {
            format!(
                "reading {} (image {} of the COLMAP model)",
                path.display(),
                im.name
            )
        })?;
        if (w, h) != (cam.width, cam.height) {
            bail!(
                "{} is {w}x{h} but camera {} of the COLMAP model {} is {}x{}",
                path.display(),
                cam.id,
                model.display(),
                cam.width,
                cam.height
            );
        }
        let pp = cam.principal_point();
        images.push(ImageEntry {
            id: im.id,
            name: im.name.clone(),
            path,
            width: w,
            height: h,
            num_keypoints: im.keypoints.len(),
            // The model's calibration, as trusted as a calibration file.
            prior: FocalPrior {
                focal_x: cam.focal_x(),
                focal_y: cam.focal_y(),
                cx: pp.x,
                cy: pp.y,
                source: FocalSource::CalibrationFile,
            },
            exif_orientation: None,
            camera_make: None,
            camera_model: None,
            contrast_threshold: None,
        });
    }
    write_images(
        ws,
        &ImageList {
            version: IMAGES_VERSION,
            images,
        },
    )?;
    let sparse = ws.join("sparse");
    std::fs::create_dir_all(&sparse).with_context(|| format!("creating {}", sparse.display()))?;
    let dir = sparse.join("0");
    let tmp = sparse.join(format!(".0.tmp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    colmap::write_text(&rec, &tmp)?;
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
    }
    std::fs::rename(&tmp, &dir).with_context(|| format!("writing {}", dir.display()))?;
    let mut cloud = Mesh::default();
    let mut colours = Vec::with_capacity(rec.points3d.len());
    for p in rec.points3d.values() {
        cloud.positions.push(p.position);
        colours.push(p.color);
    }
    cloud.colors = Some(colours);
    let points = sparse.join("points.ply");
    fresco_core::ply::write_mesh(&points, &cloud, PlyFormat::BinaryLittleEndian)?;
    Ok(serde_json::json!({
        "model": model,
        "format": format!("{:?}", colmap::detect_format(model)?),
        "registered": rec.images.len(),
        "cameras": rec.cameras.len(),
        "points": rec.points3d.len(),
        "mean_reprojection_px": rec.mean_reprojection_error().map(|(e, _)| e),
    }))
}

/// `--mesh`: the user's mesh (PLY or OBJ, in the frame of the cameras) as `<ws>/mesh.ply`.
pub fn import_mesh(path: &Path, ws: &Path) -> anyhow::Result<serde_json::Value> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let mut mesh = match ext.as_str() {
        "ply" => fresco_core::ply::read_mesh(path)?,
        "obj" => fresco_core::obj::read_mesh(path)?,
        _ => bail!("--mesh {}: expected a .ply or .obj mesh", path.display()),
    };
    if mesh.faces.is_empty() {
        bail!("--mesh {}: the file has no faces", path.display());
    }
    // Only the surface is kept: the unwrap stage gives it new texture coordinates.
    mesh.corner_uvs = None;
    mesh.face_textures = None;
    let out = ws.join("mesh.ply");
    fresco_core::ply::write_mesh(&out, &mesh, PlyFormat::BinaryLittleEndian)?;
    Ok(serde_json::json!({
        "input": path,
        "output": out,
        "faces": mesh.faces.len(),
        "vertices": mesh.positions.len(),
    }))
}
