//! Cutting a triangle mesh with a horizontal plane.
//!
//! Robustness comes from topology, not from comparing floating-point points: a vertex
//! lying exactly in the plane is treated as lying above it (symbolic perturbation), so
//! every triangle crossing the plane has exactly two edges that cross it and yields one
//! segment whose ends are identified by the crossing edges (pairs of vertex indices).
//! Neighbouring triangles share those edges, so segments chain into loops without any
//! tolerance. Faces lying in the plane produce nothing, and vertices or edges in the
//! plane produce segments through them. What does not close (open meshes, non-manifold
//! edges) is joined across the mesh's holes ([`crate::holes`]) and small gaps, and
//! reported when it cannot be.

use std::sync::Arc;

use lamina_api::options::SharedOption;
use lamina_api::{Contour, Layer, LayerSlot, Mesh, Point2, Result, Warning};

/// The code of the warnings about open chains a layer drops.
const OPEN_CHAINS_DROPPED: &str = "open-chains-dropped";
/// The code of the warnings about cuts closed across the mesh's holes.
const HOLES_CLOSED: &str = "holes-closed";
/// Most chains a layer asks [`winding_number`] about.
const SOLID_TESTS: usize = 16;
/// The winding number above which the point beside a chain is inside a solid: 1 for a
/// solid, a half beside a sheet, with room either way for what other holes and sheets
/// subtend.
const SOLID_WINDING: f64 = 0.75;
use crate::holes::{Holes, edge_key, probe, winding_number};
use lamina_geom::ring::{Ring, contour_of, ring_of};
use lamina_geom::segment_distance;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// How overlapping or self-crossing loops are resolved into simple contours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FillRule {
    /// Inside where the loops wind around a point at all: overlapping shells merge,
    /// holes (wound the other way) subtract. Right for meshes with consistent winding.
    #[default]
    NonZero,
    /// Inside where an odd number of loops surround a point, whatever their winding:
    /// for meshes whose winding cannot be trusted.
    EvenOdd,
}

/// How the cut treats defects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutOptions {
    /// Open chains whose ends are closer than this (mm) are joined.
    pub close_gaps: f64,
    /// Loops enclosing less area than this (mm²) are dropped as noise.
    pub min_area: f64,
    pub fill_rule: FillRule,
}

lamina_api::option_type!(FillRule = "string");

/// Options every slicer takes, documented once.
pub(crate) const CLOSE_GAPS: SharedOption = SharedOption::new(
    "0.05",
    "open chains whose ends are closer than this (mm) are joined; ends on the rim of one hole of the mesh are joined whatever the gap, where the mesh's winding number says the chain is a solid's wall",
)
.within(0.0, 10.0);
pub(crate) const FILL_RULE: SharedOption = SharedOption::new(
    "\"nonzero\"",
    "how overlapping loops combine: \"nonzero\" (shells merge) or \"evenodd\" (winding ignored)",
);
/// Upper bound on the layer count, against a mistyped thickness.
pub(crate) const MAX_LAYERS: SharedOption =
    SharedOption::new("100000", "refuse to make more layers than this").within(1.0, 1e7);

impl CutOptions {
    /// The options a slicer's table gives, checked; errors point at the key.
    pub fn from_table(
        config: &lamina_api::stage::StageConfig<'_>,
        close_gaps: f64,
        fill_rule: FillRule,
    ) -> Result<Self> {
        if !(close_gaps.is_finite() && close_gaps >= 0.0) {
            return Err(config.error("close_gaps", "must be a non-negative number of mm"));
        }
        Ok(Self {
            close_gaps,
            fill_rule,
            ..Self::default()
        })
    }
}

impl Default for CutOptions {
    fn default() -> Self {
        Self {
            close_gaps: 0.05,
            min_area: 1e-8,
            fill_rule: FillRule::NonZero,
        }
    }
}

/// A mesh indexed by height for repeated cuts.
#[derive(Debug)]
pub struct CutMesh {
    mesh: Arc<Mesh>,
    /// Sign of the mesh's volume: +1 when triangles wind outward, -1 when inside out.
    orientation: f64,
    /// Triangle z ranges, each widened by twice `snap`: a triangle can only cross a plane
    /// inside its widened range.
    ranges: Vec<(f64, f64)>,
    /// Vertices closer than this to the plane (mm) are cut as if they lay in it.
    snap: f64,
    /// Buckets of triangle indices by z: bucket `b` spans `z0 + b * bucket` and holds
    /// `entries[starts[b]..starts[b + 1]]`.
    z0: f64,
    bucket: f64,
    /// `1 / bucket`: the lookup of a bucket is a product.
    per_bucket: f64,
    starts: Vec<u32>,
    entries: Vec<u32>,
    options: CutOptions,
    /// The middle of the mesh's box in x and y: the point the section's area is summed
    /// about, so that a segment missing from an open cut changes the sum by no more
    /// than the thin triangle it makes with this point.
    centre: Point2,
    /// The mesh's holes, across which cuts are closed.
    holes: Holes,
    /// How far beside a chain the winding number is asked (mm): thinner than any wall,
    /// a hundred-thousandth of the mesh's size.
    reach: f64,
}

/// One cut segment: its two ends, each an edge key and a point, and the direction the
/// triangle's winding gives it.
#[derive(Debug, Clone, Copy)]
struct Segment {
    keys: [u64; 2],
    points: [Point2; 2],
}

/// The area a chain of points, each step with the solid on its left, sweeps about
/// `centre`: the sum of the triangles its steps make with it (Green's theorem). A
/// closed chain's own area; an open one's, less the triangle of its gap with `centre`.
fn swept_area(chain: &[Point2], centre: Point2) -> f64 {
    chain
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0] - centre, w[1] - centre);
            0.5 * (a.x * b.y - a.y * b.x)
        })
        .sum()
}

