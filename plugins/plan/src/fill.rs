//! The fill of one sub-region, to its boundary. Bead width is first fitted to the
//! region: a band of the discretiser (a ring between two iso-material contours) of
//! width W takes n = W / w' beads exactly when w' = W / n lies in the nozzle's width
//! range, so the nominal width is bent within that range to the nearest whole count
//! (the region's mean width, twice its area over its perimeter, stands for W).
//!
//! Then, level by level from the boundary inward (E_0 is the region, E_k+1 = E_k
//! eroded by w'), a closed loop of width w' runs at depth (k + ½) w' wherever the
//! region reaches depth (k + 1) w' (up to a slack of a tenth of w'): the boundary of
//! the erosion to that depth dilated back by w'/2. Its bead covers depths k w' to
//! (k + 1) w' and nothing of the next level, so loops never overlap beyond that slack.
//! What no loop covers (the medial band where the region is too thin for another
//! loop, and the corners between two loops) is the residue of each level, E_k minus
//! the loop's band; it is filled by variable-width beads along its centre line
//! ([`crate::axis`]), whose widths follow the residue's local width and whose areas
//! add up to the residue's. Loops and centre beads together fill the region's area.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::float::single::SingleFloatOverlay;
use lamina_api::{Point2, Polygon};

use lamina_geom::Shapes;
use lamina_geom::offset::{round_offset_straddling, round_outline, tidy_straddling as tidy};
use lamina_geom::ring::{ring_area, ring_of, ring_perimeter};
use lamina_geom::segment::segment_distance2;
use lamina_geom::simplify::simplify_straddling;

use crate::axis::centre_beads;
use crate::bead::Bead;

/// Largest distance (mm) between a loop or a level and the exact offset it stands
/// for: mainstream slicers' G-code resolution (PrusaSlicer's 0.0125 mm). The chords
/// straddle the exact line ([`simplify_straddling`]), so a loop is as much outside
/// its path as inside, and the part is not short of material along every convex wall.
/// Against 5 um with one-sided chords: a quarter fewer G-code lines and a fifth less
/// time for the graded two-tool 3DBenchy, its mean replayed coverage 0.9968 to 0.9958.
const TOLERANCE: f64 = 0.0125;

/// Largest distance (mm) between the centre line of a residue and the straight runs
/// its beads take. Finer than [`TOLERANCE`]: a centre bead fills its whole residue's
/// width, so where it sags off a curved centre line (a thin round wall) the sag is
/// an unfilled strip along the whole bead.
const AXIS_TOLERANCE: f64 = 0.005;

/// Upper bound on levels per region, so a huge region with a tiny width cannot run
/// away with memory.
const MAX_PASSES: usize = 100_000;

/// Residue pieces smaller than this share of a bead's square (w²) are specks: on the
/// gear and shaft they are a sixth of the residue's beads for 0.01 % of the area, each
/// a bead of under 0.003 mm³ that costs a travel and a retraction.
const SPECK: f64 = 0.05;

/// The widths a nozzle lays: the nominal one and the range a bead may be bent to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Widths {
    pub nominal: f64,
    pub min: f64,
    pub max: f64,
}

impl Widths {
    /// The width of the loops of a region whose mean width is `mean`: the nominal width
    /// bent, within the range, to fill the mean width with a whole number of beads.
    pub fn fitted(&self, mean: f64) -> f64 {
        if !(mean.is_finite() && mean > 0.0) {
            return self.nominal;
        }
        let n = (mean / self.nominal).round().max(1.0);
        let mut best: Option<f64> = None;
        for k in [n, n - 1.0, n + 1.0] {
            if k < 1.0 {
                continue;
            }
            let w = mean / k;
            if w >= self.min
                && w <= self.max
                && best.is_none_or(|b| (w - self.nominal).abs() < (b - self.nominal).abs())
            {
                best = Some(w);
            }
        }
        best.unwrap_or(self.nominal)
    }
}

/// Twice the area over the perimeter: the width of a band, the radius of a disc.
pub fn mean_width(p: &Polygon) -> f64 {
    let perimeter: f64 = p.contours().map(lamina_api::Contour::perimeter).sum();
    if perimeter > 0.0 {
        2.0 * p.area() / perimeter
    } else {
        0.0
    }
}

