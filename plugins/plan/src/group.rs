//! Which sub-regions are filled together. A sub-region at least one extrusion width
//! across is filled on its own, along its own iso-material contours. A discretisation
//! finer than the bead (ten rings across a 1 mm wall cut rings of 0.1 mm) leaves
//! sub-regions no pass fits in; dropping them would leave the wall empty, so each such
//! sliver is merged with the next levels of its family (and cell) until the merged band
//! takes a pass, and the band is deposited with the area-weighted mean of the merged
//! compositions: the finest grading the bead can lay down. Only what is thinner than a
//! pass even with all its neighbours (a fin narrower than the bead) is left out, and
//! reported.

use std::collections::{BTreeMap, HashMap};

use i_overlay::core::fill_rule::FillRule;
use i_overlay::float::simplify::SimplifyShape;
use lamina_api::{Composition, Contour, Point2, Polygon, SubRegion};

use crate::bead::Bead;
use crate::fill::{Fill, Widths, fill, mean_width};
use crate::pieces;

lamina_api::option_type!(Thin = "string");

/// What to do with sub-regions too thin for one pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Thin {
    /// Deposit them together with the next levels of their family.
    #[default]
    Merge,
    /// Leave them out (and report them).
    Skip,
}

/// Sub-regions of one part filled as one: their passes and mean composition.
#[derive(Debug, Clone)]
pub struct Group {
    /// Indices into the part's regions, in level order.
    pub members: Vec<usize>,
    pub passes: Vec<Bead>,
    pub composition: Option<Composition>,
}

/// How a part's sub-regions are filled.
#[derive(Debug, Default)]
pub struct Grouping {
    pub groups: Vec<Group>,
    /// (first region index, area in mm²) of what no pass fits in.
    pub thin: Vec<(usize, f64)>,
}

impl Grouping {
    /// Sub-regions deposited together with others.
    pub fn merged(&self) -> usize {
        self.groups
            .iter()
            .filter(|g| g.members.len() > 1)
            .flat_map(|g| &g.members)
            .collect::<std::collections::BTreeSet<_>>()
            .len()
    }
}

/// Groups the sub-regions of one part for filling with beads of `widths`.
pub fn group(regions: &[SubRegion], widths: &Widths, thin: Thin) -> Grouping {
    let grouper = Grouper {
        regions,
        widths,
        // A region whose mean width is below the narrowest bead cannot be laid alone.
        width: widths.min,
        thin,
    };
    let (buckets, walls) = grouper.sort();
    let mut out = Grouping::default();
    // Per family, the regions still too thin after merging within their cell.
    let mut leftover: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for levels in buckets.values() {
        grouper.family(levels, &mut out, &mut leftover);
    }
    grouper.merge_across_cells(leftover, &mut out);
    for members in walls.into_values() {
        wall(regions, &members, widths, &mut out);
    }
    for g in &mut out.groups {
        if g.members.len() > 1 && g.composition.is_none() {
            g.composition = mean_composition(regions, &g.members);
        }
    }
    out
}

/// Levels of each family and cell, in level order: per (family, cell), per level, the
/// indices of its regions.
type Buckets = BTreeMap<(usize, Option<usize>), BTreeMap<usize, Vec<usize>>>;

/// The sub-regions of one part and the beads that fill them: what every grouping
/// decision reads.
struct Grouper<'a> {
    regions: &'a [SubRegion],
    widths: &'a Widths,
    /// The narrowest bead's width.
    width: f64,
    thin: Thin,
}

