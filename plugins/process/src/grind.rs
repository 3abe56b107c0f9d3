//! `grind`: steps 3 and 6 of the process. The annular face of a cup wheel takes the
//! sprayed surface down: the rough pass to the layer's height plus the finish allowance
//! (to the height itself where there is none), the finish pass, after the voids are
//! engraved and filled, to the design height. The wheel levels everything under its
//! face, so the surface it grinds must stand higher than every other region's; the run
//! checks that as the layers pass.
//!
//! The wheel's centre runs along x in lines `stepover` apart over the area grown by
//! half a stepover: every point of the area then lies within half a stepover, at most
//! the wheel's radius, of the centre's path, so the face passes over all of it.

use lamina_api::stage::{AnyStage, Process, StageConfig, StageInfo, StageKind};
use lamina_api::table::TableRef;
use lamina_api::{LayerPlan, Operation, OperationTool, ProcessContext, Result, StageFactory};
use serde::Deserialize;

use crate::area::{last_of, layer_area, offset, raster, surface_now};
use crate::regions::selected;
use crate::tool::{DIAMETER, FEED, SPINDLE, ToolSpec, checked};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Pass {
    Rough,
    Finish,
}

lamina_api::option_type!(Pass = "string");

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// `rough`: down to the height plus the finish allowance, after spraying; `finish`: down to the design height, where a finish allowance was sprayed
        pass: Pass = r#""rough""#,
        /// the material regions ground; default: every layer
        regions: Vec<String> = "[]",
        /// the wheel's name
        tool: String = r#""cup-wheel""#,
        /// outer diameter of the wheel's grinding face (mm)
        #[range(DIAMETER.0, DIAMETER.1)]
        diameter: f64 = "20.0",
        /// distance between the wheel's passes, as a share of its diameter
        #[range(0.01, 1.0)]
        stepover: f64 = "0.5",
        /// table feed (mm/s)
        #[range(FEED.0, FEED.1)]
        feed: f64 = "20.0",
        /// speed of the wheel's rim (m/s): vitrified wheels want 20-35; the spindle speed follows from the diameter
        #[range(0.01, 500.0)]
        surface_speed: f64 = "25.0",
        /// wheel speed (rev/min), instead of `surface_speed`
        #[range(SPINDLE.0, SPINDLE.1)]
        spindle: Option<f64>,
    }
}

struct Grind {
    options: Options,
    tool: OperationTool,
    table: TableRef,
    limits: lamina_api::Limits,
}

impl Process for Grind {
    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        let o = &self.options;
        if !selected(ctx, &self.table, plan, &o.regions)? {
            return Ok(());
        }
        // What this layer sprayed, and how high the surface stands now.
        let region = plan.material_region;
        let Some(spray) = last_of(plan, "spray") else {
            return Ok(());
        };
        let finish = spray.values.get("finish_allowance").copied().unwrap_or(0.0);
        let now = surface_now(plan);
        let target = match o.pass {
            Pass::Rough => crate::area::micrometres(plan.z + finish),
            Pass::Finish if finish > 0.0 => plan.z,
            Pass::Finish => return Ok(()),
        };
        if now <= target + 1e-9 {
            return Ok(());
        }
        let area = layer_area(plan);
        let step = self.tool.diameter * o.stepover;
        let mut op = Operation::new("grind", region);
        op.pass = match o.pass {
            Pass::Rough => "rough",
            Pass::Finish => "finish",
        }
        .into();
        op.tool = Some(self.tool.clone());
        op.surface = Some(target);
        op.levels = true;
        op.paths = raster(&offset(&area, step / 2.0 + 0.01), step, target, &self.limits)?;
        op.values.insert("from".into(), now);
        op.values.insert("removed".into(), now - target);
        plan.operations.push(op);
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    if !(options.stepover.is_finite() && options.stepover > 0.0 && options.stepover <= 1.0) {
        return Err(config.error("stepover", "must be above 0 and at most 1 (a whole diameter)"));
    }
    if !(options.surface_speed.is_finite() && options.surface_speed > 0.0) {
        return Err(config.error("surface_speed", "must be a positive number of m/s"));
    }
    if options.spindle.is_some() && config.has("surface_speed") {
        return Err(config.error("spindle", "give `spindle` or `surface_speed`, not both"));
    }
    // v = pi d n: rev/min from m/s on a rim of d mm.
    let spindle = options.spindle.unwrap_or_else(|| {
        (options.surface_speed * 60_000.0 / (std::f64::consts::PI * options.diameter)).round()
    });
    let tool = checked(
        config,
        ToolSpec {
            name: &options.tool,
            kind: "grinding-wheel",
            diameter: options.diameter,
            feed: options.feed,
            spindle: Some(spindle),
            power: None,
        },
    )?;
    Ok(AnyStage::Process(Box::new(Grind {
        options,
        tool,
        table: config.table.clone(),
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Process,
        name: "grind",
        doc: "Grinds the sprayed surface flat with a cup wheel: `rough` to the height plus the finish allowance, `finish` to the design height (CMPM steps 3 and 6).",
        options: Options::SPECS,
        example: "use = \"grind\"\npass = \"rough\"\ndiameter = 10.0",
    },
    build,
});
