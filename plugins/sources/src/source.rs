//! One grading source: where d is measured from, f(d), the end compositions, the
//! step width and the weight; the step-wise truncation of f and the distance
//! thresholds where the steps change.

use lamina_api::Point2;
use lamina_fgm::steps::Truncation;

/// Where distances are measured from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Datum {
    /// d = distance to a point.
    Point([f64; 3]),
    /// d = distance to the line through `at` along `direction` (unit).
    Axis { at: [f64; 3], direction: [f64; 3] },
    /// d = signed distance along the unit normal from the plane through `at`; points
    /// behind the plane have f < 0 (the -ve complementary region).
    Plane { at: [f64; 3], normal: [f64; 3] },
    /// d = the minimum distance in space from the selected outer surfaces of the part
    /// (grading-step-width Fig. 1d): chosen faces of the part's mesh, measured from the
    /// layer's mid-plane.
    Surface,
    /// d = distance to the outer surface measured within the layer: the shortest
    /// distance to the family's boundary (its outer contour and its holes). The
    /// surface seen by each layer on its own, blind to the faces above and below.
    LayerBoundary,
}

/// A grading source.
#[derive(Debug, Clone, PartialEq)]
pub struct Source {
    pub datum: Datum,
    /// f(d) = (alpha d)^k for d >= 0; f(d) = alpha d for d < 0 (only planes give d < 0).
    pub alpha: f64,
    pub k: f64,
    /// Composition where f <= 0 (Ms) and where f >= 1 (Me), over the part's materials.
    pub start: Vec<f64>,
    pub end: Vec<f64>,
    /// Grading step-width t_g and its levels.
    pub steps: Truncation,
    /// Weight k_i of Eq. 8.
    pub weight: f64,
}

impl Source {
    /// f(d).
    pub fn f(&self, d: f64) -> f64 {
        if d < 0.0 {
            self.alpha * d
        } else {
            (self.alpha * d).powf(self.k)
        }
    }

    /// The distance where f reaches `value` (in (0, 1)): the inverse of f.
    pub fn d_at(&self, value: f64) -> f64 {
        value.powf(1.0 / self.k) / self.alpha
    }

    /// N_c = 1/t_g + 1 step levels 0, t_g, ..., 1.
    pub fn levels(&self) -> Vec<f64> {
        self.steps.levels()
    }

    /// The truncated value of f (grading-step-width 3.1): 0 below t_g/2, t_g (u + 1)
    /// from (u + 1/2) t_g, and 1 from the last half step.
    pub fn truncate(&self, f: f64) -> f64 {
        self.steps.truncate(f)
    }

    /// The distances where the truncated value steps up: f(d) = (u + 1/2) t_g.
    pub fn thresholds(&self) -> Vec<f64> {
        self.steps
            .thresholds()
            .into_iter()
            .map(|t| self.d_at(t))
            .collect()
    }

    /// The composition at a truncated level (Eq. 2: Ms + (Me - Ms) f).
    pub fn composition(&self, level: f64) -> Vec<f64> {
        self.start
            .iter()
            .zip(&self.end)
            .map(|(s, e)| s + (e - s) * level)
            .collect()
    }

    /// Distance of a point of the layer plane at height `z`; NaN for the surfaces,
    /// whose distance depends on the part's mesh or the layer's contours.
    pub fn distance(&self, p: Point2, z: f64) -> f64 {
        match self.datum {
            Datum::Point(c) => ((p.x - c[0]).powi(2) + (p.y - c[1]).powi(2) + (z - c[2]).powi(2)).sqrt(),
            Datum::Axis { at, direction: u } => {
                let w = [p.x - at[0], p.y - at[1], z - at[2]];
                let along = w[0] * u[0] + w[1] * u[1] + w[2] * u[2];
                (w[0] * w[0] + w[1] * w[1] + w[2] * w[2] - along * along)
                    .max(0.0)
                    .sqrt()
            }
            Datum::Plane { at, normal: n } => {
                (p.x - at[0]) * n[0] + (p.y - at[1]) * n[1] + (z - at[2]) * n[2]
            }
            Datum::Surface | Datum::LayerBoundary => f64::NAN,
        }
    }
}

