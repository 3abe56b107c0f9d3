//! Base cells of a periodic microstructure and the voids they leave in a layer
//! (cmpm-process-planning 4.3 and Fig. 5).
//!
//! A microstructure region is an array of base cells: one at each inserting point of a
//! lattice, each a void of some shape (a sphere, a box, a cylinder) with a size and an
//! orientation that may vary with position. A layer's voids are the sections of the
//! cells its plane cuts.
//!
//! The lattice may stand tilted against the layers (the spraying plane at an angle Φ
//! to the lattice's z axis, Fig. 5). Only the inserting points within `L_max` of the
//! plane are visited, where `L_max` bounds how far a cell reaches from its inserting
//! point: the lattice indices come from the box of the layer's area thickened by
//! `L_max` above and below, mapped into the lattice's frame, and each candidate is kept
//! when its distance to the plane is at most `L_max` (the paper's two auxiliary planes).

use nalgebra::{Matrix3, Vector3};

use crate::shape::{BBox2, Contour, Point2};

/// The shape of a base cell's void, in the cell's own frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BaseCellShape {
    /// Radius `half[0]`.
    Sphere,
    /// Half-edges `half[0..3]` along the cell's x, y and z.
    Box,
    /// Radius `half[0]` about the cell's z axis, half-height `half[2]`.
    Cylinder,
}

/// Sides of the prism a cylinder is cut as, and points of a sphere's section.
const ROUND: usize = 32;

/// One base cell placed in the machine's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedBaseCell {
    pub shape: BaseCellShape,
    pub centre: Vector3<f64>,
    pub half: [f64; 3],
    /// Cell frame to machine frame.
    pub rotation: Matrix3<f64>,
}

impl PlacedBaseCell {
    /// How far the cell reaches from its centre.
    pub fn reach(&self) -> f64 {
        match self.shape {
            BaseCellShape::Sphere => self.half[0],
            BaseCellShape::Box => Vector3::from(self.half).norm(),
            BaseCellShape::Cylinder => self.half[0].hypot(self.half[2]),
        }
    }

    /// The cell's surface as flat pieces: (area, outward unit normal) in the machine's
    /// frame; its main surfaces, for choosing a build direction. A sphere has none
    /// that matter: every direction weighs it the same, so it gives none.
    pub fn facets(&self) -> Vec<(f64, Vector3<f64>)> {
        let axis = |k: usize| self.rotation.column(k).into_owned();
        let [a, b, c] = self.half;
        match self.shape {
            BaseCellShape::Sphere => Vec::new(),
            BaseCellShape::Box => {
                let mut out = Vec::with_capacity(6);
                for (k, area) in [(0, 4.0 * b * c), (1, 4.0 * a * c), (2, 4.0 * a * b)] {
                    out.push((area, axis(k)));
                    out.push((area, -axis(k)));
                }
                out
            }
            BaseCellShape::Cylinder => {
                let (r, h) = (a, c);
                let mut out = vec![
                    (std::f64::consts::PI * r * r, axis(2)),
                    (std::f64::consts::PI * r * r, -axis(2)),
                ];
                let side = 2.0 * std::f64::consts::PI * r * 2.0 * h / ROUND as f64;
                for k in 0..ROUND {
                    let t = std::f64::consts::TAU * (k as f64 + 0.5) / ROUND as f64;
                    out.push((side, axis(0) * t.cos() + axis(1) * t.sin()));
                }
                out
            }
        }
    }

    /// The section of the cell by the horizontal plane at `z`, counter-clockwise, or
    /// `None` where the plane misses it.
    pub fn section(&self, z: f64) -> Option<Contour> {
        let dz = z - self.centre.z;
        if dz.abs() >= self.reach() {
            return None;
        }
        match self.shape {
            BaseCellShape::Sphere => {
                let r = (self.half[0] * self.half[0] - dz * dz).sqrt();
                Some(Contour::circle(
                    Point2::new(self.centre.x, self.centre.y),
                    r,
                    ROUND,
                ))
            }
            BaseCellShape::Box => {
                let [a, b, c] = self.half;
                let corners: Vec<Vector3<f64>> = (0..8)
                    .map(|i| {
                        Vector3::new(
                            if i & 1 == 0 { -a } else { a },
                            if i & 2 == 0 { -b } else { b },
                            if i & 4 == 0 { -c } else { c },
                        )
                    })
                    .collect();
                let mut edges = Vec::new();
                for i in 0..8usize {
                    for bit in [1, 2, 4] {
                        if i & bit == 0 {
                            edges.push((i, i | bit));
                        }
                    }
                }
                self.cut(&corners, &edges, z)
            }
            BaseCellShape::Cylinder => {
                let (r, h) = (self.half[0], self.half[2]);
                let mut corners = Vec::with_capacity(2 * ROUND);
                for k in 0..ROUND {
                    let a = std::f64::consts::TAU * k as f64 / ROUND as f64;
                    corners.push(Vector3::new(r * a.cos(), r * a.sin(), -h));
                    corners.push(Vector3::new(r * a.cos(), r * a.sin(), h));
                }
                let mut edges = Vec::new();
                for k in 0..ROUND {
                    let next = (k + 1) % ROUND;
                    edges.push((2 * k, 2 * k + 1));
                    edges.push((2 * k, 2 * next));
                    edges.push((2 * k + 1, 2 * next + 1));
                }
                self.cut(&corners, &edges, z)
            }
        }
    }

