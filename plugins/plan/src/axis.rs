//! Variable-width beads along the centre line of thin regions: what contour-parallel
//! loops of one width leave open (the medial band of a region, the corners between two
//! loops). The centre line is the chordal axis of a constrained Delaunay triangulation
//! of the region (Prasad's chordal axis transform): every interior edge of the
//! triangulation is a chord across the region, the axis joins the chords' midpoints,
//! and the chord's length is the region's local width.
//!
//! Each triangle gives its own area to the axis segment that crosses it (a sleeve: the
//! segment between its two chords' midpoints; a junction: a third to each of the three
//! segments to its centroid; an end: the segment from its chord to its apex), so the
//! beads fill exactly the region's area: a segment's width is its area over its
//! length. This is the role of Arachne's variable-width extrusions in PrusaSlicer and
//! Cura, computed from a triangulation rather than a Voronoi diagram.

use std::collections::HashMap;

use lamina_api::Point2;
use lamina_geom::ring::ring_area;
use spade::handles::FixedFaceHandle;
use spade::{ConstrainedDelaunayTriangulation, Triangulation};

use crate::bead::Bead;

/// Most axis segments merged into one straight run (the merge test is quadratic in
/// the run's length).
const MAX_RUN: usize = 32;

type Cdt = ConstrainedDelaunayTriangulation<spade::Point2<f64>>;

/// Largest number of boundary vertices triangulated for one shape; a residue larger
/// than this is left unfilled (and so counted as under-fill) rather than stalling a
/// layer.
const MAX_VERTICES: usize = 400_000;

/// The beads along the centre lines of `shapes` (each an outer ring then its holes,
/// rings open, any orientation). Boundary edges are split to at most `max_edge` so
/// that chords run across the region rather than along it; axis vertices that stray
/// less than `tol` from a straight run are merged; the ends of an open bead narrower
/// than `floor` (mm) are laid by the segment next to them ([`trim_ends`]).
pub fn centre_beads(shapes: &[Vec<Vec<[f64; 2]>>], max_edge: f64, tol: f64, floor: f64) -> Vec<Bead> {
    let mut out = Vec::new();
    for shape in shapes {
        centre_beads_of(shape, Lay { max_edge, tol, floor }, &mut out);
    }
    out
}

/// How the centre beads are laid: the longest boundary edge triangulated, the
/// straightness tolerance and the narrowest end kept (see [`centre_beads`]).
#[derive(Clone, Copy)]
struct Lay {
    max_edge: f64,
    tol: f64,
    floor: f64,
}

fn centre_beads_of(shape: &[Vec<[f64; 2]>], lay: Lay, out: &mut Vec<Bead>) {
    let Lay { max_edge, tol, floor } = lay;
    let shape: Vec<Vec<[f64; 2]>> = shape.iter().map(|r| clean(r)).filter(|r| r.len() >= 3).collect();
    let shape = &shape[..];
    if let [ring] = shape
        && ring.len() == 3
        && (0..ring.len()).all(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
            (b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) <= 4.0 * max_edge * max_edge
        })
    {
        out.extend(small_bead(ring));
        return;
    }
    let mut vertices: Vec<spade::Point2<f64>> = Vec::new();
    let mut edges: Vec<[usize; 2]> = Vec::new();
    let mut starts: Vec<usize> = Vec::new();
    for ring in shape.iter().filter(|r| r.len() >= 3) {
        let start = vertices.len();
        starts.push(start);
        if !split(ring, max_edge, &mut vertices) {
            return;
        }
        let n = vertices.len() - start;
        edges.extend((0..n).map(|i| [start + i, start + (i + 1) % n]));
    }
    if vertices.len() < 3 || vertices.iter().any(|p| !(p.x.is_finite() && p.y.is_finite())) {
        return;
    }
    if let [_, hole] = starts[..]
        && let Some(graph) = ladder(&vertices[..hole], &vertices[hole..], max_edge)
    {
        // One cycle: no spurs to prune.
        out.extend(graph.beads(tol, floor));
        return;
    }
    let count = vertices.len();
    let mut conflicts = 0usize;
    let Ok(cdt) = Cdt::try_bulk_load_cdt(vertices, edges, |_| conflicts += 1) else {
        return;
    };
    // Parity needs every constraint to be a boundary edge crossed once: when rings
    // touched (a constraint was refused, or shared vertices merged) or the inside
    // found does not add up to the shape's area, every face is tested on its own.
    let mut inside = classify(&cdt, shape, conflicts > 0 || cdt.num_vertices() < count);
    let area: f64 = shape.iter().map(|r| ring_area(r)).sum::<f64>().abs();
    if conflicts == 0 && (inside_area(&cdt, &inside) - area).abs() > 1e-6 * area.max(1e-3) {
        inside = classify(&cdt, shape, true);
    }
    let mut graph = axis_graph(&cdt, &inside);
    graph.prune();
    out.extend(graph.beads(tol, floor));
}

