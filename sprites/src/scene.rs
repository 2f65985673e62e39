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
//!       "attributes": [], "spin": 90, "cycle": [0, 1], "cycle_fps": 4,
//!       "keys": [{ "t": 0 }, { "t": 2, "center": [0.2, 0, 0.98], "normal": [0.2, 0, 1],
//!                  "size": [0.4, 0.4], "rotation": 120 }] }
//!   ]
//! }
//! ```
//! Everything but `patterns` and `sprites` is optional (defaults: [`TreeConfig::default`],
//! [`BlendConfig::default`], bounds = the mesh's bounding cube grown by 5%). Per sprite only
//! `center`, `normal` and `size` are required: `up` defaults to +z (+y when the normal is
//! along z), `depth` to half the larger side, `rotation` (degrees about the normal) to 0,
//! `pattern` to 0, `order` to 0 (larger on top, ties by position in the list), `blend` to
//! `over` (`over`, `add`, `blobby`, `voronoi`). Animation: `spin` (degrees per second about
//! the normal) and `cycle` (pattern ids shown in turn, `cycle_fps` per second), and `keys`:
//! keyframes of `center`, `normal`, `size` and `rotation` at times `t` (seconds, strictly
//! increasing), each field optional (missing: the sprite's own value). Between two keys the
//! centre, size and rotation are interpolated linearly and the normal by normalised lerp of
//! the unit normals; before the first key and after the last the state is held; spin adds
//! on top of the keyed rotation ([`SpriteSpec::keyed_at`]). Pattern paths are relative to
//! the JSON file. Unknown fields are errors, and every error names the sprite (its index in
//! the list), the key (`sprite 3, key 1: ...`) or the pattern.
//!
//! Animation changes sprite parameters only: [`Scene::update`] moves a tree built at one time
//! to another time with [`SpriteTree::update`] per sprite (section 5.2 of the sprites paper),
//! which keeps the tree minimal, instead of building it again.

use std::path::{Path, PathBuf};

use crate::blend::BlendConfig;
use crate::error::{Result, SpriteError};
use crate::pattern::Pattern;
use crate::sprite::{BlendMode, Placement, Sprite, add, cross, dot, norm, normalize, scale};
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
    /// Keyframes, sorted by `t` (strictly increasing); empty: the sprite does not move.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keys: Vec<Key>,
}

/// One keyframe of a sprite: its centre, normal, size and rotation at time `t` (seconds).
/// A missing field takes the sprite's own value, so a key can animate one parameter only.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Key {
    pub t: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<f64>,
}

/// The parameters keys animate, at one time ([`SpriteSpec::keyed_at`]); `rotation` in
/// degrees, spin not included.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyedState {
    pub center: [f64; 3],
    pub normal: [f64; 3],
    pub size: [f64; 2],
    pub rotation: f64,
}

/// What [`Scene::update`] did to a tree.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct UpdateReport {
    /// Sprites moved, turned or scaled through [`SpriteTree::update`].
    pub updated: usize,
    /// Sprites whose pattern alone changed (pattern cycling: no tree change).
    pub repatterned: usize,
    /// Whether an update failed and the tree was built again instead (see [`Scene::update`]).
    pub rebuilt: bool,
}

