//! Chosen faces of a part's mesh and the distance in space to them: the surface
//! features of the papers (a material distance field from selected faces of the part,
//! distance-field paper; the outer-surface grading source of Fig. 1d, grading-step-width
//! paper), shared here so that every stage selects and measures alike.

use std::sync::{Arc, Mutex};

use serde::Deserialize;

use lamina_api::mesh::{Mesh, Point3, Vector3};

/// Which faces of the mesh form the surface.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct FaceSelection {
    /// Faces whose outward normal lies within `within` degrees of this direction.
    #[serde(default)]
    pub normal: Option<[f64; 3]>,
    /// Angle (degrees) for `normal`.
    #[serde(default = "default_within")]
    pub within: f64,
    /// Faces of these named groups (a 3MF object's base materials).
    #[serde(default)]
    pub groups: Vec<String>,
}

fn default_within() -> f64 {
    30.0
}

impl FaceSelection {
    /// Refuses a zero normal or an angle outside [0, 180].
    pub fn check(&self) -> std::result::Result<(), String> {
        if let Some(n) = self.normal
            && !(n.iter().all(|c| c.is_finite()) && n.iter().any(|c| *c != 0.0))
        {
            return Err(format!("`normal` must be a non-zero direction, not {n:?}"));
        }
        if !(0.0..=180.0).contains(&self.within) {
            return Err(format!(
                "`within` must be an angle in [0, 180] degrees, not {}",
                self.within
            ));
        }
        Ok(())
    }

    /// The selected triangles of `mesh`: all when nothing is asked, else those that
    /// meet every given criterion.
    pub fn select(&self, mesh: &Mesh) -> std::result::Result<Vec<usize>, String> {
        let mut groups = Vec::with_capacity(self.groups.len());
        for g in &self.groups {
            match mesh.material_names.iter().position(|n| n == g) {
                Some(i) => groups.push(i as u32),
                None if mesh.material_names.is_empty() => {
                    return Err(format!(
                        "mesh `{}` has no named face groups (asked for `{g}`)",
                        mesh.name
                    ));
                }
                None => {
                    return Err(format!(
                        "mesh `{}` has no face group `{g}` (it has: {})",
                        mesh.name,
                        mesh.material_names.join(", ")
                    ));
                }
            }
        }
        let cos = self.within.to_radians().cos();
        let dir = self.normal.map(|n| Vector3::from(n).normalize());
        Ok((0..mesh.triangles.len())
            .filter(|&t| {
                let by_group =
                    groups.is_empty() || mesh.triangle_materials.get(t).is_some_and(|m| groups.contains(m));
                let by_normal = dir.is_none_or(|d| {
                    let [a, b, c] = mesh.triangle(t);
                    let n = (b - a).cross(&(c - a));
                    let len = n.norm();
                    len > 0.0 && n.dot(&d) / len >= cos - 1e-12
                });
                by_group && by_normal
            })
            .collect())
    }
}

/// The chosen triangles bucketed on a uniform grid, for distance queries.
#[derive(Debug, Clone)]
pub struct Surface {
    triangles: Vec<[Point3; 3]>,
    min: Point3,
    bucket: f64,
    dims: [usize; 3],
    buckets: Vec<Vec<u32>>,
}