impl CutMesh {
    pub fn new(mesh: Arc<Mesh>, options: CutOptions) -> Self {
        let bb = mesh.bbox();
        let (z0, z1) = if bb.is_empty() {
            (0.0, 1.0)
        } else {
            (bb.min.z, bb.max.z)
        };
        let height = (z1 - z0).max(1e-9);
        let snap = snap_distance(z0, z1);
        // One parallel pass over the triangles gives their (widened) z ranges and their
        // terms of the signed volume, summed below in triangle order as
        // `Mesh::signed_volume` does.
        let (ranges, volumes): (Vec<(f64, f64)>, Vec<f64>) = mesh
            .triangles
            .par_iter()
            .with_min_len(4096)
            .map(|&[a, b, c]| {
                let v = &mesh.vertices;
                let (a, b, c) = (v[a as usize], v[b as usize], v[c as usize]);
                let (lo, hi) = (a.z.min(b.z).min(c.z), a.z.max(b.z).max(c.z));
                let range = (lo - 2.0 * snap, hi + 2.0 * snap);
                (range, a.coords.dot(&b.coords.cross(&c.coords)) / 6.0)
            })
            .unzip();
        let volume: f64 = volumes.iter().sum();
        drop(volumes);
        // Each triangle is listed in every bucket its z range touches, so the entries
        // number about n + sum(extent) * count / height. The count is chosen so that
        // this stays below 4 n (flat caps and tall walls alike), and at most 65536.
        let n = ranges.len().max(1) as f64;
        let total_extent: f64 = ranges.par_iter().with_min_len(4096).map(|(lo, hi)| hi - lo).sum();
        let by_entries = if total_extent > 0.0 {
            3.0 * n * height / total_extent
        } else {
            n
        };
        let count = (by_entries.min(n).floor() as usize).clamp(1, 65536);
        let bucket = height / count as f64;
        let per_bucket = 1.0 / bucket;
        let span = |(lo, hi): (f64, f64)| {
            bucket_of(lo, z0, per_bucket, count)..bucket_of(hi, z0, per_bucket, count) + 1
        };
        // The buckets as one array (counted, then filled), each in triangle order.
        let mut starts = vec![0u32; count + 1];
        for &r in &ranges {
            for b in span(r) {
                starts[b + 1] += 1;
            }
        }
        for b in 0..count {
            starts[b + 1] += starts[b];
        }
        let mut entries = vec![0u32; starts[count] as usize];
        let mut next = starts.clone();
        for (i, &r) in ranges.iter().enumerate() {
            for b in span(r) {
                entries[next[b] as usize] = i as u32;
                next[b] += 1;
            }
        }
        let orientation = if volume < 0.0 { -1.0 } else { 1.0 };
        let centre = if bb.is_empty() {
            Point2::origin()
        } else {
            Point2::new(0.5 * (bb.min.x + bb.max.x), 0.5 * (bb.min.y + bb.max.y))
        };
        let reach = if bb.is_empty() {
            1e-6
        } else {
            ((bb.max - bb.min).norm() * 1e-5).max(1e-9)
        };
        let holes = Holes::of(&mesh);
        Self {
            centre,
            holes,
            reach,
            mesh,
            orientation,
            ranges,
            snap,
            z0,
            bucket,
            per_bucket,
            starts,
            entries,
            options,
        }
    }

    /// The triangles whose z range touches bucket `b`, in increasing order.
    fn bucket(&self, b: usize) -> &[u32] {
        &self.entries[self.starts[b] as usize..self.starts[b + 1] as usize]
    }

    pub fn mesh(&self) -> &Arc<Mesh> {
        &self.mesh
    }

    /// The segments of the plane `z`.
    fn segments(&self, z: f64) -> Vec<Segment> {
        let count = self.starts.len() - 1;
        // Every triangle whose widened range holds `z` is listed in `z`'s bucket (the
        // ranges were bucketed widened), whichever bucket the clamping picks at the ends.
        if !(z >= self.z0 - 3.0 * self.snap && z <= self.z0 + self.bucket * count as f64 + 3.0 * self.snap) {
            return Vec::new();
        }
        let b = bucket_of(z, self.z0, self.per_bucket, count);
        let snap = self.snap;
        // In the plane (within `snap`) counts as above, as exactly in the plane does.
        let on = |p: &lamina_api::Point3| (p.z - z).abs() <= snap;
        let mut out = Vec::new();
        for &t in self.bucket(b) {
            let (lo, hi) = self.ranges[t as usize];
            if !(lo < z && hi >= z) {
                continue;
            }
            let ids = self.mesh.triangles[t as usize];
            let pts = self.mesh.triangle(t as usize);
            let above = pts.map(|p| p.z >= z || on(&p));
            if above[0] == above[1] && above[1] == above[2] {
                continue;
            }
            // The lone vertex on its side, and the two edges leaving it.
            let lone = match above {
                [a, b, c] if a != b && a != c => 0,
                [a, b, c] if b != a && b != c => 1,
                [_, _, _] => 2,
            };
            let (i1, i2) = ((lone + 1) % 3, (lone + 2) % 3);
            // An edge from a vertex below to one in the plane is cut at that vertex,
            // exactly, so all the cuts next to it coincide and merge.
            let cross = |i: usize, j: usize| {
                let (p, q) = (pts[i], pts[j]);
                if on(&q) {
                    return Point2::new(q.x, q.y);
                }
                if on(&p) {
                    return Point2::new(p.x, p.y);
                }
                let s = (z - p.z) / (q.z - p.z);
                Point2::new(p.x + (q.x - p.x) * s, p.y + (q.y - p.y) * s)
            };
            let pa = cross(lone, i1);
            let pb = cross(lone, i2);
            let ka = edge_key(ids[lone], ids[i1]);
            let kb = edge_key(ids[lone], ids[i2]);
            // Material lies to the left of the segment when the mesh winds outward:
            // a lone vertex below the plane means the walk goes from edge (lone, i1)
            // to edge (lone, i2) with the solid on the left... decided by the normal.
            let n = (pts[1] - pts[0]).cross(&(pts[2] - pts[0])) * self.orientation;
            // Direction z × n has the solid on its left.
            let want = lamina_api::Vector2::new(-n.y, n.x);
            let d = pb - pa;
            if d.dot(&want) >= 0.0 {
                out.push(Segment {
                    keys: [ka, kb],
                    points: [pa, pb],
                });
            } else {
                out.push(Segment {
                    keys: [kb, ka],
                    points: [pb, pa],
                });
            }
        }
        out
    }

    /// Cuts the mesh for one layer slot.
    pub fn cut(&self, slot: &LayerSlot) -> Result<Layer> {
        let mut layer = Layer::from_slot(slot);
        let segments = self.segments(slot.cut_z);
        let (loops, open) = chain(&segments);
        let mut contours = Vec::new();
        let mut gaps = Gaps::default();
        // Each chain asked about costs a pass over the triangles: a layer asks about a
        // few, so that a soup of open chains costs no more than a few cuts.
        let mut asked = 0;
        let mut bounds_solid = |chain: &[Point2]| {
            asked += 1;
            asked <= SOLID_TESTS
                && probe(chain, slot.cut_z, self.reach)
                    .is_some_and(|p| self.orientation * winding_number(&self.mesh, p) > SOLID_WINDING)
        };
        let mut closing = Closing {
            tolerance: self.options.close_gaps,
            holes: &self.holes,
            bounds_solid: &mut bounds_solid,
        };
        let closed = close_open(open, &mut closing, self.centre, &mut gaps);
        for mut lp in loops.into_iter().chain(closed) {
            lp.points.dedup_by(|a, b| (*a - *b).norm() <= 1e-12);
            while lp.points.len() > 1 && (lp.points[0] - lp.points[lp.points.len() - 1]).norm() <= 1e-12 {
                lp.points.pop();
            }
            if lp.points.len() < 3 || lp.area() < self.options.min_area {
                continue;
            }
            contours.push(lp);
        }
        // The runtime says which layer and part a warning is about.
        // A few chains are told one by one; a soup's thousands in one line, so that the
        // warnings do not outweigh the layer.
        if gaps.dropped.len() <= DROPPED_TOLD {
            for d in &gaps.dropped {
                layer.warnings.push(Warning::new(
                    OPEN_CHAINS_DROPPED,
                    format!(
                        "dropped an open chain of {} points from ({:.3}, {:.3}) to ({:.3}, {:.3}): gap of {:.3} mm (open mesh?)",
                        d.points, d.first.x, d.first.y, d.last.x, d.last.y, d.gap
                    ),
                ));
            }
        } else if let Some(d) = gaps.dropped.iter().max_by(|a, b| a.gap.total_cmp(&b.gap)) {
            let points: usize = gaps.dropped.iter().map(|d| d.points).sum();
            layer.warnings.push(Warning::new(
                OPEN_CHAINS_DROPPED,
                format!(
                    "dropped {} open chains of {points} points in all (open mesh?), the widest gap {:.3} mm from ({:.3}, {:.3}) to ({:.3}, {:.3})",
                    gaps.dropped.len(),
                    d.gap,
                    d.first.x,
                    d.first.y,
                    d.last.x,
                    d.last.y
                ),
            ));
        }
        if let Some((widest, at)) = gaps.widest_bridge {
            layer.warnings.push(Warning::new(
                HOLES_CLOSED,
                format!(
                    "closed {} cut(s) across holes of the mesh ({} hole(s), the longest rim {:.2} mm), the widest gap {widest:.3} mm at ({:.3}, {:.3})",
                    gaps.bridged,
                    self.holes.count(),
                    self.holes.longest(),
                    at.x,
                    at.y
                ),
            ));
        }
        if let Some((widest, at)) = gaps.widest {
            layer.warnings.push(Warning::new(
                "gaps-closed",
                format!(
                    "closed {} gap(s) below {} mm, the widest ({widest:.2e} mm) at ({:.3}, {:.3})",
                    gaps.closed, self.options.close_gaps, at.x, at.y
                ),
            ));
        }
        layer.contours = simple_contours(&contours, self.options);
        // What the layer should hold: its contours, and the dropped chains that are
        // loops missing a piece. Not the sum over every segment, which counts twice
        // where closed shells overlap.
        let kept: f64 = layer.contours.iter().map(Contour::signed_area).sum();
        let lost: f64 = gaps
            .dropped
            .iter()
            .filter(|d| d.is_broken_loop())
            .map(|d| d.area)
            .sum();
        layer.section_area = Some(kept + lost);
        Ok(layer)
    }
}

