//! Turning a triangle soup (STL stores every corner again) into an indexed mesh:
//! vertices closer than a tolerance are merged and triangles that collapse are dropped.
//! Slicing relies on shared vertex indices to chain the cut segments into loops.

use lamina_api::{Mesh, Point3, Warning};

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

/// Welds a soup into an indexed mesh. Corners are snapped to a grid of bucket
/// `tolerance`: corners in the same bucket become one vertex, which merges the exact
/// duplicates STL files are made of and the tiny rounding differences some exporters
/// leave. Triangles with two equal corners after welding are dropped.
pub fn weld(name: &str, soup: &Soup, tolerance: f64) -> (Mesh, WeldReport) {
    let mut welder = MeshWelder::new(tolerance, soup.triangles.len());
    welder.push(&soup.triangles);
    let (mesh, report, _) = welder.finish(name);
    (mesh, report)
}

/// Welds a mesh, keeping its per-triangle materials in step with the triangles kept.
pub fn weld_mesh(mesh: &Mesh, tolerance: f64) -> Mesh {
    let (mut out, _, dropped) = weld_with(&mesh.name, mesh.triangles.len(), |t| mesh.triangle(t), tolerance);
    if mesh.triangle_materials.len() == mesh.triangles.len() {
        let mut dropped = dropped.iter().peekable();
        out.triangle_materials = (0..mesh.triangles.len())
            .filter(|&t| dropped.next_if_eq(&&t).is_none())
            .map(|t| mesh.triangle_materials[t])
            .collect();
        out.material_names = mesh.material_names.clone();
    }
    out
}

/// [`weld`] of the `count` triangles `triangle(0..count)`, also returning the indices of
/// the triangles dropped, in increasing order.
fn weld_with(
    name: &str,
    count: usize,
    triangle: impl Fn(usize) -> [Point3; 3],
    tolerance: f64,
) -> (Mesh, WeldReport, Vec<usize>) {
    let mut welder = MeshWelder::new(tolerance, count);
    let mut block = Vec::with_capacity(MeshWelder::BLOCK);
    for start in (0..count).step_by(MeshWelder::BLOCK) {
        block.clear();
        block.extend((start..count.min(start + MeshWelder::BLOCK)).map(&triangle));
        welder.push(&block);
    }
    welder.finish(name)
}

/// Welds triangles as they come, so that a reader can weld while it reads without
/// building a [`Soup`] first (a soup of a large file is several times the file).
pub(crate) struct MeshWelder {
    welder: Welder,
    tolerance: f64,
    triangles: Vec<[u32; 3]>,
    dropped: Vec<usize>,
    count: usize,
    ids: Vec<u32>,
}

impl MeshWelder {
    /// Triangles welded together at best: a block's table lookups overlap in memory.
    pub(crate) const BLOCK: usize = 256;

    /// A welder for about `triangles` triangles (the storage is sized for them).
    pub(crate) fn new(tolerance: f64, triangles: usize) -> Self {
        Self {
            welder: Welder::new(Grid::new(tolerance), 3 * triangles),
            tolerance,
            triangles: Vec::with_capacity(triangles),
            dropped: Vec::new(),
            count: 0,
            ids: Vec::new(),
        }
    }

    /// Welds the next triangles (best in blocks of [`Self::BLOCK`]).
    pub(crate) fn push(&mut self, triangles: &[[Point3; 3]]) {
        for block in triangles.chunks(Self::BLOCK) {
            self.welder.ids(block.as_flattened(), &mut self.ids);
            for tri in self.ids.chunks_exact(3) {
                let tri = [tri[0], tri[1], tri[2]];
                if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                    self.dropped.push(self.count);
                } else {
                    self.triangles.push(tri);
                }
                self.count += 1;
            }
        }
    }

    /// The mesh, what welding changed, and the indices of the triangles dropped, in
    /// increasing order.
    pub(crate) fn finish(self, name: &str) -> (Mesh, WeldReport, Vec<usize>) {
        let degenerate = self.dropped.len();
        let vertices = self.welder.into_vertices();
        let report = WeldReport {
            corners: 3 * self.count,
            vertices: vertices.len(),
            degenerate,
        };
        let mut mesh = Mesh::new(name, vertices, self.triangles);
        if degenerate > 0 {
            mesh.warnings.push(Warning::new(
                "degenerate-triangles-dropped",
                format!(
                    "{name}: dropped {degenerate} degenerate triangle(s) (corners closer than {} mm)",
                    self.tolerance
                ),
            ));
        }
        (mesh, report, self.dropped)
    }
}

