//! Test fixture: a third-party plugin crate with its own workspace and lock file, which
//! resolves releases of serde, toml and rmp-serde other than the host's. Meshes (nalgebra
//! points), options (parsed with this crate's serde and toml), compositions and scripts
//! all cross the boundary, and the run must come out as with the host's own copies.

use lamina_api::mesh::{Mesh, Point3};
use lamina_api::script::{ScriptArgs, ScriptFn};
use lamina_api::stage::{
    AnyStage, FamilyContext, Grader, ModelSource, OptionSpec, StageConfig, StageInfo, StageKind,
};
use lamina_api::{Composition, Result, StageFactory, SubRegion};
use serde::Deserialize;

lamina_api::export_plugin!("skewed");

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BoxOptions {
    size: [f64; 3],
}

/// A box with one corner at the origin, as twelve triangles wound outwards.
struct SkewedBox([f64; 3]);

impl ModelSource for SkewedBox {
    fn load(&self, _: &std::path::Path) -> Result<Vec<Mesh>> {
        let [x, y, z] = self.0;
        let vertices = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 == 0 { 0.0 } else { x },
                    if i & 2 == 0 { 0.0 } else { y },
                    if i & 4 == 0 { 0.0 } else { z },
                )
            })
            .collect();
        let triangles = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        Ok(vec![Mesh::new("skewed-box", vertices, triangles)])
    }
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "skewed-box",
        doc: "A box with one corner at the origin (test fixture).",
        options: &[OptionSpec::required(
            "size",
            "array of float",
            "size along x, y, z (mm)"
        )],
        example: "use = \"skewed-box\"\nsize = [10.0, 5.0, 2.0]",
    },
    build: |config| {
        let o: BoxOptions = config.parse()?;
        Ok(AnyStage::Model(Box::new(SkewedBox(o.size))))
    },
});

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GradeOptions {
    f: String,
}

/// Fractions from a script of the layer's height, run by the host.
struct SkewedGrade(ScriptFn);

impl Grader for SkewedGrade {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        let n = ctx.info.parts[ctx.part].materials.len();
        for region in regions.iter_mut() {
            let args = ScriptArgs {
                r: region.level,
                z: ctx.layer.z,
                layer: ctx.layer.index as i64,
                part: &ctx.info.parts[ctx.part].name,
                ..ScriptArgs::default()
            };
            let fractions = self.0.fractions(&args, n, "a skewed region")?;
            region.composition = Some(Composition::new(fractions)?);
        }
        Ok(())
    }
}

fn build_grade(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: GradeOptions = config.parse()?;
    let f = config.scripts.compile(&o.f, config.string_location("f"))?;
    Ok(AnyStage::Grade(Box::new(SkewedGrade(f))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: "skewed-z",
        doc: "Fractions from a Rhai expression, run by the host (test fixture).",
        options: &[OptionSpec::required("f", "string", "a Rhai expression")],
        example: "use = \"skewed-z\"\nf = \"clamp01(z)\"",
    },
    build: build_grade,
});
