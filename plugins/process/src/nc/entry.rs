//! How a cutter enters the work: never straight down into it.
//!
//! - An end mill ramps along its own path: down at the ramp angle from the approach
//!   height to the cutting depth, around a closed path as many laps as it takes, back
//!   and forth along an open one; at depth it then cuts the whole path, so the ramp's
//!   stretch is cut at depth too.
//! - A cup wheel enters from the side: each pass is lengthened at both ends until the
//!   wheel's whole face stands clear of the area, and the wheel ramps down to the
//!   grinding height there, in the air, before it feeds in.

use lamina_api::{Point2, Polygon};

use crate::area::distance_to_area;

/// A point of a path in three dimensions.
pub type Point3 = (Point2, f64);

/// The point at arc length `s` along `points` (closed: wrapping round).
fn at(points: &[Point2], closed: bool, s: f64) -> Point2 {
    let n = points.len();
    let segments = if closed { n } else { n - 1 };
    let mut left = s;
    for i in 0..segments {
        let (a, b) = (points[i], points[(i + 1) % n]);
        let l = (b - a).norm();
        if left <= l {
            return if l > 0.0 { a + (b - a) * (left / l) } else { a };
        }
        left -= l;
    }
    points[if closed { 0 } else { n - 1 }]
}

/// Arc lengths of the path's vertices, and its whole length.
fn stations(points: &[Point2], closed: bool) -> (Vec<f64>, f64) {
    let n = points.len();
    let mut s = vec![0.0];
    let segments = if closed { n } else { n - 1 };
    for i in 0..segments {
        let l = (points[(i + 1) % n] - points[i]).norm();
        s.push(s[i] + l);
    }
    let total = s[segments];
    s.truncate(n);
    (s, total)
}

/// The path's points between arc lengths `from` and `to` (either way; a closed path's
/// arc lengths grow past its length to wrap round), the end points included.
fn walk(points: &[Point2], closed: bool, from: f64, to: f64) -> Vec<(f64, Point2)> {
    let (st, total) = stations(points, closed);
    let mut out = vec![(from, at(points, closed, wrap(from, total, closed)))];
    let (lo, hi) = (from.min(to), from.max(to));
    let mut inner = Vec::new();
    if closed && total > 0.0 {
        let first_lap = (lo / total).floor() as i64;
        let last_lap = (hi / total).floor() as i64;
        for lap in first_lap..=last_lap {
            for (i, &v) in st.iter().enumerate() {
                let s = lap as f64 * total + v;
                if s > lo + 1e-9 && s < hi - 1e-9 {
                    inner.push((s, points[i]));
                }
            }
        }
    } else {
        for (i, &v) in st.iter().enumerate() {
            if v > lo + 1e-9 && v < hi - 1e-9 {
                inner.push((v, points[i]));
            }
        }
    }
    inner.sort_by(|a, b| a.0.total_cmp(&b.0));
    if to < from {
        inner.reverse();
    }
    out.extend(inner);
    out.push((to, at(points, closed, wrap(to, total, closed))));
    out
}

fn wrap(s: f64, total: f64, closed: bool) -> f64 {
    if closed && total > 0.0 {
        s.rem_euclid(total)
    } else {
        s
    }
}

