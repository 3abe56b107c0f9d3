//! Turning bands of a family into `SubRegion`s: one region per polygon of a band (a band
//! that splits into islands gives several regions of the same index and level), each
//! with a reference point inside it.

use i_overlay::i_shape::int::shape::IntShapes;
use lamina_api::{FamilyContext, SubRegion};

use crate::grid::Grid;

/// Regions from bands (outermost first) with the given levels (one per band).
pub fn from_bands(
    ctx: &FamilyContext<'_>,
    grid: &Grid,
    bands: &[IntShapes<i32>],
    count: usize,
    level: impl Fn(usize) -> f64,
) -> Vec<SubRegion> {
    let mut regions = Vec::new();
    for (index, band) in bands.iter().enumerate() {
        for polygon in grid.polygons(band) {
            if polygon.outer.len() < 3 {
                continue;
            }
            regions.push(SubRegion::new(ctx.family, index, count, level(index), polygon));
        }
    }
    regions
}

/// Level r_j = j / (N_R - 1) of Eq. 21; 0 for a single region.
pub fn uniform_level(j: usize, count: usize) -> f64 {
    if count <= 1 {
        0.0
    } else {
        (j as f64 / (count - 1) as f64).min(1.0)
    }
}

/// The family as one region: the fallback for a family the grid or the overlay cannot
/// represent (no area at the grid's resolution).
pub fn whole(ctx: &FamilyContext<'_>) -> Vec<SubRegion> {
    vec![SubRegion::new(ctx.family, 0, 1, 0.0, ctx.polygon().clone())]
}
