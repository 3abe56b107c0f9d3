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

    #[test]
    fn every_void_the_plane_cuts_near_the_box_is_found_and_no_other() {
        // Against every inserting point of a wide block of the lattice: a void is
        // listed when the plane cuts it and its circle reaches the box (its centre
        // within the circle's radius of it), off the origin and with unequal periods.
        let l = Lattice {
            period: [0.7, 1.3, 0.45],
            origin: [-0.35, 2.1, 0.2],
            radius: 0.5,
        };
        let bbox = BBox2::from_points([Point2::new(-1.9, -0.6), Point2::new(2.3, 3.4)]);
        for z in [-1.37, 0.2, 0.41, 1.0, 2.66] {
            let mut got = l.circles(z, &bbox);
            let mut want = Vec::new();
            for k in -20i32..20 {
                for i in -20i32..20 {
                    for j in -20i32..20 {
                        let c = [
                            l.origin[0] + f64::from(i) * l.period[0],
                            l.origin[1] + f64::from(j) * l.period[1],
                            l.origin[2] + f64::from(k) * l.period[2],
                        ];
                        let rc2 = l.radius * l.radius - (c[2] - z).powi(2);
                        if rc2 <= 0.0 {
                            continue;
                        }
                        let rc = rc2.sqrt();
                        if c[0] >= bbox.min.x - rc
                            && c[0] <= bbox.max.x + rc
                            && c[1] >= bbox.min.y - rc
                            && c[1] <= bbox.max.y + rc
                        {
                            want.push((c[0], c[1], rc));
                        }
                    }
                }
            }
            let key = |c: &(f64, f64, f64)| (c.2, c.0, c.1);
            got.sort_by(|a, b| key(a).partial_cmp(&key(b)).expect("numbers"));
            want.sort_by(|a, b| key(a).partial_cmp(&key(b)).expect("numbers"));
            assert!(!want.is_empty(), "z = {z}");
            assert_eq!(got.len(), want.len(), "z = {z}");
            for (g, w) in got.iter().zip(&want) {
                assert!(
                    (g.0 - w.0).abs() < 1e-9 && (g.1 - w.1).abs() < 1e-9 && (g.2 - w.2).abs() < 1e-9,
                    "z = {z}: {g:?} {w:?}"
                );
            }
        }
    }
}
