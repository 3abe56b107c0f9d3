//! A turbine-blade-like model, the example of the topological-hierarchy paper (a blade
//! graded from ceramic skin to metal core, with cooling cavities): a NACA 4-digit
//! airfoil twisted linearly along its span, standing on a rectangular root block, with
//! zero, one or two cooling cavities.
//!
//! The cavities are offset sub-profiles of the airfoil that run straight up from the bed
//! through the root and the airfoil and open at the tip, like cooling passages fed
//! through the root. Every horizontal layer is therefore one solid area with `cavities`
//! holes, and the mesh stays a single closed surface (of genus `cavities`).
//!
//! Every section is the base section rotated about the twist axis, so the skin and rib
//! thicknesses are the same at every section. Between two sections the walls are ruled
//! bands; since the twist is linear and the sections evenly spaced, all bands are
//! congruent, and checking one band at a few heights checks them all.

use std::f64::consts::PI;

use lamina_api::{Contour, Mesh, Point2, Point3};

/// A NACA 4-digit section on a unit chord: maximum camber `m` at `p` of the chord and
/// maximum thickness `t`, all fractions of the chord.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Naca {
    pub m: f64,
    pub p: f64,
    pub t: f64,
}

impl Naca {
    /// Reads a designation such as `"2412"` (m = 0.02, p = 0.4, t = 0.12).
    pub fn from_code(code: &str) -> Option<Naca> {
        let d: Vec<u32> = code
            .trim()
            .chars()
            .map(|c| c.to_digit(10))
            .collect::<Option<_>>()?;
        if d.len() != 4 {
            return None;
        }
        Some(Naca {
            m: f64::from(d[0]) / 100.0,
            p: f64::from(d[1]) / 10.0,
            t: f64::from(d[2] * 10 + d[3]) / 100.0,
        })
    }

    /// Which parameter is out of range, if any. Cambers above 10 % or thicknesses above
    /// 40 % are not 4-digit sections any more; a camber needs its position strictly
    /// inside the chord.
    pub fn check(&self) -> Result<(), Invalid> {
        if !(self.t > 0.0 && self.t <= 0.4) {
            return Err(Invalid::new(
                "thickness",
                "must lie in (0, 0.4] (a fraction of the chord)",
            ));
        }
        if !(0.0..0.1).contains(&self.m) {
            return Err(Invalid::new(
                "max_camber",
                "must lie in [0, 0.1) (a fraction of the chord)",
            ));
        }
        if self.m > 0.0 && !(self.p >= 0.05 && self.p <= 0.95) {
            return Err(Invalid::new(
                "camber_position",
                "must lie in [0.05, 0.95] when the section is cambered",
            ));
        }
        Ok(())
    }

    /// Half-thickness at chord position `x`: the standard 4-digit polynomial, which
    /// leaves a blunt trailing edge of about 1 % of `t`. The outline closes it with a
    /// straight edge, which slices more robustly than a knife edge of zero angle.
    pub fn half_thickness(&self, x: f64) -> f64 {
        let x = x.clamp(0.0, 1.0);
        5.0 * self.t
            * (0.2969 * x.sqrt() - 0.1260 * x - 0.3516 * x * x + 0.2843 * x.powi(3) - 0.1015 * x.powi(4))
    }

    /// Mean line height and slope at `x`.
    pub fn camber(&self, x: f64) -> (f64, f64) {
        let (m, p) = (self.m, self.p);
        if m == 0.0 {
            (0.0, 0.0)
        } else if x < p {
            (m / (p * p) * (2.0 * p * x - x * x), 2.0 * m / (p * p) * (p - x))
        } else {
            let q = (1.0 - p) * (1.0 - p);
            (
                m / q * (1.0 - 2.0 * p + 2.0 * p * x - x * x),
                2.0 * m / q * (p - x),
            )
        }
    }

    /// The point at chord position `x`, `h` (chord fractions, signed; positive towards
    /// the upper surface) from the mean line along its normal. Surfaces and cavities are
    /// both made this way, so a cavity with |h| below the half-thickness lies inside.
    pub fn offset_point(&self, x: f64, h: f64) -> Point2 {
        let (yc, slope) = self.camber(x);
        let theta = slope.atan();
        Point2::new(x - h * theta.sin(), yc + h * theta.cos())
    }

