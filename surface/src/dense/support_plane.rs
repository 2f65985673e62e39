//! Removal of the surface an object stands on (a table, a turntable, a platform) from the
//! fused cloud of an object-centric capture.
//!
//! A capture is object-centric when its cameras look inward at a common point: the point
//! nearest (least squares) to every optical axis lies within `max_aim_deg` of the axis of at
//! least 80% of them. Then the normal of the plane nearest the camera centres, on the side
//! of their mean direction from that point, is roughly "up" (a ring or a dome stands above
//! the ground). The support plane is searched among the points
//! whose normal faces up (within 45 degrees) by a Hough transform over its tilt (to 30
//! degrees from the cameras' up: a ring need not be parallel to the ground): for each
//! candidate normal, the points' heights along it in bins of the smallest tolerance; the
//! plane is the fullest pair of adjacent bins. Positions decide, not the fused normals
//! (PatchMatch's normals on a weakly textured ground are biased). The height is then refined
//! by the median of the points near it. It is the support plane only when
//! - it holds at least `min_fraction` of the points (dominant),
//! - every camera and the aim point lie on its upper side (the object stands on it, seen
//!   from above; candidates of the vote that fail this do not compete),
//! - most of the points off the plane lie above it (the object is there),
//! - at least `min_outside_footprint` of its points lie outside the footprint of the points
//!   above it (a table is seen around the object; the object's own plinth or step lies
//!   under its overhangs).
//!
//! The points on the plane (within the tolerance) and below it are then dropped. The
//! tolerance is three robust standard deviations of the plane points' distances (1.4826
//! times their median absolute deviation), kept between 0.2% and 1% of the cameras' mean
//! distance to the aim point. No RANSAC: one vote per candidate tilt finds the plane
//! deterministically (about a second for 20,000 up-facing points, sampled evenly).

use fresco_core::nalgebra::{Matrix3, Point3, Vector3};
use serde::Serialize;

/// Support-plane removal settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SupportPlaneConfig {
    /// Remove the support plane of object-centric captures. Default true.
    pub remove: bool,
    /// Smallest fraction of the fused points a support plane holds. Default 0.05.
    pub min_fraction: f64,
    /// Largest angle between a camera's optical axis and the direction to the common aim
    /// point for the capture to count as object-centric, degrees. Default 25.
    pub max_aim_deg: f64,
    /// Smallest fraction of the plane's points outside the footprint of the points above it
    /// (cells of 2% of the cameras' distance to the aim point, grown by one cell). Default
    /// 0.25.
    pub min_outside_footprint: f64,
}

impl Default for SupportPlaneConfig {
    fn default() -> Self {
        SupportPlaneConfig {
            remove: true,
            min_fraction: 0.05,
            max_aim_deg: 25.0,
            min_outside_footprint: 0.25,
        }
    }
}

impl SupportPlaneConfig {
    /// The first field with an unusable value, by name.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.min_fraction.is_finite() && self.min_fraction > 0.0 && self.min_fraction < 1.0) {
            return Err((
                "support_plane.min_fraction",
                format!("{} is outside (0, 1)", self.min_fraction),
            ));
        }
        if !(self.max_aim_deg.is_finite() && self.max_aim_deg > 0.0 && self.max_aim_deg < 90.0) {
            return Err((
                "support_plane.max_aim_deg",
                format!("{} is outside (0, 90)", self.max_aim_deg),
            ));
        }
        if !(0.0..1.0).contains(&self.min_outside_footprint) {
            return Err((
                "support_plane.min_outside_footprint",
                format!("{} is outside [0, 1)", self.min_outside_footprint),
            ));
        }
        Ok(())
    }
}

/// A camera as the plane search needs it: its centre and optical axis (unit, world frame).
#[derive(Clone, Copy, Debug)]
pub struct CameraRay {
    pub centre: Point3<f64>,
    pub axis: Vector3<f64>,
}

/// The support plane found: `normal . p = offset` with `normal` pointing up, and the points
/// dropped.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SupportPlane {
    pub normal: [f64; 3],
    pub offset: f64,
    /// Points within this distance of the plane count as on it.
    pub tolerance: f64,
    /// Points on or below the plane.
    pub removed: u64,
}

