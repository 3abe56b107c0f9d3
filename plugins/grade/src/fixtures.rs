//! What the graders' unit tests share: a run of one part, the context of its first
//! family, and the sub-regions of a family.

use lamina_api::stage::FamilyContext;
use lamina_api::{Contour, ContourTree, Layer, Material, PartInfo, Point2, Polygon, RunInfo, SubRegion};

use crate::xy::index_level;

/// A run of one part, `plate`, 1 mm tall, made of `materials` (name, colour) in order.
pub fn info(materials: &[(&str, [u8; 3])]) -> RunInfo {
    RunInfo {
        base_dir: ".".into(),
        materials: materials
            .iter()
            .map(|&(name, colour)| Material {
                name: name.into(),
                colour,
                layer_thickness: None,
            })
            .collect(),
        parts: vec![PartInfo {
            name: "plate".into(),
            materials: (0..materials.len()).collect(),
            mesh: 0,
            z_min: 0.0,
            z_max: 1.0,
            z_gradient: None,
        }],
        z_min: 0.0,
        z_max: 1.0,
        xy_bounds: lamina_api::BBox2::EMPTY,
        machine: None,
        model_frame: None,
    }
}

/// `n` sub-regions of one family, numbered from the outer contour in, each a unit
/// square with its reference at the centre, at the level j / (n - 1).
pub fn regions(n: usize) -> Vec<SubRegion> {
    let square = Contour::new(vec![
        Point2::new(0.0, 0.0),
        Point2::new(1.0, 0.0),
        Point2::new(1.0, 1.0),
        Point2::new(0.0, 1.0),
    ]);
    (0..n)
        .map(|j| SubRegion {
            family: 0,
            index: j,
            count: n,
            level: index_level(j, n),
            polygon: Polygon::new(square.clone(), vec![]),
            cell: None,
            reference: Point2::new(0.5, 0.5),
            composition: None,
            samples: Vec::new(),
        })
        .collect()
}

/// Family 0 of part 0 on `layer`, whose families' polygons are `polygons` (empty for
/// graders that read none).
pub fn context<'a>(
    info: &'a RunInfo,
    layer: &'a Layer,
    tree: &'a ContourTree,
    polygons: &'a [Polygon],
) -> FamilyContext<'a> {
    FamilyContext {
        info,
        layer,
        tree,
        polygons,
        mesh: None,
        part: 0,
        family: 0,
    }
}