    /// The outline on a unit chord with the leading edge at the origin, `points` per
    /// surface with cosine spacing (dense at both edges, where the curvature is):
    /// upper surface from the trailing edge to the leading edge, lower surface back,
    /// closed by the trailing edge segment. Counter-clockwise, `2 points - 1` vertices.
    pub fn outline(&self, points: usize) -> Vec<Point2> {
        let xs = cosine_spacing(points.max(3));
        let mut pts = Vec::with_capacity(2 * xs.len() - 1);
        pts.extend(
            xs.iter()
                .rev()
                .map(|&x| self.offset_point(x, self.half_thickness(x))),
        );
        pts.extend(
            xs[1..]
                .iter()
                .map(|&x| self.offset_point(x, -self.half_thickness(x))),
        );
        pts
    }
}

/// `n` positions in [0, 1], dense near both ends.
fn cosine_spacing(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 0.5 * (1.0 - (PI * i as f64 / (n - 1) as f64).cos()))
        .collect()
}

/// A bad parameter: which option, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Invalid {
    pub option: &'static str,
    pub message: String,
}

impl Invalid {
    fn new(option: &'static str, message: impl Into<String>) -> Self {
        Self {
            option,
            message: message.into(),
        }
    }
}

impl std::fmt::Display for Invalid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.option, self.message)
    }
}

impl std::error::Error for Invalid {}

/// The parameters of a blade; lengths in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct Blade {
    pub profile: Naca,
    pub chord: f64,
    /// Height of the airfoil above the root block.
    pub span: f64,
    /// Rotation of the tip section against the base section (degrees, counter-clockwise
    /// seen from above), about the quarter-chord line.
    pub twist: f64,
    /// Sections along the span, both ends included.
    pub sections: usize,
    /// Vertices per airfoil surface (upper and lower).
    pub points: usize,
    /// Size of the root block along x and y; it is centred under the base section.
    pub root_size: [f64; 2],
    /// Height of the root block; 0 for a bare airfoil.
    pub root_height: f64,
    pub cavities: usize,
    /// Skin thickness between the airfoil surface and the cavities.
    pub wall: f64,
    /// Thickness of the rib between two cavities.
    pub rib: f64,
}

/// Where the twist axis crosses the chord (the quarter chord, the usual stacking line).
const TWIST_AXIS: f64 = 0.25;

/// The largest twist between two sections: beyond it the ruled bands between sections
/// stray too far from the airfoil to be a fair approximation.
const MAX_STEP_DEGREES: f64 = 5.0;

/// The cavities span the part of the chord where the room left inside the skin is at
/// least this share of its maximum, which keeps them out of the thin leading and
/// trailing edges.
const CAVITY_DEPTH_SHARE: f64 = 0.35;

impl Blade {
    /// Default parameters for a chord: root block 1.25 x 0.5 chords and 0.25 chord
    /// high, skin 3 % of the chord.
    pub fn with_chord(chord: f64) -> Blade {
        Blade {
            profile: Naca {
                m: 0.02,
                p: 0.4,
                t: 0.12,
            },
            chord,
            span: 1.5 * chord,
            twist: 20.0,
            sections: 21,
            points: 48,
            root_size: [1.25 * chord, 0.5 * chord],
            root_height: 0.25 * chord,
            cavities: 0,
            wall: 0.03 * chord,
            rib: 0.03 * chord,
        }
    }

    /// The closed, outward-wound mesh, or which parameter makes it impossible.
    pub fn mesh(&self) -> Result<Mesh, Invalid> {
        let rings = self.base_rings()?;
        let mut gap_needed = 0.5 * self.wall;
        if self.cavities == 2 {
            gap_needed = gap_needed.min(0.5 * self.rib);
        }
        check_rings(&rings, gap_needed).map_err(|m| {
            let option = if m.contains("outline") { "points" } else { "wall" };
            Invalid::new(option, format!("the base section is not a valid area: {m}"))
        })?;
        self.check_bands(&rings, gap_needed)?;
        self.build(&rings)
    }

