//! A lattice of spherical voids: the periodic microstructure of cmpm-process-planning
//! 4.3, whose voids a layer's bitmap leaves out and a laser engraves.
//!
//! Only the inserting points near a plane are visited: a void of radius r centred at
//! height z_k meets the cutting plane z_c only when |z_k - z_c| < r, so the lattice rows
//! k inside that narrow band (the paper's two auxiliary planes at distance L_max = r
//! around the layer, Fig. 5) are computed directly instead of testing every cell.

use crate::shape::BBox2;

/// A lattice of spherical voids.
#[derive(Debug, Clone, Copy)]
pub struct Lattice {
    pub period: [f64; 3],
    pub origin: [f64; 3],
    pub radius: f64,
}

impl Lattice {
    /// Lattice rows k whose voids meet the plane at height `z`: the narrow band
    /// |z_k - z| < r, found by arithmetic.
    pub fn band(&self, z: f64) -> std::ops::RangeInclusive<i64> {
        let (o, a, r) = (self.origin[2], self.period[2], self.radius);
        let lo = ((z - r - o) / a).ceil() as i64;
        let hi = ((z + r - o) / a).floor() as i64;
        lo..=hi
    }

    /// Circles (centre x, centre y, radius) the voids cut in the plane at `z`, within
    /// `bbox`.
    pub fn circles(&self, z: f64, bbox: &BBox2) -> Vec<(f64, f64, f64)> {
        let mut out = Vec::new();
        for k in self.band(z) {
            let dz = self.origin[2] + k as f64 * self.period[2] - z;
            let rc2 = self.radius * self.radius - dz * dz;
            if rc2 <= 0.0 {
                continue;
            }
            let rc = rc2.sqrt();
            let range = |axis: usize, lo: f64, hi: f64| {
                let (o, a) = (self.origin[axis], self.period[axis]);
                ((lo - rc - o) / a).ceil() as i64..=((hi + rc - o) / a).floor() as i64
            };
            for i in range(0, bbox.min.x, bbox.max.x) {
                for j in range(1, bbox.min.y, bbox.max.y) {
                    out.push((
                        self.origin[0] + i as f64 * self.period[0],
                        self.origin[1] + j as f64 * self.period[1],
                        rc,
                    ));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Point2;

    #[test]
    fn the_band_holds_only_the_rows_near_the_plane() {
        let l = Lattice {
            period: [1.0, 1.0, 0.5],
            origin: [0.0, 0.0, 0.0],
            radius: 0.3,
        };
        // Only the row at z = 1.0 lies within 0.3 of 1.15; at 1.25 the rows at 1.0 and 1.5.
        assert_eq!(l.band(1.15), 2..=2);
        assert_eq!(l.band(1.25), 2..=3);
        let bbox = BBox2::from_points([Point2::new(0.0, 0.0), Point2::new(2.0, 2.0)]);
        let circles = l.circles(1.25, &bbox);
        // Two rows, each with the 3 x 3 lattice points of [0, 2]^2.
        assert_eq!(circles.len(), 18);
        assert!(
            circles
                .iter()
                .all(|c| (c.2 - (0.09f64 - 0.0625).sqrt()).abs() < 1e-12)
        );
    }
}
