//! The contours of a family's sub-regions as the modified CLI file stores them (Fig. 9
//! of the topological-hierarchy paper): every distinct contour once, from the outermost
//! to the innermost, each with its contour identifying number: 1 for the family's outer
//! contour, 2..N for the offset contours from the outside in, 0 for the innermost
//! contours (the family's holes).
//!
//! The ids are read from the geometry, not from the discretiser's settings: a region
//! boundary that is the family's outer contour is 1 and one that is a hole is 0, in
//! whatever mode the rings were made (from the outer contour, from every boundary, in
//! islands or cells). A contour shared by two sub-regions (the hole of ring j is the
//! outer boundary of ring j + 1) is written once, with the id and material of the
//! deeper region: the contour at which that region starts, as C_Dj starts R_j in
//! Fig. 5. A boundary that no other region shares (a cell's outline, an island's edge)
//! is written with the region it bounds: its outer boundary opens ring j (id j + 1),
//! its holes close it (id j + 2, or 0 for the last ring).

use lamina_api::{BBox2, Contour, PartLayer, SubRegion};

/// Relative area difference and distance (mm) within which two rings are one contour.
/// The sub-regions of a family share their vertices exactly (one integer grid), and the
/// grid is micrometre-fine: a family contour comes back within its rounding.
const SAME_AREA: f64 = 1e-5;
const SAME_DISTANCE: f64 = 1e-3;

/// Vertices of a ring checked against the other ring (spread along it).
const SAMPLES: usize = 16;

/// One contour to write.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry<'a> {
    /// The paper's contour identifying number.
    pub id: usize,
    /// Counter-clockwise (the outer boundary of `region`) or clockwise (a hole of it).
    pub ccw: bool,
    /// The region whose material the contour carries (index into the part's regions).
    pub region: usize,
    pub contour: &'a Contour,
}

#[derive(Debug, Clone, Copy)]
struct Ring<'a> {
    contour: &'a Contour,
    area: f64,
    bbox: BBox2,
    /// Index into the part's regions.
    region: usize,
    outer: bool,
}

impl<'a> Ring<'a> {
    fn new(contour: &'a Contour, region: usize, outer: bool) -> Self {
        Ring {
            contour,
            area: contour.area(),
            bbox: contour.bbox(),
            region,
            outer,
        }
    }
}

/// Whether two rings are the same closed curve: equal areas and bounding boxes, and
/// sampled vertices of each on the other.
fn same(a: &Contour, a_area: f64, a_box: &BBox2, b: &Contour, b_area: f64, b_box: &BBox2) -> bool {
    let close = |p: lamina_api::Point2, q: lamina_api::Point2| (p - q).norm() <= SAME_DISTANCE;
    if (a_area - b_area).abs() > SAME_AREA * a_area.max(b_area)
        || !close(a_box.min, b_box.min)
        || !close(a_box.max, b_box.max)
    {
        return false;
    }
    let on = |x: &Contour, y: &Contour| {
        let n = x.points.len();
        let step = (n / SAMPLES).max(1);
        x.points
            .iter()
            .step_by(step)
            .all(|&p| y.distance(p) <= SAME_DISTANCE)
    };
    on(a, b) && on(b, a)
}

/// The contours of every family of `part`, each family's from the outside in (1, 2,
/// ..., N, then 0), families in the order their regions come.
pub fn entries(part: &PartLayer) -> Vec<Entry<'_>> {
    let mut families: Vec<usize> = Vec::new();
    for r in &part.regions {
        if !families.contains(&r.family) {
            families.push(r.family);
        }
    }
    let mut out = Vec::new();
    for f in families {
        out.extend(family_entries(part, f));
    }
    out
}

