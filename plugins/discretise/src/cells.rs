//! Circumferential cells (Fig. 13): each sub-region split along its length into cells
//! by angular sectors about the family's centre (the centre of its largest hole, or the
//! pole of a family without holes), so that a grader can vary the material around the
//! contours too. The sectors are built on the family's grid and share their edges, so
//! the cells of a region tile it exactly.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::{Overlay, ShapeType};
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::i_float::int::point::IntPoint;
use lamina_core::stage::{OptionSpec, StageConfig};
use lamina_core::{Point2, Polygon, Region, Result};

use crate::bands::{options, solver};
use crate::grid::Grid;
use crate::measure::pole;
use crate::regions::region;

/// More cells around one region than anyone could deposit: a guard against typos.
pub const MAX_CELLS: usize = 1000;

pub const AROUND_OPTION: OptionSpec = OptionSpec::new(
    "cells_around",
    "integer",
    "none",
    "split every sub-region into this many circumferential cells (equal angles about the family's centre)",
);

pub const LENGTH_OPTION: OptionSpec = OptionSpec::new(
    "cell_length",
    "float",
    "none",
    "split every sub-region into circumferential cells about this long (mm, along its middle)",
);

/// How sub-regions are split around.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Cells {
    #[default]
    None,
    /// This many equal sectors.
    Around(usize),
    /// Sectors about this long (mm) along the region's middle.
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

    /// Number of sectors for one region.
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
    /// with `cell = Some(i)` (numbered counter-clockwise from the +x direction) and a
    /// reference point inside it.
    pub fn split(&self, grid: &Grid, family: &Polygon, regions: &mut Vec<Region>) {
        if *self == Cells::None || regions.is_empty() {
            return;
        }
        let centre = centre(family);
        let bbox = family.bbox();
        let reach = [
            bbox.min,
            bbox.max,
            Point2::new(bbox.min.x, bbox.max.y),
            Point2::new(bbox.max.x, bbox.min.y),
        ]
        .iter()
        .map(|&p| (p - centre).norm())
        .fold(0.0, f64::max);
        // Far enough that the sectors' outer arcs (chords of at most 45 degrees) lie
        // outside the family, and relative to its size, so that the sectors stay in
        // the grid's range (a few times its half extent) whatever the scale.
        let far = 2.0 * reach.max(f64::MIN_POSITIVE);
        let mut overlay = Overlay::new_custom(0, options(), solver());
        let mut out = Vec::with_capacity(regions.len());
        for r in regions.drain(..) {
            let n = self.count(&r.polygon);
            if n <= 1 {
                out.push(Region { cell: Some(0), ..r });
                continue;
            }
            let shape = grid.shape(&r.polygon);
            let mut cell = 0;
            for m in 0..n {
                let sector = sector(grid, centre, far, m, n);
                overlay.clear();
                overlay.add_contour(&sector, ShapeType::Clip);
                for c in &shape {
                    overlay.add_contour(c, ShapeType::Subject);
                }
                let pieces = overlay.overlay(OverlayRule::Intersect, FillRule::NonZero);
                for polygon in grid.polygons(&pieces) {
                    if polygon.outer.len() < 3 {
                        continue;
                    }
                    let mut c = region(r.family, r.index, r.count, r.level, polygon);
                    c.cell = Some(cell);
                    out.push(c);
                    cell += 1;
                }
            }
        }
        *regions = out;
    }
}

/// The point the sectors fan out from: the centre of the largest hole's bounding box,
/// or the pole of a family without holes (its bounding-box centre if none is found).
fn centre(family: &Polygon) -> Point2 {
    match family.holes.iter().max_by(|a, b| a.area().total_cmp(&b.area())) {
        Some(h) => h.bbox().center(),
        None => pole(family, family.bbox().diagonal() * 1e-3)
            .map(|(c, _)| c)
            .unwrap_or_else(|| family.bbox().center()),
    }
}

/// Sector `m` of `n` about `centre` as a counter-clockwise grid contour reaching `far`
/// mm out. Its two straight edges are computed from the angle alone, so neighbouring
/// sectors share them exactly.
fn sector(grid: &Grid, centre: Point2, far: f64, m: usize, n: usize) -> Vec<IntPoint<i32>> {
    let at = |a: f64| grid.point(centre + lamina_core::Vector2::new(a.cos(), a.sin()) * far);
    let (a0, a1) = (
        std::f64::consts::TAU * m as f64 / n as f64,
        std::f64::consts::TAU * (m + 1) as f64 / n as f64,
    );
    let steps = ((a1 - a0) / std::f64::consts::FRAC_PI_4).ceil().max(1.0) as usize;
    let mut points = vec![grid.point(centre)];
    for s in 0..=steps {
        let a = if s == steps {
            a1
        } else {
            a0 + (a1 - a0) * s as f64 / steps as f64
        };
        points.push(at(a));
    }
    points
}
