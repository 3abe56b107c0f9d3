//! Beads cut where the material under them changes. A wall whose sub-regions are all
//! narrower than a bead (rings of 0.1 mm cut into circumferential cells that do not
//! line up from one ring to the next) is filled as one wall, with beads that follow it;
//! the material is then read back from the sub-regions each bead covers. Along the
//! bead, the composition of every short step is the mean of the sub-regions its
//! cross-section (a segment of the bead's width, across it) passes through, weighted
//! by the length of the cross-section inside each; the bead is cut where that
//! composition moves away from the piece's by more than a tolerance. The pieces follow
//! each other end to start, so a mixing head runs the wall as one extrusion whose mix
//! changes in place, and a tool changer gets each piece to the tool of its dominant
//! material.

use lamina_api::{BBox2, Composition, Point2, SubRegion, Vector2};

use crate::bead::Bead;

/// A stretch of a bead with one composition.
#[derive(Debug, Clone)]
pub struct Piece {
    pub bead: Bead,
    pub composition: Option<Composition>,
    /// The sub-regions under the piece, the one it covers most first.
    pub regions: Vec<usize>,
}

/// What lies under one step: the composition's fractions, and the length of the
/// cross-section in each sub-region (by index into the graded members).
type Under = (Vec<f64>, Vec<(usize, f64)>);

/// One step of a bead: where it ends on its segment, and what lies under it.
struct Sample {
    /// Segment index and the fraction along it where the step ends.
    segment: usize,
    end: f64,
    /// Area-weighted fractions and the weight per sub-region (index into `members`).
    fractions: Vec<f64>,
    under: Vec<(usize, f64)>,
}

/// `bead` cut into pieces of about one composition (no fraction more than `tolerance`
/// from the piece's first step), read from the sub-regions `members` of `regions`;
/// steps are at most `step` long. A bead over sub-regions without compositions comes
/// back whole, without a composition.
pub fn split(bead: Bead, members: &[usize], regions: &[SubRegion], step: f64, tolerance: f64) -> Vec<Piece> {
    let graded: Vec<usize> = members
        .iter()
        .copied()
        .filter(|&m| regions[m].composition.is_some())
        .collect();
    let n = graded
        .first()
        .and_then(|&m| regions[m].composition.as_ref())
        .map_or(0, |c| c.fractions.len());
    if n == 0
        || bead.points.len() < 2
        || graded.iter().any(|&m| {
            regions[m]
                .composition
                .as_ref()
                .is_none_or(|c| c.fractions.len() != n)
        })
    {
        return vec![Piece {
            bead,
            composition: None,
            regions: members.to_vec(),
        }];
    }
    let boxes: Vec<BBox2> = graded.iter().map(|&m| regions[m].polygon.bbox()).collect();
    let samples = sample(&bead, &graded, &boxes, regions, step.max(1e-3), n);
    let mut pieces = group_samples(&bead, &samples, tolerance, &graded);
    if bead.closed && pieces.len() > 1 {
        // The seam of a loop is no reason to cut it.
        let (first, last) = (&pieces[0], &pieces[pieces.len() - 1]);
        if close(first.composition.as_ref(), last.composition.as_ref(), tolerance) {
            let last = pieces.pop().expect("two pieces");
            let first = &mut pieces[0];
            let mut points = last.bead.points;
            points.extend_from_slice(&first.bead.points[1..]);
            let mut widths = last.bead.widths;
            widths.extend_from_slice(&first.bead.widths);
            first.bead = Bead {
                points,
                widths,
                closed: false,
            };
        }
    }
    if bead.closed && pieces.len() == 1 {
        pieces[0].bead.closed = true;
    }
    pieces
}

/// Whether no fraction of `a` is more than `tolerance` from `b`'s.
fn close(a: Option<&Composition>, b: Option<&Composition>, tolerance: f64) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => a
            .fractions
            .iter()
            .zip(&b.fractions)
            .all(|(x, y)| (x - y).abs() <= tolerance),
        (None, None) => true,
        _ => false,
    }
}