impl Grouper<'_> {
    /// The regions by family, cell and level, and apart from them, per family, the
    /// thin circumferential cells: their levels' cells need not line up, so they are
    /// filled as one wall and the material read back along the beads.
    fn sort(&self) -> (Buckets, BTreeMap<usize, Vec<usize>>) {
        let mut buckets = Buckets::new();
        let mut walls: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for (i, r) in self.regions.iter().enumerate() {
            if r.cell.is_some() && self.thin == Thin::Merge && mean_width(&r.polygon) < self.width {
                walls.entry(r.family).or_default().push(i);
                continue;
            }
            buckets
                .entry((r.family, r.cell))
                .or_default()
                .entry(r.index)
                .or_default()
                .push(i);
        }
        (buckets, walls)
    }

    /// The beads filling the union of `members`. Unions are always taken of the
    /// regions as cut: a union's output is rounded to its own grid, and a second union
    /// against it would find the shared edges a rounding apart.
    fn fill_union(&self, members: &[usize]) -> Vec<Bead> {
        ring_union(&self.polygons(members))
            .iter()
            .flat_map(|q| fill(q, self.widths))
            .collect()
    }

    /// The fills of the union of `members` when every piece of it takes a bead (merged
    /// levels of a cell that do not touch stay as thin as they were) and it lays any.
    fn fills_if_wide(&self, members: &[usize]) -> Option<Fills> {
        let pieces = ring_union(&self.polygons(members));
        if pieces.iter().all(|q| mean_width(q) >= self.width) {
            Fills::of(
                pieces
                    .iter()
                    .filter_map(|q| Fill::start(q, self.widths))
                    .collect(),
            )
        } else {
            None
        }
    }

    /// The polygons of `members`.
    fn polygons(&self, members: &[usize]) -> Vec<&Polygon> {
        members.iter().map(|&m| &self.regions[m].polygon).collect()
    }

    /// Half the perimeter of a level: the length of a band along its family, so that
    /// area / length is the band's mean width.
    fn length(&self, members: &[usize]) -> f64 {
        members
            .iter()
            .flat_map(|&m| self.regions[m].polygon.contours())
            .map(Contour::perimeter)
            .sum::<f64>()
            / 2.0
    }

    /// Groups the levels of one family and cell: each level wide enough on its own,
    /// and the thinner ones merged with the next until the band takes a pass. What
    /// stays too thin goes to `leftover`, by family.
    fn family(
        &self,
        levels: &BTreeMap<usize, Vec<usize>>,
        out: &mut Grouping,
        leftover: &mut BTreeMap<usize, Vec<usize>>,
    ) {
        let (regions, width) = (self.regions, self.width);
        let first = out.groups.len();
        // The groups of this family whose beads are not laid out yet. The last group
        // takes the innermost levels when they are too thin on their own, and is then
        // filled with them; so that no group is filled for nothing, fills wait until
        // the family's groups are known.
        let mut later: Vec<(usize, Vec<Fill>)> = Vec::new();
        let mut push = |out: &mut Grouping, group: Group, fills: Fills| match fills {
            Fills::Done(passes) => out.groups.push(Group { passes, ..group }),
            Fills::Later(fills) => {
                later.push((out.groups.len(), fills));
                out.groups.push(group);
            }
        };
        let mut pending: Vec<usize> = Vec::new();
        let (mut area, mut along) = (0.0, 0.0f64);
        for members in levels.values() {
            if pending.is_empty() {
                for &m in members {
                    let fills = if mean_width(&regions[m].polygon) >= width {
                        Fill::start(&regions[m].polygon, self.widths).and_then(|f| Fills::of(vec![f]))
                    } else {
                        None
                    };
                    if let Some(fills) = fills {
                        let group = Group {
                            members: vec![m],
                            passes: Vec::new(),
                            composition: regions[m].composition.clone(),
                        };
                        push(out, group, fills);
                    } else if self.thin == Thin::Skip {
                        out.thin.push((m, regions[m].area()));
                    } else {
                        pending.push(m);
                        area += regions[m].area();
                        along = along.max(self.length(&[m]));
                    }
                }
                continue;
            }
            pending.extend_from_slice(members);
            area += members.iter().map(|&m| regions[m].area()).sum::<f64>();
            along = along.max(self.length(members));
            // Nested bands share their sides, so the merged band is about as long as
            // its longest level and as wide as their areas add up to: no union is
            // tried before that width nears one pass.
            if area < width * along {
                continue;
            }
            if let Some(fills) = self.fills_if_wide(&pending) {
                let group = Group {
                    members: std::mem::take(&mut pending),
                    passes: Vec::new(),
                    composition: None,
                };
                push(out, group, fills);
                (area, along) = (0.0, 0.0);
            }
        }
        // The innermost levels: with the last group of the family, on their own when
        // they were never tried together, or left out when the whole family is
        // thinner than a pass.
        if !pending.is_empty() && out.groups.len() > first {
            let last = out.groups.len() - 1;
            later.retain(|(g, _)| *g != last);
            let last = &mut out.groups[last];
            last.members.append(&mut pending);
            last.passes = self.fill_union(&last.members);
        }
        for (g, fills) in later {
            out.groups[g].passes = fills.into_iter().flat_map(Fill::beads).collect();
        }
        if pending.is_empty() {
            return;
        }
        let fills = if area >= width * along {
            self.fills_if_wide(&pending)
        } else {
            None
        };
        match fills {
            None => leftover
                .entry(regions[pending[0]].family)
                .or_default()
                .extend(pending),
            Some(fills) => out.groups.push(Group {
                members: pending,
                passes: fills.into_beads(),
                composition: None,
            }),
        }
    }

    /// What stayed too thin within its cell (cells of neighbouring levels need not
    /// line up, so a cell's levels can be scattered slivers) is merged across the
    /// cells of its family: each connected piece of their union that takes a bead is
    /// filled, with the mean composition of the slivers it holds.
    fn merge_across_cells(&self, leftover: BTreeMap<usize, Vec<usize>>, out: &mut Grouping) {
        let regions = self.regions;
        for members in leftover.into_values() {
            for piece in union(members.iter().map(|&m| &regions[m].polygon)) {
                let inside = inside(regions, &members, &piece);
                let Some(&first) = inside.first() else {
                    continue;
                };
                if mean_width(&piece) >= self.width {
                    out.groups.push(Group {
                        members: inside,
                        passes: fill(&piece, self.widths),
                        composition: None,
                    });
                } else {
                    out.thin.push((first, piece.area()));
                }
            }
        }
    }
}

