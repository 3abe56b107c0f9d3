//! `distance-field` (distance-field paper): per family, a distance field on a grid to a
//! chosen material feature (all boundaries, the outer contour, the holes, the centre or
//! a point), normalised to [0, 1]; the iso-contours at the chosen levels, clipped to the
//! family, bound the sub-regions. With `step`, the levels follow the grading step-width
//! truncation instead of equal parts.

use lamina_core::stage::{
    AnyStage, Discretiser, FamilyContext, OptionSpec, StageConfig, StageInfo, StageKind,
};
use lamina_core::steps::Truncation;
use lamina_core::{Contour, Point2, Polygon, Region, Result, StageFactory};
use serde::Deserialize;

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::ShapeType;

use crate::bands::{clean, nested_bands};
use crate::cells::Cells;
use crate::field::Field;
use crate::grid::Grid;
use crate::iso::iso_levels;
use crate::measure::pole;
use crate::regions::{from_bands, uniform_level, whole};

const STAGE: &str = "discretise:distance-field";

/// Below every level: keeps iso-loops closed at the grid's border.
const FLOOR: f64 = -1e300;

/// The material feature distances are measured from (r = 0 there).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Feature {
    /// Every contour of the family: the signed distance to the boundary.
    Boundary,
    Outer,
    Holes,
    /// The pole of inaccessibility (the most inland point).
    Centre,
    /// The point `point = [x, y]`.
    Point,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Options {
    #[serde(default = "default_feature")]
    feature: Feature,
    #[serde(default)]
    point: Option<[f64; 2]>,
    #[serde(default = "default_count")]
    count: usize,
    #[serde(default)]
    step: Option<f64>,
    #[serde(default)]
    spacing: Option<f64>,
    #[serde(default = "default_cells")]
    cells: usize,
    #[serde(default)]
    cell_size: Option<f64>,
    #[serde(default)]
    cells_around: Option<usize>,
    #[serde(default)]
    cell_length: Option<f64>,
}

fn default_feature() -> Feature {
    Feature::Boundary
}
fn default_count() -> usize {
    10
}
fn default_cells() -> usize {
    256
}

/// How the normalised distance is cut into levels.
#[derive(Debug, Clone)]
pub enum Levels {
    /// `n` equal parts of r, levels j / (n - 1) (Eq. 21).
    Equal(usize),
    Steps(Truncation),
    /// Iso-contours every `s` mm of distance from the feature (Fig. 7: 0, 1.5, ...,
    /// 10.5 over a maximum of 11.76); the region from the contour at d = j s on has the
    /// level j s / max(d) of Eq. 2, and the last one runs to the maximum.
    Spacing(f64),
}

/// The cut of one family's field: where each band starts (values of r) and each
/// band's level.
#[derive(Debug, Clone, PartialEq)]
pub struct Cut {
    /// Values of r where band k starts, k in 1..count.
    pub thresholds: Vec<f64>,
    /// The level of every band, outermost first.
    pub levels: Vec<f64>,
}

impl Levels {
    /// The cut for a field whose largest distance inside the family is `max` mm.
    pub fn cut(&self, max: f64) -> Cut {
        match self {
            Levels::Equal(n) => Cut {
                thresholds: (1..*n).map(|k| k as f64 / *n as f64).collect(),
                levels: (0..*n).map(|k| uniform_level(k, *n)).collect(),
            },
            Levels::Steps(t) => Cut {
                thresholds: t.thresholds(),
                levels: t.levels(),
            },
            Levels::Spacing(s) => {
                // Contours strictly below the maximum: one at the maximum itself would
                // bound nothing. The guard keeps a tiny spacing on a huge part finite.
                let n = ((max / s).ceil() as usize).clamp(1, crate::options::MAX_COUNT);
                let levels: Vec<f64> = (0..n).map(|k| (k as f64 * s / max).min(1.0)).collect();
                Cut {
                    thresholds: levels[1..].to_vec(),
                    levels,
                }
            }
        }
    }
}

/// One family's field and its iso-loops.
#[derive(Debug, Clone)]
pub struct IsoSets {
    /// Normalised distances r.
    pub field: Field,
    /// max(d_ij) (mm).
    pub max: f64,
    pub cut: Cut,
    /// The loops of every threshold of `cut`.
    pub sets: Vec<Vec<Contour>>,
}

/// The distance-field discretiser.
#[derive(Debug, Clone)]
pub struct DistanceField {
    pub feature: Feature,
    pub point: Option<Point2>,
    pub levels: Levels,
    pub cells: usize,
    pub cell_size: Option<f64>,
    /// Circumferential cells of every sub-region.
    pub around: Cells,
}

