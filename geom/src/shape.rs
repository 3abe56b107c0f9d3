//! The shapes every stage passes on: closed contours, polygons with holes and bounding
//! boxes, on nalgebra points, with the measures every stage needs (area, orientation,
//! containment, distance). These types cross the plugin boundary: core's wire
//! fingerprint hashes this file.

use serde::{Deserialize, Serialize};

use crate::segment::segment_distance;

pub type Point2 = nalgebra::Point2<f64>;
pub type Vector2 = nalgebra::Vector2<f64>;

/// A closed contour: the last point connects back to the first, which is not repeated.
/// Outer boundaries are counter-clockwise, holes clockwise (positive area = material).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Contour {
    pub points: Vec<Point2>,
}

impl Contour {
    pub fn new(points: Vec<Point2>) -> Self {
        Self { points }
    }

    /// The regular polygon of `n` vertices (at least 3) inscribed in the circle of
    /// `radius` about `centre`, counter-clockwise from angle 0.
    pub fn circle(centre: Point2, radius: f64, n: usize) -> Self {
        let n = n.max(3);
        Self::new(
            (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    centre + Vector2::new(a.cos(), a.sin()) * radius
                })
                .collect(),
        )
    }

    /// The axis-aligned rectangle with corners `min` and `max`, counter-clockwise
    /// from `min`.
    pub fn rectangle(min: Point2, max: Point2) -> Self {
        Self::new(vec![
            min,
            Point2::new(max.x, min.y),
            max,
            Point2::new(min.x, max.y),
        ])
    }

    /// The square of side `2 * half` about `centre`, counter-clockwise.
    pub fn square(centre: Point2, half: f64) -> Self {
        let h = Vector2::new(half, half);
        Self::rectangle(centre - h, centre + h)
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The edges as point pairs, including the closing edge.
    pub fn edges(&self) -> impl Iterator<Item = (Point2, Point2)> + '_ {
        let n = self.points.len();
        (0..n).map(move |i| (self.points[i], self.points[(i + 1) % n]))
    }

    /// Signed area by the shoelace formula: positive when counter-clockwise.
    pub fn signed_area(&self) -> f64 {
        // Summing relative to the first point keeps precision far from the origin.
        let Some(o) = self.points.first() else {
            return 0.0;
        };
        let mut twice = 0.0;
        for (a, b) in self.edges() {
            twice += (a.x - o.x) * (b.y - o.y) - (b.x - o.x) * (a.y - o.y);
        }
        twice / 2.0
    }

    pub fn area(&self) -> f64 {
        self.signed_area().abs()
    }

    pub fn is_ccw(&self) -> bool {
        self.signed_area() > 0.0
    }

    pub fn reverse(&mut self) {
        self.points.reverse();
    }

    /// Returns the contour oriented counter-clockwise (`ccw = true`) or clockwise.
    pub fn oriented(mut self, ccw: bool) -> Self {
        if self.is_ccw() != ccw {
            self.reverse();
        }
        self
    }

    pub fn perimeter(&self) -> f64 {
        self.edges().map(|(a, b)| (b - a).norm()).sum()
    }

    pub fn bbox(&self) -> BBox2 {
        BBox2::from_points(self.points.iter().copied())
    }

    /// Winding number of the contour around `p` (non-zero = inside). Points on the
    /// boundary may go either way; callers that care test [`Contour::distance`].
    pub fn winding_number(&self, p: Point2) -> i32 {
        let mut wn = 0;
        for (a, b) in self.edges() {
            let cross = (b.x - a.x) * (p.y - a.y) - (p.x - a.x) * (b.y - a.y);
            if a.y <= p.y {
                if b.y > p.y && cross > 0.0 {
                    wn += 1;
                }
            } else if b.y <= p.y && cross < 0.0 {
                wn -= 1;
            }
        }
        wn
    }

    pub fn contains(&self, p: Point2) -> bool {
        self.winding_number(p) != 0
    }

    /// Shortest distance from `p` to the contour's boundary.
    pub fn distance(&self, p: Point2) -> f64 {
        self.edges()
            .map(|(a, b)| segment_distance(p, a, b))
            .fold(f64::INFINITY, f64::min)
    }

    /// A point strictly inside the contour (for containment tests between contours that
    /// do not cross): the midpoint of the first edge nudged inward, falling back to
    /// scanning for an interior point.
    pub fn interior_point(&self) -> Option<Point2> {
        if self.points.len() < 3 {
            return None;
        }
        let ccw = self.is_ccw();
        let scale = self.bbox().diagonal().max(f64::MIN_POSITIVE);
        for (a, b) in self.edges() {
            let d = b - a;
            let len = d.norm();
            if len <= 0.0 {
                continue;
            }
            let inward = if ccw {
                Vector2::new(-d.y, d.x)
            } else {
                Vector2::new(d.y, -d.x)
            } / len;
            let mid = a + d * 0.5;
            let mut step = len.min(scale) * 1e-3;
            for _ in 0..8 {
                let q = mid + inward * step;
                if self.contains(q) && self.distance(q) > step * 0.25 {
                    return Some(q);
                }
                step *= 0.1;
            }
        }
        None
    }
}