fn sample(
    bead: &Bead,
    graded: &[usize],
    boxes: &[BBox2],
    regions: &[SubRegion],
    step: f64,
    n: usize,
) -> Vec<Sample> {
    let mut out = Vec::new();
    let mut last: Option<Under> = None;
    for (i, (seg, &w)) in bead.points.windows(2).zip(&bead.widths).enumerate() {
        let (a, b) = (seg[0], seg[1]);
        let d = b - a;
        let len = d.norm();
        if len <= 1e-12 {
            continue;
        }
        let k = (len / step).ceil().clamp(1.0, 1e6) as usize;
        let normal = Vector2::new(-d.y, d.x) / len * (w.max(1e-6) / 2.0);
        for j in 0..k {
            let mid = a + d * ((j as f64 + 0.5) / k as f64);
            let (p0, p1) = (mid - normal, mid + normal);
            let cross = BBox2::from_points([p0, p1]);
            let mut fractions = vec![0.0; n];
            let mut under = Vec::new();
            let mut total = 0.0;
            for (g, &m) in graded.iter().enumerate() {
                if !boxes[g].overlaps(&cross) {
                    continue;
                }
                let inside = inside_length(&regions[m], p0, p1);
                if inside <= 0.0 {
                    continue;
                }
                let c = regions[m].composition.as_ref().expect("graded");
                for (f, x) in fractions.iter_mut().zip(&c.fractions) {
                    *f += inside * x;
                }
                under.push((g, inside));
                total += inside;
            }
            let (fractions, under) = if total > 0.0 {
                for f in &mut fractions {
                    *f /= total;
                }
                (fractions, under)
            } else {
                // Off every sub-region (a rounding at the wall's edge): as before.
                last.clone().unwrap_or_else(|| nearest(graded, regions, mid, n))
            };
            last = Some((fractions.clone(), under.clone()));
            out.push(Sample {
                segment: i,
                end: (j + 1) as f64 / k as f64,
                fractions,
                under,
            });
        }
    }
    out
}

/// The composition of the sub-region nearest `p` (by reference point).
fn nearest(graded: &[usize], regions: &[SubRegion], p: Point2, n: usize) -> Under {
    let best = (0..graded.len()).min_by(|&a, &b| {
        let da = (regions[graded[a]].reference - p).norm_squared();
        let db = (regions[graded[b]].reference - p).norm_squared();
        da.total_cmp(&db)
    });
    match best {
        Some(g) => (
            regions[graded[g]]
                .composition
                .as_ref()
                .map_or_else(|| vec![0.0; n], |c| c.fractions.clone()),
            vec![(g, 1.0)],
        ),
        None => (vec![0.0; n], Vec::new()),
    }
}

/// Length of the segment `p0`-`p1` inside `region` (even-odd over its contours).
fn inside_length(region: &SubRegion, p0: Point2, p1: Point2) -> f64 {
    let d = p1 - p0;
    let len = d.norm();
    if len <= 0.0 {
        return 0.0;
    }
    let mut ts: Vec<f64> = Vec::new();
    for c in region.polygon.contours() {
        let pts = &c.points;
        for i in 0..pts.len() {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            let e = b - a;
            let den = d.x * e.y - d.y * e.x;
            if den.abs() <= 1e-18 {
                continue;
            }
            let w = a - p0;
            let t = (w.x * e.y - w.y * e.x) / den;
            let u = (w.x * d.y - w.y * d.x) / den;
            if t > 0.0 && t < 1.0 && (0.0..=1.0).contains(&u) {
                ts.push(t);
            }
        }
    }
    ts.push(0.0);
    ts.push(1.0);
    ts.sort_by(f64::total_cmp);
    ts.dedup_by(|a, b| (*a - *b).abs() <= 1e-12);
    // Each stretch between crossings is inside or out as a whole: its middle says
    // which (a parity count would be fooled by ends on the boundary).
    let sum: f64 = ts
        .windows(2)
        .filter(|w| region.polygon.contains(p0 + d * ((w[0] + w[1]) / 2.0)))
        .map(|w| w[1] - w[0])
        .sum();
    sum.clamp(0.0, 1.0) * len
}

/// Consecutive samples grouped into pieces.
fn group_samples(bead: &Bead, samples: &[Sample], tolerance: f64, graded: &[usize]) -> Vec<Piece> {
    let mut pieces = Vec::new();
    let point_at = |s: &Sample| {
        let (a, b) = (bead.points[s.segment], bead.points[s.segment + 1]);
        a + (b - a) * s.end
    };
    let mut start = 0;
    while start < samples.len() {
        let first = &samples[start].fractions;
        let mut end = start + 1;
        while end < samples.len()
            && samples[end]
                .fractions
                .iter()
                .zip(first)
                .all(|(x, y)| (x - y).abs() <= tolerance)
        {
            end += 1;
        }
        // The piece runs from where sample `start` begins to where `end - 1` ends.
        let from = if start == 0 {
            bead.points[0]
        } else {
            point_at(&samples[start - 1])
        };
        let mut points = vec![from];
        let mut prev = from;
        let mut widths = Vec::new();
        let mut weight = vec![0.0; first.len()];
        let mut under: Vec<f64> = vec![0.0; graded.len()];
        for (k, s) in samples[start..end].iter().enumerate() {
            let p = point_at(s);
            let last_of_segment = k + 1 == end - start || samples[start + k + 1].segment != s.segment;
            let area = (p - prev).norm() * bead.widths[s.segment];
            prev = p;
            for (w, f) in weight.iter_mut().zip(&s.fractions) {
                *w += area.max(1e-12) * f;
            }
            for &(g, l) in &s.under {
                under[g] += l;
            }
            if last_of_segment {
                // Vertices within a segment's steps stay off the path.
                if (p - *points.last().expect("a point")).norm() > 1e-12 {
                    points.push(p);
                    widths.push(bead.widths[s.segment]);
                }
            }
        }
        if points.len() >= 2 {
            let total: f64 = weight.iter().sum();
            let composition = (total > 0.0)
                .then(|| normalised(weight.iter().map(|w| w / total).collect()))
                .flatten();
            let mut order: Vec<usize> = (0..graded.len()).filter(|&g| under[g] > 0.0).collect();
            order.sort_by(|&a, &b| under[b].total_cmp(&under[a]).then(a.cmp(&b)));
            pieces.push(Piece {
                bead: Bead {
                    points,
                    widths,
                    closed: false,
                },
                composition,
                regions: order.into_iter().map(|g| graded[g]).collect(),
            });
        }
        start = end;
    }
    pieces
}