/// The bucket of height `z`, for listing a triangle's range and for looking up a plane
/// alike: the product is monotonic, so a range that holds z is listed in z's bucket.
/// `as usize` truncates like `floor` here and saturates negatives and NaN to 0.
fn bucket_of(z: f64, z0: f64, per_bucket: f64, count: usize) -> usize {
    (((z - z0) * per_bucket).max(0.0) as usize).min(count - 1)
}

/// How close to the cutting plane a vertex is taken to lie in it: eight times the
/// rounding of a single-precision height at the mesh's largest height.
///
/// STL and most exporters store single-precision coordinates, so a vertex at a design
/// height that is a whole number of layers (12.1 mm on a 0.2 mm grid cut at mid-layer)
/// comes back a few ulps off the plane, never in it. Cut exactly, the edges next to it
/// give points a fraction of a micrometre apart, and the union has to resolve the
/// layer. Cutting with such vertices moved into the plane is the exact cut of a mesh
/// moved by a few times its own rounding; the vertex is then the cut of all its edges,
/// and the loop passes through it once. Which vertices move depends on the vertex
/// alone, so neighbouring triangles agree and the segments still chain.
fn snap_distance(z0: f64, z1: f64) -> f64 {
    let scale = z0.abs().max(z1.abs());
    if scale.is_finite() {
        scale * 4.0 * f64::from(f32::EPSILON)
    } else {
        0.0
    }
}

/// Most dropped open chains a layer's warnings name one by one.
const DROPPED_TOLD: usize = 3;

/// What joining open chains did in one layer.
#[derive(Default)]
struct Gaps {
    closed: usize,
    /// The widest gap closed and where (the end of the chain it was closed from).
    widest: Option<(f64, Point2)>,
    /// Joins across the mesh's holes, and the widest.
    bridged: usize,
    widest_bridge: Option<(f64, Point2)>,
    dropped: Vec<Dropped>,
}

impl Gaps {
    fn close(&mut self, gap: f64, at: Point2) {
        self.closed += 1;
        if self.widest.is_none_or(|(w, _)| gap > w) {
            self.widest = Some((gap, at));
        }
    }

    fn bridge(&mut self, gap: f64, at: Point2) {
        self.bridged += 1;
        if self.widest_bridge.is_none_or(|(w, _)| gap > w) {
            self.widest_bridge = Some((gap, at));
        }
    }
}

/// An open chain that could not be closed.
struct Dropped {
    points: usize,
    first: Point2,
    last: Point2,
    gap: f64,
    /// The area it sweeps about the mesh's middle ([`swept_area`]): about what the
    /// layer loses with it.
    area: f64,
    /// Its length along its points (mm).
    length: f64,
}

impl Dropped {
    /// Whether the chain is a loop missing a piece (a wall with a hole in it), whose
    /// area the layer loses, rather than a stray sheet standing in or beside the part
    /// (an arc, a fin), which encloses nothing: its gap is under a third of its length.
    /// A square missing most of a side is a loop; an arc of less than about 290
    /// degrees is a sheet.
    fn is_broken_loop(&self) -> bool {
        self.gap <= self.length / 3.0
    }
}

/// Resolves the loops into simple, non-crossing contours (outer counter-clockwise,
/// holes clockwise) with a boolean union under the fill rule: overlapping shells merge,
/// self-touching or slightly self-crossing loops (near-coincident vertices that were not
/// welded) are cut apart. Coordinates move by at most the integer grid of the overlay
/// (about 1e-9 of the layer's extent). Loops that are already simple, apart and wound
/// as they nest are the union's answer as they stand, and are returned unchanged.
fn simple_contours(loops: &[Contour], options: CutOptions) -> Vec<Contour> {
    if loops.is_empty() {
        return Vec::new();
    }
    if already_simple(loops) {
        return loops.iter().map(drop_straight).collect();
    }
    union(loops, options)
}

/// The loop without the points that lie on the straight line between their
/// neighbours, within 1e-9 of the loop's extent: the union drops them (its grid is about
/// that fine), and a flat wall made of many triangles leaves one per triangle.
fn drop_straight(c: &Contour) -> Contour {
    let b = c.bbox();
    let tol = b.width().max(b.height()) * 1e-9;
    let pts = &c.points;
    let n = pts.len();
    let mut out: Vec<Point2> = Vec::with_capacity(n);
    for (i, &p) in pts.iter().enumerate() {
        let prev = out.last().copied().unwrap_or(pts[n - 1]);
        if segment_distance(p, prev, pts[(i + 1) % n]) > tol {
            out.push(p);
        }
    }
    if out.len() < 3 {
        return c.clone();
    }
    Contour::new(out)
}

/// The boolean union of [`simple_contours`].
fn union(loops: &[Contour], options: CutOptions) -> Vec<Contour> {
    use i_overlay::core::fill_rule::FillRule as Rule;
    use i_overlay::core::solver::Solver;
    use i_overlay::float::overlay::OverlayOptions;
    use i_overlay::float::simplify::SimplifyShape;

    let paths: Vec<Ring> = loops.iter().map(ring_of).collect();
    let rule = match options.fill_rule {
        FillRule::NonZero => Rule::NonZero,
        FillRule::EvenOdd => Rule::EvenOdd,
    };
    // OGC-valid output: every ring simple. Without it i_overlay walks a ring that
    // touches itself at a vertex as one ring through that vertex twice (3DBenchy, layers
    // 44-52: a sliver triangle's cut curls back across the previous segment, the
    // non-zero rule fills the curl, and the hole came out as ...A, B, C, A... with a
    // 4e-11 mm² lobe). In OGC mode the lobe is a shape of its own, and `min_output_area`
    // drops it; a hole pinched to its outer becomes a hole touching it at one point.
    let mut overlay_options = OverlayOptions::<f64>::default();
    overlay_options.ogc = true;
    overlay_options.min_output_area = options.min_area;
    // The runtime already runs layers in parallel; the overlay stays on this thread.
    let solver = Solver {
        multithreading: None,
        ..Solver::default()
    };
    let shapes = paths.simplify_shape_custom(rule, overlay_options, solver);
    shapes
        .into_iter()
        .flatten()
        .filter(|path| path.len() >= 3)
        .map(|path| contour_of(&path))
        .collect()
}

