//! Copies of a part on the plate (`copies` on a `[[parts]]` entry).
//!
//! A copy is not sliced, discretised or graded again: each layer, the part's own plan
//! (contours, sub-regions, their reference points and graded samples) is moved to the
//! copy's place, so a grading in absolute X-Y is the part's in every copy, and a copy
//! costs only its planning. Copies are laid out beside the part's model in a grid
//! (columns first), a gap apart; parts of one model (an assembly) move together.

use crate::error::{Error, Result};
use crate::geom::{BBox2, Contour, Point2, Polygon, Vector2};
use crate::model::PartLayer;

/// One copy of a part: the part's plan moved by `offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PartCopy {
    /// The part it copies: its index among the pipeline's parts.
    pub of: usize,
    /// Its number among the part's copies: 2 for the first copy (the part itself is 1).
    pub number: usize,
    pub offset: Vector2,
}

/// The places of `copies` instances of a model whose box is `model` (the first is the
/// model where it is), in a grid of `columns` (unset: about as many as rows), `gap`
/// apart.
pub(super) fn grid(model: &BBox2, copies: usize, gap: f64, columns: Option<usize>) -> Vec<Vector2> {
    let columns = columns
        .unwrap_or_else(|| (copies as f64).sqrt().ceil() as usize)
        .max(1);
    let size = model.max - model.min;
    (0..copies)
        .map(|k| {
            let (column, row) = (k % columns, k / columns);
            Vector2::new(column as f64 * (size.x + gap), row as f64 * (size.y + gap))
        })
        .collect()
}

/// One instance on the plate: the parts of one model at one place, and their box.
#[derive(Debug, Clone)]
pub(super) struct Instance {
    pub model: usize,
    pub offset: Vector2,
    /// The parts placed there, by name, for messages ("part `gear`'s copy 2").
    pub label: String,
    pub bbox: BBox2,
}

/// Refuses a plate where two instances overlap and one of them is a copy: the
/// pipeline's own placement of different models is its to decide.
pub(super) fn check_apart(instances: &[Instance]) -> Result<()> {
    for (i, a) in instances.iter().enumerate() {
        for b in &instances[i + 1..] {
            let moved = a.offset != Vector2::zeros() || b.offset != Vector2::zeros();
            let same = a.model == b.model && a.offset == b.offset;
            if moved && !same && overlap(&a.bbox, &b.bbox) {
                return Err(Error::config(format!(
                    "{} (X {:.1}..{:.1}, Y {:.1}..{:.1}) overlaps {} (X {:.1}..{:.1}, Y {:.1}..{:.1}) on the plate: widen `copy_gap`, or place the models apart",
                    a.label,
                    a.bbox.min.x,
                    a.bbox.max.x,
                    a.bbox.min.y,
                    a.bbox.max.y,
                    b.label,
                    b.bbox.min.x,
                    b.bbox.max.x,
                    b.bbox.min.y,
                    b.bbox.max.y
                )));
            }
        }
    }
    Ok(())
}

/// Whether two boxes share more than an edge.
fn overlap(a: &BBox2, b: &BBox2) -> bool {
    a.min.x < b.max.x && b.min.x < a.max.x && a.min.y < b.max.y && b.min.y < a.max.y
}

/// `b` moved by `by`.
pub(super) fn moved_box(b: &BBox2, by: Vector2) -> BBox2 {
    BBox2 {
        min: b.min + by,
        max: b.max + by,
    }
}

fn moved_contour(c: &Contour, by: Vector2) -> Contour {
    Contour::new(c.points.iter().map(|p| p + by).collect())
}

/// `p` moved by `by`.
pub(super) fn moved_polygon(p: &Polygon, by: Vector2) -> Polygon {
    Polygon::new(
        moved_contour(&p.outer, by),
        p.holes.iter().map(|h| moved_contour(h, by)).collect(),
    )
}

