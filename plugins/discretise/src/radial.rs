//! `radial` (Method 2, Eq. 17): a radial line from each vertex v_i of the outer contour
//! toward the centre of an inner contour, ending where it meets that contour (v'_i);
//! offset contour j runs through the points v_i + (j / N_R) (v'_i - v_i) of every line.
//! With several inner contours (Fig. 12) each line goes to the nearest one; the closed
//! loops this leaves are dropped by the positive winding rule and sharp turns by a
//! spike filter. In a family without holes each line ends on the family's medial axis
//! (the centre of the largest inscribed disc touching the outline at v_i), so the
//! offset contours are insets of the outline. Sub-region j is the band between offset contours j and j + 1,
//! clipped on the family's grid as for `offset`, so the tiling stays exact.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::ShapeType;
use lamina_api::stage::{AnyStage, Discretiser, FamilyContext, StageConfig, StageInfo, StageKind};
use lamina_api::{Contour, Point2, Polygon, Result, StageFactory, SubRegion};

use crate::bands::nested_bands;
use crate::cells::Cells;
use crate::grid::Grid;
use crate::inset::From;
use crate::measure::pole;
use crate::offset::reach;
use crate::options::{self, derived_count};
use crate::regions::{from_bands, uniform_level, whole};

const STAGE: &str = "discretise:radial";

/// At least this many radial lines around the outer contour: long edges are divided
/// so that offset contours follow the inner contours' shape, not only the outer's
/// corners.
const MIN_RAYS: usize = 256;

/// Angular bins per inner contour for finding where a ray meets it.
const BINS: usize = 128;

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        nozzle: f64 = use crate::options::NOZZLE,
        count: Option<usize> = use crate::options::COUNT,
        cells_around: Option<usize> = use crate::cells::AROUND_OPTION,
        cell_length: Option<f64> = use crate::cells::LENGTH_OPTION,
        cell_cuts: Option<crate::cells::Cuts> = use crate::cells::CUTS_OPTION,
    }
}