impl DistanceField {
    /// The field of normalised distances r (border samples at `FLOOR`), the largest
    /// distance inside the family (mm, Eq. 2's max(d_ij)), the cut into levels and the
    /// iso-loops of every threshold, without clipping. `None` when the family has no
    /// inside at the grid's resolution.
    pub fn iso_sets(&self, polygon: &Polygon) -> Option<IsoSets> {
        let bbox = polygon.bbox();
        let cells = match self.cell_size {
            Some(s) => ((bbox.width().max(bbox.height()) / s).ceil() as usize + 3).clamp(4, 8192),
            None => self.cells,
        };
        let mut field = Field::over(&bbox, cells);
        let all: Vec<&Contour> = polygon.contours().collect();
        let inside = field.inside(&all);
        match self.feature {
            Feature::Boundary => field.distance_to(&all),
            Feature::Outer => field.distance_to(&[&polygon.outer]),
            Feature::Holes => {
                if polygon.holes.is_empty() {
                    return None;
                }
                let holes: Vec<&Contour> = polygon.holes.iter().collect();
                field.distance_to(&holes);
            }
            Feature::Centre | Feature::Point => {
                let c = match (self.feature, self.point) {
                    (Feature::Point, Some(p)) => p,
                    _ => pole(polygon, field.h * 0.5)?.0,
                };
                for j in 0..field.ny {
                    for i in 0..field.nx {
                        field.values[j * field.nx + i] = (field.point(i, j) - c).norm();
                    }
                }
            }
        }
        let max = field
            .values
            .iter()
            .zip(&inside)
            .filter(|(_, i)| **i)
            .map(|(v, _)| *v)
            .fold(0.0f64, f64::max);
        if max.is_nan() || max <= 0.0 || max.is_infinite() {
            return None;
        }
        let (nx, ny) = (field.nx, field.ny);
        for j in 0..ny {
            for i in 0..nx {
                let k = j * nx + i;
                let v = &mut field.values[k];
                *v = if i == 0 || j == 0 || i == nx - 1 || j == ny - 1 {
                    FLOOR
                } else if self.feature == Feature::Boundary && !inside[k] {
                    -*v / max
                } else {
                    *v / max
                };
            }
        }
        let cut = self.levels.cut(max);
        let sets = iso_levels(&field, &field.values, &cut.thresholds);
        Some(IsoSets {
            field,
            max,
            cut,
            sets,
        })
    }
}

impl Discretiser for DistanceField {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<Region>> {
        let polygon = ctx.tree.family_polygon(&ctx.layer.contours, ctx.family);
        let Ok(grid) = Grid::for_polygon(&polygon, STAGE) else {
            return Ok(whole(ctx, polygon));
        };
        let base = clean(&vec![grid.shape(&polygon)]);
        let Some(IsoSets { cut, sets, .. }) = self.iso_sets(&polygon).filter(|_| !base.is_empty()) else {
            return Ok(whole(ctx, polygon));
        };
        let count = cut.levels.len();
        // Loops keep the set on their left: the non-zero rule in the band overlay reads
        // them as outers and holes.
        let bands = nested_bands(&base, count, FillRule::NonZero, |k, _, overlay| {
            let mut any = false;
            for c in &sets[k - 1] {
                let c = grid.contour(c);
                if c.len() >= 3 {
                    overlay.add_contour(&c, ShapeType::Clip);
                    any = true;
                }
            }
            Ok(any)
        })?;
        let mut regions = from_bands(ctx, &grid, &bands, count, |k| cut.levels[k]);
        self.around.split(&grid, &mut regions);
        Ok(regions)
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let levels = match (o.step, o.spacing) {
        (Some(_), Some(_)) => return Err(config.error("spacing", "give `step` or `spacing`, not both")),
        (Some(step), None) => Levels::Steps(Truncation::new(step).map_err(|e| config.error("step", e))?),
        (None, Some(s)) => Levels::Spacing(crate::options::positive_mm(config, "spacing", s)?),
        (None, None) if (1..=crate::options::MAX_COUNT).contains(&o.count) => Levels::Equal(o.count),
        (None, None) => {
            return Err(config.error(
                "count",
                format!(
                    "`count` must be in 1..={}, not {}",
                    crate::options::MAX_COUNT,
                    o.count
                ),
            ));
        }
    };
    if !(8..=8192).contains(&o.cells) {
        return Err(config.error("cells", format!("`cells` must be in 8..=8192, not {}", o.cells)));
    }
    if let Some(s) = o.cell_size
        && (s.is_nan() || s <= 0.0 || s.is_infinite())
    {
        return Err(config.error("cell_size", "`cell_size` must be a positive number of mm"));
    }
    let point = match (o.feature, o.point) {
        (Feature::Point, None) => {
            return Err(config.error("point", "`feature = \"point\"` needs `point = [x, y]`"));
        }
        (_, p) => p.map(|[x, y]| Point2::new(x, y)),
    };
    Ok(AnyStage::Discretise(Box::new(DistanceField {
        feature: o.feature,
        point,
        levels,
        cells: o.cells,
        cell_size: o.cell_size,
        around: Cells::checked(o.cells_around, o.cell_length, config)?,
    })))
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "distance-field",
        doc: "Iso-contours of a normalised distance field to a material feature bound the sub-regions, clipped to the family.",
        options: &[
            OptionSpec::new(
                "feature",
                "string",
                "\"boundary\"",
                "where r = 0: `boundary` (signed), `outer`, `holes`, `centre` or `point`"
            ),
            OptionSpec::new(
                "point",
                "array of float",
                "none",
                "[x, y] (mm) of the feature `point`"
            ),
            OptionSpec::new(
                "count",
                "integer",
                "10",
                "number of equal parts of r; levels j / (count - 1)"
            ),
            OptionSpec::new(
                "step",
                "float",
                "none",
                "grading step-width t_g: levels 0, t_g, ..., 1 at half steps"
            ),
            OptionSpec::new(
                "spacing",
                "float",
                "none",
                "iso-contours every `spacing` mm of distance (Fig. 7) instead of `count` parts of r; levels d / max(d) (Eq. 2)"
            ),
            OptionSpec::new(
                "cells",
                "integer",
                "256",
                "samples along the family's longer side"
            ),
            OptionSpec::new(
                "cell_size",
                "float",
                "none",
                "sample spacing (mm) instead of `cells`"
            ),
            crate::cells::AROUND_OPTION,
            crate::cells::LENGTH_OPTION,
        ],
        example: "use = \"distance-field\"\nfeature = \"outer\"\ncount = 4",
    },
    build,
});
