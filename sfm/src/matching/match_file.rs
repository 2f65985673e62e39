//! The verified matches of a workspace and their binary file (`<ws>/matches/two_view.bin`).
//!
//! Layout, version 1, all numbers little-endian:
//!
//! | size      | content                                                                   |
//! |-----------|---------------------------------------------------------------------------|
//! | 8         | magic `b"FRMATCH\0"`                                                      |
//! | 4 (u32)   | version = 1                                                               |
//! | 4 (u32)   | number of pairs `p`                                                       |
//! | p records | one per pair, in the order written (sorted by `(image1, image2)`)         |
//!
//! A pair record:
//!
//! | size         | content                                                                |
//! |--------------|------------------------------------------------------------------------|
//! | 4 (u32)      | `image1` id                                                            |
//! | 4 (u32)      | `image2` id                                                            |
//! | 4 (u32)      | kind ([`PairKind`] discriminant: 0 degenerate .. 5 planar-or-panoramic) |
//! | 4 (u32)      | flags: bit 0 F, bit 1 E, bit 2 H, bit 3 relative pose present            |
//! | 4 (u32)      | number of matches before verification                                  |
//! | 4 (u32)      | number of inliers `k`                                                  |
//! | 34 x 8 (f64) | F (9, row-major), E (9), H (9), pose quaternion `w x y z` (4), translation (3); zeros where absent |
//! | 8 k          | inliers: `u32` keypoint index in image 1, `u32` in image 2               |
//!
//! See [`TwoViewGeometry`] for the conventions of the matrices and the pose.

use std::path::Path;

use fresco_core::{FormatError, Rigid3};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

use crate::features::feature_file::write_atomically;
use crate::geometry::two_view::{PairKind, TwoViewGeometry, VerifiedPair};

/// The magic bytes a match file starts with.
pub const MATCH_MAGIC: [u8; 8] = *b"FRMATCH\0";
/// The version this code writes and reads.
pub const MATCH_VERSION: u32 = 1;
const PAIR_HEADER_LEN: usize = 24 + 34 * 8;

