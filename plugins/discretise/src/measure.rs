//! Measures of a family that decide how it is divided: the minimum distance between its
//! contours (L_s of Eq. 14) and its inradius (how deep an inward offset can go). A
//! region's reference point is `lamina_geom::reference`.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use lamina_api::{Contour, Point2, Polygon};
use lamina_geom::reference::interior_point;
use static_aabb2d_index::{Control, StaticAABB2DIndex, StaticAABB2DIndexBuilder};

/// The edges of one or more contours, binned on a grid for the distance to the
/// nearest ([`Bins`]) and in a packed, static R-tree (boxes sorted along a Hilbert
/// curve) for the crossings of a ray: a sliced wall has thousands of edges, and the
/// measures below ask for the distance to them thousands of times. Both are built
/// once per family and never change, so flat arrays are cheaper to build than a
/// dynamic tree's nodes (the build was a fifth of a large mesh's run).
pub struct Edges {
    lines: Vec<[[f64; 2]; 2]>,
    /// Boxes of `lines`, by their indices; none without lines.
    index: Option<StaticAABB2DIndex<f64>>,
    /// The lines binned on a uniform grid, for the nearest-edge search.
    bins: Option<Bins>,
}

/// Lines binned on a uniform grid of about two lines per cell: the nearest one to a
/// point is found by visiting the cells in rings around the point's until the ring
/// is farther than the nearest so far. The pole search asks this thousands of times
/// of one family; each answer costs a handful of cells, where the tree's best-first
/// search pushed and popped a heap of nodes (2 us a query, the pole's whole cost).
struct Bins {
    origin: [f64; 2],
    cell: f64,
    cols: usize,
    rows: usize,
    /// Compressed rows: the lines of cell `c` are `lines[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    lines: Vec<u32>,
}

/// Most cells per line of the grid.
const CELLS_PER_LINE: usize = 4;