/// Pushes the points of `ring` with its edges split to at most `max_edge` (the
/// closing edge too, the first point not repeated); `false` past [`MAX_VERTICES`].
fn split(ring: &[[f64; 2]], max_edge: f64, vertices: &mut Vec<spade::Point2<f64>>) -> bool {
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let pieces = if max_edge > 0.0 && len.is_finite() {
            ((len / max_edge).ceil() as usize).clamp(1, 1 << 16)
        } else {
            1
        };
        for k in 0..pieces {
            let t = k as f64 / pieces as f64;
            vertices.push(spade::Point2::new(
                a[0] + (b[0] - a[0]) * t,
                a[1] + (b[1] - a[1]) * t,
            ));
        }
        if vertices.len() > MAX_VERTICES {
            return false;
        }
    }
    true
}

/// Longest rung of a ladder, in edge lengths: a band wider than this somewhere is left
/// to the triangulation, whose axis branches where the band does.
const LADDER_RUNG: f64 = 2.5;

/// The chordal axis of a band between an outer ring and one hole (their edges split to
/// `max_edge`), triangulated as a ladder: from the hole's point nearest the outer
/// ring's first, each step adds the shorter of the two rungs that advance along one
/// ring or the other, until both rings are walked round. Each triangle is a sleeve
/// between two rungs, so the axis is one cycle through the rungs' midpoints, each
/// segment carrying its triangle's area. These bands are what a level one bead wide
/// leaves to the centre beads (the middle level of a ring an odd number of beads wide,
/// a ring one bead wide): on 3DBenchy 1,323 residues, 80 % of the points the
/// triangulation would take, where a ladder costs a step a point.
///
/// The ladder tiles the band exactly when every triangle turns counter-clockwise: the
/// triangles' boundaries cancel along the rungs and leave the two rings, which wind once
/// round every point of the band and not round any other, and with every triangle
/// positive that winding is the number of triangles over the point. `None` (the
/// triangulation then does it) when one does not, or when a rung is longer than
/// [`LADDER_RUNG`] edges.
fn ladder(outer: &[spade::Point2<f64>], hole: &[spade::Point2<f64>], max_edge: f64) -> Option<Graph> {
    let p = |q: spade::Point2<f64>| Point2::new(q.x, q.y);
    let signed = |r: &[spade::Point2<f64>]| {
        (0..r.len())
            .map(|i| {
                let (a, b) = (r[i], r[(i + 1) % r.len()]);
                a.x * b.y - b.x * a.y
            })
            .sum::<f64>()
    };
    let (so, sh) = (signed(outer), signed(hole));
    // A hole as large as its ring, or no rung length to allow, fails below at the
    // first triangle or rung.
    if outer.is_empty() {
        return None;
    }
    // Both rings counter-clockwise, the hole from its point nearest the outer's first.
    let mut o: Vec<Point2> = outer.iter().map(|&q| p(q)).collect();
    let mut h: Vec<Point2> = hole.iter().map(|&q| p(q)).collect();
    if so < 0.0 {
        o.reverse();
    }
    if sh < 0.0 {
        h.reverse();
    }
    let nearest = (0..h.len()).min_by(|&a, &b| {
        (h[a] - o[0])
            .norm_squared()
            .total_cmp(&(h[b] - o[0]).norm_squared())
    })?;
    h.rotate_left(nearest);
    let (no, nh) = (o.len(), h.len());
    let longest = LADDER_RUNG * max_edge;
    let mut g = Graph::default();
    let rung = |g: &mut Graph, i: usize, j: usize| -> Option<usize> {
        let (a, b) = (o[i % no], h[j % nh]);
        let len = (a - b).norm();
        if len > longest {
            return None;
        }
        if i == no && j == nh {
            return Some(0);
        }
        g.nodes.push(Point2::from((a.coords + b.coords) / 2.0));
        g.widths.push(len);
        Some(g.nodes.len() - 1)
    };
    let cross = |a: Point2, b: Point2, c: Point2| (b - a).perp(&(c - a));
    let (mut i, mut j) = (0, 0);
    let mut at = rung(&mut g, 0, 0)?;
    while i < no || j < nh {
        let along_outer = j == nh
            || (i < no
                && (o[(i + 1) % no] - h[j % nh]).norm_squared()
                    <= (o[i % no] - h[(j + 1) % nh]).norm_squared());
        let twice = if along_outer {
            let t = cross(o[i % no], o[(i + 1) % no], h[j % nh]);
            i += 1;
            t
        } else {
            let t = cross(o[i % no], h[(j + 1) % nh], h[j % nh]);
            j += 1;
            t
        };
        if twice.is_nan() || twice <= 0.0 {
            return None;
        }
        let next = rung(&mut g, i, j)?;
        g.edges.push((at, next, twice / 2.0));
        at = next;
    }
    Some(g)
}