/// Gives every corner its vertex: corners with the same key share the vertex made from
/// the first of them, numbered in order of first appearance.
///
/// The table is open addressing over one word per slot (a tag from the key's hash and
/// the vertex index; the keys themselves are kept once, by vertex), sized from the
/// corner count for the usual six corners per vertex: a table eight times smaller than
/// a general map of keys stays in the processor's caches longer. Even so, a new vertex
/// is nearly always a miss there, so corners come in blocks whose keys are hashed and
/// whose slots are read first, all in one tight loop: the misses overlap instead of
/// following each other. (A cache of exact coordinates in front of the table, which
/// answers repeated corners, costs more than it saves once the table lookups overlap.)
struct Welder {
    grid: Grid,
    /// `0` for empty, else the key hash's low half above `vertex + 1`.
    slots: Vec<u64>,
    /// The key of each vertex.
    keys: Vec<[i64; 3]>,
    vertices: Vec<Point3>,
}

impl Welder {
    fn new(grid: Grid, corners: usize) -> Self {
        let expected = corners / 6 + 1;
        Self {
            grid,
            slots: vec![0; (2 * expected).next_power_of_two().max(16)],
            keys: Vec::with_capacity(expected),
            vertices: Vec::with_capacity(expected),
        }
    }

    /// The vertices of `corners`, in `ids`.
    fn ids(&mut self, corners: &[Point3], ids: &mut Vec<u32>) {
        ids.clear();
        for chunk in corners.chunks(3 * MeshWelder::BLOCK) {
            let mask = self.slots.len() - 1;
            let mut keys = [([0i64; 3], 0u64); 3 * MeshWelder::BLOCK];
            let keys = &mut keys[..chunk.len()];
            for (p, k) in chunk.iter().zip(keys.iter_mut()) {
                let key = self.grid.key(p);
                *k = (key, mix(key.map(|k| k as u64)));
            }
            let touched = keys.iter().fold(0u64, |t, &(_, h)| {
                t.wrapping_add(self.slots[(h >> 32) as usize & mask])
            });
            std::hint::black_box(touched);
            for (p, &(key, h)) in chunk.iter().zip(keys.iter()) {
                let id = self.lookup(key, h, p);
                ids.push(id);
            }
        }
    }

    /// The vertex of `key` (whose hash is `h`), made from `p` if the key is new.
    fn lookup(&mut self, key: [i64; 3], h: u64, p: &Point3) -> u32 {
        let tag = h << 32;
        let mask = self.slots.len() - 1;
        let mut i = (h >> 32) as usize & mask;
        loop {
            let s = self.slots[i];
            if s == 0 {
                break;
            }
            if s & !0xFFFF_FFFF == tag {
                let v = (s as u32 - 1) as usize;
                if self.keys[v] == key {
                    return v as u32;
                }
            }
            i = (i + 1) & mask;
        }
        let v = self.vertices.len();
        self.slots[i] = tag | (v as u64 + 1);
        self.keys.push(key);
        self.vertices.push(*p);
        if 2 * self.vertices.len() > self.slots.len() {
            self.grow();
        }
        v as u32
    }

    /// Doubles the table (more vertices than the corner count suggested).
    fn grow(&mut self) {
        let mut slots = vec![0u64; 2 * self.slots.len()];
        let mask = slots.len() - 1;
        for (v, key) in self.keys.iter().enumerate() {
            let h = mix(key.map(|k| k as u64));
            let mut i = (h >> 32) as usize & mask;
            while slots[i] != 0 {
                i = (i + 1) & mask;
            }
            slots[i] = (h << 32) | (v as u64 + 1);
        }
        self.slots = slots;
    }

