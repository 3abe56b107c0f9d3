//! `spray`: step 2 of the process. The layer's area is sprayed in passes along x, the
//! layer thicker by the grinding allowances (the rough allowance on every region, the
//! finish allowance on the regions whose voids are engraved and filled before the last
//! grind), with the inclusions of a composite region.
//!
//! The gun mixes its powders as it goes (cmpm-process-planning §2, step 2, and §4.2.2:
//! the constituents' volume fractions "for every pixel"): the area is sprayed by
//! sub-regions of one composition, one operation each, whose `fraction:<material>`
//! values are the graded composition the feeders are set to (`inclusion:<name>` the
//! inclusions' volume fractions).

use std::collections::BTreeMap;

use lamina_api::stage::{AnyStage, Process, StageConfig, StageInfo, StageKind};
use lamina_api::table::TableRef;
use lamina_api::{LayerPlan, Operation, OperationTool, Polygon, ProcessContext, Result, StageFactory};

use crate::area::raster;
use crate::regions::{check_names, selected, value_for};
use crate::tool::{DIAMETER, FEED, LENGTH, POWER, ToolSpec, checked, non_negative};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// the material regions sprayed; default: every layer
        regions: Vec<String> = "[]",
        /// thickness added for the rough grind (mm), on every region
        #[range(0.0, LENGTH)]
        rough_allowance: f64 = "0.1",
        /// thickness added for the finish grind (mm), by region name (the microstructure regions)
        finish_allowance: BTreeMap<String, f64> = "{}",
        /// inclusions sprayed into composite regions: `{ region = { inclusion = volume fraction } }`
        inclusions: BTreeMap<String, BTreeMap<String, f64>> = "{}",
        /// the spray gun's name
        tool: String = r#""spray-gun""#,
        /// width of the sprayed track (mm)
        #[range(DIAMETER.0, DIAMETER.1)]
        diameter: f64 = "3.0",
        /// share of a track the next one covers again
        #[range(0.0, 0.9)]
        overlap: f64 = "0.25",
        /// travel speed of the gun while spraying (mm/s)
        #[range(FEED.0, FEED.1)]
        feed: f64 = "100.0",
        /// torch power (W), if the gun takes one
        #[range(POWER.0, POWER.1)]
        power: Option<f64>,
    }
}

struct Spray {
    options: Options,
    tool: OperationTool,
    table: TableRef,
    limits: lamina_api::Limits,
}

impl Process for Spray {
    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        let o = &self.options;
        check_names(ctx, &self.table, "finish_allowance", o.finish_allowance.keys())?;
        check_names(ctx, &self.table, "inclusions", o.inclusions.keys())?;
        if !selected(ctx, &self.table, plan, &o.regions)? {
            return Ok(());
        }
        let finish = value_for(ctx, plan, &o.finish_allowance).copied().unwrap_or(0.0);
        let surface = crate::area::micrometres(plan.z + o.rough_allowance + finish);
        let spacing = self.tool.diameter * (1.0 - o.overlap);
        for (fractions, polygons) in by_composition(ctx, plan) {
            let mut op = Operation::new("spray", plan.material_region);
            op.tool = Some(self.tool.clone());
            op.surface = Some(surface);
            op.paths = raster(&polygons, spacing, surface, &self.limits)?;
            op.values.insert("thickness".into(), plan.thickness);
            op.values.insert("rough_allowance".into(), o.rough_allowance);
            op.values.insert("finish_allowance".into(), finish);
            for (name, fraction) in fractions {
                op.values.insert(format!("fraction:{name}"), fraction);
            }
            if let Some(inclusions) = value_for(ctx, plan, &o.inclusions) {
                for (name, fraction) in inclusions {
                    op.values.insert(format!("inclusion:{name}"), *fraction);
                }
            }
            plan.operations.push(op);
        }
        Ok(())
    }
}

/// The layer's area as sprayed: each part's graded sub-regions, grouped by
/// composition (by material name, in the order they first come); a part not graded
/// gives its whole area, with its material when it has one. A part with several
/// materials and no grading gets no fractions: the plan does not say what to mix.
fn by_composition(ctx: &ProcessContext<'_>, plan: &LayerPlan) -> Vec<(BTreeMap<String, f64>, Vec<Polygon>)> {
    let name = |part: usize, i: usize| -> String {
        ctx.info
            .parts
            .get(part)
            .and_then(|p| p.materials.get(i))
            .and_then(|&m| ctx.info.materials.get(m))
            .map_or_else(|| format!("material {i}"), |m| m.name.clone())
    };
    let mut groups: Vec<(BTreeMap<String, f64>, Vec<Polygon>)> = Vec::new();
    let mut add = |fractions: BTreeMap<String, f64>, polygon: Polygon| {
        if polygon.area() <= 0.0 {
            return;
        }
        match groups.iter_mut().find(|(g, _)| same(g, &fractions)) {
            Some((_, polygons)) => polygons.push(polygon),
            None => groups.push((fractions, vec![polygon])),
        }
    };
    for part in &plan.parts {
        let graded = !part.regions.is_empty() && part.regions.iter().all(|r| r.composition.is_some());
        if graded {
            for r in &part.regions {
                let mut fractions = BTreeMap::new();
                for (i, f) in r.composition.iter().flat_map(|c| c.fractions.iter().enumerate()) {
                    *fractions.entry(name(part.part, i)).or_insert(0.0) += f;
                }
                add(fractions, r.polygon.clone());
            }
        } else {
            let single = ctx
                .info
                .parts
                .get(part.part)
                .is_some_and(|p| p.materials.len() == 1);
            let fractions: BTreeMap<String, f64> = if single {
                [(name(part.part, 0), 1.0)].into()
            } else {
                BTreeMap::new()
            };
            for &f in &part.families {
                add(fractions.clone(), part.tree.family_polygon(&part.contours, f));
            }
        }
    }
    groups
}

/// Two compositions a feeder cannot tell apart (1e-9 in every fraction).
fn same(a: &BTreeMap<String, f64>, b: &BTreeMap<String, f64>) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|((ka, va), (kb, vb))| ka == kb && (va - vb).abs() <= 1e-9)
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    non_negative(config, "rough_allowance", options.rough_allowance)?;
    for v in options.finish_allowance.values() {
        non_negative(config, "finish_allowance", *v)?;
    }
    for inclusions in options.inclusions.values() {
        let sum: f64 = inclusions.values().sum();
        if inclusions
            .values()
            .any(|f| !(f.is_finite() && (0.0..=1.0).contains(f)))
            || sum > 1.0
        {
            return Err(config.error(
                "inclusions",
                "volume fractions must lie in [0, 1] and sum to at most 1 per region",
            ));
        }
    }
    if !(options.overlap.is_finite() && (0.0..0.9).contains(&options.overlap)) {
        return Err(config.error("overlap", "must be at least 0 and below 0.9"));
    }
    let tool = checked(
        config,
        ToolSpec {
            name: &options.tool,
            kind: "spray",
            diameter: options.diameter,
            feed: options.feed,
            spindle: None,
            power: options.power,
        },
    )?;
    Ok(AnyStage::Process(Box::new(Spray {
        options,
        tool,
        table: config.table.clone(),
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Process,
        name: "spray",
        doc: "Sprays each layer's area in passes, thicker by the grinding allowances, with a composite's inclusions (CMPM step 2).",
        options: Options::SPECS,
        example: "use = \"spray\"\nrough_allowance = 0.1\ndiameter = 2.0",
    },
    build,
});