/// Which faces lie inside the shape: parity of the constraint edges crossed on the way
/// from the outside, or (when some boundary edges could not be inserted because rings
/// touch) each face's centroid tested against the rings.
fn classify(cdt: &Cdt, shape: &[Vec<[f64; 2]>], fallback: bool) -> Vec<bool> {
    let n = cdt.num_all_faces();
    let mut inside = vec![false; n];
    if fallback {
        for f in cdt.inner_faces() {
            let [a, b, c] = f.positions();
            let p = [(a.x + b.x + c.x) / 3.0, (a.y + b.y + c.y) / 3.0];
            inside[f.fix().index()] = even_odd(shape, p);
        }
        return inside;
    }
    let mut seen = vec![false; n];
    let mut queue: Vec<FixedFaceHandle<spade::handles::InnerTag>> = Vec::new();
    for e in cdt.convex_hull() {
        // Hull edges run with the outer face on their left; the inner face is across.
        if let Some(f) = e.rev().face().as_inner() {
            let i = f.fix().index();
            if !seen[i] {
                seen[i] = true;
                inside[i] = e.is_constraint_edge();
                queue.push(f.fix());
            }
        }
    }
    while let Some(f) = queue.pop() {
        let face = cdt.face(f);
        let here = inside[f.index()];
        for e in face.adjacent_edges() {
            if let Some(g) = e.rev().face().as_inner() {
                let j = g.fix().index();
                if !seen[j] {
                    seen[j] = true;
                    inside[j] = here ^ e.is_constraint_edge();
                    queue.push(g.fix());
                }
            }
        }
    }
    inside
}

/// One straight bead through a small triangle holding its area, from the middle of its
/// shortest side to the corner across (into a corner loops leave open). Only
/// triangles: a corner with a loop's round join along it has more vertices, and one
/// straight bead of its mean width, across it or along it, leaves its tip or its sides
/// open (0.14 % of 3DBenchy's layer 140), where the triangulation's bead tapers into it.
fn small_bead(ring: &[[f64; 2]]) -> Option<Bead> {
    let area = ring_area(ring).abs();
    let p = |v: [f64; 2]| Point2::new(v[0], v[1]);
    let side = |i: usize| (p(ring[(i + 1) % 3]) - p(ring[i])).norm_squared();
    let i = (0..3).min_by(|&i, &j| side(i).total_cmp(&side(j)))?;
    let a = (p(ring[i]) + p(ring[(i + 1) % 3]).coords) / 2.0;
    let b = p(ring[(i + 2) % 3]);
    let len = (b - a).norm();
    if len <= 1e-9 || area <= 0.0 {
        return None;
    }
    Some(Bead {
        points: vec![a, b],
        widths: vec![area / len],
        closed: false,
    })
}

/// The ring without repeated points and without spikes (a vertex where the ring
/// turns straight back: the trace of a boolean operation's collinear edges), which
/// would be constraints with the region on both sides.
fn clean(ring: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(ring.len());
    let same = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9;
    // Whether `b` is the tip of a spike a -> b -> c.
    let spike = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        let (u, v) = ([b[0] - a[0], b[1] - a[1]], [c[0] - b[0], c[1] - b[1]]);
        let cross = u[0] * v[1] - u[1] * v[0];
        let dot = u[0] * v[0] + u[1] * v[1];
        let scale = (u[0].hypot(u[1]) * v[0].hypot(v[1])).max(1e-300);
        dot < 0.0 && cross.abs() <= 1e-9 * scale
    };
    for &p in ring {
        if out.last().is_some_and(|&q| same(p, q)) {
            continue;
        }
        out.push(p);
        while out.len() >= 3 {
            let n = out.len();
            if spike(out[n - 3], out[n - 2], out[n - 1]) || same(out[n - 3], out[n - 1]) {
                let last = out.pop().unwrap_or(p);
                out.pop();
                if !out.last().is_some_and(|&q| same(q, last)) {
                    out.push(last);
                }
            } else {
                break;
            }
        }
    }
    // The same across the ring's seam.
    loop {
        let n = out.len();
        if n < 3 {
            break;
        }
        if same(out[0], out[n - 1]) || spike(out[n - 2], out[n - 1], out[0]) {
            out.pop();
        } else if spike(out[n - 1], out[0], out[1]) {
            out.remove(0);
        } else {
            break;
        }
    }
    if out.len() < 3 || ring_area(&out).abs() < 1e-12 {
        return Vec::new();
    }
    out
}

fn inside_area(cdt: &Cdt, inside: &[bool]) -> f64 {
    cdt.inner_faces()
        .filter(|f| inside[f.fix().index()])
        .map(|f| {
            let [a, b, c] = f.positions();
            ((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y)).abs() / 2.0
        })
        .sum()
}