    fn check_params(&self) -> Result<(), Invalid> {
        self.profile.check()?;
        let positive = |option: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Invalid::new(
                    option,
                    format!("must be a positive number, not {v}"),
                ))
            }
        };
        positive("chord", self.chord)?;
        positive("span", self.span)?;
        positive("wall", self.wall)?;
        positive("rib", self.rib)?;
        if !(self.twist.is_finite() && self.twist.abs() <= 90.0) {
            return Err(Invalid::new("twist", "must lie in [-90, 90] degrees"));
        }
        if !(2..=10_000).contains(&self.sections) {
            return Err(Invalid::new("sections", "must lie in 2..=10000"));
        }
        if !(4..=10_000).contains(&self.points) {
            return Err(Invalid::new("points", "must lie in 4..=10000"));
        }
        if self.cavities > 2 {
            return Err(Invalid::new("cavities", "must be 0, 1 or 2"));
        }
        if !(self.root_height.is_finite() && self.root_height >= 0.0) {
            return Err(Invalid::new(
                "root_height",
                "must be 0 (no root) or a positive number",
            ));
        }
        if self.root_height > 0.0 {
            positive("root_size", self.root_size[0])?;
            positive("root_size", self.root_size[1])?;
        }
        Ok(())
    }

    /// The cavity intervals along the unit chord.
    fn cavity_intervals(&self) -> Result<Vec<(f64, f64)>, Invalid> {
        if self.cavities == 0 {
            return Ok(Vec::new());
        }
        let room = |x: f64| self.profile.half_thickness(x) - self.wall / self.chord;
        let xs: Vec<f64> = (0..=2000).map(|i| i as f64 / 2000.0).collect();
        let deepest = xs.iter().map(|&x| room(x)).fold(f64::NEG_INFINITY, f64::max);
        if deepest <= 0.0 {
            return Err(Invalid::new(
                "wall",
                format!(
                    "leaves no room for a cavity: the airfoil is at most {:.3} mm thick",
                    2.0 * self.chord * (deepest + self.wall / self.chord)
                ),
            ));
        }
        let deep: Vec<f64> = xs
            .iter()
            .copied()
            .filter(|&x| room(x) >= CAVITY_DEPTH_SHARE * deepest)
            .collect();
        let (a, b) = match (deep.first(), deep.last()) {
            (Some(&a), Some(&b)) if b > a => (a, b),
            _ => return Err(Invalid::new("wall", "leaves no room for a cavity")),
        };
        if self.cavities == 1 {
            return Ok(vec![(a, b)]);
        }
        let mid = 0.5 * (a + b);
        let half_rib = 0.5 * self.rib / self.chord;
        let min_len = 0.02;
        if mid - half_rib - a < min_len {
            return Err(Invalid::new(
                "rib",
                format!(
                    "leaves no room for two cavities: must be well below {:.3} mm",
                    (b - a) * self.chord
                ),
            ));
        }
        Ok(vec![(a, mid - half_rib), (mid + half_rib, b)])
    }

    /// A cavity between chord positions `x0` and `x1` on a unit chord: the room inside
    /// the skin with elliptic ends, `k` vertices per side, clockwise.
    fn cavity(&self, (x0, x1): (f64, f64), k: usize) -> Vec<Point2> {
        let (mid, half) = (0.5 * (x0 + x1), 0.5 * (x1 - x0));
        let room = |x: f64| (self.profile.half_thickness(x) - self.wall / self.chord).max(0.0);
        let at = |j: usize, side: f64| {
            let phi = PI * j as f64 / (k - 1) as f64;
            let x = mid - half * phi.cos();
            let h = if j == 0 || j == k - 1 {
                0.0
            } else {
                room(x) * phi.sin()
            };
            self.profile.offset_point(x, side * h)
        };
        let mut pts: Vec<Point2> = (0..k).map(|j| at(j, 1.0)).collect();
        pts.extend((1..k - 1).rev().map(|j| at(j, -1.0)));
        pts
    }

    /// The base section in mm, in the blade's frame (the twist axis at the origin): the
    /// outline first (counter-clockwise), then the cavities (clockwise).
    fn base_rings(&self) -> Result<Vec<Vec<Point2>>, Invalid> {
        self.check_params()?;
        let unit = |p: Point2| Point2::new((p.x - TWIST_AXIS) * self.chord, p.y * self.chord);
        let mut rings = vec![self.profile.outline(self.points).into_iter().map(unit).collect()];
        let k = (self.points / 2).max(8);
        for interval in self.cavity_intervals()? {
            rings.push(self.cavity(interval, k).into_iter().map(unit).collect());
        }
        Ok(rings)
    }

    fn step(&self) -> f64 {
        self.twist.to_radians() / (self.sections - 1) as f64
    }

    /// Checks the ruled band between the first two sections: the walls of different
    /// rings must stay `gap_needed` apart and every ring simple.
    ///
    /// A horizontal section of the band is exact in the height fraction s: its vertices
    /// move linearly with s. The distance between two segments changes by at most the
    /// largest move of their end points, so with samples closer than `gap_needed` in
    /// that move, walls at least `gap_needed` apart at every sample are apart at every
    /// height in between: the skin and rib thicknesses are positive throughout, not
    /// only at the samples. Each ring's own simplicity is checked at the samples, with
    /// the twist per section capped so that a band stays close to its sections.
    fn check_bands(&self, rings: &[Vec<Point2>], gap_needed: f64) -> Result<(), Invalid> {
        let step = self.step();
        let too_far = |why: String| {
            Invalid::new(
                "sections",
                format!(
                    "a twist of {:.2} degrees per section bends the walls too far between sections \
                     ({why}); use more sections",
                    step.abs().to_degrees()
                ),
            )
        };
        if step.abs() > MAX_STEP_DEGREES.to_radians() {
            return Err(too_far(format!("at most {MAX_STEP_DEGREES} degrees")));
        }
        let (sin, cos) = step.sin_cos();
        let rotate = |p: &Point2| Point2::new(cos * p.x - sin * p.y, sin * p.x + cos * p.y);
        let pairs: Vec<(&Vec<Point2>, Vec<Point2>)> = rings
            .iter()
            .map(|a| (a, a.iter().map(rotate).collect()))
            .collect();
        // The largest move of a section vertex over the band: to b_i or b_(i+1).
        let travel = pairs
            .iter()
            .flat_map(|(a, b)| {
                (0..a.len()).map(move |i| (b[i] - a[i]).norm().max((b[(i + 1) % a.len()] - a[i]).norm()))
            })
            .fold(0.0, f64::max);
        let samples = if rings.len() > 1 {
            (travel / gap_needed).ceil() as usize + 1
        } else {
            8
        }
        .clamp(4, 400);
        for k in 1..samples {
            let s = k as f64 / samples as f64;
            let loops: Vec<Vec<Point2>> = pairs.iter().map(|(a, b)| band_section(a, b, s)).collect();
            check_rings(&loops, gap_needed).map_err(too_far)?;
        }
        Ok(())
    }

    fn build(&self, rings: &[Vec<Point2>]) -> Result<Mesh, Invalid> {
        // The root block is centred under the base section's bounding box.
        let bbox = lamina_api::BBox2::from_points(rings[0].iter().copied());
        let centre = bbox.center();
        let place = |p: Point2, angle: f64| {
            let (sin, cos) = angle.sin_cos();
            Point2::new(cos * p.x - sin * p.y - centre.x, sin * p.x + cos * p.y - centre.y)
        };
        let section = |angle: f64| -> Vec<Vec<Point2>> {
            rings
                .iter()
                .map(|r| r.iter().map(|&p| place(p, angle)).collect())
                .collect()
        };
        let mut b = Builder::default();
        let base = section(0.0);
        let h0 = self.root_height;
        let mut lower: Vec<Ring>;
        if h0 > 0.0 {
            let (hx, hy) = (0.5 * self.root_size[0], 0.5 * self.root_size[1]);
            let margin = 1e-6 * self.chord;
            if bbox.width() * 0.5 + margin >= hx || bbox.height() * 0.5 + margin >= hy {
                return Err(Invalid::new(
                    "root_size",
                    format!(
                        "must exceed the base section, {:.3} x {:.3} mm",
                        bbox.width(),
                        bbox.height()
                    ),
                ));
            }
            let rect = [
                Point2::new(-hx, -hy),
                Point2::new(hx, -hy),
                Point2::new(hx, hy),
                Point2::new(-hx, hy),
            ];
            let r0 = b.ring(&rect, 0.0);
            let r1 = b.ring(&rect, h0);
            b.band(r0, r1);
            let bed: Vec<Ring> = base[1..].iter().map(|c| b.ring(c, 0.0)).collect();
            b.cap(&[&[r0][..], &bed].concat(), false)?;
            lower = base.iter().map(|r| b.ring(r, h0)).collect();
            b.cap(&[r1, lower[0]], true)?;
            for (&c, &l) in bed.iter().zip(&lower[1..]) {
                b.band(c, l);
            }
        } else {
            lower = base.iter().map(|r| b.ring(r, 0.0)).collect();
            b.cap(&lower, false)?;
        }
        for k in 1..self.sections {
            let z = h0 + self.span * k as f64 / (self.sections - 1) as f64;
            let upper: Vec<Ring> = section(self.step() * k as f64)
                .iter()
                .map(|r| b.ring(r, z))
                .collect();
            for (&l, &u) in lower.iter().zip(&upper) {
                b.band(l, u);
            }
            lower = upper;
        }
        b.cap(&lower, true)?;
        Ok(Mesh::new("blade", b.vertices, b.triangles))
    }
}

