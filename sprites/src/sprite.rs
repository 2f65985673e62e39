//! The sprite parameter table (section 5.1) and each sprite's positioning (section 5.3).
//!
//! A sprite projects its pattern onto the surface along its frame `M = (l, h, n)`: a surface
//! point `P` has pattern-space coordinates `U = M^-1 (P - c)` (section 5.3), `u` along `l`,
//! `v` along `h`, `w` along `n`. The pattern square is `u, v in [-1/2, 1/2]` (pattern
//! coordinates `s = u + 1/2` to the right, `t = 1/2 - v` down) and the sprite only applies in
//! the slab `|w| <= 1/2`: the length of `n` is the thickness that separates close folds of
//! the surface (the paper's `w`). The bounding volume `V` is that parallelepiped,
//! `c + M [-1/2, 1/2]^3`.

use crate::error::{Result, SpriteError};

/// How a sprite combines with the sprites below it (section 5.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BlendMode {
    /// Ordered transparency ("over" compositing), the usual decal behaviour.
    Over,
    /// Premultiplied colours add up (glows, light spots), clamped to 1.
    Add,
    /// Blobby painting: the pattern alpha is a tabulated distance; the alpha of consecutive
    /// blobby sprites sums into an implicit field, thresholded into a smooth surface.
    Blobby,
    /// Voronoi / cellular: of consecutive Voronoi sprites, the closest (largest tabulated
    /// alpha) gives its colour (Worley 1996).
    Voronoi,
}

impl BlendMode {
    pub const ALL: [BlendMode; 4] = [
        BlendMode::Over,
        BlendMode::Add,
        BlendMode::Blobby,
        BlendMode::Voronoi,
    ];
}

/// One sprite's parameters as the user gives them (world units).
#[derive(Clone, Debug, PartialEq)]
pub struct Sprite {
    /// Centre `c` (the sprite handle).
    pub center: [f64; 3],
    /// Frame `l` (pattern width direction and size), `h` (pattern height), `n` (projection
    /// direction and slab thickness).
    pub l: [f64; 3],
    pub h: [f64; 3],
    pub n: [f64; 3],
    /// Index into the pattern table.
    pub pattern: u32,
    /// User order: larger is drawn on top; ties go to the larger id.
    pub order: i64,
    pub blend: BlendMode,
    /// Free user attributes (stored, not interpreted).
    pub attributes: Vec<f32>,
}

/// How a sprite is placed on a surface, the usual way of making one.
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    pub center: [f64; 3],
    /// Surface normal at the centre (projection direction); need not be unit.
    pub normal: [f64; 3],
    /// A direction the pattern's "up" leans towards; need not be unit or tangent.
    pub up: [f64; 3],
    /// Pattern width and height (world units).
    pub size: [f64; 2],
    /// Slab thickness along the normal (world units).
    pub depth: f64,
    /// Rotation of the pattern about the normal, degrees counter-clockwise.
    pub rotation_deg: f64,
}

impl Sprite {
    /// The frame of a placement: `n` along the normal (length `depth`), `l` and `h` in the
    /// tangent plane, rotated by `rotation_deg` from the projection of `up`.
    pub fn placed(p: &Placement, pattern: u32, order: i64, blend: BlendMode) -> Result<Sprite> {
        let bad = |m: String| SpriteError::Sprite {
            index: usize::MAX,
            message: m,
        };
        let all = p
            .center
            .iter()
            .chain(&p.normal)
            .chain(&p.up)
            .chain(&p.size)
            .chain([&p.depth, &p.rotation_deg]);
        if all.clone().any(|v| !v.is_finite()) {
            return Err(bad("a parameter is not finite (NaN or infinite)".into()));
        }
        if p.size.iter().any(|&s| s <= 0.0) || p.depth <= 0.0 {
            return Err(bad(format!(
                "size {:?} and depth {} must be positive",
                p.size, p.depth
            )));
        }
        let n = normalize(p.normal).ok_or_else(|| bad("the normal has zero length".into()))?;
        let up = sub(p.up, scale(n, dot(p.up, n)));
        let t = normalize(up).ok_or_else(|| bad("up is parallel to the normal".into()))?;
        // Right-handed tangent frame (x, t, n) with x = t x n, rotated about n.
        let (s, c) = p.rotation_deg.to_radians().sin_cos();
        let x_axis = cross(t, n);
        let x = add(scale(x_axis, c), scale(t, s));
        let y = add(scale(x_axis, -s), scale(t, c));
        Ok(Sprite {
            center: p.center,
            l: scale(x, p.size[0]),
            h: scale(y, p.size[1]),
            n: scale(n, p.depth),
            pattern,
            order,
            blend,
            attributes: Vec::new(),
        })
    }

