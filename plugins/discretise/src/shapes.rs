//! Generated contours for tests and benchmarks: circles and rectangles, counter-clockwise.

use lamina_core::{Contour, Point2};

/// A regular `n`-gon inscribed in the circle of radius `r` about `(cx, cy)`.
pub fn circle(cx: f64, cy: f64, r: f64, n: usize) -> Contour {
    Contour::new(
        (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                Point2::new(cx + r * a.cos(), cy + r * a.sin())
            })
            .collect(),
    )
}

/// The axis-aligned rectangle from `(x0, y0)` of size `w` by `h`.
pub fn rect(x0: f64, y0: f64, w: f64, h: f64) -> Contour {
    Contour::new(vec![
        Point2::new(x0, y0),
        Point2::new(x0 + w, y0),
        Point2::new(x0 + w, y0 + h),
        Point2::new(x0, y0 + h),
    ])
}