impl Bins {
    fn new(lines: &[[[f64; 2]; 2]]) -> Option<Self> {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for q in lines.iter().flatten() {
            for a in 0..2 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
        if !(w.is_finite() && h.is_finite()) || lines.len() >= u32::MAX as usize {
            return None;
        }
        let n = lines.len() as f64;
        // About two lines a cell over the box; a box with no area gets cells along
        // its length.
        let mut cell = (2.0 * w * h / n).sqrt().max(w.max(h) / n);
        if cell.is_nan() || cell <= 0.0 {
            cell = 1.0;
        }
        let dims = |cell: f64| ((w / cell) as usize + 1, (h / cell) as usize + 1);
        let (mut cols, mut rows) = dims(cell);
        while cols.saturating_mul(rows) > CELLS_PER_LINE * lines.len() + 16 {
            cell *= 1.5;
            (cols, rows) = dims(cell);
        }
        let at = |v: f64, a: usize, n: usize| (((v - lo[a]) / cell) as usize).min(n - 1);
        let span = |l: &[[f64; 2]; 2]| {
            (
                at(l[0][0].min(l[1][0]), 0, cols)..=at(l[0][0].max(l[1][0]), 0, cols),
                at(l[0][1].min(l[1][1]), 1, rows)..=at(l[0][1].max(l[1][1]), 1, rows),
            )
        };
        let mut start = vec![0u32; cols * rows + 1];
        for l in lines {
            let (xs, ys) = span(l);
            for y in ys {
                for x in xs.clone() {
                    start[y * cols + x + 1] += 1;
                }
            }
        }
        for c in 0..cols * rows {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut binned = vec![0u32; start[cols * rows] as usize];
        for (i, l) in lines.iter().enumerate() {
            let (xs, ys) = span(l);
            for y in ys {
                for x in xs.clone() {
                    let c = y * cols + x;
                    binned[fill[c] as usize] = i as u32;
                    fill[c] += 1;
                }
            }
        }
        Some(Bins {
            origin: lo,
            cell,
            cols,
            rows,
            start,
            lines: binned,
        })
    }

    /// The least squared distance from `q` to `lines` (binned here), or `limit` when
    /// none is nearer: the search stops once the cells left are all beyond it.
    fn nearest_2(&self, lines: &[[[f64; 2]; 2]], q: [f64; 2], limit: f64) -> f64 {
        let cell_of = |v: f64, a: usize, n: usize| {
            let k = ((v - self.origin[a]) / self.cell).floor();
            if k <= 0.0 { 0 } else { (k as usize).min(n - 1) }
        };
        let (cx, cy) = (cell_of(q[0], 0, self.cols), cell_of(q[1], 1, self.rows));
        let mut best = limit;
        let visit = |x: usize, y: usize, best: &mut f64| {
            let c = y * self.cols + x;
            for &i in &self.lines[self.start[c] as usize..self.start[c + 1] as usize] {
                *best = best.min(line_distance_2(&lines[i as usize], q));
            }
        };
        for r in 0.. {
            // Ring r: the cells r steps from (cx, cy) in either axis, clipped to the grid.
            let (x0, x1) = (cx.saturating_sub(r), (cx + r).min(self.cols - 1));
            let (y0, y1) = (cy.saturating_sub(r), (cy + r).min(self.rows - 1));
            for y in y0..=y1 {
                if y + r == cy || y == cy + r {
                    for x in x0..=x1 {
                        visit(x, y, &mut best);
                    }
                } else {
                    if x0 + r == cx {
                        visit(x0, y, &mut best);
                    }
                    if x1 == cx + r {
                        visit(x1, y, &mut best);
                    }
                }
            }
            // Every cell not visited lies beyond a side of the block visited that is
            // not the grid's edge: at least that side's distance from `q`.
            let side = |lo_edge: bool, hi_edge: bool, lo: f64, hi: f64, v: f64| {
                let a = if lo_edge { f64::INFINITY } else { v - lo };
                let b = if hi_edge { f64::INFINITY } else { hi - v };
                a.min(b)
            };
            let bx = side(
                x0 == 0,
                x1 == self.cols - 1,
                self.origin[0] + x0 as f64 * self.cell,
                self.origin[0] + (x1 + 1) as f64 * self.cell,
                q[0],
            );
            let by = side(
                y0 == 0,
                y1 == self.rows - 1,
                self.origin[1] + y0 as f64 * self.cell,
                self.origin[1] + (y1 + 1) as f64 * self.cell,
                q[1],
            );
            // Less a hair for the rounding of cell edges against the binning.
            let bound = bx.min(by) - 1e-9 * self.cell;
            if bound == f64::INFINITY || (bound > 0.0 && bound * bound >= best) {
                break;
            }
        }
        best
    }
}

/// Squared distance from `q` to the segment `l`: the foot of the perpendicular
/// where it falls inside the segment, else the nearer end. The same operations,
/// in the same order, as the measure the discretiser used before (rstar's
/// `Line::distance_2`), so its plans stay the same to the last bit.
fn line_distance_2(l: &[[f64; 2]; 2], q: [f64; 2]) -> f64 {
    let (p1, p2) = (l[0], l[1]);
    let dir = [p2[0] - p1[0], p2[1] - p1[1]];
    let s = ((q[0] - p1[0]) * dir[0] + (q[1] - p1[1]) * dir[1]) / (dir[0] * dir[0] + dir[1] * dir[1]);
    let n = if 0.0 < s && s < 1.0 {
        [p1[0] + dir[0] * s, p1[1] + dir[1] * s]
    } else if s <= 0.0 {
        p1
    } else {
        p2
    };
    let d = [n[0] - q[0], n[1] - q[1]];
    d[0] * d[0] + d[1] * d[1]
}

/// Whether the segment `l` crosses the ray from `p` toward +x (half-open in y, so a
/// vertex on the ray counts once).
fn crosses_ray(l: &[[f64; 2]; 2], p: Point2) -> bool {
    let [a, b] = *l;
    (a[1] > p.y) != (b[1] > p.y) && p.x < a[0] + (p.y - a[1]) / (b[1] - a[1]) * (b[0] - a[0])
}

impl Edges {
    pub fn new<'a>(contours: impl IntoIterator<Item = &'a Contour>) -> Self {
        let lines: Vec<[[f64; 2]; 2]> = contours
            .into_iter()
            .flat_map(|c| c.edges())
            .map(|(a, b)| [[a.x, a.y], [b.x, b.y]])
            .collect();
        let index = (!lines.is_empty()).then(|| {
            let mut b = StaticAABB2DIndexBuilder::new(lines.len());
            for l in &lines {
                b.add(
                    l[0][0].min(l[1][0]),
                    l[0][1].min(l[1][1]),
                    l[0][0].max(l[1][0]),
                    l[0][1].max(l[1][1]),
                );
            }
            // Fails only with a count other than the one given, or none.
            b.build().expect("as many boxes as lines")
        });
        let bins = Bins::new(&lines);
        Edges { lines, index, bins }
    }

    /// Distance from `p` to the nearest edge (infinite without edges).
    pub fn distance(&self, p: Point2) -> f64 {
        self.distance_2_below(p, f64::INFINITY).sqrt()
    }

    /// The distance from `p` to the nearest edge when its square is less than
    /// `bound²` (the distance is then at most `bound`); `None` when the distance is
    /// `bound` or more. The distance found is [`Edges::distance`]'s, and the root of a
    /// number squared is the number, so a minimum taken with it is the same.
    pub fn distance_below(&self, p: Point2, bound: f64) -> Option<f64> {
        let limit = bound * bound;
        let d2 = self.distance_2_below(p, limit);
        (d2 < limit).then(|| d2.sqrt())
    }

    /// The least squared distance from `p` to an edge, or `limit` when none is nearer.
    fn distance_2_below(&self, p: Point2, limit: f64) -> f64 {
        if let Some(bins) = &self.bins {
            return bins.nearest_2(&self.lines, [p.x, p.y], limit);
        }
        let Some(index) = &self.index else {
            return limit;
        };
        let q = [p.x, p.y];
        let mut best = limit;
        index.visit_neighbors(p.x, p.y, &mut |i: usize, box_d2: f64| {
            if box_d2 > best {
                return Control::Break(());
            }
            best = best.min(line_distance_2(&self.lines[i], q));
            Control::Continue
        });
        best
    }

    /// Whether `p` is inside under the even-odd rule, which for a polygon's outer
    /// contour and holes is inside the outer and outside every hole: the edges
    /// crossed by the ray from `p` toward +x, counted.
    pub fn contains(&self, p: Point2) -> bool {
        let Some((index, bounds)) = self.index.as_ref().and_then(|i| Some((i, i.bounds()?))) else {
            return false;
        };
        if p.x > bounds.max_x {
            return false;
        }
        let mut inside = false;
        index.visit_query(p.x, p.y, bounds.max_x, p.y, &mut |i: usize| {
            inside ^= crosses_ray(&self.lines[i], p);
        });
        inside
    }
}

/// Shortest distance between two contours that do not cross: attained at a vertex of
/// one of them, so vertex-to-segment distances both ways are exact.
pub fn contour_distance(a: &Contour, b: &Contour) -> f64 {
    edges_distance(a, &Edges::new([a]), b, &Edges::new([b]), f64::INFINITY)
}

/// [`contour_distance`] of `a` and `b` with their edge trees, or any value not below
/// `bound` when they are no closer than that: a vertex whose distance to the other
/// contour's box reaches the least distance so far cannot lower it, and takes no
/// query (an outer contour's vertices, most of them far from any one hole's box).
fn edges_distance(a: &Contour, ea: &Edges, b: &Contour, eb: &Edges, bound: f64) -> f64 {
    let mut best = bound;
    for (a, b, eb) in [(a, b, eb), (b, a, ea)] {
        let bb = b.bbox();
        for &p in &a.points {
            let dx = (bb.min.x - p.x).max(p.x - bb.max.x).max(0.0);
            let dy = (bb.min.y - p.y).max(p.y - bb.max.y).max(0.0);
            if dx * dx + dy * dy >= best * best {
                continue;
            }
            if let Some(d) = eb.distance_below(p, best) {
                best = best.min(d);
            }
        }
    }
    best
}

/// L_s: the minimum distance between any two contours of the family; `None` for a
/// family without holes.
pub fn min_contour_distance(polygon: &Polygon) -> Option<f64> {
    let contours: Vec<&Contour> = polygon.contours().collect();
    if contours.len() < 2 {
        return None;
    }
    let edges: Vec<Edges> = contours.iter().map(|c| Edges::new([*c])).collect();
    let boxes: Vec<_> = contours.iter().map(|c| c.bbox()).collect();
    let mut best = f64::INFINITY;
    for i in 0..contours.len() {
        for j in i + 1..contours.len() {
            // Boxes farther apart than the best distance so far cannot improve it.
            let (a, b) = (&boxes[i], &boxes[j]);
            let dx = (a.min.x - b.max.x).max(b.min.x - a.max.x).max(0.0);
            let dy = (a.min.y - b.max.y).max(b.min.y - a.max.y).max(0.0);
            if dx.hypot(dy) >= best {
                continue;
            }
            best = best.min(edges_distance(
                contours[i],
                &edges[i],
                contours[j],
                &edges[j],
                best,
            ));
        }
    }
    (contours.len() > 1 && best.is_finite()).then_some(best)
}

/// A square of the pole search: centre, half size, distance of the centre to the
/// boundary (negative outside) and the best distance any point of the square can reach.
struct Square {
    c: Point2,
    h: f64,
    d: f64,
    max: f64,
}

impl Square {
    fn new(edges: &Edges, c: Point2, h: f64) -> Self {
        Self::at(edges, c, h, edges.distance(c))
    }

