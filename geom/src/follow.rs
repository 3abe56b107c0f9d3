//! Following one solid area up and down through the layers: how parts that share a mesh
//! tell their solids apart (a pipeline's `family_at`). The area holding a point in one
//! layer is selected; in each neighbouring layer, so are the areas overlapping those
//! selected in the layer before, upward and downward from it.

use crate::shape::{Point2, Polygon};

/// A solid area of one layer with a point strictly inside it.
#[derive(Debug, Clone)]
pub struct Area {
    pub polygon: Polygon,
    /// NaN when the polygon has no interior (it then overlaps nothing by its point).
    pub inside: Point2,
}

impl Area {
    pub fn new(polygon: Polygon) -> Self {
        let inside = polygon
            .outer
            .interior_point()
            .unwrap_or(Point2::new(f64::NAN, f64::NAN));
        Self { polygon, inside }
    }

    /// Areas of neighbouring layers overlap when either holds the other's inner point:
    /// a cheap test that holds for the overlaps a layer step makes (the area moves by
    /// less than its own size), with no boolean operation.
    pub fn overlaps(&self, other: &Area) -> bool {
        self.polygon.contains(other.inside) || other.polygon.contains(self.inside)
    }
}

/// What following needs of one layer once its polygons are gone: a point inside each
/// area, and for each area the areas of the layer above that it overlaps. A few numbers
/// per area, so that the layers of a whole part can be held at once.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LayerLinks {
    /// [`Area::inside`] of each area.
    pub inside: Vec<Point2>,
    /// For each area, the areas of the next layer up it overlaps (empty on the top
    /// layer), in increasing order.
    pub up: Vec<Vec<usize>>,
}

impl LayerLinks {
    /// The links of `lower` to `upper`, the layer above (`None` on the top layer).
    pub fn new(lower: &[Area], upper: Option<&[Area]>) -> Self {
        Self {
            inside: lower.iter().map(|a| a.inside).collect(),
            up: lower
                .iter()
                .map(|a| match upper {
                    Some(upper) => (0..upper.len()).filter(|&f| a.overlaps(&upper[f])).collect(),
                    None => Vec::new(),
                })
                .collect(),
        }
    }
}

/// Per layer, the indices of the areas connected to the one holding `point` in layer
/// `start`. `None` when no area of that layer holds the point.
pub fn follow(layers: &[Vec<Area>], start: usize, point: Point2) -> Option<Vec<Vec<usize>>> {
    let first = holding(layers.get(start)?, point);
    if first.is_empty() {
        return None;
    }
    let links: Vec<LayerLinks> = (0..layers.len())
        .map(|k| LayerLinks::new(&layers[k], layers.get(k + 1).map(Vec::as_slice)))
        .collect();
    Some(follow_links(&links, start, first))
}

/// The areas of `areas` that hold `point`.
pub fn holding(areas: &[Area], point: Point2) -> Vec<usize> {
    (0..areas.len())
        .filter(|&f| areas[f].polygon.contains(point))
        .collect()
}

/// Per layer, the indices of the areas connected to `first`, areas of layer `start`,
/// through the overlaps `layers` records: upward, the areas the selected ones overlap;
/// downward, the areas that overlap a selected one.
pub fn follow_links(layers: &[LayerLinks], start: usize, first: Vec<usize>) -> Vec<Vec<usize>> {
    let mut selected: Vec<Vec<usize>> = vec![Vec::new(); layers.len()];
    if start >= layers.len() {
        return selected;
    }
    selected[start] = first;
    for k in start..layers.len() - 1 {
        let mut reached = vec![false; layers[k + 1].inside.len()];
        for &s in &selected[k] {
            for &f in &layers[k].up[s] {
                reached[f] = true;
            }
        }
        selected[k + 1] = (0..reached.len()).filter(|&f| reached[f]).collect();
    }
    for k in (0..start).rev() {
        let above = &selected[k + 1];
        selected[k] = (0..layers[k].up.len())
            .filter(|&f| layers[k].up[f].iter().any(|u| above.contains(u)))
            .collect();
    }
    selected
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Contour;

    fn square(x0: f64, s: f64) -> Area {
        Area::new(Polygon::new(
            Contour::new(vec![
                Point2::new(x0, 0.0),
                Point2::new(x0 + s, 0.0),
                Point2::new(x0 + s, s),
                Point2::new(x0, s),
            ]),
            Vec::new(),
        ))
    }

    #[test]
    fn two_towers_that_merge_are_followed_through_the_merge() {
        // Layers 0-1: two separate squares; layer 2: one bar over both.
        let layers = vec![
            vec![square(0.0, 1.0), square(5.0, 1.0)],
            vec![square(5.0, 1.0), square(0.0, 1.0)],
            vec![square(0.0, 6.0)],
        ];
        let picked = follow(&layers, 0, Point2::new(5.5, 0.5)).expect("the point is in a solid");
        assert_eq!(picked, vec![vec![1], vec![0], vec![0]]);
        // From the top down, the bar holds both towers.
        let down = follow(&layers, 2, Point2::new(3.0, 3.0)).expect("the bar holds it");
        assert_eq!(down, vec![vec![0, 1], vec![0, 1], vec![0]]);
        assert!(follow(&layers, 0, Point2::new(3.0, 0.5)).is_none());
        assert!(follow(&layers, 7, Point2::new(0.5, 0.5)).is_none());
    }
}