    fn into_vertices(self) -> Vec<Point3> {
        self.vertices
    }
}

/// The welding grid: a corner's key is its bucket, or its exact coordinates when the
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
            let bucket = [p.x * self.inv, p.y * self.inv, p.z * self.inv];
            // A bucket finer than the coordinates' own spacing (past 2^52 buckets from the
            // origin) merges nothing that exact equality does not, and past i64 it would
            // merge everything beyond into one corner (a weld of 1e-18 mm made slivers
            // of most of a boat). Such a corner is keyed by its exact coordinates: at
            // least one component is then a float's bits beyond 2^52, which no bucket
            // reaches, so the two kinds of key never meet.
            if bucket.iter().all(|c| c.abs() < EXACT) {
                return bucket.map(round);
            }
        }
        [p.x.to_bits() as i64, p.y.to_bits() as i64, p.z.to_bits() as i64]
    }
}

/// 2^52: from here on every f64 is whole.
const EXACT: f64 = 4_503_599_627_370_496.0;

/// `x.round() as i64` (half away from zero, saturating) without the call into libm that
/// `f64::round` makes on baseline x86-64; welding rounds three times per corner.
fn round(x: f64) -> i64 {
    if x.abs() < EXACT {
        let t = x as i64;
        // Exact: `t` is `x` without its fraction. The fraction is as likely to round
        // up as down, so it is added as a flag, not branched on.
        let fraction = x - t as f64;
        t + i64::from(fraction >= 0.5) - i64::from(fraction <= -0.5)
    } else {
        x as i64
    }
}

/// Mixes three words into 64 well-spread bits (the table takes both halves).
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
    fn a_weld_finer_than_the_coordinates_merges_only_equal_corners() {
        // Corners tens of millimetres out, so that a bucket of 1e-18 mm would number
        // past i64 (and saturate into one) if it were used.
        let p = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
        let mut triangles = Vec::new();
        for i in 0..50 {
            let x = 20.0 + i as f64 * 0.5;
            triangles.push([p(x, 30.0, 5.0), p(x + 0.5, 30.0, 5.0), p(x, 31.0, 5.0)]);
            triangles.push([p(x + 0.5, 30.0, 5.0), p(x + 0.5, 31.0, 5.0), p(x, 31.0, 5.0)]);
        }
        let soup = Soup { triangles };
        let (exact, _) = weld("t", &soup, 0.0);
        for tolerance in [1e-18, 1e-30, f64::MIN_POSITIVE] {
            let (mesh, report) = weld("t", &soup, tolerance);
            assert_eq!(mesh.triangles.len(), 100, "{tolerance}");
            assert_eq!(mesh.vertices.len(), exact.vertices.len(), "{tolerance}");
            assert_eq!(report.degenerate, 0, "{tolerance}");
        }
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
        let mut rng = fastrand::Rng::with_seed(0x1234_5678_9abc_def0);
        for _ in 0..100_000 {
            let x = rng.u64(..);
            values.push(f64::from_bits(x));
            values.push((x % 2_000_001) as f64 / 1000.0 - 1000.0);
        }
        for v in values {
            assert_eq!(round(v), v.round() as i64, "{v:e}");
        }
    }

    /// The blocked table lookup equals one exact map, vertex order included.
    #[test]
    fn table_ids_are_the_exact_ones() {
        let mut rng = fastrand::Rng::with_seed(7);
        let mut next = move || rng.u64(..);
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
            // Sized for far fewer vertices than there are, so that the table grows.
            let mut welder = Welder::new(grid, 600);
            let mut ids = Vec::new();
            for block in corners.chunks(3 * MeshWelder::BLOCK - 2) {
                let mut some = Vec::new();
                welder.ids(block, &mut some);
                ids.extend(some);
            }
            let vertices = welder.into_vertices();
            let mut reference: std::collections::HashMap<[i64; 3], u32> = Default::default();
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