/// The fills of a group known to lay beads: laid out already, or begun with one that
/// surely lays a loop, to be finished once it is known that the group keeps its
/// members.
enum Fills {
    Done(Vec<Bead>),
    Later(Vec<Fill>),
}

impl Fills {
    /// The fills of `fills` in order, or `None` when they lay no bead.
    fn of(fills: Vec<Fill>) -> Option<Self> {
        if fills.iter().any(Fill::surely_beads) {
            return Some(Fills::Later(fills));
        }
        let beads: Vec<Bead> = fills.into_iter().flat_map(Fill::beads).collect();
        (!beads.is_empty()).then_some(Fills::Done(beads))
    }

    fn into_beads(self) -> Vec<Bead> {
        match self {
            Fills::Done(beads) => beads,
            Fills::Later(fills) => fills.into_iter().flat_map(Fill::beads).collect(),
        }
    }
}

/// The sub-regions among `members` that lie in `piece` of their union.
fn inside(regions: &[SubRegion], members: &[usize], piece: &Polygon) -> Vec<usize> {
    let bbox = piece.bbox();
    members
        .iter()
        .copied()
        .filter(|&m| {
            let polygon = &regions[m].polygon;
            polygon.bbox().overlaps(&bbox)
                && polygon.outer.interior_point().is_some_and(|p| piece.contains(p))
        })
        .collect()
}

/// Fills the union of the thin cells `members` of one family as one wall, each bead
/// cut into pieces by the composition of the cells under it ([`pieces`]).
fn wall(regions: &[SubRegion], members: &[usize], widths: &Widths, out: &mut Grouping) {
    for piece in union(members.iter().map(|&m| &regions[m].polygon)) {
        let inside = inside(regions, members, &piece);
        let Some(&first) = inside.first() else {
            continue;
        };
        if mean_width(&piece) < widths.min {
            out.thin.push((first, piece.area()));
            continue;
        }
        for bead in fill(&piece, widths) {
            for p in pieces::split(bead, &inside, regions, widths.nominal, PIECE_TOLERANCE) {
                let members = if p.regions.is_empty() {
                    vec![first]
                } else {
                    p.regions
                };
                let composition = p.composition.or_else(|| mean_composition(regions, &inside));
                out.groups.push(Group {
                    members,
                    passes: vec![p.bead],
                    composition,
                });
            }
        }
    }
}

