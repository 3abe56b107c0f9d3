//! `radial` (Method 2, Eq. 17): a radial line from each vertex v_i of the outer contour
//! toward the centre of an inner contour, ending where it meets that contour (v'_i);
//! offset contour j runs through the points v_i + (j / N_R) (v'_i - v_i) of every line.
//! With several inner contours (Fig. 12) each line goes to the nearest one; the closed
//! loops this leaves are dropped by the positive winding rule and sharp turns by a
//! spike filter. A family without holes grades toward its centre (the pole of
//! inaccessibility). Sub-region j is the band between offset contours j and j + 1,
//! clipped on the family's grid as for `offset`, so the tiling stays exact.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::ShapeType;
use lamina_core::stage::{AnyStage, Discretiser, FamilyContext, StageConfig, StageInfo, StageKind};
use lamina_core::{Contour, Point2, Polygon, Region, Result, StageFactory};
use serde::Deserialize;

use crate::bands::{clean, nested_bands};
use crate::cells::Cells;
use crate::grid::Grid;
use crate::inset::From;
use crate::measure::pole;
use crate::offset::reach;
use crate::options::{self, MAX_COUNT, positive_mm};
use crate::regions::{from_bands, uniform_level, whole};

const STAGE: &str = "discretise:radial";

/// At least this many radial lines around the outer contour: long edges are divided
/// so that offset contours follow the inner contours' shape, not only the outer's
/// corners.
const MIN_RAYS: usize = 256;

/// Nor more than this many added vertices (a bound on the work for huge contours).
const MAX_ADDED: usize = 4096;

/// Angular bins per inner contour for finding where a ray meets it.
const BINS: usize = 128;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Options {
    #[serde(default = "default_nozzle")]
    nozzle: f64,
    #[serde(default)]
    count: Option<usize>,
    #[serde(default)]
    cells_around: Option<usize>,
    #[serde(default)]
    cell_length: Option<f64>,
}

fn default_nozzle() -> f64 {
    0.4
}

struct Radial {
    nozzle: f64,
    count: Option<usize>,
    cells: Cells,
}

/// An inner contour with its centre and its edges binned by the angle they span as
/// seen from the centre, so that a ray through the centre meets only a few candidates.
struct Target<'a> {
    contour: &'a Contour,
    centre: Point2,
    /// Largest distance of a vertex from the centre.
    radius: f64,
    bins: Vec<Vec<usize>>,
}

impl<'a> Target<'a> {
    fn new(contour: &'a Contour, centre: Point2) -> Self {
        let angle = |p: Point2| (p.y - centre.y).atan2(p.x - centre.x);
        let bin = |a: f64| {
            let f = (a + std::f64::consts::PI) / std::f64::consts::TAU;
            ((f * BINS as f64) as usize).min(BINS - 1)
        };
        let mut bins = vec![Vec::new(); BINS];
        for (e, (a, b)) in contour.edges().enumerate() {
            let (ba, bb) = (bin(angle(a)), bin(angle(b)));
            // The shorter way round from one end's bin to the other's.
            let (lo, hi) = (ba.min(bb), ba.max(bb));
            if hi - lo <= BINS / 2 {
                for list in &mut bins[lo..=hi] {
                    list.push(e);
                }
            } else {
                for b in (hi..BINS).chain(0..=lo) {
                    bins[b].push(e);
                }
            }
        }
        let radius = contour
            .points
            .iter()
            .map(|&p| (p - centre).norm())
            .fold(0.0, f64::max);
        Self {
            contour,
            centre,
            radius,
            bins,
        }
    }

    /// Where the line from `v` to the centre first meets the contour (the hit farthest
    /// from the centre, not beyond `v`); the nearest vertex when the ray misses (a
    /// centre outside a very concave contour).
    fn hit(&self, v: Point2) -> Point2 {
        let c = self.centre;
        let d = v - c;
        let len = d.norm();
        if len > 0.0 {
            let u = d / len;
            let a = u.y.atan2(u.x);
            let f = (a + std::f64::consts::PI) / std::f64::consts::TAU;
            let bin = ((f * BINS as f64) as usize).min(BINS - 1);
            let n = self.contour.len();
            let mut best: Option<f64> = None;
            for &e in &self.bins[bin] {
                let (p, q) = (self.contour.points[e], self.contour.points[(e + 1) % n]);
                // c + s u = p + t (q - p), s in [0, len], t in [0, 1].
                let r = q - p;
                let den = u.x * r.y - u.y * r.x;
                if den.abs() < f64::MIN_POSITIVE {
                    continue;
                }
                let w = p - c;
                let s = (w.x * r.y - w.y * r.x) / den;
                let t = (w.x * u.y - w.y * u.x) / den;
                if (-1e-12..=1.0 + 1e-12).contains(&t) && (0.0..=len).contains(&s) {
                    best = Some(best.map_or(s, |b: f64| b.max(s)));
                }
            }
            if let Some(s) = best {
                return c + u * s;
            }
        }
        self.contour
            .points
            .iter()
            .copied()
            .min_by(|a, b| (*a - v).norm_squared().total_cmp(&(*b - v).norm_squared()))
            .unwrap_or(c)
    }
}

