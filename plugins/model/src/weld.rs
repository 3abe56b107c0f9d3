//! Turning a triangle soup (STL stores every corner again) into an indexed mesh:
//! vertices closer than a tolerance are merged and triangles that collapse are dropped.
//! Slicing relies on shared vertex indices to chain the cut segments into loops.

use lamina_core::{Mesh, Point3};
use rustc_hash::FxHashMap;

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
    let corners = soup.triangles.as_flattened();
    let grid = Grid::new(tolerance);
    let mut vertices = Vec::with_capacity(soup.triangles.len() / 2 + 3);
    let ids = vertex_ids(corners, grid, &mut vertices);
    let mut triangles = Vec::with_capacity(soup.triangles.len());
    let mut kept = Vec::with_capacity(soup.triangles.len());
    let mut degenerate = 0;
    for (t, tri) in ids.chunks_exact(3).enumerate() {
        let tri = [tri[0], tri[1], tri[2]];
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            degenerate += 1;
            continue;
        }
        triangles.push(tri);
        kept.push(t);
    }
    let report = WeldReport {
        corners: corners.len(),
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

/// The vertex index of every corner: corners with the same key share the vertex made
/// from the first of them, numbered in order of first appearance.
///
/// A corner is nearly always a bit-for-bit copy of one met a few triangles earlier (STL
/// repeats every shared corner), so a small cache from exact coordinates to vertex,
/// which stays in the processor's cache, answers most corners before the map from key
/// to vertex, which outgrows it on large meshes, is asked. Equal coordinates have equal
/// keys, so the cache never changes an answer.
fn vertex_ids(corners: &[Point3], grid: Grid, vertices: &mut Vec<Point3>) -> Vec<u32> {
    const CACHE_BITS: u32 = 13;
    const EMPTY: u32 = u32::MAX;
    let mut cache = vec![([0u64; 3], EMPTY); 1 << CACHE_BITS];
    let mut seen: FxHashMap<[i64; 3], u32> =
        FxHashMap::with_capacity_and_hasher(corners.len() / 4 + 1, Default::default());
    corners
        .iter()
        .map(|p| {
            let b = bits(p);
            let slot = &mut cache[(mix(b) >> (64 - CACHE_BITS)) as usize];
            if slot.1 != EMPTY && slot.0 == b {
                return slot.1;
            }
            let id = *seen.entry(grid.key(p)).or_insert_with(|| {
                vertices.push(*p);
                (vertices.len() - 1) as u32
            });
            *slot = (b, id);
            id
        })
        .collect()
}

/// The welding grid: a corner's key is its cell, or its exact coordinates when the
/// tolerance is zero.
#[derive(Clone, Copy)]
struct Grid {
    inv: f64,
}

impl Grid {
    fn new(tolerance: f64) -> Self {
        Self {
            inv: if tolerance > 0.0 { 1.0 / tolerance } else { 0.0 },
        }
    }

    fn key(self, p: &Point3) -> [i64; 3] {
        if self.inv > 0.0 {
            [
                round(p.x * self.inv),
                round(p.y * self.inv),
                round(p.z * self.inv),
            ]
        } else {
            [p.x.to_bits() as i64, p.y.to_bits() as i64, p.z.to_bits() as i64]
        }
    }
}

/// `x.round() as i64` (half away from zero, saturating) without the call into libm that
/// `f64::round` makes on baseline x86-64; welding rounds three times per corner.
fn round(x: f64) -> i64 {
    const EXACT: f64 = 4_503_599_627_370_496.0; // 2^52: from here on every f64 is whole
    if x.abs() < EXACT {
        let t = x as i64;
        // Exact: `t` is `x` without its fraction.
        let fraction = x - t as f64;
        if fraction >= 0.5 {
            t + 1
        } else if fraction <= -0.5 {
            t - 1
        } else {
            t
        }
    } else {
        x as i64
    }
}

fn bits(p: &Point3) -> [u64; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

/// Mixes three words into 64 well-spread bits (the cache takes the top bits).
fn mix(words: [u64; 3]) -> u64 {
    let mut h = 0x9E37_79B9_7F4A_7C15u64;
    for v in words {
        h = (h ^ v).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 31;
    }
    h = (h ^ (h >> 33)).wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^ (h >> 33)
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

    #[test]
    fn round_matches_std() {
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            4_503_599_627_370_496.0,
            1e19,
            -1e19,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN_POSITIVE,
        ];
        let mut x = 0x1234_5678_9abc_def0u64;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            values.push(f64::from_bits(x));
            values.push((x % 2_000_001) as f64 / 1000.0 - 1000.0);
        }
        for v in values {
            assert_eq!(round(v), v.round() as i64, "{v:e}");
        }
    }

    /// The cached lookup equals one exact map, vertex order included.
    #[test]
    fn cached_ids_are_the_exact_ones() {
        let mut x = 7u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        // A grid of points, reused by many triangles, some nudged below the tolerance,
        // some -0.0 where others are 0.0.
        let points: Vec<Point3> = (0..20_000)
            .map(|i| {
                Point3::new(
                    (i % 37) as f64 * 0.1,
                    (i / 37 % 29) as f64 * 0.1,
                    (i / 1073) as f64 * 0.1,
                )
            })
            .collect();
        let corners: Vec<Point3> = (0..90_000)
            .map(|_| {
                let p = points[(next() % points.len() as u64) as usize];
                let nudge = (next() % 3) as f64 * 1e-7;
                let sign = if next() % 2 == 0 { 1.0 } else { -1.0 };
                Point3::new(p.x + nudge, p.y * sign, p.z - nudge)
            })
            .collect();
        for tolerance in [1e-5, 0.0, 0.25] {
            let grid = Grid::new(tolerance);
            let mut vertices = Vec::new();
            let ids = vertex_ids(&corners, grid, &mut vertices);
            let mut reference: FxHashMap<[i64; 3], u32> = FxHashMap::default();
            let mut expected_vertices = Vec::new();
            let expected: Vec<u32> = corners
                .iter()
                .map(|p| {
                    *reference.entry(grid.key(p)).or_insert_with(|| {
                        expected_vertices.push(*p);
                        (expected_vertices.len() - 1) as u32
                    })
                })
                .collect();
            assert_eq!(ids, expected);
            assert_eq!(vertices, expected_vertices);
        }
    }
}
