//! A distance field of one family on an `nx` by `ny` grid of samples: the exact distance
//! to the nearest boundary segment for samples within a cell of it, propagated to the
//! rest by the Felzenszwalb-Huttenlocher transform with the nearest seed tracked (so a
//! far sample's distance is measured to a seed's exact boundary point, within half a
//! cell of the exact distance), and the
//! interior found by scanning each row. The grid is padded so that its border samples
//! lie outside the family.

use lamina_core::geom::closest_on_segment;
use lamina_core::{BBox2, Contour, Point2};

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
        let cells = cells.max(4);
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
        let n = self.nx * self.ny;
        let mut near = vec![Point2::origin(); n];
        let mut seed_d2 = vec![f64::INFINITY; n];
        // Exact distances for the samples around each segment, found by walking it in
        // half-cell steps and visiting the 4 x 4 samples about each step.
        for c in contours {
            for (a, b) in c.edges() {
                let len = (b - a).norm();
                let steps = ((len / (0.5 * self.h)).ceil() as usize).max(1);
                for s in 0..=steps {
                    let p = a + (b - a) * (s as f64 / steps as f64);
                    let ci = ((p.x - self.origin.x) / self.h).floor() as isize;
                    let cj = ((p.y - self.origin.y) / self.h).floor() as isize;
                    for j in cj - 1..=cj + 2 {
                        for i in ci - 1..=ci + 2 {
                            if i < 0 || j < 0 || i as usize >= self.nx || j as usize >= self.ny {
                                continue;
                            }
                            let k = j as usize * self.nx + i as usize;
                            let q = self.point(i as usize, j as usize);
                            let on = closest_on_segment(q, a, b);
                            let d2 = (q - on).norm_squared();
                            if d2 < seed_d2[k] {
                                seed_d2[k] = d2;
                                near[k] = on;
                            }
                        }
                    }
                }
            }
        }
        // Seeds are the samples within a cell of the boundary: a thin band keeps the
        // nearest seed's boundary point close to the true nearest boundary point.
        let h2 = self.h * self.h;
        for d2 in &mut seed_d2 {
            if *d2 > h2 {
                *d2 = f64::INFINITY;
            }
        }
        let (nx, ny) = (self.nx, self.ny);
        // Column pass: squared distance in samples to the nearest seed of the column.
        let mut g = vec![f64::INFINITY; n];
        let mut from_row = vec![u32::MAX; n];
        let mut scratch = Envelope::new(nx.max(ny));
        let mut f = vec![0.0; ny];
        let mut out = vec![0.0; ny];
        let mut arg = vec![0u32; ny];
        for i in 0..nx {
            for j in 0..ny {
                f[j] = if seed_d2[j * nx + i].is_finite() {
                    0.0
                } else {
                    f64::INFINITY
                };
            }
            scratch.transform(&f, &mut out, &mut arg);
            for j in 0..ny {
                g[j * nx + i] = out[j];
                from_row[j * nx + i] = arg[j];
            }
        }
        // Row pass: over the column results; the argmin names the column, whose
        // column pass names the row of the nearest seed.
        let mut out = vec![0.0; nx];
        let mut arg = vec![0u32; nx];
        let mut seed_of = vec![u32::MAX; n];
        for j in 0..ny {
            let row = &g[j * nx..(j + 1) * nx];
            scratch.transform(row, &mut out, &mut arg);
            for i in 0..nx {
                if out[i].is_finite() {
                    let col = arg[i] as usize;
                    seed_of[j * nx + i] = (from_row[j * nx + col] as usize * nx + col) as u32;
                }
            }
        }
        // Each sample takes the nearest of the boundary points its own and its eight
        // neighbours' seeds found: near a medial axis the nearest seed in samples may
        // sit on the farther boundary.
        for j in 0..ny {
            for i in 0..nx {
                let k = j * nx + i;
                if seed_d2[k].is_finite() {
                    self.values[k] = seed_d2[k].sqrt();
                    continue;
                }
                let p = self.point(i, j);
                let own = seed_of[k];
                let mut best = if own == u32::MAX {
                    f64::INFINITY
                } else {
                    (p - near[own as usize]).norm_squared()
                };
                // Neighbours mostly share the sample's own seed: only others are measured.
                for nj in j.saturating_sub(1)..(j + 2).min(ny) {
                    for &s in &seed_of[nj * nx + i.saturating_sub(1)..nj * nx + (i + 2).min(nx)] {
                        if s != u32::MAX && s != own {
                            best = best.min((p - near[s as usize]).norm_squared());
                        }
                    }
                }
                self.values[k] = best.sqrt();
            }
        }
    }
}

/// The lower envelope of parabolas of the 1-D transform, with buffers kept across rows.
struct Envelope {
    v: Vec<usize>,
    z: Vec<f64>,
}

impl Envelope {
    fn new(n: usize) -> Self {
        Self {
            v: vec![0; n],
            z: vec![0.0; n + 1],
        }
    }

    /// `out[q] = min_p (q - p)^2 + f[p]` and `arg[q]` the minimising p (Felzenszwalb and
    /// Huttenlocher). Infinite f values are skipped; all infinite gives infinity.
    fn transform(&mut self, f: &[f64], out: &mut [f64], arg: &mut [u32]) {
        let n = f.len();
        let mut k: isize = -1;
        for q in 0..n {
            if !f[q].is_finite() {
                continue;
            }
            let fq = f[q] + (q * q) as f64;
            loop {
                if k < 0 {
                    k = 0;
                    self.v[0] = q;
                    self.z[0] = f64::NEG_INFINITY;
                    self.z[1] = f64::INFINITY;
                    break;
                }
                let p = self.v[k as usize];
                let s = (fq - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64));
                if s <= self.z[k as usize] {
                    k -= 1;
                    continue;
                }
                k += 1;
                self.v[k as usize] = q;
                self.z[k as usize] = s;
                self.z[k as usize + 1] = f64::INFINITY;
                break;
            }
        }
        if k < 0 {
            out.fill(f64::INFINITY);
            arg.fill(0);
            return;
        }
        let mut k = 0usize;
        for q in 0..n {
            while self.z[k + 1] < q as f64 {
                k += 1;
            }
            let p = self.v[k];
            let d = q as f64 - p as f64;
            out[q] = d * d + f[p];
            arg[q] = p as u32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{circle, rect};

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
    fn border_samples_are_outside() {
        let r = rect(0.0, 0.0, 3.0, 1.0);
        let f = Field::over(&r.bbox(), 64);
        let inside = f.inside(&[&r]);
        for i in 0..f.nx {
            assert!(!inside[i] && !inside[(f.ny - 1) * f.nx + i]);
        }
    }
}