/// The outer contour with long edges divided, so that there are at least `MIN_RAYS`
/// radial lines.
fn rays(outer: &Contour) -> Vec<Point2> {
    let perimeter = outer.perimeter();
    let step = perimeter / MIN_RAYS as f64;
    let mut points = Vec::with_capacity(outer.len() + MIN_RAYS);
    let mut added = 0;
    for (a, b) in outer.edges() {
        points.push(a);
        let parts = if step > 0.0 {
            ((b - a).norm() / step).ceil() as usize
        } else {
            1
        };
        for k in 1..parts {
            if added >= MAX_ADDED {
                break;
            }
            points.push(a + (b - a) * (k as f64 / parts as f64));
            added += 1;
        }
    }
    points
}

/// The end v'_i of each radial line: on the nearest inner contour (by the distance to
/// its enclosing circle about its centre), or the family's centre without holes.
fn ends(polygon: &Polygon, starts: &[Point2], precision: f64) -> Option<Vec<Point2>> {
    if polygon.holes.is_empty() {
        let (c, _) = pole(polygon, precision)?;
        return Some(vec![c; starts.len()]);
    }
    let targets: Vec<Target<'_>> = polygon
        .holes
        .iter()
        .map(|h| {
            let centre = pole(&Polygon::new(h.clone().oriented(true), vec![]), precision)
                .map(|(c, _)| c)
                .unwrap_or_else(|| h.bbox().center());
            Target::new(h, centre)
        })
        .collect();
    Some(
        starts
            .iter()
            .map(|&v| {
                let nearest = targets.iter().min_by(|a, b| {
                    ((v - a.centre).norm() - a.radius).total_cmp(&((v - b.centre).norm() - b.radius))
                });
                nearest.map_or(v, |t| t.hit(v))
            })
            .collect(),
    )
}

/// Drops the vertices where the contour turns back sharply (more than about 170
/// degrees): the spikes left where neighbouring radial lines end on different inner
/// contours.
fn without_spikes(points: &mut Vec<Point2>) {
    for _ in 0..4 {
        let n = points.len();
        if n < 4 {
            return;
        }
        let keep: Vec<bool> = (0..n)
            .map(|i| {
                let (a, b, c) = (points[(i + n - 1) % n], points[i], points[(i + 1) % n]);
                let (u, v) = (b - a, c - b);
                let norm = u.norm() * v.norm();
                norm == 0.0 || u.dot(&v) / norm > -0.985
            })
            .collect();
        if keep.iter().all(|&k| k) {
            return;
        }
        let mut i = 0;
        points.retain(|_| {
            i += 1;
            keep[i - 1]
        });
    }
}

impl Discretiser for Radial {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<Region>> {
        let polygon = ctx.tree.family_polygon(&ctx.layer.contours, ctx.family);
        let Ok(grid) = Grid::for_polygon(&polygon, STAGE) else {
            return Ok(whole(ctx, polygon));
        };
        let base = clean(&vec![grid.shape(&polygon)]);
        if base.is_empty() {
            return Ok(whole(ctx, polygon));
        }
        let count = match self.count {
            Some(n) => n,
            None => match reach(&polygon, From::Outer, self.nozzle * 0.05) {
                Some(r) => ((r / self.nozzle) as usize).clamp(1, MAX_COUNT),
                None => return Ok(whole(ctx, polygon)),
            },
        };
        let starts = rays(&polygon.outer);
        let Some(ends) = ends(&polygon, &starts, self.nozzle * 0.05) else {
            return Ok(whole(ctx, polygon));
        };
        let mut points = Vec::with_capacity(starts.len());
        let bands = nested_bands(&base, count, FillRule::Positive, |k, _, overlay| {
            // Eq. 17: the k-th dividing point of every radial line.
            let r = k as f64 / count as f64;
            points.clear();
            points.extend(starts.iter().zip(&ends).map(|(&v, &w)| v + (w - v) * r));
            without_spikes(&mut points);
            let contour = grid.contour(&Contour::new(points.clone()));
            if contour.len() < 3 {
                return Ok(false);
            }
            overlay.add_contour(&contour, ShapeType::Clip);
            Ok(true)
        })?;
        let mut regions = from_bands(ctx, &grid, &bands, count, |j| uniform_level(j, count));
        self.cells.split(&grid, &mut regions);
        Ok(regions)
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    positive_mm(config, "nozzle", o.nozzle)?;
    options::count(config, o.count)?;
    let cells = Cells::checked(o.cells_around, o.cell_length, config)?;
    Ok(AnyStage::Discretise(Box::new(Radial {
        nozzle: o.nozzle,
        count: o.count,
        cells,
    })))
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "radial",
        doc: "Method 2: radial lines from the outer contour to the inner contours (or the centre), divided into N_R equal parts; offset contours through the dividing points (Eq. 17).",
        options: &[
            options::NOZZLE,
            options::COUNT,
            crate::cells::AROUND_OPTION,
            crate::cells::LENGTH_OPTION,
        ],
        example: "use = \"radial\"\ncount = 10",
    },
    build,
});