/// A solid area: one outer contour (counter-clockwise) and its holes (clockwise).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Polygon {
    pub outer: Contour,
    #[serde(default)]
    pub holes: Vec<Contour>,
}

impl Polygon {
    pub fn new(outer: Contour, holes: Vec<Contour>) -> Self {
        Self { outer, holes }
    }

    /// Material area: the outer area less the holes.
    pub fn area(&self) -> f64 {
        self.outer.area() - self.holes.iter().map(Contour::area).sum::<f64>()
    }

    pub fn contains(&self, p: Point2) -> bool {
        self.outer.contains(p) && !self.holes.iter().any(|h| h.contains(p))
    }

    /// Shortest distance from `p` to any boundary of the polygon.
    pub fn boundary_distance(&self, p: Point2) -> f64 {
        self.holes
            .iter()
            .map(|h| h.distance(p))
            .fold(self.outer.distance(p), f64::min)
    }

    pub fn bbox(&self) -> BBox2 {
        self.outer.bbox()
    }

    /// All contours, outer first.
    pub fn contours(&self) -> impl Iterator<Item = &Contour> {
        std::iter::once(&self.outer).chain(self.holes.iter())
    }
}

/// An axis-aligned box in the plane. Empty boxes have `min > max`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BBox2 {
    pub min: Point2,
    pub max: Point2,
}

impl Default for BBox2 {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl BBox2 {
    pub const EMPTY: BBox2 = BBox2 {
        min: Point2::new(f64::INFINITY, f64::INFINITY),
        max: Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
    };

    pub fn from_points(points: impl IntoIterator<Item = Point2>) -> Self {
        let mut b = Self::EMPTY;
        for p in points {
            b.include(p);
        }
        b
    }

    pub fn include(&mut self, p: Point2) {
        self.min = Point2::new(self.min.x.min(p.x), self.min.y.min(p.y));
        self.max = Point2::new(self.max.x.max(p.x), self.max.y.max(p.y));
    }

    pub fn union(&self, other: &BBox2) -> BBox2 {
        BBox2 {
            min: Point2::new(self.min.x.min(other.min.x), self.min.y.min(other.min.y)),
            max: Point2::new(self.max.x.max(other.max.x), self.max.y.max(other.max.y)),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y
    }

    pub fn width(&self) -> f64 {
        (self.max.x - self.min.x).max(0.0)
    }

    pub fn height(&self) -> f64 {
        (self.max.y - self.min.y).max(0.0)
    }

    pub fn diagonal(&self) -> f64 {
        if self.is_empty() {
            0.0
        } else {
            (self.max - self.min).norm()
        }
    }

    pub fn center(&self) -> Point2 {
        nalgebra::center(&self.min, &self.max)
    }

    pub fn contains_box(&self, other: &BBox2) -> bool {
        self.min.x <= other.min.x
            && self.min.y <= other.min.y
            && self.max.x >= other.max.x
            && self.max.y >= other.max.y
    }

    pub fn overlaps(&self, other: &BBox2) -> bool {
        self.min.x <= other.max.x
            && other.min.x <= self.max.x
            && self.min.y <= other.max.y
            && other.min.y <= self.max.y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x0: f64, y0: f64, s: f64) -> Contour {
        Contour::rectangle(Point2::new(x0, y0), Point2::new(x0 + s, y0 + s))
    }

    #[test]
    fn square_measures() {
        let c = square(1e6, 1e6, 2.0);
        assert_eq!(c.signed_area(), 4.0);
        assert!(c.is_ccw());
        assert_eq!(c.perimeter(), 8.0);
        assert!(c.contains(Point2::new(1e6 + 1.0, 1e6 + 1.0)));
        assert!(!c.contains(Point2::new(1e6 + 3.0, 1e6 + 1.0)));
        assert!((c.distance(Point2::new(1e6 + 1.0, 1e6 + 0.5)) - 0.5).abs() < 1e-9);
        let p = c.interior_point().expect("interior point");
        assert!(c.contains(p));
    }

    #[test]
    fn polygon_with_hole() {
        let p = Polygon::new(square(0.0, 0.0, 4.0), vec![square(1.0, 1.0, 2.0).oriented(false)]);
        assert_eq!(p.area(), 12.0);
        assert!(!p.contains(Point2::new(2.0, 2.0)));
        assert!(p.contains(Point2::new(0.5, 2.0)));
        assert_eq!(p.boundary_distance(Point2::new(0.5, 2.0)), 0.5);
    }

    /// Whether `p` is inside `c` by counting the edges a ray to the right crosses.
    fn crossings_odd(c: &Contour, p: Point2) -> bool {
        c.edges()
            .filter(|(a, b)| {
                (a.y > p.y) != (b.y > p.y) && a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) > p.x
            })
            .count()
            % 2
            == 1
    }

