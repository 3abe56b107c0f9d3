//! Measures of a family that decide how it is divided: the minimum distance between its
//! contours (L_s of Eq. 14), its inradius (how deep an inward offset can go), and a
//! point well inside a polygon for a region's reference.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use lamina_api::geom::{closest_on_segment, polygon_centroid, segment_distance};
use lamina_api::{Contour, Point2, Polygon};
use rstar::primitives::Line;
use rstar::{AABB, PointDistance, RTree};

/// The edges of one or more contours in an R-tree: a sliced wall has thousands of
/// edges, and the measures below ask for the distance to them thousands of times.
pub struct Edges {
    tree: RTree<Line<[f64; 2]>>,
    max_x: f64,
}

impl Edges {
    pub fn new<'a>(contours: impl IntoIterator<Item = &'a Contour>) -> Self {
        let lines: Vec<Line<[f64; 2]>> = contours
            .into_iter()
            .flat_map(|c| c.edges())
            .map(|(a, b)| Line::new([a.x, a.y], [b.x, b.y]))
            .collect();
        let max_x = lines
            .iter()
            .map(|l| l.from[0].max(l.to[0]))
            .fold(f64::NEG_INFINITY, f64::max);
        Edges {
            tree: RTree::bulk_load(lines),
            max_x,
        }
    }

    /// Distance from `p` to the nearest edge (infinite without edges).
    pub fn distance(&self, p: Point2) -> f64 {
        self.tree
            .nearest_neighbor([p.x, p.y])
            .map_or(f64::INFINITY, |l| l.distance_2(&[p.x, p.y]).sqrt())
    }

    /// Whether `p` is inside under the even-odd rule, which for a polygon's outer
    /// contour and holes is inside the outer and outside every hole: the edges
    /// crossed by the ray from `p` toward +x, counted.
    pub fn contains(&self, p: Point2) -> bool {
        if p.x > self.max_x {
            return false;
        }
        let ray = AABB::from_corners([p.x, p.y], [self.max_x, p.y]);
        let mut inside = false;
        for l in self.tree.locate_in_envelope_intersecting(ray) {
            let (a, b) = (l.from, l.to);
            if (a[1] > p.y) != (b[1] > p.y) && p.x < a[0] + (p.y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
                inside = !inside;
            }
        }
        inside
    }
}

/// Shortest distance between two contours that do not cross: attained at a vertex of
/// one of them, so vertex-to-segment distances both ways are exact.
pub fn contour_distance(a: &Contour, b: &Contour) -> f64 {
    edges_distance(a, &Edges::new([a]), b, &Edges::new([b]))
}

fn edges_distance(a: &Contour, ea: &Edges, b: &Contour, eb: &Edges) -> f64 {
    let one_way = |a: &Contour, eb: &Edges| {
        a.points
            .iter()
            .map(|&p| eb.distance(p))
            .fold(f64::INFINITY, f64::min)
    };
    one_way(a, eb).min(one_way(b, ea))
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
            best = best.min(edges_distance(contours[i], &edges[i], contours[j], &edges[j]));
        }
    }
    (contours.len() > 1 && best.is_finite()).then_some(best)
}

/// A square cell of the pole search: centre, half size, distance of the centre to the
/// boundary (negative outside) and the best distance any point of the cell can reach.
struct Cell {
    c: Point2,
    h: f64,
    d: f64,
    max: f64,
}

impl Cell {
    fn new(edges: &Edges, c: Point2, h: f64) -> Self {
        let d = edges.distance(c);
        let d = if edges.contains(c) { d } else { -d };
        Self {
            c,
            h,
            d,
            max: d + h * std::f64::consts::SQRT_2,
        }
    }
}

impl PartialEq for Cell {
    fn eq(&self, other: &Self) -> bool {
        self.max == other.max
    }
}
impl Eq for Cell {}
impl PartialOrd for Cell {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Cell {
    fn cmp(&self, other: &Self) -> Ordering {
        self.max.total_cmp(&other.max)
    }
}

/// The pole of inaccessibility (the interior point farthest from the boundary) within
/// `precision`, and its distance to the boundary: the radius of the largest inscribed
/// circle. Branch and bound over square cells; `None` for a polygon with no inside.
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
            heap.push(Cell::new(&edges, Point2::new(x + h, y + h), h));
            x += size;
        }
        y += size;
    }
    let start = interior_point(polygon)?;
    let mut best = Cell::new(&edges, start, 0.0);
    // A bound on the work for pathological inputs: the answer stays a valid interior
    // point, only less central.
    let mut budget = 20_000;
    while let Some(cell) = heap.pop() {
        if cell.d > best.d {
            best = Cell::new(&edges, cell.c, 0.0);
        }
        if cell.max - best.d <= precision || budget == 0 {
            continue;
        }
        budget -= 1;
        let h = cell.h / 2.0;
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            heap.push(Cell::new(
                &edges,
                Point2::new(cell.c.x + sx * h, cell.c.y + sy * h),
                h,
            ));
        }
    }
    (best.d > 0.0).then_some((best.c, best.d))
}

