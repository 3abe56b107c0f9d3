//! Generated contours for tests and benchmarks, in the short form they are written in
//! there: circles and rectangles, counter-clockwise, and contours through listed points.

use lamina_api::{Contour, Point2};

/// A regular `n`-gon inscribed in the circle of radius `r` about `(cx, cy)`.
pub fn circle(cx: f64, cy: f64, r: f64, n: usize) -> Contour {
    Contour::circle(Point2::new(cx, cy), r, n)
}

/// The axis-aligned rectangle from `(x0, y0)` of size `w` by `h`.
pub fn rect(x0: f64, y0: f64, w: f64, h: f64) -> Contour {
    Contour::rectangle(Point2::new(x0, y0), Point2::new(x0 + w, y0 + h))
}

/// The contour through `points`, in their order and orientation.
pub fn through(points: &[(f64, f64)]) -> Contour {
    Contour::new(points.iter().map(|&(x, y)| Point2::new(x, y)).collect())
}
