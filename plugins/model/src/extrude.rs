//! Extrusion of a planar profile into a closed, consistently wound (outward) triangle
//! mesh: walls from each ring's edges, caps triangulated with earcut.

use lamina_core::{Error, Mesh, Point3, Polygon, Result};

/// Extrudes `profile` from `z0` to `z1` (z1 > z0). The mesh is watertight: every edge
/// is shared by exactly two triangles.
pub fn extrude(name: &str, profile: &Polygon, z0: f64, z1: f64) -> Result<Mesh> {
    if z1.is_nan() || z0.is_nan() || z1 <= z0 {
        return Err(Error::stage(
            name,
            format!("extrusion height {z0}..{z1} is empty"),
        ));
    }
    let rings: Vec<&lamina_core::Contour> = profile.contours().collect();
    let mut flat: Vec<[f64; 2]> = Vec::new();
    let mut hole_starts: Vec<u32> = Vec::new();
    for (i, ring) in rings.iter().enumerate() {
        if ring.len() < 3 {
            return Err(Error::stage(name, "a profile ring has fewer than three points"));
        }
        if i > 0 {
            hole_starts.push(flat.len() as u32);
        }
        flat.extend(ring.points.iter().map(|p| [p.x, p.y]));
    }
    let n = flat.len() as u32;
    let mut vertices: Vec<Point3> = Vec::with_capacity(2 * flat.len());
    vertices.extend(flat.iter().map(|p| Point3::new(p[0], p[1], z0)));
    vertices.extend(flat.iter().map(|p| Point3::new(p[0], p[1], z1)));

    let mut cap: Vec<u32> = Vec::new();
    earcut::Earcut::new().earcut(flat.iter().copied(), &hole_starts, &mut cap);
    let mut triangles = Vec::with_capacity(cap.len() / 3 * 2 + 2 * flat.len());
    for t in cap.chunks_exact(3) {
        let (a, b, c) = (flat[t[0] as usize], flat[t[1] as usize], flat[t[2] as usize]);
        let ccw = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) > 0.0;
        let (i, j, k) = if ccw {
            (t[0], t[1], t[2])
        } else {
            (t[0], t[2], t[1])
        };
        triangles.push([i + n, j + n, k + n]); // top faces up
        triangles.push([i, k, j]); // bottom faces down
    }
    let mut start = 0u32;
    for ring in &rings {
        let len = ring.len() as u32;
        for e in 0..len {
            let a = start + e;
            let b = start + (e + 1) % len;
            triangles.push([a, b, b + n]);
            triangles.push([a, b + n, a + n]);
        }
        start += len;
    }
    Ok(Mesh::new(name, vertices, triangles))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::{circle, polygon};
    use lamina_core::Point2;
    use std::collections::HashMap;

    #[test]
    fn extruded_tube_is_watertight_with_the_right_volume() {
        let p = polygon(
            circle(Point2::origin(), 10.0, 64),
            vec![circle(Point2::origin(), 6.0, 64)],
        );
        let m = extrude("tube", &p, 0.0, 5.0).expect("extrudes");
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
            }
        }
        // Each undirected edge used once in each direction: closed and consistently wound.
        assert!(edges.values().all(|&v| v == 0));
        let expected = p.area() * 5.0;
        assert!((m.signed_volume() - expected).abs() < 1e-6 * expected);
    }
}