    /// The section of the convex polyhedron with `corners` (cell frame) and `edges` by
    /// the plane at `z`: where the edges cross it, in angular order.
    fn cut(&self, corners: &[Vector3<f64>], edges: &[(usize, usize)], z: f64) -> Option<Contour> {
        let placed: Vec<Vector3<f64>> = corners.iter().map(|c| self.centre + self.rotation * c).collect();
        let mut pts: Vec<Point2> = Vec::new();
        for &(i, j) in edges {
            let (p, q) = (placed[i], placed[j]);
            let (dp, dq) = (p.z - z, q.z - z);
            if (dp < 0.0) != (dq < 0.0) {
                let t = dp / (dp - dq);
                let x = p + (q - p) * t;
                pts.push(Point2::new(x.x, x.y));
            }
        }
        if pts.len() < 3 {
            return None;
        }
        let n = pts.len() as f64;
        let c = pts.iter().fold(Point2::new(0.0, 0.0), |s, p| {
            Point2::new(s.x + p.x / n, s.y + p.y / n)
        });
        pts.sort_by(|a, b| {
            (a.y - c.y)
                .atan2(a.x - c.x)
                .total_cmp(&(b.y - c.y).atan2(b.x - c.x))
        });
        pts.dedup_by(|a, b| (*a - *b).norm() < 1e-12);
        let contour = Contour::new(pts);
        (contour.len() >= 3 && contour.area() > 1e-12).then_some(contour)
    }
}

/// The convex polygon `c` moved in by `d` (every edge `d` further in, corners kept
/// sharp, as an inward offset of a convex shape is), or `None` once nothing is left:
/// `c` clipped by each of its edges' half-planes shifted by `d`.
pub fn inset_convex(c: &Contour, d: f64) -> Option<Contour> {
    let ring = c.clone().oriented(true);
    let n = ring.len();
    if n < 3 {
        return None;
    }
    let mut poly: Vec<Point2> = ring.points.clone();
    for i in 0..n {
        let (a, b) = (ring.points[i], ring.points[(i + 1) % n]);
        let e = b - a;
        let len = e.norm();
        if len < 1e-15 {
            continue;
        }
        // Inward normal of a counter-clockwise edge, and the shifted line's offset.
        let nrm = crate::shape::Vector2::new(-e.y / len, e.x / len);
        let keep = |p: &Point2| (p - a).dot(&nrm) - d;
        let mut next = Vec::with_capacity(poly.len() + 1);
        for k in 0..poly.len() {
            let (p, q) = (poly[k], poly[(k + 1) % poly.len()]);
            let (sp, sq) = (keep(&p), keep(&q));
            if sp >= 0.0 {
                next.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                next.push(p + (q - p) * (sp / (sp - sq)));
            }
        }
        poly = next;
        if poly.len() < 3 {
            return None;
        }
    }
    let out = Contour::new(poly);
    (out.area() > 1e-12).then_some(out)
}

/// The lattice of inserting points: `origin + i a + j b + k c` in the lattice's frame,
/// turned into the machine's frame by `rotation` (the tilt of Fig. 5, and the model's
/// own turn) and moved by `offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaseCellArray {
    pub period: [f64; 3],
    pub origin: [f64; 3],
    /// Lattice frame to machine frame.
    pub rotation: Matrix3<f64>,
    /// Added after the rotation (machine frame).
    pub offset: Vector3<f64>,
}

impl BaseCellArray {
    /// An upright lattice.
    pub fn upright(period: [f64; 3], origin: [f64; 3]) -> Self {
        Self {
            period,
            origin,
            rotation: Matrix3::identity(),
            offset: Vector3::zeros(),
        }
    }

