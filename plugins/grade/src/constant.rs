//! `constant`: one composition for every region of the part, given as a material name
//! or as fractions.

use lamina_api::stage::{AnyStage, FamilyContext, Grader, StageConfig, StageInfo, StageKind};
use lamina_api::{Composition, Error, Result, StageFactory, SubRegion};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// the single material of the part
        material: Option<String>,
        /// fractions over the part's materials, summing to 1
        #[range(0, 1)]
        fractions: Option<Vec<f64>>,
    }
}

enum Spec {
    Material(String),
    Fractions(Vec<f64>),
}

struct Constant(Spec);

impl Grader for Constant {
    /// Reads the layer's height and the regions' levels and references only.
    fn reads_geometry(&self) -> bool {
        false
    }

    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        let composition = match &self.0 {
            Spec::Material(name) => {
                let i = part
                    .materials
                    .iter()
                    .position(|&m| ctx.info.materials[m].name == *name)
                    .ok_or_else(|| {
                        Error::stage(
                            "grade:constant",
                            format!("part `{}` has no material `{name}`", part.name),
                        )
                    })?;
                Composition::pure(i, n)
            }
            Spec::Fractions(f) => {
                if f.len() != n {
                    return Err(Error::stage(
                        "grade:constant",
                        format!(
                            "{} fractions given, part `{}` has {n} materials",
                            f.len(),
                            part.name
                        ),
                    ));
                }
                Composition::new(f.clone())?
            }
        };
        for r in regions {
            r.composition = Some(composition.clone());
        }
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let spec = match (o.material, o.fractions) {
        (Some(m), None) => Spec::Material(m),
        (None, Some(f)) => {
            Composition::check(&f).map_err(|e| config.error("fractions", e.to_string()))?;
            Spec::Fractions(f)
        }
        _ => return Err(config.error("material", "give either `material` or `fractions`")),
    };
    Ok(AnyStage::Grade(Box::new(Constant(spec))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: "constant",
        doc: "One composition for the whole part: a material by name, or fractions over the part's materials.",
        options: Options::SPECS,
        example: "use = \"constant\"\nfractions = [0.25, 0.75]",
    },
    build,
});