    /// Checks the frame (finite, invertible) and the pattern index.
    pub fn check(&self, patterns: usize) -> std::result::Result<(), String> {
        let vals = self
            .center
            .iter()
            .chain(&self.l)
            .chain(&self.h)
            .chain(&self.n);
        if vals.clone().any(|v| !v.is_finite()) {
            return Err("the centre or frame is not finite (NaN or infinite)".into());
        }
        let det = dot(self.l, cross(self.h, self.n));
        let scale = norm(self.l) * norm(self.h) * norm(self.n);
        if scale == 0.0 || det.abs() <= 1e-9 * scale || det.is_nan() {
            return Err("the frame (l, h, n) is degenerate: zero size or flat".into());
        }
        if self.pattern as usize >= patterns {
            return Err(format!(
                "pattern {} does not exist ({patterns} patterns)",
                self.pattern
            ));
        }
        if self.attributes.iter().any(|a| !a.is_finite()) {
            return Err("an attribute is not finite".into());
        }
        Ok(())
    }

    /// `M^-1` as rows (f64).
    pub fn inverse_frame(&self) -> [[f64; 3]; 3] {
        let (l, h, n) = (self.l, self.h, self.n);
        let det = dot(l, cross(h, n));
        // Rows of the inverse of the column matrix (l h n) are the cross products / det.
        [
            scale(cross(h, n), 1.0 / det),
            scale(cross(n, l), 1.0 / det),
            scale(cross(l, h), 1.0 / det),
        ]
    }

    /// The eight corners of the bounding volume, grown by the relative margin `grow`.
    pub fn corners(&self, grow: f64) -> [[f64; 3]; 8] {
        let k = 0.5 * (1.0 + grow);
        std::array::from_fn(|i| {
            let su = if i & 1 == 0 { -k } else { k };
            let sv = if i & 2 == 0 { -k } else { k };
            let sw = if i & 4 == 0 { -k } else { k };
            add(
                self.center,
                add(scale(self.l, su), add(scale(self.h, sv), scale(self.n, sw))),
            )
        })
    }

    /// Axis-aligned bounds of the bounding volume.
    pub fn aabb(&self, grow: f64) -> ([f64; 3], [f64; 3]) {
        let c = self.corners(grow);
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in c {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    }

    /// Area of the pattern square (world units squared).
    pub fn area(&self) -> f64 {
        norm(cross(self.l, self.h))
    }
}

/// What a lookup needs of a sprite, in f32 (the GPU's sprite parameter table row).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prepared {
    pub center: [f32; 3],
    /// Rows of `M^-1`.
    pub inv: [[f32; 3]; 3],
    /// Unit projection direction (for the attenuation by the angle to the surface normal).
    pub normal: [f32; 3],
    pub pattern: u32,
    pub blend: BlendMode,
}

impl Prepared {
    pub fn new(s: &Sprite) -> Prepared {
        let inv = s.inverse_frame();
        let n = normalize(s.n).unwrap_or([0.0, 0.0, 1.0]);
        Prepared {
            center: s.center.map(|v| v as f32),
            inv: inv.map(|r| r.map(|v| v as f32)),
            normal: n.map(|v| v as f32),
            pattern: s.pattern,
            blend: s.blend,
        }
    }

    /// `U = M^-1 (P - c)` (section 5.3).
    #[inline]
    pub fn local(&self, p: [f32; 3]) -> [f32; 3] {
        let d = [
            p[0] - self.center[0],
            p[1] - self.center[1],
            p[2] - self.center[2],
        ];
        let r = &self.inv;
        [
            r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
            r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
            r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
        ]
    }
}