impl Surface {
    /// The surface of the given triangles of `mesh`; `None` when there are none.
    pub fn new(mesh: &Mesh, chosen: &[usize]) -> Option<Self> {
        if chosen.is_empty() {
            return None;
        }
        let triangles: Vec<[Point3; 3]> = chosen.iter().map(|&t| mesh.triangle(t)).collect();
        let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let mut hi = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for p in triangles.iter().flatten() {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let size = hi - lo;
        let extent = size.x.max(size.y).max(size.z);
        if !(extent.is_finite() && extent > 0.0) {
            return None;
        }
        // About one triangle per bucket on average, at most 128 buckets a side.
        let side = ((triangles.len() as f64).cbrt().ceil() as usize).clamp(1, 128);
        let bucket = extent / side as f64;
        let dims = [0, 1, 2].map(|k| ((size[k] / bucket) as usize + 1).min(side + 1));
        let mut surface = Surface {
            triangles,
            min: lo,
            bucket,
            dims,
            buckets: vec![Vec::new(); dims[0] * dims[1] * dims[2]],
        };
        for (i, t) in surface.triangles.iter().enumerate() {
            let a = t[0].inf(&t[1]).inf(&t[2]);
            let b = t[0].sup(&t[1]).sup(&t[2]);
            let (i0, i1) = (surface.index(&a), surface.index(&b));
            for z in i0[2]..=i1[2] {
                for y in i0[1]..=i1[1] {
                    for x in i0[0]..=i1[0] {
                        let k = (z * dims[1] + y) * dims[0] + x;
                        surface.buckets[k].push(i as u32);
                    }
                }
            }
        }
        Some(surface)
    }

    fn index(&self, p: &Point3) -> [usize; 3] {
        [0, 1, 2].map(|k| {
            let v = (p[k] - self.min[k]) / self.bucket;
            if v.is_nan() || v <= 0.0 {
                0
            } else {
                (v as usize).min(self.dims[k] - 1)
            }
        })
    }

    /// The distance from `p` to the nearest chosen triangle: buckets searched in shells
    /// about the bucket nearest to `p` until no farther shell can hold a nearer one.
    pub fn distance(&self, p: Point3) -> f64 {
        self.distance_within(p, f64::INFINITY)
    }

    /// [`Self::distance`] where it is below `cap`, else some value at least `cap`: the
    /// search stops at the shells beyond `cap`, so points far from the surface cost a
    /// few empty buckets instead of a walk to the nearest triangle.
    pub fn distance_within(&self, p: Point3, cap: f64) -> f64 {
        let c = self.index(&p);
        // How far p lies outside the grid's box: shells start counting from there.
        let outside = {
            let hi = self.min + Vector3::from(self.dims.map(|d| d as f64 * self.bucket));
            let d = Vector3::new(
                (self.min.x - p.x).max(p.x - hi.x).max(0.0),
                (self.min.y - p.y).max(p.y - hi.y).max(0.0),
                (self.min.z - p.z).max(p.z - hi.z).max(0.0),
            );
            d.norm()
        };
        let mut best = if cap.is_nan() { f64::INFINITY } else { cap };
        let max_shell = self.dims.iter().copied().max().unwrap_or(1);
        for r in 0..=max_shell {
            // Every bucket of shell r is at least (r - 1) buckets from p, and no nearer than
            // the grid's box.
            if outside.max((r as f64 - 1.0) * self.bucket) > best {
                break;
            }
            let r = r as isize;
            for z in -r..=r {
                for y in -r..=r {
                    for x in -r..=r {
                        if x.abs().max(y.abs()).max(z.abs()) != r {
                            continue;
                        }
                        let q = [c[0] as isize + x, c[1] as isize + y, c[2] as isize + z];
                        if (0..3).any(|k| q[k] < 0 || q[k] as usize >= self.dims[k]) {
                            continue;
                        }
                        let k = (q[2] as usize * self.dims[1] + q[1] as usize) * self.dims[0] + q[0] as usize;
                        if self.buckets[k].is_empty() {
                            continue;
                        }
                        // A triangle's nearest point to p lies in one of the buckets it is
                        // listed in, no nearer than that bucket's box: a bucket whose box is
                        // beyond the best so far holds nothing nearer.
                        let gap = Vector3::from([0, 1, 2].map(|a| {
                            let lo = self.min[a] + q[a] as f64 * self.bucket;
                            (lo - p[a]).max(p[a] - (lo + self.bucket)).max(0.0)
                        }));
                        if gap.norm_squared() >= best * best {
                            continue;
                        }
                        // A triangle in several buckets is measured again: cheaper than
                        // remembering which were.
                        for &t in &self.buckets[k] {
                            best = best.min(triangle_distance(p, &self.triangles[t as usize]));
                        }
                    }
                }
            }
        }
        best
    }
}

/// The chosen faces of each mesh a stage has met, keyed by the mesh's address: built
/// once per run, shared by the layers' threads.
#[derive(Debug, Default)]
pub struct Surfaces(Mutex<Vec<(usize, Option<Arc<Surface>>)>>);

impl Clone for Surfaces {
    fn clone(&self) -> Self {
        Surfaces::default()
    }
}

impl Surfaces {
    /// The surface of `faces` on `mesh`, built on first use.
    pub fn of(
        &self,
        mesh: &Mesh,
        faces: &FaceSelection,
    ) -> std::result::Result<Option<Arc<Surface>>, String> {
        let key = mesh as *const Mesh as usize;
        let mut known = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, s)) = known.iter().find(|(k, _)| *k == key) {
            return Ok(s.clone());
        }
        let chosen = faces.select(mesh)?;
        let surface = Surface::new(mesh, &chosen).map(Arc::new);
        known.push((key, surface.clone()));
        Ok(surface)
    }
}

