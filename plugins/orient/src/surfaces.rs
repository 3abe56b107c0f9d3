//! What the criteria measure on a mesh: facets with their areas and unit normals, the
//! flat faces they form, and the two costs of a build direction.

use std::collections::HashMap;

use lamina_api::Mesh;
use nalgebra::Vector3;

/// A facet reduced to what the criteria need.
#[derive(Debug, Clone, Copy)]
pub struct Facet {
    pub area: f64,
    pub normal: Vector3<f64>,
}

/// Facets of all meshes; degenerate ones carry no area and are left out.
pub fn facets(meshes: &[&Mesh]) -> Vec<Facet> {
    let mut out = Vec::new();
    for m in meshes {
        for i in 0..m.triangles.len() {
            let [a, b, c] = m.triangle(i);
            let n = (b - a).cross(&(c - a));
            let len = n.norm();
            if len > 0.0 && len.is_finite() {
                out.push(Facet {
                    area: len / 2.0,
                    normal: n / len,
                });
            }
        }
    }
    out
}

/// Flat faces: facets grouped by normal direction (to about 0.1°), with their summed
/// area and area-weighted mean normal, largest first. These are the "main surfaces"
/// of the criterion, and their normals are natural build directions.
pub fn flat_faces(facets: &[Facet]) -> Vec<Facet> {
    const STEPS: f64 = 500.0;
    let mut groups: HashMap<[i32; 3], (f64, Vector3<f64>)> = HashMap::new();
    for f in facets {
        let key = [
            (f.normal.x * STEPS).round() as i32,
            (f.normal.y * STEPS).round() as i32,
            (f.normal.z * STEPS).round() as i32,
        ];
        let g = groups.entry(key).or_insert((0.0, Vector3::zeros()));
        g.0 += f.area;
        g.1 += f.normal * f.area;
    }
    let mut faces: Vec<Facet> = groups
        .into_iter()
        .filter_map(|(_, (area, sum))| {
            let len = sum.norm();
            (len > 0.0).then(|| Facet {
                area,
                normal: sum / len,
            })
        })
        .collect();
    // Ties broken by the normal so the order does not depend on hashing.
    faces.sort_by(|a, b| {
        b.area
            .total_cmp(&a.area)
            .then(a.normal.x.total_cmp(&b.normal.x))
            .then(a.normal.y.total_cmp(&b.normal.y))
            .then(a.normal.z.total_cmp(&b.normal.z))
    });
    faces
}

/// Sum of area x the angle between each surface and the build direction `d` (a unit
/// vector): 0 for a wall parallel to `d`, pi/2 for a face lying flat on the table.
/// The angle between a plane and a line is asin |n . d|.
pub fn surface_angle(surfaces: &[Facet], d: &Vector3<f64>) -> f64 {
    surfaces
        .iter()
        .map(|f| f.area * f.normal.dot(d).abs().min(1.0).asin())
        .sum()
}

/// Extent of the vertices along `d`: the build height.
pub fn height(meshes: &[&Mesh], d: &Vector3<f64>) -> f64 {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for m in meshes {
        for v in &m.vertices {
            let h = v.coords.dot(d);
            lo = lo.min(h);
            hi = hi.max(h);
        }
    }
    if lo <= hi { hi - lo } else { 0.0 }
}

/// Area of the facets that would rest on the bed, facing down within about 1° and
/// lying within `tol` of the lowest point along `d`: the steadier base wins a tie.
pub fn bed_contact(meshes: &[&Mesh], d: &Vector3<f64>, tol: f64) -> f64 {
    let lo = meshes
        .iter()
        .flat_map(|m| m.vertices.iter())
        .map(|v| v.coords.dot(d))
        .fold(f64::INFINITY, f64::min);
    let mut area = 0.0;
    for m in meshes {
        for i in 0..m.triangles.len() {
            let [a, b, c] = m.triangle(i);
            let n = (b - a).cross(&(c - a));
            let len = n.norm();
            if len <= 0.0 || n.dot(d) / len > -0.9998 {
                continue;
            }
            if [a, b, c].iter().all(|p| p.coords.dot(d) - lo <= tol) {
                area += len / 2.0;
            }
        }
    }
    area
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use lamina_api::Point3;

    /// An axis-aligned box with outward winding.
    pub fn cuboid(x: f64, y: f64, z: f64) -> Mesh {
        let v: Vec<Point3> = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 != 0 { x } else { 0.0 },
                    if i & 2 != 0 { y } else { 0.0 },
                    if i & 4 != 0 { z } else { 0.0 },
                )
            })
            .collect();
        let t = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        Mesh::new("cuboid", v, t)
    }

    #[test]
    fn a_plate_standing_on_edge_has_the_least_surface_angle() {
        let m = cuboid(10.0, 2.0, 1.0);
        let f = facets(&[&m]);
        let faces = flat_faces(&f);
        assert_eq!(faces.len(), 6);
        assert!((faces[0].area - 20.0).abs() < 1e-12);
        let half_pi = std::f64::consts::FRAC_PI_2;
        // Up along z: the two 10 x 2 faces lie flat.
        assert!((surface_angle(&f, &Vector3::z()) - 2.0 * 20.0 * half_pi).abs() < 1e-9);
        // Up along x: only the two 2 x 1 ends lie flat.
        assert!((surface_angle(&f, &Vector3::x()) - 2.0 * 2.0 * half_pi).abs() < 1e-9);
        assert!((height(&[&m], &Vector3::x()) - 10.0).abs() < 1e-12);
        assert!((bed_contact(&[&m], &Vector3::z(), 1e-9) - 20.0).abs() < 1e-9);
        // A 45° direction in x-z: every face is at 45° or parallel.
        let d = Vector3::new(1.0, 0.0, 1.0).normalize();
        let quarter = std::f64::consts::FRAC_PI_4;
        let expect = 2.0 * (20.0 + 2.0) * quarter;
        assert!((surface_angle(&f, &d) - expect).abs() < 1e-9);
    }
}