// Small vector helpers (f64).
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(crate) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub(crate) fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
pub(crate) fn normalize(a: [f64; 3]) -> Option<[f64; 3]> {
    let l = norm(a);
    (l > 0.0 && l.is_finite()).then(|| scale(a, 1.0 / l))
}

/// Whether the parallelepiped `s` (grown by `grow`) meets the axis-aligned box `[lo, hi]`:
/// the separating-axis theorem with the 3 box normals, the 3 face normals of `s` and the 9
/// edge cross products (exact for two convex polyhedra).
pub fn meets_box(s: &Sprite, grow: f64, lo: [f64; 3], hi: [f64; 3]) -> bool {
    let corners = s.corners(grow);
    let box_corners: [[f64; 3]; 8] = std::array::from_fn(|i| {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]
    });
    let e = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let f = [s.l, s.h, s.n];
    let separated = |axis: [f64; 3]| {
        if dot(axis, axis) < 1e-30 {
            return false;
        }
        let (mut a0, mut a1) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in &corners {
            let d = dot(*p, axis);
            a0 = a0.min(d);
            a1 = a1.max(d);
        }
        let (mut b0, mut b1) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in &box_corners {
            let d = dot(*p, axis);
            b0 = b0.min(d);
            b1 = b1.max(d);
        }
        a1 < b0 || b1 < a0
    };
    // Box normals: compare the AABB first (cheapest).
    let (alo, ahi) = s.aabb(grow);
    if (0..3).any(|a| ahi[a] < lo[a] || hi[a] < alo[a]) {
        return false;
    }
    if [cross(f[0], f[1]), cross(f[1], f[2]), cross(f[2], f[0])]
        .into_iter()
        .any(separated)
    {
        return false;
    }
    for ea in e {
        for fb in f {
            if separated(cross(ea, fb)) {
                return false;
            }
        }
    }
    true
}

/// Half-spaces `a . x <= b` bounding a sprite's volume.
fn sprite_planes(s: &Sprite, out: &mut Vec<([f64; 3], f64)>) {
    let inv = s.inverse_frame();
    for r in inv {
        let rc = dot(r, s.center);
        out.push((r, 0.5 + rc));
        out.push((scale(r, -1.0), 0.5 - rc));
    }
}