/// Whether the union would return `loops` unchanged (up to its integer grid and the
/// points it drops on straight runs): every loop simple, no two loops touching, and
/// each loop wound as its nesting says (counter-clockwise at even depth, clockwise at
/// odd), so that both fill rules fill exactly the loops. Most layers of a sound mesh
/// are like this, and the check costs a fraction of the union.
///
/// Closeness is judged with a margin of 1e-8 of the layer's extent: far above rounding,
/// and five to ten steps of the union's grid (2^-29 of half the extent or finer), so
/// that no snapping to that grid can make loops kept apart by the margin touch:
/// segments (other than neighbours in a loop) must be farther apart than that, and
/// neighbours must not fold back onto each other. Loops that cross, touch, or come near
/// (the near-duplicate vertices of a badly welded mesh, overlapping shells) go to the
/// union. A larger margin would send every layer with a short segment (the cut of a
/// sliver triangle, 1e-5 mm across) to the union, which would keep it unchanged.
fn already_simple(loops: &[Contour]) -> bool {
    let bbox = loops
        .iter()
        .fold(lamina_api::BBox2::EMPTY, |b, c| b.union(&c.bbox()));
    let extent = bbox.width().max(bbox.height());
    if !(extent.is_finite() && extent > 0.0) {
        return false;
    }
    let eps = extent * 1e-8;
    // Every segment with its box grown by eps; neighbours in a loop must not fold back.
    let mut segs = Vec::with_capacity(loops.iter().map(|c| c.points.len()).sum());
    let mut length = 0.0;
    for (l, c) in loops.iter().enumerate() {
        let pts = &c.points;
        if pts.len() < 3 {
            return false;
        }
        for i in 0..pts.len() {
            let (a, b, next) = (pts[i], pts[(i + 1) % pts.len()], pts[(i + 2) % pts.len()]);
            if segment_distance(next, a, b) <= eps || segment_distance(a, b, next) <= eps {
                return false;
            }
            length += (b - a).norm();
            segs.push(Seg {
                a,
                b,
                lo: Point2::new(a.x.min(b.x) - eps, a.y.min(b.y) - eps),
                hi: Point2::new(a.x.max(b.x) + eps, a.y.max(b.y) + eps),
                at: (l as u32, i as u32, pts.len() as u32),
            });
        }
    }
    let n = segs.len();
    // A grid of square buckets about twice the mean segment length, at most ~2 per segment;
    // each segment is listed in the buckets its grown box touches.
    let (x0, y0) = (bbox.min.x - eps, bbox.min.y - eps);
    let (w, h) = (bbox.width() + 2.0 * eps, bbox.height() + 2.0 * eps);
    let bucket = (2.0 * length / n as f64)
        .max((w * h / (2 * n) as f64).sqrt())
        .max(eps);
    let nx = (w / bucket) as usize + 1;
    let ny = (h / bucket) as usize + 1;
    // Any monotone map from coordinates to buckets lists two overlapping boxes in a
    // common bucket (the buckets of the overlap's corners are in both ranges), so a product
    // serves as well as a quotient.
    let per_cell = 1.0 / bucket;
    let buckets = |s: &Seg| {
        let c = |v: f64, o: f64, n: usize| (((v - o) * per_cell).max(0.0) as usize).min(n - 1);
        (
            c(s.lo.x, x0, nx)..=c(s.hi.x, x0, nx),
            c(s.lo.y, y0, ny)..=c(s.hi.y, y0, ny),
        )
    };
    let mut starts = vec![0u32; nx * ny + 1];
    let mut listed = 0usize;
    // Each segment's buckets, worked out once for counting and listing.
    let mut spans = Vec::with_capacity(n);
    for s in &segs {
        let (xs, ys) = buckets(s);
        listed += xs.clone().count() * ys.clone().count();
        // Long segments over many buckets: a layer unlike a sliced solid; leave it.
        if listed > 16 * n + 64 {
            return false;
        }
        for y in ys.clone() {
            for x in xs.clone() {
                starts[y * nx + x + 1] += 1;
            }
        }
        spans.push((xs, ys));
    }
    for i in 0..nx * ny {
        starts[i + 1] += starts[i];
    }
    let mut members = vec![0u32; listed];
    let mut next = starts.clone();
    for (g, (xs, ys)) in spans.into_iter().enumerate() {
        for y in ys {
            for x in xs.clone() {
                let slot = &mut next[y * nx + x];
                members[*slot as usize] = g as u32;
                *slot += 1;
            }
        }
    }
    let mut tests = 0usize;
    for c in 0..nx * ny {
        let here = &members[starts[c] as usize..starts[c + 1] as usize];
        tests += here.len() * here.len().saturating_sub(1) / 2;
        if tests > 64 * n + 1024 {
            return false;
        }
        for (k, &g) in here.iter().enumerate() {
            let s = &segs[g as usize];
            for &h in &here[k + 1..] {
                let t = &segs[h as usize];
                if s.lo.x > t.hi.x || t.lo.x > s.hi.x || s.lo.y > t.hi.y || t.lo.y > s.hi.y {
                    continue;
                }
                // Neighbours (checked above) share a point.
                let ((l, i, len), (m, j, _)) = (s.at, t.at);
                if l == m && (j == (i + 1) % len || i == (j + 1) % len) {
                    continue;
                }
                if segments_within(s.a, s.b, t.a, t.b, eps) {
                    return false;
                }
            }
        }
    }
    // Loops neither cross nor touch, so one point tells whether a loop lies inside
    // another; the depth must match the winding.
    let boxes: Vec<lamina_api::BBox2> = loops.iter().map(Contour::bbox).collect();
    loops.iter().enumerate().all(|(i, c)| {
        let p = c.points[0];
        let depth = loops
            .iter()
            .enumerate()
            .filter(|&(j, o)| {
                let (bi, bj) = (&boxes[i], &boxes[j]);
                j != i
                    && bj.min.x <= bi.min.x
                    && bj.min.y <= bi.min.y
                    && bj.max.x >= bi.max.x
                    && bj.max.y >= bi.max.y
                    && o.contains(p)
            })
            .count();
        c.is_ccw() == depth.is_multiple_of(2)
    })
}

/// A loop segment for [`already_simple`]: its ends, its box grown by the margin, and
/// (loop, index in the loop, loop length).
struct Seg {
    a: Point2,
    b: Point2,
    lo: Point2,
    hi: Point2,
    at: (u32, u32, u32),
}