/// Serialises `pairs` into the version-1 layout.
pub fn encode_matches(pairs: &[VerifiedPair]) -> Vec<u8> {
    let inliers: usize = pairs.iter().map(|p| p.geometry.inliers.len()).sum();
    let mut out = Vec::with_capacity(16 + pairs.len() * PAIR_HEADER_LEN + 8 * inliers);
    out.extend_from_slice(&MATCH_MAGIC);
    out.extend_from_slice(&MATCH_VERSION.to_le_bytes());
    out.extend_from_slice(&(pairs.len() as u32).to_le_bytes());
    for p in pairs {
        let g = &p.geometry;
        let flags = u32::from(g.fundamental.is_some())
            | (u32::from(g.essential.is_some()) << 1)
            | (u32::from(g.homography.is_some()) << 2)
            | (u32::from(g.cam2_from_cam1.is_some()) << 3);
        for v in [
            p.image1,
            p.image2,
            g.kind as u32,
            flags,
            p.num_matches,
            g.inliers.len() as u32,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for m in [g.fundamental, g.essential, g.homography] {
            let m = m.unwrap_or_else(Matrix3::zeros);
            for r in 0..3 {
                for c in 0..3 {
                    out.extend_from_slice(&m[(r, c)].to_le_bytes());
                }
            }
        }
        let (q, t) = g.cam2_from_cam1.map_or(([0.0; 4], [0.0; 3]), |pose| {
            let q = pose.rotation.quaternion();
            (
                [q.w, q.i, q.j, q.k],
                [pose.translation.x, pose.translation.y, pose.translation.z],
            )
        });
        for v in q.into_iter().chain(t) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for [a, b] in &g.inliers {
            out.extend_from_slice(&a.to_le_bytes());
            out.extend_from_slice(&b.to_le_bytes());
        }
    }
    out
}

/// Parses the version-1 layout; `path` only names the source in errors.
pub fn decode_matches(bytes: &[u8], path: &Path) -> Result<Vec<VerifiedPair>, FormatError> {
    let mut r = Cursor { bytes, at: 0, path };
    let magic = r.take(8, "the magic")?;
    if magic != MATCH_MAGIC {
        return Err(FormatError::binary(
            path,
            0,
            "not a fresco match file (magic FRMATCH missing)",
        ));
    }
    let version = r.u32("the version")?;
    if version != MATCH_VERSION {
        return Err(FormatError::binary(
            path,
            8,
            format!("match file version {version}, this fresco reads version {MATCH_VERSION}"),
        ));
    }
    let count = r.u32("the pair count")? as usize;
    let mut pairs = Vec::with_capacity(count.min(bytes.len() / PAIR_HEADER_LEN));
    for i in 0..count {
        let start = r.at;
        let image1 = r.u32("a pair record")?;
        let image2 = r.u32("a pair record")?;
        let kind_raw = r.u32("a pair record")?;
        let kind = PairKind::from_u32(kind_raw).ok_or_else(|| {
            FormatError::binary(
                path,
                start as u64 + 8,
                format!("pair {i}: unknown kind {kind_raw}"),
            )
        })?;
        let flags = r.u32("a pair record")?;
        let num_matches = r.u32("a pair record")?;
        let k = r.u32("a pair record")? as usize;
        let mut matrix = || -> Result<Matrix3<f64>, FormatError> {
            let mut m = Matrix3::zeros();
            for row in 0..3 {
                for col in 0..3 {
                    m[(row, col)] = r.f64("a pair record")?;
                }
            }
            Ok(m)
        };
        let f = matrix()?;
        let e = matrix()?;
        let h = matrix()?;
        let mut pose = [0.0; 7];
        for v in &mut pose {
            *v = r.f64("a pair record")?;
        }
        let needed = 8 * k;
        let raw = r.take(needed, "the inliers of a pair")?;
        let inliers = raw
            .chunks_exact(8)
            .map(|c| {
                [
                    u32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                    u32::from_le_bytes([c[4], c[5], c[6], c[7]]),
                ]
            })
            .collect();
        let cam2_from_cam1 = (flags & 8 != 0).then(|| {
            Rigid3::new(
                UnitQuaternion::from_quaternion(Quaternion::new(
                    pose[0], pose[1], pose[2], pose[3],
                )),
                Vector3::new(pose[4], pose[5], pose[6]),
            )
        });
        pairs.push(VerifiedPair {
            image1,
            image2,
            num_matches,
            geometry: TwoViewGeometry {
                kind,
                fundamental: (flags & 1 != 0).then_some(f),
                essential: (flags & 2 != 0).then_some(e),
                homography: (flags & 4 != 0).then_some(h),
                cam2_from_cam1,
                inliers,
            },
        });
    }
    if r.at != bytes.len() {
        return Err(FormatError::binary(
            path,
            r.at as u64,
            format!("{} bytes after the last pair", bytes.len() - r.at),
        ));
    }
    Ok(pairs)
}

/// Writes `pairs` to `path` atomically.
pub fn write_match_file(path: &Path, pairs: &[VerifiedPair]) -> Result<(), FormatError> {
    write_atomically(path, &encode_matches(pairs))
}

/// Reads a match file written by [`write_match_file`].
pub fn read_match_file(path: &Path) -> Result<Vec<VerifiedPair>, FormatError> {
    let bytes = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
    decode_matches(&bytes, path)
}

/// Reads little-endian numbers from a byte slice, failing with the offset and what was expected.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], FormatError> {
        if self.bytes.len() - self.at < n {
            return Err(FormatError::binary(
                self.path,
                self.at as u64,
                format!("file ends inside {what} ({n} bytes expected)"),
            ));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32, FormatError> {
        let s = self.take(4, what)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn f64(&mut self, what: &str) -> Result<f64, FormatError> {
        let s = self.take(8, what)?;
        Ok(f64::from_le_bytes(s.try_into().expect("8 bytes")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<VerifiedPair> {
        let pose = Rigid3::new(
            UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
            Vector3::new(0.6, 0.0, 0.8),
        );
        vec![
            VerifiedPair {
                image1: 1,
                image2: 2,
                num_matches: 120,
                geometry: TwoViewGeometry {
                    kind: PairKind::Calibrated,
                    fundamental: Some(Matrix3::from_fn(|r, c| (r * 3 + c) as f64 * 0.5)),
                    essential: Some(Matrix3::from_fn(|r, c| (r + c) as f64 - 1.0)),
                    homography: None,
                    cam2_from_cam1: Some(pose),
                    inliers: vec![[0, 5], [3, 2], [7, 7]],
                },
            },
            VerifiedPair {
                image1: 1,
                image2: 3,
                num_matches: 4,
                geometry: TwoViewGeometry::degenerate(),
            },
        ]
    }

    #[test]
    fn round_trip_keeps_every_bit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("two_view.bin");
        write_match_file(&path, &sample()).unwrap();
        let back = read_match_file(&path).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[1], sample()[1]);
        let (a, b) = (&back[0].geometry, &sample()[0].geometry);
        assert_eq!(a.fundamental, b.fundamental);
        assert_eq!(a.essential, b.essential);
        assert_eq!(a.inliers, b.inliers);
        // The quaternion goes through a renormalisation: equal to 1e-15.
        let (pa, pb) = (a.cam2_from_cam1.unwrap(), b.cam2_from_cam1.unwrap());
        assert!(pa.rotation.angle_to(&pb.rotation) < 1e-12);
        assert_eq!(pa.translation, pb.translation);
    }

    #[test]
    fn damaged_files_are_located_errors() {
        let p = Path::new("m.bin");
        let good = encode_matches(&sample());
        let err = |b: &[u8]| decode_matches(b, p).unwrap_err().to_string();
        let first = encode_matches(&sample()[..1]);
        assert!(err(&first[..first.len() - 3]).contains("inliers"));
        assert!(err(&good[..good.len() - 3]).contains("pair record"));
        assert!(err(&good[..10]).contains("version"));
        let mut bad_kind = good.clone();
        bad_kind[16 + 8] = 77;
        assert!(err(&bad_kind).contains("unknown kind 77"));
        let mut longer = good.clone();
        longer.push(0);
        assert!(err(&longer).contains("after the last pair"));
        assert!(err(b"FRSIFT\0\0xxxxxxxx").contains("magic"));
    }
}