    #[test]
    fn winding_numbers_count_turns_with_their_sign() {
        // A star with notches, either way round, against the crossing count.
        let star = Contour::new(
            (0..18)
                .map(|i| {
                    let a = std::f64::consts::TAU * f64::from(i) / 18.0;
                    let r = if i % 2 == 0 { 9.0 } else { 4.0 };
                    Point2::new(3.0 + r * a.cos(), -2.0 + r * a.sin())
                })
                .collect(),
        );
        let cw = star.clone().oriented(false);
        for j in 0..60 {
            for i in 0..60 {
                let p = Point2::new(-7.05 + f64::from(i) * 0.34, -12.03 + f64::from(j) * 0.34);
                let inside = crossings_odd(&star, p);
                assert_eq!(star.winding_number(p), i32::from(inside), "{p:?}");
                assert_eq!(cw.winding_number(p), -i32::from(inside), "{p:?}");
                assert_eq!(star.contains(p), inside);
                assert_eq!(cw.contains(p), inside);
            }
        }
        // Points level with vertices: counted once, either way round, inside and out.
        let diamond = Contour::new(vec![
            Point2::new(5.0, 0.0),
            Point2::new(10.0, 5.0),
            Point2::new(5.0, 10.0),
            Point2::new(0.0, 5.0),
        ]);
        let reversed = diamond.clone().oriented(false);
        for (p, w) in [
            ((5.0, 5.0), 1),
            ((12.0, 5.0), 0),
            ((-1.0, 5.0), 0),
            ((5.0, 9.0), 1),
            ((3.0, 0.0), 0),
        ] {
            let p = Point2::new(p.0, p.1);
            assert_eq!(diamond.winding_number(p), w, "{p:?}");
            assert_eq!(reversed.winding_number(p), -w, "{p:?}");
        }
        // A circle gone round twice winds twice.
        let mut twice = Contour::circle(Point2::new(0.0, 0.0), 1.0, 16).points;
        twice.extend(twice.clone());
        assert_eq!(Contour::new(twice).winding_number(Point2::new(0.1, 0.2)), 2);
    }

    #[test]
    fn circles_rectangles_and_squares_run_counter_clockwise() {
        let c = Contour::circle(Point2::new(1.0, 2.0), 3.0, 6);
        assert_eq!(c.len(), 6);
        assert!((c.points[0] - Point2::new(4.0, 2.0)).norm() < 1e-12);
        assert!(
            c.points
                .iter()
                .all(|p| ((p - Point2::new(1.0, 2.0)).norm() - 3.0).abs() < 1e-12)
        );
        assert!(c.is_ccw());
        // A hexagon of circumradius 3: 6 equilateral triangles of side 3.
        assert!((c.area() - 6.0 * 9.0 * 3f64.sqrt() / 4.0).abs() < 1e-9);
        assert_eq!(Contour::circle(Point2::new(0.0, 0.0), 1.0, 1).len(), 3);
        let r = Contour::rectangle(Point2::new(-1.0, 2.0), Point2::new(3.0, 5.0));
        assert_eq!(
            r.points,
            vec![
                Point2::new(-1.0, 2.0),
                Point2::new(3.0, 2.0),
                Point2::new(3.0, 5.0),
                Point2::new(-1.0, 5.0)
            ]
        );
        assert_eq!((r.signed_area(), r.perimeter()), (12.0, 14.0));
        let s = Contour::square(Point2::new(1.0, 1.0), 0.5);
        assert_eq!(s.points[0], Point2::new(0.5, 0.5));
        assert_eq!(s.points[2], Point2::new(1.5, 1.5));
        let mut back = r.clone();
        back.reverse();
        assert_eq!(back.signed_area(), -12.0);
        assert!(!back.is_ccw());
        assert_eq!(back.clone().oriented(true).signed_area(), 12.0);
        assert_eq!(back.clone().oriented(false), back);
        assert_eq!(Contour::default().signed_area(), 0.0);
        assert!(Contour::default().is_empty() && !r.is_empty());
    }

