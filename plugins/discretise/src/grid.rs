//! The integer grid every boolean and offset of one family runs on: one origin and one
//! power-of-two scale per family, so that offsets, differences and intersections of the
//! same family share their vertices exactly and the sub-regions tile by construction.

use i_overlay::i_float::int::point::IntPoint;
use i_overlay::i_shape::int::shape::{IntContour, IntShape, IntShapes};
use lamina_api::{Contour, Error, Point2, Polygon, Result};
use lamina_geom::offset::grid_scale;

/// Maps the family's plane to i32 grid points: `(p - origin) * scale`, rounded.
#[derive(Debug, Clone, Copy)]
pub struct Grid {
    origin: Point2,
    scale: f64,
}

impl Grid {
    /// The grid for a polygon: origin at its bounding-box centre, the largest
    /// power-of-two scale that keeps the polygon (and offsets inside it) in range, by
    /// the offset engine's rule ([`grid_scale`]).
    /// Refuses non-finite or zero-extent geometry.
    pub fn for_polygon(polygon: &Polygon, stage: &str) -> Result<Self> {
        let bbox = polygon.bbox();
        let finite = polygon
            .contours()
            .flat_map(|c| c.points.iter())
            .all(|p| p.x.is_finite() && p.y.is_finite());
        if !finite || bbox.is_empty() {
            return Err(Error::stage(stage, "family has non-finite or no coordinates"));
        }
        let half = 0.5 * bbox.width().max(bbox.height());
        if half <= 0.0 {
            return Err(Error::stage(stage, "family has zero extent"));
        }
        let scale = grid_scale(half);
        Ok(Self {
            origin: bbox.center(),
            scale,
        })
    }

    /// The family's grid and its shape on it, cleaned; `None` when the grid cannot
    /// hold the polygon or nothing of it is left on the grid (the discretisers then
    /// keep the family as one region).
    pub fn family(polygon: &Polygon, stage: &str) -> Option<(Self, IntShapes<i32>)> {
        let grid = Self::for_polygon(polygon, stage).ok()?;
        let base = crate::bands::clean(&vec![grid.shape(polygon)]);
        (!base.is_empty()).then_some((grid, base))
    }

