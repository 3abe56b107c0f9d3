//! Extrusion of a planar profile into a closed, consistently wound (outward) triangle
//! mesh: walls from each ring's edges, caps triangulated with earcut.

use lamina_api::{Error, Mesh, Point3, Polygon, Result};

/// Extrudes `profile` from `z0` to `z1` (z1 > z0). The mesh is watertight: every edge
/// is shared by exactly two triangles.
pub fn extrude(name: &str, profile: &Polygon, z0: f64, z1: f64) -> Result<Mesh> {
    if z1.is_nan() || z0.is_nan() || z1 <= z0 {
        return Err(Error::stage(
            name,
            format!("extrusion height {z0}..{z1} is empty"),
        ));
    }
    let rings: Vec<&lamina_api::Contour> = profile.contours().collect();
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

/// The first defect that keeps `mesh` from being a closed, consistently wound surface,
/// or `None`: every directed edge must occur exactly once and its reverse exactly once,
/// so every edge has two triangles that agree on the inside. (A balance of the two
/// directions alone would accept an edge shared by four triangles.)
pub fn edge_defect(mesh: &Mesh) -> Option<String> {
    let mut directed: rustc_hash::FxHashMap<(u32, u32), u32> = rustc_hash::FxHashMap::default();
    for (i, t) in mesh.triangles.iter().enumerate() {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return Some(format!("triangle {i} repeats a vertex"));
        }
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &directed {
        if n > 1 {
            return Some(format!("edge {a}-{b} is used {n} times in the same direction"));
        }
        if !directed.contains_key(&(b, a)) {
            return Some(format!("edge {a}-{b} has no triangle on its other side"));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::polygon;
    use lamina_api::Contour;
    use lamina_api::Point2;

    #[test]
    fn extruded_tube_is_watertight_with_the_right_volume() {
        let p = polygon(
            Contour::circle(Point2::origin(), 10.0, 64),
            vec![Contour::circle(Point2::origin(), 6.0, 64)],
        );
        let m = extrude("tube", &p, 0.0, 5.0).expect("extrudes");
        assert_eq!(edge_defect(&m), None);
        let expected = p.area() * 5.0;
        assert!((m.signed_volume() - expected).abs() < 1e-6 * expected);
    }

    #[test]
    fn edge_defects_are_found() {
        let p = polygon(Contour::circle(Point2::origin(), 1.0, 8), vec![]);
        let mut m = extrude("rod", &p, 0.0, 1.0).expect("extrudes");
        let last = m.triangles.len() - 1;
        m.triangles[last].swap(0, 1);
        assert!(edge_defect(&m).is_some(), "a flipped triangle");
        m.triangles.pop();
        assert!(edge_defect(&m).expect("open").contains("other side"));
    }
}