fn over() -> BlendMode {
    BlendMode::Over
}
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl SpriteSpec {
    /// The values of key `k`, missing fields taken from the sprite.
    fn key_state(&self, k: &Key) -> KeyedState {
        KeyedState {
            center: k.center.unwrap_or(self.center),
            normal: k.normal.unwrap_or(self.normal),
            size: k.size.unwrap_or(self.size),
            rotation: k.rotation.unwrap_or(self.rotation),
        }
    }

    /// Centre, normal, size and rotation at time `t` (seconds): the sprite's own values
    /// without keys; else held before the first key and after the last, and between keys
    /// `a`, `b` at `s = (t - t_a) / (t_b - t_a)`: `(1 - s) a + s b` for the centre, size and
    /// rotation (degrees, not wrapped: 0 to 720 turns twice), the normalised lerp of the
    /// unit normals for the normal. At a key's time the state is the key's values exactly
    /// (`s = 0` picks key `a` as written), so a keyed sprite there is the still sprite with
    /// those values.
    pub fn keyed_at(&self, t: f64) -> KeyedState {
        let (Some(first), Some(last)) = (self.keys.first(), self.keys.last()) else {
            return self.key_state(&Key::default());
        };
        // NaN times hold the first key, as times before it.
        if t.is_nan() || t <= first.t {
            return self.key_state(first);
        }
        if t >= last.t {
            return self.key_state(last);
        }
        // The last key at or before t (keys are sorted, first.t < t < last.t).
        let j = self.keys.partition_point(|k| k.t <= t) - 1;
        let (ka, kb) = (&self.keys[j], &self.keys[j + 1]);
        let (a, b) = (self.key_state(ka), self.key_state(kb));
        let s = (t - ka.t) / (kb.t - ka.t);
        if s == 0.0 {
            return a;
        }
        // (1 - s) a + s b rather than a + s (b - a): it stays finite for any finite a, b.
        let lerp = |x: f64, y: f64| (1.0 - s) * x + s * y;
        let normal = match (normalize(a.normal), normalize(b.normal)) {
            (Some(na), Some(nb)) => {
                let m = [0, 1, 2].map(|i| lerp(na[i], nb[i]));
                normalize(m).unwrap_or(m)
            }
            // Unchecked specs only (check() refuses zero normals): the frame will say so.
            _ => [0, 1, 2].map(|i| lerp(a.normal[i], b.normal[i])),
        };
        KeyedState {
            center: [0, 1, 2].map(|i| lerp(a.center[i], b.center[i])),
            normal,
            size: [0, 1].map(|i| lerp(a.size[i], b.size[i])),
            rotation: lerp(a.rotation, b.rotation),
        }
    }

    /// The sprite at time `t` (seconds): keys, spin (on top of the keyed rotation) and
    /// pattern cycling applied. `up` and `depth` defaults follow the keyed normal and size,
    /// as for a still sprite with those values.
    pub fn at_time(&self, t: f64) -> std::result::Result<Sprite, String> {
        let k = self.keyed_at(t);
        let up = self.up.unwrap_or(default_up(k.normal));
        let depth = self.depth.unwrap_or(0.5 * k.size[0].max(k.size[1]));
        let pattern = if self.cycle.is_empty() {
            self.pattern
        } else {
            let k = (t * self.cycle_fps).floor();
            let k = if k.is_finite() { k as i64 } else { 0 };
            self.cycle[k.rem_euclid(self.cycle.len() as i64) as usize]
        };
        let mut s = Sprite::placed(
            &Placement {
                center: k.center,
                normal: k.normal,
                up,
                size: k.size,
                depth,
                rotation_deg: k.rotation + self.spin * t,
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

    /// Checks the sprite as [`Scene::parse`] does; `index` (its place in the list) starts
    /// every message, with the key's index for a bad key (`sprite 3, key 1: ...`).
    pub fn check(&self, index: usize, patterns: usize) -> std::result::Result<(), String> {
        let i = index;
        if self.pattern as usize >= patterns || self.cycle.iter().any(|&p| p as usize >= patterns) {
            return Err(format!(
                "sprite {i}: pattern {} does not exist ({patterns} patterns)",
                self.cycle
                    .iter()
                    .copied()
                    .max()
                    .unwrap_or(0)
                    .max(self.pattern),
            ));
        }
        if !(self.spin.is_finite() && self.cycle_fps.is_finite() && self.cycle_fps >= 0.0) {
            return Err(format!(
                "sprite {i}: spin and cycle_fps must be finite, cycle_fps >= 0"
            ));
        }
        // The sprite's own values stand for every field a key leaves out.
        let still = SpriteSpec {
            keys: Vec::new(),
            ..self.clone()
        };
        still.at_time(0.0).map_err(|m| format!("sprite {i}: {m}"))?;
        let mut prev: Option<(&Key, KeyedState)> = None;
        for (k, key) in self.keys.iter().enumerate() {
            let bad = |m: String| Err(format!("sprite {i}, key {k}: {m}"));
            if !key.t.is_finite() {
                return bad(format!("t {} is not finite", key.t));
            }
            if let Some((p, _)) = prev
                && key.t <= p.t
            {
                return bad(format!(
                    "t {} is not after key {}'s t {}: keys must be sorted by t, strictly increasing",
                    key.t,
                    k - 1,
                    p.t
                ));
            }
            let st = self.key_state(key);
            let all = st.center.iter().chain(&st.normal).chain(&st.size);
            if all.chain([&st.rotation]).any(|v| !v.is_finite()) {
                return bad(
                    "center, normal, size and rotation must be finite (NaN or infinite)".into(),
                );
            }
            if st.size.iter().any(|&v| v <= 0.0) {
                return bad(format!("size {:?} must be positive", st.size));
            }
            let Some(n) = normalize(st.normal) else {
                return bad("the normal has zero length".into());
            };
            // The still sprite with the key's values (up, depth, the frame).
            SpriteSpec {
                center: st.center,
                normal: st.normal,
                size: st.size,
                rotation: st.rotation,
                ..still.clone()
            }
            .at_time(0.0)
            .map_err(|m| format!("sprite {i}, key {k}: {m}"))?;
            if let Some((_, ps)) = prev {
                let pn = normalize(ps.normal).expect("checked at the previous key");
                // The normalised lerp of opposite normals vanishes half-way.
                if norm(add(pn, n)) < 1e-6 {
                    return bad(format!(
                        "the normal is opposite to key {}'s: the interpolated normal would vanish",
                        k - 1
                    ));
                }
                // An explicit up must not meet the normal on its way between the keys.
                if let Some(up) = self.up.and_then(normalize)
                    && (on_arc(pn, n, up) || on_arc(pn, n, scale(up, -1.0)))
                {
                    return bad(format!(
                        "up is parallel to the normal between keys {} and {k}",
                        k - 1
                    ));
                }
            }
            prev = Some((key, st));
        }
        Ok(())
    }
}

/// `up` when the sprite gives none: +z, or +y for normals along z.
fn default_up(normal: [f64; 3]) -> [f64; 3] {
    if normal[0] == 0.0 && normal[1] == 0.0 {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// Whether unit `u` lies (up to rounding) on the shorter great-circle arc from unit `a` to
/// unit `b` (not opposite), the path of their normalised lerp.
fn on_arc(a: [f64; 3], b: [f64; 3], u: [f64; 3]) -> bool {
    let c = cross(a, b);
    let lc = norm(c);
    if lc < 1e-12 {
        return norm(cross(a, u)) < 1e-9 && dot(a, u) > 0.0;
    }
    dot(c, u).abs() <= 1e-9 * lc && dot(cross(a, u), c) >= 0.0 && dot(cross(u, b), c) >= 0.0
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
            // Keys one by one first, so that a key's unknown field or bad type names the key.
            if let Some(keys) = v.get("keys").and_then(|k| k.as_array()) {
                for (k, key) in keys.iter().enumerate() {
                    serde_json::from_value::<Key>(key.clone())
                        .map_err(|e| format!("sprite {i}, key {k}: {e}"))?;
                }
            }
            let spec: SpriteSpec =
                serde_json::from_value(v).map_err(|e| format!("sprite {i}: {e}"))?;
            spec.check(i, file.patterns.len())?;
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
    /// bounds. Errors name the sprite (its index in the file). Sprite `i` gets id `i`, which
    /// [`Scene::update`] relies on.
    pub fn build(&self, lo: [f64; 3], hi: [f64; 3], t: f64) -> Result<SpriteTree> {
        let (min, size) = match &self.bounds {
            Some(b) => (b.min, b.size),
            None => SpriteTree::cube_around(lo, hi, 0.05),
        };
        self.build_in(min, size, t)
    }

    /// The tree of the scene at time `t` over the cube `[min, min + size]^3`.
    fn build_in(&self, min: [f64; 3], size: f64, t: f64) -> Result<SpriteTree> {
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

    /// Moves `tree`, built by [`Scene::build`] of this scene at some time, to time `t`:
    /// animation changes sprite parameters, not the tree's construction, so each sprite
    /// whose frame changed goes through [`SpriteTree::update`] (section 5.2 of the sprites
    /// paper: removal collapses the cells that no longer need splitting, insertion splits
    /// the ones that do), which keeps the tree minimal; one whose pattern alone changed
    /// gets [`SpriteTree::set_pattern`]; the others are left alone. Lookups then equal those
    /// of a tree built at `t`.
    ///
    /// The paper's insertion test depends on the order of insertion, so an update can fail
    /// ("O_max too small") where a tree built from scratch at `t` succeeds; the tree is then
    /// built again at `t` (`rebuilt` in the report), and only that build's error is returned.
    /// Every sprite at `t` is checked before the tree changes: a bad sprite leaves it as it
    /// was.
    pub fn update(&self, tree: &mut SpriteTree, t: f64) -> Result<UpdateReport> {
        let sprites = self.sprites_at(t)?;
        if tree.len() != sprites.len() || tree.ids().zip(0..).any(|(id, i)| id != i) {
            return Err(SpriteError::Input(format!(
                "the tree holds {} sprites, not the scene's {} with ids 0..{}: build it with Scene::build",
                tree.len(),
                sprites.len(),
                sprites.len()
            )));
        }
        let mut report = UpdateReport::default();
        for (id, s) in sprites.into_iter().enumerate() {
            let old = tree.sprite(id).expect("ids checked");
            if *old == s {
                continue;
            }
            if *old
                == (Sprite {
                    pattern: old.pattern,
                    ..s.clone()
                })
            {
                tree.set_pattern(id, s.pattern)?;
                report.repatterned += 1;
                continue;
            }
            match tree.update(id, s) {
                Ok(()) => report.updated += 1,
                Err(SpriteError::OmaxTooSmall { .. } | SpriteError::MaxDepth { .. }) => {
                    let (min, size) = tree.cube();
                    *tree = self.build_in(min, size, t)?;
                    report.rebuilt = true;
                    return Ok(report);
                }
                Err(e) => return Err(e),
            }
        }
        Ok(report)
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

    /// A still sprite with the given keyed values (and the rest of `spec`).
    fn still(spec: &SpriteSpec, k: KeyedState) -> SpriteSpec {
        SpriteSpec {
            center: k.center,
            normal: k.normal,
            size: k.size,
            rotation: k.rotation,
            keys: Vec::new(),
            ..spec.clone()
        }
    }

    fn close(a: &Sprite, b: &Sprite) -> bool {
        let v = |s: &Sprite| [s.center, s.l, s.h, s.n].concat();
        v(a).iter().zip(v(b)).all(|(x, y)| (x - y).abs() < 1e-12)
            && (a.pattern, a.order, a.blend) == (b.pattern, b.order, b.blend)
    }

    #[test]
    fn keyed_sprites_equal_their_keys_lerp_between_and_hold_outside() {
        let dir = tempfile::tempdir().unwrap();
        write_pattern(dir.path());
        let text = r#"{"patterns": ["p.png", "p.png"], "sprites": [
            {"center": [0, 0, 1], "normal": [0, 0, 1], "size": [0.3, 0.2], "rotation": 10,
             "spin": 30, "cycle": [0, 1], "cycle_fps": 1, "keys": [
               {"t": 1, "center": [0.1, 0, 1], "rotation": 20},
               {"t": 3, "center": [0.5, 0.2, 0.8], "normal": [1, 0, 1], "size": [0.5, 0.4],
                "rotation": 100},
               {"t": 4, "size": [0.2, 0.25]}]}]}"#;
        let scene = Scene::parse(text, dir.path()).unwrap();
        let spec = &scene.sprites[0];
        let at = |t: f64| scene.sprites_at(t).unwrap().remove(0);
        let base = KeyedState {
            center: [0.0, 0.0, 1.0],
            normal: [0.0, 0.0, 1.0],
            size: [0.3, 0.2],
            rotation: 10.0,
        };
        // The keys' values, missing fields from the sprite (key 2 keeps the base centre,
        // normal and rotation).
        let k0 = KeyedState {
            center: [0.1, 0.0, 1.0],
            rotation: 20.0,
            ..base
        };
        let k1 = KeyedState {
            center: [0.5, 0.2, 0.8],
            normal: [1.0, 0.0, 1.0],
            size: [0.5, 0.4],
            rotation: 100.0,
        };
        let k2 = KeyedState {
            size: [0.2, 0.25],
            ..base
        };
        for (t, k) in [(1.0, k0), (3.0, k1), (4.0, k2)] {
            assert_eq!(spec.keyed_at(t), k, "t = {t}");
            // Exactly the still sprite with the key's values (spin and cycle on top).
            assert_eq!(at(t), still(spec, k).at_time(t).unwrap(), "t = {t}");
        }
        // Held before the first key and after the last; spin still turns the sprite.
        for t in [0.0, -5.0, f64::NAN] {
            assert_eq!(spec.keyed_at(t), k0, "t = {t}");
        }
        assert_eq!(spec.keyed_at(10.0), k2);
        assert_eq!(at(10.0), still(spec, k2).at_time(10.0).unwrap());
        assert_ne!(at(10.0), at(4.0), "spin turns after the last key");
        // A quarter of the way from key 0 to key 1 (not half-way, which would not tell the
        // keys apart): lerp of centre, size, rotation; normalised lerp of the unit normals.
        let s = 0.25;
        let lerp = |a: f64, b: f64| (1.0 - s) * a + s * b;
        let r = std::f64::consts::FRAC_1_SQRT_2;
        let n = [lerp(0.0, r), 0.0, lerp(1.0, r)];
        let ln = (n[0] * n[0] + n[2] * n[2]).sqrt();
        let mid = KeyedState {
            center: [lerp(0.1, 0.5), lerp(0.0, 0.2), lerp(1.0, 0.8)],
            normal: [n[0] / ln, 0.0, n[2] / ln],
            size: [lerp(0.3, 0.5), lerp(0.2, 0.4)],
            rotation: lerp(20.0, 100.0),
        };
        let got = spec.keyed_at(1.5);
        let v = |k: &KeyedState| [&k.center[..], &k.normal, &k.size, &[k.rotation]].concat();
        for (a, b) in v(&got).iter().zip(v(&mid)) {
            assert!((a - b).abs() < 1e-12, "{got:?} vs {mid:?}");
        }
        assert!(close(&at(1.5), &still(spec, mid).at_time(1.5).unwrap()));
        // Between keys 1 and 2 the centre goes back to the base value.
        let c = spec.keyed_at(3.5).center;
        assert!(
            (c[0] - 0.25).abs() < 1e-12 && (c[2] - 0.9).abs() < 1e-12,
            "{c:?}"
        );
        // Pattern cycling works as without keys.
        assert_eq!((at(1.5).pattern, at(2.5).pattern), (1, 0));
    }

    #[test]
    fn bad_keys_name_the_sprite_and_the_key() {
        let dir = tempfile::tempdir().unwrap();
        write_pattern(dir.path());
        let with_keys = |keys: &str, up: &str| {
            scene(&format!(
                r#"{{"center": [0, 1, 0], "normal": [0, 1, 0], "size": [0.3, 0.2]{up}, "keys": [{keys}]}}"#
            ))
        };
        let ok = with_keys(r#"{"t": 0}, {"t": 1, "normal": [1, 1, 0]}"#, "");
        assert_eq!(
            Scene::parse(&ok, dir.path()).unwrap().sprites[1].keys.len(),
            2
        );
        let cases = [
            (
                r#"{"t": 0}, {"t": 2}, {"t": 1}"#,
                "",
                "sprite 1, key 2: t 1 is not after key 1's t 2",
            ),
            (
                r#"{"t": 0}, {"t": 0}"#,
                "",
                "sprite 1, key 1: t 0 is not after",
            ),
            (
                r#"{"t": 0, "size": [0.0, 0.2]}"#,
                "",
                "sprite 1, key 0: size [0.0, 0.2] must be positive",
            ),
            (
                r#"{"t": 0}, {"t": 1, "size": [0.1, -1]}"#,
                "",
                "sprite 1, key 1: size [0.1, -1.0] must be positive",
            ),
            (
                r#"{"t": 0}, {"t": 1, "colour": 3}"#,
                "",
                "sprite 1, key 1: unknown field `colour`",
            ),
            (
                r#"{"center": [0, 1, 0]}"#,
                "",
                "sprite 1, key 0: missing field `t`",
            ),
            (
                r#"{"t": 0}, {"t": 1, "normal": [0, 0, 0]}"#,
                "",
                "sprite 1, key 1: the normal has zero length",
            ),
            (
                r#"{"t": 0}, {"t": 1, "normal": [0, -2, 0]}"#,
                "",
                "sprite 1, key 1: the normal is opposite to key 0's",
            ),
            (
                r#"{"t": 0, "normal": [1, 0, 1]}, {"t": 1, "normal": [-1, 0, 1]}"#,
                r#", "up": [0, 0, 1]"#,
                "sprite 1, key 1: up is parallel to the normal between keys 0 and 1",
            ),
            (
                r#"{"t": 0, "normal": [0, 0, 1]}"#,
                r#", "up": [0, 0, 1]"#,
                "sprite 1, key 0: up is parallel to the normal",
            ),
        ];
        for (keys, up, expect) in cases {
            let e = Scene::parse(&with_keys(keys, up), dir.path()).unwrap_err();
            assert!(e.contains(expect), "{e} does not say {expect}");
        }
        // JSON has no NaN: a program's spec with a NaN centre in a key.
        let mut spec = Scene::parse(&ok, dir.path()).unwrap().sprites.remove(1);
        spec.keys[1].center = Some([f64::NAN, 1.0, 0.0]);
        let e = spec.check(1, 1).unwrap_err();
        assert!(
            e.starts_with("sprite 1, key 1: center, normal, size and rotation must be finite"),
            "{e}"
        );
        spec.keys[1].center = None;
        spec.keys[1].t = f64::INFINITY;
        let e = spec.check(1, 1).unwrap_err();
        assert!(e.starts_with("sprite 1, key 1: t inf is not finite"), "{e}");
    }
}