/// An end mill's way along `points` from `top` down to `depth` and the whole path at
/// depth, in order; empty for a path of no length.
pub fn ramp(points: &[Point2], closed: bool, top: f64, depth: f64, angle_deg: f64) -> Vec<Point3> {
    let closed = closed && points.len() > 2;
    if points.len() < 2 {
        return Vec::new();
    }
    let (_, total) = stations(points, closed);
    if total <= 1e-9 {
        return Vec::new();
    }
    let slope = angle_deg.to_radians().tan();
    let drop = (top - depth).max(0.0);
    let run = drop / slope;
    let mut out: Vec<Point3> = vec![(points[0], top)];
    let z_at = |travelled: f64| {
        if travelled >= run - 1e-9 {
            depth
        } else {
            (top - travelled * slope).max(depth)
        }
    };
    if closed {
        // Laps down, then one lap at depth from where the ramp ends.
        for (s, p) in walk(points, true, 0.0, run).into_iter().skip(1) {
            out.push((p, z_at(s)));
        }
        for (_, p) in walk(points, true, run, run + total).into_iter().skip(1) {
            out.push((p, depth));
        }
    } else {
        // Back and forth until at depth, back to the start, then the whole path.
        let (mut s, mut forward, mut travelled) = (0.0, true, 0.0);
        while travelled < run - 1e-9 {
            let end = if forward { total } else { 0.0 };
            let leg = (end - s).abs().min(run - travelled);
            let to = if forward { s + leg } else { s - leg };
            for (t, p) in walk(points, false, s, to).into_iter().skip(1) {
                out.push((p, z_at(travelled + (t - s).abs())));
            }
            travelled += leg;
            s = to;
            forward = !forward;
        }
        for (_, p) in walk(points, false, s, 0.0).into_iter().skip(1) {
            out.push((p, depth));
        }
        for (_, p) in walk(points, false, 0.0, total).into_iter().skip(1) {
            out.push((p, depth));
        }
    }
    out.dedup_by(|a, b| (a.0 - b.0).norm() < 1e-9 && (a.1 - b.1).abs() < 1e-9);
    out
}

/// A cup wheel as it enters the work.
#[derive(Debug, Clone, Copy)]
pub struct Wheel {
    pub radius: f64,
    /// Room between its face and the area where it is lowered (mm).
    pub margin: f64,
    /// Angle of its way down (degrees).
    pub angle_deg: f64,
}

