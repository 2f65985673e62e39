//! Evaluation of the composite texture at a surface point from the sprites covering it
//! (sections 5.3, 5.4 and 6): positioning `U = M^-1 (P - c)`, attenuation by the angle between
//! the sprite and surface normals, pattern filtering from the screen-space footprint
//! ([`Pattern::filter_sq`], fixed point), and the blending modes. The tree lookup and the brute-force reference both call [`composite`]
//! with the sprites in the same order, so they agree to the bit.
//!
//! Blending, in user order (lowest first), on premultiplied RGBA:
//! - `over`: `acc = s + (1 - s.a) acc`;
//! - `add`: `acc = min(acc + s, 1)`;
//! - a run of consecutive `blobby` sprites sums its alphas into an implicit field `F` (the
//!   patterns' alpha is a tabulated distance function, section 5.4); the run's coverage is
//!   `smoothstep(T - d, T + d, F)` and its colour the alpha-weighted mean; composited over;
//! - a run of consecutive `voronoi` sprites keeps the colour of the sprite with the largest
//!   tabulated alpha (the closest centre), opaque; composited over.

use crate::pattern::Pattern;
use crate::sprite::{BlendMode, Prepared};

/// Settings of the evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct BlendConfig {
    /// Angle (degrees) between sprite and surface normals up to which a sprite has its full
    /// weight. Default 60.
    pub fade_start_deg: f32,
    /// Angle (degrees) at which the weight reaches zero (section 5.3: avoids projection
    /// stretching on steep surfaces and keeps sprites off back-facing folds). Default 85.
    pub fade_end_deg: f32,
    /// Iso-value of the blobby implicit field. Default 0.5.
    pub blobby_threshold: f32,
    /// Half-width of the smooth step around the iso-value. Default 0.1.
    pub blobby_softness: f32,
}

impl Default for BlendConfig {
    fn default() -> Self {
        BlendConfig {
            fade_start_deg: 60.0,
            fade_end_deg: 85.0,
            blobby_threshold: 0.5,
            blobby_softness: 0.1,
        }
    }
}

impl BlendConfig {
    /// Validates every field by name.
    pub fn check(&self) -> Result<(), crate::SpriteError> {
        let bad = |field, message: String| Err(crate::SpriteError::Config { field, message });
        if !(0.0..=180.0).contains(&self.fade_start_deg) {
            return bad(
                "fade_start_deg",
                format!("{} is outside [0, 180]", self.fade_start_deg),
            );
        }
        if !(self.fade_end_deg > self.fade_start_deg && self.fade_end_deg <= 180.0) {
            return bad(
                "fade_end_deg",
                format!("{} must be in (fade_start_deg, 180]", self.fade_end_deg),
            );
        }
        if !(self.blobby_threshold > 0.0 && self.blobby_threshold.is_finite()) {
            return bad(
                "blobby_threshold",
                format!("{} must be positive", self.blobby_threshold),
            );
        }
        if !(self.blobby_softness > 0.0 && self.blobby_softness < self.blobby_threshold) {
            return bad(
                "blobby_softness",
                format!("{} must be in (0, blobby_threshold)", self.blobby_softness),
            );
        }
        Ok(())
    }

    pub(crate) fn prepare(&self) -> Blend {
        Blend {
            cos_start: self.fade_start_deg.to_radians().cos(),
            cos_end: self.fade_end_deg.to_radians().cos(),
            lo: self.blobby_threshold - self.blobby_softness,
            inv_width: 0.5 / self.blobby_softness,
        }
    }
}

/// [`BlendConfig`] in the form the inner loop uses.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Blend {
    cos_start: f32,
    pub(crate) cos_end: f32,
    lo: f32,
    inv_width: f32,
}

impl Blend {
    /// `cos_start - cos_end`, the divisor of the attenuation.
    #[inline]
    pub(crate) fn fade_range(&self) -> f32 {
        self.cos_start - self.cos_end
    }
}

/// The surface's screen-space footprint at a point: world-space derivatives of the surface
/// point per pixel step in x and y (the rasteriser gives them, the paper's ddx/ddy).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    pub dpdx: [f32; 3],
    pub dpdy: [f32; 3],
}

/// A lookup: where, with which surface normal (None: no attenuation) and footprint (None:
/// bilinear in the patterns' finest level).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Query {
    pub p: [f32; 3],
    pub normal: Option<[f32; 3]>,
    pub footprint: Option<Footprint>,
}