    /// The square about `c` whose centre lies `near` from the boundary.
    fn at(edges: &Edges, c: Point2, h: f64, near: f64) -> Self {
        let d = if edges.contains(c) { near } else { -near };
        Self {
            c,
            h,
            d,
            max: d + h * std::f64::consts::SQRT_2,
        }
    }
}

impl PartialEq for Square {
    fn eq(&self, other: &Self) -> bool {
        self.max == other.max
    }
}
impl Eq for Square {}
impl PartialOrd for Square {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Square {
    fn cmp(&self, other: &Self) -> Ordering {
        self.max.total_cmp(&other.max)
    }
}

/// The pole of inaccessibility (the interior point farthest from the boundary) within
/// `precision`, and its distance to the boundary: the radius of the largest inscribed
/// circle. Branch and bound over squares; `None` for a polygon with no inside.
pub fn pole(polygon: &Polygon, precision: f64) -> Option<(Point2, f64)> {
    let bbox = polygon.bbox();
    let size = bbox.width().min(bbox.height());
    if size.is_nan() || size <= 0.0 {
        return None;
    }
    let precision = precision.max(size * 1e-6);
    let edges = Edges::new(polygon.contours());
    let h = size / 2.0;
    let mut heap = BinaryHeap::new();
    let mut y = bbox.min.y;
    while y < bbox.max.y {
        let mut x = bbox.min.x;
        while x < bbox.max.x {
            heap.push(Square::new(&edges, Point2::new(x + h, y + h), h));
            x += size;
        }
        y += size;
    }
    let start = interior_point(polygon)?;
    let mut best = Square::new(&edges, start, 0.0);
    // A bound on the work for pathological inputs: the answer stays a valid interior
    // point, only less central.
    let mut budget = 20_000;
    while let Some(square) = heap.pop() {
        if square.d > best.d {
            best = Square::new(&edges, square.c, 0.0);
        }
        if square.max - best.d <= precision || budget == 0 {
            continue;
        }
        budget -= 1;
        let h = square.h / 2.0;
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = Point2::new(square.c.x + sx * h, square.c.y + sy * h);
            // Whichever side of the boundary it lies, a square whose centre is no
            // farther from it than the best so far, and whose best point cannot beat
            // that by the precision, would be popped only to be dropped: it is not
            // made, which spares the containment test (most of the squares' cost).
            let near = edges.distance(c);
            if near <= best.d && near + h * std::f64::consts::SQRT_2 - best.d <= precision {
                continue;
            }
            heap.push(Square::at(&edges, c, h, near));
        }
    }
    (best.d > 0.0).then_some((best.c, best.d))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{circle, rect, through as pts};