/// Largest difference of a material's fraction along one piece of a wall's bead: the
/// percent resolution of a mixing head's mix.
const PIECE_TOLERANCE: f64 = 0.01;

/// The area-weighted mean composition of `members` (none when they are not graded).
fn mean_composition(regions: &[SubRegion], members: &[usize]) -> Option<Composition> {
    let mut sum: Vec<f64> = Vec::new();
    let mut total = 0.0;
    for &m in members {
        let c = regions[m].composition.as_ref()?;
        let a = regions[m].area();
        if sum.is_empty() {
            sum = vec![0.0; c.fractions.len()];
        }
        if sum.len() != c.fractions.len() {
            return regions[members[0]].composition.clone();
        }
        for (s, f) in sum.iter_mut().zip(&c.fractions) {
            *s += a * f;
        }
        total += a;
    }
    if total <= 0.0 {
        return regions[members[0]].composition.clone();
    }
    let mut fractions: Vec<f64> = sum.iter().map(|s| (s / total).clamp(0.0, 1.0)).collect();
    // Rounding can leave the sum a few ulps off 1: give the difference to the largest.
    let err = 1.0 - fractions.iter().sum::<f64>();
    if let Some(big) = fractions.iter_mut().max_by(|a, b| a.total_cmp(b)) {
        *big = (*big + err).clamp(0.0, 1.0);
    }
    Composition::new(fractions)
        .ok()
        .or_else(|| regions[members[0]].composition.clone())
}

/// The union of sub-regions of one family and cell: nested rings of a family share
/// whole contours (a ring's hole is the next ring's outer contour, point for point, the
/// other way round), so their union is the contours that are not shared
/// ([`seamless_union`]), without a boolean; anything else goes through [`union`].
fn ring_union(pieces: &[&Polygon]) -> Vec<Polygon> {
    seamless_union(pieces).unwrap_or_else(|| union(pieces.iter().copied()))
}

/// A contour's points, for matching: exact coordinates.
fn bits(p: Point2) -> (u64, u64) {
    (p.x.to_bits(), p.y.to_bits())
}

/// The union of `pieces` (disjoint, tiling their union) when every piece shares a
/// whole contour with another, traversed the other way: the contours left once each
/// such pair is dropped, each hole in the smallest outer contour around it. `None`
/// (take the boolean union) when a piece shares no whole contour, or when two of the
/// contours left, of different pieces, meet at a point: where pieces share only part
/// of a contour (cut across, or split at different points), the seams would stay.
fn seamless_union(pieces: &[&Polygon]) -> Option<Vec<Polygon>> {
    if pieces.len() < 2 {
        return None;
    }
    // (piece, contour), with the index of its least point and its length as the key.
    let contours: Vec<(usize, &Contour)> = pieces
        .iter()
        .enumerate()
        .flat_map(|(i, p)| p.contours().map(move |c| (i, c)))
        .filter(|(_, c)| c.points.len() >= 3)
        .collect();
    let least = |c: &Contour| {
        (0..c.points.len())
            .min_by_key(|&k| bits(c.points[k]))
            .unwrap_or(0)
    };
    let keys: Vec<(usize, usize, (u64, u64))> = contours
        .iter()
        .map(|(_, c)| {
            let k = least(c);
            (k, c.points.len(), bits(c.points[k]))
        })
        .collect();
    let mut by_key: HashMap<(usize, (u64, u64)), Vec<usize>> = HashMap::new();
    for (i, &(_, n, p)) in keys.iter().enumerate() {
        by_key.entry((n, p)).or_default().push(i);
    }
    // Whether contour `b` is contour `a` run backwards.
    let reversed = |a: usize, b: usize| {
        let (ca, cb) = (&contours[a].1.points, &contours[b].1.points);
        let (ka, kb, n) = (keys[a].0, keys[b].0, ca.len());
        (0..n).all(|k| bits(ca[(ka + k) % n]) == bits(cb[(kb + n - k) % n]))
    };
    let mut shared = vec![false; contours.len()];
    let mut joined = vec![false; pieces.len()];
    for a in 0..contours.len() {
        if shared[a] {
            continue;
        }
        let key = (keys[a].1, keys[a].2);
        let partner = by_key[&key]
            .iter()
            .copied()
            .find(|&b| b != a && !shared[b] && contours[b].0 != contours[a].0 && reversed(a, b));
        if let Some(b) = partner {
            shared[a] = true;
            shared[b] = true;
            joined[contours[a].0] = true;
            joined[contours[b].0] = true;
        }
    }
    if !joined.iter().all(|&j| j) {
        return None;
    }
    let kept: Vec<&(usize, &Contour)> = contours
        .iter()
        .zip(&shared)
        .filter(|(_, s)| !**s)
        .map(|(c, _)| c)
        .collect();
    let mut owner: HashMap<(u64, u64), usize> = HashMap::new();
    for (piece, c) in &kept {
        for &q in &c.points {
            if *owner.entry(bits(q)).or_insert(*piece) != *piece {
                return None;
            }
        }
    }
    let (outers, holes): (Vec<&Contour>, Vec<&Contour>) =
        kept.iter().map(|(_, c)| *c).partition(|c| c.signed_area() > 0.0);
    let areas: Vec<f64> = outers.iter().map(|c| c.area()).collect();
    let mut polygons: Vec<Polygon> = outers
        .iter()
        .map(|c| Polygon::new((*c).clone().oriented(true), Vec::new()))
        .collect();
    for hole in holes {
        let p = hole.points[0];
        let home = (0..outers.len())
            .filter(|&i| outers[i].contains(p))
            .min_by(|&i, &j| areas[i].total_cmp(&areas[j]))?;
        polygons[home].holes.push(hole.clone().oriented(false));
    }
    Some(polygons)
}