/// Whether sprites `a` and `b` overlap inside the box `[lo, hi]` (three convex sets share a
/// point): the intersection of 18 half-spaces is bounded, so it is non-empty iff one of its
/// candidate vertices (any three planes) satisfies all of them.
pub fn overlap_in_box(a: &Sprite, b: &Sprite, lo: [f64; 3], hi: [f64; 3]) -> bool {
    let mut planes = Vec::with_capacity(18);
    sprite_planes(a, &mut planes);
    sprite_planes(b, &mut planes);
    for ax in 0..3 {
        let mut e = [0.0; 3];
        e[ax] = 1.0;
        planes.push((e, hi[ax]));
        planes.push((scale(e, -1.0), -lo[ax]));
    }
    // Tolerances relative to each plane's scale.
    let tol: Vec<f64> = planes
        .iter()
        .map(|(a, b)| {
            1e-9 * (norm(*a) * (1.0 + hi.iter().chain(&lo).fold(0f64, |m, v| m.max(v.abs()))))
                + 1e-12 * b.abs()
        })
        .collect();
    let k = planes.len();
    for i in 0..k {
        for j in i + 1..k {
            for l in j + 1..k {
                let (a0, a1, a2) = (planes[i].0, planes[j].0, planes[l].0);
                let det = dot(a0, cross(a1, a2));
                let sc = norm(a0) * norm(a1) * norm(a2);
                if det.abs() <= 1e-12 * sc {
                    continue;
                }
                // Cramer's rule.
                let (b0, b1, b2) = (planes[i].1, planes[j].1, planes[l].1);
                let x = scale(
                    add(
                        add(scale(cross(a1, a2), b0), scale(cross(a2, a0), b1)),
                        scale(cross(a0, a1), b2),
                    ),
                    1.0 / det,
                );
                if planes
                    .iter()
                    .zip(&tol)
                    .all(|((a, b), t)| dot(*a, x) <= b + t)
                {
                    return true;
                }
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(center: [f64; 3], size: f64) -> Sprite {
        Sprite::placed(
            &Placement {
                center,
                normal: [0.0, 0.0, 1.0],
                up: [0.0, 1.0, 0.0],
                size: [size, size],
                depth: 0.1,
                rotation_deg: 0.0,
            },
            0,
            0,
            BlendMode::Over,
        )
        .unwrap()
    }

    #[test]
    fn placement_builds_a_right_handed_frame_and_local_coordinates_invert_it() {
        let s = Sprite::placed(
            &Placement {
                center: [1.0, 2.0, 3.0],
                normal: [0.0, 0.0, 2.0],
                up: [0.0, 1.0, 0.5],
                size: [2.0, 1.0],
                depth: 0.2,
                rotation_deg: 90.0,
            },
            0,
            0,
            BlendMode::Over,
        )
        .unwrap();
        assert!(dot(s.l, cross(s.h, s.n)) > 0.0);
        // Rotated by 90 degrees: the width now runs along y, the height along -x.
        assert!((s.l[1] - 2.0).abs() < 1e-12 && (s.h[0] + 1.0).abs() < 1e-12);
        let p = Prepared::new(&s);
        let u = p.local([1.0 - 0.25, 2.0 + 0.5, 3.0 + 0.05]);
        assert!(
            (u[0] - 0.25).abs() < 1e-6 && (u[1] - 0.25).abs() < 1e-6 && (u[2] - 0.25).abs() < 1e-6,
            "{u:?}"
        );
    }

    #[test]
    fn box_and_pair_overlap_tests_agree_with_sampling() {
        let a = flat([0.0, 0.0, 0.0], 1.0);
        assert!(meets_box(&a, 0.0, [0.4, 0.4, -1.0], [1.0, 1.0, 1.0]));
        assert!(!meets_box(&a, 0.0, [0.6, 0.4, -1.0], [1.0, 1.0, 1.0]));
        assert!(!meets_box(&a, 0.0, [-1.0, -1.0, 0.06], [1.0, 1.0, 1.0]));
        // A sprite tilted by 45 degrees: its AABB meets the box corner, the sprite does not.
        let t = Sprite::placed(
            &Placement {
                center: [0.0; 3],
                normal: [1.0, 1.0, 0.0],
                up: [0.0, 0.0, 1.0],
                size: [1.0, 1.0],
                depth: 0.01,
                rotation_deg: 0.0,
            },
            0,
            0,
            BlendMode::Over,
        )
        .unwrap();
        assert!(!meets_box(&t, 0.0, [0.2, 0.2, -0.1], [0.4, 0.4, 0.1]));
        assert!(meets_box(&t, 0.0, [-0.1, -0.1, -0.1], [0.1, 0.1, 0.1]));
        let b = flat([0.9, 0.0, 0.0], 1.0);
        assert!(overlap_in_box(&a, &b, [-2.0; 3], [2.0; 3]));
        assert!(!overlap_in_box(&a, &b, [-2.0; 3], [0.3, 2.0, 2.0]));
        let c = flat([1.1, 0.0, 0.0], 1.0);
        assert!(!overlap_in_box(&a, &c, [-2.0; 3], [2.0; 3]));
    }

    #[test]
    fn bad_frames_are_refused() {
        let mut p = Placement {
            center: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            up: [0.0, 0.0, 1.0],
            size: [1.0, 1.0],
            depth: 0.1,
            rotation_deg: 0.0,
        };
        assert!(Sprite::placed(&p, 0, 0, BlendMode::Over).is_err());
        p.up = [0.0, 1.0, 0.0];
        p.size = [0.0, 1.0];
        assert!(Sprite::placed(&p, 0, 0, BlendMode::Over).is_err());
        p.size = [1.0, 1.0];
        p.center[1] = f64::NAN;
        assert!(Sprite::placed(&p, 0, 0, BlendMode::Over).is_err());
    }
}
