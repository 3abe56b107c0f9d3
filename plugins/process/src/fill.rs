//! `fill`: step 5 of the process. Where a layer's voids were engraved, a low-strength,
//! high-melting filler is laid over the area in passes so the next spray cannot fill
//! them; the finish grind then takes the surplus off. The paper leaves the filler in
//! the voids, where it protects the part from erosion (cmpm-process-planning §2, step
//! 7: repeat from step 1 until the part is done).
//!
//! `remove-filler` is not the paper's: an extra operation for a part whose voids must
//! end empty, melted out or leached once the last layer is done.

use lamina_api::stage::{AnyStage, Process, StageConfig, StageInfo, StageKind};
use lamina_api::table::TableRef;
use lamina_api::{LayerPlan, Operation, OperationTool, ProcessContext, Result, StageFactory};

use crate::area::{last_of, layer_area, raster, surface_now};
use crate::regions::selected;
use crate::tool::{DIAMETER, FEED, ToolSpec, checked};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// the material regions filled; default: every layer that was engraved
        regions: Vec<String> = "[]",
        /// the filler nozzle's name
        tool: String = r#""filler""#,
        /// width of the filler's track (mm)
        #[range(DIAMETER.0, DIAMETER.1)]
        diameter: f64 = "1.0",
        /// travel speed while filling (mm/s)
        #[range(FEED.0, FEED.1)]
        feed: f64 = "30.0",
    }
}

struct Fill {
    options: Options,
    tool: OperationTool,
    table: TableRef,
    limits: lamina_api::Limits,
}

impl Process for Fill {
    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        if !selected(ctx, &self.table, plan, &self.options.regions)? {
            return Ok(());
        }
        let region = plan.material_region;
        let Some(engraved) = last_of(plan, "engrave") else {
            return Ok(());
        };
        let (voids, void_area, depth) = (
            engraved.values.get("voids").copied().unwrap_or(0.0),
            engraved.values.get("void_area").copied().unwrap_or(0.0),
            engraved.values.get("depth").copied().unwrap_or(0.0),
        );
        let surface = surface_now(plan);
        let mut op = Operation::new("fill", region);
        op.tool = Some(self.tool.clone());
        op.paths = raster(&layer_area(plan), self.tool.diameter, surface, &self.limits)?;
        op.values.insert("voids".into(), voids);
        op.values.insert("void_volume".into(), void_area * depth);
        plan.operations.push(op);
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    let tool = checked(
        config,
        ToolSpec {
            name: &options.tool,
            kind: "dispenser",
            diameter: options.diameter,
            feed: options.feed,
            spindle: None,
            power: None,
        },
    )?;
    Ok(AnyStage::Process(Box::new(Fill {
        options,
        tool,
        table: config.table.clone(),
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Process,
        name: "fill",
        doc: "Lays a low-strength, high-melting filler over the layers whose voids were engraved, so the next spray leaves them open (CMPM step 5).",
        options: Options::SPECS,
        example: "use = \"fill\"\ndiameter = 1.0",
    },
    build,
});

lamina_api::stage_options! {
    #[derive(Debug)]
    struct RemoveOptions {
        /// how the filler leaves: `melt-out` (heated above its melting point) or `leach` (dissolved)
        method: String = r#""melt-out""#,
        /// temperature of a melt-out (°C)
        #[range(1.0, 2000.0)]
        temperature: f64 = "350.0",
    }
}

struct RemoveFiller {
    options: RemoveOptions,
}

impl Process for RemoveFiller {
    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        if !ctx.last {
            return Ok(());
        }
        let mut op = Operation::new("remove-filler", None);
        op.pass = self.options.method.clone();
        if self.options.method == "melt-out" {
            op.values.insert("temperature".into(), self.options.temperature);
        }
        plan.operations.push(op);
        Ok(())
    }
}

fn build_remove(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: RemoveOptions = config.parse()?;
    if !matches!(options.method.as_str(), "melt-out" | "leach") {
        return Err(config.error("method", "must be `melt-out` or `leach`"));
    }
    if !(options.temperature.is_finite() && options.temperature > 0.0) {
        return Err(config.error("temperature", "must be a positive number of °C"));
    }
    Ok(AnyStage::Process(Box::new(RemoveFiller { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Process,
        name: "remove-filler",
        doc: "Removes the voids' filler once the last layer is done, by melting it out or leaching it: an extra operation, since the CMPM process leaves the filler in the voids.",
        options: RemoveOptions::SPECS,
        example: "use = \"remove-filler\"\nmethod = \"melt-out\"",
    },
    build: build_remove,
});
