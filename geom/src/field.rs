//! A distance field of one family on an `nx` by `ny` grid of samples: the exact distance
//! to the nearest boundary segment for samples within a cell of it, propagated to the
//! rest by the Felzenszwalb-Huttenlocher transform with the nearest seed tracked (so a
//! far sample's distance is measured to a seed's exact boundary point, within half a
//! cell of the exact distance), and the
//! interior found by scanning each row. The grid is padded so that its border samples
//! lie outside the family.

use crate::segment::closest_on_segment;
use crate::shape::{BBox2, Contour, Point2};

/// Samples of a field over a padded bounding box.
#[derive(Debug, Clone)]
pub struct Field {
    pub nx: usize,
    pub ny: usize,
    /// Position of sample (0, 0).
    pub origin: Point2,
    /// Sample spacing (mm), the same along x and y.
    pub h: f64,
    /// Row-major values, `values[j * nx + i]` at `origin + (i h, j h)`.
    pub values: Vec<f64>,
}

impl Field {
    /// An empty field of `cells` samples along the longer side of `bbox`, with 1.5
    /// samples of margin all round.
    pub fn over(bbox: &BBox2, cells: usize) -> Self {
        let extent = bbox.width().max(bbox.height()).max(f64::MIN_POSITIVE);
        // Seeds are packed with 16 bits a coordinate.
        let cells = cells.clamp(4, 1 << 15);
        let h = extent / (cells as f64 - 3.0);
        let nx = ((bbox.width() / h).ceil() as usize + 4).max(4);
        let ny = ((bbox.height() / h).ceil() as usize + 4).max(4);
        Self {
            nx,
            ny,
            origin: Point2::new(bbox.min.x - 1.5 * h, bbox.min.y - 1.5 * h),
            h,
            values: vec![0.0; nx * ny],
        }
    }

    pub fn point(&self, i: usize, j: usize) -> Point2 {
        Point2::new(
            self.origin.x + i as f64 * self.h,
            self.origin.y + j as f64 * self.h,
        )
    }

    /// Inside flags of the samples by even-odd scan lines over `contours`.
    pub fn inside(&self, contours: &[&Contour]) -> Vec<bool> {
        let mut rows: Vec<Vec<f64>> = vec![Vec::new(); self.ny];
        for c in contours {
            for (a, b) in c.edges() {
                let (lo, hi) = if a.y <= b.y { (a, b) } else { (b, a) };
                // Rows with lo.y <= y < hi.y cross this edge.
                // A row more on each side: the exact test below decides, so that both
                // edges at a vertex agree on the rows through it.
                let j0 = ((lo.y - self.origin.y) / self.h).floor().max(0.0) as usize;
                let j1 = (((hi.y - self.origin.y) / self.h).floor().max(0.0) as usize + 2).min(self.ny);
                for (j, row) in rows.iter_mut().enumerate().take(j1).skip(j0) {
                    let y = self.origin.y + j as f64 * self.h;
                    if y >= lo.y && y < hi.y {
                        row.push(lo.x + (y - lo.y) / (hi.y - lo.y) * (hi.x - lo.x));
                    }
                }
            }
        }
        let mut inside = vec![false; self.nx * self.ny];
        for (j, xs) in rows.iter_mut().enumerate() {
            xs.sort_unstable_by(f64::total_cmp);
            for pair in xs.chunks_exact(2) {
                let i0 = ((pair[0] - self.origin.x) / self.h).ceil().max(0.0) as usize;
                let i1 = (((pair[1] - self.origin.x) / self.h).ceil().max(0.0) as usize).min(self.nx);
                for flag in &mut inside[j * self.nx + i0.min(i1)..j * self.nx + i1] {
                    *flag = true;
                }
            }
        }
        inside
    }

    /// Fills `values` with the distance of every sample to the nearest of `contours`.
    pub fn distance_to(&mut self, contours: &[&Contour]) {
        self.distance_where(contours, None);
    }

    /// [`Field::distance_to`] measured only at the samples `wanted` flags and those
    /// within a cell of the boundary; the others are left at infinity. A signed field
    /// cut at positive levels never reads the outside beyond the first cell: a cell
    /// edge that a level crosses has a sample inside, so its other end is within a
    /// cell of the boundary.
    pub fn distance_within(&mut self, contours: &[&Contour], wanted: &[bool]) {
        self.distance_where(contours, Some(wanted));
    }