/// The region's contours for the offsetter, simplified first: sub-regions cut on a
/// fine grid carry hundreds of vertices per millimetre of round or stepped boundary,
/// and the offsetter's cost grows with every crossing of their offset edges (a thin
/// ring's inner and outer offsets cross at every wiggle). Dropping what strays less
/// than the chord tolerance moves no pass by more than that tolerance.
/// A region whose outer contour simplifies to a sliver has no shape.
fn shapes_of(p: &Polygon) -> Shapes {
    let ring = |c: &lamina_api::Contour| simplify_straddling(&ring_of(c), TOLERANCE);
    let outer = ring(&p.outer);
    if outer.len() < 3 {
        return Vec::new();
    }
    let mut shape = vec![outer];
    shape.extend(p.holes.iter().map(ring).filter(|c| c.len() >= 3));
    vec![shape]
}

/// `shapes` offset by `d` (negative: inward) with round joins, simplified with chords
/// that straddle the offset.
fn offset(shapes: &Shapes, d: f64) -> Shapes {
    round_offset_straddling(shapes, d, TOLERANCE)
}

/// The area of a shape: its outer ring less its holes (the offsetter writes holes
/// the other way round, so the signed areas add up to it).
fn shape_area(shape: &[Vec<[f64; 2]>]) -> f64 {
    shape.iter().map(|r| ring_area(r)).sum::<f64>().abs()
}

/// How far a loop's band reaches past the loop's bead (mm). Along a level's straight
/// and gently curved stretches the band's edge and the level's are the same line, which
/// the offsets' rounding and the engine's dropping of vertices within a fifth of the
/// tolerance of their chord leave on either side of each other: a hair of band beyond
/// the level costs nothing, a hair of level beyond the band is a residue as long as the
/// stretch, which would join the corners' residues and either make them hairlines or
/// send centre beads along it.
const REACH: f64 = 0.2 * TOLERANCE;

/// A residue whose mean width is below this share of the bead is a hairline (on the
/// gear and shaft, hairlines were 95 % of the beads and a third of the nozzle's path,
/// for 0.3 % of the area).
const HAIRLINE: f64 = 0.05;

/// The narrowest end of a centre bead, as a share of the bead: a tip that tapers
/// below it is laid by the segment next to it, at the same volume. A nozzle ten times
/// wider lays nothing of it but a move; on 3DBenchy these tips were 4.6 m of the
/// nozzle's path (2.6 minutes of the print) for 14 mm³.
const TIP: f64 = 0.1;

/// Twice the area over the perimeter of a shape (outer ring and holes).
fn shape_mean_width(shape: &[Vec<[f64; 2]>]) -> f64 {
    let perimeter: f64 = shape.iter().map(|r| ring_perimeter(r)).sum();
    if perimeter > 0.0 {
        2.0 * shape_area(shape) / perimeter
    } else {
        0.0
    }
}

/// The beads filling `polygon`: loops outermost first, then the centre beads of what
/// they leave. Empty for a region with no area, or none but specks and hairlines.
pub fn fill(polygon: &Polygon, widths: &Widths) -> Vec<Bead> {
    Fill::start(polygon, widths).map(Fill::beads).unwrap_or_default()
}

/// A fill begun: the bead width fitted and the region's first erosion made, which is
/// enough to tell that it will lay beads ([`Fill::surely_beads`]) before the rest is
/// worked out.
pub struct Fill {
    w: f64,
    level: Shapes,
    /// The level eroded by a width less the slack: where the first loop runs.
    deep: Shapes,
}

impl Fill {
    /// The fill of `polygon`; `None` for a region with no area (no beads).
    pub fn start(polygon: &Polygon, widths: &Widths) -> Option<Self> {
        if widths.nominal.is_nan()
            || widths.nominal <= 0.0
            || polygon.outer.len() < 3
            || polygon.area() <= 0.0
        {
            return None;
        }
        let w = widths.fitted(mean_width(polygon));
        let level = shapes_of(polygon);
        let deep = deep(&level, w);
        Some(Self { w, level, deep })
    }

    /// Whether the fill lays a loop, and so at least one bead (`false`: not known):
    /// a region that reaches a width deep has a loop at half a width.
    pub fn surely_beads(&self) -> bool {
        self.deep.iter().any(|shape| shape_area(shape) > 0.0)
    }

