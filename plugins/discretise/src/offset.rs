//! `offset` (Method 1, Eq. 14-16): inward offsets of the family at equal spacing;
//! sub-region j is the ring between the j-th and (j+1)-th offsets, the last one the
//! remaining core. As the paper states it (the default): the outer contour moves toward
//! the holes (C_3 -> C_2 of Fig. 5), N_R = int(L_s / D_N) and the offset distance d is
//! D_N, so every ring is one nozzle wide and the last one takes the remainder. With
//! `from = "all"` the holes move out as well, the reach is L_s / 2 and each index has a
//! band on the outer side and one about each hole. `count` and `spacing` override N_R
//! and d; a `count` alone spreads the rings over the whole reach.

use lamina_api::stage::{AnyStage, Discretiser, FamilyContext, StageConfig, StageInfo, StageKind};
use lamina_api::{Polygon, Result, StageFactory, SubRegion};

use crate::bands::offset_bands;
use crate::cells::Cells;
use crate::grid::Grid;
use crate::inset::{From, Inset, Join};
use crate::measure::{min_contour_distance, pole};
use crate::options::{self, derived_count};
use crate::regions::{from_bands, uniform_level, whole};

const STAGE: &str = "discretise:offset";

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        nozzle: f64 = use crate::options::NOZZLE,
        count: Option<usize> = use crate::options::COUNT,
        /// offset distance d (mm); default D_N (the nozzle), or reach / count when only `count` is given
        #[range(0.001, 1e6)]
        spacing: Option<f64>,
        /// grading reference: `outer` (the paper's: the outer contour moves toward the holes, reach L_s) or `all` (outer and holes move together and meet halfway, reach L_s / 2, a band on each side per index)
        from: From = r#""outer""#,
        join: Join = use crate::options::JOIN,
        tolerance: f64 = use crate::options::TOLERANCE,
        cells_around: Option<usize> = use crate::cells::AROUND_OPTION,
        cell_length: Option<f64> = use crate::cells::LENGTH_OPTION,
        cell_cuts: Option<crate::cells::Cuts> = use crate::cells::CUTS_OPTION,
    }
}

/// The offset discretiser with its checked options.
#[derive(Debug, Clone, Copy)]
pub struct Offset {
    pub nozzle: f64,
    pub count: Option<usize>,
    pub spacing: Option<f64>,
    pub inset: Inset,
    pub cells: Cells,
    /// The run's limits: a count the geometry implies is checked against them.
    pub limits: lamina_api::Limits,
}

/// How deep the offsets can go before they meet: L_s from the outer contour to the
/// nearest hole, half of it when the holes move out too, the inradius without holes.
pub fn reach(polygon: &Polygon, from: From, precision: f64) -> Option<f64> {
    match (min_contour_distance(polygon), from) {
        (Some(ls), From::Outer) => Some(ls),
        (Some(ls), From::All) => Some(ls / 2.0),
        (None, _) => pole(polygon, precision).map(|(_, r)| r),
    }
}

impl Offset {
    /// N_R and the spacing d (mm) for a family: Eq. 14 with d = D_N unless `count`
    /// or `spacing` says otherwise.
    pub fn plan(&self, polygon: &Polygon) -> Result<Option<(usize, f64)>> {
        let rings = |r: f64, s: f64| {
            derived_count(
                &self.limits,
                r / s,
                &format!("{r:.3} mm of reach in rings {s} mm apart"),
            )
            .map(|n| Some((n, s)))
        };
        match (self.count, self.spacing) {
            (Some(n), Some(s)) => Ok(Some((n, s))),
            (Some(n), None) => {
                Ok(reach(polygon, self.inset.from, self.nozzle * 0.05).map(|r| (n, r / n as f64)))
            }
            (None, Some(s)) => match reach(polygon, self.inset.from, s * 0.05) {
                Some(r) => rings(r, s),
                None => Ok(None),
            },
            (None, None) => match reach(polygon, self.inset.from, self.nozzle * 0.05) {
                Some(r) => rings(r, self.nozzle),
                None => Ok(None),
            },
        }
    }
}

impl Discretiser for Offset {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>> {
        let polygon = ctx.polygon();
        let Some((grid, base)) = Grid::family(polygon, STAGE) else {
            return Ok(whole(ctx));
        };
        let Some((count, spacing)) = self.plan(polygon)? else {
            return Ok(whole(ctx));
        };
        if spacing.is_nan() || spacing <= 0.0 || spacing.is_infinite() {
            return Ok(whole(ctx));
        }
        let bands = offset_bands(&base, grid.scale(), count, &self.inset, |k| k as f64 * spacing)?;
        let mut regions = from_bands(ctx, &grid, &bands, count, |j| uniform_level(j, count));
        self.cells.split(&grid, polygon, &mut regions, &self.limits)?;
        Ok(regions)
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    Ok(AnyStage::Discretise(Box::new(checked(&o, config)?)))
}

fn checked(o: &Options, config: &StageConfig<'_>) -> Result<Offset> {
    options::count(config, o.count)?;
    Ok(Offset {
        nozzle: o.nozzle,
        count: o.count,
        spacing: o.spacing,
        inset: Inset {
            from: o.from,
            join: o.join,
            tolerance: o.tolerance,
        },
        cells: Cells::checked(o.cells_around, o.cell_length, o.cell_cuts, config)?,
        limits: config.limits,
    })
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "offset",
        doc: "Method 1: rings between inward offsets of the outer contour toward the holes, one nozzle apart, N_R = int(L_s / D_N); the last ring takes the remainder.",
        options: Options::SPECS,
        example: "use = \"offset\"\nnozzle = 0.2",
    },
    build,
});