    fn distance_where(&mut self, contours: &[&Contour], wanted: Option<&[bool]>) {
        SCRATCH.with(|scratch| {
            let mut scratch = scratch.borrow_mut();
            self.distance_with(contours, wanted, &mut scratch);
            // A field far beyond the usual is not kept for the rest of the run.
            if self.nx * self.ny > KEEP_SAMPLES {
                *scratch = Scratch::default();
            }
        });
    }

    fn distance_with(&mut self, contours: &[&Contour], wanted: Option<&[bool]>, scratch: &mut Scratch) {
        let n = self.nx * self.ny;
        let (nx, ny) = (self.nx, self.ny);
        let Scratch {
            near,
            seed_d2,
            from_row,
            seed_of,
        } = scratch;
        // Boundary points of the seeds: read only where a seed was measured in this
        // call, so what an earlier call left there needs no clearing.
        near.resize(n, [0.0; 2]);
        seed_d2.clear();
        seed_d2.resize(n, f64::INFINITY);
        // Seeds are the samples within a cell of the boundary: a thin band keeps the
        // nearest seed's boundary point close to the true nearest boundary point. Each
        // segment visits, column by column, the samples of its cell-wide neighbourhood
        // and measures them exactly.
        let h = self.h;
        let h2 = h * h;
        let (ox, oy) = (self.origin.x, self.origin.y);
        for c in contours {
            for (a, b) in c.edges() {
                let ab = b - a;
                let (x0, x1) = (a.x.min(b.x) - h, a.x.max(b.x) + h);
                let i0 = ((x0 - ox) / h).ceil().max(0.0) as usize;
                let i1 = (((x1 - ox) / h).floor().max(-1.0) + 1.0) as usize;
                for i in i0..i1.min(nx) {
                    let x = ox + i as f64 * h;
                    // The segment's y-range where it is within h in x, widened by h.
                    let (ya, yb) = if ab.x.abs() > 0.0 {
                        let ta = ((x - h - a.x) / ab.x).clamp(0.0, 1.0);
                        let tb = ((x + h - a.x) / ab.x).clamp(0.0, 1.0);
                        (a.y + ab.y * ta, a.y + ab.y * tb)
                    } else {
                        (a.y, b.y)
                    };
                    let (y0, y1) = (ya.min(yb) - h, ya.max(yb) + h);
                    let j0 = ((y0 - oy) / h).ceil().max(0.0) as usize;
                    let j1 = (((y1 - oy) / h).floor().max(-1.0) + 1.0) as usize;
                    for j in j0..j1.min(ny) {
                        let q = Point2::new(x, oy + j as f64 * h);
                        let on = closest_on_segment(q, a, b);
                        let d2 = (q - on).norm_squared();
                        let k = j * nx + i;
                        if d2 <= h2 && d2 < seed_d2[k] {
                            seed_d2[k] = d2;
                            near[k] = [on.x, on.y];
                        }
                    }
                }
            }
        }
        // Column pass: the row of the nearest seed in each sample's column, by a sweep
        // up and a sweep down over whole rows (the seeds are all at 0, so the nearest
        // in a column is the nearest below or above).
        // Every entry is written by the upward sweep.
        from_row.resize(n, u32::MAX);
        let mut last = vec![u32::MAX; nx];
        for j in 0..ny {
            let row = j * nx..(j + 1) * nx;
            for ((l, d), r) in last.iter_mut().zip(&seed_d2[row.clone()]).zip(&mut from_row[row]) {
                if d.is_finite() {
                    *l = j as u32;
                }
                *r = *l;
            }
        }
        last.fill(u32::MAX);
        for j in (0..ny).rev() {
            let row = j * nx..(j + 1) * nx;
            for ((l, d), r) in last.iter_mut().zip(&seed_d2[row.clone()]).zip(&mut from_row[row]) {
                if d.is_finite() {
                    *l = j as u32;
                }
                // Below is nearer when there is none above or it is closer.
                if *l != u32::MAX && (*r == u32::MAX || *l as usize - j < j - *r as usize) {
                    *r = *l;
                }
            }
        }
        // Row pass: over the column results (squared distances in samples, made row by
        // row); the argmin names the column, whose column pass names the row of the
        // nearest seed. Seeds are kept as (row << 16) | column (grids stay below 2^16
        // samples a side), so that comparing them needs no division.
        let mut scratch = Envelope::new(nx.max(ny));
        let mut arg = vec![0u32; nx];
        let mut g = vec![NONE; nx];
        seed_of.clear();
        seed_of.resize(n, u32::MAX);
        for j in 0..ny {
            let from = &from_row[j * nx..(j + 1) * nx];
            for (g, &r) in g.iter_mut().zip(from) {
                *g = if r == u32::MAX {
                    NONE
                } else {
                    let d = j.abs_diff(r as usize) as i64;
                    d * d
                };
            }
            if scratch.transform(&g, &mut arg) {
                for (s, &col) in seed_of[j * nx..(j + 1) * nx].iter_mut().zip(&arg) {
                    *s = (from[col as usize] << 16) | col;
                }
            }
        }
        // Every sample measures its nearest seed's boundary point (seeds their own,
        // exact); squared until the end.
        let d2 = |p: Point2, s: u32| {
            if s == u32::MAX {
                f64::INFINITY
            } else {
                let q = near[(s >> 16) as usize * nx + (s & 0xffff) as usize];
                (p.x - q[0]).powi(2) + (p.y - q[1]).powi(2)
            }
        };
        let want = |k: usize| wanted.is_none_or(|w| w[k]);
        for j in 0..ny {
            let y = oy + j as f64 * h;
            for i in 0..nx {
                let k = j * nx + i;
                self.values[k] = if seed_d2[k].is_finite() {
                    seed_d2[k]
                } else if want(k) {
                    d2(Point2::new(ox + i as f64 * h, y), seed_of[k])
                } else {
                    f64::INFINITY
                };
            }
        }
        // Near a medial axis the nearest seed in samples may sit on the farther
        // boundary. There neighbouring samples take seeds on different stretches of
        // the boundary (seeds more than two samples apart), and each of the two also
        // tries the other's seed.
        // A missing seed (all bits set) is more than two samples from every real one
        // (below 2^15 a side) and none from another missing one: no special case, and
        // no branch for the compiler to keep.
        let apart = |a: u32, b: u32| (a & 0xffff).abs_diff(b & 0xffff).max((a >> 16).abs_diff(b >> 16)) > 2;
        let at = |i: usize, j: usize| Point2::new(ox + i as f64 * h, oy + j as f64 * h);
        let values = &mut self.values;
        // Each sample with its right and upper neighbours: with the samples that look
        // back, its four edge neighbours (the diagonals found nothing more on the
        // tests' medial axes, and cost as much again). The test is inline; the rare
        // pairs that are apart are measured out of line.
        let mut cross = |(i, j): (usize, usize), (ni, nj): (usize, usize), s: u32, t: u32| {
            let (k, m) = (j * nx + i, nj * nx + ni);
            if values[k].is_finite() {
                values[k] = values[k].min(d2(at(i, j), t));
            }
            if values[m].is_finite() {
                values[m] = values[m].min(d2(at(ni, nj), s));
            }
        };
        for j in 0..ny {
            let row = &seed_of[j * nx..(j + 1) * nx];
            let up = seed_of.get((j + 1) * nx..(j + 2) * nx);
            for i in 0..nx {
                let s = row[i];
                if i + 1 < nx && apart(s, row[i + 1]) {
                    cross((i, j), (i + 1, j), s, row[i + 1]);
                }
                if let Some(up) = up
                    && apart(s, up[i])
                {
                    cross((i, j), (i, j + 1), s, up[i]);
                }
            }
        }
        for v in &mut self.values {
            *v = v.sqrt();
        }
    }
}

