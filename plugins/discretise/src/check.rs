//! Checks that sub-regions tile their family: areas add up, no two overlap (measured by
//! a boolean union), every polygon is simple and oriented (outer counter-clockwise,
//! holes clockwise). Used by the tests and the acceptance suite on real models.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::float::single::SingleFloatOverlay;
use lamina_core::{Contour, Polygon, Region};

/// How well a set of regions tiles a family.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tiling {
    pub family_area: f64,
    /// Sum of the regions' areas.
    pub region_area: f64,
    /// |region area - family area| / family area.
    pub area_error: f64,
    /// Area covered more than once (sum of areas less the area of their union), relative
    /// to the family's area.
    pub overlap: f64,
    /// Contours wrongly oriented (outer clockwise or hole counter-clockwise).
    pub misoriented: usize,
    /// Contours with crossing edges or with fewer than 3 points.
    pub non_simple: usize,
}

impl Tiling {
    /// Within the targets: 1e-3 of the area, no overlap, every polygon valid.
    pub fn is_ok(&self, tolerance: f64) -> bool {
        self.area_error <= tolerance
            && self.overlap <= tolerance
            && self.misoriented == 0
            && self.non_simple == 0
    }
}

/// Measures how `regions` tile `family`.
pub fn tiling(family: &Polygon, regions: &[Region]) -> Tiling {
    let family_area = family.area();
    let region_area: f64 = regions.iter().map(Region::area).sum();
    let paths: Vec<Vec<[f64; 2]>> = regions
        .iter()
        .flat_map(|r| r.polygon.contours())
        .map(|c| c.points.iter().map(|p| [p.x, p.y]).collect())
        .collect();
    let empty: Vec<Vec<[f64; 2]>> = Vec::new();
    // Each region's holes are clockwise: the positive rule counts every covered point
    // once, the union's area is what the regions cover.
    let union = if paths.is_empty() {
        Vec::new()
    } else {
        paths.overlay(&empty, OverlayRule::Subject, FillRule::Positive)
    };
    let union_area: f64 = union
        .iter()
        .flatten()
        .map(|c| Contour::new(c.iter().map(|p| lamina_core::Point2::new(p[0], p[1])).collect()).signed_area())
        .sum();
    let scale = family_area.abs().max(f64::MIN_POSITIVE);
    let mut misoriented = 0;
    let mut non_simple = 0;
    for r in regions {
        if !r.polygon.outer.is_ccw() {
            misoriented += 1;
        }
        misoriented += r.polygon.holes.iter().filter(|h| h.is_ccw()).count();
        non_simple += r
            .polygon
            .contours()
            .filter(|c| c.len() < 3 || self_crossings(c) > 0)
            .count();
    }
    Tiling {
        family_area,
        region_area,
        area_error: (region_area - family_area).abs() / scale,
        overlap: ((region_area - union_area) / scale).max(0.0),
        misoriented,
        non_simple,
    }
}

/// Proper crossings between non-adjacent edges of one contour, found by a sweep over
/// the edges sorted by their lowest x.
pub fn self_crossings(c: &Contour) -> usize {
    let n = c.len();
    if n < 4 {
        return 0;
    }
    let edges: Vec<_> = c.edges().collect();
    let mut order: Vec<usize> = (0..n).collect();
    let lo = |i: usize| edges[i].0.x.min(edges[i].1.x);
    let hi = |i: usize| edges[i].0.x.max(edges[i].1.x);
    order.sort_unstable_by(|&a, &b| lo(a).total_cmp(&lo(b)));
    let mut active: Vec<usize> = Vec::new();
    let mut count = 0;
    for &i in &order {
        let x = lo(i);
        active.retain(|&j| hi(j) >= x);
        for &j in &active {
            let adjacent = (i + 1) % n == j || (j + 1) % n == i;
            if !adjacent && crosses(edges[i], edges[j]) {
                count += 1;
            }
        }
        active.push(i);
    }
    count
}

type Seg = (lamina_core::Point2, lamina_core::Point2);

/// Whether two segments cross at a point interior to both.
fn crosses((a, b): Seg, (c, d): Seg) -> bool {
    let orient = |p: lamina_core::Point2, q: lamina_core::Point2, r: lamina_core::Point2| {
        (q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x)
    };
    let d1 = orient(a, b, c);
    let d2 = orient(a, b, d);
    let d3 = orient(c, d, a);
    let d4 = orient(c, d, b);
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_core::Point2;

    #[test]
    fn a_bow_tie_crosses_itself() {
        let bow = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(1.0, 0.0),
            Point2::new(0.0, 1.0),
        ]);
        assert_eq!(self_crossings(&bow), 1);
        assert_eq!(self_crossings(&crate::shapes::rect(0.0, 0.0, 1.0, 1.0)), 0);
    }

    #[test]
    fn overlapping_regions_are_measured() {
        let family = Polygon::new(crate::shapes::rect(0.0, 0.0, 2.0, 1.0), vec![]);
        let region = |x: f64| Region {
            family: 0,
            index: 0,
            count: 1,
            level: 0.0,
            polygon: Polygon::new(crate::shapes::rect(x, 0.0, 1.5, 1.0), vec![]),
            cell: None,
            reference: Point2::new(x, 0.5),
            composition: None,
        };
        let t = tiling(&family, &[region(0.0), region(0.5)]);
        assert!((t.overlap - 0.5).abs() < 1e-9, "{t:?}");
        assert!((t.area_error - 0.5).abs() < 1e-9);
    }
}