/// Whether segments `a b` and `c d` come within `eps` of each other (or cross).
fn segments_within(a: Point2, b: Point2, c: Point2, d: Point2, eps: f64) -> bool {
    if segment_distance(a, c, d) <= eps
        || segment_distance(b, c, d) <= eps
        || segment_distance(c, a, b) <= eps
        || segment_distance(d, a, b) <= eps
    {
        return true;
    }
    // Every end is clear of the other segment, so a crossing is a proper one and the
    // signs below are far from rounding.
    let orient = |p: Point2, q: Point2, r: Point2| (q - p).perp(&(r - p));
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    (o1 > 0.0) != (o2 > 0.0) && (o3 > 0.0) != (o4 > 0.0)
}

/// Chains segments into closed loops by their edge keys. Returns the loops (oriented
/// by the majority of their segments' directions) and the chains that did not close.
fn chain(segments: &[Segment]) -> (Vec<Contour>, Vec<Open>) {
    let at = Ends::new(segments);
    let mut used = vec![false; segments.len()];
    let mut loops = Vec::new();
    let mut open = Vec::new();
    for start in 0..segments.len() {
        if used[start] {
            continue;
        }
        used[start] = true;
        let s = segments[start];
        let mut points = vec![s.points[0], s.points[1]];
        let mut votes = 1i64;
        let first_key = s.keys[0];
        let mut key = s.keys[1];
        let mut closed = false;
        // Walk forward.
        loop {
            if key == first_key {
                closed = true;
                break;
            }
            let Some(next) = at.unused(key, &used) else {
                break;
            };
            used[next as usize] = true;
            let seg = segments[next as usize];
            let (p, k, v) = if seg.keys[0] == key {
                (seg.points[1], seg.keys[1], 1)
            } else {
                (seg.points[0], seg.keys[0], -1)
            };
            votes += v;
            points.push(p);
            key = k;
        }
        let last_key = key;
        if closed {
            points.pop();
            let mut c = Contour::new(points);
            if votes < 0 {
                c.reverse();
            }
            loops.push(c);
            continue;
        }
        // Walk backward from the start to complete the open chain.
        let mut back = Vec::new();
        let mut key = first_key;
        while let Some(next) = at.unused(key, &used) {
            used[next as usize] = true;
            let seg = segments[next as usize];
            let (p, k, v) = if seg.keys[1] == key {
                (seg.points[0], seg.keys[0], 1)
            } else {
                (seg.points[1], seg.keys[1], -1)
            };
            votes += v;
            back.push(p);
            key = k;
        }
        back.reverse();
        back.extend(points);
        let mut keys = [key, last_key];
        if votes < 0 {
            back.reverse();
            keys.reverse();
        }
        open.push(Open { points: back, keys });
    }
    (loops, open)
}

/// A chain of segments that does not close: its points, each step with the solid on
/// its left, and the edges its first and last points lie on.
struct Open {
    points: Vec<Point2>,
    keys: [u64; 2],
}

/// The segments ending at each edge key: each key is the end of (normally) two
/// segments. A map from key to the first of them, and a link from each segment end to
/// the next with the same key, lists them in increasing order without sorting.
struct Ends {
    first: FxHashMap<u64, u32>,
    /// For end `2 s + k` (key `k` of segment `s`): the next end with the same key.
    next: Vec<u32>,
}

impl Ends {
    const NONE: u32 = u32::MAX;

    fn new(segments: &[Segment]) -> Self {
        let mut first: FxHashMap<u64, u32> =
            FxHashMap::with_capacity_and_hasher(segments.len() + 1, Default::default());
        let mut next = vec![Self::NONE; 2 * segments.len()];
        // Backwards, so that each list comes out in increasing segment order.
        for (i, s) in segments.iter().enumerate().rev() {
            for k in [1, 0] {
                let end = (2 * i + k) as u32;
                next[end as usize] = first.insert(s.keys[k], end).unwrap_or(Self::NONE);
            }
        }
        Self { first, next }
    }

    /// The first segment ending at `key` that is not used yet.
    fn unused(&self, key: u64, used: &[bool]) -> Option<u32> {
        let mut end = *self.first.get(&key)?;
        while end != Self::NONE {
            let s = end / 2;
            if !used[s as usize] {
                return Some(s);
            }
            end = self.next[end as usize];
        }
        None
    }
}

/// How open chains are joined: across gaps smaller than `tolerance`, and across the
/// mesh's `holes` where `bounds_solid` says the chain is the wall of a solid.
struct Closing<'a> {
    tolerance: f64,
    holes: &'a Holes,
    /// Whether a chain (each step with the solid on its left) is the cut of a solid's
    /// wall rather than of a sheet; asked once per chain, and only for a join across a
    /// hole wider than `tolerance`.
    bounds_solid: &'a mut dyn FnMut(&[Point2]) -> bool,
}

/// Joins open chains end to start, first across holes (a chain's end to the nearest
/// chain start on the same rim, its own included, or to the nearest end there,
/// reversed, when no start is), then across gaps smaller than the tolerance; chains
/// that still do not close are reported and dropped (stray sheets).
///
/// The chains wait in `open` and are taken from its end; a chain's end is joined to the
/// nearest start (or end, the chain then reversed) of a waiting chain, ties going to the
/// lowest place in `open` and a start before an end, and a taken chain's place is filled
/// by the last one (`swap_remove`). The ends are found through a grid of buckets of the
/// tolerance's size, so that a layer of many open chains (a triangle soup gives one per
/// triangle it cuts) costs time in proportion to their number, not its square; the
/// ends on a rim through a list per rim, which a rim with more ends in one layer than
/// [`RIM_ENDS`] does not get (a soup's rims are everything).
fn close_open(
    mut open: Vec<Open>,
    closing: &mut Closing<'_>,
    centre: Point2,
    gaps: &mut Gaps,
) -> Vec<Contour> {
    let tolerance = closing.tolerance;
    let ends = EndGrid::new(&open, tolerance);
    let rims = RimEnds::new(&open, closing.holes);
    // `id[i]`: the chain at place `i` of `open`, by its first place; `place[id]`: back.
    let mut id: Vec<usize> = (0..open.len()).collect();
    let mut place: Vec<Option<usize>> = (0..open.len()).map(Some).collect();
    let mut out = Vec::new();
    let mut near = Vec::new();
    while let Some(Open {
        points: mut chain,
        keys,
    }) = open.pop()
    {
        if let Some(c) = id.pop() {
            place[c] = None;
        }
        let start_key = keys[0];
        let mut end_key = keys[1];
        let mut solid: Option<bool> = None;
        loop {
            let (first, last) = (chain[0], chain[chain.len() - 1]);
            if (last - first).norm() <= tolerance && chain.len() > 2 {
                gaps.close((last - first).norm(), last);
                out.push(Contour::new(chain));
                break;
            }
            // The nearest end across the hole our end lies on: (distance, place or
            // none for our own start, reversed).
            let mut across: Option<(f64, Option<usize>, bool)> = None;
            if let Some(rim) = closing.holes.rim(end_key).filter(|r| rims.has(*r)) {
                if chain.len() > 2 && closing.holes.rim(start_key) == Some(rim) {
                    across = Some(((last - first).norm(), None, false));
                }
                // A start before any end: a mesh wound one way joins end to start, and
                // an end reversed is taken only where no start lies on the rim.
                for &(c, rev) in rims.on(rim) {
                    let Some(i) = place[c] else { continue };
                    let d = (end_of(&open[i].points, rev) - last).norm();
                    if across.is_none_or(|(b, bi, brev)| (rev, d, Some(i)) < (brev, b, bi)) {
                        across = Some((d, Some(i), rev));
                    }
                }
                if let Some((d, _, _)) = across
                    && d > tolerance
                    && !*solid.get_or_insert_with(|| (closing.bounds_solid)(&chain))
                {
                    across = None;
                }
            }
            let best = match across {
                Some((d, None, _)) => {
                    gaps.bridge(d, last);
                    out.push(Contour::new(chain));
                    break;
                }
                Some((d, Some(i), rev)) => {
                    gaps.bridge(d, last);
                    Some((i, rev))
                }
                None => {
                    // The nearest chain start (or end, reversed) to our end within the
                    // tolerance: (distance, place, reversed), least first.
                    let mut best: Option<(f64, usize, bool)> = None;
                    ends.near(last, &mut near);
                    for &(c, rev) in &near {
                        let Some(i) = place[c] else { continue };
                        let d = (end_of(&open[i].points, rev) - last).norm();
                        if d <= tolerance && best.is_none_or(|b| (d, i, rev) < b) {
                            best = Some((d, i, rev));
                        }
                    }
                    best.map(|(d, i, rev)| {
                        gaps.close(d, last);
                        (i, rev)
                    })
                }
            };
            match best {
                Some((i, rev)) => {
                    let mut next = open.swap_remove(i);
                    let taken = id.swap_remove(i);
                    place[taken] = None;
                    if let Some(&moved) = id.get(i) {
                        place[moved] = Some(i);
                    }
                    if rev {
                        next.points.reverse();
                        next.keys.reverse();
                    }
                    end_key = next.keys[1];
                    chain.extend(next.points);
                }
                None => {
                    gaps.dropped.push(Dropped {
                        points: chain.len(),
                        first,
                        last,
                        gap: (last - first).norm(),
                        area: swept_area(&chain, centre),
                        length: chain.windows(2).map(|w| (w[1] - w[0]).norm()).sum(),
                    });
                    break;
                }
            }
        }
    }
    out
}