/// Fractions clamped to [0, 1] with the rounding difference given to the largest.
fn normalised(mut fractions: Vec<f64>) -> Option<Composition> {
    for f in &mut fractions {
        *f = f.clamp(0.0, 1.0);
    }
    let err = 1.0 - fractions.iter().sum::<f64>();
    if let Some(big) = fractions.iter_mut().max_by(|a, b| a.total_cmp(b)) {
        *big = (*big + err).clamp(0.0, 1.0);
    }
    Composition::new(fractions).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::{Contour, Polygon};

    fn cell(x0: f64, x1: f64, y0: f64, y1: f64, f: f64, index: usize) -> SubRegion {
        SubRegion {
            family: 0,
            index: 0,
            count: 1,
            level: 0.0,
            polygon: Polygon::new(
                Contour::new(vec![
                    Point2::new(x0, y0),
                    Point2::new(x1, y0),
                    Point2::new(x1, y1),
                    Point2::new(x0, y1),
                ]),
                vec![],
            ),
            cell: Some(index),
            reference: Point2::new((x0 + x1) / 2.0, (y0 + y1) / 2.0),
            composition: Some(Composition::binary(f).expect("valid")),
            samples: Vec::new(),
        }
    }

    #[test]
    fn a_bead_over_two_cells_is_cut_where_they_meet() {
        let regions = vec![
            cell(0.0, 10.0, 0.0, 0.4, 1.0, 0),
            cell(10.0, 20.0, 0.0, 0.4, 0.0, 1),
        ];
        let bead = Bead {
            points: vec![Point2::new(0.0, 0.2), Point2::new(20.0, 0.2)],
            widths: vec![0.4],
            closed: false,
        };
        let pieces = split(bead.clone(), &[0, 1], &regions, 0.4, 0.01);
        assert_eq!(pieces.len(), 2, "{pieces:?}");
        let [a, b] = [&pieces[0], &pieces[1]];
        assert_eq!(a.bead.points.last(), b.bead.points.first(), "one chain");
        assert!((a.bead.points.last().expect("end").x - 10.0).abs() < 1e-9);
        assert_eq!(a.composition.as_ref().expect("graded").fractions, vec![1.0, 0.0]);
        assert_eq!(b.composition.as_ref().expect("graded").fractions, vec![0.0, 1.0]);
        assert_eq!((a.regions.clone(), b.regions.clone()), (vec![0], vec![1]));
        let area: f64 = pieces.iter().map(|p| p.bead.area()).sum();
        assert!((area - bead.area()).abs() < 1e-9);
    }

    #[test]
    fn a_bead_across_two_cells_takes_their_mean_by_cross_section() {
        // Cells stacked across the bead: a quarter of its width in the first.
        let regions = vec![
            cell(0.0, 20.0, 0.0, 0.1, 1.0, 0),
            cell(0.0, 20.0, 0.1, 0.4, 0.0, 1),
        ];
        let bead = Bead {
            points: vec![Point2::new(0.0, 0.2), Point2::new(20.0, 0.2)],
            widths: vec![0.4],
            closed: false,
        };
        let pieces = split(bead, &[0, 1], &regions, 0.4, 0.01);
        assert_eq!(pieces.len(), 1);
        let f = &pieces[0].composition.as_ref().expect("graded").fractions;
        assert!((f[0] - 0.25).abs() < 1e-9 && (f[1] - 0.75).abs() < 1e-9, "{f:?}");
        assert_eq!(pieces[0].regions, vec![1, 0], "the one it covers most first");
    }

    #[test]
    fn a_loop_of_one_composition_stays_a_loop() {
        let regions = vec![cell(-1.0, 11.0, -1.0, 11.0, 0.3, 0)];
        let ring: Vec<Point2> = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)]
            .iter()
            .map(|&(x, y)| Point2::new(x, y))
            .collect();
        let pieces = split(Bead::closed(ring, 0.4), &[0], &regions, 0.4, 0.01);
        assert_eq!(pieces.len(), 1);
        assert!(pieces[0].bead.closed);
        assert_eq!(pieces[0].bead.points.len(), 5);
    }
}
