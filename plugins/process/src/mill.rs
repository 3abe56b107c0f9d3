//! `end-mill`: step 1 of the process. A spray jet covers more than the region it
//! sprays, so where an adjoining region stands higher than this layer's base its spray
//! has landed on this layer's area. Before the layer is sprayed, an end mill contours
//! the area's boundary along that region, its centre the cutter's radius inside the
//! boundary, down to the area's surface: the layer then gets its precise boundary.

use lamina_api::stage::{AnyStage, Process, StageConfig, StageInfo, StageKind};
use lamina_api::table::TableRef;
use lamina_api::{
    LayerPlan, Operation, OperationPath, OperationTool, Polygon, ProcessContext, Result, StageFactory,
};

use crate::area::{adjoining_runs, layer_area, offset};
use crate::regions::selected;
use crate::tool::{DIAMETER, FEED, LENGTH, SPINDLE, ToolSpec, checked, non_negative};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// the material regions milled; default: every layer
        regions: Vec<String> = "[]",
        /// the cutter's name
        tool: String = r#""end-mill""#,
        /// cutter diameter (mm)
        #[range(DIAMETER.0, DIAMETER.1)]
        diameter: f64 = "2.0",
        /// contour passes along the boundary, each further in by `stepover`
        #[range(1, 100)]
        passes: usize = "1",
        /// distance between passes, as a share of the diameter
        #[range(0.01, 1.0)]
        stepover: f64 = "0.5",
        /// widest gap between two regions that still counts as adjoining (mm)
        #[range(0.0, LENGTH)]
        gap: f64 = "0.1",
        /// feed (mm/s)
        #[range(FEED.0, FEED.1)]
        feed: f64 = "10.0",
        /// spindle speed (rev/min)
        #[range(SPINDLE.0, SPINDLE.1)]
        spindle: f64 = "12000.0",
    }
}

struct EndMill {
    options: Options,
    tool: OperationTool,
    table: TableRef,
}

impl Process for EndMill {
    fn needs_higher(&self) -> bool {
        true
    }

    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        let o = &self.options;
        if ctx.higher.is_empty() || !selected(ctx, &self.table, plan, &o.regions)? {
            return Ok(());
        }
        let area = layer_area(plan);
        let higher: Vec<Polygon> = ctx
            .higher
            .iter()
            .flat_map(|h| h.polygons.iter().cloned())
            .collect();
        let top = ctx
            .higher
            .iter()
            .map(|h| h.surface)
            .fold(f64::NEG_INFINITY, f64::max);
        let base = plan
            .material_region
            .and_then(|r| ctx.surfaces.get(r).copied().flatten())
            .unwrap_or(plan.z - plan.thickness);
        let radius = self.tool.diameter / 2.0;
        let mut paths = Vec::new();
        for k in 0..o.passes {
            let inset = radius + k as f64 * o.stepover * self.tool.diameter;
            let inner = offset(&area, -inset);
            if inner.is_empty() {
                // Nothing left for further passes.
                break;
            }
            for ring in inner.iter().flat_map(|p| p.contours()) {
                for (points, closed) in adjoining_runs(&ring.points, &higher, inset + o.gap, 0.25) {
                    paths.push(OperationPath {
                        z: base,
                        points,
                        closed,
                    });
                }
            }
        }
        if paths.is_empty() {
            // Where a higher region adjoins but the cutter fits nowhere along it, the
            // overhang stays: say so.
            let adjoins = area
                .iter()
                .flat_map(|p| p.contours())
                .any(|c| !adjoining_runs(&c.points, &higher, o.gap, 0.25).is_empty());
            if adjoins {
                plan.warn(
                    StageKind::Process,
                    "cutter-fits-nowhere",
                    format!(
                        "end-mill: a higher region adjoins the layer's area, but the {} mm cutter fits \
                         nowhere along it; what was sprayed over the boundary stays",
                        self.tool.diameter
                    ),
                );
            }
            return Ok(());
        }
        let mut op = Operation::new("end-mill", plan.material_region);
        op.tool = Some(self.tool.clone());
        op.paths = paths;
        op.values.insert("depth".into(), top - base);
        op.values.insert("regions_higher".into(), ctx.higher.len() as f64);
        plan.operations.push(op);
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    non_negative(config, "gap", options.gap)?;
    if !(1..=100).contains(&options.passes) {
        return Err(config.error("passes", "must be 1 to 100"));
    }
    if !(options.stepover.is_finite() && options.stepover > 0.0 && options.stepover <= 1.0) {
        return Err(config.error("stepover", "must be above 0 and at most 1 (a whole diameter)"));
    }
    let tool = checked(
        config,
        ToolSpec {
            name: &options.tool,
            kind: "end-mill",
            diameter: options.diameter,
            feed: options.feed,
            spindle: Some(options.spindle),
            power: None,
        },
    )?;
    Ok(AnyStage::Process(Box::new(EndMill {
        options,
        tool,
        table: config.table.clone(),
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Process,
        name: "end-mill",
        doc: "Contours a layer's boundary with an end mill where an adjoining region stands higher, before the layer is sprayed (CMPM step 1).",
        options: Options::SPECS,
        example: "use = \"end-mill\"\ndiameter = 1.0",
    },
    build,
});
