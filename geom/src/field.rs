//! A distance field of one family on an `nx` by `ny` grid of samples: the exact distance
//! to the nearest boundary segment for samples within a cell of it, propagated to the
//! rest by the Felzenszwalb-Huttenlocher transform with the nearest seed tracked, and the
//! interior found by scanning each row. The grid is padded so that its border samples
//! lie outside the family.
//!
//! A far sample's distance is measured to a seed's exact boundary point, so it is never
//! short of the exact distance. It is over by less than half a cell on round shapes
//! (the tests' discs), and by at most (1 + 1/sqrt 2) cells anywhere: the nearest seed
//! on the grid is no farther than the seed nearest the true nearest boundary point
//! (within half a cell's diagonal of it), and a seed is within a cell of its own
//! boundary point. Where seeds on two stretches of boundary tie on the grid (beside a
//! square corner), three quarters of a cell occurs.

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
        let Scratch { near, from_row } = scratch;
        // Boundary points of the seeds: read only where a seed was measured in this
        // call, so what an earlier call left there needs no clearing.
        near.resize(n, [0.0; 2]);
        // The seeds' squared distances go straight into `values`, which every other
        // sample overwrites below: infinite marks a sample that is not a seed.
        self.values.clear();
        self.values.resize(n, f64::INFINITY);
        self.measure_seeds(contours, near);
        self.nearest_seed_rows(from_row);
        self.measure_from_seeds(near, from_row, wanted);
    }

    /// Seeds are the samples within a cell of the boundary: a thin band keeps the
    /// nearest seed's boundary point close to the true nearest boundary point. Each
    /// segment visits, column by column, the samples of its cell-wide neighbourhood
    /// and measures them exactly: a seed's squared distance into `values`, and its
    /// nearest boundary point into `near`.
    fn measure_seeds(&mut self, contours: &[&Contour], near: &mut [[f64; 2]]) {
        let (nx, ny) = (self.nx, self.ny);
        let values = &mut self.values;
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
                        if d2 <= h2 && d2 < values[k] {
                            values[k] = d2;
                            near[k] = [on.x, on.y];
                        }
                    }
                }
            }
        }
    }

    /// Column pass: the row of the nearest seed in each sample's column, by a sweep
    /// up and a sweep down over whole rows (the seeds are all at 0, so the nearest
    /// in a column is the nearest below or above).
    fn nearest_seed_rows(&self, from_row: &mut Vec<u32>) {
        let (nx, ny) = (self.nx, self.ny);
        let values = &self.values;
        // Every entry is written by the upward sweep, which leaves a seed's own row on
        // the seeds and an earlier row (or none) on the others: the downward sweep
        // tells the seeds by that.
        from_row.resize(nx * ny, u32::MAX);
        let mut last = vec![u32::MAX; nx];
        for j in 0..ny {
            let row = j * nx..(j + 1) * nx;
            for ((l, d), r) in last.iter_mut().zip(&values[row.clone()]).zip(&mut from_row[row]) {
                if d.is_finite() {
                    *l = j as u32;
                }
                *r = *l;
            }
        }
        last.fill(u32::MAX);
        for j in (0..ny).rev() {
            for (l, r) in last.iter_mut().zip(&mut from_row[j * nx..(j + 1) * nx]) {
                if *r == j as u32 {
                    *l = j as u32;
                }
                // Below is nearer when there is none above or it is closer.
                if *l != u32::MAX && (*r == u32::MAX || *l as usize - j < j - *r as usize) {
                    *r = *l;
                }
            }
        }
    }

    /// Row pass: over the column results (squared distances in samples, made row by
    /// row); the argmin names the column, whose column pass names the row of the
    /// nearest seed. Seeds are kept as (row << 16) | column (grids stay below 2^16
    /// samples a side), so that comparing them needs no division. Every sample
    /// then measures its nearest seed's boundary point (seeds keep their own,
    /// exact), squared until the end; samples `wanted` leaves out (seeds aside) stay
    /// at infinity.
    fn measure_from_seeds(&mut self, near: &[[f64; 2]], from_row: &[u32], wanted: Option<&[bool]>) {
        let (nx, ny) = (self.nx, self.ny);
        let values = &mut self.values;
        let h = self.h;
        let (ox, oy) = (self.origin.x, self.origin.y);
        let mut envelope = Envelope::new(nx);
        let d2 = |p: Point2, s: u32| {
            if s == u32::MAX {
                f64::INFINITY
            } else {
                let q = near[(s >> 16) as usize * nx + (s & 0xffff) as usize];
                (p.x - q[0]).powi(2) + (p.y - q[1]).powi(2)
            }
        };
        // Row `j` of seeds into `seeds` and of (squared) distances into `values`.
        let mut measure_row = |j: usize, seeds: &mut [u32], values: &mut [f64]| {
            envelope.nearest(j, &from_row[j * nx..(j + 1) * nx], seeds);
            let y = oy + j as f64 * h;
            let wanted = wanted.map(|w| &w[j * nx..(j + 1) * nx]);
            for (i, (v, &s)) in values.iter_mut().zip(seeds.iter()).enumerate() {
                if !v.is_finite() && wanted.is_none_or(|w| w[i]) {
                    *v = d2(Point2::new(ox + i as f64 * h, y), s);
                }
            }
        };
        // Near a medial axis the nearest seed in samples may sit on the farther
        // boundary. There neighbouring samples take seeds on different stretches of
        // the boundary (seeds more than two samples apart: [`apart`]), and each of the
        // two also tries the other's seed.
        let at = |i: usize, j: usize| Point2::new(ox + i as f64 * h, oy + j as f64 * h);
        // Each sample with its right and upper neighbours: with the samples that look
        // back, its four edge neighbours (the diagonals found nothing more on the
        // tests' medial axes, and cost as much again). A row's pairs are flagged in one
        // sweep; the rare pairs that are apart are measured after it.
        let cross = |values: &mut [f64], (i, j): (usize, usize), (ni, nj): (usize, usize), s: u32, t: u32| {
            let (k, m) = (j * nx + i, nj * nx + ni);
            if values[k].is_finite() {
                values[k] = values[k].min(d2(at(i, j), t));
            }
            if values[m].is_finite() {
                values[m] = values[m].min(d2(at(ni, nj), s));
            }
        };
        // Rows are measured one ahead of the pairs, so that only two rows of seeds are
        // kept and each row is still in cache when its pairs and roots are taken.
        let mut row = vec![u32::MAX; nx];
        let mut up = vec![u32::MAX; nx];
        let mut right = vec![false; nx];
        let mut above = vec![false; nx];
        measure_row(0, &mut row, &mut values[..nx]);
        for j in 0..ny {
            let has_up = j + 1 < ny;
            if has_up {
                measure_row(j + 1, &mut up, &mut values[(j + 1) * nx..(j + 2) * nx]);
            }
            for ((f, s), t) in right.iter_mut().zip(&row).zip(&row[1..]) {
                *f = apart(*s, *t);
            }
            if has_up {
                for ((f, s), t) in above.iter_mut().zip(&row).zip(&up) {
                    *f = apart(*s, *t);
                }
            }
            for i in 0..nx {
                if right[i] {
                    cross(values, (i, j), (i + 1, j), row[i], row[i + 1]);
                }
                if has_up && above[i] {
                    cross(values, (i, j), (i, j + 1), row[i], up[i]);
                }
            }
            // No later pair reaches back to this row: its distances are final.
            for v in &mut values[j * nx..(j + 1) * nx] {
                *v = v.sqrt();
            }
            std::mem::swap(&mut row, &mut up);
        }
    }
}