/// Premultiplied RGBA of sprite `s` at the query, weighted by the attenuation, or `None`
/// when the point is outside its volume or the weight is zero. (`lookup.rs` evaluates the
/// same expressions for several queries at once in SIMD lanes, operation for operation, and
/// ends in the same [`shade`].)
#[inline]
pub(crate) fn contribution(
    s: &Prepared,
    patterns: &[Pattern],
    q: &Query,
    b: &Blend,
) -> Option<[f32; 4]> {
    let u = s.local(q.p);
    if u[0].abs() > 0.5 || u[1].abs() > 0.5 || u[2].abs() > 0.5 {
        return None;
    }
    let att = match q.normal {
        Some(n) => {
            let c = s.normal[0] * n[0] + s.normal[1] * n[1] + s.normal[2] * n[2];
            let w = (c - b.cos_end) / b.fade_range();
            if w <= 0.0 {
                return None;
            }
            w.min(1.0)
        }
        None => 1.0,
    };
    let pat = &patterns[s.pattern as usize];
    let rho2 = match &q.footprint {
        Some(f) => {
            let (w, h) = (pat.width() as f32, pat.height() as f32);
            let r = &s.inv;
            let d =
                |v: [f32; 3], row: usize| r[row][0] * v[0] + r[row][1] * v[1] + r[row][2] * v[2];
            let (ux, vx) = (d(f.dpdx, 0) * w, d(f.dpdx, 1) * h);
            let (uy, vy) = (d(f.dpdy, 0) * w, d(f.dpdy, 1) * h);
            (ux * ux + vx * vx).max(uy * uy + vy * vy)
        }
        None => 0.0,
    };
    Some(shade(pat, u[0], u[1], att, rho2))
}

/// The pattern at sprite coordinates (`u0`, `u1`) filtered for the squared footprint `rho2`
/// (level-0 texels), weighted by the attenuation `att`.
#[inline]
pub(crate) fn shade(pat: &Pattern, u0: f32, u1: f32, att: f32, rho2: f32) -> [f32; 4] {
    let c = pat.filter_sq(u0 + 0.5, 0.5 - u1, rho2);
    [c[0] * att, c[1] * att, c[2] * att, c[3] * att]
}

/// A run of blobby or Voronoi sprites being gathered.
enum Run {
    None,
    Blobby { field: f32, rgb: [f32; 3] },
    Voronoi { best: f32, rgb: [f32; 3] },
}

/// `acc = s + (1 - s.a) acc`: what [`Compositor::push`] does for an `over` sprite when no
/// run is pending.
#[inline]
pub(crate) fn over(acc: &mut [f32; 4], s: [f32; 4]) {
    let k = 1.0 - s[3];
    for i in 0..4 {
        acc[i] = s[i] + k * acc[i];
    }
}

#[inline]
fn flush(run: &mut Run, acc: &mut [f32; 4], b: &Blend) {
    match std::mem::replace(run, Run::None) {
        Run::None => {}
        Run::Blobby { field, rgb } => {
            let t = ((field - b.lo) * b.inv_width).clamp(0.0, 1.0);
            let a = t * t * (3.0 - 2.0 * t);
            if a > 0.0 {
                let k = a / field;
                over(acc, [rgb[0] * k, rgb[1] * k, rgb[2] * k, a]);
            }
        }
        Run::Voronoi { best, rgb } => {
            if best > 0.0 {
                let k = 1.0 / best;
                *acc = [rgb[0] * k, rgb[1] * k, rgb[2] * k, 1.0];
            }
        }
    }
}

/// The composite texture at `q` from `sprites` given in user order (section 5.4).
#[inline]
pub(crate) fn composite<'a>(
    sprites: impl Iterator<Item = &'a Prepared>,
    patterns: &[Pattern],
    q: &Query,
    b: &Blend,
) -> [f32; 4] {
    let mut acc = Compositor::new();
    for s in sprites {
        if let Some(c) = contribution(s, patterns, q, b) {
            acc.push(s.blend, c, b);
        }
    }
    acc.finish(b)
}

/// The blending state of one lookup: contributions go in, in user order, with
/// [`Compositor::push`] (sprites that do not contribute are skipped, they do not end a run).
pub(crate) struct Compositor {
    acc: [f32; 4],
    run: Run,
}

impl Compositor {
    #[inline]
    pub(crate) fn new() -> Compositor {
        Compositor {
            acc: [0.0; 4],
            run: Run::None,
        }
    }

    /// Blends the contribution `c` of a sprite with mode `mode`.
    #[inline(always)]
    pub(crate) fn push(&mut self, mode: BlendMode, c: [f32; 4], b: &Blend) {
        let (run, acc) = (&mut self.run, &mut self.acc);
        match mode {
            BlendMode::Over => {
                flush(run, acc, b);
                over(acc, c);
            }
            BlendMode::Add => {
                flush(run, acc, b);
                for i in 0..4 {
                    acc[i] = (acc[i] + c[i]).min(1.0);
                }
            }
            BlendMode::Blobby => {
                if !matches!(run, Run::Blobby { .. }) {
                    flush(run, acc, b);
                    *run = Run::Blobby {
                        field: 0.0,
                        rgb: [0.0; 3],
                    };
                }
                if let Run::Blobby { field, rgb } = run {
                    *field += c[3];
                    for i in 0..3 {
                        rgb[i] += c[i];
                    }
                }
            }
            BlendMode::Voronoi => {
                if !matches!(run, Run::Voronoi { .. }) {
                    flush(run, acc, b);
                    *run = Run::Voronoi {
                        best: 0.0,
                        rgb: [0.0; 3],
                    };
                }
                if let Run::Voronoi { best, rgb } = run
                    && c[3] > *best
                {
                    *best = c[3];
                    *rgb = [c[0], c[1], c[2]];
                }
            }
        }
    }

    /// The premultiplied RGBA once every sprite went in.
    #[inline]
    pub(crate) fn finish(mut self, b: &Blend) -> [f32; 4] {
        flush(&mut self.run, &mut self.acc, b);
        self.acc
    }
}
