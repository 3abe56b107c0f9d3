//! A bead: one continuous extrusion, closed (a loop along an iso-material contour) or
//! open (a centre line through what the loops leave), with the width of each of its
//! segments. A segment's width times its length is the area it fills, so a route's
//! extrusion is the area it was cut to fill.

use lamina_api::Point2;

#[derive(Debug, Clone, PartialEq)]
pub struct Bead {
    /// For a closed bead `points.first() == points.last()`.
    pub points: Vec<Point2>,
    /// `widths[i]` is the width of the segment `points[i]` to `points[i + 1]`.
    pub widths: Vec<f64>,
    pub closed: bool,
}

impl Bead {
    /// A closed loop of one width through `ring` (an open ring: it is closed here).
    pub fn closed(mut ring: Vec<Point2>, width: f64) -> Self {
        if let Some(&first) = ring.first() {
            ring.push(first);
        }
        let widths = vec![width; ring.len().saturating_sub(1)];
        Bead {
            points: ring,
            widths,
            closed: true,
        }
    }

    pub fn length(&self) -> f64 {
        self.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    /// The area the bead fills (mm²).
    pub fn area(&self) -> f64 {
        self.points
            .windows(2)
            .zip(&self.widths)
            .map(|(w, b)| (w[1] - w[0]).norm() * b)
            .sum()
    }

    /// The one width of every segment, if they share one.
    pub fn uniform_width(&self) -> Option<f64> {
        let first = *self.widths.first()?;
        self.widths.iter().all(|&w| w == first).then_some(first)
    }

    /// The bead started at vertex `i`: a closed bead restarts there (its seam), keeping
    /// start = end; an open bead can only start at an end, so `i` other than 0 runs it
    /// backwards from its last point.
    pub fn started_at(&self, i: usize) -> Bead {
        if !self.closed {
            if i == 0 {
                return self.clone();
            }
            let mut b = self.clone();
            b.points.reverse();
            b.widths.reverse();
            return b;
        }
        let n = self.points.len().saturating_sub(1);
        if n == 0 || i == 0 || i >= n {
            return self.clone();
        }
        let mut points: Vec<Point2> = self.points[i..n].to_vec();
        points.extend_from_slice(&self.points[..=i]);
        let mut widths: Vec<f64> = self.widths[i..].to_vec();
        widths.extend_from_slice(&self.widths[..i]);
        Bead {
            points,
            widths,
            closed: true,
        }
    }

    /// Where the bead can start nearest to `p`: any vertex of a closed bead, an end of
    /// an open one (the last point is reported as index `points.len() - 1`).
    pub fn nearest_start(&self, p: Point2) -> (usize, f64) {
        if !self.closed {
            let last = self.points.len().saturating_sub(1);
            let d0 = self.points.first().map_or(f64::INFINITY, |q| (q - p).norm());
            let d1 = self.points.last().map_or(f64::INFINITY, |q| (q - p).norm());
            return if d1 < d0 { (last, d1) } else { (0, d0) };
        }
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

    /// Index of the vertex with the largest x (then largest y): an aligned seam. An
    /// open bead starts at whichever end lies further that way.
    pub fn max_x_vertex(&self) -> usize {
        let n = if self.closed {
            self.points.len().saturating_sub(1).max(1)
        } else {
            self.points.len()
        };
        let candidates: Vec<usize> = if self.closed {
            (0..n.min(self.points.len())).collect()
        } else {
            vec![0, self.points.len().saturating_sub(1)]
        };
        let mut best = 0;
        for i in candidates {
            let (q, b) = (self.points[i], self.points[best]);
            if q.x > b.x || (q.x == b.x && q.y > b.y) {
                best = i;
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Bead {
        Bead::closed(
            vec![
                Point2::new(0.0, 0.0),
                Point2::new(1.0, 0.0),
                Point2::new(1.0, 1.0),
                Point2::new(0.0, 1.0),
            ],
            0.4,
        )
    }

    #[test]
    fn seams_rotate_and_keep_the_loop_closed() {
        let mut l = square();
        l.widths[2] = 0.5;
        assert_eq!(l.max_x_vertex(), 2);
        let r = l.started_at(2);
        assert_eq!(r.points.first(), Some(&Point2::new(1.0, 1.0)));
        assert_eq!(r.points.first(), r.points.last());
        assert!((r.length() - 4.0).abs() < 1e-12);
        // The segment from (1,1) keeps its own width.
        assert_eq!(r.widths[0], 0.5);
        assert!((r.area() - l.area()).abs() < 1e-12);
        assert_eq!(l.nearest_start(Point2::new(0.1, 0.9)).0, 3);
    }

    #[test]
    fn open_beads_start_at_an_end() {
        let b = Bead {
            points: vec![
                Point2::new(0.0, 0.0),
                Point2::new(1.0, 0.0),
                Point2::new(3.0, 0.0),
            ],
            widths: vec![0.3, 0.5],
            closed: false,
        };
        assert_eq!(b.nearest_start(Point2::new(2.9, 0.0)).0, 2);
        let r = b.started_at(2);
        assert_eq!(r.points[0], Point2::new(3.0, 0.0));
        assert_eq!(r.widths, vec![0.5, 0.3]);
        assert!((b.area() - 1.3).abs() < 1e-12);
        assert_eq!(b.uniform_width(), None);
        assert_eq!(b.max_x_vertex(), 2);
    }
}
