//! The JSON sprite-scene format that `fresco sprites render` / `bake` read (documented in the
//! README, examples in `datasets/sprites/`).
//!
//! ```json
//! {
//!   "tree": { "n": 4, "o_max": 8, "max_depth": 10 },
//!   "blend": { "fade_start_deg": 60, "fade_end_deg": 85,
//!              "blobby_threshold": 0.5, "blobby_softness": 0.1 },
//!   "bounds": { "min": [-1.2, -1.2, -1.2], "size": 2.4 },
//!   "patterns": ["patterns/gear.png"],
//!   "sprites": [
//!     { "center": [0, 0, 1], "normal": [0, 0, 1], "up": [0, 1, 0], "size": [0.3, 0.3],
//!       "depth": 0.15, "rotation": 30, "pattern": 0, "order": 0, "blend": "over",
//!       "attributes": [], "spin": 90, "cycle": [0, 1], "cycle_fps": 4 }
//!   ]
//! }
//! ```
//! Everything but `patterns` and `sprites` is optional (defaults: [`TreeConfig::default`],
//! [`BlendConfig::default`], bounds = the mesh's bounding cube grown by 5%). Per sprite only
//! `center`, `normal` and `size` are required: `up` defaults to +z (+y when the normal is
//! along z), `depth` to half the larger side, `rotation` (degrees about the normal) to 0,
//! `pattern` to 0, `order` to 0 (larger on top, ties by position in the list), `blend` to
//! `over` (`over`, `add`, `blobby`, `voronoi`). Animation: `spin` (degrees per second about
//! the normal) and `cycle` (pattern ids shown in turn, `cycle_fps` per second). Pattern paths
//! are relative to the JSON file. Unknown fields are errors, and every error names the
//! sprite (its index in the list) or the pattern.

use std::path::{Path, PathBuf};

use crate::blend::BlendConfig;
use crate::error::{Result, SpriteError};
use crate::pattern::Pattern;
use crate::sprite::{BlendMode, Placement, Sprite};
use crate::tree::{SpriteTree, TreeConfig};

/// The file as written.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub tree: TreeConfig,
    #[serde(default)]
    pub blend: BlendSettings,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<Bounds>,
    pub patterns: Vec<String>,
    pub sprites: Vec<serde_json::Value>,
}

/// [`BlendConfig`] as JSON.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BlendSettings {
    pub fade_start_deg: f32,
    pub fade_end_deg: f32,
    pub blobby_threshold: f32,
    pub blobby_softness: f32,
}

impl Default for BlendSettings {
    fn default() -> Self {
        let b = BlendConfig::default();
        BlendSettings {
            fade_start_deg: b.fade_start_deg,
            fade_end_deg: b.fade_end_deg,
            blobby_threshold: b.blobby_threshold,
            blobby_softness: b.blobby_softness,
        }
    }
}

impl From<&BlendSettings> for BlendConfig {
    fn from(b: &BlendSettings) -> BlendConfig {
        BlendConfig {
            fade_start_deg: b.fade_start_deg,
            fade_end_deg: b.fade_end_deg,
            blobby_threshold: b.blobby_threshold,
            blobby_softness: b.blobby_softness,
        }
    }
}

/// The tree's cube.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bounds {
    pub min: [f64; 3],
    pub size: f64,
}

/// One sprite as written.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpriteSpec {
    pub center: [f64; 3],
    pub normal: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f64; 3]>,
    pub size: [f64; 2],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<f64>,
    #[serde(default)]
    pub rotation: f64,
    #[serde(default)]
    pub pattern: u32,
    #[serde(default)]
    pub order: i64,
    #[serde(default = "over")]
    pub blend: BlendMode,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub attributes: Vec<f32>,
    #[serde(default, skip_serializing_if = "is_zero")]
    pub spin: f64,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cycle: Vec<u32>,
    #[serde(default, skip_serializing_if = "is_zero")]
    pub cycle_fps: f64,
}