/// The common aim point of object-centric cameras, or `None` when they do not look inward
/// at one point.
pub fn aim_point(cameras: &[CameraRay], max_aim_deg: f64) -> Option<Point3<f64>> {
    if cameras.len() < 3 {
        return None;
    }
    // Least squares: sum over cameras of (I - a a^T) (p - c) = 0.
    let mut m = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for c in cameras {
        let proj = Matrix3::identity() - c.axis * c.axis.transpose();
        m += proj;
        rhs += proj * c.centre.coords;
    }
    let p = Point3::from(m.try_inverse()? * rhs);
    let cos_max = max_aim_deg.to_radians().cos();
    let aimed = cameras
        .iter()
        .filter(|c| {
            let d = p - c.centre;
            let len = d.norm();
            len > 0.0 && d.dot(&c.axis) / len >= cos_max
        })
        .count();
    (aimed * 5 >= cameras.len() * 4).then_some(p)
}

/// "Up" of an object-centric capture: the normal of the plane nearest the camera centres (a
/// ring's axis, a dome's), on the side of the cameras' mean direction from the aim point
/// `mean_dir`. The mean direction alone tilts towards whichever part of a low ring has more
/// cameras (a ring at 8 degrees of elevation with two photos left out: 40 degrees off).
fn camera_up(cameras: &[CameraRay], mean_dir: &Vector3<f64>) -> Option<Vector3<f64>> {
    let n = cameras.len() as f64;
    let centroid = cameras
        .iter()
        .map(|c| c.centre.coords)
        .sum::<Vector3<f64>>()
        / n;
    let scatter = cameras
        .iter()
        .map(|c| (c.centre.coords - centroid) * (c.centre.coords - centroid).transpose())
        .sum::<Matrix3<f64>>();
    let eigen = scatter.symmetric_eigen();
    let (smallest, _) = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let normal = eigen.eigenvectors.column(smallest).into_owned();
    let up = if normal.dot(mean_dir) < 0.0 {
        -normal
    } else {
        normal
    };
    up.try_normalize(1e-12)
}

/// Two unit vectors that complete the unit `normal` to an orthonormal frame: coordinates in
/// the plane.
fn plane_basis(normal: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if normal.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = normal.cross(&helper).normalize();
    (e1, normal.cross(&e1))
}

