//! The holes of an open mesh, for closing the cuts through them.
//!
//! Where a mesh misses triangles, a plane through the hole cuts a chain that stops at
//! the hole's rim: at an edge only one triangle uses. The chain's ends belong together
//! when they lie on the same rim, however far apart they are (a missing wall triangle
//! can leave a gap of millimetres on a part of any size), and the straight segment
//! between them is the cut of the flattest patch that fills the hole. A fixed distance
//! limit cannot tell that apart from two sheets that merely come close.
//!
//! A rim is also all a stray sheet has (a fin, an open cylinder standing in or beside
//! the part): the chain it leaves ends on its own rim too, but closing it would invent a
//! solid. What tells them apart is the mesh's generalised winding number just inside
//! the chain, on the side the triangles' winding calls solid: about 1 beside the wall
//! of a solid with a hole elsewhere (the hole subtends only its own solid angle), and
//! about 1/2 beside a sheet, which surrounds nothing.

use lamina_api::{Mesh, Point2, Point3};
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// The rims of a mesh's holes: each edge that one triangle alone uses, by the rim
/// (connected set of such edges) it belongs to.
#[derive(Debug, Default)]
pub struct Holes {
    rim_of_edge: FxHashMap<u64, u32>,
    /// Each rim's length (mm, in space).
    perimeters: Vec<f64>,
}

impl Holes {
    /// The holes of `mesh`, found from its triangles' vertex indices alone: a closed
    /// mesh has none and costs two passes over its edges ([`lone_edges`]).
    pub fn of(mesh: &Mesh) -> Self {
        let lone = lone_edges(mesh);
        if lone.is_empty() {
            return Self::default();
        }
        // Rims are the connected sets of lone edges, joined at shared vertices.
        let mut sets = Sets::default();
        for &k in &lone {
            let (a, b) = ends(k);
            sets.union(a, b);
        }
        let mut rim_ids: FxHashMap<u32, u32> = FxHashMap::default();
        let mut perimeters = Vec::new();
        let mut rim_of_edge = FxHashMap::with_capacity_and_hasher(lone.len(), Default::default());
        for &k in &lone {
            let (a, b) = ends(k);
            let root = sets.find(a);
            let next = rim_ids.len() as u32;
            let id = *rim_ids.entry(root).or_insert(next);
            if id as usize == perimeters.len() {
                perimeters.push(0.0);
            }
            let (p, q) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
            perimeters[id as usize] += (p - q).norm();
            rim_of_edge.insert(k, id);
        }
        Self {
            rim_of_edge,
            perimeters,
        }
    }

    /// The rim the edge `key` lies on, when one triangle alone uses it.
    pub fn rim(&self, key: u64) -> Option<u32> {
        self.rim_of_edge.get(&key).copied()
    }

    /// How many holes the mesh has.
    pub fn count(&self) -> usize {
        self.perimeters.len()
    }

    /// The length of the longest rim (mm), 0 for a closed mesh.
    pub fn longest(&self) -> f64 {
        self.perimeters.iter().copied().fold(0.0, f64::max)
    }
}

/// The keys of the edges exactly one triangle uses, in increasing order.
///
/// Each edge is filed under its lower vertex (counted, then placed: one array in
/// rows by vertex), and each row, about six edges long, is sorted on its own: a
/// counting sort by the keys' high half, where sorting every key of a mesh of
/// hundreds of thousands of triangles took a fifth of a slicing run. Edges whose
/// ends are one vertex, and corners that name no vertex of the mesh, count for
/// nothing.
fn lone_edges(mesh: &Mesh) -> Vec<u64> {
    let n = mesh.vertices.len();
    let edges = || {
        mesh.triangles
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .filter(move |&(a, b)| a != b && (a as usize) < n && (b as usize) < n)
            .map(|(a, b)| if a < b { (a, b) } else { (b, a) })
    };
    let mut start = vec![0u32; n + 1];
    for (lo, _) in edges() {
        start[lo as usize + 1] += 1;
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let mut next = start.clone();
    let mut other = vec![0u32; start[n] as usize];
    for (lo, hi) in edges() {
        let slot = &mut next[lo as usize];
        other[*slot as usize] = hi;
        *slot += 1;
    }
    let mut lone = Vec::new();
    for v in 0..n {
        let row = &mut other[start[v] as usize..start[v + 1] as usize];
        row.sort_unstable();
        for (k, &hi) in row.iter().enumerate() {
            let twin = (k > 0 && row[k - 1] == hi) || row.get(k + 1) == Some(&hi);
            if !twin {
                lone.push(edge_key(v as u32, hi));
            }
        }
    }
    lone
}

/// The key of the edge between vertices `a` and `b`, whichever way it runs.
pub(crate) fn edge_key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    (u64::from(lo) << 32) | u64::from(hi)
}