struct Radial {
    nozzle: f64,
    count: Option<usize>,
    cells: Cells,
    limits: lamina_api::Limits,
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
/// radial lines. An edge of length l gets ceil(l / step) - 1 < l / step added points,
/// so all edges together get fewer than `MIN_RAYS`, however many edges there are.
fn rays(outer: &Contour) -> Vec<Point2> {
    let perimeter = outer.perimeter();
    let step = perimeter / MIN_RAYS as f64;
    let mut points = Vec::with_capacity(outer.len() + MIN_RAYS);
    for (a, b) in outer.edges() {
        points.push(a);
        let parts = if step > 0.0 {
            ((b - a).norm() / step).ceil() as usize
        } else {
            1
        };
        for k in 1..parts {
            points.push(a + (b - a) * (k as f64 / parts as f64));
        }
    }
    points
}

/// The end v'_i of each radial line: on the nearest inner contour (by the distance to
/// its enclosing circle about its centre), or on the family's medial axis without
/// holes.
fn ends(polygon: &Polygon, starts: &[Point2], precision: f64) -> Option<Vec<Point2>> {
    if polygon.holes.is_empty() {
        return medial_ends(polygon, starts, precision);
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

/// Where the radial line from each start ends on the medial axis of a family without
/// holes: the centre of the largest disc inside the family that touches the outer
/// contour at the start, found along the inward normal there (the bisector at a
/// corner). The discs tangent at v grow with their radius t, so t is the smallest
/// radius at which the disc meets another edge, in closed form per edge. A convex
/// family's lines thus end on its skeleton (a rectangle's on its mid-line and the
/// bisectors of its corners), and the offset contours of Eq. 17 are insets of the
/// outline, not copies scaled toward one pole.
fn medial_ends(polygon: &Polygon, starts: &[Point2], precision: f64) -> Option<Vec<Point2>> {
    if starts.len() < 3 {
        return None;
    }
    let outer = polygon.outer.clone().oriented(true);
    let edges: Vec<(Point2, Point2)> = outer.edges().collect();
    let eps = precision.max(1e-12);
    let grid = EdgeGrid::new(&edges);
    let mut seen = vec![usize::MAX; edges.len()];
    let mut out = Vec::with_capacity(starts.len());
    let unit = |a: Point2, b: Point2| {
        let e = b - a;
        let el = e.norm();
        (el > 0.0).then(|| (e / el, el))
    };
    let inward = |u: lamina_api::Vector2| lamina_api::Vector2::new(-u.y, u.x);
    for (index, &v) in starts.iter().enumerate() {
        // The edges through v (one inside an edge, two at a vertex), and the inward
        // normal there: the edge's, or the corner's bisector.
        let mut incident: Vec<usize> = Vec::with_capacity(2);
        for r in 0..2 {
            grid.ring(v, r, |e| {
                let (a, b) = edges[e];
                if !incident.contains(&e)
                    && unit(a, b).is_some_and(|(u, el)| {
                        (v - a).perp(&u).abs() <= eps && (-eps..=el + eps).contains(&(v - a).dot(&u))
                    })
                {
                    incident.push(e);
                }
            });
        }
        let sum = incident
            .iter()
            .filter_map(|&k| unit(edges[k].0, edges[k].1))
            .fold(lamina_api::Vector2::zeros(), |s, (u, _)| s + inward(u));
        let norm = sum.norm();
        if incident.is_empty() || norm <= 1e-12 {
            out.push(v);
            continue;
        }
        let nrm = sum / norm;
        // The disc centred at v + n t touches the edges through v at radius k t: at a
        // convex corner the sine of its half angle, elsewhere 1 (at v itself).
        let k = incident
            .iter()
            .filter_map(|&e| unit(edges[e].0, edges[e].1).map(|(u, el)| (e, u, el)))
            .map(|(e, u, el)| {
                let along = (v - edges[e].0).dot(&u) + nrm.dot(&u) * 1e-6;
                if (0.0..=el).contains(&along) {
                    inward(u).dot(&nrm)
                } else {
                    1.0
                }
            })
            .fold(1.0f64, f64::min)
            .max(1e-6);
        let mut t_min = f64::INFINITY;
        // Edges in rings of grid cells about v, nearest first: an edge at distance
        // delta from v meets the disc only once its diameter, at most 2 t, reaches it.
        for r in 0..=grid.rings() {
            if (r as f64 - 1.0) * grid.cell > 2.0 * t_min {
                break;
            }
            grid.ring(v, r, |e| {
                if seen[e] == index || incident.contains(&e) {
                    return;
                }
                seen[e] = index;
                let (a, b) = edges[e];
                let Some((u, el)) = unit(a, b) else { return };
                // Touching the edge's line: m . (v + n t - a) = k t, m its inward normal.
                let m = inward(u);
                let den = k - m.dot(&nrm);
                if den > 1e-12 {
                    let t = m.dot(&(v - a)) / den;
                    if t > eps {
                        let s = (v + nrm * t - a).dot(&u);
                        if (0.0..=el).contains(&s) {
                            t_min = t_min.min(t);
                            return;
                        }
                    }
                }
                // Touching an end point p: |v + n t - p| = k t.
                for p in [a, b] {
                    let w = v - p;
                    if w.norm() <= eps {
                        continue;
                    }
                    let (qa, qb, qc) = (1.0 - k * k, 2.0 * nrm.dot(&w), w.norm_squared());
                    let t = if qa.abs() < 1e-12 {
                        if qb < 0.0 { -qc / qb } else { f64::INFINITY }
                    } else {
                        // A disc that only grazes p (the far end of an edge through
                        // v, where the outline turns away) is a double root, which
                        // rounding may leave a hair below zero: the graze is a touch
                        // whichever way it rounds, or the line's end would jump.
                        let disc = qb * qb - 4.0 * qa * qc;
                        if disc < -1e-9 * qb * qb {
                            f64::INFINITY
                        } else {
                            let root = disc.max(0.0).sqrt();
                            [(-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)]
                                .into_iter()
                                .filter(|t| *t > eps)
                                .fold(f64::INFINITY, f64::min)
                        }
                    };
                    t_min = t_min.min(t);
                }
            });
        }
        out.push(if t_min.is_finite() { v + nrm * t_min } else { v });
    }
    Some(out)
}

/// The edges of a contour bucketed on a uniform grid of square cells, so that the
/// edges near a point are found ring by ring of cells.
struct EdgeGrid {
    min: Point2,
    cell: f64,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<usize>>,
}

impl EdgeGrid {
    fn new(edges: &[(Point2, Point2)]) -> Self {
        let bbox = lamina_api::BBox2::from_points(edges.iter().map(|e| e.0));
        let side = ((edges.len() as f64).sqrt().ceil() as usize).clamp(1, 512);
        let extent = bbox.width().max(bbox.height());
        let cell = if extent > 0.0 && extent.is_finite() {
            extent / side as f64
        } else {
            1.0
        };
        let nx = ((bbox.width() / cell) as usize + 1).min(side + 1);
        let ny = ((bbox.height() / cell) as usize + 1).min(side + 1);
        let mut grid = EdgeGrid {
            min: bbox.min,
            cell,
            nx,
            ny,
            cells: vec![Vec::new(); nx * ny],
        };
        for (e, &(a, b)) in edges.iter().enumerate() {
            let (i0, j0) = grid.index(Point2::new(a.x.min(b.x), a.y.min(b.y)));
            let (i1, j1) = grid.index(Point2::new(a.x.max(b.x), a.y.max(b.y)));
            for j in j0..=j1 {
                for i in i0..=i1 {
                    grid.cells[j * nx + i].push(e);
                }
            }
        }
        grid
    }

    fn index(&self, p: Point2) -> (usize, usize) {
        let f = |v: f64, n: usize| {
            if v.is_nan() || v <= 0.0 {
                0
            } else {
                (v as usize).min(n - 1)
            }
        };
        (
            f((p.x - self.min.x) / self.cell, self.nx),
            f((p.y - self.min.y) / self.cell, self.ny),
        )
    }

    /// The largest ring that holds any cell.
    fn rings(&self) -> usize {
        self.nx.max(self.ny)
    }

    /// Calls `f` with every edge of the cells r rings (Chebyshev distance) from the
    /// cell of `p`; an edge in several cells comes several times.
    fn ring(&self, p: Point2, r: usize, mut f: impl FnMut(usize)) {
        let (ci, cj) = self.index(p);
        let (ci, cj, r) = (ci as isize, cj as isize, r as isize);
        let mut visit = |i: isize, j: isize| {
            if i >= 0 && j >= 0 && (i as usize) < self.nx && (j as usize) < self.ny {
                for &e in &self.cells[j as usize * self.nx + i as usize] {
                    f(e);
                }
            }
        };
        if r == 0 {
            visit(ci, cj);
            return;
        }
        for i in ci - r..=ci + r {
            visit(i, cj - r);
            visit(i, cj + r);
        }
        for j in cj - r + 1..=cj + r - 1 {
            visit(ci - r, j);
            visit(ci + r, j);
        }
    }
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
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>> {
        let polygon = ctx.polygon();
        let Some((grid, base)) = Grid::family(polygon, STAGE) else {
            return Ok(whole(ctx));
        };
        let count = match self.count {
            Some(n) => n,
            None => match reach(polygon, From::Outer, self.nozzle * 0.05) {
                Some(r) => derived_count(
                    &self.limits,
                    r / self.nozzle,
                    &format!("{r:.3} mm of reach in rings of the {} mm nozzle", self.nozzle),
                )?,
                None => return Ok(whole(ctx)),
            },
        };
        let starts = rays(&polygon.outer);
        let Some(ends) = ends(polygon, &starts, self.nozzle * 0.05) else {
            return Ok(whole(ctx));
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
        self.cells.split(&grid, polygon, &mut regions, &self.limits)?;
        Ok(regions)
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    options::count(config, o.count)?;
    let cells = Cells::checked(o.cells_around, o.cell_length, o.cell_cuts, config)?;
    Ok(AnyStage::Discretise(Box::new(Radial {
        nozzle: o.nozzle,
        count: o.count,
        cells,
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "radial",
        doc: "Method 2: radial lines from the outer contour to the inner contours (or the centre), divided into N_R equal parts; offset contours through the dividing points (Eq. 17).",
        options: Options::SPECS,
        example: "use = \"radial\"\ncount = 10",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{circle, rect};

    /// Without holes a line ends at the centre of the largest disc inside the family
    /// that touches the outline at its start. In a 40 x 10 rectangle: from inside a long
    /// side, on the mid-line 5 mm in; from a side near a corner, on the corner's
    /// bisector as far in as the start is from the corner; from the corner itself, where
    /// the bisector meets the mid-line; from the middle of a short side, 5 mm in.
    #[test]
    fn without_holes_a_line_ends_on_the_medial_axis() {
        let polygon = Polygon::new(rect(0.0, 0.0, 40.0, 10.0).oriented(true), vec![]);
        let cases = [
            ((20.0, 0.0), (20.0, 5.0)),
            ((20.0, 10.0), (20.0, 5.0)),
            ((2.0, 0.0), (2.0, 2.0)),
            ((0.0, 3.0), (3.0, 3.0)),
            ((0.0, 0.0), (5.0, 5.0)),
            ((40.0, 10.0), (35.0, 5.0)),
            ((40.0, 5.0), (35.0, 5.0)),
        ];
        let starts: Vec<Point2> = cases.iter().map(|&((x, y), _)| Point2::new(x, y)).collect();
        let got = medial_ends(&polygon, &starts, 1e-3).expect("ends");
        for (&(start, (x, y)), end) in cases.iter().zip(got) {
            assert!((end - Point2::new(x, y)).norm() < 1e-6, "from {start:?}: {end}");
        }
    }

    /// Where the largest disc first meets a corner of the outline rather than a side: in
    /// an L of 20 x 20 with the 10 x 10 square at (10, 10) cut away, the disc growing up
    /// from (9, 0) reaches the inner corner (10, 10) at radius t with 1 + (10 - t)^2 =
    /// t^2, t = 5.05, before any side; from (15, 0) it meets the side above at t = 5.
    #[test]
    fn a_line_ends_where_its_disc_meets_an_inner_corner() {
        let p = |x: f64, y: f64| Point2::new(x, y);
        let outline = [
            (0.0, 0.0),
            (20.0, 0.0),
            (20.0, 10.0),
            (10.0, 10.0),
            (10.0, 20.0),
            (0.0, 20.0),
        ];
        let polygon = Polygon::new(
            Contour::new(outline.iter().map(|&(x, y)| p(x, y)).collect()).oriented(true),
            vec![],
        );
        let starts = [p(9.0, 0.0), p(15.0, 0.0), p(0.0, 15.0)];
        let got = medial_ends(&polygon, &starts, 1e-3).expect("ends");
        for (end, want) in got.into_iter().zip([p(9.0, 5.05), p(15.0, 5.0), p(5.0, 15.0)]) {
            assert!((end - want).norm() < 1e-9, "{end} against {want}");
        }
    }

    /// The same on outlines of many short edges, whose grid of edges the search walks
    /// ring by ring: the side a line meets is up, down, left or right of its start.
    #[test]
    fn the_medial_axis_search_finds_the_edge_it_meets_in_every_direction() {
        let dense = |w: f64, h: f64| {
            let corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)];
            let mut points = Vec::new();
            for k in 0..4 {
                let (a, b) = (corners[k], corners[(k + 1) % 4]);
                let n = (4.0 * f64::max((b.0 - a.0).abs(), (b.1 - a.1).abs())) as usize;
                for i in 0..n {
                    let s = i as f64 / n as f64;
                    points.push(Point2::new(a.0 + (b.0 - a.0) * s, a.1 + (b.1 - a.1) * s));
                }
            }
            Polygon::new(Contour::new(points).oriented(true), vec![])
        };
        for (polygon, cases) in [
            (
                dense(40.0, 10.0),
                [((20.0, 0.0), (20.0, 5.0)), ((20.0, 10.0), (20.0, 5.0))],
            ),
            (
                dense(10.0, 40.0),
                [((0.0, 20.0), (5.0, 20.0)), ((10.0, 20.0), (5.0, 20.0))],
            ),
        ] {
            let mut starts: Vec<Point2> = cases.iter().map(|&((x, y), _)| Point2::new(x, y)).collect();
            starts.push(polygon.outer.points[1]);
            let got = medial_ends(&polygon, &starts, 1e-3).expect("ends");
            for (&(start, (x, y)), end) in cases.iter().zip(got) {
                assert!((end - Point2::new(x, y)).norm() < 1e-6, "from {start:?}: {end}");
            }
        }
    }

    /// Against a search of its own: on random star-shaped outlines, the line from a
    /// point inside an edge (disc radius t) or from a convex corner (on its bisector,
    /// radius k t, k the sine of the half angle) ends where the disc first meets an
    /// edge not through the start. For one edge the gap |c(t) - edge| - k t is convex
    /// in t, so its first zero is found by a ternary search for its least and a
    /// bisection before it. A graze counts as a meeting (within 1e-9 mm).
    #[test]
    fn the_medial_axis_ends_are_those_a_bisection_finds() {
        let mut rng = fastrand::Rng::with_seed(0x853c_49e6_748f_ea9b);
        let mut next = move || rng.f64();
        let mut tested = 0;
        for _ in 0..60 {
            let n = 5 + (next() * 40.0) as usize;
            let mut angles: Vec<f64> = (0..n).map(|_| next() * std::f64::consts::TAU).collect();
            angles.sort_by(f64::total_cmp);
            let points: Vec<Point2> = angles
                .iter()
                .map(|&a| {
                    let r = 5.0 + next() * 15.0;
                    Point2::new(r * a.cos(), r * a.sin())
                })
                .collect();
            let outer = Contour::new(points).oriented(true);
            if outer.area().abs() < 1.0 || !crate::check::is_simple(&outer) {
                continue;
            }
            let edges: Vec<(Point2, Point2)> = outer.edges().collect();
            let polygon = Polygon::new(outer, vec![]);
            // Points inside edges (the disc touches there, radius t) and convex
            // corners (on the bisector, radius k t, k the sine of the half angle).
            let inward = |u: lamina_api::Vector2| lamina_api::Vector2::new(-u.y, u.x);
            let mut starts: Vec<(Point2, lamina_api::Vector2, f64)> = edges
                .iter()
                .filter(|(a, b)| (b - a).norm() > 0.5)
                .map(|&(a, b)| {
                    (
                        a + (b - a) * (0.1 + 0.8 * next()),
                        inward((b - a).normalize()),
                        1.0,
                    )
                })
                .collect();
            for w in 0..edges.len() {
                let ((a, v), (_, b)) = (edges[w], edges[(w + 1) % edges.len()]);
                if (v - a).norm() < 0.5 || (b - v).norm() < 0.5 {
                    continue;
                }
                let (u1, u2) = ((v - a).normalize(), (b - v).normalize());
                if u1.perp(&u2) > 0.05 {
                    let n = (inward(u1) + inward(u2)).normalize();
                    starts.push((v, n, inward(u1).dot(&n)));
                }
            }
            let got =
                medial_ends(&polygon, &starts.iter().map(|s| s.0).collect::<Vec<_>>(), 1e-3).expect("ends");
            assert_eq!(got.len(), starts.len());
            tested += starts.len();
            for (&(v, nrm, k), end) in starts.iter().zip(got) {
                // For one edge, the gap f(t) = |c(t) - edge| - k t is convex in t: the
                // disc first meets the edge where f first falls to 0, before f's least.
                let first_touch = |a: Point2, b: Point2| {
                    let f = |t: f64| lamina_api::geom::segment_distance(v + nrm * t, a, b) - k * t;
                    let (mut lo, mut hi) = (0.0, 100.0);
                    for _ in 0..200 {
                        let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
                        if f(m1) <= f(m2) {
                            hi = m2;
                        } else {
                            lo = m1;
                        }
                    }
                    if f(lo) > 1e-9 {
                        return f64::INFINITY;
                    }
                    let (mut lo, mut hi) = (0.0, lo);
                    for _ in 0..100 {
                        let t = 0.5 * (lo + hi);
                        if f(t) > 1e-9 {
                            lo = t;
                        } else {
                            hi = t;
                        }
                    }
                    hi
                };
                let t = edges
                    .iter()
                    .filter(|&&(a, b)| lamina_api::geom::segment_distance(v, a, b) > 1e-9)
                    .map(|&(a, b)| first_touch(a, b))
                    .fold(f64::INFINITY, f64::min);
                let want = v + nrm * t;
                assert!((end - want).norm() < 1e-3, "from {v}: {end} against {want}");
            }
        }
        assert!(tested > 500, "{tested} lines");
    }

    /// Long edges are divided so that there are at least 256 lines, evenly along each
    /// edge: a 10 mm square (steps of 40 / 256 mm) gets 64 parts an edge, 256 points;
    /// a 1,000-gon of edges shorter than a step keeps its own 1,000 vertices.
    #[test]
    fn long_edges_are_divided_into_at_least_256_lines() {
        let square = rect(0.0, 0.0, 10.0, 10.0);
        let points = rays(&square);
        assert_eq!(points.len(), 256);
        for (k, p) in points.iter().take(64).enumerate() {
            assert!(
                (p - Point2::new(10.0 * k as f64 / 64.0, 0.0)).norm() < 1e-12,
                "{k}: {p}"
            );
        }
        assert!(points.iter().all(|&p| square.distance(p) < 1e-12));
        let round = circle(0.0, 0.0, 10.0, 1000);
        assert_eq!(rays(&round), round.points);
    }

    /// A vertex where the contour turns back by more than about 170 degrees goes (a
    /// spike between lines that end on different holes); corners, turns of 150 and 163
    /// degrees and a repeated point stay.
    #[test]
    fn spikes_are_dropped_and_corners_kept() {
        let p = |x: f64, y: f64| Point2::new(x, y);
        let mut points = vec![
            p(0.0, 0.0),
            p(10.0, 0.0),
            p(10.0, 0.0),
            p(10.0, 10.0),
            p(7.0, 10.0),
            p(7.0, 16.0),
            p(7.01, 10.0),
            p(4.0, 10.0),
            p(4.0 + 3.0 * 3f64.sqrt() / 2.0, 11.5),
            p(0.0, 10.0),
        ];
        // The tip goes first; its base then turns back on itself and goes next pass.
        let mut want = points.clone();
        want.drain(4..7);
        without_spikes(&mut points);
        assert_eq!(points, want);
    }

    /// A radial line goes to the hole whose outline is nearest (the distance to its
    /// centre less its radius), not to the nearest centre: from the top of a disc of
    /// radius 30, a hole of radius 10 centred 12 mm right is 32.3 - 10 = 22.3 mm away,
    /// one of radius 1 centred 10 mm left 31.6 - 1 = 30.6 mm, though its centre is the
    /// nearer.
    #[test]
    fn a_radial_line_ends_on_the_hole_whose_outline_is_nearest() {
        let (large, small) = (
            circle(12.0, 0.0, 10.0, 360).oriented(false),
            circle(-10.0, 0.0, 1.0, 90).oriented(false),
        );
        // Whichever hole is listed first.
        for holes in [vec![large.clone(), small.clone()], vec![small, large]] {
            let polygon = Polygon::new(circle(0.0, 0.0, 30.0, 360).oriented(true), holes);
            let end = ends(&polygon, &[Point2::new(0.0, 30.0)], 1e-3).expect("ends")[0];
            assert!(
                ((end - Point2::new(12.0, 0.0)).norm() - 10.0).abs() < 0.01,
                "{end}"
            );
        }
    }
}