/// Finds the support plane of `points` (with unit `normals` facing their cameras) under
/// `cameras`; see the module documentation. `None` when the capture is not object-centric
/// or no plane qualifies.
pub fn find_support_plane(
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    cameras: &[CameraRay],
    cfg: &SupportPlaneConfig,
) -> Option<SupportPlane> {
    let aim = aim_point(cameras, cfg.max_aim_deg)?;
    let mean_dir: Vector3<f64> = cameras.iter().map(|c| c.centre - aim).sum::<Vector3<f64>>();
    let mut up = camera_up(cameras, &mean_dir)?;
    let distance =
        cameras.iter().map(|c| (c.centre - aim).norm()).sum::<f64>() / cameras.len() as f64;
    let (min_tol, max_tol) = (0.002 * distance, 0.02 * distance);
    let cos_up = 45f64.to_radians().cos();
    let facing: Vec<usize> = (0..points.len())
        .filter(|&i| normals[i].dot(&up) >= cos_up)
        .collect();
    if (facing.len() as f64) < cfg.min_fraction * points.len() as f64 {
        return None;
    }
    let bin = max_tol / 2.0;
    // The Hough transform: tilts to 30 degrees in 1 degree steps, then 0.1 degree steps
    // around the best.
    let sample: Vec<Vector3<f64>> = facing
        .iter()
        .step_by(facing.len().div_ceil(20_000).max(1))
        .map(|&i| points[i].coords)
        // Far strays would only widen the histograms.
        .filter(|p| (p - aim.coords).norm() <= 5.0 * distance)
        .collect();
    let (e1, e2) = plane_basis(&up);
    let peak = |n: &Vector3<f64>| -> (usize, f64) {
        let heights: Vec<f64> = sample.iter().map(|p| p.dot(n) / min_tol).collect();
        let lo = heights
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
            .floor();
        let hi = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut votes = vec![0usize; (hi - lo) as usize + 2];
        for h in heights {
            votes[(h - lo) as usize] += 1;
        }
        // The fullest pair of adjacent bins (the lowest one on a tie).
        let (mut count, mut at) = (0, 0);
        for (b, pair) in votes.windows(2).enumerate() {
            if pair[0] + pair[1] > count {
                (count, at) = (pair[0] + pair[1], b);
            }
        }
        (count, (lo + at as f64 + 1.0) * min_tol)
    };
    let mut best = (0usize, 0.0f64, up);
    for (step, half) in [(1.0f64, 30i32), (0.1, 10)] {
        let (centre, mut round) = (best.2, best);
        for i in -half..=half {
            for j in -half..=half {
                let (a, b) = (
                    (i as f64 * step).to_radians().tan(),
                    (j as f64 * step).to_radians().tan(),
                );
                let n = (centre + a * e1 + b * e2).normalize();
                let (count, offset) = peak(&n);
                // Only a plane with every camera and the aim point on its upper side can be
                // the support: a backdrop or a wall tilted towards the search's limit may
                // hold more up-facing points, but cameras stand on both of its sides.
                let clear = |p: &Point3<f64>| p.coords.dot(&n) - offset > max_tol;
                if count > round.0 && clear(&aim) && cameras.iter().all(|c| clear(&c.centre)) {
                    round = (count, offset, n);
                }
            }
        }
        best = round;
    }
    up = best.2;
    let mut offset = best.1;
    let mut tolerance = 2.0 * min_tol;
    for _ in 0..3 {
        let mut dist: Vec<f64> = facing
            .iter()
            .map(|&i| points[i].coords.dot(&up) - offset)
            .filter(|d| d.abs() <= tolerance)
            .collect();
        if dist.len() < 3 {
            return None;
        }
        dist.sort_by(f64::total_cmp);
        offset += dist[dist.len() / 2];
        let mut dev: Vec<f64> = dist
            .iter()
            .map(|d| (d - dist[dist.len() / 2]).abs())
            .collect();
        dev.sort_by(f64::total_cmp);
        tolerance = (3.0 * 1.4826 * dev[dev.len() / 2]).clamp(min_tol, bin);
    }
    // Cameras and the aim point above the plane.
    let above = |p: &Point3<f64>| p.coords.dot(&up) - offset;
    if above(&aim) <= tolerance || cameras.iter().any(|c| above(&c.centre) <= tolerance) {
        return None;
    }
    let (mut on, mut over, mut under) = (0u64, 0u64, 0u64);
    for p in points {
        let h = above(p);
        if h.abs() <= tolerance {
            on += 1;
        } else if h > 0.0 {
            over += 1;
        } else {
            under += 1;
        }
    }
    if (on as f64) < cfg.min_fraction * points.len() as f64 || over <= under {
        return None;
    }
    let plane = SupportPlane {
        normal: [up.x, up.y, up.z],
        offset,
        tolerance,
        removed: on + under,
    };
    // A support reaches out around the object it carries: the object hides the part under
    // it, so most of what the cameras see of a table lies outside the object's footprint
    // (templeSparseRing's platform: 52% outside). A plinth, a step or a ledge of the object
    // itself lies under its overhangs and between its parts (the synthetic temple's lower
    // step: 0% outside, under its roof).
    if plane.outside_footprint(points, max_tol) < cfg.min_outside_footprint {
        return None;
    }
    Some(plane)
}

