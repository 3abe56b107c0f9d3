//! Circumferential cells (Fig. 13): each sub-region split along its own offset contour
//! into cells of equal arc length, so that a grader can vary the material around the
//! contours too. The cuts run across the ring toward its largest hole (toward its most
//! inland point in a core); they are sliced on the family's grid, so the cells of a
//! region tile it exactly.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::string::line::IntLine;
use i_overlay::string::slice::IntSlice;
use lamina_core::stage::{OptionSpec, StageConfig};
use lamina_core::{Contour, Point2, Polygon, Region, Result, Vector2};

use crate::grid::Grid;
use crate::measure::{interior_point, pole};
use crate::regions::region;

/// More cells around one region than anyone could deposit: a guard against typos.
pub const MAX_CELLS: usize = 1000;

pub const AROUND_OPTION: OptionSpec = OptionSpec::new(
    "cells_around",
    "integer",
    "none",
    "split every sub-region into this many circumferential cells of equal arc length along its outer contour",
);

pub const LENGTH_OPTION: OptionSpec = OptionSpec::new(
    "cell_length",
    "float",
    "none",
    "split every sub-region into circumferential cells of equal arc length about this long (mm, along its middle)",
);

/// How sub-regions are split around.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Cells {
    #[default]
    None,
    /// This many cells of equal arc length.
    Around(usize),
    /// Cells about this long (mm) along the region's middle.
    Length(f64),
}

impl Cells {
    /// The setting from the stage options `cells_around` and `cell_length` (at most
    /// one of them).
    pub fn checked(around: Option<usize>, length: Option<f64>, config: &StageConfig<'_>) -> Result<Self> {
        match (around, length) {
            (Some(_), Some(_)) => {
                Err(config.error("cell_length", "give `cells_around` or `cell_length`, not both"))
            }
            (Some(n), None) if (1..=MAX_CELLS).contains(&n) => Ok(Cells::Around(n)),
            (Some(n), None) => Err(config.error(
                "cells_around",
                format!("`cells_around` must be in 1..={MAX_CELLS}, not {n}"),
            )),
            (None, Some(l)) if l > 0.0 && l.is_finite() => Ok(Cells::Length(l)),
            (None, Some(l)) => Err(config.error(
                "cell_length",
                format!("`cell_length` must be a positive number of mm, not {l}"),
            )),
            (None, None) => Ok(Cells::None),
        }
    }

    /// Number of cells for one region.
    fn count(&self, polygon: &Polygon) -> usize {
        match *self {
            Cells::None => 1,
            Cells::Around(n) => n,
            Cells::Length(l) => {
                // Along the middle of a ring: the mean of its outer and inner lengths;
                // half the outer length for a region without holes.
                let middle = 0.5
                    * (polygon.outer.perimeter() + polygon.holes.iter().map(|h| h.perimeter()).sum::<f64>());
                ((middle / l).round() as usize).clamp(1, MAX_CELLS)
            }
        }
    }

    /// Splits every region of `regions` (one family on `grid`) into its cells, each
    /// with `cell = Some(i)` and a reference point inside it. The cells of a region
    /// have equal arc lengths along its own outer contour (the offset contour it starts
    /// at): the cuts start at equal steps of arc length, counter-clockwise from the
    /// contour's point farthest along +x, and run toward the contour's pole across the
    /// region (see [`cuts`]).
    pub fn split(&self, grid: &Grid, regions: &mut Vec<Region>) {
        if *self == Cells::None || regions.is_empty() {
            return;
        }
        let mut out = Vec::with_capacity(regions.len());
        for r in regions.drain(..) {
            let n = self.count(&r.polygon);
            let cuts = if n > 1 {
                cuts(grid, &r.polygon, n)
            } else {
                Vec::new()
            };
            if cuts.is_empty() {
                out.push(Region { cell: Some(0), ..r });
                continue;
            }
            let shape = vec![grid.shape(&r.polygon)];
            let pieces = shape.slice_by_lines(&cuts, FillRule::NonZero);
            let mut cells: Vec<(f64, Polygon)> = grid
                .polygons(&pieces)
                .into_iter()
                .filter(|p| p.outer.len() >= 3)
                .map(|p| {
                    (
                        arc_position(
                            &r.polygon.outer,
                            interior_point(&p).unwrap_or_else(|| p.bbox().center()),
                        ),
                        p,
                    )
                })
                .collect();
            // Numbered along the contour from the first cut.
            cells.sort_by(|a, b| a.0.total_cmp(&b.0));
            for (i, (_, polygon)) in cells.into_iter().enumerate() {
                let mut c = region(r.family, r.index, r.count, r.level, polygon);
                c.cell = Some(i);
                out.push(c);
            }
        }
        *regions = out;
    }
}