    /// A lattice tilted by `phi` radians about the machine's x axis: its z axis leans
    /// from the machine's z toward -y.
    pub fn tilted_about_x(period: [f64; 3], origin: [f64; 3], phi: f64) -> Self {
        Self {
            period,
            origin,
            rotation: *nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), phi).matrix(),
            offset: Vector3::zeros(),
        }
    }

    /// The same lattice moved as a whole: turned by `rotation`, then moved by `offset`
    /// (a model's own frame carried into the build's).
    pub fn moved(&self, rotation: &Matrix3<f64>, offset: Vector3<f64>) -> Self {
        Self {
            period: self.period,
            origin: self.origin,
            rotation: rotation * self.rotation,
            offset: rotation * self.offset + offset,
        }
    }

    /// The inserting point of lattice indices `(i, j, k)` in the machine's frame.
    pub fn point(&self, i: i64, j: i64, k: i64) -> Vector3<f64> {
        let l = Vector3::new(
            self.origin[0] + i as f64 * self.period[0],
            self.origin[1] + j as f64 * self.period[1],
            self.origin[2] + k as f64 * self.period[2],
        );
        self.rotation * l + self.offset
    }

    /// The lattice indices whose points may lie in the box `lo..hi` (machine frame):
    /// the box's corners mapped into the lattice's frame. Empty where a bound is not
    /// finite.
    fn index_ranges(&self, lo: Vector3<f64>, hi: Vector3<f64>) -> [(i64, i64); 3] {
        let inverse = self.rotation.transpose();
        let mut l0 = [f64::INFINITY; 3];
        let mut l1 = [f64::NEG_INFINITY; 3];
        for corner in 0..8 {
            let p = Vector3::new(
                if corner & 1 == 0 { lo.x } else { hi.x },
                if corner & 2 == 0 { lo.y } else { hi.y },
                if corner & 4 == 0 { lo.z } else { hi.z },
            );
            let l = inverse * (p - self.offset);
            for a in 0..3 {
                let t = (l[a] - self.origin[a]) / self.period[a];
                l0[a] = l0[a].min(t);
                l1[a] = l1[a].max(t);
            }
        }
        let mut out = [(0, -1); 3];
        for a in 0..3 {
            if l0[a].is_finite() && l1[a].is_finite() && l0[a].abs() < 1e15 && l1[a].abs() < 1e15 {
                out[a] = (l0[a].ceil() as i64, l1[a].floor() as i64);
            } else {
                return [(0, -1); 3];
            }
        }
        out
    }

    /// How many lattice indices [`Self::in_box`] visits for the box `lo..hi`: what a
    /// caller checks against its limits first.
    pub fn count_in_box(&self, lo: Vector3<f64>, hi: Vector3<f64>) -> f64 {
        self.index_ranges(lo, hi)
            .iter()
            .map(|&(a, b)| (b - a + 1).max(0) as f64)
            .product()
    }

    /// Calls `f` with every inserting point inside the box `lo..hi` (machine frame)
    /// and its lattice indices, in a fixed order; `f` returns false to stop.
    pub fn in_box(
        &self,
        lo: Vector3<f64>,
        hi: Vector3<f64>,
        mut f: impl FnMut([i64; 3], Vector3<f64>) -> bool,
    ) {
        let [(i0, i1), (j0, j1), (k0, k1)] = self.index_ranges(lo, hi);
        for k in k0..=k1 {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let p = self.point(i, j, k);
                    if (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]) && !f([i, j, k], p) {
                        return;
                    }
                }
            }
        }
    }

    /// The box of the search band around the horizontal plane at `z` over `bbox`.
    fn band(z: f64, reach: f64, bbox: &BBox2) -> (Vector3<f64>, Vector3<f64>) {
        (
            Vector3::new(bbox.min.x - reach, bbox.min.y - reach, z - reach),
            Vector3::new(bbox.max.x + reach, bbox.max.y + reach, z + reach),
        )
    }

    /// The lattice axis that climbs most steeply through a horizontal plane, and the
    /// other two: the band is walked over the other two and solved along it.
    fn axes(&self) -> (usize, usize, usize) {
        let r = self.rotation.row(2);
        let s = (0..3)
            .max_by(|&a, &b| r[a].abs().total_cmp(&r[b].abs()))
            .unwrap_or(2);
        let others: Vec<usize> = (0..3).filter(|&a| a != s).collect();
        (s, others[0], others[1])
    }

    /// How many lattice indices [`Self::near_plane`] visits.
    pub fn count_near_plane(&self, z: f64, reach: f64, bbox: &BBox2) -> f64 {
        let (lo, hi) = Self::band(z, reach, bbox);
        let ranges = self.index_ranges(lo, hi);
        let (s, u, v) = self.axes();
        // Each column crosses the band in at most this many steps along `s` (whose
        // climb is at least 1/sqrt(3) of a step: the largest part of a unit vector).
        let rows = (2.0 * reach / (self.period[s] * self.rotation[(2, s)].abs())).ceil() + 1.0;
        let n = |a: usize| (ranges[a].1 - ranges[a].0 + 1).max(0) as f64;
        n(u) * n(v) * rows
    }

    /// The inserting points within `reach` of the horizontal plane at `z`, over the
    /// XY box `bbox` grown by `reach`: the search band of Fig. 5. The steps along the
    /// steepest lattice axis are solved from the plane's equation for each column of
    /// the other two, so a tilted lattice visits only the points near the plane (the
    /// two auxiliary planes), not the box around them. Each comes with its lattice
    /// indices, in a fixed order.
    pub fn near_plane(&self, z: f64, reach: f64, bbox: &BBox2) -> Vec<([i64; 3], Vector3<f64>)> {
        let (lo, hi) = Self::band(z, reach, bbox);
        let ranges = self.index_ranges(lo, hi);
        let (s, u, v) = self.axes();
        let r = self.rotation.row(2);
        let step = r[s] * self.period[s];
        let mut out = Vec::new();
        if step.abs() < 1e-12 {
            return out;
        }
        for iu in ranges[u].0..=ranges[u].1 {
            for iv in ranges[v].0..=ranges[v].1 {
                let base = r[u] * (self.origin[u] + iu as f64 * self.period[u])
                    + r[v] * (self.origin[v] + iv as f64 * self.period[v])
                    + r[s] * self.origin[s]
                    + self.offset.z;
                let (a, b) = ((z - reach - base) / step, (z + reach - base) / step);
                let (k0, k1) = (a.min(b), a.max(b));
                if !(k0.is_finite() && k1.is_finite() && k0.abs() < 1e15 && k1.abs() < 1e15) {
                    continue;
                }
                for ks in (k0.ceil() as i64)..=(k1.floor() as i64) {
                    let mut ijk = [0i64; 3];
                    (ijk[s], ijk[u], ijk[v]) = (ks, iu, iv);
                    let p = self.point(ijk[0], ijk[1], ijk[2]);
                    if (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]) {
                        out.push((ijk, p));
                    }
                }
            }
        }
        // In the lattice's order, rows first, as a box walk gives them.
        out.sort_by_key(|(ijk, _)| (ijk[2], ijk[1], ijk[0]));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placed(shape: BaseCellShape, half: [f64; 3], rotation: Matrix3<f64>) -> PlacedBaseCell {
        PlacedBaseCell {
            shape,
            centre: Vector3::new(1.0, 2.0, 3.0),
            half,
            rotation,
        }
    }

    #[test]
    fn a_sphere_cuts_a_circle_of_the_chord_radius() {
        let s = placed(BaseCellShape::Sphere, [0.5, 0.0, 0.0], Matrix3::identity());
        let c = s.section(3.3).expect("cut");
        let r = (0.25f64 - 0.09).sqrt();
        assert!((c.area() - std::f64::consts::PI * r * r).abs() < 0.01 * c.area());
        assert!(s.section(3.5).is_none());
    }

    #[test]
    fn a_box_turned_about_x_cuts_a_rectangle_as_wide_as_its_slant() {
        // Half-edges 0.4 x 0.2 x 0.1, turned 30 degrees about x: the plane through its
        // centre meets a rectangle 0.8 long in x and 2 * 0.1 / sin 30 = 0.4 wide in y
        // (where the thin z half-edge limits it), or 2 * 0.2 / cos 30 where y does.
        let rot = *nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), 30f64.to_radians()).matrix();
        let b = placed(BaseCellShape::Box, [0.4, 0.2, 0.1], rot);
        let c = b.section(3.0).expect("cut");
        let width = (2.0f64 * 0.1 / 30f64.to_radians().sin()).min(2.0 * 0.2 / 30f64.to_radians().cos());
        assert!(
            (c.area() - 0.8 * width).abs() < 1e-9,
            "{} vs {}",
            c.area(),
            0.8 * width
        );
        assert!(c.is_ccw());
        // Upright, a plane above its top misses it.
        let up = placed(BaseCellShape::Box, [0.4, 0.2, 0.1], Matrix3::identity());
        assert!(up.section(3.11).is_none());
        assert!((up.section(3.05).expect("cut").area() - 0.8 * 0.4).abs() < 1e-9);
    }

    #[test]
    fn a_cylinder_lying_on_its_side_cuts_a_rectangle() {
        // Radius 0.2, half-height 0.5, its axis along x: a plane 0.1 above the axis
        // cuts a rectangle 1.0 long and 2 sqrt(0.2^2 - 0.1^2) wide (the prism's chord).
        let rot = *nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), 90f64.to_radians()).matrix();
        let c = placed(BaseCellShape::Cylinder, [0.2, 0.2, 0.5], rot)
            .section(3.1)
            .expect("cut");
        let want = 1.0 * 2.0 * (0.04f64 - 0.01).sqrt();
        assert!((c.area() - want).abs() < 0.02 * want, "{} vs {want}", c.area());
    }

    #[test]
    fn a_boxs_facets_are_its_six_faces_turned_with_it() {
        let rot = *nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), 90f64.to_radians()).matrix();
        let f = placed(BaseCellShape::Box, [0.3, 0.1, 0.02], rot).facets();
        assert_eq!(f.len(), 6);
        let total: f64 = f.iter().map(|x| x.0).sum();
        assert!((total - 8.0 * (0.1 * 0.02 + 0.3 * 0.02 + 0.3 * 0.1)).abs() < 1e-12);
        // The largest faces (normal the cell's z) now face along -y and +y.
        let big = f.iter().max_by(|a, b| a.0.total_cmp(&b.0)).expect("faces");
        assert!((big.1.y.abs() - 1.0).abs() < 1e-12, "{:?}", big.1);
    }

    #[test]
    fn an_inset_convex_polygon_moves_every_edge_in() {
        let sq = Contour::rectangle(Point2::new(0.0, 0.0), Point2::new(4.0, 2.0));
        let i = inset_convex(&sq, 0.5).expect("left");
        assert!((i.area() - 3.0 * 1.0).abs() < 1e-12, "{}", i.area());
        assert!(inset_convex(&sq, 1.0).is_none());
        let circle = Contour::circle(Point2::new(0.0, 0.0), 1.0, 64);
        let r = inset_convex(&circle, 0.25).expect("left");
        // A regular polygon moves in by its apothem: the same shape, scaled.
        let apothem = (std::f64::consts::PI / 64.0).cos();
        let want = circle.area() * ((apothem - 0.25) / apothem).powi(2);
        assert!((r.area() - want).abs() < 1e-9, "{} vs {want}", r.area());
    }

    /// Every point of `lattice` with indices in `-n..n` along each axis that `keep`
    /// accepts, in the order k, j, i (the band's order): the brute-force scan the
    /// walks are checked against.
    fn points_where(lattice: &BaseCellArray, n: i64, keep: impl Fn(Vector3<f64>) -> bool) -> Vec<[i64; 3]> {
        let mut out = Vec::new();
        for k in -n..n {
            for j in -n..n {
                for i in -n..n {
                    if keep(lattice.point(i, j, k)) {
                        out.push([i, j, k]);
                    }
                }
            }
        }
        out
    }

    #[test]
    fn the_band_visits_only_points_near_the_plane_even_when_tilted() {
        let bbox = BBox2::from_points([Point2::new(0.0, 0.0), Point2::new(4.0, 4.0)]);
        let up = BaseCellArray::upright([1.0, 1.0, 1.0], [0.0; 3]);
        let near = up.near_plane(2.2, 0.3, &bbox);
        // Only the row k = 2, over the 5 x 5 points of the box (grown by 0.3: still 5 x 5).
        assert_eq!(near.len(), 25);
        assert!(near.iter().all(|(ijk, _)| ijk[2] == 2));
        let tilted = BaseCellArray::tilted_about_x([1.0, 1.0, 1.0], [0.0; 3], 20f64.to_radians());
        let near = tilted.near_plane(2.2, 0.3, &bbox);
        assert!(!near.is_empty());
        // Every point within the band, and none of the lattice's points near the plane
        // missed: a brute-force scan agrees.
        let in_band = |p: Vector3<f64>| {
            (p.z - 2.2).abs() <= 0.3 && p.x >= -0.3 && p.x <= 4.3 && p.y >= -0.3 && p.y <= 4.3
        };
        let mut brute = points_where(&tilted, 20, in_band);
        let mut got: Vec<[i64; 3]> = near.iter().map(|(ijk, _)| *ijk).collect();
        got.sort();
        brute.sort();
        assert_eq!(got, brute);
        // A lattice turned a right angle about x (its y axis now climbs) is walked
        // along y: the same points as a brute-force scan.
        let turned = BaseCellArray::tilted_about_x([1.0, 1.0, 1.0], [0.0; 3], 90f64.to_radians());
        let mut near: Vec<[i64; 3]> = turned
            .near_plane(2.2, 0.3, &bbox)
            .iter()
            .map(|(ijk, _)| *ijk)
            .collect();
        near.sort();
        let mut brute = points_where(&turned, 20, in_band);
        brute.sort();
        assert!(!near.is_empty());
        assert_eq!(near, brute);
        // The rows visited lean with the tilt: several k for one plane.
        let ks: std::collections::BTreeSet<i64> = got.iter().map(|ijk| ijk[2]).collect();
        assert!(ks.len() > 1, "{ks:?}");
    }

    /// A rotation from three angles (about z, then y, then x).
    fn turn(a: f64, b: f64, c: f64) -> Matrix3<f64> {
        *nalgebra::Rotation3::from_euler_angles(c, b, a).matrix()
    }

    /// Whether `p` (machine frame) is inside the solid the cell's sections are cut
    /// from: the box, the cylinder's prism of `ROUND` sides, or the sphere.
    fn solid_holds(cell: &PlacedBaseCell, p: Vector3<f64>) -> bool {
        let q = cell.rotation.transpose() * (p - cell.centre);
        let [a, b, c] = cell.half;
        match cell.shape {
            BaseCellShape::Sphere => q.norm() <= a,
            BaseCellShape::Box => q.x.abs() <= a && q.y.abs() <= b && q.z.abs() <= c,
            BaseCellShape::Cylinder => {
                let prism = Contour::circle(Point2::new(0.0, 0.0), a, ROUND);
                q.z.abs() <= c && prism.contains(Point2::new(q.x, q.y))
            }
        }
    }

    #[test]
    fn sections_of_turned_cells_hold_what_the_solid_holds() {
        // Boxes and cylinders at random turns, cut at several heights: a point of the
        // plane is inside the section exactly when it is inside the solid (the sphere's
        // section is a polygon of its circle, so it is checked off its edge only).
        let mut rng = fastrand::Rng::with_seed(0x2545_f491_4f6c_dd1d);
        let mut random = move || rng.f64();
        let mut cut = 0;
        for case in 0..60 {
            let shape = [BaseCellShape::Box, BaseCellShape::Cylinder, BaseCellShape::Sphere][case % 3];
            let rotation = turn(random() * 6.3, random() * 6.3, random() * 6.3);
            let cell = PlacedBaseCell {
                shape,
                centre: Vector3::new(random() * 10.0 - 5.0, random() * 10.0 - 5.0, random() * 4.0),
                half: [0.3 + random(), 0.3 + random(), 0.3 + random()],
                rotation,
            };
            let reach = cell.reach();
            for dz in [-0.9, -0.5, -0.1, 0.0, 0.3, 0.7, 0.95] {
                let z = cell.centre.z + dz * reach;
                let section = cell.section(z);
                let mut inside = 0;
                for j in 0..40 {
                    for i in 0..40 {
                        let p = Vector3::new(
                            cell.centre.x + (f64::from(i) / 39.5 - 0.5) * 2.0 * reach,
                            cell.centre.y + (f64::from(j) / 39.5 - 0.5) * 2.0 * reach,
                            z,
                        );
                        let holds = solid_holds(&cell, p);
                        let flat = Point2::new(p.x, p.y);
                        let got = section.as_ref().is_some_and(|c| c.contains(flat));
                        let edge = section.as_ref().map_or(f64::INFINITY, |c| c.distance(flat));
                        let margin = if shape == BaseCellShape::Sphere {
                            0.02 * reach
                        } else {
                            1e-9
                        };
                        if edge > margin
                            && (shape != BaseCellShape::Sphere || {
                                let q = p - cell.centre;
                                (q.norm() - cell.half[0]).abs() > margin
                            })
                        {
                            assert_eq!(got, holds, "case {case} {shape:?} at {p:?}");
                        }
                        inside += usize::from(got);
                    }
                }
                if let Some(c) = &section {
                    assert!(c.is_ccw(), "case {case}");
                    cut += usize::from(inside > 0);
                }
            }
            // Beyond its reach the plane misses it.
            assert!(cell.section(cell.centre.z + 1.001 * reach).is_none());
            assert!(cell.section(cell.centre.z - 1.001 * reach).is_none());
        }
        assert!(cut > 200, "{cut}");
    }

    #[test]
    fn a_cells_reach_and_a_cylinders_facets() {
        let up = |shape, half| PlacedBaseCell {
            shape,
            centre: Vector3::zeros(),
            half,
            rotation: Matrix3::identity(),
        };
        assert_eq!(up(BaseCellShape::Sphere, [0.5, 9.0, 9.0]).reach(), 0.5);
        assert_eq!(up(BaseCellShape::Box, [2.0, 3.0, 6.0]).reach(), 7.0);
        assert_eq!(up(BaseCellShape::Cylinder, [3.0, 9.0, 4.0]).reach(), 5.0);
        assert!(up(BaseCellShape::Sphere, [0.5, 0.5, 0.5]).facets().is_empty());
        // A cylinder of radius 1.5 and height 4: two caps along +-z, and the side in
        // ROUND strips facing out through their middles, the prism's side area.
        let f = up(BaseCellShape::Cylinder, [1.5, 1.0, 2.0]).facets();
        assert_eq!(f.len(), 2 + ROUND);
        assert_eq!((f[0].1, f[1].1), (Vector3::z(), -Vector3::z()));
        assert!((f[0].0 - std::f64::consts::PI * 2.25).abs() < 1e-12);
        let side: f64 = f[2..].iter().map(|x| x.0).sum();
        assert!(
            (side - 2.0 * std::f64::consts::PI * 1.5 * 4.0).abs() < 1e-9,
            "{side}"
        );
        for (k, (_, n)) in f[2..].iter().enumerate() {
            let t = std::f64::consts::TAU * (k as f64 + 0.5) / ROUND as f64;
            assert!(
                (n - Vector3::new(t.cos(), t.sin(), 0.0)).norm() < 1e-12,
                "strip {k}: {n:?}"
            );
        }
        // A box's faces come in opposite pairs along its axes, each pair as large as
        // the other two half-edges make.
        let f = up(BaseCellShape::Box, [1.0, 2.0, 3.0]).facets();
        let want = [
            (24.0, Vector3::x()),
            (24.0, -Vector3::x()),
            (12.0, Vector3::y()),
            (12.0, -Vector3::y()),
            (8.0, Vector3::z()),
            (8.0, -Vector3::z()),
        ];
        assert_eq!(f, want);
    }

    #[test]
    fn a_moved_lattice_visits_every_point_of_a_box_once() {
        // A tilted lattice turned again and moved: the points visited are exactly the
        // lattice points inside the box, each once, no more than counted; the points
        // near a plane are those of the box walk within the band.
        let lattice = BaseCellArray::tilted_about_x([0.7, 1.1, 0.9], [0.2, -0.3, 0.1], 0.4)
            .moved(&turn(0.7, 0.0, 0.0), Vector3::new(5.0, -2.0, 1.5));
        let (lo, hi) = (Vector3::new(1.0, -6.0, 0.0), Vector3::new(9.0, 2.0, 3.0));
        let mut visited = Vec::new();
        lattice.in_box(lo, hi, |ijk, p| {
            assert!((lattice.point(ijk[0], ijk[1], ijk[2]) - p).norm() < 1e-12);
            visited.push(ijk);
            true
        });
        let mut brute = points_where(&lattice, 30, |p| (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]));
        let count = visited.len();
        visited.sort();
        visited.dedup();
        brute.sort();
        assert_eq!(visited.len(), count);
        assert!(!brute.is_empty());
        assert_eq!(visited, brute);
        assert!(lattice.count_in_box(lo, hi) >= count as f64);
        // Stopping early stops.
        let mut seen = 0;
        lattice.in_box(lo, hi, |_, _| {
            seen += 1;
            seen < 3
        });
        assert_eq!(seen, 3);
        // The band about z = 1.4, over the box's x-y.
        let bbox = BBox2::from_points([Point2::new(2.0, -5.0), Point2::new(8.0, 1.0)]);
        let near: Vec<[i64; 3]> = lattice
            .near_plane(1.4, 0.5, &bbox)
            .into_iter()
            .map(|(ijk, _)| ijk)
            .collect();
        let want = points_where(&lattice, 30, |p| {
            (p.z - 1.4).abs() <= 0.5 && p.x >= 1.5 && p.x <= 8.5 && p.y >= -5.5 && p.y <= 1.5
        });
        assert!(!want.is_empty());
        assert_eq!(near, want);
        assert!(lattice.count_near_plane(1.4, 0.5, &bbox) >= near.len() as f64);
        // An unbounded box visits nothing.
        assert_eq!(
            lattice.count_in_box(lo, Vector3::new(f64::INFINITY, 2.0, 3.0)),
            0.0
        );
    }

    #[test]
    fn lattice_points_and_index_ranges_by_hand() {
        // Upright: origin plus indices times periods; the ranges of an axis-aligned box
        // are exact, so the count is what the walk visits.
        let up = BaseCellArray::upright([0.5, 2.0, 0.25], [0.1, -1.0, 0.0]);
        assert_eq!(up.point(2, 3, -4), Vector3::new(1.1, 5.0, -1.0));
        let (lo, hi) = (Vector3::new(0.0, -1.0, 0.0), Vector3::new(2.0, 4.0, 1.0));
        let mut visited = 0;
        up.in_box(lo, hi, |_, _| {
            visited += 1;
            true
        });
        // x: 0.1 .. 1.6 (4), y: -1, 1, 3 (3), z: 0 .. 1 (5).
        assert_eq!(visited, 4 * 3 * 5);
        assert_eq!(up.count_in_box(lo, hi), 60.0);
        // No bound that is not a finite number of a sane size gives any range.
        for bad in [f64::INFINITY, f64::NAN, 1e20] {
            assert_eq!(up.count_in_box(lo, Vector3::new(bad, 4.0, 1.0)), 0.0, "{bad}");
            assert_eq!(up.count_in_box(Vector3::new(0.0, -bad, 0.0), hi), 0.0, "{bad}");
        }
        // The band about z = 0.4, 0.3 thick each way, over x 0..2 and y -1..4: 5 x 3
        // columns (the box grown by the band), each crossed in at most
        // ceil(0.6 / 0.25) + 1 = 4 rows; 2 of them (z = 0.25 and 0.5) are in it.
        let bbox = BBox2::from_points([Point2::new(0.0, -1.0), Point2::new(2.0, 4.0)]);
        assert_eq!(up.count_near_plane(0.4, 0.3, &bbox), 60.0);
        assert_eq!(up.near_plane(0.4, 0.3, &bbox).len(), 30);
        // A lattice turned about all three axes (every lattice axis climbs): the band
        // holds exactly the points a scan of every point finds.
        let turned = BaseCellArray::upright([0.6, 0.9, 0.8], [0.1, 0.2, -0.3])
            .moved(&turn(0.7, 0.5, 0.3), Vector3::new(1.0, 2.0, 0.4));
        let (z, reach) = (1.3, 0.35);
        let got: Vec<[i64; 3]> = turned
            .near_plane(z, reach, &bbox)
            .into_iter()
            .map(|(ijk, _)| ijk)
            .collect();
        let want = points_where(&turned, 20, |p| {
            (p.z - z).abs() <= reach
                && p.x >= -reach
                && p.x <= 2.0 + reach
                && p.y >= -1.0 - reach
                && p.y <= 4.0 + reach
        });
        assert!(want.len() > 10, "{}", want.len());
        assert_eq!(got, want);
        assert!(turned.count_near_plane(z, reach, &bbox) >= got.len() as f64);
        // Moving a lattice turns and shifts each of its points.
        let tilted = BaseCellArray::tilted_about_x([0.7, 1.1, 0.9], [0.2, -0.3, 0.1], 0.4);
        let (r, o) = (turn(0.7, 0.2, 0.0), Vector3::new(5.0, -2.0, 1.5));
        let once = tilted.moved(&r, o);
        let twice = once.moved(&r, o);
        for (i, j, k) in [(0, 0, 0), (2, -1, 3), (-4, 5, 1)] {
            let p = tilted.point(i, j, k);
            assert!((once.point(i, j, k) - (r * p + o)).norm() < 1e-12);
            assert!((twice.point(i, j, k) - (r * (r * p + o) + o)).norm() < 1e-12);
        }
    }

    #[test]
    fn a_triangle_insets_to_a_smaller_triangle() {
        // The 3-4-5 triangle has inradius 1: moved in by 0.5 it is the same triangle
        // halved about its incentre (a quarter of the area); by 1 nothing is left.
        let t = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(4.0, 0.0),
            Point2::new(0.0, 3.0),
        ]);
        let i = inset_convex(&t, 0.5).expect("left");
        assert_eq!(i.len(), 3);
        assert!((i.area() - 6.0 / 4.0).abs() < 1e-12, "{}", i.area());
        assert!(inset_convex(&t, 1.0 + 1e-9).is_none());
        assert!(inset_convex(&t.clone().oriented(false), 0.5).is_some());
    }
}
