//! Planar profiles of the generated models, as polygons with holes (outer
//! counter-clockwise, holes clockwise), ready to be extruded.

use std::f64::consts::TAU;

use lamina_api::{Contour, Point2, Polygon};

/// Parameters of a spur gear profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GearProfile {
    pub teeth: usize,
    /// Radius of the tooth tips (mm).
    pub tip_radius: f64,
    /// Radius of the tooth roots (mm).
    pub root_radius: f64,
    /// Share of the pitch taken by a tooth at its tip, in (0, 1).
    pub tip_share: f64,
    /// Share of the pitch taken by a tooth at its root, in (0, 1).
    pub root_share: f64,
    /// Vertices per arc (tip and root each).
    pub arc_segments: usize,
}

impl GearProfile {
    /// The outline: trapezoidal teeth whose flanks run straight from root to tip, with
    /// circular tip and root lands. Counter-clockwise.
    pub fn outline(&self) -> Contour {
        let pitch = TAU / self.teeth as f64;
        let arc = |r: f64, a0: f64, a1: f64, pts: &mut Vec<Point2>| {
            let n = self.arc_segments.max(1);
            for k in 0..=n {
                let a = a0 + (a1 - a0) * k as f64 / n as f64;
                pts.push(Point2::new(r * a.cos(), r * a.sin()));
            }
        };
        let mut pts = Vec::new();
        for t in 0..self.teeth {
            let c = pitch * t as f64;
            let root_half = pitch * self.root_share / 2.0;
            let tip_half = pitch * self.tip_share / 2.0;
            // Root land before the tooth, the tooth's tip land, then on to the next.
            arc(self.root_radius, c - pitch / 2.0, c - root_half, &mut pts);
            arc(self.tip_radius, c - tip_half, c + tip_half, &mut pts);
            arc(self.root_radius, c + root_half, c + pitch / 2.0, &mut pts);
            pts.pop();
        }
        dedup(Contour::new(pts))
    }
}

/// Removes consecutive duplicate points (and a closing duplicate).
pub fn dedup(mut c: Contour) -> Contour {
    c.points.dedup_by(|a, b| (*a - *b).norm() < 1e-12);
    while c.points.len() > 1 && (c.points[0] - c.points[c.points.len() - 1]).norm() < 1e-12 {
        c.points.pop();
    }
    c
}

/// A polygon with `outer` and holes oriented as Lamina expects.
pub fn polygon(outer: Contour, holes: Vec<Contour>) -> Polygon {
    Polygon::new(
        outer.oriented(true),
        holes.into_iter().map(|h| h.oriented(false)).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gear_outline_is_ccw_between_root_and_tip() {
        let g = GearProfile {
            teeth: 12,
            tip_radius: 20.0,
            root_radius: 16.0,
            tip_share: 0.3,
            root_share: 0.55,
            arc_segments: 3,
        };
        let o = g.outline();
        assert!(o.is_ccw());
        for p in &o.points {
            let r = p.coords.norm();
            assert!((16.0 - 1e-9..=20.0 + 1e-9).contains(&r));
        }
        let area = o.area();
        assert!(area > std::f64::consts::PI * 16.0 * 16.0 && area < std::f64::consts::PI * 400.0);
    }
}