fn family_entries(part: &PartLayer, family: usize) -> Vec<Entry<'_>> {
    let regions: &[SubRegion] = &part.regions;
    let mut rings = Vec::new();
    for (i, r) in regions.iter().enumerate().filter(|(_, r)| r.family == family) {
        rings.push(Ring::new(&r.polygon.outer, i, true));
        rings.extend(r.polygon.holes.iter().map(|h| Ring::new(h, i, false)));
    }
    // The family's own contours, to recognise its outer contour and its holes.
    let fam = part.tree.families.get(family);
    let original = |ring: &Ring<'_>, c: usize| {
        part.contours
            .get(c)
            .is_some_and(|c| same(ring.contour, ring.area, &ring.bbox, c, c.area(), &c.bbox()))
    };
    // Pairs: a hole of one region that is the outer boundary of another.
    let mut partner = vec![None; rings.len()];
    for a in 0..rings.len() {
        if rings[a].outer || partner[a].is_some() {
            continue;
        }
        for b in 0..rings.len() {
            let (x, y) = (&rings[a], &rings[b]);
            if y.outer
                && partner[b].is_none()
                && x.region != y.region
                && same(x.contour, x.area, &x.bbox, y.contour, y.area, &y.bbox)
            {
                partner[a] = Some(b);
                partner[b] = Some(a);
                break;
            }
        }
    }
    let mut entries = Vec::new();
    for (i, ring) in rings.iter().enumerate() {
        // A pair is written once, by its deeper side.
        let ring = match partner[i] {
            Some(j) if regions[rings[j].region].index > regions[ring.region].index => continue,
            Some(j) if regions[rings[j].region].index == regions[ring.region].index && j < i => continue,
            _ => *ring,
        };
        let r = &regions[ring.region];
        let id = if fam.is_some_and(|f| original(&ring, f.outer)) {
            1
        } else if fam.is_some_and(|f| f.holes.iter().any(|&h| original(&ring, h))) {
            0
        } else if ring.outer || partner[i].is_some() {
            // Shared or not, the contour at which region j starts.
            r.index + 1
        } else if r.index + 1 >= r.count {
            0
        } else {
            r.index + 2
        };
        entries.push(Entry {
            id,
            ccw: ring.outer,
            region: ring.region,
            contour: ring.contour,
        });
    }
    // From the outside in: 1, 2, ..., N, then the innermost contours.
    entries.sort_by_key(|e| if e.id == 0 { usize::MAX } else { e.id });
    entries
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::{ContourTree, Family, Point2, Polygon};

    fn square(c: f64, h: f64, ccw: bool) -> Contour {
        Contour::square(Point2::new(c, c), h).oriented(ccw)
    }

    fn region(index: usize, count: usize, outer: f64, hole: Option<f64>) -> SubRegion {
        SubRegion {
            family: 0,
            index,
            count,
            level: 0.0,
            polygon: Polygon {
                outer: square(0.0, outer, true),
                holes: hole.map(|h| vec![square(0.0, h, false)]).unwrap_or_default(),
            },
            cell: None,
            reference: Point2::new(0.0, 0.0),
            composition: None,
            samples: Vec::new(),
        }
    }

    /// Nested square rings of a square family with a square hole: each contour once,
    /// 1, 2, 3 and 0 from the outside in.
    #[test]
    fn nested_rings_are_written_once_from_the_outside_in() {
        let contours = vec![square(0.0, 10.0, true), square(0.0, 4.0, false)];
        let tree = ContourTree {
            nodes: Vec::new(),
            families: vec![Family {
                outer: 0,
                holes: vec![1],
            }],
        };
        let part = PartLayer {
            part: 0,
            contours,
            tree,
            families: vec![0],
            regions: vec![
                region(0, 3, 10.0, Some(8.0)),
                region(1, 3, 8.0, Some(6.0)),
                region(2, 3, 6.0, Some(4.0)),
            ],
        };
        let got: Vec<(usize, bool, usize)> = entries(&part).iter().map(|e| (e.id, e.ccw, e.region)).collect();
        assert_eq!(got, [(1, true, 0), (2, true, 1), (3, true, 2), (0, false, 2)]);
    }
}