/// Whether two seeds lie on different stretches of the boundary, as far as the cross
/// step of [`Field::measure_from_seeds`] is concerned: more than two samples apart in
/// column or in row. Seeds are (row << 16) | column, and the test is
/// (difference + 2) > 4 in wrapping unsigned arithmetic, without a branch, so that a
/// whole row is tested at once. A missing seed (all bits set) is apart from every real
/// one (below 2^15 a side) and not from another missing one: no special case.
#[inline]
fn apart(a: u32, b: u32) -> bool {
    let dc = (a & 0xffff).wrapping_sub(b & 0xffff).wrapping_add(2);
    let dr = (a >> 16).wrapping_sub(b >> 16).wrapping_add(2);
    (dc > 4) | (dr > 4)
}

/// The per-sample work arrays of [`Field::distance_to`], kept per thread: a family's
/// field is several megabytes of them, and fresh allocations of that size are fresh
/// pages from the system on every family, faulted in one by one.
#[derive(Default)]
struct Scratch {
    near: Vec<[f64; 2]>,
    from_row: Vec<u32>,
}

/// Largest field (samples) whose work arrays a thread keeps for the next family: a
/// 1024 x 1024 field, 20 MiB.
const KEEP_SAMPLES: usize = 1 << 20;

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
}

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

    /// Row `j` of the row pass (Felzenszwalb and Huttenlocher): `from[p]` is the row
    /// of the nearest seed in column p (`u32::MAX`: none), so f[p] = (j - from[p])^2;
    /// each `seed[q]` is set to the seed (row << 16) | p of the p minimising
    /// `(q - p)^2 + f[p]`, or to `u32::MAX` when no column has a seed.
    fn nearest(&mut self, j: usize, from: &[u32], seed: &mut [u32]) {
        // The stack below its top two parabolas, which stay in registers: each new
        // parabola is compared with them first, and most pop none or one.
        let (v, h) = (&mut self.v, &mut self.h);
        let mut k = 0usize;
        let (mut v0, mut h0, mut v1, mut h1) = (0i64, 0i64, 0i64, 0i64);
        for (q, &r) in from.iter().enumerate() {
            if r == u32::MAX {
                continue;
            }
            let d = j.abs_diff(r as usize) as i64;
            let q = q as i64;
            let hq = d * d + q * q;
            // Parabola k - 1 is hidden when the new one meets it left of where it
            // meets parabola k - 2: (hq - h1) / (q - v1) <= (h1 - h0) / (v1 - v0).
            while k > 1 && (hq - h1) * (v1 - v0) <= (h1 - h0) * (q - v1) {
                k -= 1;
                (v1, h1) = (v0, h0);
                if k > 1 {
                    (v0, h0) = (v[k - 2], h[k - 2]);
                }
            }
            if k > 0 {
                (v0, h0) = (v1, h1);
            }
            (v1, h1) = (q, hq);
            v[k] = q;
            h[k] = hq;
            k += 1;
        }
        // Parabola m + 1 takes over from m at the first q where it is strictly lower:
        // (q - v1)^2 + f1 < (q - v0)^2 + f0, that is 2 q (v1 - v0) > h1 - h0, so at
        // q = floor((h1 - h0) / (2 (v1 - v0))) + 1. The intersections grow from one
        // parabola to the next, so each parabola holds one run of samples, filled
        // with its seed at once.
        if k == 0 {
            seed.fill(u32::MAX);
            return;
        }
        let (v, h) = (&self.v[..k], &self.h[..k]);
        let n = seed.len() as i64;
        let mut start = 0i64;
        for m in 0..k {
            let end = if m + 1 < k {
                ((h[m + 1] - h[m]).div_euclid(2 * (v[m + 1] - v[m])) + 1).clamp(start, n)
            } else {
                n
            };
            let p = v[m] as usize;
            seed[start as usize..end as usize].fill((from[p] << 16) | p as u32);
            start = end;
        }
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
    fn each_sample_of_a_row_takes_the_first_nearest_column_seed() {
        // Rows of column results (with columns that have no seed, and many ties, as a
        // grid gives), against the minimum over every column: the seed of the smallest
        // column that reaches it. Runs of samples are filled per parabola, so this is
        // where an off-by-one in a run's end would show.
        let mut rng = fastrand::Rng::with_seed(0x9e37_79b9_7f4a_7c15);
        let mut next = |m: u64| rng.u64(..m);
        let mut envelope = Envelope::new(64);
        for _ in 0..2000 {
            let n = 1 + next(64) as usize;
            let j = next(40) as usize;
            let from: Vec<u32> = (0..n)
                .map(|_| if next(5) == 0 { u32::MAX } else { next(40) as u32 })
                .collect();
            let mut seed = vec![7u32; n];
            envelope.nearest(j, &from, &mut seed);
            for (q, &got) in seed.iter().enumerate() {
                let cost = |p: usize| {
                    let d = j.abs_diff(from[p] as usize);
                    q.abs_diff(p).pow(2) + d * d
                };
                let best = (0..n)
                    .filter(|&p| from[p] != u32::MAX)
                    .min_by_key(|&p| (cost(p), p));
                let want = best.map_or(u32::MAX, |p| (from[p] << 16) | p as u32);
                assert_eq!(got, want, "row {j}, sample {q} of {from:?}");
            }
        }
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
    fn the_grid_covers_the_box_with_square_cells_and_a_margin() {
        // 13 samples' worth along the longer side: 10 cells over the box, 1.5 cells of
        // margin each side.
        let bbox = BBox2::from_points([Point2::new(100.0, -50.0), Point2::new(130.0, -30.0)]);
        let f = Field::over(&bbox, 13);
        assert_eq!(f.h, 3.0);
        assert_eq!((f.nx, f.ny), (14, 11));
        assert_eq!((f.origin.x, f.origin.y), (95.5, -54.5));
        assert_eq!(f.values.len(), 14 * 11);
        assert_eq!(f.point(2, 3), Point2::new(101.5, -45.5));
        // The far samples lie beyond the box by the margin at least.
        let far = f.point(f.nx - 1, f.ny - 1);
        assert!(
            far.x >= 130.0 + 1.5 * f.h && far.y >= -30.0 + 1.5 * f.h,
            "{far:?}"
        );
        // Too few samples asked for: four along the longer side.
        let f = Field::over(&bbox, 1);
        assert_eq!((f.h, f.nx, f.ny), (30.0, 5, 5));
    }

    /// Every sample's inside flag and distance against the exact ones: the flag
    /// wherever the sample is off the boundary, the distance exact within a cell of
    /// it, and elsewhere never short of the exact one nor more than the bound of the
    /// module's documentation over it.
    fn check_exact(f: &Field, contours: &[&Contour]) {
        let mut g = f.clone();
        g.distance_to(contours);
        let inside = g.inside(contours);
        let mut flagged = 0;
        for j in 0..g.ny {
            for i in 0..g.nx {
                let p = g.point(i, j);
                let exact = contours
                    .iter()
                    .map(|c| c.distance(p))
                    .fold(f64::INFINITY, f64::min);
                let got = g.values[j * g.nx + i];
                if exact <= g.h {
                    assert!((got - exact).abs() < 1e-9, "{got} at {p:?}: {exact}");
                } else {
                    let bound = (1.0 + std::f64::consts::FRAC_1_SQRT_2) * g.h;
                    assert!(
                        got >= exact - 1e-9 && got - exact <= bound,
                        "{got} at {p:?}: {exact}"
                    );
                }
                let truly = contours.iter().filter(|c| c.contains(p)).count() % 2 == 1;
                if exact > 1e-9 {
                    assert_eq!(inside[j * g.nx + i], truly, "{p:?}");
                }
                flagged += usize::from(inside[j * g.nx + i]);
            }
        }
        assert!(flagged > 0);
    }

    #[test]
    fn a_part_far_from_the_origin_on_coarse_cells_is_measured_exactly() {
        // Cells of 3.2 mm, a part 400 mm wide a kilometre away, edges along the axes
        // (a rectangle, a square hole) and slanted (a triangular hole).
        let outer = rect(1000.0, 2000.0, 400.0, 300.0);
        let square = rect(1100.0, 2100.0, 80.0, 80.0).oriented(false);
        let triangle = Contour::new(vec![
            Point2::new(1250.0, 2050.0),
            Point2::new(1350.0, 2120.0),
            Point2::new(1240.0, 2240.0),
        ])
        .oriented(false);
        let contours = [&outer, &square, &triangle];
        let f = Field::over(&outer.bbox(), 128);
        assert_eq!(f.h, 3.2);
        check_exact(&f, &contours);
        // The same part below and left of the origin.
        let mirrored: Vec<Contour> = contours
            .iter()
            .map(|c| Contour::new(c.points.iter().map(|p| Point2::new(-p.x, -p.y)).collect()))
            .collect();
        let mirrored: Vec<&Contour> = mirrored.iter().collect();
        let f = Field::over(&mirrored[0].bbox(), 128);
        check_exact(&f, &mirrored);
    }

    #[test]
    fn a_row_through_a_vertex_crosses_the_boundary_once() {
        // The vertex (5, 5) lies on row 5 of a unit grid, where the contour turns in x
        // and goes on up: one crossing there, not two.
        let c = Contour::new(vec![
            Point2::new(2.0, 2.0),
            Point2::new(8.0, 2.0),
            Point2::new(8.0, 8.5),
            Point2::new(2.0, 8.5),
            Point2::new(5.0, 5.0),
        ]);
        let f = Field {
            nx: 11,
            ny: 11,
            origin: Point2::new(0.0, 0.0),
            h: 1.0,
            values: vec![0.0; 121],
        };
        let inside = f.inside(&[&c]);
        let row: Vec<bool> = (0..11).map(|i| inside[5 * 11 + i]).collect();
        let want: Vec<bool> = (0..11).map(|i| (5..=7).contains(&i)).collect();
        assert_eq!(row, want);
        check_exact(&f, &[&c]);
    }

    #[test]
    fn a_window_over_a_larger_shape_flags_what_it_covers() {
        // The field covers a window inside a disc: the shape's edges start and end
        // beyond the grid, on every side of it.
        let c = circle(0.0, 0.0, 10.0, 360);
        let window = BBox2::from_points([Point2::new(-4.0, -8.0), Point2::new(4.0, -2.0)]);
        let f = Field::over(&window, 24);
        let inside = f.inside(&[&c]);
        for j in 0..f.ny {
            for i in 0..f.nx {
                let p = f.point(i, j);
                if c.distance(p) > 1e-9 {
                    assert_eq!(inside[j * f.nx + i], c.contains(p), "{p:?}");
                }
            }
        }
    }

    #[test]
    fn only_usual_fields_keep_their_work_arrays() {
        let kept = || SCRATCH.with(|s| s.borrow().near.capacity());
        let c = circle(0.0, 0.0, 10.0, 64);
        let mut small = Field::over(&c.bbox(), 64);
        small.distance_to(&[&c]);
        assert!(kept() >= small.nx * small.ny);
        // 1100 x 1100 samples: beyond the 1024 x 1024 kept.
        let mut large = Field::over(&c.bbox(), 1100);
        large.distance_to(&[&c]);
        assert_eq!(kept(), 0);
    }

    #[test]
    fn seeds_are_apart_beyond_two_samples_in_column_or_row() {
        let seed = |row: u32, column: u32| (row << 16) | column;
        let s = seed(100, 200);
        for (dr, dc, want) in [
            (0, 0, false),
            (2, 0, false),
            (0, 2, false),
            (2, 2, false),
            (3, 0, true),
            (0, 3, true),
            (3, 3, true),
            (1, 5, true),
            (40, 1, true),
        ] {
            for (r, c) in [(100 + dr, 200 + dc), (100 - dr, 200 - dc), (100 + dr, 200 - dc)] {
                assert_eq!(apart(s, seed(r, c)), want, "{dr} rows, {dc} columns");
                assert_eq!(apart(seed(r, c), s), want, "{dr} rows, {dc} columns");
            }
        }
        // At the grid's corners, and against a missing seed.
        assert!(!apart(seed(0, 0), seed(2, 1)));
        assert!(apart(seed(0, 0), seed(0, (1 << 15) - 1)));
        assert!(apart(s, u32::MAX) && apart(u32::MAX, s));
        assert!(!apart(u32::MAX, u32::MAX));
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