fn ends(key: u64) -> (u32, u32) {
    ((key >> 32) as u32, key as u32)
}

/// Disjoint sets of vertex indices, for the few a mesh's rims hold.
#[derive(Default)]
struct Sets {
    parent: FxHashMap<u32, u32>,
}

impl Sets {
    fn find(&mut self, v: u32) -> u32 {
        let mut root = v;
        while let Some(&p) = self.parent.get(&root) {
            if p == root {
                break;
            }
            root = p;
        }
        // Path compression: every vertex on the way points at the root.
        let mut at = v;
        while at != root {
            let next = self.parent.insert(at, root).unwrap_or(root);
            at = next;
        }
        self.parent.entry(root).or_insert(root);
        root
    }

    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            // The smaller index roots the set, so that rims are numbered the same
            // however the edges came.
            let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
            self.parent.insert(hi, lo);
        }
    }
}

/// The generalised winding number of `mesh` at `p`: the solid angle its triangles
/// subtend there over 4π, each signed by its winding (Van Oosterom and Strackee's
/// formula). 1 inside a closed mesh wound outward, 0 outside, fractions near holes and
/// sheets.
pub fn winding_number(mesh: &Mesh, p: Point3) -> f64 {
    // Summed by fixed chunks, then in order: the same number whatever the threads.
    let chunks: Vec<f64> = mesh
        .triangles
        .par_chunks(8192)
        .map(|chunk| {
            chunk
                .iter()
                .map(|&[a, b, c]| {
                    let v = &mesh.vertices;
                    let (a, b, c) = (v[a as usize] - p, v[b as usize] - p, v[c as usize] - p);
                    let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
                    let det = a.dot(&b.cross(&c));
                    let div = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
                    2.0 * det.atan2(div)
                })
                .sum::<f64>()
        })
        .collect();
    chunks.iter().sum::<f64>() / (4.0 * std::f64::consts::PI)
}