/// Eq. 8: the weighted combination of the sources' compositions at a point.
pub fn combine(parts: &[(f64, Vec<f64>)]) -> Vec<f64> {
    let total: f64 = parts.iter().map(|(k, _)| k).sum();
    let n = parts.first().map_or(0, |(_, m)| m.len());
    (0..n)
        .map(|j| parts.iter().map(|(k, m)| k * m[j]).sum::<f64>() / total)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn source(step: f64) -> Source {
        Source {
            datum: Datum::Point([0.0; 3]),
            alpha: 0.1,
            k: 1.0,
            start: vec![1.0, 0.0],
            end: vec![0.0, 1.0],
            steps: Truncation::new(step).unwrap(),
            weight: 1.0,
        }
    }

    /// grading-step-width 3.1: t_g = 0.25 gives N_c = 5 levels 0, .25, .5, .75, 1 and
    /// the truncation at the half steps.
    #[test]
    fn step_width_quarter_truncates_at_half_steps() {
        // The levels and the truncation are the shared step rule's (its own table of
        // t_g = 0.25 is in lamina-api's steps); the source must use it as it is.
        let s = source(0.25);
        assert_eq!(s.levels(), [0.0, 0.25, 0.5, 0.75, 1.0]);
        for f in (-30..=170).map(|i| f64::from(i) / 100.0) {
            assert_eq!(s.truncate(f), s.steps.truncate(f), "f = {f}");
        }
        assert_eq!(s.truncate(0.374), 0.25);
        assert_eq!(s.truncate(0.375), 0.5);
        let d: Vec<f64> = s.thresholds();
        let want = [1.25, 3.75, 6.25, 8.75];
        assert_eq!(d.len(), want.len());
        for (a, b) in d.iter().zip(want) {
            assert!((a - b).abs() < 1e-12);
        }
        assert_eq!(source(1.0).levels(), [0.0, 1.0]);
        assert_eq!(source(0.1).levels().len(), 11);
        // A step that does not divide 1: the paper's half-step thresholds, 1 at the top
        // (the same rule as the `step-width` discretiser).
        assert_eq!(source(0.3).levels(), [0.0, 0.3, 0.6, 1.0]);
        assert_eq!(source(0.3).truncate(0.8), 1.0);
    }

    #[test]
    fn compositions_follow_eq_2_and_combine_by_eq_8() {
        let s = source(0.25);
        assert_eq!(s.composition(0.25), [0.75, 0.25]);
        let m = combine(&[(1.0, vec![1.0, 0.0]), (3.0, vec![0.0, 1.0])]);
        assert_eq!(m, [0.25, 0.75]);
    }

    /// f(d) = (alpha d)^k, alpha d behind a plane, and its inverse, with alpha and k
    /// other than 1; the distances to data placed off the origin and turned off the
    /// axes, worked by hand.
    #[test]
    fn f_its_inverse_and_distances_away_from_the_origin() {
        let s = Source {
            alpha: 0.2,
            k: 2.0,
            ..source(0.25)
        };
        assert!((s.f(3.0) - 0.36).abs() < 1e-12);
        assert!((s.f(-2.0) + 0.4).abs() < 1e-12);
        assert!((s.d_at(0.36) - 3.0).abs() < 1e-12);
        // Thresholds where f = 0.125, 0.375, 0.625, 0.875: d = sqrt(t) / 0.2.
        for (d, t) in s.thresholds().iter().zip([0.125f64, 0.375, 0.625, 0.875]) {
            assert!((d - t.sqrt() / 0.2).abs() < 1e-12, "{d}");
        }
        let at = |datum| Source { datum, ..source(0.5) };
        let p = Point2::new(4.0, 2.0);
        // (3, 4, 3) from the point.
        let d = at(Datum::Point([1.0, -2.0, 0.5])).distance(p, 3.5);
        assert!((d - 34f64.sqrt()).abs() < 1e-12, "{d}");
        // w = (2, 3, 1) from (1, 1, 1); along (2, 1, 2)/3 it runs 3: 14 - 9 = 5.
        let axis = at(Datum::Axis {
            at: [1.0, 1.0, 1.0],
            direction: [2.0 / 3.0, 1.0 / 3.0, 2.0 / 3.0],
        });
        assert!((axis.distance(Point2::new(3.0, 4.0), 2.0) - 5f64.sqrt()).abs() < 1e-12);
        // (3, 4, 2) from (1, 2, 3) along (2, 3, 6)/7: 30/7.
        let plane = at(Datum::Plane {
            at: [1.0, 2.0, 3.0],
            normal: [2.0 / 7.0, 3.0 / 7.0, 6.0 / 7.0],
        });
        assert!((plane.distance(Point2::new(4.0, 6.0), 5.0) - 30.0 / 7.0).abs() < 1e-12);
    }

    #[test]
    fn distances_to_each_datum() {
        let p = Point2::new(3.0, 4.0);
        assert_eq!(source(0.5).distance(p, 0.0), 5.0);
        let axis = Source {
            datum: Datum::Axis {
                at: [0.0; 3],
                direction: [0.0, 0.0, 1.0],
            },
            ..source(0.5)
        };
        assert_eq!(axis.distance(p, 7.0), 5.0);
        let plane = Source {
            datum: Datum::Plane {
                at: [1.0, 0.0, 0.0],
                normal: [1.0, 0.0, 0.0],
            },
            ..source(0.5)
        };
        assert_eq!(plane.distance(p, 0.0), 2.0);
        assert_eq!(plane.distance(Point2::new(-1.0, 0.0), 0.0), -2.0);
        assert!(plane.f(-2.0) < 0.0);
    }
}