    /// Grid units per mm.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    pub fn point(&self, p: Point2) -> IntPoint<i32> {
        IntPoint::new(
            ((p.x - self.origin.x) * self.scale).round() as i32,
            ((p.y - self.origin.y) * self.scale).round() as i32,
        )
    }

    pub fn unpoint(&self, p: IntPoint<i32>) -> Point2 {
        Point2::new(
            f64::from(p.x) / self.scale + self.origin.x,
            f64::from(p.y) / self.scale + self.origin.y,
        )
    }

    pub fn contour(&self, c: &Contour) -> IntContour<i32> {
        self.snapped(c.points.iter().copied())
    }

    /// [`Grid::contour`] of a ring of coordinates.
    pub fn ring(&self, ring: &[[f64; 2]]) -> IntContour<i32> {
        self.snapped(ring.iter().map(|&[x, y]| Point2::new(x, y)))
    }

    /// A ring's points on the grid, repeats (and a closing copy of the first) dropped.
    fn snapped(&self, points: impl ExactSizeIterator<Item = Point2>) -> IntContour<i32> {
        let mut out: IntContour<i32> = Vec::with_capacity(points.len());
        for p in points {
            let q = self.point(p);
            if out.last() != Some(&q) {
                out.push(q);
            }
        }
        while out.len() > 1 && out.first() == out.last() {
            out.pop();
        }
        out
    }

    pub fn shape(&self, polygon: &Polygon) -> IntShape<i32> {
        polygon.contours().map(|c| self.contour(c)).collect()
    }

    pub fn uncontour(&self, c: &[IntPoint<i32>]) -> Contour {
        Contour::new(c.iter().map(|&p| self.unpoint(p)).collect())
    }

    /// Overlay shapes (outer counter-clockwise first, holes clockwise) as polygons.
    pub fn polygons(&self, shapes: &IntShapes<i32>) -> Vec<Polygon> {
        shapes
            .iter()
            .filter(|s| !s.is_empty())
            .map(|s| {
                Polygon::new(
                    self.uncontour(&s[0]),
                    s[1..].iter().map(|h| self.uncontour(h)).collect(),
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_geom::offset::HALF_RANGE;

    /// Points that land on one grid point are one; a ring closed by a copy of its
    /// first point, or several, is left open; a ring of one point stays one point.
    #[test]
    fn snapping_drops_repeats_and_closing_copies() {
        let grid = Grid {
            origin: Point2::new(0.0, 0.0),
            scale: 1.0,
        };
        let at = |v: &[(f64, f64)]| {
            grid.snapped(
                v.iter()
                    .map(|&(x, y)| Point2::new(x, y))
                    .collect::<Vec<_>>()
                    .into_iter(),
            )
        };
        let q = |x: i32, y: i32| IntPoint::new(x, y);
        assert_eq!(
            at(&[
                (0.0, 0.0),
                (0.2, 0.1),
                (3.0, 0.0),
                (3.0, 2.0),
                (0.0, 0.0),
                (0.1, 0.0)
            ]),
            vec![q(0, 0), q(3, 0), q(3, 2)]
        );
        assert_eq!(at(&[(1.0, 1.0), (1.0, 1.0), (1.0, 1.0)]), vec![q(1, 1)]);
        assert_eq!(at(&[(0.0, 0.0), (2.0, 0.0), (0.0, 0.0)]), vec![q(0, 0), q(2, 0)]);
    }

    /// A family with one coordinate not a number, or none at all, has no grid: a NaN
    /// in y alone, or an infinite x, is enough.
    #[test]
    fn non_finite_or_empty_families_are_refused() {
        let triangle = |x: f64, y: f64| {
            Polygon::new(
                Contour::new(vec![
                    Point2::new(0.0, 0.0),
                    Point2::new(10.0, 0.0),
                    Point2::new(x, y),
                ]),
                Vec::new(),
            )
        };
        assert!(Grid::for_polygon(&triangle(5.0, 5.0), "test").is_ok());
        for (x, y) in [
            (5.0, f64::NAN),
            (f64::INFINITY, 5.0),
            (f64::NAN, 5.0),
            (5.0, f64::NEG_INFINITY),
        ] {
            let err = Grid::for_polygon(&triangle(x, y), "test").expect_err("refused");
            assert!(err.to_string().contains("non-finite"), "({x}, {y}): {err}");
        }
        let empty = Polygon::new(Contour::new(Vec::new()), Vec::new());
        assert!(Grid::for_polygon(&empty, "test").is_err());
        let point = Polygon::new(Contour::new(vec![Point2::new(1.0, 1.0); 3]), Vec::new());
        assert!(Grid::for_polygon(&point, "test").is_err());
    }

    #[test]
    fn round_trip_is_within_half_a_unit() {
        let poly = Polygon::new(
            Contour::new(vec![
                Point2::new(100.0, 100.0),
                Point2::new(160.0, 100.0),
                Point2::new(160.0, 131.0),
            ]),
            vec![],
        );
        let g = Grid::for_polygon(&poly, "t").expect("grid");
        for &p in &poly.outer.points {
            let q = g.unpoint(g.point(p));
            assert!((q - p).norm() <= 1.0 / g.scale);
        }
        assert!(g.scale * 30.0 <= HALF_RANGE && g.scale * 60.0 > HALF_RANGE);
    }

    #[test]
    fn degenerate_input_is_an_error() {
        let poly = Polygon::new(Contour::new(vec![Point2::new(1.0, 1.0); 3]), vec![]);
        assert!(Grid::for_polygon(&poly, "t").is_err());
        let nan = Polygon::new(Contour::new(vec![Point2::new(f64::NAN, 1.0); 3]), vec![]);
        assert!(Grid::for_polygon(&nan, "t").is_err());
    }
}
