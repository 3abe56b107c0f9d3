//! The layer's solid areas as a travel sees them. A straight travel that crosses no
//! contour of the layer and runs inside a part stays over the part: what oozes on the
//! way lands where the layer is, or will be, deposited, so the travel needs neither a
//! retraction nor a lift (PrusaSlicer's "only retract when crossing perimeters").

use lamina_api::{LayerPlan, Point2, Vector2};

/// Cells of the edge grid along the layer's longer side, at most.
const BUCKETS: f64 = 128.0;

/// The contours of a layer's parts, in machine coordinates, filed in a grid.
pub struct Solid {
    edges: Vec<(Point2, Point2)>,
    /// The middle of each family's outer contour's box, where detours turn toward.
    centres: Vec<Point2>,
    min: Point2,
    bucket: f64,
    cols: usize,
    rows: usize,
    grid: Vec<Vec<u32>>,
}

impl Solid {
    /// The solid areas of `plan`'s parts (each part's families: outer contours and
    /// holes), moved by `offset` onto the bed.
    pub fn new(plan: &LayerPlan, offset: Vector2) -> Self {
        let mut edges = Vec::new();
        let mut centres = Vec::new();
        for part in &plan.parts {
            for &f in &part.families {
                let Some(family) = part.tree.families.get(f) else {
                    continue;
                };
                if let Some(outer) = part.contours.get(family.outer)
                    && !outer.points.is_empty()
                {
                    let (lo, hi) = outer.points.iter().fold(
                        (Point2::new(f64::MAX, f64::MAX), Point2::new(f64::MIN, f64::MIN)),
                        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
                    );
                    centres.push(Point2::from((lo.coords + hi.coords) / 2.0) + offset);
                }
                for &c in std::iter::once(&family.outer).chain(&family.holes) {
                    let Some(contour) = part.contours.get(c) else {
                        continue;
                    };
                    let p = &contour.points;
                    for i in 0..p.len() {
                        let (a, b) = (p[i] + offset, p[(i + 1) % p.len()] + offset);
                        if a != b {
                            edges.push((a, b));
                        }
                    }
                }
            }
        }
        let (mut min, mut max) = (Point2::new(f64::MAX, f64::MAX), Point2::new(f64::MIN, f64::MIN));
        for (a, b) in &edges {
            for p in [a, b] {
                min = Point2::new(min.x.min(p.x), min.y.min(p.y));
                max = Point2::new(max.x.max(p.x), max.y.max(p.y));
            }
        }
        if edges.is_empty() {
            return Self {
                edges,
                centres,
                min: Point2::origin(),
                bucket: 1.0,
                cols: 0,
                rows: 0,
                grid: Vec::new(),
            };
        }
        let bucket = ((max.x - min.x).max(max.y - min.y) / BUCKETS).max(0.5);
        let cols = ((max.x - min.x) / bucket).floor() as usize + 1;
        let rows = ((max.y - min.y) / bucket).floor() as usize + 1;
        let mut solid = Self {
            edges,
            centres,
            min,
            bucket,
            cols,
            rows,
            grid: vec![Vec::new(); cols * rows],
        };
        for (i, &(a, b)) in solid.edges.iter().enumerate() {
            let ((c0, r0), (c1, r1)) = solid.span(a, b);
            for r in r0..=r1 {
                for c in c0..=c1 {
                    solid.grid[r * cols + c].push(i as u32);
                }
            }
        }
        solid
    }

    /// The buckets (column, row) of the box of `a`-`b`, clamped to the grid.
    fn span(&self, a: Point2, b: Point2) -> ((usize, usize), (usize, usize)) {
        let index =
            |v: f64, lo: f64, n: usize| (((v - lo) / self.bucket).floor().max(0.0) as usize).min(n - 1);
        let (x0, x1) = (a.x.min(b.x), a.x.max(b.x));
        let (y0, y1) = (a.y.min(b.y), a.y.max(b.y));
        (
            (index(x0, self.min.x, self.cols), index(y0, self.min.y, self.rows)),
            (index(x1, self.min.x, self.cols), index(y1, self.min.y, self.rows)),
        )
    }

    /// Whether the straight travel from `a` to `b` stays inside the solid areas: it
    /// crosses no contour and its middle is inside.
    pub fn holds(&self, a: Point2, b: Point2) -> bool {
        if self.edges.is_empty() {
            return false;
        }
        let ((c0, r0), (c1, r1)) = self.span(a, b);
        for r in r0..=r1 {
            for c in c0..=c1 {
                for &e in &self.grid[r * self.cols + c] {
                    let (p, q) = self.edges[e as usize];
                    if crosses(a, b, p, q) {
                        return false;
                    }
                }
            }
        }
        self.inside(Point2::from((a.coords + b.coords) / 2.0))
    }