/// Where a point projects onto a closed contour, as a fraction of its length from the
/// contour's start point of [`start`].
fn arc_position(outer: &Contour, p: Point2) -> f64 {
    let pts = start(outer);
    let total: f64 = perimeter(&pts);
    let (mut best, mut at, mut run) = (f64::INFINITY, 0.0, 0.0);
    for k in 0..pts.len() {
        let (a, b) = (pts[k], pts[(k + 1) % pts.len()]);
        let d = b - a;
        let len = d.norm();
        let t = if len > 0.0 {
            ((p - a).dot(&d) / (len * len)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let dist = (a + d * t - p).norm();
        if dist < best {
            best = dist;
            at = run + t * len;
        }
        run += len;
    }
    if total > 0.0 { at / total } else { 0.0 }
}

fn perimeter(pts: &[Point2]) -> f64 {
    (0..pts.len())
        .map(|k| (pts[(k + 1) % pts.len()] - pts[k]).norm())
        .sum()
}

/// The contour's points counter-clockwise from its point farthest along +x (the lowest
/// of those), so that cells start at the same side of every ring.
fn start(outer: &Contour) -> Vec<Point2> {
    let c = outer.clone().oriented(true);
    let k = (0..c.points.len())
        .max_by(|&i, &j| {
            let (p, q) = (c.points[i], c.points[j]);
            p.x.total_cmp(&q.x).then(q.y.total_cmp(&p.y))
        })
        .unwrap_or(0);
    c.points[k..].iter().chain(&c.points[..k]).copied().collect()
}

/// The cut lines of a region into `n` cells of equal arc length along its outer
/// contour, on the grid. Each cut runs from its point on the outer contour toward one
/// centre up to where it first leaves the region: the pole (most inland point) of the
/// region's largest hole, so that a ring is cut across to its inner side, or the pole
/// of a core without holes, where the cuts meet. Cuts aimed at one point never cross
/// each other, however thick the region.
fn cuts(grid: &Grid, polygon: &Polygon, n: usize) -> Vec<IntLine<i32>> {
    let pts = start(&polygon.outer);
    if pts.len() < 3 {
        return Vec::new();
    }
    let total = perimeter(&pts);
    let extent = polygon.bbox().diagonal();
    if !(total > 0.0 && extent > 0.0) {
        return Vec::new();
    }
    let target = match polygon.holes.iter().max_by(|a, b| a.area().total_cmp(&b.area())) {
        Some(h) => Polygon::new(h.clone().oriented(true), Vec::new()),
        None => polygon.clone(),
    };
    let Some((centre, _)) = pole(&target, extent * 1e-3) else {
        return Vec::new();
    };
    // Beyond the boundary by a little, so that the cut crosses it cleanly.
    let overshoot = 1e-3 * extent;
    let mut lines = Vec::with_capacity(n);
    for i in 0..n {
        let p = at_length(&pts, total * i as f64 / n as f64);
        let to_centre = centre - p;
        let len = to_centre.norm();
        if len.is_nan() || len <= overshoot {
            continue;
        }
        let dir = to_centre / len;
        let to = match first_exit(polygon, p, dir) {
            Some(t) if t < len => p + dir * (t + overshoot),
            _ => centre,
        };
        lines.push([grid.point(p - dir * overshoot), grid.point(to)]);
    }
    lines
}

/// The point at arc length `s` (taken around, any sign) along the closed contour `pts`.
fn at_length(pts: &[Point2], s: f64) -> Point2 {
    let total = perimeter(pts);
    let mut s = s.rem_euclid(total);
    for k in 0..pts.len() {
        let (a, b) = (pts[k], pts[(k + 1) % pts.len()]);
        let len = (b - a).norm();
        if s <= len {
            return if len > 0.0 { a + (b - a) * (s / len) } else { a };
        }
        s -= len;
    }
    pts[0]
}

/// How far the ray from `p` (on the outer contour) along `dir` runs inside the
/// polygon before it meets a boundary again.
fn first_exit(polygon: &Polygon, p: Point2, dir: Vector2) -> Option<f64> {
    let eps = 1e-9 * polygon.bbox().diagonal();
    let mut best: Option<f64> = None;
    for c in polygon.contours() {
        for (a, b) in c.edges() {
            let e = b - a;
            let den = dir.x * e.y - dir.y * e.x;
            if den.abs() < 1e-300 {
                continue;
            }
            let w = a - p;
            let t = (w.x * e.y - w.y * e.x) / den;
            let u = (w.x * dir.y - w.y * dir.x) / den;
            if t > eps && (0.0..=1.0).contains(&u) && best.is_none_or(|b| t < b) {
                best = Some(t);
            }
        }
    }
    best
}