/// Distance from `p` to a triangle (Ericson, Real-Time Collision Detection, 5.1.5:
/// the closest point by the Voronoi regions of the corners, edges and face).
pub fn triangle_distance(p: Point3, t: &[Point3; 3]) -> f64 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.norm();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + ab * v)).norm();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).norm();
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        // A degenerate triangle: the nearest of its edges.
        return [(a, b), (b, c), (c, a)]
            .iter()
            .map(|&(s, e)| {
                let d = e - s;
                let l2 = d.norm_squared();
                let u = if l2 > 0.0 {
                    ((p - s).dot(&d) / l2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (p - (s + d * u)).norm()
            })
            .fold(f64::INFINITY, f64::min);
    }
    let (v, w) = (vb / denom, vc / denom);
    (p - (a + ab * v + ac * w)).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> Mesh {
        // A unit cube, outward winding.
        let v = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
        let vertices = vec![
            v(0.0, 0.0, 0.0),
            v(1.0, 0.0, 0.0),
            v(1.0, 1.0, 0.0),
            v(0.0, 1.0, 0.0),
            v(0.0, 0.0, 1.0),
            v(1.0, 0.0, 1.0),
            v(1.0, 1.0, 1.0),
            v(0.0, 1.0, 1.0),
        ];
        let triangles = vec![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [2, 3, 7],
            [2, 7, 6],
            [1, 2, 6],
            [1, 6, 5],
            [0, 4, 7],
            [0, 7, 3],
        ];
        Mesh::new("cube", vertices, triangles)
    }

    #[test]
    fn faces_chosen_by_normal_and_their_distance() {
        let mesh = cube();
        let top = FaceSelection {
            normal: Some([0.0, 0.0, 1.0]),
            ..FaceSelection::default()
        };
        let chosen = top.select(&mesh).unwrap();
        assert_eq!(chosen, [2, 3]);
        let s = Surface::new(&mesh, &chosen).unwrap();
        assert!((s.distance(Point3::new(0.5, 0.5, 0.25)) - 0.75).abs() < 1e-12);
        assert!((s.distance(Point3::new(3.0, 0.5, 1.0)) - 2.0).abs() < 1e-12);
        let all = Surface::new(&mesh, &FaceSelection::default().select(&mesh).unwrap()).unwrap();
        assert!((all.distance(Point3::new(0.5, 0.4, 0.5)) - 0.4).abs() < 1e-12);
        assert!(
            FaceSelection {
                groups: vec!["skin".into()],
                ..FaceSelection::default()
            }
            .select(&mesh)
            .unwrap_err()
            .contains("no named face groups")
        );
    }

    /// The distance to a triangle by another route: inside the triangle's own
    /// projection, the height over its plane; else the nearest of its three edges.
    fn reference_distance(p: Point3, t: &[Point3; 3]) -> f64 {
        let [a, b, c] = *t;
        let segment = |s: Point3, e: Point3| {
            let d = e - s;
            let u = ((p - s).dot(&d) / d.norm_squared()).clamp(0.0, 1.0);
            (p - (s + d * u)).norm()
        };
        let edges = segment(a, b).min(segment(b, c)).min(segment(c, a));
        let n = (b - a).cross(&(c - a)).normalize();
        let h = (p - a).dot(&n);
        let q = p - n * h;
        let side = |s: Point3, e: Point3| (e - s).cross(&(q - s)).dot(&n);
        if side(a, b) >= 0.0 && side(b, c) >= 0.0 && side(c, a) >= 0.0 {
            h.abs()
        } else {
            edges
        }
    }

    /// A reproducible sequence of numbers in [0, 1).
    fn numbers(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn point_to_triangle_agrees_with_the_projection_and_the_edges() {
        let mut r = numbers(7);
        for _ in 0..5000 {
            let mut v = || Point3::new(4.0 * r() - 2.0, 4.0 * r() - 2.0, 4.0 * r() - 2.0);
            let t = [v(), v(), v()];
            let p = v();
            if (t[1] - t[0]).cross(&(t[2] - t[0])).norm() < 1e-3 {
                continue;
            }
            let (got, want) = (triangle_distance(p, &t), reference_distance(p, &t));
            assert!((got - want).abs() < 1e-9, "{p:?} to {t:?}: {got} against {want}");
        }
    }

    #[test]
    fn a_degenerate_triangle_is_its_nearest_edge() {
        let a = Point3::new(0.0, 0.0, 0.0);
        let b = Point3::new(2.0, 0.0, 0.0);
        // Collinear corners: the segment from a to b.
        let line = [a, b, Point3::new(1.0, 0.0, 0.0)];
        assert!((triangle_distance(Point3::new(1.0, 3.0, 4.0), &line) - 5.0).abs() < 1e-12);
        assert!((triangle_distance(Point3::new(3.0, 0.0, 0.0), &line) - 1.0).abs() < 1e-12);
        // All corners at one point.
        let dot = [b, b, b];
        assert!((triangle_distance(Point3::new(2.0, 3.0, 4.0), &dot) - 5.0).abs() < 1e-12);
    }

    /// A closed, finely cut surface: a sphere of radius 5 about (1, 2, 3), as a
    /// latitude-longitude grid of 2 * 24 * 48 triangles.
    fn sphere() -> Mesh {
        let (rings, sectors) = (24u32, 48u32);
        let mut vertices = Vec::new();
        for i in 0..=rings {
            let theta = std::f64::consts::PI * i as f64 / rings as f64;
            for j in 0..sectors {
                let phi = 2.0 * std::f64::consts::PI * j as f64 / sectors as f64;
                vertices.push(Point3::new(
                    1.0 + 5.0 * theta.sin() * phi.cos(),
                    2.0 + 5.0 * theta.sin() * phi.sin(),
                    3.0 + 5.0 * theta.cos(),
                ));
            }
        }
        let at = |i: u32, j: u32| i * sectors + j % sectors;
        let mut triangles = Vec::new();
        for i in 0..rings {
            for j in 0..sectors {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        Mesh::new("sphere", vertices, triangles)
    }

    #[test]
    fn the_grid_finds_the_nearest_triangle_inside_outside_and_far_away() {
        let mesh = sphere();
        let chosen: Vec<usize> = (0..mesh.triangles.len()).collect();
        let s = Surface::new(&mesh, &chosen).expect("a surface");
        let brute = |p: Point3| {
            chosen
                .iter()
                .map(|&t| triangle_distance(p, &mesh.triangle(t)))
                .fold(f64::INFINITY, f64::min)
        };
        let mut r = numbers(11);
        for i in 0..600 {
            // Inside the grid's box, around it, and far beyond it.
            let spread = [12.0, 30.0, 400.0][i % 3];
            let p = Point3::new(
                1.0 + spread * (r() - 0.5),
                2.0 + spread * (r() - 0.5),
                3.0 + spread * (r() - 0.5),
            );
            let want = brute(p);
            assert!((s.distance(p) - want).abs() < 1e-12, "{p:?}");
            // Under a cap the distance is exact; beyond it, at least the cap.
            for cap in [0.5, 2.0, 7.0] {
                let got = s.distance_within(p, cap);
                if want < cap {
                    assert!(
                        (got - want).abs() < 1e-12,
                        "{p:?} under {cap}: {got} against {want}"
                    );
                } else {
                    assert!(
                        got >= cap.min(want) - 1e-12,
                        "{p:?} under {cap}: {got} against {want}"
                    );
                }
            }
        }
        // The centre is about the radius from every face.
        assert!((s.distance(Point3::new(1.0, 2.0, 3.0)) - 5.0).abs() < 0.06);
        // A NaN cap is no cap.
        assert!((s.distance_within(Point3::new(1.0, 2.0, 20.0), f64::NAN) - 12.0).abs() < 1e-9);
    }

    /// Faces within `within` degrees of the direction halfway between +x and up.
    fn toward_x_and_up(within: f64) -> FaceSelection {
        FaceSelection {
            normal: Some([1.0, 0.0, 1.0]),
            within,
            groups: Vec::new(),
        }
    }

    #[test]
    fn faces_chosen_by_group_and_within_an_angle() {
        let mut mesh = cube();
        mesh.material_names = vec!["core".into(), "skin".into()];
        // The top and the side at x = 1 are skin.
        mesh.triangle_materials = vec![0, 0, 1, 1, 0, 0, 0, 0, 1, 1, 0, 0];
        let skin = FaceSelection {
            groups: vec!["skin".into()],
            ..FaceSelection::default()
        };
        assert_eq!(skin.select(&mesh).unwrap(), [2, 3, 8, 9]);
        // Both criteria: skin facing up.
        let up_skin = FaceSelection {
            normal: Some([0.0, 0.0, 2.0]),
            ..skin.clone()
        };
        assert_eq!(up_skin.select(&mesh).unwrap(), [2, 3]);
        let e = FaceSelection {
            groups: vec!["shell".into()],
            ..FaceSelection::default()
        }
        .select(&mesh)
        .unwrap_err();
        assert!(e.contains("no face group `shell` (it has: core, skin)"), "{e}");
        // A direction halfway between up and +x: the top and that side lie 45 degrees
        // off it, the others 90 or more.
        assert_eq!(toward_x_and_up(45.0).select(&mesh).unwrap(), [2, 3, 8, 9]);
        assert!(toward_x_and_up(44.0).select(&mesh).unwrap().is_empty());
        assert_eq!(toward_x_and_up(90.0).select(&mesh).unwrap().len(), 12 - 4);
        assert_eq!(toward_x_and_up(180.0).select(&mesh).unwrap().len(), 12);
        // A triangle of no area faces nowhere.
        let mut flat = cube();
        flat.triangles[2] = [4, 4, 5];
        let up = FaceSelection {
            normal: Some([0.0, 0.0, 1.0]),
            ..FaceSelection::default()
        };
        assert_eq!(up.select(&flat).unwrap(), [3]);
    }

    /// The angle between a face's normal and the asked direction, on faces whose
    /// normals are not of unit length (a cube of side 3), and the default angle.
    #[test]
    fn the_angle_is_measured_whatever_the_faces_size() {
        let mut big = cube();
        for v in &mut big.vertices {
            *v = Point3::from(v.coords * 3.0);
        }
        assert_eq!(toward_x_and_up(45.0).select(&big).unwrap(), [2, 3, 8, 9]);
        assert!(toward_x_and_up(44.0).select(&big).unwrap().is_empty());
        // 30 degrees unless the table says.
        let unsaid = FaceSelection::deserialize(serde::de::value::MapDeserializer::<
            _,
            serde::de::value::Error,
        >::new(std::iter::empty::<(&str, f64)>()))
        .unwrap();
        assert_eq!(unsaid.within, 30.0);
        assert_eq!(
            unsaid,
            FaceSelection {
                within: 30.0,
                ..FaceSelection::default()
            }
        );
        // 30 degrees off the top: within the default, not within 29.
        let (s, c) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
        let off = FaceSelection {
            normal: Some([s, 0.0, c]),
            ..unsaid.clone()
        };
        assert_eq!(off.select(&big).unwrap(), [2, 3]);
        assert!(
            FaceSelection { within: 29.0, ..off }
                .select(&big)
                .unwrap()
                .is_empty()
        );
    }

    /// Two small faces at opposite corners of the grid, and points beyond the grid's
    /// box where the nearer face lies at the far end of the grid along one axis: the
    /// shells must reach across the whole grid from where the point clamps to it.
    #[test]
    fn the_search_reaches_across_the_grid_from_outside_it() {
        let v = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
        let mesh = Mesh::new(
            "corners",
            vec![
                v(0.0, 0.0, 0.0),
                v(1.0, 0.0, 0.0),
                v(0.0, 1.0, 0.0),
                v(100.0, 100.0, 0.0),
                v(99.0, 100.0, 0.0),
                v(100.0, 99.0, 0.0),
            ],
            vec![[0, 1, 2], [3, 4, 5]],
        );
        let s = Surface::new(&mesh, &[0, 1]).expect("a surface");
        let brute = |p: Point3| {
            (0..2)
                .map(|t| triangle_distance(p, &mesh.triangle(t)))
                .fold(f64::INFINITY, f64::min)
        };
        for p in [
            v(101.0, -200.0, 0.0),
            v(-200.0, 101.0, 0.0),
            v(150.0, -60.0, 3.0),
            v(50.0, 50.0, 0.0),
            v(49.0, 49.0, -40.0),
            v(51.0, 51.0, 40.0),
            v(101.0, 101.0, 0.0),
            v(200.0, -600.0, 0.0),
            v(-600.0, 200.0, 5.0),
        ] {
            assert!(
                (s.distance(p) - brute(p)).abs() < 1e-12,
                "{p:?}: {} against {}",
                s.distance(p),
                brute(p)
            );
        }
    }

    #[test]
    fn selections_are_checked() {
        let ok = FaceSelection::default();
        assert!(ok.check().is_ok());
        for (sel, says) in [
            (
                FaceSelection {
                    normal: Some([0.0; 3]),
                    ..FaceSelection::default()
                },
                "non-zero direction",
            ),
            (
                FaceSelection {
                    normal: Some([f64::NAN, 0.0, 1.0]),
                    ..FaceSelection::default()
                },
                "non-zero direction",
            ),
            (
                FaceSelection {
                    within: -1.0,
                    ..FaceSelection::default()
                },
                "[0, 180]",
            ),
            (
                FaceSelection {
                    within: 180.5,
                    ..FaceSelection::default()
                },
                "[0, 180]",
            ),
        ] {
            assert!(sel.check().unwrap_err().contains(says), "{sel:?}");
        }
        for within in [0.0, 180.0] {
            assert!(FaceSelection { within, ..ok.clone() }.check().is_ok());
        }
        assert!(
            FaceSelection {
                normal: Some([0.0, 0.0, -1.0]),
                ..ok
            }
            .check()
            .is_ok()
        );
    }

    #[test]
    fn surfaces_are_built_once_per_mesh_and_none_without_faces() {
        let (a, b) = (cube(), sphere());
        let all = FaceSelection::default();
        let surfaces = Surfaces::default();
        let first = surfaces.of(&a, &all).unwrap().expect("a surface");
        let again = surfaces.of(&a, &all).unwrap().expect("a surface");
        assert!(Arc::ptr_eq(&first, &again));
        let other = surfaces.of(&b, &all).unwrap().expect("a surface");
        assert!(!Arc::ptr_eq(&first, &other));
        // A clone starts empty: its own run's meshes.
        let fresh = surfaces.clone().of(&a, &all).unwrap().expect("a surface");
        assert!(!Arc::ptr_eq(&first, &fresh));
        assert!(Surface::new(&a, &[]).is_none());
        // A surface of one point has no extent.
        let mut dot = cube();
        dot.triangles = vec![[1, 1, 1]];
        assert!(Surface::new(&dot, &[0]).is_none());
        // A selection that matches nothing gives no surface.
        let diagonal = FaceSelection {
            normal: Some([1.0, 1.0, 1.0]),
            within: 0.0,
            groups: Vec::new(),
        };
        assert!(Surfaces::default().of(&a, &diagonal).unwrap().is_none());
    }

    #[test]
    fn point_to_triangle_in_every_region() {
        let t = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(2.0, 0.0, 0.0),
            Point3::new(0.0, 2.0, 0.0),
        ];
        for (p, d) in [
            (Point3::new(0.5, 0.5, 3.0), 3.0),
            (Point3::new(-1.0, -1.0, 0.0), 2f64.sqrt()),
            (Point3::new(1.0, -2.0, 0.0), 2.0),
            (Point3::new(2.0, 2.0, 0.0), 2f64.sqrt()),
            (Point3::new(3.0, 0.0, 0.0), 1.0),
        ] {
            assert!((triangle_distance(p, &t) - d).abs() < 1e-12, "{p:?}");
        }
    }
}