fn over() -> BlendMode {
    BlendMode::Over
}
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl SpriteSpec {
    /// The sprite at time `t` (seconds): spin and pattern cycling applied.
    pub fn at_time(&self, t: f64) -> std::result::Result<Sprite, String> {
        let up = self
            .up
            .unwrap_or(if self.normal[0] == 0.0 && self.normal[1] == 0.0 {
                [0.0, 1.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            });
        let depth = self.depth.unwrap_or(0.5 * self.size[0].max(self.size[1]));
        let pattern = if self.cycle.is_empty() {
            self.pattern
        } else {
            let k = (t * self.cycle_fps).floor();
            let k = if k.is_finite() { k as i64 } else { 0 };
            self.cycle[k.rem_euclid(self.cycle.len() as i64) as usize]
        };
        let mut s = Sprite::placed(
            &Placement {
                center: self.center,
                normal: self.normal,
                up,
                size: self.size,
                depth,
                rotation_deg: self.rotation + self.spin * t,
            },
            pattern,
            self.order,
            self.blend,
        )
        .map_err(|e| match e {
            SpriteError::Sprite { message, .. } => message,
            other => other.to_string(),
        })?;
        s.attributes = self.attributes.clone();
        Ok(s)
    }
}

/// A loaded scene: settings, patterns (decoded, with mip-maps) and sprites.
#[derive(Clone, Debug)]
pub struct Scene {
    pub tree: TreeConfig,
    pub blend: BlendConfig,
    pub bounds: Option<Bounds>,
    pub pattern_paths: Vec<PathBuf>,
    pub patterns: Vec<Pattern>,
    pub sprites: Vec<SpriteSpec>,
}

impl Scene {
    /// Reads and checks a scene file and its pattern images.
    pub fn load(path: &Path) -> Result<Scene> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SpriteError::Format(fresco_core::FormatError::io(path, e)))?;
        let base = path.parent().unwrap_or(Path::new("."));
        Scene::parse(&text, base).map_err(|message| SpriteError::Scene {
            path: path.to_path_buf(),
            message,
        })
    }

    /// Parses scene JSON whose pattern paths are relative to `base`; the error names the
    /// sprite or pattern.
    pub fn parse(text: &str, base: &Path) -> std::result::Result<Scene, String> {
        let file: SceneFile = serde_json::from_str(text).map_err(|e| e.to_string())?;
        let mut sprites = Vec::with_capacity(file.sprites.len());
        for (i, v) in file.sprites.into_iter().enumerate() {
            let spec: SpriteSpec =
                serde_json::from_value(v).map_err(|e| format!("sprite {i}: {e}"))?;
            if spec.pattern as usize >= file.patterns.len()
                || spec
                    .cycle
                    .iter()
                    .any(|&p| p as usize >= file.patterns.len())
            {
                return Err(format!(
                    "sprite {i}: pattern {} does not exist ({} patterns)",
                    spec.cycle
                        .iter()
                        .copied()
                        .max()
                        .unwrap_or(0)
                        .max(spec.pattern),
                    file.patterns.len()
                ));
            }
            if !(spec.spin.is_finite() && spec.cycle_fps.is_finite() && spec.cycle_fps >= 0.0) {
                return Err(format!(
                    "sprite {i}: spin and cycle_fps must be finite, cycle_fps >= 0"
                ));
            }
            spec.at_time(0.0).map_err(|m| format!("sprite {i}: {m}"))?;
            sprites.push(spec);
        }
        let blend = BlendConfig::from(&file.blend);
        file.tree.check().map_err(|e| e.to_string())?;
        blend.check().map_err(|e| e.to_string())?;
        if let Some(b) = &file.bounds
            && !(b.size > 0.0 && b.size.is_finite() && b.min.iter().all(|v| v.is_finite()))
        {
            return Err("bounds: size must be positive and everything finite".into());
        }
        let mut patterns = Vec::new();
        let mut pattern_paths = Vec::new();
        for (k, rel) in file.patterns.iter().enumerate() {
            let path = base.join(rel);
            let users = sprites
                .iter()
                .position(|s| s.pattern as usize == k || s.cycle.contains(&(k as u32)))
                .map_or(String::new(), |i| format!(", used by sprite {i}"));
            let img = image::open(&path)
                .map_err(|e| format!("pattern {k} ({}{users}): {e}", path.display()))?;
            if img.width() == 0 || img.height() == 0 {
                return Err(format!(
                    "pattern {k} ({}{users}): empty image",
                    path.display()
                ));
            }
            patterns.push(Pattern::new(&img.to_rgba8()));
            pattern_paths.push(path);
        }
        Ok(Scene {
            tree: file.tree,
            blend,
            bounds: file.bounds,
            pattern_paths,
            patterns,
            sprites,
        })
    }

    /// The sprites at time `t` (seconds).
    pub fn sprites_at(&self, t: f64) -> Result<Vec<Sprite>> {
        self.sprites
            .iter()
            .enumerate()
            .map(|(index, s)| {
                s.at_time(t)
                    .map_err(|message| SpriteError::Sprite { index, message })
            })
            .collect()
    }

    /// The tree of the scene at time `t`; `lo`, `hi` bound the surface when the scene has no
    /// bounds. Errors name the sprite (its index in the file).
    pub fn build(&self, lo: [f64; 3], hi: [f64; 3], t: f64) -> Result<SpriteTree> {
        let (min, size) = match &self.bounds {
            Some(b) => (b.min, b.size),
            None => SpriteTree::cube_around(lo, hi, 0.05),
        };
        let mut tree = SpriteTree::new(
            min,
            size,
            self.patterns.clone(),
            self.tree.clone(),
            &self.blend,
        )?;
        for s in self.sprites_at(t)? {
            tree.add(s)?;
        }
        Ok(tree)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_pattern(dir: &Path) {
        image::RgbaImage::from_pixel(4, 4, image::Rgba([255, 0, 0, 255]))
            .save(dir.join("p.png"))
            .unwrap();
    }

    fn scene(sprite: &str) -> String {
        format!(
            r#"{{"patterns": ["p.png"], "sprites": [
            {{"center": [0, 0, 1], "normal": [0, 0, 1], "size": [0.3, 0.3]}},
            {sprite}]}}"#
        )
    }

    #[test]
    fn bad_scenes_name_the_sprite_or_pattern() {
        let dir = tempfile::tempdir().unwrap();
        write_pattern(dir.path());
        let ok = r#"{"center": [0, 1, 0], "normal": [0, 1, 0], "size": [0.3, 0.2], "blend": "voronoi", "spin": 10}"#;
        let s = Scene::parse(&scene(ok), dir.path()).unwrap();
        assert_eq!(s.sprites.len(), 2);
        assert_eq!(s.sprites[1].blend, BlendMode::Voronoi);
        let cases = [
            (
                r#"{"center": [0, 1, 0], "normal": [0, 1, 0], "size": [0.3, 0.2], "colour": 3}"#,
                "sprite 1: unknown field `colour`",
            ),
            (
                r#"{"center": [0, 1, 0], "normal": [0, 0, 0], "size": [0.3, 0.2]}"#,
                "sprite 1: the normal has zero length",
            ),
            (
                r#"{"center": [0, 1, 0], "normal": [0, 1, 0], "size": [0.0, 0.2]}"#,
                "sprite 1: size [0.0, 0.2] and depth 0.1 must be positive",
            ),
            (
                r#"{"center": [0, 1, 0], "normal": [0, 1, 0], "size": [0.3, 0.2], "pattern": 4}"#,
                "sprite 1: pattern 4 does not exist",
            ),
            (
                r#"{"center": [0, 1, 0], "normal": [0, 1, 0], "size": [0.3, 0.2], "up": [0, 2, 0]}"#,
                "sprite 1: up is parallel to the normal",
            ),
            (
                r#"{"center": [0, 1e400, 0], "normal": [0, 1, 0], "size": [0.3, 0.2]}"#,
                "number out of range",
            ),
            (
                r#"{"center": [0, 1, 0], "normal": [0, 1, 0], "size": [0.3, 0.2], "blend": "multiply"}"#,
                "sprite 1: unknown variant `multiply`",
            ),
        ];
        for (sprite, expect) in cases {
            let e = Scene::parse(&scene(sprite), dir.path()).unwrap_err();
            assert!(e.contains(expect), "{e} does not say {expect}");
        }
        let missing = r#"{"patterns": ["p.png", "nope.png"], "sprites": [
            {"center": [0, 0, 1], "normal": [0, 0, 1], "size": [0.3, 0.3], "pattern": 1}]}"#;
        let e = Scene::parse(missing, dir.path()).unwrap_err();
        assert!(
            e.starts_with("pattern 1 (") && e.contains("used by sprite 0"),
            "{e}"
        );
        let e =
            Scene::parse(r#"{"patterns": [], "sprites": [], "extra": 1}"#, dir.path()).unwrap_err();
        assert!(e.contains("unknown field `extra`"), "{e}");
        let e = Scene::parse(
            r#"{"patterns": [], "sprites": [], "tree": {"n": 3}}"#,
            dir.path(),
        )
        .unwrap_err();
        assert!(e.contains("n: 3 must be 2, 4 or 8"), "{e}");
    }

    #[test]
    fn spin_and_cycling_change_the_sprite_over_time() {
        let dir = tempfile::tempdir().unwrap();
        write_pattern(dir.path());
        let text = r#"{"patterns": ["p.png", "p.png", "p.png"], "sprites": [
            {"center": [0, 0, 1], "normal": [0, 0, 1], "size": [0.4, 0.2], "spin": 90,
             "cycle": [2, 0, 1], "cycle_fps": 2}]}"#;
        let s = Scene::parse(text, dir.path()).unwrap();
        let a = s.sprites_at(0.0).unwrap().remove(0);
        let b = s.sprites_at(1.0).unwrap().remove(0);
        assert_eq!((a.pattern, b.pattern), (2, 1));
        // A quarter turn: the width direction l turned into the old height direction.
        let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
        assert!((dot(b.l, a.h) / (0.4 * 0.2) - 1.0).abs() < 1e-9);
    }
}