/// Even-odd containment of `p` in the rings of `shape`.
fn even_odd(shape: &[Vec<[f64; 2]>], p: [f64; 2]) -> bool {
    let mut odd = false;
    for ring in shape {
        let n = ring.len();
        for i in 0..n {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]);
                if x > p[0] {
                    odd = !odd;
                }
            }
        }
    }
    odd
}

/// The chordal axis as a graph: nodes at chord midpoints, junction centroids and end
/// apexes; each edge carries the area of the triangle (or third) it crosses.
#[derive(Default)]
struct Graph {
    nodes: Vec<Point2>,
    /// The region's width at each node: its chord's length (at a junction the longest
    /// side of its triangle, at an end none).
    widths: Vec<f64>,
    /// (node, node, area)
    edges: Vec<(usize, usize, f64)>,
}

fn axis_graph(cdt: &Cdt, inside: &[bool]) -> Graph {
    let mut g = Graph::default();
    let mut chord_node: HashMap<usize, usize> = HashMap::new();
    let p2 = |p: spade::Point2<f64>| Point2::new(p.x, p.y);
    let is_in = |f: spade::handles::FaceHandle<'_, spade::handles::PossiblyOuterTag, _, _, _, _>| {
        f.as_inner().is_some_and(|f| inside[f.fix().index()])
    };
    for f in cdt.inner_faces() {
        if !inside[f.fix().index()] {
            continue;
        }
        let [a, b, c] = f.positions();
        let area = ((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y)).abs() / 2.0;
        // A chord is an edge shared with another inside face (a boundary edge is a
        // constraint, or borders the outside).
        let mut chords: Vec<usize> = Vec::with_capacity(3);
        let mut walls: Vec<usize> = Vec::with_capacity(3);
        let edges = f.adjacent_edges();
        for (k, e) in edges.iter().enumerate() {
            if !e.is_constraint_edge() && is_in(e.rev().face()) {
                chords.push(k);
            } else {
                walls.push(k);
            }
        }
        let mut node_of = |k: usize, g: &mut Graph| -> usize {
            let e = edges[k];
            let key = e.as_undirected().fix().index();
            *chord_node.entry(key).or_insert_with(|| {
                let [p, q] = e.positions();
                g.nodes.push(Point2::new((p.x + q.x) / 2.0, (p.y + q.y) / 2.0));
                g.widths.push(e.length_2().sqrt());
                g.nodes.len() - 1
            })
        };
        match chords.len() {
            2 => {
                let (m0, m1) = (node_of(chords[0], &mut g), node_of(chords[1], &mut g));
                g.edges.push((m0, m1, area));
            }
            1 => {
                // An end: from the chord to the vertex across it.
                let m = node_of(chords[0], &mut g);
                let e = edges[chords[0]];
                let apex = e.next().to().position();
                g.nodes.push(p2(apex));
                g.widths.push(0.0);
                let n = g.nodes.len() - 1;
                g.edges.push((m, n, area));
            }
            3 => {
                g.nodes
                    .push(Point2::new((a.x + b.x + c.x) / 3.0, (a.y + b.y + c.y) / 3.0));
                g.widths
                    .push(edges.iter().map(|e| e.length_2().sqrt()).fold(0.0, f64::max));
                let centre = g.nodes.len() - 1;
                for &k in &chords {
                    let m = node_of(k, &mut g);
                    g.edges.push((m, centre, area / 3.0));
                }
            }
            _ => {
                // A lone triangle: across it from its longest side.
                let k = walls
                    .iter()
                    .copied()
                    .max_by(|&i, &j| edges[i].length_2().total_cmp(&edges[j].length_2()))
                    .unwrap_or(0);
                let e = edges[k];
                let [p, q] = e.positions();
                g.nodes.push(Point2::new((p.x + q.x) / 2.0, (p.y + q.y) / 2.0));
                g.nodes.push(p2(e.next().to().position()));
                g.widths.extend([0.0, 0.0]);
                let n = g.nodes.len();
                g.edges.push((n - 2, n - 1, area));
            }
        }
    }
    g
}