    #[test]
    fn an_interior_point_is_inside_and_off_the_boundary() {
        // A thin C, either way round, starting on a degenerate edge: the point is
        // strictly inside, clear of the boundary by a share of its nudge.
        let c = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(0.0, 0.0),
            Point2::new(10.0, 0.0),
            Point2::new(10.0, 0.2),
            Point2::new(0.2, 0.2),
            Point2::new(0.2, 9.8),
            Point2::new(10.0, 9.8),
            Point2::new(10.0, 10.0),
            Point2::new(0.0, 10.0),
        ]);
        for c in [c.clone(), c.oriented(false)] {
            let p = c.interior_point().expect("a point inside");
            assert!(crossings_odd(&c, p), "{p:?}");
            assert!(c.distance(p) > 1e-6, "{p:?}");
        }
        // Nothing inside: too few points, or all on a line.
        assert!(
            Contour::new(vec![Point2::new(0.0, 0.0), Point2::new(1.0, 1.0)])
                .interior_point()
                .is_none()
        );
        let flat = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(2.0, 2.0),
        ]);
        assert!(flat.interior_point().is_none());
    }

    #[test]
    fn boxes_grow_join_and_compare() {
        let b = BBox2::from_points([
            Point2::new(1.0, 5.0),
            Point2::new(-2.0, 3.0),
            Point2::new(0.0, 9.0),
        ]);
        assert_eq!((b.min, b.max), (Point2::new(-2.0, 3.0), Point2::new(1.0, 9.0)));
        assert_eq!((b.width(), b.height(), b.diagonal()), (3.0, 6.0, 45f64.sqrt()));
        assert_eq!(b.center(), Point2::new(-0.5, 6.0));
        assert!(!b.is_empty());
        // Inside out along one axis only is empty too.
        let flat_x = BBox2 {
            min: Point2::new(1.0, 0.0),
            max: Point2::new(0.0, 1.0),
        };
        let flat_y = BBox2 {
            min: Point2::new(0.0, 1.0),
            max: Point2::new(1.0, 0.0),
        };
        assert!(flat_x.is_empty() && flat_y.is_empty());
        let empty = BBox2::default();
        assert!(empty.is_empty());
        assert_eq!((empty.width(), empty.height(), empty.diagonal()), (0.0, 0.0, 0.0));
        assert_eq!(empty.union(&b), b);
        // A box of no width is not empty.
        assert!(!BBox2::from_points([Point2::new(1.0, 1.0), Point2::new(1.0, 2.0)]).is_empty());
        let other = BBox2::from_points([Point2::new(1.0, 0.0), Point2::new(4.0, 3.0)]);
        let u = b.union(&other);
        assert_eq!((u.min, u.max), (Point2::new(-2.0, 0.0), Point2::new(4.0, 9.0)));
        assert!(u.contains_box(&b) && u.contains_box(&other) && !b.contains_box(&u));
        // Reaching beyond a box's top right is not enough, nor its bottom left alone.
        let unit = BBox2::from_points([Point2::new(0.0, 0.0), Point2::new(1.0, 1.0)]);
        let shifted = BBox2::from_points([Point2::new(0.5, 0.5), Point2::new(2.0, 2.0)]);
        assert!(!shifted.contains_box(&unit) && !unit.contains_box(&shifted));
        // Touching at a corner overlaps; apart along x or along y does not.
        assert!(b.overlaps(&other) && other.overlaps(&b));
        let right = BBox2::from_points([Point2::new(1.5, 3.0), Point2::new(2.0, 9.0)]);
        let above = BBox2::from_points([Point2::new(-2.0, 9.5), Point2::new(1.0, 10.0)]);
        let below = BBox2::from_points([Point2::new(-2.0, 0.0), Point2::new(1.0, 2.5)]);
        for o in [right, above, below] {
            assert!(!b.overlaps(&o) && !o.overlaps(&b), "{o:?}");
        }
        let polygon = Polygon::new(Contour::rectangle(b.min, b.max), Vec::new());
        assert_eq!(polygon.bbox(), b);
    }
}