/// The per-sample work arrays of [`Field::distance_to`], kept per thread: a family's
/// field is several megabytes of them, and fresh allocations of that size are fresh
/// pages from the system on every family, faulted in one by one.
#[derive(Default)]
struct Scratch {
    near: Vec<[f64; 2]>,
    seed_d2: Vec<f64>,
    from_row: Vec<u32>,
    seed_of: Vec<u32>,
}

/// Largest field (samples) whose work arrays a thread keeps for the next family: a
/// 1024 x 1024 field, 24 MiB.
const KEEP_SAMPLES: usize = 1 << 20;

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
}

/// No seed in the column: the column pass leaves this for the row pass to skip.
const NONE: i64 = i64::MAX;

/// The lower envelope of parabolas of the 1-D transform, with buffers kept across rows.
/// Inputs are squared distances in samples, so every comparison of intersections is
/// made exactly in integers by cross-multiplying instead of dividing.
struct Envelope {
    /// Vertices of the parabolas of the envelope and their heights f[p] + p^2.
    v: Vec<i64>,
    h: Vec<i64>,
}

impl Envelope {
    fn new(n: usize) -> Self {
        Self {
            v: vec![0; n],
            h: vec![0; n],
        }
    }

    /// `arg[q]` = the p minimising `(q - p)^2 + f[p]` (Felzenszwalb and Huttenlocher).
    /// `NONE` values are skipped; `false` (and `arg` untouched) when all are.
    fn transform(&mut self, f: &[i64], arg: &mut [u32]) -> bool {
        let mut k = 0usize;
        for (q, &fq) in f.iter().enumerate() {
            if fq == NONE {
                continue;
            }
            let q = q as i64;
            let hq = fq + q * q;
            // Parabola k - 1 is hidden when the new one meets it left of where it
            // meets parabola k - 2: (hq - h1) / (q - v1) <= (h1 - h0) / (v1 - v0).
            while k > 1 {
                let (v0, h0, v1, h1) = (self.v[k - 2], self.h[k - 2], self.v[k - 1], self.h[k - 1]);
                if (hq - h1) * (v1 - v0) <= (h1 - h0) * (q - v1) {
                    k -= 1;
                } else {
                    break;
                }
            }
            self.v[k] = q;
            self.h[k] = hq;
            k += 1;
        }
        if k == 0 {
            return false;
        }
        // Parabola m + 1 takes over from m at the first q where it is strictly lower:
        // (q - v1)^2 + f1 < (q - v0)^2 + f0, that is 2 q (v1 - v0) > h1 - h0. A
        // product per step instead of a division per parabola.
        let (v, h) = (&self.v[..k], &self.h[..k]);
        let mut m = 0usize;
        for (q, a) in arg.iter_mut().enumerate() {
            let q = q as i64;
            while m + 1 < k && 2 * q * (v[m + 1] - v[m]) > h[m + 1] - h[m] {
                m += 1;
            }
            *a = v[m] as u32;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Point2;

    fn circle(cx: f64, cy: f64, r: f64, n: usize) -> Contour {
        Contour::circle(Point2::new(cx, cy), r, n)
    }

    fn rect(x0: f64, y0: f64, w: f64, h: f64) -> Contour {
        Contour::rectangle(Point2::new(x0, y0), Point2::new(x0 + w, y0 + h))
    }

    #[test]
    fn distances_match_the_exact_distance() {
        let c = circle(0.0, 0.0, 10.0, 400);
        let hole = circle(3.0, 1.0, 2.0, 100);
        let mut f = Field::over(&c.bbox(), 128);
        f.distance_to(&[&c, &hole]);
        let inside = f.inside(&[&c, &hole]);
        let mut worst = 0.0f64;
        for j in 0..f.ny {
            for i in 0..f.nx {
                let p = f.point(i, j);
                let exact = c.distance(p).min(hole.distance(p));
                let err = (f.values[j * f.nx + i] - exact).abs();
                worst = worst.max(err);
                if exact <= f.h {
                    assert!(err < 1e-9, "not exact near the boundary at {p:?}");
                }
                let truly = c.contains(p) && !hole.contains(p);
                if exact > 1e-9 {
                    assert_eq!(inside[j * f.nx + i], truly, "{p:?}");
                }
            }
        }
        assert!(worst < 0.5 * f.h, "worst {worst} vs cell {}", f.h);
    }

    #[test]
    fn a_field_within_the_inside_agrees_there_and_near_the_boundary() {
        let c = circle(0.0, 0.0, 10.0, 300);
        let hole = circle(-2.0, 3.0, 3.0, 90);
        let mut all = Field::over(&c.bbox(), 96);
        all.distance_to(&[&c, &hole]);
        let inside = all.inside(&[&c, &hole]);
        let mut within = Field::over(&c.bbox(), 96);
        within.distance_within(&[&c, &hole], &inside);
        let mut skipped = 0;
        for (k, (&a, &w)) in all.values.iter().zip(&within.values).enumerate() {
            if inside[k] || a <= all.h {
                assert_eq!(a, w, "sample {k}");
            } else {
                assert!(w == f64::INFINITY, "sample {k}: {w}");
                skipped += 1;
            }
        }
        assert!(skipped > 0);
    }

    #[test]
    fn border_samples_are_outside() {
        let r = rect(0.0, 0.0, 3.0, 1.0);
        let f = Field::over(&r.bbox(), 64);
        let inside = f.inside(&[&r]);
        for i in 0..f.nx {
            assert!(!inside[i] && !inside[(f.ny - 1) * f.nx + i]);
        }
    }
}