/// The section at height fraction `s` of the band between rings `a` and `b` (same
/// length, vertex i above vertex i) as [`Builder::band`] triangulates it.
fn band_section(a: &[Point2], b: &[Point2], s: f64) -> Vec<Point2> {
    let n = a.len();
    let lerp = |p: Point2, q: Point2| Point2::from(p.coords * (1.0 - s) + q.coords * s);
    (0..n)
        .flat_map(|i| [lerp(a[i], b[i]), lerp(a[i], b[(i + 1) % n])])
        .collect()
}

/// Checks that `rings` (outline first, then cavities) bound one area with holes: every
/// ring simple, no two rings crossing or closer than `gap_needed`, every cavity inside
/// the outline and outside the other cavities. Returns the smallest gap.
fn check_rings(rings: &[Vec<Point2>], gap_needed: f64) -> Result<f64, String> {
    for (i, r) in rings.iter().enumerate() {
        let what = if i == 0 { "the outline" } else { "a cavity" };
        if let Some((e, f)) = self_crossing(r) {
            return Err(format!("{what} crosses itself (edges {e} and {f})"));
        }
    }
    let contours: Vec<Contour> = rings.iter().map(|r| Contour::new(r.clone())).collect();
    let mut smallest = f64::INFINITY;
    for i in 0..rings.len() {
        for j in i + 1..rings.len() {
            if rings_cross(&rings[i], &rings[j]) {
                return Err("the walls cross".into());
            }
            let gap = ring_gap(&rings[i], &contours[j]).min(ring_gap(&rings[j], &contours[i]));
            smallest = smallest.min(gap);
            if gap < gap_needed {
                return Err(format!("a wall is only {gap:.4} mm thick"));
            }
        }
        if i > 0 {
            let p = rings[i][0];
            if !contours[0].contains(p) || (1..rings.len()).any(|j| j != i && contours[j].contains(p)) {
                return Err("a cavity lies outside the outline or inside another cavity".into());
            }
        }
    }
    Ok(smallest)
}