/// A point just inside `chain` (each step with the solid on its left) at height `z`:
/// beside the middle of its middle step, `reach` to the left. Where a solid's wall is,
/// that is inside the solid for any `reach` thinner than the wall.
pub fn probe(chain: &[Point2], z: f64, reach: f64) -> Option<Point3> {
    if chain.len() < 2 {
        return None;
    }
    let i = chain.len() / 2;
    let (a, b) = (chain[i - 1], chain[i]);
    let d = b - a;
    let len = d.norm();
    if len <= 0.0 || !len.is_finite() {
        return None;
    }
    let m = a + 0.5 * d;
    Some(Point3::new(m.x - d.y / len * reach, m.y + d.x / len * reach, z))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis-aligned box of 12 outward triangles, without the triangles `missing`.
    fn cube_without(missing: &[usize]) -> Mesh {
        let v: Vec<Point3> = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 != 0 { 2.0 } else { 0.0 },
                    if i & 2 != 0 { 2.0 } else { 0.0 },
                    if i & 4 != 0 { 2.0 } else { 0.0 },
                )
            })
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let t: Vec<[u32; 3]> = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .enumerate()
            .filter(|(i, _)| !missing.contains(i))
            .map(|(_, t)| t)
            .collect();
        Mesh::new("cube", v, t)
    }

    #[test]
    fn a_closed_mesh_has_no_holes() {
        let h = Holes::of(&cube_without(&[]));
        assert_eq!(h.count(), 0);
        assert_eq!(h.longest(), 0.0);
    }

    #[test]
    fn a_missing_triangle_is_one_hole_whose_rim_is_its_three_edges() {
        let h = Holes::of(&cube_without(&[4]));
        assert_eq!(h.count(), 1);
        // Two sides of 2 mm and the diagonal.
        assert!(
            (h.longest() - (4.0 + 8f64.sqrt())).abs() < 1e-12,
            "{}",
            h.longest()
        );
        assert_eq!(h.rim(edge_key(0, 1)), Some(0));
        assert_eq!(h.rim(edge_key(0, 5)), Some(0));
        assert_eq!(h.rim(edge_key(0, 2)), None);
        // Two holes apart are two rims.
        let two = Holes::of(&cube_without(&[4, 7]));
        assert_eq!(two.count(), 2);
        assert_ne!(two.rim(edge_key(0, 1)), two.rim(edge_key(2, 3)));
    }

    #[test]
    fn lone_edges_are_the_edges_one_triangle_alone_uses_in_key_order() {
        // A box missing two triangles, with a triangle listed twice (its edges used
        // three or four times), one folded onto an edge (two corners one vertex) and one
        // naming a vertex the mesh lacks.
        let mut mesh = cube_without(&[4, 9]);
        mesh.triangles.push(mesh.triangles[0]);
        mesh.triangles.push([2, 2, 6]);
        mesh.triangles.push([1, 3, 99]);
        // Every edge counted on its own, the mesh's own corners only.
        let mut uses: std::collections::BTreeMap<u64, usize> = Default::default();
        for &[a, b, c] in &mesh.triangles {
            for (p, q) in [(a, b), (b, c), (c, a)] {
                if p != q && p < 8 && q < 8 {
                    *uses.entry(edge_key(p, q)).or_default() += 1;
                }
            }
        }
        let expected: Vec<u64> = uses
            .into_iter()
            .filter(|&(_, n)| n == 1)
            .map(|(k, _)| k)
            .collect();
        assert_eq!(expected.len(), 4, "{expected:?}");
        assert_eq!(lone_edges(&mesh), expected);
        assert!(lone_edges(&cube_without(&[])).is_empty());
    }

    #[test]
    fn the_winding_number_is_one_inside_nought_outside_and_about_a_half_by_a_sheet() {
        let cube = cube_without(&[]);
        assert!((winding_number(&cube, Point3::new(1.0, 1.0, 1.0)) - 1.0).abs() < 1e-9);
        assert!(winding_number(&cube, Point3::new(3.0, 1.0, 1.0)).abs() < 1e-9);
        // One triangle missing from a face: inside reads nearly 1 away from the hole.
        let holed = cube_without(&[4]);
        let w = winding_number(&holed, Point3::new(1.0, 1.9, 1.0));
        assert!(w > 0.9 && w < 1.0, "{w}");
        // Just behind a lone face: a half.
        let sheet = Mesh::new(
            "sheet",
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(10.0, 0.0, 0.0),
                Point3::new(10.0, 0.0, 10.0),
                Point3::new(0.0, 0.0, 10.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let w = winding_number(&sheet, Point3::new(5.0, 0.001, 5.0));
        assert!((w.abs() - 0.5).abs() < 0.01, "{w}");
    }

    #[test]
    fn a_probe_lies_left_of_the_chains_middle_step() {
        let chain = [
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(2.0, 0.0),
        ];
        let p = probe(&chain, 3.0, 0.01).expect("a probe");
        assert!((p - Point3::new(0.5, 0.01, 3.0)).norm() < 1e-12, "{p}");
        assert!(probe(&chain[..1], 0.0, 0.01).is_none());
    }
}
