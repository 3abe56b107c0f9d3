//! Contour-parallel fill of one sub-region: closed loops along the iso-material
//! contours (the region's boundary offset inward by w/2, 3w/2, ...). Each loop's bead
//! covers the band within w/2 of it, so consecutive loops w apart neither leave a gap
//! nor deposit twice; what stays uncovered is the part of the medial band narrower
//! than one width. A last pass that is a ring narrower than one width keeps only its
//! outer side, where loops along both would deposit their overlap twice; a last pass
//! that is a hole-free sliver keeps its loop (a centre line would need the medial
//! axis).

use i_overlay::mesh::float::outline::offset::OutlineOffset;
use i_overlay::mesh::float::style::{LineJoin, OutlineStyle};
use lamina_core::{Point2, Polygon};

/// Largest distance (mm) between a round offset corner and its chords.
const TOLERANCE: f64 = 0.005;

/// Upper bound on passes per region, so a huge region with a tiny width cannot run
/// away with memory.
const MAX_PASSES: usize = 100_000;

/// One closed pass: `points.first() == points.last()`.
#[derive(Debug, Clone, PartialEq)]
pub struct Loop {
    pub points: Vec<Point2>,
}

impl Loop {
    pub fn length(&self) -> f64 {
        self.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    /// Restarts the closed loop at vertex `i` (the seam), keeping start = end.
    pub fn rotated(&self, i: usize) -> Loop {
        let n = self.points.len().saturating_sub(1);
        if n == 0 || i == 0 || i >= n {
            return self.clone();
        }
        let mut points: Vec<Point2> = self.points[i..n].to_vec();
        points.extend_from_slice(&self.points[..=i]);
        Loop { points }
    }

    /// Index and distance of the vertex nearest to `p`.
    pub fn nearest_vertex(&self, p: Point2) -> (usize, f64) {
        let n = self.points.len().saturating_sub(1).max(1).min(self.points.len());
        let mut best = (0, f64::INFINITY);
        for (i, q) in self.points[..n].iter().enumerate() {
            let d2 = (q - p).norm_squared();
            if d2 < best.1 {
                best = (i, d2);
            }
        }
        (best.0, best.1.sqrt())
    }

    /// Index of the vertex with the largest x (then largest y): an aligned seam.
    pub fn max_x_vertex(&self) -> usize {
        let n = self.points.len().saturating_sub(1).max(1);
        let mut best = 0;
        for (i, q) in self.points[..n.min(self.points.len())].iter().enumerate() {
            let b = self.points[best];
            if q.x > b.x || (q.x == b.x && q.y > b.y) {
                best = i;
            }
        }
        best
    }
}

/// The region's contours for the offsetter, simplified first: sub-regions cut on a
/// fine grid carry hundreds of vertices per millimetre of round or stepped boundary,
/// and the offsetter's cost grows with every crossing of their offset edges (a thin
/// ring's inner and outer offsets cross at every wiggle). Dropping what strays less
/// than the chord tolerance moves no pass by more than that tolerance.
/// A region whose outer contour simplifies to a sliver has no shape.
fn shapes_of(p: &Polygon) -> Vec<Vec<Vec<[f64; 2]>>> {
    let ring = |c: &lamina_core::Contour| {
        let ring: Vec<[f64; 2]> = c.points.iter().map(|q| [q.x, q.y]).collect();
        simplify(&ring, TOLERANCE)
    };
    let outer = ring(&p.outer);
    if outer.len() < 3 {
        return Vec::new();
    }
    let mut shape = vec![outer];
    shape.extend(p.holes.iter().map(ring).filter(|c| c.len() >= 3));
    vec![shape]
}

/// The passes filling `polygon` at extrusion width `width`, outermost first. Empty
/// when the region is thinner than one width everywhere.
pub fn contour_passes(polygon: &Polygon, width: f64) -> Vec<Loop> {
    let mut loops = Vec::new();
    if width.is_nan() || width <= 0.0 || polygon.outer.len() < 3 || polygon.area() <= 0.0 {
        return loops;
    }
    // Each pass is the previous one offset by one width (the first by half a width):
    // erosions by discs compose, and small offsets need far fewer arc segments for the
    // same chord tolerance than one large offset of the region.
    let mut current = shapes_of(polygon);
    for k in 0..MAX_PASSES {
        let d = if k == 0 { width / 2.0 } else { width };
        if current.iter().all(|shape| surely_thin(shape, d)) {
            break;
        }
        let step = 2.0 * (1.0 - (TOLERANCE / d).min(1.0)).acos();
        let style = OutlineStyle::new(-d).line_join(LineJoin::Round(step.max(0.01)));
        let inset: Vec<Vec<Vec<[f64; 2]>>> = current.outline(&style);
        if inset.is_empty() {
            break;
        }
        for shape in &inset {
            // A band narrower than one width everywhere (the last pass of a ring):
            // beads along both its sides would overlap by the difference, so only its
            // outer side is deposited, leaving less than one width open.
            let sides = if shape.len() > 1 && surely_thin(shape, width / 2.0) {
                1
            } else {
                shape.len()
            };
            for contour in &shape[..sides] {
                if contour.len() < 3 {
                    continue;
                }
                let contour = simplify(contour, TOLERANCE);
                if contour.len() < 3 {
                    continue;
                }
                let mut points: Vec<Point2> = contour.iter().map(|q| Point2::new(q[0], q[1])).collect();
                // Every loop runs counter-clockwise, holes' too: two tools working
                // along the same wall then move the same way round instead of
                // meeting head-on, where one of them must step aside.
                if signed_area(&points) < 0.0 {
                    points.reverse();
                }
                points.push(points[0]);
                loops.push(Loop { points });
            }
        }
        // Offsets of offsets would multiply the arc vertices pass after pass.
        current = inset
            .into_iter()
            .map(|shape| {
                shape
                    .into_iter()
                    .map(|c| simplify(&c, TOLERANCE))
                    .filter(|c| c.len() >= 3)
                    .collect()
            })
            .filter(|s: &Vec<Vec<[f64; 2]>>| !s.is_empty())
            .collect();
    }
    loops
}

/// The shoelace area of an open ring (positive counter-clockwise).
fn signed_area(ring: &[Point2]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        / 2.0
}

/// Largest number of sample points the thinness test spends on one shape before it
/// leaves the answer to the offsetter.
const MAX_SAMPLES: usize = 200_000;

/// Most cells of the edge table of the thinness test.
const MAX_CELLS: usize = 4096;

/// Whether no point of `shape` (outer ring, then holes) lies `d` or more from its
/// boundary, so that offsetting it inward by `d` leaves nothing. Most sub-regions of a
/// finely graded part are such slivers, and proving it on a sample grid is far cheaper
/// than offsetting them. Distance to the boundary is 1-Lipschitz: with samples `s`
/// apart, every point inside is within `s/√2` of an inside sample (or of the boundary),
/// so when every inside sample is nearer than `d - s/√2` to an edge, no point reaches
/// `d`. `false` means "not proven", never "thick".
fn surely_thin(shape: &[Vec<[f64; 2]>], d: f64) -> bool {
    let s = d / 3.0;
    let reach = d - s * std::f64::consts::FRAC_1_SQRT_2;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for q in shape.iter().flatten() {
        for a in 0..2 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    if !(lo[0].is_finite() && hi[0].is_finite() && lo[1].is_finite() && hi[1].is_finite() && s > 0.0) {
        return false;
    }
    let cols = ((hi[0] - lo[0]) / s).ceil() as usize + 1;
    let rows = ((hi[1] - lo[1]) / s).ceil() as usize + 1;
    if cols.saturating_mul(rows) > MAX_SAMPLES {
        return false;
    }
    // Edges binned on cells of side at least `reach` (coarser on large shapes, to keep
    // the table small): a sample nearer than `reach` to an edge finds it in its own cell
    // or the eight around it. Compressed rows: `start[c]..start[c + 1]` in `binned`.
    let cell = reach.max(((hi[0] - lo[0]) * (hi[1] - lo[1]) / MAX_CELLS as f64).sqrt());
    let (gw, gh) = (
        ((hi[0] - lo[0]) / cell) as usize + 1,
        ((hi[1] - lo[1]) / cell) as usize + 1,
    );
    let cell_of = |v: f64, a: usize, n: usize| (((v - lo[a]) / cell).max(0.0) as usize).min(n - 1);
    let edges: Vec<([f64; 2], [f64; 2])> = shape
        .iter()
        .filter(|r| r.len() >= 2)
        .flat_map(|r| (0..r.len()).map(move |i| (r[i], r[(i + 1) % r.len()])))
        .collect();
    let span = |(a, b): &([f64; 2], [f64; 2])| {
        (
            cell_of(a[0].min(b[0]), 0, gw)..=cell_of(a[0].max(b[0]), 0, gw),
            cell_of(a[1].min(b[1]), 1, gh)..=cell_of(a[1].max(b[1]), 1, gh),
        )
    };
    let mut start = vec![0u32; gw * gh + 1];
    let mut total = 0usize;
    for e in &edges {
        let (xs, ys) = span(e);
        total += xs.clone().count() * ys.clone().count();
        if total > MAX_SAMPLES {
            return false;
        }
        for y in ys {
            for x in xs.clone() {
                start[y * gw + x + 1] += 1;
            }
        }
    }
    for c in 0..gw * gh {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut binned = vec![0u32; total];
    for (i, e) in edges.iter().enumerate() {
        let (xs, ys) = span(e);
        for y in ys {
            for x in xs.clone() {
                let slot = &mut fill[y * gw + x];
                binned[*slot as usize] = i as u32;
                *slot += 1;
            }
        }
    }
    let bins = |c: usize| &binned[start[c] as usize..start[c + 1] as usize];
    // Rows of samples at y = lo + (k + ½) s; the inside of a row lies between pairs of
    // sorted edge crossings (even-odd, which the outer ring and holes share).
    let mut crossings: Vec<(usize, f64)> = Vec::new();
    for (a, b) in &edges {
        let (p, q) = if a[1] <= b[1] { (a, b) } else { (b, a) };
        if p[1] == q[1] {
            continue;
        }
        let first = ((p[1] - lo[1]) / s - 0.5).ceil().max(0.0) as usize;
        let mut k = first;
        loop {
            let y = lo[1] + (k as f64 + 0.5) * s;
            if y >= q[1] || k >= rows {
                break;
            }
            if y >= p[1] {
                crossings.push((k, p[0] + (q[0] - p[0]) * (y - p[1]) / (q[1] - p[1])));
            }
            k += 1;
        }
    }
    crossings.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let near = |x: f64, y: f64| {
        let (cx, cy) = (cell_of(x, 0, gw), cell_of(y, 1, gh));
        let p = Point2::new(x, y);
        (cy.saturating_sub(1)..=(cy + 1).min(gh - 1)).any(|gy| {
            (cx.saturating_sub(1)..=(cx + 1).min(gw - 1)).any(|gx| {
                bins(gy * gw + gx).iter().any(|&e| {
                    let (a, b) = edges[e as usize];
                    lamina_core::geom::segment_distance(p, Point2::new(a[0], a[1]), Point2::new(b[0], b[1]))
                        < reach
                })
            })
        })
    };
    for row in crossings.chunk_by(|a, b| a.0 == b.0) {
        let y = lo[1] + (row[0].0 as f64 + 0.5) * s;
        for pair in row.chunks_exact(2) {
            let (xa, xb) = (pair[0].1, pair[1].1);
            // Samples on the column grid x = lo + (j + ½) s inside [xa, xb].
            let mut j = ((xa - lo[0]) / s - 0.5).ceil().max(0.0) as usize;
            loop {
                let x = lo[0] + (j as f64 + 0.5) * s;
                if x > xb {
                    break;
                }
                if !near(x, y) {
                    return false;
                }
                j += 1;
            }
        }
    }
    true
}

/// A closed ring with the vertices dropped that stray less than `tol` from the chord
/// replacing them (greedy, runs of at most 64 vertices).
pub fn simplify(ring: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    let n = ring.len();
    if n <= 3 {
        return ring.to_vec();
    }
    let mut out = Vec::with_capacity(n / 2 + 3);
    let mut a = 0;
    out.push(ring[0]);
    while a < n {
        // Extend the chord from `a` as far as every skipped vertex stays within `tol`.
        let mut b = a + 1;
        while b < n && b - a < 64 {
            let next = b + 1;
            let end = ring[next % n];
            let ok = (a + 1..next).all(|k| chord_distance2(ring[k % n], ring[a % n], end) <= tol * tol);
            if !ok {
                break;
            }
            b = next;
        }
        if b >= n {
            break;
        }
        out.push(ring[b % n]);
        a = b;
    }
    out
}

/// Squared distance from `p` to segment `ab`: the simplifier compares it with the
/// squared tolerance for every skipped vertex of every chord it tries, so no root.
fn chord_distance2(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (abx, aby) = (b[0] - a[0], b[1] - a[1]);
    let (apx, apy) = (p[0] - a[0], p[1] - a[1]);
    let len2 = abx * abx + aby * aby;
    let t = if len2 > 0.0 {
        ((apx * abx + apy * aby) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (dx, dy) = (apx - abx * t, apy - aby * t);
    dx * dx + dy * dy
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_core::Contour;

    fn square(c: f64, h: f64) -> Contour {
        Contour::new(vec![
            Point2::new(c - h, c - h),
            Point2::new(c + h, c - h),
            Point2::new(c + h, c + h),
            Point2::new(c - h, c + h),
        ])
    }

    #[test]
    fn a_square_gets_concentric_closed_loops() {
        let p = Polygon::new(square(0.0, 5.0), vec![]);
        let loops = contour_passes(&p, 0.4);
        // Offsets at 0.2, 0.6, ..., 4.6 (12 passes; 5.0 is the inradius).
        assert_eq!(loops.len(), 12, "{}", loops.len());
        for l in &loops {
            assert_eq!(l.points.first(), l.points.last());
        }
        let deposited: f64 = loops.iter().map(|l| l.length() * 0.4).sum();
        assert!((deposited - p.area()).abs() / p.area() < 0.02, "{deposited}");
    }

    #[test]
    fn a_ring_gets_loops_around_the_hole_and_a_thin_region_none() {
        let p = Polygon::new(square(0.0, 5.0), vec![square(0.0, 3.0).oriented(false)]);
        let loops = contour_passes(&p, 0.4);
        // A 2 mm band: passes at 0.2 and 0.6 mm from each side, and small loops in the
        // four thicker corners; along the sides the medial band 0.8..1.2 mm (one width)
        // stays open rather than being deposited twice.
        assert_eq!(loops.len(), 8);
        let deposited: f64 = loops.iter().map(|l| l.length() * 0.4).sum();
        let gap = 8.0 * 4.0 * 0.4;
        assert!(
            deposited <= p.area() && deposited + gap >= p.area() - 0.5,
            "{deposited} vs {}",
            p.area()
        );
        let thin = Polygon::new(square(0.0, 0.15), vec![]);
        assert!(contour_passes(&thin, 0.4).is_empty());
    }

    #[test]
    fn a_ring_narrower_than_two_widths_gets_one_loop_not_two_overlapping() {
        // A 0.6 mm band: the pass at 0.2 mm is a 0.2 mm ring; beads along both its
        // sides would overlap by 0.2 mm, so only the outer one is laid.
        let p = Polygon::new(square(0.0, 5.0), vec![square(0.0, 4.4).oriented(false)]);
        let loops = contour_passes(&p, 0.4);
        assert_eq!(loops.len(), 1);
        let deposited = loops[0].length() * 0.4;
        assert!(deposited <= p.area() + 1e-6, "{deposited} vs {}", p.area());
        assert!(deposited >= p.area() * 0.6, "{deposited} vs {}", p.area());
    }

    #[test]
    fn seams_rotate_and_keep_the_loop_closed() {
        let l = Loop {
            points: vec![
                Point2::new(0.0, 0.0),
                Point2::new(1.0, 0.0),
                Point2::new(1.0, 1.0),
                Point2::new(0.0, 1.0),
                Point2::new(0.0, 0.0),
            ],
        };
        assert_eq!(l.max_x_vertex(), 2);
        let r = l.rotated(2);
        assert_eq!(r.points.first(), Some(&Point2::new(1.0, 1.0)));
        assert_eq!(r.points.first(), r.points.last());
        assert!((r.length() - 4.0).abs() < 1e-12);
        assert_eq!(l.nearest_vertex(Point2::new(0.1, 0.9)).0, 3);
    }
}
