//! Turning a triangle soup (STL stores every corner again) into an indexed mesh:
//! vertices closer than a tolerance are merged and triangles that collapse are dropped.
//! Slicing relies on shared vertex indices to chain the cut segments into loops.

use lamina_core::{Mesh, Point3};

/// Triangles as three corners each, before welding.
#[derive(Debug, Default, Clone)]
pub struct Soup {
    pub triangles: Vec<[Point3; 3]>,
}

/// What welding changed.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct WeldReport {
    pub corners: usize,
    pub vertices: usize,
    pub degenerate: usize,
}

/// Welds a soup into an indexed mesh. Corners are snapped to a grid of cell
/// `tolerance`: corners in the same cell become one vertex, which merges the exact
/// duplicates STL files are made of and the tiny rounding differences some exporters
/// leave. Triangles with two equal corners after welding are dropped.
pub fn weld(name: &str, soup: &Soup, tolerance: f64) -> (Mesh, WeldReport) {
    let (mesh, report, _) = weld_kept(name, soup, tolerance);
    (mesh, report)
}

/// Welds a mesh, keeping its per-triangle materials in step with the triangles kept.
pub fn weld_mesh(mesh: &Mesh, tolerance: f64) -> Mesh {
    let soup = Soup {
        triangles: (0..mesh.triangles.len()).map(|i| mesh.triangle(i)).collect(),
    };
    let (mut out, _, kept) = weld_kept(&mesh.name, &soup, tolerance);
    if mesh.triangle_materials.len() == mesh.triangles.len() {
        out.triangle_materials = kept.iter().map(|&i| mesh.triangle_materials[i]).collect();
        out.material_names = mesh.material_names.clone();
    }
    out
}

/// [`weld`], also returning the indices of the soup triangles kept.
fn weld_kept(name: &str, soup: &Soup, tolerance: f64) -> (Mesh, WeldReport, Vec<usize>) {
    let inv = if tolerance > 0.0 { 1.0 / tolerance } else { 0.0 };
    let mut index: rustc_hash::FxHashMap<[i64; 3], u32> =
        rustc_hash::FxHashMap::with_capacity_and_hasher(soup.triangles.len(), Default::default());
    let mut vertices = Vec::with_capacity(soup.triangles.len() / 2 + 3);
    let mut triangles = Vec::with_capacity(soup.triangles.len());
    let mut kept = Vec::with_capacity(soup.triangles.len());
    let mut degenerate = 0;
    for (t, tri) in soup.triangles.iter().enumerate() {
        let mut ids = [0u32; 3];
        for (id, p) in ids.iter_mut().zip(tri) {
            let key = if inv > 0.0 {
                [
                    (p.x * inv).round() as i64,
                    (p.y * inv).round() as i64,
                    (p.z * inv).round() as i64,
                ]
            } else {
                [p.x.to_bits() as i64, p.y.to_bits() as i64, p.z.to_bits() as i64]
            };
            *id = *index.entry(key).or_insert_with(|| {
                vertices.push(*p);
                (vertices.len() - 1) as u32
            });
        }
        if ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2] {
            degenerate += 1;
            continue;
        }
        triangles.push(ids);
        kept.push(t);
    }
    let report = WeldReport {
        corners: soup.triangles.len() * 3,
        vertices: vertices.len(),
        degenerate,
    };
    let mut mesh = Mesh::new(name, vertices, triangles);
    if degenerate > 0 {
        mesh.warnings.push(format!(
            "{name}: dropped {degenerate} degenerate triangle(s) (corners closer than {tolerance} mm)"
        ));
    }
    (mesh, report, kept)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_corners_become_one_vertex_and_slivers_are_dropped() {
        let p = |x: f64, y: f64| Point3::new(x, y, 0.0);
        let soup = Soup {
            triangles: vec![
                [p(0.0, 0.0), p(1.0, 0.0), p(0.0, 1.0)],
                [p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0 + 1e-9)],
                [p(0.0, 0.0), p(1e-9, 0.0), p(0.5, 0.5)],
            ],
        };
        let (mesh, report) = weld("t", &soup, 1e-6);
        assert_eq!(mesh.vertices.len(), 5);
        assert_eq!(mesh.triangles.len(), 2);
        assert_eq!(report.degenerate, 1);
        assert_eq!(mesh.warnings.len(), 1);
    }
}