/// A chain's first point, or its last when `rev`.
fn end_of(chain: &[Point2], rev: bool) -> Point2 {
    if rev { chain[chain.len() - 1] } else { chain[0] }
}

/// Most chain ends one rim may have in a layer for joins across it.
const RIM_ENDS: usize = 64;

/// Chain ends grouped by a key, in one list sorted by key: a soup's layer has tens of
/// thousands of ends, one or two per key, and a list of its own per key made that many
/// allocations, more time than the joins themselves.
struct Grouped<K> {
    /// Each key's run in `ends`: (first, past the last).
    runs: FxHashMap<K, (u32, u32)>,
    /// (chain, whether it is the chain's end), by key.
    ends: Vec<(usize, bool)>,
}

impl<K: Copy + Ord + std::hash::Hash> Grouped<K> {
    /// `keyed`'s ends grouped by their keys; within a key they keep their order.
    fn new(mut keyed: Vec<(K, (usize, bool))>) -> Self {
        keyed.sort_by_key(|&(k, _)| k);
        let mut runs = FxHashMap::with_capacity_and_hasher(keyed.len(), Default::default());
        let mut first = 0;
        for (i, w) in keyed.iter().enumerate() {
            if keyed.get(i + 1).is_none_or(|n| n.0 != w.0) {
                runs.insert(w.0, (first as u32, i as u32 + 1));
                first = i + 1;
            }
        }
        Self {
            runs,
            ends: keyed.into_iter().map(|(_, e)| e).collect(),
        }
    }

    fn get(&self, key: &K) -> &[(usize, bool)] {
        self.runs
            .get(key)
            .map_or(&[], |&(a, b)| &self.ends[a as usize..b as usize])
    }

    /// Drops the keys holding more than `most` ends.
    fn retain_at_most(&mut self, most: usize) {
        self.runs.retain(|_, (a, b)| (*b - *a) as usize <= most);
    }
}

/// The ends of open chains by the rim they lie on: (chain, whether it is the chain's
/// end), for the rims with at most [`RIM_ENDS`] of them.
struct RimEnds(Grouped<u32>);

impl RimEnds {
    fn new(open: &[Open], holes: &Holes) -> Self {
        let mut keyed = Vec::new();
        if holes.count() > 0 {
            for (c, chain) in open.iter().enumerate() {
                for (rev, key) in [(false, chain.keys[0]), (true, chain.keys[1])] {
                    if let Some(rim) = holes.rim(key) {
                        keyed.push((rim, (c, rev)));
                    }
                }
            }
        }
        let mut by_rim = Grouped::new(keyed);
        by_rim.retain_at_most(RIM_ENDS);
        Self(by_rim)
    }

    fn has(&self, rim: u32) -> bool {
        self.0.runs.contains_key(&rim)
    }

    fn on(&self, rim: u32) -> &[(usize, bool)] {
        self.0.get(&rim)
    }
}

/// The ends of open chains by grid bucket: (chain, whether it is the chain's end).
struct EndGrid {
    bucket: f64,
    buckets: Grouped<(i64, i64)>,
}

impl EndGrid {
    fn new(open: &[Open], tolerance: f64) -> Self {
        // A bucket no smaller than the coordinates can tell apart; buckets saturate far
        // out, which only puts more candidates in one bucket.
        let bucket = if tolerance.is_finite() && tolerance > 0.0 {
            tolerance.max(1e-9)
        } else {
            1e-9
        };
        let key = |p: Point2| Self::key_of(bucket, p);
        let keyed = open
            .iter()
            .enumerate()
            .flat_map(|(c, chain)| [false, true].map(|rev| (key(end_of(&chain.points, rev)), (c, rev))))
            .collect();
        Self {
            bucket,
            buckets: Grouped::new(keyed),
        }
    }

    fn key_of(bucket: f64, p: Point2) -> (i64, i64) {
        ((p.x / bucket).floor() as i64, (p.y / bucket).floor() as i64)
    }

    /// The ends in the buckets around `p` into `found`: every end within one bucket's size
    /// of it, and some farther.
    fn near(&self, p: Point2, found: &mut Vec<(usize, bool)>) {
        let (x, y) = Self::key_of(self.bucket, p);
        found.clear();
        for dx in -1..=1i64 {
            for dy in -1..=1i64 {
                found.extend_from_slice(self.buckets.get(&(x.saturating_add(dx), y.saturating_add(dy))));
            }
        }
    }
}