    /// The beads: loops outermost first, then the centre beads of what they leave.
    pub fn beads(self) -> Vec<Bead> {
        let Self { w, mut level, deep } = self;
        let slack = slack(w);
        let mut beads = Vec::new();
        let mut residue: Shapes = Vec::new();
        let mut first = Some(deep);
        for _ in 0..MAX_PASSES {
            if level.is_empty() {
                break;
            }
            // Where the level reaches one more width (less the slack), a loop at half a
            // width; its band reaches from the level's boundary to the next level's.
            let deep = first.take().unwrap_or_else(|| self::deep(&level, w));
            if deep.is_empty() {
                residue.extend(level);
                break;
            }
            let loops = offset(&deep, w / 2.0 - slack);
            for contour in loops.iter().flatten() {
                let mut points: Vec<Point2> = contour.iter().map(|q| Point2::new(q[0], q[1])).collect();
                // Every loop runs counter-clockwise, holes' too: two tools working along
                // the same wall then move the same way round instead of meeting head-on,
                // where one of them must step aside.
                if ring_area(contour) < 0.0 {
                    points.reverse();
                }
                beads.push(Bead::closed(points, w));
            }
            let band = round_outline(&loops, w / 2.0 + REACH, TOLERANCE);
            let rest: Shapes = tidy(
                level.overlay(&band, OverlayRule::Difference, FillRule::EvenOdd),
                TOLERANCE,
            );
            residue.extend(rest);
            level = offset(&level, -w);
        }
        // Offsets and the difference leave rounding slivers and specks, and a loop's band
        // meets the next level along hairlines thinner than anything a nozzle lays:
        // dropped once, here. Their area is nothing; their length would be minutes of
        // nozzle travel.
        residue.retain(|s| shape_area(s) >= SPECK * w * w && shape_mean_width(s) >= HAIRLINE * w);
        // Edges split to one width at most: a segment's bead stands for the triangle it
        // crosses, and the longer the triangles the less a bead of their mean width
        // covers them where the residue widens or bends (splitting to three widths saves
        // a fifth of the plan's time and leaves 0.7 % of a layer uncovered on 3DBenchy's
        // cabin, against 0.2 %).
        // Their ends are laid by the segment next to them where they taper below a
        // tenth of the bead.
        beads.extend(centre_beads(&residue, w, AXIS_TOLERANCE, TIP * w));
        beads
    }
}

/// How much less than a width `w` a level must reach for another loop: a tenth of it.
fn slack(w: f64) -> f64 {
    0.1 * w
}

/// `level` eroded by a width `w` less the slack: empty when the level is surely
/// thinner than that. A shape whose mean width reaches twice the depth (a band as wide
/// as two depths, a disc as wide as one) is offset without the thinness test, which
/// would sample all of it only to find one deep point.
fn deep(level: &Shapes, w: f64) -> Shapes {
    let d = w - slack(w);
    if level
        .iter()
        .all(|shape| shape_mean_width(shape) < 2.0 * d && surely_thin(shape, d))
    {
        Vec::new()
    } else {
        offset(level, -d)
    }
}

/// Largest number of sample points the thinness test spends on one shape before it
/// leaves the answer to the offsetter.
const MAX_SAMPLES: usize = 200_000;

/// Most cells of the edge table of the thinness test.
const MAX_CELLS: usize = 4096;

