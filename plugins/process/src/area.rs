//! The geometry the operations share: a layer's area, offsets, raster passes over an
//! area, and the stretches of a boundary that run along another region.

use lamina_api::{LayerPlan, Limit, Limits, OperationPath, Point2, Polygon, Result};
use lamina_geom::Shapes;
use lamina_geom::offset::round_offset;
use lamina_geom::ring::{polygons_of, shape_of};

/// Chord tolerance of offsets (mm).
const TOLERANCE: f64 = 0.005;

/// A height rounded to whole micrometres, the sequence's unit, so that heights built
/// by adding allowances read as they were meant (0.32, not 0.32000000000000006).
pub fn micrometres(mm: f64) -> f64 {
    (mm * 1000.0).round() / 1000.0
}

/// The surface of the layer's region as its operations so far leave it: the last
/// height one of them set, else the layer's design height.
pub fn surface_now(plan: &LayerPlan) -> f64 {
    plan.operations
        .iter()
        .rev()
        .find(|op| op.region == plan.material_region && op.surface.is_some())
        .and_then(|op| op.surface)
        .unwrap_or(plan.z)
}

/// The last operation of `kind` on the layer's region so far, if any.
pub fn last_of<'p>(plan: &'p LayerPlan, kind: &str) -> Option<&'p lamina_api::Operation> {
    plan.operations
        .iter()
        .rfind(|op| op.kind == kind && op.region == plan.material_region)
}

/// The solid area of a planned layer: every family of every part.
pub fn layer_area(plan: &LayerPlan) -> Vec<Polygon> {
    plan.parts
        .iter()
        .flat_map(|p| p.families.iter().map(|&f| p.tree.family_polygon(&p.contours, f)))
        .filter(|p| p.area() > 0.0)
        .collect()
}

/// `polygons` offset by `d` (negative: inward) with round joins.
///
/// Growing a polygon closes every hole no wider than `2 d` (its inradius is at most
/// half its box's smaller side): such holes are left out beforehand, which is exact and
/// spares the engine the inverted rings that make it slow.
pub fn offset(polygons: &[Polygon], d: f64) -> Vec<Polygon> {
    let shapes: Shapes = polygons
        .iter()
        .map(|p| {
            let mut p = p.clone();
            if d > 0.0 {
                p.holes.retain(|h| {
                    let b = h.bbox();
                    b.width().min(b.height()) > 2.0 * d
                });
            }
            shape_of(&p)
        })
        .collect();
    if shapes.is_empty() || d == 0.0 {
        return polygons.to_vec();
    }
    polygons_of(&round_offset(&shapes, d, TOLERANCE))
}

/// Passes along x, `spacing` apart, over `polygons` (even-odd inside), at height `z`:
/// the lines at the middle of each band of `spacing`, cut where they cross a boundary,
/// every other line reversed so the tool zig-zags. The number of lines is checked
/// against the run's grid limit first.
pub fn raster(polygons: &[Polygon], spacing: f64, z: f64, limits: &Limits) -> Result<Vec<OperationPath>> {
    let Some(bbox) = polygons.iter().map(Polygon::bbox).reduce(|a, b| a.union(&b)) else {
        return Ok(Vec::new());
    };
    if !spacing.is_finite() || spacing <= 0.0 || bbox.is_empty() {
        return Ok(Vec::new());
    }
    let count = (bbox.height() / spacing).ceil().max(1.0);
    limits.check(
        Limit::GridSamples,
        count,
        &format!("passes {spacing} mm apart over the layer"),
    )?;
    let lines = count as usize;
    // Centre the lines on the box, so both edges get the same margin.
    let y0 = bbox.center().y - (lines as f64 - 1.0) * spacing / 2.0;
    let mut out = Vec::new();
    let mut xs = Vec::new();
    for k in 0..lines {
        let y = y0 + k as f64 * spacing;
        xs.clear();
        for p in polygons {
            for c in p.contours() {
                for (a, b) in c.edges() {
                    // Half-open in y, so a vertex on the line counts once.
                    if (a.y <= y) != (b.y <= y) {
                        xs.push(a.x + (y - a.y) / (b.y - a.y) * (b.x - a.x));
                    }
                }
            }
        }
        xs.sort_by(f64::total_cmp);
        let mut spans: Vec<(f64, f64)> = xs
            .chunks_exact(2)
            .filter(|s| s[1] > s[0])
            .map(|s| (s[0], s[1]))
            .collect();
        if k % 2 == 1 {
            spans.reverse();
            for s in &mut spans {
                *s = (s.1, s.0);
            }
        }
        out.extend(spans.into_iter().map(|(a, b)| OperationPath {
            z,
            points: vec![Point2::new(a, y), Point2::new(b, y)],
            closed: false,
        }));
    }
    Ok(out)
}

