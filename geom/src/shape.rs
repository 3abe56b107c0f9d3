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
}