/// Whether no point of `shape` (outer ring, then holes) lies `d` or more from its
/// boundary, so that offsetting it inward by `d` leaves nothing. Most sub-regions of a
/// finely graded part are such slivers, and proving it on a sample grid is far cheaper
/// than offsetting them. Distance to the boundary is 1-Lipschitz: with samples `s`
/// apart, every point inside is within `s/√2` of an inside sample (or of the boundary),
/// so when every inside sample is nearer than `d - s/√2` to an edge, no point reaches
/// `d`. `false` means "not proven", never "thick".
fn surely_thin(shape: &[Vec<[f64; 2]>], d: f64) -> bool {
    let s = d / 3.0;
    let reach = d - s * std::f64::consts::FRAC_1_SQRT_2;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for q in shape.iter().flatten() {
        for a in 0..2 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    if !(lo[0].is_finite() && hi[0].is_finite() && lo[1].is_finite() && hi[1].is_finite() && s > 0.0) {
        return false;
    }
    let cols = ((hi[0] - lo[0]) / s).ceil() as usize + 1;
    let rows = ((hi[1] - lo[1]) / s).ceil() as usize + 1;
    if cols.saturating_mul(rows) > MAX_SAMPLES {
        return false;
    }
    // Edges binned on cells of side at least `reach` (coarser on large shapes, to keep
    // the table small): a sample nearer than `reach` to an edge finds it in its own cell
    // or the eight around it. Compressed rows: `start[c]..start[c + 1]` in `binned`.
    let cell = reach.max(((hi[0] - lo[0]) * (hi[1] - lo[1]) / MAX_CELLS as f64).sqrt());
    let (gw, gh) = (
        ((hi[0] - lo[0]) / cell) as usize + 1,
        ((hi[1] - lo[1]) / cell) as usize + 1,
    );
    let cell_of = |v: f64, a: usize, n: usize| (((v - lo[a]) / cell).max(0.0) as usize).min(n - 1);
    let edges: Vec<([f64; 2], [f64; 2])> = shape
        .iter()
        .filter(|r| r.len() >= 2)
        .flat_map(|r| (0..r.len()).map(move |i| (r[i], r[(i + 1) % r.len()])))
        .collect();
    let span = |(a, b): &([f64; 2], [f64; 2])| {
        (
            cell_of(a[0].min(b[0]), 0, gw)..=cell_of(a[0].max(b[0]), 0, gw),
            cell_of(a[1].min(b[1]), 1, gh)..=cell_of(a[1].max(b[1]), 1, gh),
        )
    };
    let mut start = vec![0u32; gw * gh + 1];
    let mut total = 0usize;
    for e in &edges {
        let (xs, ys) = span(e);
        total += xs.clone().count() * ys.clone().count();
        if total > MAX_SAMPLES {
            return false;
        }
        for y in ys {
            for x in xs.clone() {
                start[y * gw + x + 1] += 1;
            }
        }
    }
    for c in 0..gw * gh {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut binned = vec![0u32; total];
    for (i, e) in edges.iter().enumerate() {
        let (xs, ys) = span(e);
        for y in ys {
            for x in xs.clone() {
                let slot = &mut fill[y * gw + x];
                binned[*slot as usize] = i as u32;
                *slot += 1;
            }
        }
    }
    let bins = |c: usize| &binned[start[c] as usize..start[c + 1] as usize];
    // Rows of samples at y = lo + (k + ½) s; the inside of a row lies between pairs of
    // sorted edge crossings (even-odd, which the outer ring and holes share).
    let mut crossings: Vec<(usize, f64)> = Vec::new();
    for (a, b) in &edges {
        let (p, q) = if a[1] <= b[1] { (a, b) } else { (b, a) };
        if p[1] == q[1] {
            continue;
        }
        let first = ((p[1] - lo[1]) / s - 0.5).ceil().max(0.0) as usize;
        let mut k = first;
        loop {
            let y = lo[1] + (k as f64 + 0.5) * s;
            if y >= q[1] || k >= rows {
                break;
            }
            if y >= p[1] {
                crossings.push((k, p[0] + (q[0] - p[0]) * (y - p[1]) / (q[1] - p[1])));
            }
            k += 1;
        }
    }
    crossings.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let reach2 = reach * reach;
    let near = |x: f64, y: f64| {
        let (cx, cy) = (cell_of(x, 0, gw), cell_of(y, 1, gh));
        (cy.saturating_sub(1)..=(cy + 1).min(gh - 1)).any(|gy| {
            (cx.saturating_sub(1)..=(cx + 1).min(gw - 1)).any(|gx| {
                bins(gy * gw + gx).iter().any(|&e| {
                    let (a, b) = edges[e as usize];
                    segment_distance2([x, y], a, b) < reach2
                })
            })
        })
    };
    for row in crossings.chunk_by(|a, b| a.0 == b.0) {
        let y = lo[1] + (row[0].0 as f64 + 0.5) * s;
        for pair in row.chunks_exact(2) {
            let (xa, xb) = (pair[0].1, pair[1].1);
            // Samples on the column grid x = lo + (j + ½) s inside [xa, xb].
            let mut j = ((xa - lo[0]) / s - 0.5).ceil().max(0.0) as usize;
            loop {
                let x = lo[0] + (j as f64 + 0.5) * s;
                if x > xb {
                    break;
                }
                if !near(x, y) {
                    return false;
                }
                j += 1;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::Contour;

    fn square(c: f64, h: f64) -> Contour {
        Contour::square(Point2::new(c, c), h)
    }

    const NOZZLE: Widths = Widths {
        nominal: 0.4,
        min: 0.24,
        max: 0.6,
    };

    fn filled(beads: &[Bead]) -> f64 {
        beads.iter().map(Bead::area).sum()
    }

    #[test]
    fn widths_are_bent_to_a_whole_count() {
        // A 1.1 mm ring: three beads of 0.367, not two of 0.4 and a gap.
        assert!((NOZZLE.fitted(1.1) - 1.1 / 3.0).abs() < 1e-12);
        assert!((NOZZLE.fitted(0.5) - 0.5).abs() < 1e-12);
        assert!((NOZZLE.fitted(0.7) - 0.35).abs() < 1e-12);
        assert_eq!(NOZZLE.fitted(0.1), 0.4, "nothing in range");
    }

    #[test]
    fn a_square_is_filled_to_its_area() {
        let p = Polygon::new(square(0.0, 5.0), vec![]);
        let beads = fill(&p, &NOZZLE);
        assert!(
            beads
                .iter()
                .all(|b| b.points.len() >= 2 && b.widths.len() + 1 == b.points.len())
        );
        let loops = beads.iter().filter(|b| b.closed).count();
        // Mean width 5 mm: beads of 5 / 12 mm, twelve loops deep... less the centre.
        assert!(loops >= 10, "{loops}");
        let a = filled(&beads);
        assert!((a - p.area()).abs() / p.area() < 0.01, "{a} vs {}", p.area());
        for b in &beads {
            for w in &b.widths {
                assert!(*w > 0.0 && *w < 1.0, "{w}");
            }
        }
    }

    #[test]
    fn every_corner_of_every_level_is_filled_whatever_the_turn() {
        // Each loop's band, the level eroded and grown back by a width, leaves the
        // level's four corners: each takes a centre bead, at every level, also where
        // the sides are slanted and the offsets' rounding lies along them.
        for degrees in [0.0f64, 10.0, 30.0, 45.0] {
            let (sin, cos) = degrees.to_radians().sin_cos();
            let turned = [[0.0, 0.0], [5.0, 0.0], [5.0, 5.0], [0.0, 5.0]]
                .iter()
                .map(|[x, y]| Point2::new(x * cos - y * sin + 3.3, x * sin + y * cos - 1.7))
                .collect();
            let p = Polygon::new(Contour::new(turned), vec![]);
            let beads = fill(&p, &NOZZLE);
            let loops = beads.iter().filter(|b| b.closed).count();
            assert_eq!(loops, 6, "{degrees}");
            assert_eq!(beads.len() - loops, 4 * loops, "{degrees}");
            let a = filled(&beads);
            assert!((a - 25.0).abs() < 0.05, "{degrees}: {a}");
        }
    }

    #[test]
    fn no_bead_is_a_hairline() {
        // Bands whose loops meet the next level along hairlines: every bead lays
        // something a nozzle can, and the area is still filled.
        // Rings between circles drawn with different vertex counts (as offset rings
        // of a real part are): their loops and the next level never quite meet.
        let circle = |r: f64, n: usize| {
            Contour::new(
                (0..n)
                    .map(|i| {
                        let a = std::f64::consts::TAU * i as f64 / n as f64;
                        Point2::new(r * a.cos(), r * a.sin())
                    })
                    .collect(),
            )
        };
        for band in [0.8, 1.2, 1.6, 2.4] {
            let p = Polygon::new(circle(10.0, 96), vec![circle(10.0 - band, 61).oriented(false)]);
            let beads = fill(&p, &NOZZLE);
            for b in &beads {
                let widest = b.widths.iter().copied().fold(0.0, f64::max);
                assert!(
                    widest >= HAIRLINE * NOZZLE.nominal,
                    "band {band}: a bead {widest} wide"
                );
            }
            let a = filled(&beads);
            assert!(
                (a - p.area()).abs() / p.area() < 0.01,
                "band {band}: {a} vs {}",
                p.area()
            );
        }
    }

    #[test]
    fn rings_are_filled_without_gaps_or_overlaps() {
        for band in [0.3, 0.5, 0.6, 0.8, 1.1, 1.3, 2.0, 2.75] {
            let p = Polygon::new(square(0.0, 5.0), vec![square(0.0, 5.0 - band).oriented(false)]);
            let beads = fill(&p, &NOZZLE);
            let a = filled(&beads);
            assert!(
                (a - p.area()).abs() / p.area() < 0.01,
                "band {band}: {a} vs {}",
                p.area()
            );
            for b in &beads {
                for w in &b.widths {
                    assert!(*w < 2.0 * NOZZLE.max, "band {band}: width {w}");
                }
            }
        }
    }

    #[test]
    fn a_thin_region_gets_a_centre_bead() {
        let thin = Polygon::new(square(0.0, 0.15), vec![]);
        let beads = fill(&thin, &NOZZLE);
        assert!(!beads.is_empty());
        assert!((filled(&beads) - 0.09).abs() < 1e-6);
    }

    #[test]
    fn a_speck_gets_no_bead() {
        // 0.05 of a 0.4 mm bead's square is 0.008 mm²: a square 0.1 mm wide (0.01 mm²)
        // takes a bead, one 0.085 mm wide (0.0072 mm²) none. Both are wider than a
        // hairline (0.02 mm).
        let kept = fill(&Polygon::new(square(0.0, 0.05), vec![]), &NOZZLE);
        assert!((filled(&kept) - 0.01).abs() < 1e-6, "{}", filled(&kept));
        assert!(fill(&Polygon::new(square(0.0, 0.0425), vec![]), &NOZZLE).is_empty());
    }
}