/// The part layer of a copy: `source` moved by `by`, as part `part`.
pub(super) fn moved(source: &PartLayer, part: usize, by: Vector2) -> PartLayer {
    let point = |p: &Point2| p + by;
    let polygon = |p: &Polygon| moved_polygon(p, by);
    PartLayer {
        part,
        contours: source.contours.iter().map(|c| moved_contour(c, by)).collect(),
        tree: source.tree.clone(),
        families: source.families.clone(),
        regions: source
            .regions
            .iter()
            .map(|r| {
                let mut r2 = r.clone();
                r2.polygon = polygon(&r.polygon);
                r2.reference = point(&r.reference);
                for s in &mut r2.samples {
                    s.at = point(&s.at);
                }
                r2
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{ContourTree, SubRegion};

    fn square(x: f64, y: f64, side: f64) -> Contour {
        Contour::new(vec![
            Point2::new(x, y),
            Point2::new(x + side, y),
            Point2::new(x + side, y + side),
            Point2::new(x, y + side),
        ])
    }

    #[test]
    fn copies_fill_a_grid_a_gap_apart() {
        let model = BBox2 {
            min: Point2::new(-5.0, 10.0),
            max: Point2::new(15.0, 20.0),
        };
        let at = grid(&model, 5, 2.0, None);
        let want = [(0.0, 0.0), (22.0, 0.0), (44.0, 0.0), (0.0, 12.0), (22.0, 12.0)];
        assert_eq!(at.len(), 5);
        for (a, (x, y)) in at.iter().zip(want) {
            assert_eq!((a.x, a.y), (x, y));
        }
        assert_eq!(grid(&model, 1, 2.0, None), vec![Vector2::zeros()]);
        assert_eq!(grid(&model, 4, 0.0, None)[3], Vector2::new(20.0, 10.0));
        let column = grid(&model, 3, 1.0, Some(1));
        assert_eq!(
            column,
            vec![Vector2::zeros(), Vector2::new(0.0, 11.0), Vector2::new(0.0, 22.0)]
        );
    }

    #[test]
    fn a_copy_overlapping_another_model_is_refused_and_an_assembly_is_not() {
        let at = |model, x: f64, label: &str| Instance {
            model,
            offset: Vector2::new(x, 0.0),
            label: label.into(),
            bbox: BBox2 {
                min: Point2::new(x, 0.0),
                max: Point2::new(x + 10.0, 10.0),
            },
        };
        // Two parts of one model at one place (a gear on its shaft) may overlap.
        check_apart(&[at(0, 0.0, "a"), at(0, 0.0, "b"), at(0, 10.0, "a's copy 2")]).expect("apart");
        let e = check_apart(&[at(0, 0.0, "a"), at(1, 5.0, "part `b`'s copy 2")]).expect_err("overlap");
        assert!(e.to_string().contains("part `b`'s copy 2"), "{e}");
        // Originals of two models are the pipeline's to place.
        let mut b = at(1, 5.0, "b");
        b.offset = Vector2::zeros();
        check_apart(&[at(0, 0.0, "a"), b]).expect("the pipeline's placement");
        // The copies of two parts of one model at one place (gear and shaft) may
        // overlap; a copy over its own model's original may not.
        check_apart(&[at(0, 10.0, "gear's copy 2"), at(0, 10.0, "shaft's copy 2")]).expect("an assembly");
        check_apart(&[at(0, 0.0, "a"), at(0, 5.0, "a's copy 2")]).expect_err("over its original");
    }

    /// Boxes that only touch, side by side in X or in Y, either way round, are apart.
    #[test]
    fn copies_touching_along_an_edge_are_apart() {
        let at = |label: &str, x: f64, y: f64| Instance {
            model: 0,
            offset: Vector2::new(x, y),
            label: label.into(),
            bbox: BBox2 {
                min: Point2::new(x, y),
                max: Point2::new(x + 10.0, y + 10.0),
            },
        };
        for (dx, dy) in [(10.0, 0.0), (-10.0, 0.0), (0.0, 10.0), (0.0, -10.0)] {
            check_apart(&[at("copy 2", 20.0, 20.0), at("copy 3", 20.0 + dx, 20.0 + dy)]).expect("touching");
            check_apart(&[
                at("copy 2", 20.0, 20.0),
                at("copy 3", 20.0 + dx / 2.0, 20.0 + dy / 2.0),
            ])
            .expect_err("overlapping");
        }
        let b = BBox2 {
            min: Point2::new(1.0, 2.0),
            max: Point2::new(3.0, 5.0),
        };
        let m = moved_box(&b, Vector2::new(10.0, -1.0));
        assert_eq!((m.min, m.max), (Point2::new(11.0, 1.0), Point2::new(13.0, 4.0)));
    }

    #[test]
    fn a_copy_moves_every_point_of_the_plan_and_keeps_its_grading() {
        let region = SubRegion {
            family: 0,
            index: 0,
            count: 1,
            level: 0.25,
            polygon: Polygon::new(square(0.0, 0.0, 2.0), vec![square(0.5, 0.5, 1.0)]),
            cell: None,
            reference: Point2::new(0.25, 0.25),
            composition: Some(crate::model::Composition::binary(0.3).expect("composition")),
            samples: vec![crate::model::Sample {
                at: Point2::new(1.0, 0.2),
                composition: crate::model::Composition::binary(0.7).expect("composition"),
            }],
        };
        let source = PartLayer {
            part: 0,
            contours: vec![square(0.0, 0.0, 2.0)],
            tree: ContourTree::default(),
            families: vec![0],
            regions: vec![region],
        };
        let by = Vector2::new(30.0, -4.0);
        let copy = moved(&source, 3, by);
        assert_eq!(copy.part, 3);
        assert_eq!(copy.contours[0].points[2], Point2::new(32.0, -2.0));
        let r = &copy.regions[0];
        assert_eq!(r.polygon.holes[0].points[0], Point2::new(30.5, -3.5));
        assert_eq!(r.polygon.outer.points[1], Point2::new(32.0, -4.0));
        assert_eq!(r.reference, Point2::new(30.25, -3.75));
        assert_eq!(r.samples[0].at, Point2::new(31.0, -3.8));
        assert_eq!(r.composition, source.regions[0].composition);
        assert_eq!(r.samples[0].composition, source.regions[0].samples[0].composition);
        assert_eq!((r.level, r.area()), (0.25, source.regions[0].area()));
    }
}