/// A cup wheel's pass from `a` to `b` at height `z`, entered from the side: the way in
/// (from `approach` height down to `z` at the ramp angle, in the air), the pass
/// lengthened until the wheel stands its margin clear of `area` at both ends.
pub fn side_entry(
    a: Point2,
    b: Point2,
    z: f64,
    approach: f64,
    wheel: Wheel,
    area: &[Polygon],
) -> Vec<Point3> {
    let Wheel {
        radius,
        margin,
        angle_deg,
    } = wheel;
    let d = b - a;
    let length = d.norm();
    if length <= 1e-9 {
        return Vec::new();
    }
    let u = d / length;
    let clear = |p: Point2| distance_to_area(p, area) >= radius + margin;
    // Out along the line until the face is clear: at most the area's size past it.
    let reach = area
        .iter()
        .map(|p| {
            let b = p.bbox();
            b.width() + b.height()
        })
        .fold(0.0, f64::max)
        + radius
        + margin;
    let out_from = |p: Point2, dir: lamina_api::Vector2| {
        let mut t = radius + margin;
        while !clear(p + dir * t) && t < reach {
            t += 0.5;
        }
        p + dir * t
    };
    let start = out_from(a, -u);
    let end = out_from(b, u);
    let slope = angle_deg.to_radians().tan();
    let run = (approach - z).max(0.0) / slope;
    vec![(start - u * run, approach), (start, z), (a, z), (b, z), (end, z)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::Contour;

    fn length3(path: &[Point3]) -> f64 {
        path.windows(2)
            .map(|w| ((w[1].0 - w[0].0).norm_squared() + (w[1].1 - w[0].1).powi(2)).sqrt())
            .sum()
    }

    #[test]
    fn a_ramp_around_a_loop_never_falls_steeper_than_its_angle_and_cuts_a_whole_lap_at_depth() {
        let square = Contour::rectangle(Point2::new(0.0, 0.0), Point2::new(2.0, 2.0)).points;
        let path = ramp(&square, true, 1.0, 0.0, 3.0);
        let slope = 3f64.to_radians().tan();
        for w in path.windows(2) {
            let flat = (w[1].0 - w[0].0).norm();
            let fall = w[0].1 - w[1].1;
            assert!(fall <= flat * slope + 1e-9, "{w:?}");
            assert!(flat > 1e-12, "a vertical move {w:?}");
        }
        assert_eq!(path[0].1, 1.0);
        let at_depth: f64 = path
            .windows(2)
            .filter(|w| w[0].1 == 0.0 && w[1].1 == 0.0)
            .map(|w| (w[1].0 - w[0].0).norm())
            .sum();
        assert!((at_depth - 8.0).abs() < 1e-9, "{at_depth}");
        // 1 mm down at 3 degrees: 19.08 mm of ramp, then the 8 mm lap.
        assert!((length3(&path) - (1.0 / 3f64.to_radians().sin() + 8.0)).abs() < 1e-6);
    }

    #[test]
    fn a_ramp_from_above_the_depth_goes_on_forward_and_a_two_point_loop_is_a_line() {
        let square = Contour::rectangle(Point2::new(0.0, 0.0), Point2::new(2.0, 2.0)).points;
        // From 1.5 down to 0.5 mm: a drop of 1 mm, whatever the depth.
        let path = ramp(&square, true, 1.5, 0.5, 3.0);
        assert_eq!(path[0].1, 1.5);
        assert!(path.iter().all(|p| p.1 >= 0.5));
        assert!((length3(&path) - (1.0 / 3f64.to_radians().sin() + 8.0)).abs() < 1e-6);
        // The ramp ends 19.08 mm round (3.08 into the second edge, at y = 1.08); the lap
        // at depth goes on the same way round, to (2, 2) first.
        let end = path.iter().position(|p| p.1 == 0.5).expect("at depth");
        assert!((path[end].0 - Point2::new(2.0, 1.0 / 3f64.to_radians().tan() - 18.0)).norm() < 1e-9);
        assert_eq!(path[end + 1].0, Point2::new(2.0, 2.0));
        // Two points make a line, whatever the flag says.
        let line = [Point2::new(0.0, 0.0), Point2::new(5.0, 0.0)];
        assert_eq!(
            ramp(&line, true, 0.5, 0.0, 3.0),
            ramp(&line, false, 0.5, 0.0, 3.0)
        );
    }

    #[test]
    fn a_ramp_along_a_short_open_path_goes_back_and_forth_then_cuts_it_whole() {
        let line = [Point2::new(0.0, 0.0), Point2::new(5.0, 0.0)];
        let path = ramp(&line, false, 0.5, 0.0, 3.0);
        let slope = 3f64.to_radians().tan();
        let run = 0.5 / slope;
        for w in path.windows(2) {
            assert!((w[1].0 - w[0].0).norm() > 1e-12, "a vertical move {w:?}");
        }
        let last = path.last().expect("points");
        assert_eq!((last.0, last.1), (Point2::new(5.0, 0.0), 0.0));
        let flat: f64 = path.windows(2).map(|w| (w[1].0 - w[0].0).norm()).sum();
        // The ramp's run, back to the start, and the whole line at depth.
        let back = if ((run / 5.0).floor() as i64) % 2 == 0 {
            run % 5.0
        } else {
            5.0 - run % 5.0
        };
        assert!((flat - (run + back + 5.0)).abs() < 1e-6, "{flat} {run}");
        // A ramp that ends back on the start (twice the line's length): no point twice.
        let path = ramp(&line, false, 0.5, 0.0, 0.05f64.atan().to_degrees());
        for w in path.windows(2) {
            assert!(
                (w[1].0 - w[0].0).norm() > 1e-12,
                "a point twice or a vertical move {w:?}"
            );
        }
        assert_eq!(path.len(), 4, "{path:?}");
    }

    /// On the way back along an open path the ramp goes on falling: each vertex it
    /// passes at the height its whole way so far gives.
    #[test]
    fn a_ramp_falls_by_its_whole_way_on_the_way_back_too() {
        let line = [
            Point2::new(0.0, 0.0),
            Point2::new(10.0, 0.0),
            Point2::new(20.0, 0.0),
        ];
        let slope = 3f64.to_radians().tan();
        // 35 mm of ramp: out 20 mm, back 15 mm past the middle vertex.
        let top = 35.0 * slope;
        let path = ramp(&line, false, top, 0.0, 3.0);
        let travelled = [0.0, 10.0, 20.0, 30.0, 35.0];
        let xs = [0.0, 10.0, 20.0, 10.0, 5.0];
        for (k, (&t, &x)) in travelled.iter().zip(&xs).enumerate() {
            let (p, z) = path[k];
            assert_eq!(p, Point2::new(x, 0.0), "{path:?}");
            assert!((z - (top - t * slope)).abs() < 1e-9, "point {k}: {z}");
        }
        // Back to the start at depth, then the whole line.
        assert_eq!(path.len(), 5 + 1 + 2, "{path:?}");
        assert!(path[5..].iter().all(|&(_, z)| z == 0.0));
    }

    #[test]
    fn a_wheel_enters_where_its_face_is_clear_of_the_area() {
        let disc = Polygon::new(Contour::circle(Point2::new(0.0, 0.0), 10.0, 128), Vec::new());
        let (a, b) = (Point2::new(-4.36, 9.0), Point2::new(4.36, 9.0));
        let way = side_entry(
            a,
            b,
            1.0,
            2.0,
            Wheel {
                radius: 10.0,
                margin: 1.0,
                angle_deg: 5.0,
            },
            std::slice::from_ref(&disc),
        );
        let (start, end) = (way[1].0, way[4].0);
        assert!(distance_to_area(start, std::slice::from_ref(&disc)) >= 11.0 - 1e-9);
        assert!(distance_to_area(end, std::slice::from_ref(&disc)) >= 11.0 - 1e-9);
        // The way down is in the air, at the ramp angle.
        let fall = way[0].1 - way[1].1;
        assert!((fall / (way[1].0 - way[0].0).norm() - 5f64.to_radians().tan()).abs() < 1e-9);
        assert!(way.iter().skip(1).all(|p| p.1 == 1.0));
    }

    #[test]
    fn a_wheel_stands_off_outward_at_the_first_half_millimetre_where_its_face_is_clear() {
        let disc = Polygon::new(Contour::circle(Point2::new(0.0, 0.0), 10.0, 128), Vec::new());
        let area = std::slice::from_ref(&disc);
        let (a, b) = (Point2::new(-4.36, 9.0), Point2::new(4.36, 9.0));
        for (radius, margin) in [(10.0, 0.3), (50.0, 1.0), (3.0, 0.0)] {
            let wheel = Wheel {
                radius,
                margin,
                angle_deg: 5.0,
            };
            let way = side_entry(a, b, 1.0, 2.0, wheel, area);
            let clear = |p: Point2| distance_to_area(p, area) >= radius + margin;
            // Out from each end of the pass, along it, by radius + margin + k 0.5 mm,
            // the first of these where the face is clear.
            for (end, from, dir) in [(way[1].0, a, -1.0), (way[4].0, b, 1.0)] {
                let t = (end - from).x * dir;
                assert!((end - from).y.abs() < 1e-12 && t > 0.0, "{end:?} from {from:?}");
                let k = (t - radius - margin) / 0.5;
                assert!((k - k.round()).abs() < 1e-9 && k > -1e-9, "t {t}");
                assert!(clear(end), "{end:?}");
                if k.round() > 0.0 {
                    assert!(
                        !clear(from + Point2::new(dir * (t - 0.5), 0.0).coords),
                        "not the first"
                    );
                }
            }
            let run = 1.0 / 5f64.to_radians().tan();
            assert!((way[0].0 - (way[1].0 - Point2::new(run, 0.0).coords)).norm() < 1e-9);
            assert_eq!((way[2].0, way[3].0), (a, b));
        }
    }

    #[test]
    fn a_walk_lists_the_vertices_strictly_between_its_ends_in_its_direction() {
        let p = |x: f64, y: f64| Point2::new(x, y);
        // A 2 x 2 square, 8 mm round, vertices at 0, 2, 4, 6.
        let square = [p(0.0, 0.0), p(2.0, 0.0), p(2.0, 2.0), p(0.0, 2.0)];
        let w = walk(&square, true, 1.0, 5.0);
        assert_eq!(
            w,
            vec![
                (1.0, p(1.0, 0.0)),
                (2.0, p(2.0, 0.0)),
                (4.0, p(2.0, 2.0)),
                (5.0, p(1.0, 2.0))
            ]
        );
        // Backwards, and past the first lap into the second and third: every vertex of
        // each lap on the way, none twice, none at an end.
        let w = walk(&square, true, 13.0, 3.0);
        let s: Vec<f64> = w.iter().map(|(s, _)| *s).collect();
        assert_eq!(s, vec![13.0, 12.0, 10.0, 8.0, 6.0, 4.0, 3.0]);
        assert_eq!(w[0].1, p(1.0, 2.0));
        assert_eq!(w[1].1, p(2.0, 2.0));
        assert_eq!(w[3].1, p(0.0, 0.0));
        assert_eq!(w[6].1, p(2.0, 1.0));
        // Ends on vertices: the vertices are the ends, not listed again.
        let w = walk(&square, true, 2.0, 6.0);
        let s: Vec<f64> = w.iter().map(|(s, _)| *s).collect();
        assert_eq!(s, vec![2.0, 4.0, 6.0]);
        // A negative arc length wraps round a closed path.
        assert_eq!(walk(&square, true, -1.0, 0.5)[0].1, p(0.0, 1.0));
        // Open: no wrapping; vertices between the ends only.
        let line = [p(0.0, 0.0), p(1.0, 0.0), p(3.0, 0.0)];
        let w = walk(&line, false, 2.5, 0.5);
        assert_eq!(
            w,
            vec![(2.5, p(2.5, 0.0)), (1.0, p(1.0, 0.0)), (0.5, p(0.5, 0.0))]
        );
        // Vertices before the nearer end, or on the farther one, are not between them.
        let w = walk(&line, false, 1.5, 3.0);
        assert_eq!(w, vec![(1.5, p(1.5, 0.0)), (3.0, p(3.0, 0.0))]);
        let w = walk(&line, false, 3.0, 1.5);
        assert_eq!(w, vec![(3.0, p(3.0, 0.0)), (1.5, p(1.5, 0.0))]);
        // Past an open path's end nothing repeats: its last vertex once.
        let w = walk(&line, false, 0.0, 4.0);
        let s: Vec<f64> = w.iter().map(|(s, _)| *s).collect();
        assert_eq!(s, vec![0.0, 1.0, 3.0, 4.0]);
        assert_eq!(wrap(-1.0, 3.0, false), -1.0);
        assert_eq!(wrap(7.0, 3.0, true), 1.0);
        assert_eq!(wrap(7.0, 0.0, true), 7.0);
    }

    #[test]
    fn a_point_at_an_arc_length_lies_on_the_path_and_its_ends_hold_past_them() {
        let p = |x: f64, y: f64| Point2::new(x, y);
        // An open path starting on a repeated point, 3 + 4 mm long.
        let open = [p(0.0, 0.0), p(0.0, 0.0), p(3.0, 0.0), p(3.0, 4.0)];
        assert_eq!(at(&open, false, 0.0), p(0.0, 0.0));
        assert_eq!(at(&open, false, 1.5), p(1.5, 0.0));
        assert_eq!(at(&open, false, 5.0), p(3.0, 2.0));
        // Past the end: the last point, not round to the first.
        assert_eq!(at(&open, false, 7.0), p(3.0, 4.0));
        assert_eq!(at(&open, false, 9.0), p(3.0, 4.0));
        // Closed, the way back to the first point is part of it (5 mm), and past the
        // whole length stands the first point.
        assert_eq!(at(&open, true, 9.5), p(1.5, 2.0));
        assert_eq!(at(&open, true, 13.0), p(0.0, 0.0));
        let (st, total) = stations(&open, true);
        assert_eq!((st, total), (vec![0.0, 0.0, 3.0, 7.0], 12.0));
        let (st, total) = stations(&open, false);
        assert_eq!((st, total), (vec![0.0, 0.0, 3.0, 7.0], 7.0));
    }
}
