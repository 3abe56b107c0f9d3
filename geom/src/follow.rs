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

/// Per layer, the indices of the areas connected to the one holding `point` in layer
/// `start`. `None` when no area of that layer holds the point.
pub fn follow(layers: &[Vec<Area>], start: usize, point: Point2) -> Option<Vec<Vec<usize>>> {
    let first: Vec<usize> = (0..layers.get(start)?.len())
        .filter(|&f| layers[start][f].polygon.contains(point))
        .collect();
    if first.is_empty() {
        return None;
    }
    let mut selected: Vec<Vec<usize>> = vec![Vec::new(); layers.len()];
    selected[start] = first;
    for k in start + 1..layers.len() {
        selected[k] = next(&layers[k - 1], &selected[k - 1], &layers[k]);
    }
    for k in (0..start).rev() {
        selected[k] = next(&layers[k + 1], &selected[k + 1], &layers[k]);
    }
    Some(selected)
}

/// Areas of `next` overlapping the `selected` areas of `prev`.
fn next(prev: &[Area], selected: &[usize], next: &[Area]) -> Vec<usize> {
    (0..next.len())
        .filter(|&f| selected.iter().any(|&s| prev[s].overlaps(&next[f])))
        .collect()
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