/// Refuses a layer thickness (option `key`) the pipeline's machine cannot press down.
pub(crate) fn check_layer_height(
    config: &lamina_api::stage::StageConfig<'_>,
    key: &str,
    t: f64,
) -> lamina_api::Result<()> {
    match config.machine {
        Some(m) if t > m.max_layer_height + 1e-9 => Err(config.error(
            key,
            format!(
                "{t} mm is thicker than machine `{}` lays: its {} mm nozzle presses layers of at most {} mm (`max_layer_height`)",
                m.name, m.nozzle_diameter, m.max_layer_height
            ),
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::Point3;

    /// An axis-aligned box made of 12 outward triangles.
    fn cube(size: f64) -> Mesh {
        let v: Vec<Point3> = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 != 0 { size } else { 0.0 },
                    if i & 2 != 0 { size } else { 0.0 },
                    if i & 4 != 0 { size } else { 0.0 },
                )
            })
            .collect();
        let quads = [
            [0, 2, 3, 1], // bottom (z = 0), facing down
            [4, 5, 7, 6], // top
            [0, 1, 5, 4], // y = 0
            [2, 6, 7, 3], // y = size
            [0, 4, 6, 2], // x = 0
            [1, 3, 7, 5], // x = size
        ];
        let mut t = Vec::new();
        for q in quads {
            t.push([q[0], q[1], q[2]]);
            t.push([q[0], q[2], q[3]]);
        }
        Mesh::new("cube", v, t)
    }

    fn slot(z: f64) -> LayerSlot {
        LayerSlot::new(0, z, 0.1, z)
    }

    #[test]
    fn cube_cuts_into_one_ccw_square() {
        let m = Arc::new(cube(2.0));
        assert!(m.signed_volume() > 0.0);
        let c = CutMesh::new(m, CutOptions::default());
        let l = c.cut(&slot(1.0)).expect("cut");
        assert_eq!(l.contours.len(), 1);
        assert!(l.contours[0].is_ccw());
        assert!((l.contours[0].area() - 4.0).abs() < 1e-12);
    }

    #[test]
    fn planes_through_vertices_and_faces_are_handled() {
        let c = CutMesh::new(Arc::new(cube(2.0)), CutOptions::default());
        // Through the bottom face: the bottom vertices count as above, nothing below.
        assert_eq!(c.cut(&slot(0.0)).expect("cut").contours.len(), 0);
        // Exactly through the top face: the side walls end there; a loop remains.
        let top = c.cut(&slot(2.0)).expect("cut");
        assert_eq!(top.contours.len(), 1, "{top:?}");
        assert!((top.contours[0].area() - 4.0).abs() < 1e-12);
        assert!(top.warnings.is_empty());
    }

    /// A barrel: squares of half-size 1 at z = 0 and 2, and one of half-size 2 at
    /// `ring` between them, the walls two triangles per quad.
    fn barrel(ring: f64) -> Mesh {
        let square = |h: f64, z: f64| [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, y)| Point3::new(x, y, z));
        let v: Vec<Point3> = [square(1.0, 0.0), square(2.0, ring), square(1.0, 2.0)].concat();
        let mut t = vec![[0, 3, 2], [0, 2, 1], [8, 9, 10], [8, 10, 11]];
        for i in 0..4u32 {
            let j = (i + 1) % 4;
            for (lo, hi) in [(0, 4), (4, 8)] {
                t.push([lo + i, lo + j, hi + j]);
                t.push([lo + i, hi + j, hi + i]);
            }
        }
        Mesh::new("barrel", v, t)
    }

    /// A vertex a few single-precision ulps off the plane (12.1 mm stored as a float) is
    /// cut as if in it: its edges all meet the plane at the vertex, and the loop has no
    /// sub-micrometre steps around it.
    #[test]
    fn vertices_within_rounding_of_the_plane_are_cut_in_it() {
        for ring in [1.0 + 1e-7, 1.0 - 1e-7, 1.0] {
            let c = CutMesh::new(Arc::new(barrel(ring)), CutOptions::default());
            let l = c.cut(&slot(1.0)).expect("cut");
            assert_eq!(l.contours.len(), 1, "{ring}");
            let mut points = l.contours[0].points.clone();
            points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
            let expected =
                [(-2.0, -2.0), (-2.0, 2.0), (2.0, -2.0), (2.0, 2.0)].map(|(x, y)| Point2::new(x, y));
            assert_eq!(points, expected, "{ring}");
            assert!(l.contours[0].is_ccw());
        }
        // Farther off, the cut is the exact one: a little inside the ring.
        let c = CutMesh::new(Arc::new(barrel(1.0 + 1e-4)), CutOptions::default());
        let l = c.cut(&slot(1.0)).expect("cut");
        assert_eq!(l.contours.len(), 1);
        let area = l.contours[0].area();
        assert!(area < 16.0 && area > 16.0 - 2e-3, "{area}");
    }

    #[test]
    fn inside_out_mesh_still_gives_ccw_outer() {
        let mut m = cube(1.0);
        for t in &mut m.triangles {
            t.swap(1, 2);
        }
        let c = CutMesh::new(Arc::new(m), CutOptions::default());
        let l = c.cut(&slot(0.5)).expect("cut");
        assert!(l.contours[0].is_ccw());
        // The section is the cut's area whichever way the mesh winds.
        let section = l.section_area.expect("measured");
        assert!((section - 1.0).abs() < 1e-12, "{section}");
    }

    #[test]
    fn overlapping_shells_are_measured_once() {
        // Two unit cubes, the second moved half a side along x: the cut is their
        // union, 1.5 mm², and so is the area the layer should hold.
        let mut m = cube(1.0);
        let shifted = cube(1.0);
        let base = m.vertices.len() as u32;
        m.vertices
            .extend(shifted.vertices.iter().map(|p| Point3::new(p.x + 0.5, p.y, p.z)));
        m.triangles
            .extend(shifted.triangles.iter().map(|t| t.map(|i| i + base)));
        let l = CutMesh::new(Arc::new(m), CutOptions::default())
            .cut(&slot(0.5))
            .expect("cut");
        let kept: f64 = l.contours.iter().map(Contour::signed_area).sum();
        let section = l.section_area.expect("measured");
        assert!(
            (kept - 1.5).abs() < 1e-9 && (section - 1.5).abs() < 1e-9,
            "{kept} {section}"
        );
    }

    #[test]
    fn a_loop_missing_a_piece_is_lost_area_and_a_stray_arc_is_not() {
        let dropped = |gap: f64, length: f64| Dropped {
            points: 2,
            first: Point2::origin(),
            last: Point2::origin(),
            gap,
            area: 0.0,
            length,
        };
        // A 4 mm square missing 3.5 mm of a side; a wall missing a triangle's width.
        assert!(dropped(3.5, 12.5).is_broken_loop());
        assert!(dropped(0.086, 120.0).is_broken_loop());
        // A stray sheet of radius 20 cut into a 219 degree arc; a flat fin.
        assert!(!dropped(37.8, 76.4).is_broken_loop());
        assert!(!dropped(10.0, 10.0).is_broken_loop());
    }

    #[test]
    fn a_box_missing_a_wall_is_closed_across_its_hole() {
        let mut m = cube(1.0);
        // Remove one side wall: the cut leaves an open chain with a 1 mm gap, 20 times
        // the distance limit, whose ends lie on the hole's rim.
        m.triangles.drain(4..6);
        let c = CutMesh::new(Arc::new(m), CutOptions::default());
        let l = c.cut(&slot(0.5)).expect("cut");
        assert_eq!(l.contours.len(), 1);
        assert!((l.contours[0].signed_area() - 1.0).abs() < 1e-12);
        assert_eq!(l.section_area, Some(l.contours[0].signed_area()));
        assert_eq!(l.warnings.len(), 1, "{:?}", l.warnings);
        let w = &l.warnings[0];
        assert_eq!(w.code, HOLES_CLOSED);
        assert!(
            w.message
                .contains("closed 1 cut(s) across holes of the mesh (1 hole(s)")
                && w.message.contains("the widest gap 1.000 mm"),
            "{w}"
        );
    }

    /// A prism of `sides` walls around the z axis, `radius` to its corners and 0 to
    /// `height` high, with its caps, wound outward.
    fn prism(sides: u32, radius: f64, height: f64) -> Mesh {
        let mut v = Vec::new();
        for z in [0.0, height] {
            for i in 0..sides {
                let a = std::f64::consts::TAU * f64::from(i) / f64::from(sides);
                v.push(Point3::new(radius * a.cos(), radius * a.sin(), z));
            }
        }
        v.push(Point3::new(0.0, 0.0, 0.0));
        v.push(Point3::new(0.0, 0.0, height));
        let (bottom, top) = (2 * sides, 2 * sides + 1);
        let mut t = Vec::new();
        for i in 0..sides {
            let j = (i + 1) % sides;
            t.push([i, j, sides + j]);
            t.push([i, sides + j, sides + i]);
            t.push([bottom, j, i]);
            t.push([top, sides + i, sides + j]);
        }
        Mesh::new("prism", v, t)
    }

    #[test]
    fn a_wall_triangle_missing_over_the_whole_height_closes_every_layer_whole() {
        let whole = prism(12, 10.0, 10.0);
        let mut m = whole.clone();
        // The wall's first triangle: every cut from z = 0 to 10 passes its hole, with
        // a gap of up to 5 mm.
        m.triangles.remove(0);
        let (whole, holed) = (
            CutMesh::new(Arc::new(whole), CutOptions::default()),
            CutMesh::new(Arc::new(m), CutOptions::default()),
        );
        for z in [0.1, 2.5, 5.0, 9.9] {
            let (a, b) = (
                whole.cut(&slot(z)).expect("cut"),
                holed.cut(&slot(z)).expect("cut"),
            );
            assert_eq!(b.contours.len(), 1, "z = {z}");
            let (a, b) = (a.contours[0].signed_area(), b.contours[0].signed_area());
            assert!((a - b).abs() < 1e-9 * a, "z = {z}: {b} against {a}");
        }
    }

    #[test]
    fn a_stray_sheet_is_reported_and_dropped() {
        // A third of an open cylinder, 10 mm in radius and 4 mm high: a sheet that
        // encloses nothing, its cut an arc whose ends lie on the sheet's one rim.
        let mut v = Vec::new();
        for z in [0.0, 4.0] {
            for i in 0..=8 {
                let a = std::f64::consts::TAU / 3.0 * f64::from(i) / 8.0;
                v.push(Point3::new(10.0 * a.cos(), 10.0 * a.sin(), z));
            }
        }
        let t = (0..8u32)
            .flat_map(|i| [[i, i + 1, i + 10], [i, i + 10, i + 9]])
            .collect();
        let c = CutMesh::new(Arc::new(Mesh::new("sheet", v, t)), CutOptions::default());
        assert_eq!(c.holes.count(), 1);
        let l = c.cut(&slot(2.0)).expect("cut");
        assert!(l.contours.is_empty());
        assert_eq!(l.warnings.len(), 1, "{:?}", l.warnings);
        let w = &l.warnings[0];
        assert_eq!(w.code, OPEN_CHAINS_DROPPED);
        assert!(w.message.starts_with("dropped an open chain"), "{w}");
        assert!(w.message.contains("gap of 17.321 mm"), "{w}");
        // An arc encloses nothing the layer should hold.
        assert_eq!(l.section_area, Some(0.0));
    }

    fn square(x: f64, y: f64, half: f64, ccw: bool) -> Contour {
        let mut c = Contour::new(vec![
            Point2::new(x - half, y - half),
            Point2::new(x + half, y - half),
            Point2::new(x + half, y + half),
            Point2::new(x - half, y + half),
        ]);
        if !ccw {
            c.reverse();
        }
        c
    }

    #[test]
    fn union_is_skipped_only_for_simple_disjoint_consistently_wound_loops() {
        let outer = square(0.0, 0.0, 2.0, true);
        let hole = square(0.0, 0.0, 1.0, false);
        let island = square(0.0, 0.0, 0.5, true);
        assert!(already_simple(&[outer.clone(), hole.clone(), island.clone()]));
        assert!(already_simple(&[square(10.0, 0.0, 1.0, true), outer.clone()]));
        // Nesting that disagrees with the winding: the union decides.
        assert!(!already_simple(&[outer.clone(), square(0.0, 0.0, 1.0, true)]));
        assert!(!already_simple(std::slice::from_ref(&hole)));
        // Overlapping shells, a shell touching another, one a hair away.
        assert!(!already_simple(&[outer.clone(), square(3.0, 0.0, 2.0, true)]));
        assert!(!already_simple(&[outer.clone(), square(4.0, 0.0, 2.0, true)]));
        assert!(!already_simple(&[
            outer.clone(),
            square(4.0 + 1e-9, 0.0, 2.0, true)
        ]));
        // A bow tie crosses itself; a spike folds back.
        let bow = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(1.0, 0.0),
            Point2::new(0.0, 1.0),
        ]);
        assert!(!already_simple(&[bow]));
        let spike = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(2.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
        ]);
        assert!(!already_simple(&[spike]));
        // Both ways give the same contours.
        let loops = [outer, hole, island];
        let union = union(&loops, CutOptions::default());
        let area = |cs: &[Contour]| cs.iter().map(Contour::signed_area).sum::<f64>();
        assert_eq!(union.len(), 3);
        assert!((area(&union) - area(&loops)).abs() < 1e-9);
    }

    /// The cut of 3DBenchy's layers 44-52 in miniature: a hole whose loop runs back over
    /// itself (a sliver triangle), so the loop crosses its own previous segment at A =
    /// (9, 5) and the non-zero rule fills the small curl A, (8.5, 5), (10, 5 + h). The
    /// union must return simple rings: no vertex visited twice, the curl dropped when
    /// it is under `min_area` and a shape of its own otherwise.
    #[test]
    fn a_curl_in_a_hole_gives_simple_rings() {
        for (h, curl_kept) in [(0.01, true), (1e-9, false)] {
            let outer = square(10.0, 10.0, 10.0, true);
            let hole = Contour::new(
                [
                    (5.0, 5.0),
                    (5.0, 15.0),
                    (15.0, 15.0),
                    (15.0, 5.0),
                    (8.5, 5.0),
                    (10.0, 5.0 + h),
                    (8.0, 5.0 - h),
                ]
                .iter()
                .map(|&(x, y)| Point2::new(x, y))
                .collect(),
            );
            let loops = [outer, hole];
            assert!(!already_simple(&loops));
            let out = union(&loops, CutOptions::default());
            for c in &out {
                let mut pts: Vec<(u64, u64)> =
                    c.points.iter().map(|p| (p.x.to_bits(), p.y.to_bits())).collect();
                pts.sort_unstable();
                let n = pts.len();
                pts.dedup();
                assert_eq!(pts.len(), n, "a ring visits a vertex twice: {c:?}");
            }
            // outer, hole, and the curl as an island of its own when it is large enough
            assert_eq!(out.len(), if curl_kept { 3 } else { 2 }, "{out:?}");
        }
    }
}
