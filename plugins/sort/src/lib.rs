//! The topological hierarchy of a layer's contours (topological-hierarchy paper,
//! Eq. 1-3 and Fig. 2b): each contour's level (0 = outermost), its parent and children,
//! and the contour families: a contour at an even level with its direct children is
//! one solid area.
//!
//! Contours of a valid layer never cross, so "A contains B" is decided by one point
//! inside B. Candidate parents come from an R-tree of bounding boxes, which keeps a
//! layer with thousands of contours far from quadratic.

use lamina_api::stage::{AnyStage, Sorter, StageConfig, StageInfo, StageKind};
use lamina_api::{Contour, ContourNode, ContourTree, Family, Layer, Point2, Result, StageFactory};
use rstar::primitives::{GeomWithData, Rectangle};
use rstar::{AABB, RTree};

type Boxed = GeomWithData<Rectangle<[f64; 2]>, usize>;

/// Builds the containment hierarchy of `contours`.
pub fn hierarchy(contours: &[Contour]) -> ContourTree {
    let n = contours.len();
    let areas: Vec<f64> = contours.iter().map(Contour::area).collect();
    let samples: Vec<Point2> = contours
        .iter()
        .map(|c| {
            c.interior_point()
                .unwrap_or_else(|| c.points.first().copied().unwrap_or_else(Point2::origin))
        })
        .collect();
    let tree = RTree::bulk_load(
        contours
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let b = c.bbox();
                Boxed::new(Rectangle::from_corners([b.min.x, b.min.y], [b.max.x, b.max.y]), i)
            })
            .collect(),
    );
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for i in 0..n {
        let s = samples[i];
        let mut best: Option<usize> = None;
        for cand in tree.locate_in_envelope_intersecting(AABB::from_point([s.x, s.y])) {
            let j = cand.data;
            // A parent is larger; ties (duplicate contours) are broken by index so the
            // relation stays acyclic.
            let larger = areas[j] > areas[i] || (areas[j] == areas[i] && j < i);
            if j == i || !larger {
                continue;
            }
            if best.is_some_and(|b| areas[b] <= areas[j]) {
                continue;
            }
            if contours[j].contains(s) {
                best = Some(j);
            }
        }
        parent[i] = best;
    }
    // Levels: parents are larger, so visiting by decreasing area sees parents first.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| areas[b].total_cmp(&areas[a]).then(a.cmp(&b)));
    let mut level = vec![0usize; n];
    for &i in &order {
        if let Some(p) = parent[i] {
            level[i] = level[p] + 1;
        }
    }
    let mut nodes: Vec<ContourNode> = (0..n)
        .map(|i| ContourNode {
            contour: i,
            level: level[i],
            parent: parent[i],
            children: Vec::new(),
        })
        .collect();
    for (i, p) in parent.iter().enumerate() {
        if let Some(p) = *p {
            nodes[p].children.push(i);
        }
    }
    let families = (0..n)
        .filter(|&i| level[i].is_multiple_of(2))
        .map(|i| Family {
            outer: i,
            holes: nodes[i].children.clone(),
        })
        .collect();
    ContourTree { nodes, families }
}

struct Hierarchy;

impl Sorter for Hierarchy {
    fn sort(&self, layer: &Layer) -> Result<ContourTree> {
        Ok(hierarchy(&layer.contours))
    }
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {}
}

// A pipeline without a [sort] table gets this stage.
lamina_api::register_default!(StageKind::Sort, "hierarchy");

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Sort,
        name: "hierarchy",
        doc: "Containment hierarchy of each layer: levels, parents, children and contour families (outer contour with its holes).",
        options: Options::SPECS,
        example: "use = \"hierarchy\"",
    },
    build: |config: &StageConfig<'_>| {
        let _: Options = config.parse()?;
        Ok(AnyStage::Sort(Box::new(Hierarchy)))
    },
});

#[cfg(test)]
mod tests {
    use super::*;

    fn square(c: f64, half: f64) -> Contour {
        Contour::square(Point2::new(c, c), half)
    }

    /// The paper's Fig. 2: C3 contains C2, which contains C1; C3 and C2 form one
    /// family, C1 another.
    #[test]
    fn nested_squares_give_levels_and_families() {
        let contours = vec![square(0.0, 1.0), square(0.0, 2.0), square(0.0, 3.0)];
        let t = hierarchy(&contours);
        assert_eq!(t.nodes[2].level, 0);
        assert_eq!(t.nodes[1].level, 1);
        assert_eq!(t.nodes[0].level, 2);
        assert_eq!(t.nodes[1].parent, Some(2));
        assert_eq!(t.nodes[2].children, vec![1]);
        assert_eq!(
            t.families,
            vec![
                Family {
                    outer: 0,
                    holes: vec![]
                },
                Family {
                    outer: 2,
                    holes: vec![1]
                }
            ]
        );
    }

    #[test]
    fn many_islands_are_siblings() {
        let mut contours = vec![square(0.0, 1000.0)];
        for i in 0..400 {
            let x = -900.0 + (i % 20) as f64 * 90.0;
            let y = -900.0 + (i / 20) as f64 * 90.0;
            contours.push(Contour::new(
                square(0.0, 10.0)
                    .points
                    .iter()
                    .map(|p| Point2::new(p.x + x, p.y + y))
                    .collect(),
            ));
        }
        let t = hierarchy(&contours);
        assert_eq!(t.nodes[0].children.len(), 400);
        assert_eq!(t.families.len(), 1);
        assert!(t.nodes[1..].iter().all(|n| n.level == 1));
    }
}