fn ring_gap(points: &[Point2], other: &Contour) -> f64 {
    points
        .iter()
        .map(|&p| other.distance(p))
        .fold(f64::INFINITY, f64::min)
}

fn orient(a: Point2, b: Point2, c: Point2) -> f64 {
    (b - a).perp(&(c - a))
}

/// Whether closed segments `ab` and `cd` share a point.
fn segments_touch(a: Point2, b: Point2, c: Point2, d: Point2) -> bool {
    let (d1, d2) = (orient(a, b, c), orient(a, b, d));
    let (d3, d4) = (orient(c, d, a), orient(c, d, b));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |p: Point2, q: Point2, r: Point2, o: f64| {
        o == 0.0 && r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    on(a, b, c, d1) || on(a, b, d, d2) || on(c, d, a, d3) || on(c, d, b, d4)
}

fn edges(r: &[Point2]) -> impl Iterator<Item = (Point2, Point2)> + '_ {
    (0..r.len()).map(move |i| (r[i], r[(i + 1) % r.len()]))
}

/// Two non-adjacent edges of `r` that touch, if any.
fn self_crossing(r: &[Point2]) -> Option<(usize, usize)> {
    let n = r.len();
    let e: Vec<(Point2, Point2)> = edges(r).collect();
    for i in 0..n {
        for j in i + 2..n {
            if i == 0 && j == n - 1 {
                continue;
            }
            let ((a, b), (c, d)) = (e[i], e[j]);
            if a.x.max(b.x) < c.x.min(d.x)
                || c.x.max(d.x) < a.x.min(b.x)
                || a.y.max(b.y) < c.y.min(d.y)
                || c.y.max(d.y) < a.y.min(b.y)
            {
                continue;
            }
            if segments_touch(a, b, c, d) {
                return Some((i, j));
            }
        }
    }
    None
}