impl SupportPlane {
    /// The fraction of the points on the plane that lie outside the footprint of the points
    /// above it: their projection onto the plane in square cells of side `cell`, a cell
    /// counting when it holds at least two points (a stray point above a table does not
    /// hide it), grown by its 8 neighbours.
    fn outside_footprint(&self, points: &[Point3<f64>], cell: f64) -> f64 {
        let up = Vector3::from(self.normal);
        let (e1, e2) = plane_basis(&up);
        let cell_of = |p: &Point3<f64>| {
            (
                (p.coords.dot(&e1) / cell).floor() as i64,
                (p.coords.dot(&e2) / cell).floor() as i64,
            )
        };
        let mut above = std::collections::HashMap::<(i64, i64), u32>::new();
        let mut on = Vec::new();
        for p in points {
            let h = p.coords.dot(&up) - self.offset;
            if h > self.tolerance {
                *above.entry(cell_of(p)).or_default() += 1;
            } else if h.abs() <= self.tolerance {
                on.push(cell_of(p));
            }
        }
        let covered = |(x, y): (i64, i64)| {
            (-1..=1).any(|i| (-1..=1).any(|j| above.get(&(x + i, y + j)).is_some_and(|&n| n >= 2)))
        };
        let outside = on.iter().filter(|&&c| !covered(c)).count();
        outside as f64 / on.len().max(1) as f64
    }