impl Graph {
    /// Removes the spurs of the axis: a branch from an end to a junction that is
    /// shorter than the region is wide there is the trace of a corner (a chordal axis branches toward
    /// every corner of its region), not a place a bead must go. Its area is handed to
    /// the junction's other branches, so the total stays the region's area, and the
    /// main line runs on through the junction as one bead.
    fn prune(&mut self) {
        let n = self.nodes.len();
        let mut alive = vec![true; self.edges.len()];
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (i, &(a, b, _)) in self.edges.iter().enumerate() {
            adj[a].push(i);
            adj[b].push(i);
        }
        let degree =
            |v: usize, alive: &[bool], adj: &[Vec<usize>]| adj[v].iter().filter(|&&e| alive[e]).count();
        for _ in 0..4 {
            let mut changed = false;
            for leaf in 0..n {
                if degree(leaf, &alive, &adj) != 1 {
                    continue;
                }
                // Walk to the first node that is not a plain link.
                let (mut v, mut prev) = (leaf, usize::MAX);
                let (mut len, mut area) = (0.0, 0.0);
                let mut path = Vec::new();
                while let Some(&e) = adj[v].iter().find(|&&e| alive[e] && e != prev) {
                    let (a, b, ar) = self.edges[e];
                    let w = if a == v { b } else { a };
                    len += (self.nodes[w] - self.nodes[v]).norm();
                    area += ar;
                    path.push(e);
                    prev = e;
                    v = w;
                    if degree(v, &alive, &adj) != 2 || path.len() > 64 {
                        break;
                    }
                }
                if degree(v, &alive, &adj) < 3 || len <= 0.0 {
                    continue;
                }
                // The width of the region at the junction: its chords'.
                let wide = self.widths[v];
                if len > wide {
                    continue;
                }
                for &e in &path {
                    alive[e] = false;
                }
                let rest: Vec<usize> = adj[v].iter().copied().filter(|&e| alive[e]).collect();
                for &e in &rest {
                    self.edges[e].2 += area / rest.len() as f64;
                }
                changed = true;
            }
            if !changed {
                break;
            }
        }
        let mut k = 0;
        self.edges.retain(|_| {
            k += 1;
            alive[k - 1]
        });
    }

    /// The beads along the axis's chains ([`bead`]).
    fn beads(&self, tol: f64, floor: f64) -> impl Iterator<Item = Bead> + '_ {
        self.chains()
            .into_iter()
            .filter_map(move |(points, areas)| bead(points, areas, tol, floor))
    }

    /// The axis cut into chains between nodes where it branches or ends (a closed
    /// chain starts and ends at the same node): points and the area of each segment.
    fn chains(&self) -> Vec<(Vec<Point2>, Vec<f64>)> {
        let n = self.nodes.len();
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (i, &(a, b, _)) in self.edges.iter().enumerate() {
            adj[a].push(i);
            adj[b].push(i);
        }
        let mut used = vec![false; self.edges.len()];
        let mut out = Vec::new();
        let other = |e: usize, v: usize| {
            let (a, b, _) = self.edges[e];
            if a == v { b } else { a }
        };
        let walk = |start: usize, first: usize, used: &mut Vec<bool>| {
            let mut points = vec![self.nodes[start]];
            let mut areas = Vec::new();
            let (mut v, mut e) = (start, first);
            loop {
                used[e] = true;
                let w = other(e, v);
                points.push(self.nodes[w]);
                areas.push(self.edges[e].2);
                if adj[w].len() != 2 || w == start {
                    break;
                }
                match adj[w].iter().copied().find(|&f| !used[f]) {
                    Some(f) => {
                        v = w;
                        e = f;
                    }
                    None => break,
                }
            }
            (points, areas)
        };
        // Open chains from every node that is not a plain link, then the cycles.
        for (v, links) in adj.iter().enumerate() {
            if links.len() == 2 {
                continue;
            }
            for &e in links {
                if !used[e] {
                    out.push(walk(v, e, &mut used));
                }
            }
        }
        for e in 0..self.edges.len() {
            if !used[e] {
                let start = self.edges[e].0;
                out.push(walk(start, e, &mut used));
            }
        }
        out
    }
}

/// A bead from a chain of axis points with the area of each segment: straight runs
/// merged (their areas summed) and each segment's width its area over its length; an
/// open bead's ends narrower than `floor` trimmed ([`trim_ends`]).
fn bead(points: Vec<Point2>, areas: Vec<f64>, tol: f64, floor: f64) -> Option<Bead> {
    let total: f64 = areas.iter().sum();
    if points.len() < 2 || total.is_nan() || total <= 0.0 {
        return None;
    }
    let closed = points.len() > 2 && (points[0] - points[points.len() - 1]).norm() < 1e-12;
    let mut out_p = vec![points[0]];
    let mut out_w = Vec::new();
    let mut a = 0;
    let mut carry = 0.0;
    while a + 1 < points.len() {
        // Extend the run from `a` while every vertex it skips stays within `tol` of
        // the chord and the run's segments have about the same width.
        let mut b = a + 1;
        let mut area = areas[a];
        loop {
            let next = b + 1;
            if next >= points.len() || next - a > MAX_RUN {
                break;
            }
            let chord = points[next] - points[a];
            let len = chord.norm();
            if len <= 0.0 {
                break;
            }
            let straight = (a + 1..next)
                .all(|k| lamina_api::geom::segment_distance(points[k], points[a], points[next]) <= tol);
            let w_run = (area + areas[b]) / len;
            let seg_w = |k: usize| areas[k] / (points[k + 1] - points[k]).norm().max(1e-12);
            let even = (a..next).all(|k| (seg_w(k) - w_run).abs() <= 0.15 * w_run + 0.01);
            if !(straight && even) {
                break;
            }
            area += areas[b];
            b = next;
        }
        let len = (points[b] - points[a]).norm();
        area += carry;
        carry = 0.0;
        if len < 1e-6 {
            // A point-like step: its area goes to the next segment (or the last one).
            carry = area;
        } else {
            out_p.push(points[b]);
            out_w.push(area / len);
        }
        a = b;
    }
    if carry > 0.0
        && let Some(last) = out_w.last_mut()
    {
        let n = out_p.len();
        *last += carry / (out_p[n - 1] - out_p[n - 2]).norm();
    }
    if out_w.is_empty() {
        return None;
    }
    if !closed {
        trim_ends(&mut out_p, &mut out_w, floor);
    }
    Some(Bead {
        points: out_p,
        widths: out_w,
        closed,
    })
}

