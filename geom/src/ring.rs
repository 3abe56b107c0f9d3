//! Contours as the boolean and offset engine (i_overlay) takes them: a ring is a closed
//! list of `[x, y]` points, a shape is an outer ring followed by its holes, and a list
//! of shapes is what a boolean operation returns. Plugins convert with these functions
//! so that every stage reads the engine's output the same way.

use crate::shape::{Contour, Point2, Polygon};

/// A closed ring: the last point joins the first, which is not repeated.
pub type Ring = Vec<[f64; 2]>;
/// An outer ring followed by its holes.
pub type Shape = Vec<Ring>;
/// Shapes as a boolean operation returns them.
pub type Shapes = Vec<Shape>;

/// The contour's points as a ring.
pub fn ring_of(c: &Contour) -> Ring {
    c.points.iter().map(|p| [p.x, p.y]).collect()
}

/// The ring's points as a contour.
pub fn contour_of(r: &[[f64; 2]]) -> Contour {
    Contour::new(r.iter().map(|p| Point2::new(p[0], p[1])).collect())
}

/// The polygon as one shape: its outer ring, then its holes.
pub fn shape_of(p: &Polygon) -> Shape {
    p.contours().map(ring_of).collect()
}

/// Polygons of a boolean result: outer counter-clockwise, holes clockwise, whatever
/// orientation the engine wrote them in. Empty shapes are dropped.
pub fn polygons_of(shapes: &[Shape]) -> Vec<Polygon> {
    shapes
        .iter()
        .filter(|s| !s.is_empty())
        .map(|s| {
            Polygon::new(
                contour_of(&s[0]).oriented(true),
                s[1..].iter().map(|h| contour_of(h).oriented(false)).collect(),
            )
        })
        .collect()
}

/// Signed area of a ring by the shoelace formula (positive counter-clockwise), summed
/// relative to the first point as [`Contour::signed_area`] does, for precision far
/// from the origin.
pub fn ring_area(r: &[[f64; 2]]) -> f64 {
    let Some(o) = r.first() else { return 0.0 };
    let n = r.len();
    let mut twice = 0.0;
    for i in 0..n {
        let (a, b) = (r[i], r[(i + 1) % n]);
        twice += (a[0] - o[0]) * (b[1] - o[1]) - (b[0] - o[0]) * (a[1] - o[1]);
    }
    twice / 2.0
}

/// Length of a ring, closing edge included.
pub fn ring_perimeter(r: &[[f64; 2]]) -> f64 {
    let n = r.len();
    (0..n)
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % n]);
            (b[0] - a[0]).hypot(b[1] - a[1])
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_with_a_hole_goes_round_trip() {
        let square = |x0: f64, s: f64| vec![[x0, x0], [x0 + s, x0], [x0 + s, x0 + s], [x0, x0 + s]];
        // The engine may write the hole counter-clockwise: the polygon turns it.
        let shapes = vec![vec![square(0.0, 4.0), square(1.0, 2.0)]];
        let polygons = polygons_of(&shapes);
        assert_eq!(polygons.len(), 1);
        assert_eq!(polygons[0].area(), 12.0);
        assert!(polygons[0].holes[0].signed_area() < 0.0);
        assert_eq!(shape_of(&polygons[0]).len(), 2);
        assert_eq!(ring_area(&square(1e6, 2.0)), 4.0);
        assert_eq!(ring_perimeter(&square(0.0, 2.0)), 8.0);
        assert_eq!(ring_area(&[]), 0.0);
    }

    #[test]
    fn rings_keep_their_orientation_and_polygons_take_the_usual_one() {
        // A clockwise 3-4-5 triangle: negative area, perimeter 12.
        let t = vec![[0.0, 0.0], [0.0, 4.0], [3.0, 0.0]];
        assert_eq!(ring_area(&t), -6.0);
        assert_eq!(ring_perimeter(&t), 12.0);
        assert_eq!(ring_of(&contour_of(&t)), t);
        // Outer rings come out counter-clockwise and holes clockwise whatever they were;
        // empty shapes are dropped.
        let outer = vec![[0.0, 0.0], [0.0, 10.0], [10.0, 10.0], [10.0, 0.0]];
        let hole = vec![[2.0, 2.0], [4.0, 2.0], [4.0, 4.0], [2.0, 4.0]];
        let polygons = polygons_of(&[vec![outer, hole], Vec::new()]);
        assert_eq!(polygons.len(), 1);
        assert!(polygons[0].outer.signed_area() > 0.0);
        assert!(polygons[0].holes[0].signed_area() < 0.0);
        assert_eq!(polygons[0].area(), 96.0);
        let back = shape_of(&polygons[0]);
        assert_eq!((ring_area(&back[0]), ring_area(&back[1])), (100.0, -4.0));
    }
}