/// Holes of a union smaller than this (mm²) are slits, not holes: where cells of
/// neighbouring levels, cut apart on their own, meet a few nanometres apart. On the
/// cooled blade's walls two hundred such slits (1e-8 mm² each, up to a millimetre
/// long) doubled a wall's perimeter and so halved its mean width, which then read as
/// thinner than a bead: the whole wall was left out. A real hole this small (a micron
/// square) is nothing a nozzle could leave open.
const SLIT: f64 = 1e-6;

/// The union of sub-regions of one family: they tile it without overlap and their
/// shared edges come from one integer grid, so the non-zero union closes the seams
/// (and what the rounding leaves of them, [`SLIT`]s, is dropped).
fn union<'a>(pieces: impl Iterator<Item = &'a Polygon>) -> Vec<Polygon> {
    let paths: Vec<Vec<[f64; 2]>> = pieces
        .flat_map(|p| p.contours())
        .map(|c| c.points.iter().map(|q| [q.x, q.y]).collect())
        .collect();
    paths
        .simplify_shape(FillRule::NonZero)
        .into_iter()
        .filter_map(|shape| {
            let mut rings = shape
                .into_iter()
                .filter(|r| r.len() >= 3)
                .map(|r| Contour::new(r.into_iter().map(|[x, y]| Point2::new(x, y)).collect()));
            let outer = rings.next()?;
            Some(Polygon::new(
                outer.oriented(true),
                rings
                    .filter(|h| h.area().abs() >= SLIT)
                    .map(|h| h.oriented(false))
                    .collect(),
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::Vector2;

    /// Beads of 0.4 mm, none narrower.
    const W: Widths = Widths {
        nominal: 0.4,
        min: 0.4,
        max: 0.6,
    };

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Contour {
        Contour::rectangle(Point2::new(x0, y0), Point2::new(x1, y1))
    }

    /// A 1 mm × 20 mm strip cut into `n` bands across its width, graded from the
    /// first material to the second.
    fn strip(n: usize) -> Vec<SubRegion> {
        (0..n)
            .map(|j| {
                let (y0, y1) = (j as f64 / n as f64, (j + 1) as f64 / n as f64);
                let f = j as f64 / (n - 1) as f64;
                SubRegion {
                    family: 0,
                    index: j,
                    count: n,
                    level: f,
                    polygon: Polygon::new(rect(0.0, y0, 20.0, y1), vec![]),
                    cell: None,
                    reference: Point2::new(10.0, (y0 + y1) / 2.0),
                    composition: Some(Composition::binary(1.0 - f).expect("valid")),
                    samples: Vec::new(),
                }
            })
            .collect()
    }

    /// The square ring between half sides `outer` and `inner` about the origin, the
    /// hole's points starting `turn` corners on.
    fn ring(outer: f64, inner: f64, turn: usize) -> Polygon {
        let mut hole = Contour::square(Point2::origin(), inner).oriented(false);
        hole.points.rotate_left(turn);
        Polygon::new(Contour::square(Point2::origin(), outer), vec![hole])
    }

    #[test]
    fn nested_rings_are_joined_along_the_contours_they_share() {
        // Three rings, each hole the next ring's outer contour backwards, from
        // another point: one ring from the outermost contour to the innermost hole.
        let rings = [ring(5.0, 4.0, 1), ring(4.0, 3.0, 3), ring(3.0, 2.0, 2)];
        let pieces: Vec<&Polygon> = rings.iter().collect();
        let joined = seamless_union(&pieces).expect("whole contours shared");
        assert_eq!(joined.len(), 1);
        assert_eq!(joined[0].outer, Contour::square(Point2::origin(), 5.0));
        assert_eq!(joined[0].holes.len(), 1);
        assert_eq!(joined[0].holes[0], rings[2].holes[0]);
        assert!((joined[0].area() - (100.0 - 16.0)).abs() < 1e-12);
        // The same as the boolean union, to its grid.
        let boolean = union(pieces.iter().copied());
        assert_eq!(boolean.len(), 1);
        assert!((boolean[0].area() - joined[0].area()).abs() < 1e-9);
        // The core inside the last ring closes the hole.
        let core = Polygon::new(Contour::square(Point2::origin(), 2.0), vec![]);
        let all: Vec<&Polygon> = rings.iter().chain([&core]).collect();
        let joined = seamless_union(&all).expect("whole contours shared");
        assert_eq!(joined.len(), 1);
        assert!(joined[0].holes.is_empty());
    }

    #[test]
    fn pieces_that_share_part_of_a_contour_or_none_go_to_the_boolean_union() {
        // Bands of a strip share part of their rectangles' sides.
        let bands = strip(3);
        let pieces: Vec<&Polygon> = bands.iter().map(|r| &r.polygon).collect();
        assert!(seamless_union(&pieces).is_none());
        assert_eq!(ring_union(&pieces).len(), 1);
        // A ring and a square apart from it share nothing.
        let (r, apart) = (
            ring(5.0, 4.0, 0),
            Polygon::new(rect(20.0, 0.0, 21.0, 1.0), vec![]),
        );
        assert!(seamless_union(&[&r, &apart]).is_none());
        assert_eq!(ring_union(&[&r, &apart]).len(), 2);
        // Two rings joined along a whole contour, and a ring and its core beside them
        // joined too, whose outer contours touch at a corner: left to the boolean.
        let (a, b) = (ring(5.0, 4.0, 0), ring(4.0, 3.0, 0));
        let beside = |p: &Polygon| {
            let moved =
                |c: &Contour| Contour::new(c.points.iter().map(|q| q + Vector2::new(7.0, 7.0)).collect());
            Polygon::new(moved(&p.outer), p.holes.iter().map(moved).collect())
        };
        let (c, core) = (
            beside(&ring(2.0, 1.0, 0)),
            beside(&Polygon::new(Contour::square(Point2::origin(), 1.0), vec![])),
        );
        assert!(seamless_union(&[&a, &b]).is_some());
        assert!(seamless_union(&[&c, &core]).is_some());
        assert!(seamless_union(&[&a, &b, &c, &core]).is_none());
        // The boolean's valid shapes meet at a point at most: two of them.
        assert_eq!(ring_union(&[&a, &b, &c, &core]).len(), 2);
    }

    #[test]
    fn wide_regions_are_filled_alone() {
        let g = group(&strip(2), &W, Thin::Merge);
        assert_eq!(g.groups.len(), 2);
        assert!(
            g.groups
                .iter()
                .all(|g| g.members.len() == 1 && !g.passes.is_empty())
        );
        assert_eq!(g.merged(), 0);
        assert!(g.thin.is_empty());
    }

    #[test]
    fn slivers_merge_with_the_next_levels_until_a_pass_fits() {
        // Ten bands of 0.1 mm: 0.4 mm of them leave nothing after the half-width
        // inset, so bands 0..=4 make the first band that takes a 0.4 mm pass and
        // 5..=9 the second.
        let regions = strip(10);
        let g = group(&regions, &W, Thin::Merge);
        let members: Vec<Vec<usize>> = g.groups.iter().map(|g| g.members.clone()).collect();
        assert_eq!(members, vec![(0..5).collect::<Vec<_>>(), (5..10).collect()]);
        assert!(g.thin.is_empty());
        assert_eq!(g.merged(), 10);
        for grp in &g.groups {
            assert!(!grp.passes.is_empty());
            // The mean of a linear grading over equal bands is its middle value.
            let expect: f64 = grp
                .members
                .iter()
                .map(|&m| regions[m].composition.as_ref().expect("graded").fractions[0])
                .sum::<f64>()
                / grp.members.len() as f64;
            let c = grp.composition.as_ref().expect("graded");
            assert!((c.fractions[0] - expect).abs() < 1e-9, "{c:?} vs {expect}");
            assert!((c.fractions.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        let skipped = group(&regions, &W, Thin::Skip);
        assert!(skipped.groups.is_empty());
        assert_eq!(skipped.thin.len(), 10);
    }

    #[test]
    fn slivers_of_cells_that_do_not_line_up_merge_across_cells() {
        // Three 0.1 mm levels of a 20 mm strip, each cut into two cells whose order
        // alternates: a cell's levels never touch, but together they make the strip.
        let mut regions = Vec::new();
        for j in 0..3 {
            let (y0, y1) = (j as f64 * 0.1, (j + 1) as f64 * 0.1);
            for (cell, (x0, x1)) in [(0.0, 10.0), (10.0, 20.0)].into_iter().enumerate() {
                let cell = if j % 2 == 0 { cell } else { 1 - cell };
                let f = j as f64 / 2.0;
                regions.push(SubRegion {
                    family: 0,
                    index: j,
                    count: 3,
                    level: f,
                    polygon: Polygon::new(rect(x0, y0, x1, y1), vec![]),
                    cell: Some(cell),
                    reference: Point2::new((x0 + x1) / 2.0, (y0 + y1) / 2.0),
                    composition: Some(Composition::binary(1.0 - f).expect("valid")),
                    samples: Vec::new(),
                });
            }
        }
        let w = Widths {
            nominal: 0.4,
            min: 0.25,
            max: 0.6,
        };
        let g = group(&regions, &w, Thin::Merge);
        assert!(g.thin.is_empty(), "{:?}", g.thin);
        assert_eq!(g.merged(), 6);
        let filled: f64 = g.groups.iter().flat_map(|g| &g.passes).map(Bead::area).sum();
        assert!((filled - 6.0).abs() < 0.06, "{filled}");
        // No bead narrower than the narrowest one the nozzle lays, bar the ends.
        let longest = g
            .groups
            .iter()
            .flat_map(|g| &g.passes)
            .max_by(|a, b| a.length().total_cmp(&b.length()))
            .expect("a bead");
        assert!(longest.length() > 15.0 && longest.area() / longest.length() > 0.25);
    }

    #[test]
    fn thin_cells_that_do_not_line_up_are_filled_as_one_wall_graded_along_it() {
        // Ten 0.1 mm levels of a 1 mm × 20 mm wall, each cut into cells of its own
        // length (4 to 6 per level), graded by the cell's position along the wall.
        let mut regions = Vec::new();
        for j in 0..10 {
            let (y0, y1) = (j as f64 * 0.1, (j + 1) as f64 * 0.1);
            let n = 4 + j % 3;
            for c in 0..n {
                let (x0, x1) = (20.0 * c as f64 / n as f64, 20.0 * (c + 1) as f64 / n as f64);
                let f = (x0 + x1) / 40.0;
                regions.push(SubRegion {
                    family: 0,
                    index: j,
                    count: 10,
                    level: j as f64 / 9.0,
                    polygon: Polygon::new(rect(x0, y0, x1, y1), vec![]),
                    cell: Some(c),
                    reference: Point2::new((x0 + x1) / 2.0, (y0 + y1) / 2.0),
                    composition: Some(Composition::binary(f).expect("valid")),
                    samples: Vec::new(),
                });
            }
        }
        let w = Widths {
            nominal: 0.4,
            min: 0.25,
            max: 0.6,
        };
        let g = group(&regions, &w, Thin::Merge);
        assert!(g.thin.is_empty(), "{:?}", g.thin);
        assert_eq!(g.merged(), regions.len());
        let filled: f64 = g.groups.iter().flat_map(|g| &g.passes).map(Bead::area).sum();
        assert!((filled - 20.0).abs() < 0.2, "{filled}");
        // Long beads along the wall, cut into pieces end to start.
        let ends: Vec<(Point2, Point2)> = g
            .groups
            .iter()
            .flat_map(|g| &g.passes)
            .map(|b| (b.points[0], b.points[b.points.len() - 1]))
            .collect();
        let chained = ends
            .iter()
            .filter(|(a, _)| ends.iter().any(|(_, b)| (*a - *b).norm() < 1e-9))
            .count();
        assert!(
            chained * 2 > ends.len(),
            "{chained} of {} pieces go on from another",
            ends.len()
        );
        // Each piece takes the grading of the cells under it: the first material's
        // share follows the position along the wall within a cell's length.
        for grp in &g.groups {
            let c = grp.composition.as_ref().expect("graded");
            assert!((c.fractions.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            let bead = &grp.passes[0];
            let xs: Vec<f64> = bead.points.iter().map(|p| p.x).collect();
            let mid = (xs.iter().copied().fold(f64::INFINITY, f64::min)
                + xs.iter().copied().fold(f64::NEG_INFINITY, f64::max))
                / 2.0;
            assert!(
                (c.fractions[0] - mid / 20.0).abs() <= 0.2,
                "piece about x = {mid} has {:?}",
                c.fractions
            );
        }
    }

    #[test]
    fn slits_between_cells_are_closed_and_real_holes_kept() {
        // Two strips whose shared side is dented by 0.4 um on one of them: the union
        // is the whole rectangle, not one with a slit hole doubling its perimeter.
        let low = Polygon::new(rect(0.0, 0.0, 10.0, 1.0), vec![]);
        let dented = |depth: f64| {
            let p = |x: f64, y: f64| Point2::new(x, y);
            Polygon::new(
                Contour::new(vec![
                    p(0.0, 1.0),
                    p(4.0, 1.0),
                    p(5.0, 1.0 + depth),
                    p(6.0, 1.0),
                    p(10.0, 1.0),
                    p(10.0, 2.0),
                    p(0.0, 2.0),
                ]),
                vec![],
            )
        };
        let closed = union([&low, &dented(4e-7)].into_iter());
        assert_eq!(closed.len(), 1);
        assert!(closed[0].holes.is_empty(), "{:?}", closed[0].holes);
        assert!((closed[0].area() - 20.0).abs() < 1e-5);
        assert!(mean_width(&closed[0]) > 1.6);
        // A dent of 0.01 mm (a hole of 0.01 mm²) is a hole.
        let open = union([&low, &dented(0.01)].into_iter());
        assert_eq!(open[0].holes.len(), 1);
    }

    #[test]
    fn a_family_thinner_than_a_pass_is_reported_once() {
        let mut regions = strip(3);
        for r in &mut regions {
            for c in [&mut r.polygon.outer] {
                for p in &mut c.points {
                    p.y *= 0.3;
                }
            }
        }
        let g = group(&regions, &W, Thin::Merge);
        assert!(g.groups.is_empty());
        assert_eq!(g.thin.len(), 1);
        assert!((g.thin[0].1 - 6.0).abs() < 1e-6, "{:?}", g.thin);
    }
}