    /// A point to turn at so that the travel from `a` to `b` stays inside in two
    /// straight moves (combing: the middle of the travel drawn toward the middle of a
    /// family, the nearest family first), when one such turn keeps the detour under
    /// twice the direct way.
    pub fn detour(&self, a: Point2, b: Point2) -> Option<Point2> {
        let middle = Point2::from((a.coords + b.coords) / 2.0);
        let direct = (b - a).norm();
        // The two nearest families' middles, nearest first.
        let mut near: [Option<Point2>; 2] = [None, None];
        for &c in &self.centres {
            let d = (c - middle).norm();
            let closer = |p: Option<Point2>| p.is_none_or(|p| d < (p - middle).norm());
            if closer(near[0]) {
                near = [Some(c), near[0]];
            } else if closer(near[1]) {
                near[1] = Some(c);
            }
        }
        for c in near.into_iter().flatten() {
            for t in [0.15, 0.3, 0.45, 0.6, 0.75, 0.9] {
                let w = middle + (c - middle) * t;
                if (w - a).norm() + (b - w).norm() > 2.0 * direct {
                    break;
                }
                if self.holds(a, w) && self.holds(w, b) {
                    return Some(w);
                }
            }
        }
        None
    }

    /// Whether `p` is inside (even-odd over every contour: holes count out).
    fn inside(&self, p: Point2) -> bool {
        // A ray toward +x meets the edges filed in the buckets of its row to the right.
        let ((c0, r), _) = self.span(p, p);
        // An edge filed in several buckets of the row counts once.
        let mut row: Vec<u32> = (c0..self.cols)
            .flat_map(|c| self.grid[r * self.cols + c].iter().copied())
            .collect();
        row.sort_unstable();
        row.dedup();
        let crossings = row
            .into_iter()
            .filter(|&e| {
                let (a, b) = self.edges[e as usize];
                (a.y > p.y) != (b.y > p.y) && a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) > p.x
            })
            .count();
        crossings % 2 == 1
    }
}

/// Whether segments a-b and p-q cross or touch.
fn crosses(a: Point2, b: Point2, p: Point2, q: Point2) -> bool {
    let orient = |o: Point2, u: Point2, v: Point2| (u - o).perp(&(v - o));
    let (d1, d2) = (orient(p, q, a), orient(p, q, b));
    let (d3, d4) = (orient(a, b, p), orient(a, b, q));
    (d1 * d2 <= 0.0) && (d3 * d4 <= 0.0) && !(d1 == 0.0 && d2 == 0.0 && d3 == 0.0 && d4 == 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::{Contour, ContourTree, Family, PartLayer};

    /// A 20 mm square with a 6 mm square hole in its middle.
    fn layer() -> LayerPlan {
        let square = |h: f64| {
            Contour::new(vec![
                Point2::new(-h, -h),
                Point2::new(h, -h),
                Point2::new(h, h),
                Point2::new(-h, h),
            ])
        };
        let tree = ContourTree {
            nodes: Vec::new(),
            families: vec![Family {
                outer: 0,
                holes: vec![1],
            }],
        };
        let part = PartLayer {
            part: 0,
            contours: vec![square(10.0), square(3.0)],
            tree,
            families: vec![0],
            regions: Vec::new(),
        };
        LayerPlan {
            index: 0,
            z: 0.2,
            thickness: 0.2,
            material_region: None,
            parts: vec![part],
            toolpaths: Vec::new(),
            build_time: None,
            sequential_time: None,
            fill: None,
            pauses: None,
            operations: Vec::new(),
            diagnostics: Vec::new(),
        }
    }

    #[test]
    fn a_travel_over_the_part_stays_and_one_across_a_hole_or_out_does_not() {
        let s = Solid::new(&layer(), Vector2::new(100.0, 100.0));
        let p = |x: f64, y: f64| Point2::new(100.0 + x, 100.0 + y);
        // Along the ring between the hole and the rim.
        assert!(s.holds(p(-8.0, -8.0), p(8.0, -8.0)));
        assert!(s.holds(p(-8.0, -8.0), p(-8.0, 8.0)));
        // Across the hole, out of the part, or from outside in.
        assert!(!s.holds(p(-8.0, 0.0), p(8.0, 0.0)));
        assert!(!s.holds(p(-8.0, -8.0), p(-12.0, -8.0)));
        assert!(!s.holds(p(-15.0, -15.0), p(15.0, -15.0)));
        // Wholly inside the hole: not over the part.
        assert!(!s.holds(p(-1.0, 0.0), p(1.0, 0.0)));
        // Across the hole there is no single turn that stays inside within twice the way.
        assert!(s.detour(p(-5.0, 0.0), p(5.0, 0.0)).is_none());
    }

    #[test]
    fn a_travel_across_a_notch_turns_inside_the_part() {
        // A square with a notch 4 mm wide and 6 mm deep in its top side, as between
        // two teeth of a gear.
        let mut plan = layer();
        plan.parts[0].contours = vec![Contour::new(
            [
                (-10.0, -10.0),
                (10.0, -10.0),
                (10.0, 10.0),
                (2.0, 10.0),
                (2.0, 4.0),
                (-2.0, 4.0),
                (-2.0, 10.0),
                (-10.0, 10.0),
            ]
            .iter()
            .map(|&(x, y)| Point2::new(x, y))
            .collect(),
        )];
        plan.parts[0].tree.families[0].holes.clear();
        let s = Solid::new(&plan, Vector2::zeros());
        let (a, b) = (Point2::new(-6.0, 8.0), Point2::new(6.0, 8.0));
        assert!(!s.holds(a, b), "straight across the notch");
        let w = s.detour(a, b).expect("a turn inside");
        assert!(s.holds(a, w) && s.holds(w, b), "{w:?}");
        assert!(w.y < 4.0, "below the notch: {w:?}");
    }
}