    /// Whether `p` is kept: strictly above the plane's tolerance band.
    pub fn keeps(&self, p: &Point3<f64>) -> bool {
        let n = Vector3::from(self.normal);
        p.coords.dot(&n) - self.offset > self.tolerance
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fresco_core::Rng;

    /// A ring of `n` cameras at `elevation` (radians) and distance 2 looking at the origin
    /// (up is +z, tilted by `tilt` about x).
    fn ring(n: usize, elevation: f64, tilt: f64) -> Vec<CameraRay> {
        let rot = fresco_core::nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), tilt);
        (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                let c = rot
                    * Point3::new(
                        2.0 * elevation.cos() * a.cos(),
                        2.0 * elevation.cos() * a.sin(),
                        2.0 * elevation.sin(),
                    );
                CameraRay {
                    centre: c,
                    axis: -c.coords.normalize(),
                }
            })
            .collect()
    }

    /// A unit-radius blob of object points above a noisy plane z = -0.5 (tilted by `tilt`).
    fn scene(tilt: f64) -> (Vec<Point3<f64>>, Vec<Vector3<f64>>, usize) {
        let rot = fresco_core::nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), tilt);
        let mut rng = Rng::new(3);
        let (mut pts, mut nrm) = (Vec::new(), Vec::new());
        for _ in 0..4000 {
            // Object: a sphere of radius 0.4 resting on the plane.
            let v = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
            pts.push(rot * Point3::from(Vector3::new(0.0, 0.0, -0.1) + 0.4 * v));
            nrm.push(rot * v);
        }
        let object = pts.len();
        for _ in 0..3000 {
            let (x, y) = (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            pts.push(rot * Point3::new(x, y, -0.5 + 0.002 * rng.normal()));
            nrm.push(rot * Vector3::z());
        }
        (pts, nrm, object)
    }

    #[test]
    fn removes_the_plane_under_a_ring_and_keeps_the_object() {
        for tilt in [0.0, 0.15] {
            // The plane tilts by `tilt`, the cameras' ring by a third of it.
            let cams = ring(16, 0.5, tilt / 3.0);
            let (pts, nrm, object) = scene(tilt);
            let plane = find_support_plane(&pts, &nrm, &cams, &SupportPlaneConfig::default())
                .expect("a support plane");
            let kept_object = pts[..object].iter().filter(|p| plane.keeps(p)).count();
            let kept_plane = pts[object..].iter().filter(|p| plane.keeps(p)).count();
            // A band of three robust standard deviations keeps ~0.1% of the noisy plane.
            let plane_points = pts.len() - object;
            assert!(
                kept_plane * 100 <= plane_points,
                "tilt {tilt}: {kept_plane}"
            );
            // The sphere touches the plane 0.1 under its centre: only its bottom cap goes.
            assert!(
                kept_object as f64 > 0.95 * object as f64,
                "tilt {tilt}: {kept_object}"
            );
            let n = Vector3::from(plane.normal);
            let truth = fresco_core::nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), tilt)
                * Vector3::z();
            assert!(n.angle(&truth).to_degrees() < 1.0);
        }
    }

    #[test]
    fn finds_the_plane_under_a_low_ring_with_a_gap() {
        // A ring 8 degrees above the aim point with three neighbouring cameras missing: the
        // cameras' mean direction leans about 60 degrees off up, the ring's axis does not.
        let cams: Vec<CameraRay> = ring(16, 0.14, 0.0).into_iter().skip(3).collect();
        let (pts, nrm, object) = scene(0.0);
        let plane = find_support_plane(&pts, &nrm, &cams, &SupportPlaneConfig::default())
            .expect("a support plane");
        assert!(
            Vector3::from(plane.normal)
                .angle(&Vector3::z())
                .to_degrees()
                < 1.0
        );
        let kept_plane = pts[object..].iter().filter(|p| plane.keeps(p)).count();
        assert!(kept_plane * 100 <= pts.len() - object, "{kept_plane}");
    }

    #[test]
    fn keeps_a_plinth_under_the_objects_own_overhang() {
        // A temple without ground: a plinth top (z = -0.5, 1 x 1), four columns and a roof
        // slab (1.2 x 1.2, z = 0.3 to 0.35) overhanging the plinth on every side.
        let mut rng = Rng::new(5);
        let (mut pts, mut nrm) = (Vec::new(), Vec::new());
        for _ in 0..3000 {
            let (x, y) = (rng.range(-0.5, 0.5), rng.range(-0.5, 0.5));
            pts.push(Point3::new(x, y, -0.5 + 0.002 * rng.normal()));
            nrm.push(Vector3::z());
        }
        for _ in 0..3000 {
            let (cx, cy) = ([-0.4, 0.4][rng.below(2)], [-0.4, 0.4][rng.below(2)]);
            let a = rng.range(0.0, std::f64::consts::TAU);
            let p = Point3::new(
                cx + 0.05 * a.cos(),
                cy + 0.05 * a.sin(),
                rng.range(-0.5, 0.3),
            );
            pts.push(p);
            nrm.push(Vector3::new(a.cos(), a.sin(), 0.0));
        }
        for (z, n) in [(0.3, -1.0), (0.35, 1.0)] {
            for _ in 0..1000 {
                let (x, y) = (rng.range(-0.6, 0.6), rng.range(-0.6, 0.6));
                pts.push(Point3::new(x, y, z));
                nrm.push(Vector3::new(0.0, 0.0, n));
            }
        }
        let cams = ring(16, 0.5, 0.0);
        let cfg = SupportPlaneConfig::default();
        assert!(find_support_plane(&pts, &nrm, &cams, &cfg).is_none());
        // Without the footprint test the plinth top passes for a support.
        let lax = SupportPlaneConfig {
            min_outside_footprint: 0.0,
            ..cfg
        };
        let plane = find_support_plane(&pts, &nrm, &cams, &lax).expect("the plinth top");
        assert!((plane.offset + 0.5).abs() < 0.01, "{}", plane.offset);
    }

    #[test]
    fn no_plane_without_object_centric_cameras_or_with_cameras_below() {
        let (pts, nrm, _) = scene(0.0);
        // Cameras side by side looking the same way (a facade): no common aim point.
        let facade: Vec<CameraRay> = (0..8)
            .map(|i| CameraRay {
                centre: Point3::new(i as f64 * 0.3, -3.0, 0.0),
                axis: Vector3::y(),
            })
            .collect();
        let cfg = SupportPlaneConfig::default();
        assert!(find_support_plane(&pts, &nrm, &facade, &cfg).is_none());
        // A ring under the plane looking up at the object: the plane is not below the object.
        let below: Vec<CameraRay> = ring(16, -1.2, 0.0);
        let flipped: Vec<Vector3<f64>> = nrm.iter().map(|n| -n).collect();
        assert!(find_support_plane(&pts, &flipped, &below, &cfg).is_none());
        // Only object: nothing dominant faces up at one height.
        let (pts, nrm, object) = scene(0.0);
        assert!(
            find_support_plane(&pts[..object], &nrm[..object], &ring(16, 0.5, 0.0), &cfg).is_none()
        );
    }
}
