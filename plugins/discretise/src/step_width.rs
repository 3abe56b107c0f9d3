//! `step-width` (grading-step-width paper, 3.1): the grading function f of the normalised
//! distance from the grading reference is truncated to the levels 0, t_g, 2 t_g, ..., 1:
//! f = 0 below t_g / 2 and f = t_g (u + 1) for (u + 1/2) t_g <= f < (u + 3/2) t_g, which
//! gives N_c = 1 / t_g + 1 homogeneous regions bounded by offsets at the half steps.

use lamina_api::stage::{AnyStage, Discretiser, FamilyContext, StageConfig, StageInfo, StageKind};
use lamina_api::{Polygon, Result, StageFactory, SubRegion};
use lamina_fgm::steps::Truncation;

use crate::bands::offset_bands;
use crate::cells::Cells;
use crate::grid::Grid;
use crate::inset::{From, Inset, Join};
use crate::measure::{contour_distance, pole};
use crate::regions::{from_bands, whole};

const STAGE: &str = "discretise:step-width";

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// grading step-width t_g in (0, 1]; N_c = int(1 / t_g) + 1 levels, the last one 1
        #[range(0.001, 1.0)]
        step: f64 = "0.25",
        /// f(d) = (d / width)^power, the grading function of the distance
        #[range(0.01, 100.0)]
        power: f64 = "1.0",
        /// grading width (mm): f = 1 beyond it; default the family's deepest point from the reference
        #[range(0.001, 1e6)]
        width: Option<f64>,
        /// distance reference: `all` boundaries or the `outer` contour
        from: From = r#""all""#,
        join: Join = use crate::options::JOIN,
        tolerance: f64 = use crate::options::TOLERANCE,
        cells_around: Option<usize> = use crate::cells::AROUND_OPTION,
        cell_length: Option<f64> = use crate::cells::LENGTH_OPTION,
        cell_cuts: Option<crate::cells::Cuts> = use crate::cells::CUTS_OPTION,
    }
}

struct StepWidth {
    truncation: Truncation,
    power: f64,
    width: Option<f64>,
    inset: Inset,
    cells: Cells,
    limits: lamina_api::Limits,
}

/// The largest distance from the reference inside the family, which normalises d:
/// the inradius when every boundary is a reference; with the outer contour alone, the
/// farthest hole vertex from the outer (or the inradius without holes).
fn far_end(polygon: &Polygon, from: From) -> Option<f64> {
    let inradius = pole(polygon, polygon.bbox().diagonal() * 1e-3).map(|(_, r)| r);
    match from {
        From::All => inradius,
        From::Outer => {
            let hole_far = polygon
                .holes
                .iter()
                .flat_map(|h| h.points.iter())
                .map(|&p| polygon.outer.distance(p))
                .fold(0.0f64, f64::max);
            let near = polygon
                .holes
                .iter()
                .map(|h| contour_distance(&polygon.outer, h))
                .fold(f64::INFINITY, f64::min);
            let far = if near.is_finite() { hole_far.max(near) } else { 0.0 };
            match inradius {
                Some(r) => Some(r.max(far)),
                None => (far > 0.0).then_some(far),
            }
        }
    }
}

impl Discretiser for StepWidth {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>> {
        let polygon = ctx.polygon();
        let Some((grid, base)) = Grid::family(polygon, STAGE) else {
            return Ok(whole(ctx));
        };
        let scale = match self.width {
            Some(w) => Some(w),
            None => far_end(polygon, self.inset.from),
        };
        let Some(scale) = scale.filter(|s| *s > 0.0) else {
            return Ok(whole(ctx));
        };
        // f(d) = (d / scale)^power: a threshold t on f is the distance scale t^(1 / power).
        let distances: Vec<f64> = self
            .truncation
            .thresholds()
            .iter()
            .map(|t| scale * t.powf(1.0 / self.power))
            .collect();
        let count = self.truncation.count;
        let depth = |k: usize| if k == 0 { 0.0 } else { distances[k - 1] };
        let bands = offset_bands(&base, grid.scale(), count, &self.inset, depth)?;
        let mut regions = from_bands(ctx, &grid, &bands, count, |k| self.truncation.level(k));
        self.cells.split(&grid, polygon, &mut regions, &self.limits)?;
        Ok(regions)
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let truncation = Truncation::new(o.step).map_err(|e| config.error("step", e))?;
    crate::options::regions(config, "step", truncation.count as f64)?;
    Ok(AnyStage::Discretise(Box::new(StepWidth {
        truncation,
        power: o.power,
        width: o.width,
        inset: Inset {
            from: o.from,
            join: o.join,
            tolerance: o.tolerance,
        },
        cells: Cells::checked(o.cells_around, o.cell_length, o.cell_cuts, config)?,
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "step-width",
        doc: "Grading step-width truncation: N_c = 1 / t_g + 1 regions at levels 0, t_g, ..., 1, split at the half steps (u + 1/2) t_g of f(d).",
        options: Options::SPECS,
        example: "use = \"step-width\"\nstep = 0.25",
    },
    build,
});
