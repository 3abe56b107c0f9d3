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
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        for region in regions.iter_mut() {
            let args = region_args(ctx, region, region.level);
            let context = format!(
                "part `{}`, layer {} (z = {:.4}), family {}, region {} (r = {})",
                part.name, ctx.layer.index, ctx.layer.z, ctx.family, region.index, region.level
            );
            let fractions = self.f.fractions(&args, n, &context)?;
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
