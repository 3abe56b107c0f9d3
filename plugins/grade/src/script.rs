//! `script`: compositions from a user's Rhai expression or function, evaluated once per
//! sub-region (never per point), with the result checked: each fraction in [0, 1] and
//! their sum 1.

use lamina_api::script::ScriptFn;
use lamina_api::stage::{AnyStage, FamilyContext, Grader, StageConfig, StageInfo, StageKind};
use lamina_api::{Composition, Result, StageFactory, SubRegion};

use crate::control::region_args;

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// an expression (e.g. "sin(r * PI)") or "file.rhai#name"; one number f means [f, 1 - f] for two materials, else an array of one fraction per material
        f: String,
    }
}

struct Script {
    f: ScriptFn,
}

impl Grader for Script {
    /// Reads the layer's height and the regions' levels and references only.
    fn reads_geometry(&self) -> bool {
        false
    }

    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        self.grade_sets(ctx, vec![(ctx.family, regions)])
    }

    fn grade_families(
        &self,
        ctx: &FamilyContext<'_>,
        families: &[usize],
        regions: &mut [Vec<SubRegion>],
    ) -> Result<()> {
        let sets = families
            .iter()
            .copied()
            .zip(regions.iter_mut().map(Vec::as_mut_slice))
            .collect();
        self.grade_sets(ctx, sets)
    }
}

impl Script {
    /// Grades the regions of several families with one batch of script calls (one
    /// request to the host from a dynamic plugin).
    fn grade_sets(&self, ctx: &FamilyContext<'_>, sets: Vec<(usize, &mut [SubRegion])>) -> Result<()> {
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        let count = sets.iter().map(|(_, r)| r.len()).sum();
        let mut calls = Vec::with_capacity(count);
        // Which family and region each call grades, for the message of one that fails.
        let mut whose = Vec::with_capacity(count);
        for (family, regions) in &sets {
            for region in regions.iter() {
                calls.push(region_args(ctx, region, region.level));
                whose.push((*family, region.index, region.level));
            }
        }
        let all = self.f.fractions_each(&calls, n, |i| {
            let (family, index, level) = whose[i];
            format!(
                "part `{}`, layer {} (z = {:.4}), family {family}, region {index} (r = {level})",
                part.name, ctx.layer.index, ctx.layer.z
            )
        })?;
        for (region, fractions) in sets.into_iter().flat_map(|(_, r)| r.iter_mut()).zip(all) {
            region.composition = Some(Composition::new(fractions)?);
        }
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let origin = config.string_location("f");
    let f = config.scripts.compile(&o.f, origin)?;
    Ok(AnyStage::Grade(Box::new(Script { f })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: crate::SCRIPT_STAGE,
        doc: "Fractions from a Rhai expression or `file.rhai#function` of r, x, y, z, layer and part, once per sub-region.",
        options: Options::SPECS,
        example: concat!("use = \"", script_stage!(), "\"\nf = \"clamp01(z / 2.0)\""),
    },
    build,
});