    #[test]
    fn tube_distance_and_pole() {
        let tube = Polygon::new(
            circle(0.0, 0.0, 10.0, 256),
            vec![circle(0.0, 0.0, 5.0, 256).oriented(false)],
        );
        let ls = min_contour_distance(&tube).expect("has holes");
        assert!((ls - 5.0).abs() < 0.01, "{ls}");
        let (_, r) = pole(&Polygon::new(rect(0.0, 0.0, 10.0, 4.0), vec![]), 1e-3).expect("pole");
        assert!((r - 2.0).abs() < 2e-3, "{r}");
    }

    /// Inside the outer contour and outside every hole, found by the ray toward +x,
    /// also next to a slanted edge.
    #[test]
    fn containment_counts_the_edges_the_ray_crosses() {
        let triangle = pts(&[(0.0, 0.0), (4.0, 0.0), (0.0, 4.0)]);
        let edges = Edges::new([&triangle]);
        for (x, y, inside) in [
            (1.0, 1.0, true),
            (1.9, 2.0, true),
            (2.1, 2.0, false),
            (3.9, 0.05, true),
            (3.9, 0.2, false),
            (-0.1, 1.0, false),
            (5.0, 1.0, false),
        ] {
            assert_eq!(edges.contains(Point2::new(x, y)), inside, "({x}, {y})");
        }
        let ring = [rect(0.0, 0.0, 10.0, 10.0), rect(4.0, 4.0, 2.0, 2.0)];
        let edges = Edges::new(ring.iter());
        assert!(edges.contains(Point2::new(2.0, 5.0)));
        assert!(!edges.contains(Point2::new(5.0, 5.0)));
        assert!(edges.contains(Point2::new(8.0, 5.0)));
        assert!((edges.distance(Point2::new(5.0, 5.0)) - 1.0).abs() < 1e-12);
        assert_eq!(Edges::new([]).distance(Point2::new(0.0, 0.0)), f64::INFINITY);
    }