/// Cuts off the segments at either end of an open bead that are narrower than `floor`
/// (mm), the segment next to them laying their area: the tips of the axis run into
/// the corners of their region, tapering to nothing, where a nozzle would move at full
/// speed laying next to nothing (on 3DBenchy 3.7 m of segments under 0.02 mm wide,
/// two minutes of the print for 9 mm³). The volume is kept; only where it is laid
/// moves, by the length of the tip. A bead narrower than `floor` throughout is left
/// as it is.
fn trim_ends(points: &mut Vec<Point2>, widths: &mut Vec<f64>, floor: f64) {
    let (Some(first), Some(last)) = (
        widths.iter().position(|&w| w >= floor),
        widths.iter().rposition(|&w| w >= floor),
    ) else {
        return;
    };
    let area = |k: usize, points: &[Point2], widths: &[f64]| widths[k] * (points[k + 1] - points[k]).norm();
    let head: f64 = (0..first).map(|k| area(k, points, widths)).sum();
    let tail: f64 = (last + 1..widths.len()).map(|k| area(k, points, widths)).sum();
    for (k, extra) in [(first, head), (last, tail)] {
        widths[k] += extra / (points[k + 1] - points[k]).norm();
    }
    points.truncate(last + 2);
    widths.truncate(last + 1);
    points.drain(..first);
    widths.drain(..first);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    #[test]
    fn a_strip_gets_one_bead_along_its_middle_of_its_width() {
        let beads = centre_beads(&[vec![rect(0.0, 0.0, 10.0, 0.3)]], 0.15, 0.005, 0.0);
        let area: f64 = beads.iter().map(Bead::area).sum();
        assert!((area - 3.0).abs() < 1e-9, "{area}");
        let longest = beads
            .iter()
            .max_by(|a, b| a.length().total_cmp(&b.length()))
            .expect("a bead");
        assert!(longest.length() > 9.0, "{}", longest.length());
        // Along the middle of the strip, as wide as the strip.
        for (w, p) in longest.widths.iter().zip(&longest.points[1..]) {
            if p.x > 0.5 && p.x < 9.5 {
                assert!((p.y - 0.15).abs() < 1e-6, "{p:?}");
                assert!((w - 0.3).abs() < 0.02, "{w}");
            }
        }
    }

    #[test]
    fn a_ring_gets_a_closed_bead_and_a_wedge_a_tapering_one() {
        let mut hole = rect(0.3, 0.3, 9.7, 9.7);
        hole.reverse();
        let beads = centre_beads(&[vec![rect(0.0, 0.0, 10.0, 10.0), hole]], 0.15, 0.005, 0.0);
        let area: f64 = beads.iter().map(Bead::area).sum();
        let expect = 100.0 - 9.4 * 9.4;
        assert!((area - expect).abs() < 1e-9, "{area} vs {expect}");
        let summary: Vec<(bool, f64, usize)> = beads
            .iter()
            .map(|b| (b.closed, b.length(), b.points.len()))
            .collect();
        assert!(beads.iter().any(|b| b.closed && b.length() > 35.0), "{summary:?}");
        // A wedge 2 mm long narrowing from 0.4 mm to a point.
        let wedge = vec![[0.0, 0.0], [2.0, 0.2], [0.0, 0.4]];
        let beads = centre_beads(&[vec![wedge]], 0.1, 0.005, 0.0);
        let area: f64 = beads.iter().map(Bead::area).sum();
        assert!((area - 0.4).abs() < 1e-9, "{area}");
        let b = beads
            .iter()
            .max_by(|a, b| a.length().total_cmp(&b.length()))
            .expect("a bead");
        // Wide (0.4 mm) at the blunt end, nothing at the tip.
        let widest = b.widths.iter().copied().fold(0.0, f64::max);
        let tip = if b.points[0].x > 1.0 {
            b.widths[0]
        } else {
            b.widths[b.widths.len() - 1]
        };
        assert!(widest > 0.3 && tip < 0.05, "{:?}", b.widths);
    }

    #[test]
    fn a_corner_a_loop_leaves_gets_a_bead_into_its_tip_and_a_triangle_one_straight_bead() {
        // The corner between a square's corner and a loop's round join of radius 0.36
        // (two chord points on the arc): the bead runs into the tip, where one straight
        // bead across the corner (from (r, 0) to (0, r)) would pass 0.25 mm from it.
        let r = 0.36;
        let mut corner = vec![[0.0, 0.0], [r, 0.0]];
        for t in [1.0, 2.0] {
            let a = t * std::f64::consts::FRAC_PI_6;
            corner.push([r - r * a.sin(), r - r * a.cos()]);
        }
        corner.push([0.0, r]);
        let area = ring_area(&corner).abs();
        let beads = centre_beads(&[vec![corner]], 0.4, 0.005, 0.0);
        let laid: f64 = beads.iter().map(Bead::area).sum();
        assert!((laid - area).abs() < 1e-9, "{laid} vs {area}");
        let tip = beads
            .iter()
            .flat_map(|b| &b.points)
            .map(|p| p.coords.norm())
            .fold(f64::INFINITY, f64::min);
        assert!(tip < 0.1, "{tip}");
        assert!(beads.iter().any(|b| b.widths.len() > 1), "{beads:?}");
        // A triangle takes one bead from the middle of its shortest side to the corner
        // across, of its area.
        let beads = centre_beads(&[vec![vec![[0.0, 0.0], [0.3, 0.0], [0.0, 0.1]]]], 0.4, 0.005, 0.0);
        assert_eq!(beads.len(), 1);
        let b = &beads[0];
        assert_eq!(b.points, vec![Point2::new(0.0, 0.05), Point2::new(0.3, 0.0)]);
        assert!((b.area() - 0.015).abs() < 1e-12, "{}", b.area());
    }

    /// A circle about (30, 20): off the origin, so that a ring's signed area is not
    /// the sum of anything else.
    fn circle(r: f64, n: usize) -> Vec<[f64; 2]> {
        (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                [30.0 + r * a.cos(), 20.0 + r * a.sin()]
            })
            .collect()
    }

    fn split_ring(ring: &[[f64; 2]], max_edge: f64) -> Vec<spade::Point2<f64>> {
        let mut v = Vec::new();
        assert!(split(ring, max_edge, &mut v));
        v
    }

    #[test]
    fn a_band_one_bead_wide_is_one_closed_bead_round_its_middle() {
        // Circles of 10 and 9.6 mm drawn with 96 and 61 points (as offset rings of a
        // real part are), either way round: one closed bead at radius 9.8, 0.4 wide,
        // holding the band's area.
        for (outer_cw, hole_cw) in [(false, true), (true, false), (false, false)] {
            let mut outer = circle(10.0, 96);
            let mut hole = circle(9.6, 61);
            if outer_cw {
                outer.reverse();
            }
            if hole_cw {
                hole.reverse();
            }
            let area = ring_area(&outer).abs() - ring_area(&hole).abs();
            let beads = centre_beads(&[vec![outer.clone(), hole.clone()]], 0.4, 0.005, 0.0);
            assert_eq!(beads.len(), 1, "{beads:?}");
            let b = &beads[0];
            assert!(b.closed);
            assert!((b.area() - area).abs() < 1e-9 * area, "{} vs {area}", b.area());
            for p in &b.points {
                assert!(((p - Point2::new(30.0, 20.0)).norm() - 9.8).abs() < 0.01, "{p:?}");
            }
            for w in &b.widths {
                assert!((w - 0.4).abs() < 0.01, "{w}");
            }
            // It is the ladder's: one node a rung, every edge split to 0.4 mm at most.
            let (o, h) = (split_ring(&outer, 0.4), split_ring(&hole, 0.4));
            let g = ladder(&o, &h, 0.4).expect("a ladder");
            assert_eq!(g.nodes.len(), o.len() + h.len());
            assert_eq!(g.edges.len(), o.len() + h.len());
            let sum: f64 = g.edges.iter().map(|e| e.2).sum();
            assert!((sum - area).abs() < 1e-9 * area);
        }
    }

    #[test]
    fn a_band_wider_than_its_rungs_allow_is_left_to_the_triangulation() {
        // The same band with a bulge 1.2 mm deep on one side: 3 edges across, past the
        // ladder's 2.5; the triangulation's beads still hold the area.
        let mut outer = circle(10.0, 96);
        outer[0] = [41.2, 20.0];
        let hole = circle(9.6, 61);
        let (o, h) = (split_ring(&outer, 0.4), split_ring(&hole, 0.4));
        assert!(ladder(&o, &h, 0.4).is_none());
        assert!(
            ladder(&o, &h, 0.7).is_some(),
            "2.5 rungs of 0.7 mm reach 1.75 mm, past the bulge's 1.6"
        );
        let area = ring_area(&outer).abs() - ring_area(&hole).abs();
        let beads = centre_beads(&[vec![outer, hole]], 0.4, 0.005, 0.0);
        let laid: f64 = beads.iter().map(Bead::area).sum();
        assert!((laid - area).abs() < 1e-9 * area, "{laid} vs {area}");
        // A hole as large as its outer ring, or larger, is no band.
        let (o, h) = (
            split_ring(&circle(10.0, 96), 0.4),
            split_ring(&circle(10.0, 61), 0.4),
        );
        assert!(ladder(&h, &o, 0.4).is_none());
        assert!(ladder(&o, &o, 0.4).is_none());
    }

    #[test]
    fn a_ladder_closes_where_one_ring_is_walked_round_first() {
        // A 4 mm square about a 3 mm one with a point more on its left side: the outer
        // ring is done a step before the hole, whose last rung closes the band.
        let outer = rect(0.0, 0.0, 4.0, 4.0);
        let hole = vec![[0.5, 0.5], [3.5, 0.5], [3.5, 3.5], [0.5, 3.5], [0.5, 1.0]];
        let (o, h) = (split_ring(&outer, 10.0), split_ring(&hole, 10.0));
        let g = ladder(&o, &h, 10.0).expect("a ladder");
        assert_eq!((g.nodes.len(), g.edges.len()), (9, 9));
        let sum: f64 = g.edges.iter().map(|e| e.2).sum();
        assert!((sum - 7.0).abs() < 1e-12, "{sum}");
        let beads = centre_beads(&[vec![outer, hole]], 10.0, 0.005, 0.0);
        assert_eq!(beads.len(), 1);
        assert!(beads[0].closed && (beads[0].area() - 7.0).abs() < 1e-12);
        // No outer ring, no ladder.
        assert!(ladder(&[], &h, 10.0).is_none());
    }

    #[test]
    fn a_ladder_that_would_fold_is_refused() {
        // A 4 mm square about a 0.5 mm one near its corner, no edge split: from the
        // corner (0, 0) the shorter rungs walk round the small square, and the second
        // triangle, (0, 0) - (1, 1) - (1, 0.5), turns clockwise. The triangulation fills
        // it instead.
        let outer = rect(0.0, 0.0, 4.0, 4.0);
        let hole = rect(0.5, 0.5, 1.0, 1.0);
        let (o, h) = (split_ring(&outer, 10.0), split_ring(&hole, 10.0));
        assert!(ladder(&o, &h, 10.0).is_none());
        let beads = centre_beads(&[vec![outer, hole]], 10.0, 0.005, 0.0);
        let laid: f64 = beads.iter().map(Bead::area).sum();
        assert!((laid - 15.75).abs() < 1e-9, "{laid}");
    }

    #[test]
    fn an_open_beads_hairline_ends_are_laid_by_the_segments_next_to_them() {
        // Four segments of 1, 2, 1 and 2 mm: the 0.01 mm head and the 0.005 mm tail
        // go, their areas (0.01 and 0.01 mm²) widen the segments next to them.
        let p = |x: f64| Point2::new(x, 0.0);
        let (mut points, mut widths) = (
            vec![p(0.0), p(1.0), p(3.0), p(4.0), p(6.0)],
            vec![0.01, 0.3, 0.2, 0.005],
        );
        trim_ends(&mut points, &mut widths, 0.02);
        assert_eq!(points, vec![p(1.0), p(3.0), p(4.0)]);
        assert!(
            (widths[0] - 0.305).abs() < 1e-12 && (widths[1] - 0.21).abs() < 1e-12,
            "{widths:?}"
        );
        // Both ends into one segment; nothing to trim; all below the floor.
        let (mut points, mut widths) = (vec![p(0.0), p(1.0), p(2.0), p(4.0)], vec![0.01, 0.1, 0.01]);
        trim_ends(&mut points, &mut widths, 0.05);
        assert_eq!((points, widths), (vec![p(1.0), p(2.0)], vec![0.1 + 0.01 + 0.02]));
        for ws in [vec![0.1, 0.2], vec![0.01, 0.01]] {
            let (mut points, mut widths) = (vec![p(0.0), p(1.0), p(2.0)], ws.clone());
            trim_ends(&mut points, &mut widths, 0.05);
            assert_eq!((points.len(), widths), (3, ws));
        }
        // The wedge of the test above: its tip no longer tapers below the floor, and
        // its area is all laid.
        let wedge = vec![[0.0, 0.0], [2.0, 0.2], [0.0, 0.4]];
        let beads = centre_beads(&[vec![wedge.clone()]], 0.1, 0.005, 0.0);
        assert!(beads.iter().flat_map(|b| &b.widths).any(|&w| w < 0.05));
        let beads = centre_beads(&[vec![wedge]], 0.1, 0.005, 0.05);
        let area: f64 = beads.iter().map(Bead::area).sum();
        assert!((area - 0.4).abs() < 1e-9, "{area}");
        for b in &beads {
            assert!(
                b.widths[0] >= 0.05 && b.widths[b.widths.len() - 1] >= 0.05,
                "{:?}",
                b.widths
            );
        }
    }
}
