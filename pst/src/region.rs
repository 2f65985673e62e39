//! Regions of space that editing operations and refinements act on.

use fresco_core::Aabb;
use serde::{Deserialize, Serialize};

use crate::error::{PstError, Result};

/// A box, a sphere, or everything.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Region {
    Box { min: [f64; 3], max: [f64; 3] },
    Sphere { center: [f64; 3], radius: f64 },
    All,
}

impl Region {
    /// Parses `box:x0,y0,z0,x1,y1,z1`, `sphere:x,y,z,r` or `all`.
    pub fn parse(text: &str) -> Result<Region> {
        let bad = || {
            PstError::Parameter(format!(
                "region {text:?}: expected box:x0,y0,z0,x1,y1,z1 or sphere:x,y,z,r or all"
            ))
        };
        if text == "all" {
            return Ok(Region::All);
        }
        let (kind, rest) = text.split_once(':').ok_or_else(bad)?;
        let v: Vec<f64> = rest
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad())?;
        if v.iter().any(|x| !x.is_finite()) {
            return Err(bad());
        }
        let region = match (kind, v.len()) {
            ("box", 6) => Region::Box {
                min: [v[0].min(v[3]), v[1].min(v[4]), v[2].min(v[5])],
                max: [v[0].max(v[3]), v[1].max(v[4]), v[2].max(v[5])],
            },
            ("sphere", 4) if v[3] > 0.0 => Region::Sphere {
                center: [v[0], v[1], v[2]],
                radius: v[3],
            },
            _ => return Err(bad()),
        };
        Ok(region)
    }

    #[inline]
    pub fn contains(&self, p: [f64; 3]) -> bool {
        match self {
            Region::Box { min, max } => (0..3).all(|a| p[a] >= min[a] && p[a] <= max[a]),
            Region::Sphere { center, radius } => {
                (0..3).map(|a| (p[a] - center[a]).powi(2)).sum::<f64>() <= radius * radius
            }
            Region::All => true,
        }
    }

    #[inline]
    pub fn contains_f32(&self, p: [f32; 3]) -> bool {
        self.contains(p.map(|v| v as f64))
    }

    /// Whether the region meets an axis-aligned box.
    pub fn intersects(&self, b: &Aabb) -> bool {
        match self {
            Region::Box { min, max } => (0..3).all(|a| min[a] <= b.max[a] && max[a] >= b.min[a]),
            Region::Sphere { center, radius } => {
                let d2: f64 = (0..3)
                    .map(|a| {
                        let c = center[a].clamp(b.min[a], b.max[a]);
                        (c - center[a]).powi(2)
                    })
                    .sum();
                d2 <= radius * radius
            }
            Region::All => true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_contains_intersects() {
        let s = Region::parse("sphere:0,0,0,1").unwrap();
        assert!(s.contains([0.5, 0.5, 0.5]) && !s.contains([0.7, 0.7, 0.7]));
        let b = Aabb {
            min: [0.9, 0.0, 0.0].into(),
            max: [2.0, 1.0, 1.0].into(),
        };
        assert!(s.intersects(&b));
        let far = Aabb {
            min: [0.8, 0.8, 0.8].into(),
            max: [2.0, 2.0, 2.0].into(),
        };
        assert!(!s.intersects(&far));
        let bx = Region::parse("box:1,1,1,0,0,0").unwrap();
        assert!(bx.contains([0.5, 0.2, 1.0]));
        assert!(Region::parse("sphere:0,0,0").is_err());
        assert!(Region::parse("cube:0,0,0,1").is_err());
        assert!(Region::parse("sphere:0,0,nan,1").is_err());
    }
}