/// Distance from `p` to the area of `polygons` (0 inside).
pub fn distance_to_area(p: Point2, polygons: &[Polygon]) -> f64 {
    if polygons.iter().any(|q| q.contains(p)) {
        return 0.0;
    }
    polygons
        .iter()
        .map(|q| q.boundary_distance(p))
        .fold(f64::INFINITY, f64::min)
}

/// The stretches of the closed ring `ring` (first point not repeated) whose points lie
/// within `reach` of the area of `other`, each as an open path; a ring that runs along
/// `other` all round comes back whole and closed. Edges are split every `step` mm so a
/// stretch starts and ends within `step` of where the ring meets or leaves `other`.
pub fn adjoining_runs(ring: &[Point2], other: &[Polygon], reach: f64, step: f64) -> Vec<(Vec<Point2>, bool)> {
    let n = ring.len();
    if n < 3 {
        return Vec::new();
    }
    let mut pts = Vec::new();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        let parts = ((b - a).norm() / step).ceil().max(1.0) as usize;
        pts.extend((0..parts).map(|k| a + (b - a) * (k as f64 / parts as f64)));
    }
    let near: Vec<bool> = pts.iter().map(|&p| distance_to_area(p, other) <= reach).collect();
    if near.iter().all(|&b| b) {
        return vec![(pts, true)];
    }
    // Start just after a point that is not near, so no run wraps around the start.
    let Some(start) = near.iter().position(|&b| !b) else {
        return Vec::new();
    };
    let m = pts.len();
    let mut runs = Vec::new();
    let mut run: Vec<Point2> = Vec::new();
    for k in 1..=m {
        let i = (start + k) % m;
        if near[i] {
            run.push(pts[i]);
        } else if !run.is_empty() {
            runs.push((std::mem::take(&mut run), false));
        }
    }
    if !run.is_empty() {
        runs.push((run, false));
    }
    // A single point touches the other region only at a corner: nothing to cut along.
    runs.retain(|(r, _)| r.len() >= 2);
    runs
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::Contour;

    fn square(x0: f64, y0: f64, s: f64) -> Polygon {
        Polygon::new(
            Contour::rectangle(Point2::new(x0, y0), Point2::new(x0 + s, y0 + s)),
            Vec::new(),
        )
    }

    #[test]
    fn raster_lines_cover_the_area_and_skip_holes() {
        let mut p = square(0.0, 0.0, 10.0);
        p.holes
            .push(Contour::rectangle(Point2::new(4.0, 0.25), Point2::new(6.0, 9.75)).oriented(false));
        let paths = raster(&[p], 1.0, 2.0, &Limits::default()).expect("within limits");
        // Ten lines at y = 0.5 .. 9.5, each cut in two by the hole.
        assert_eq!(paths.len(), 20);
        let length: f64 = paths.iter().map(OperationPath::length).sum();
        assert!((length - 80.0).abs() < 1e-9, "{length}");
        assert!(paths.iter().all(|p| p.z == 2.0));
        // Zig-zag: the second line runs backwards.
        assert!(paths.iter().any(|p| p.points[0].x > p.points[1].x));
    }

    #[test]
    fn raster_lines_are_a_spacing_apart_centred_and_end_on_slanted_sides() {
        // A square turned 45 degrees, 10 mm across: 25 lines at y = 0.2 .. 9.8, each
        // from side to side, the first along +x and every other one back.
        let diamond = Polygon::new(
            Contour::new(vec![
                Point2::new(5.0, 0.0),
                Point2::new(10.0, 5.0),
                Point2::new(5.0, 10.0),
                Point2::new(0.0, 5.0),
            ]),
            Vec::new(),
        );
        let paths = raster(&[diamond], 0.4, 1.0, &Limits::default()).expect("within limits");
        assert_eq!(paths.len(), 25);
        for (k, p) in paths.iter().enumerate() {
            let y = 0.2 + 0.4 * k as f64;
            let (a, b) = (p.points[0], p.points[1]);
            assert!(
                (a.y - y).abs() < 1e-9 && (b.y - y).abs() < 1e-9,
                "line {k}: {a:?} {b:?}"
            );
            let half = 5.0 - (y - 5.0).abs();
            let (from, to) = if k % 2 == 0 {
                (5.0 - half, 5.0 + half)
            } else {
                (5.0 + half, 5.0 - half)
            };
            assert!(
                (a.x - from).abs() < 1e-9 && (b.x - to).abs() < 1e-9,
                "line {k}: {a:?} {b:?}"
            );
        }
        // No spacing, no passes.
        for spacing in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let none = raster(&[square(0.0, 0.0, 1.0)], spacing, 0.0, &Limits::default()).expect("no passes");
            assert!(none.is_empty(), "{spacing}");
        }
    }

    #[test]
    fn offsets_move_a_square_in_by_their_distance() {
        let inner = offset(&[square(0.0, 0.0, 10.0)], -1.0);
        assert_eq!(inner.len(), 1);
        assert!((inner[0].area() - 64.0).abs() < 1e-6, "{}", inner[0].area());
        // Growing a ring closes a hole narrower than twice the distance, and only that.
        let ring = |ri: f64| {
            Polygon::new(
                Contour::circle(Point2::new(0.0, 0.0), 10.0, 128),
                vec![Contour::circle(Point2::new(0.0, 0.0), ri, 128).oriented(false)],
            )
        };
        let closed = offset(&[ring(5.0)], 5.01);
        assert!(closed.len() == 1 && closed[0].holes.is_empty());
        let open = offset(&[ring(9.0)], 2.0);
        assert_eq!(open[0].holes.len(), 1);
        assert!(
            (open[0].holes[0].area() - std::f64::consts::PI * 49.0).abs() < 0.2,
            "{}",
            open[0].holes[0].area()
        );
    }

    #[test]
    fn runs_follow_only_the_stretch_along_the_other_region() {
        // The right edge of [0, 10]^2 adjoins [10, 20] x [0, 10].
        let ring = square(0.0, 0.0, 10.0).outer.points;
        let runs = adjoining_runs(&ring, &[square(10.0, 0.0, 10.0)], 0.05, 0.5);
        assert_eq!(runs.len(), 1);
        let (run, closed) = &runs[0];
        assert!(!closed);
        assert!(run.iter().all(|p| (p.x - 10.0).abs() < 1e-9), "{run:?}");
        let length: f64 = run.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        assert!((length - 10.0).abs() < 1e-9, "{length}");
        // A ring inside the other region runs along it all round.
        let all = adjoining_runs(
            &square(12.0, 2.0, 2.0).outer.points,
            &[square(10.0, 0.0, 10.0)],
            0.0,
            0.5,
        );
        assert!(all.len() == 1 && all[0].1);
    }

    #[test]
    fn each_stretch_along_the_other_region_is_a_run_ending_within_a_step_of_it() {
        // The other region holds the lower half of the right side and the upper half of
        // the left one: two runs, points a step apart, each ending where the region does.
        let ring = square(0.0, 0.0, 10.0).outer.points;
        let other = [square(10.0, 0.0, 5.0), square(-5.0, 5.0, 5.0)];
        let runs = adjoining_runs(&ring, &other, 0.05, 0.25);
        assert_eq!(runs.len(), 2, "{runs:?}");
        for (run, closed) in &runs {
            assert!(!closed);
            assert!(run.windows(2).all(|w| (w[1] - w[0]).norm() <= 0.25 + 1e-9));
            let x = run[0].x;
            assert!(run.iter().all(|p| p.x == x), "{run:?}");
            let lo = run.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
            let hi = run.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
            let want = if x == 10.0 { (0.0, 5.0) } else { (5.0, 10.0) };
            assert!(x == 10.0 || x == 0.0, "{x}");
            assert!(
                (lo - want.0).abs() < 1e-9 && (hi - want.1).abs() < 1e-9,
                "{x}: {lo} to {hi}"
            );
        }
        // A triangle is a ring too.
        let triangle = [
            Point2::new(0.0, 0.0),
            Point2::new(10.0, 0.0),
            Point2::new(10.0, 10.0),
        ];
        assert_eq!(adjoining_runs(&triangle, &other[..1], 0.05, 0.25).len(), 1);
    }
}
