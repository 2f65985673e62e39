//! The geometric-consistency term of PatchMatch's second pass (Schönberger et al., ECCV 2016,
//! section 4.3, COLMAP's `geom_consistency`; Xu and Tao's ACMM, CVPR 2019, eq. 6): a
//! hypothesis at reference pixel `p` with depth `d` gives the 3D point `X = d K^-1 p`; `X`
//! projects into a source view at `p_s`, where the source's own (first-pass) depth map says
//! `d_s`; the source's point `d_s K_s^-1 p_s`, projected back into the reference, lands at
//! `p'`. The forward-backward reprojection error `|p - p'|` (pixels) is 0 when the two depth
//! maps agree; PatchMatch adds `weight * min(|p - p'|, max_px)` to the source's photometric
//! cost, so that depth maps converge towards agreement across views and lone errors (an
//! occluder's depth, a repeated texture) lose.
//!
//! The source's depth is looked up at the nearest pixel and back-projected through the
//! continuous position `p_s`, so that the error measures depth disagreement, not the pixel
//! grid.

use super::patch_match::{DepthMap, Intrinsics};
use fresco_core::Rigid3;

/// A source view's depth map with the geometry to test reference points against it.
pub struct DepthCheck<'a> {
    depth: &'a [f32],
    width: usize,
    height: usize,
    /// Source intrinsics (array coordinates).
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    /// `src_from_ref` rotation (row-major) and translation.
    r: [f32; 9],
    t: [f32; 3],
    /// Reference intrinsics.
    ref_fx: f32,
    ref_fy: f32,
    ref_cx: f32,
    ref_cy: f32,
}

impl<'a> DepthCheck<'a> {
    pub fn new(
        map: &'a DepthMap,
        k: &Intrinsics,
        src_from_ref: &Rigid3,
        ref_k: &Intrinsics,
    ) -> DepthCheck<'a> {
        let rot = src_from_ref.rotation.to_rotation_matrix().into_inner();
        let mut r = [0.0f32; 9];
        for i in 0..3 {
            for j in 0..3 {
                r[i * 3 + j] = rot[(i, j)] as f32;
            }
        }
        let t = src_from_ref.translation;
        DepthCheck {
            depth: &map.depth,
            width: map.width,
            height: map.height,
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            r,
            t: [t.x as f32, t.y as f32, t.z as f32],
            ref_fx: ref_k.fx as f32,
            ref_fy: ref_k.fy as f32,
            ref_cx: ref_k.cx as f32,
            ref_cy: ref_k.cy as f32,
        }
    }

    /// The forward-backward reprojection error (reference pixels) of the reference-frame
    /// point `x` seen at reference array position (`px`, `py`); `None` when the point does not
    /// project into the source or the source has no depth there.
    #[inline]
    pub fn error(&self, x: &[f32; 3], px: f32, py: f32) -> Option<f32> {
        let r = &self.r;
        let xs = [
            r[0] * x[0] + r[1] * x[1] + r[2] * x[2] + self.t[0],
            r[3] * x[0] + r[4] * x[1] + r[5] * x[2] + self.t[1],
            r[6] * x[0] + r[7] * x[1] + r[8] * x[2] + self.t[2],
        ];
        if xs[2] <= 0.0 {
            return None;
        }
        let u = self.fx * xs[0] / xs[2] + self.cx;
        let v = self.fy * xs[1] / xs[2] + self.cy;
        let (ui, vi) = (u.round(), v.round());
        if !(ui >= 0.0 && vi >= 0.0 && ui < self.width as f32 && vi < self.height as f32) {
            return None;
        }
        let ds = self.depth[vi as usize * self.width + ui as usize];
        if ds <= 0.0 {
            return None;
        }
        // The source's point, back into the reference frame: R^T (X_s - t).
        let ys = [
            (u - self.cx) / self.fx * ds - self.t[0],
            (v - self.cy) / self.fy * ds - self.t[1],
            ds - self.t[2],
        ];
        let y = [
            r[0] * ys[0] + r[3] * ys[1] + r[6] * ys[2],
            r[1] * ys[0] + r[4] * ys[1] + r[7] * ys[2],
            r[2] * ys[0] + r[5] * ys[1] + r[8] * ys[2],
        ];
        if y[2] <= 0.0 {
            return None;
        }
        let bx = self.ref_fx * y[0] / y[2] + self.ref_cx;
        let by = self.ref_fy * y[1] / y[2] + self.ref_cy;
        Some((bx - px).hypot(by - py))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dense::patch_match::backproject;
    use fresco_core::nalgebra::{UnitQuaternion, Vector3};

    #[test]
    fn agreeing_depth_maps_have_no_error_and_a_wrong_depth_does() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 31.5,
            cy: 23.5,
        };
        // Both cameras see the plane z = 3 of the reference frame.
        let src_from_ref = Rigid3::new(
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.15),
            Vector3::new(-0.4, 0.0, 0.05),
        );
        let ref_from_src = src_from_ref.inverse();
        let (w, h) = (64, 48);
        let mut map = DepthMap::empty(w, h);
        for y in 0..h {
            for x in 0..w {
                // Depth in the source of the ray through (x, y) meeting the plane z_ref = 3.
                let d = backproject(&k, x as f64, y as f64, 1.0);
                let origin = ref_from_src.translation;
                let dir = ref_from_src.rotation * d;
                let s = (3.0 - origin.z) / dir.z;
                map.depth[y * w + x] = s as f32;
            }
        }
        let check = DepthCheck::new(&map, &k, &src_from_ref, &k);
        let p = backproject(&k, 30.0, 20.0, 3.0);
        let x = [p.x as f32, p.y as f32, p.z as f32];
        let e = check.error(&x, 30.0, 20.0).unwrap();
        assert!(e < 0.05, "{e}");
        // A third farther: the two views' disparities differ by about
        // f B (1/3 - 1/4) = 100 * 0.4 / 12 = 3.3 px, the error the check must see.
        let far = backproject(&k, 30.0, 20.0, 4.0);
        let e = check
            .error(&[far.x as f32, far.y as f32, far.z as f32], 30.0, 20.0)
            .unwrap();
        assert!(e > 2.0, "{e}");
    }
}