fn rings_cross(r: &[Point2], s: &[Point2]) -> bool {
    edges(r).any(|(a, b)| edges(s).any(|(c, d)| segments_touch(a, b, c, d)))
}

/// A ring of vertices in a [`Builder`].
#[derive(Debug, Clone, Copy)]
struct Ring {
    start: u32,
    len: u32,
}

/// Accumulates rings of vertices at fixed heights, the bands between them and the caps
/// over them.
#[derive(Default)]
struct Builder {
    vertices: Vec<Point3>,
    triangles: Vec<[u32; 3]>,
}

impl Builder {
    fn ring(&mut self, pts: &[Point2], z: f64) -> Ring {
        let start = self.vertices.len() as u32;
        self.vertices.extend(pts.iter().map(|p| Point3::new(p.x, p.y, z)));
        Ring {
            start,
            len: pts.len() as u32,
        }
    }

    /// The wall between two rings of equal length, `hi` above `lo`. Facing outwards for
    /// counter-clockwise rings and into the hole for clockwise ones.
    fn band(&mut self, lo: Ring, hi: Ring) {
        debug_assert_eq!(lo.len, hi.len);
        for i in 0..lo.len {
            let j = (i + 1) % lo.len;
            let (a, b) = (lo.start + i, lo.start + j);
            let (c, d) = (hi.start + i, hi.start + j);
            self.triangles.push([a, b, d]);
            self.triangles.push([a, d, c]);
        }
    }