/// A point inside the polygon, central across its width: the midpoint of the widest
/// inside interval of a few horizontal scan lines. Cheap (no distance queries); `None`
/// when no scan line finds an inside.
pub fn interior_point(polygon: &Polygon) -> Option<Point2> {
    let bbox = polygon.bbox();
    let mut best: Option<(f64, Point2)> = None;
    let mut xs = Vec::new();
    // Odd fractions avoid scanning exactly through vertices of axis-aligned shapes.
    for f in [0.5013, 0.2507, 0.7493, 0.1249, 0.3751, 0.6249, 0.8751] {
        let y = bbox.min.y + f * bbox.height();
        xs.clear();
        for c in polygon.contours() {
            for (a, b) in c.edges() {
                if (a.y <= y) != (b.y <= y) {
                    xs.push(a.x + (y - a.y) / (b.y - a.y) * (b.x - a.x));
                }
            }
        }
        xs.sort_unstable_by(f64::total_cmp);
        for pair in xs.chunks_exact(2) {
            let width = pair[1] - pair[0];
            if width > best.map_or(0.0, |b| b.0) {
                best = Some((width, Point2::new(0.5 * (pair[0] + pair[1]), y)));
            }
        }
        if best.is_some() && f < 0.5 {
            // One line through the middle and one more are enough for a reference.
            break;
        }
    }
    best.map(|b| b.1)
}

/// The reference point of a circumferential cell: its centre, as the paper locates it
/// (topological-hierarchy Fig. 14), that is the centroid of its area. A cell that
/// wraps around a corner of its ring (an L) has its centroid outside it; a composition
/// is the cell's own only at a point of the cell, so it takes the point of the cell
/// nearest its centroid (a hair inside the boundary), and a central point inside it
/// ([`interior_point`]) should that fail.
pub fn cell_centre(polygon: &Polygon) -> Option<Point2> {
    let c = polygon_centroid(polygon)?;
    if polygon.contains(c) {
        return Some(c);
    }
    let q = polygon
        .contours()
        .flat_map(|r| r.edges())
        .map(|(a, b)| closest_on_segment(c, a, b))
        .min_by(|p, q| (p - c).norm_squared().total_cmp(&(q - c).norm_squared()));
    // From outside, the way to the nearest boundary point goes on into the cell.
    let hair = 1e-6 * polygon.bbox().diagonal().max(1e-3);
    q.and_then(|q| {
        let d = q - c;
        let n = d.norm();
        (n > 0.0).then(|| q + d * (hair / n))
    })
    .filter(|&p| polygon.contains(p))
    .or_else(|| interior_point(polygon))
}

/// Distance from `p` to the nearest of `contours`.
pub fn distance_to(contours: &[&Contour], p: Point2) -> f64 {
    contours
        .iter()
        .flat_map(|c| c.edges())
        .map(|(a, b)| segment_distance(p, a, b))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{circle, rect};

    #[test]
    fn centroid_of_a_ring_and_the_centre_of_an_l() {
        // A 10 x 10 square less a 2 x 2 hole off centre (1..3): centroid by moments.
        let hole = rect(1.0, 1.0, 2.0, 2.0);
        let ring = Polygon::new(rect(0.0, 0.0, 10.0, 10.0), vec![hole]);
        let c = polygon_centroid(&ring).expect("an area");
        let want = (100.0 * 5.0 - 4.0 * 2.0) / 96.0;
        assert!((c.x - want).abs() < 1e-12 && (c.y - want).abs() < 1e-12, "{c:?}");
        // Inside: the centroid itself.
        assert_eq!(cell_centre(&ring), Some(c));
        // An L (4 x 1 and 1 x 4 legs): its centroid (19/14, 19/14) lies in the notch,
        // outside; the centre is the point of the L nearest to it, on one of the
        // inner edges, 5/14 mm away.
        let l = Polygon::new(
            Contour::new(
                [
                    (0.0, 0.0),
                    (4.0, 0.0),
                    (4.0, 1.0),
                    (1.0, 1.0),
                    (1.0, 4.0),
                    (0.0, 4.0),
                ]
                .map(|(x, y)| Point2::new(x, y))
                .to_vec(),
            ),
            vec![],
        );
        let c = polygon_centroid(&l).expect("an area");
        let want = (4.0 * 2.0 + 3.0 * 0.5) / 7.0;
        assert!((c.x - want).abs() < 1e-12 && (c.y - want).abs() < 1e-12, "{c:?}");
        assert!(!l.contains(c));
        let p = cell_centre(&l).expect("a point");
        assert!(l.contains(p));
        assert!(((p - c).norm() - 5.0 / 14.0).abs() < 1e-4, "{p:?}");
        assert!((p.x - 1.0).abs() < 1e-4 || (p.y - 1.0).abs() < 1e-4, "{p:?}");
    }

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
        let p = interior_point(&tube).expect("inside");
        assert!(tube.contains(p));
    }
}