    /// The grid and the packed tree answer as a scan of every edge does: the nearest
    /// edge's distance, to the last bit, and the crossings of the ray, on a wavy ring
    /// with a hole (hundreds of edges, so that the tree has inner nodes and the grid
    /// hundreds of cells) at points inside, outside, beyond the box and on the far
    /// side of the ring; and on edges along one line (a grid of one row).
    #[test]
    fn the_edges_find_what_a_scan_of_every_edge_finds() {
        let wavy = |r: f64, n: usize| {
            let points: Vec<(f64, f64)> = (0..n)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / n as f64;
                    let r = r * (1.0 + 0.2 * (7.0 * a).sin());
                    (30.0 + r * a.cos(), 20.0 + r * a.sin())
                })
                .collect();
            pts(&points)
        };
        let contours = [wavy(10.0, 400), wavy(4.0, 150).oriented(false)];
        let edges = Edges::new(contours.iter());
        let lines = &edges.lines;
        assert_eq!(lines.len(), 550);
        let mut rng = fastrand::Rng::with_seed(7);
        for _ in 0..2000 {
            let p = Point2::new(rng.f64() * 40.0 + 10.0, rng.f64() * 40.0);
            let scan = lines
                .iter()
                .map(|l| line_distance_2(l, [p.x, p.y]))
                .fold(f64::INFINITY, f64::min)
                .sqrt();
            assert_eq!(edges.distance(p).to_bits(), scan.to_bits(), "{p:?}");
            // Below a bound: the same distance when it is less, none when it is more
            // (at the bound itself, either).
            for bound in [0.05, 0.5, 2.0, scan, f64::INFINITY] {
                let below = edges.distance_below(p, bound);
                assert!(
                    below.is_none_or(|d| d.to_bits() == scan.to_bits()),
                    "{p:?} {bound}"
                );
                if scan != bound {
                    assert_eq!(below.is_some(), scan < bound, "{p:?} {bound}");
                }
            }
            // And as the distance to a segment is measured elsewhere.
            let other = lines
                .iter()
                .map(|[a, b]| lamina_geom::segment::segment_distance2([p.x, p.y], *a, *b))
                .fold(f64::INFINITY, f64::min)
                .sqrt();
            assert!((edges.distance(p) - other).abs() < 1e-12, "{p:?}");
            let crossings = lines.iter().filter(|l| crosses_ray(l, p)).count();
            assert_eq!(edges.contains(p), crossings % 2 == 1, "{p:?}");
        }
        // The foot of the perpendicular inside a segment, and an end beyond it.
        let square = [rect(0.0, 0.0, 2.0, 2.0)];
        let edges = Edges::new(square.iter());
        assert_eq!(edges.distance(Point2::new(1.0, 0.5)), 0.5);
        assert_eq!(edges.distance(Point2::new(5.0, 6.0)), 5.0);
        assert!(!Edges::new([]).contains(Point2::new(0.0, 0.0)));
        let flat = Contour::new((0..50).map(|k| Point2::new(k as f64 * 0.3, 2.0)).collect());
        let edges = Edges::new([&flat]);
        for _ in 0..500 {
            let p = Point2::new(rng.f64() * 30.0 - 8.0, rng.f64() * 10.0 - 3.0);
            let scan = edges
                .lines
                .iter()
                .map(|l| line_distance_2(l, [p.x, p.y]))
                .fold(f64::INFINITY, f64::min)
                .sqrt();
            assert_eq!(edges.distance(p).to_bits(), scan.to_bits(), "{p:?}");
        }
    }

    /// L_s is the least distance over every pair of contours: here between the two
    /// holes (1 mm), not from either hole to the outer contour (2 mm).
    #[test]
    fn the_least_distance_is_over_every_pair_of_contours() {
        assert!((contour_distance(&rect(0.0, 0.0, 1.0, 1.0), &rect(3.0, 0.5, 1.0, 1.0)) - 2.0).abs() < 1e-12);
        let outer = rect(0.0, 0.0, 20.0, 20.0);
        let a = rect(2.0, 2.0, 2.0, 2.0).oriented(false);
        let b = rect(5.0, 2.0, 2.0, 2.0).oriented(false);
        let two = Polygon::new(outer.clone(), vec![a.clone(), b]);
        let ls = min_contour_distance(&two).expect("holes");
        assert!((ls - 1.0).abs() < 1e-12, "{ls}");
        let one = Polygon::new(outer.clone(), vec![a]);
        assert!((min_contour_distance(&one).expect("a hole") - 2.0).abs() < 1e-12);
        assert_eq!(min_contour_distance(&Polygon::new(outer, vec![])), None);
    }

    /// The pole of a 3-4-5 triangle is its incentre (1, 1), radius 1; a polygon with
    /// no inside has none.
    #[test]
    fn the_pole_is_the_centre_of_the_largest_inscribed_circle() {
        let triangle = Polygon::new(pts(&[(0.0, 0.0), (3.0, 0.0), (0.0, 4.0)]), vec![]);
        let (c, r) = pole(&triangle, 1e-6).expect("a pole");
        assert!(
            (c - Point2::new(1.0, 1.0)).norm() < 1e-4 && (r - 1.0).abs() < 1e-5,
            "{c:?} {r}"
        );
        // Off the origin, on the right of its box.
        let moved = Polygon::new(pts(&[(13.0, 20.0), (13.0, 24.0), (10.0, 20.0)]), vec![]);
        let (c, r) = pole(&moved, 1e-6).expect("a pole");
        assert!(
            (c - Point2::new(12.0, 21.0)).norm() < 1e-4 && (r - 1.0).abs() < 1e-5,
            "{c:?} {r}"
        );
        let flat = Polygon::new(pts(&[(0.0, 0.0), (0.0, 2.0), (0.0, 4.0)]), vec![]);
        assert_eq!(pole(&flat, 1e-3), None);
    }
}