    /// A flat cap over `rings` (the outer ring first, then holes), facing up or down.
    fn cap(&mut self, rings: &[Ring], up: bool) -> Result<(), Invalid> {
        let mut flat: Vec<[f64; 2]> = Vec::new();
        let mut ids: Vec<u32> = Vec::new();
        let mut hole_starts: Vec<u32> = Vec::new();
        for (k, r) in rings.iter().enumerate() {
            if k > 0 {
                hole_starts.push(flat.len() as u32);
            }
            for v in r.start..r.start + r.len {
                let p = self.vertices[v as usize];
                flat.push([p.x, p.y]);
                ids.push(v);
            }
        }
        let mut cap: Vec<u32> = Vec::new();
        earcut::Earcut::new().earcut(flat.iter().copied(), &hole_starts, &mut cap);
        // A polygon of n vertices with h holes has n + 2h - 2 triangles; fewer means
        // earcut gave up on part of it.
        if cap.len() / 3 + 2 != flat.len() + 2 * hole_starts.len() {
            return Err(Invalid::new("points", "a cap could not be triangulated"));
        }
        for t in cap.chunks_exact(3) {
            let (a, b, c) = (flat[t[0] as usize], flat[t[1] as usize], flat[t[2] as usize]);
            let ccw = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) > 0.0;
            let (i, j, k) = (ids[t[0] as usize], ids[t[1] as usize], ids[t[2] as usize]);
            self.triangles.push(if ccw == up { [i, j, k] } else { [i, k, j] });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extrude::edge_defect;

    fn blade(cavities: usize) -> Blade {
        Blade {
            cavities,
            ..Blade::with_chord(40.0)
        }
    }

    fn area(r: &[Point2]) -> f64 {
        Contour::new(r.to_vec()).signed_area()
    }

    #[test]
    fn naca_codes_and_outline() {
        let n = Naca::from_code("2412").expect("code");
        assert_eq!((n.m, n.p, n.t), (0.02, 0.4, 0.12));
        assert!(Naca::from_code("241").is_none() && Naca::from_code("24a2").is_none());
        let o = n.outline(40);
        assert_eq!(o.len(), 79);
        assert!(area(&o) > 0.0);
        // A symmetric 12 % section has an area of about 0.0822 chord^2.
        let s = Naca::from_code("0012").expect("code").outline(200);
        assert!((area(&s) - 0.0822).abs() < 0.001, "{}", area(&s));
        // Leading edge at the origin, blunt trailing edge closed at x = 1.
        assert!(o.iter().any(|p| p.coords.norm() < 1e-12));
        assert!((o[0].x - 1.0).abs() < 1e-3 && (o[78].x - 1.0).abs() < 1e-3 && o[0].y > o[78].y);
    }

    #[test]
    fn blades_are_closed_oriented_and_solid() {
        for cavities in 0..=2 {
            let b = blade(cavities);
            let m = b.mesh().expect("blade");
            assert_eq!(edge_defect(&m), None, "{cavities} cavities");
            let rings = b.base_rings().expect("rings");
            let section: f64 = rings.iter().map(|r| area(r)).sum();
            assert!(rings[1..].iter().all(|r| area(r) < 0.0));
            let root = b.root_size[0] * b.root_size[1] + section - area(&rings[0]);
            // Twisted bands lose a little volume against straight prisms (their
            // middles are rotated chords, slightly inside): well below 1e-3.
            let expected = root * b.root_height + section * b.span;
            let v = m.signed_volume();
            assert!(
                v > 0.0 && (v - expected).abs() < 1e-3 * expected,
                "{v} vs {expected}"
            );
        }
    }

    #[test]
    fn cavities_keep_their_walls() {
        let b = blade(2);
        let rings = b.base_rings().expect("rings");
        let gap = check_rings(&rings, 0.0).expect("valid");
        let (sin, cos) = b.step().sin_cos();
        let mid: Vec<Vec<Point2>> = rings
            .iter()
            .map(|a| {
                let turned: Vec<Point2> = a
                    .iter()
                    .map(|p| Point2::new(cos * p.x - sin * p.y, sin * p.x + cos * p.y))
                    .collect();
                band_section(a, &turned, 0.5)
            })
            .collect();
        let mid_gap = check_rings(&mid, 0.0).expect("valid between sections");
        println!("thinnest wall: {gap:.4} mm at a section, {mid_gap:.4} mm between sections");
        assert!(mid_gap > 0.9 * b.wall.min(b.rib), "{mid_gap}");
        assert!(gap > 0.9 * b.wall.min(b.rib), "{gap}");
        // The outline and straight cavities of an untwisted blade are simple too.
        let straight = Blade { twist: 0.0, ..b };
        assert!(straight.mesh().is_ok());
    }

    #[test]
    fn bad_parameters_name_their_option() {
        let cases: [(Blade, &str); 6] = [
            (
                Blade {
                    wall: 3.0,
                    ..blade(1)
                },
                "wall",
            ),
            (
                Blade {
                    rib: 29.0,
                    ..blade(2)
                },
                "rib",
            ),
            (
                Blade {
                    twist: 80.0,
                    sections: 2,
                    ..blade(2)
                },
                "sections",
            ),
            (
                Blade {
                    root_size: [30.0, 10.0],
                    ..blade(0)
                },
                "root_size",
            ),
            (
                Blade {
                    cavities: 3,
                    ..blade(0)
                },
                "cavities",
            ),
            (
                Blade {
                    span: f64::NAN,
                    ..blade(0)
                },
                "span",
            ),
        ];
        for (b, option) in cases {
            let e = b.mesh().err().unwrap_or_else(|| panic!("{option} accepted"));
            assert_eq!(e.option, option, "{e}");
        }
    }

    #[test]
    fn steep_twists_keep_their_walls_or_are_refused() {
        // 5 degrees per section, either way, at the limit.
        for twist in [60.0, -60.0] {
            let b = Blade {
                twist,
                sections: 13,
                ..blade(2)
            };
            let m = b.mesh().expect("twisted blade");
            assert_eq!(edge_defect(&m), None);
        }
        let e = Blade {
            twist: 61.0,
            sections: 13,
            ..blade(2)
        }
        .mesh()
        .err()
        .map(|e| e.option);
        assert_eq!(e, Some("sections"));
    }

    #[test]
    fn a_bare_airfoil_has_no_root() {
        let b = Blade {
            root_height: 0.0,
            ..blade(1)
        };
        let m = b.mesh().expect("blade");
        assert_eq!(edge_defect(&m), None);
        assert!(m.bbox().min.z == 0.0 && m.signed_volume() > 0.0);
    }
}
