//! Discretisers and graders are given the run's machine only when they say they read
//! it (`reads_machine`), linked or behind the plugin boundary alike: a plugin's is then
//! sent with none of its calls.

use std::path::PathBuf;

use lamina_core::pipeline::Pipeline;
use lamina_core::runtime::{Engine, RunOptions, Silent};
use lamina_core::stage::{AnyStage, Discretiser, FamilyContext, Grader, StageConfig, StageInfo, StageKind};
use lamina_core::{Composition, Error, Registry, Result, SourceFile, StageFactory, SubRegion};

/// Fails unless the machine it was given is the one it said it reads.
fn check(ctx: &FamilyContext<'_>, reads: bool, what: &str) -> Result<()> {
    match (reads, ctx.info.machine.is_some()) {
        (true, false) => Err(Error::stage(what, "reads the machine, and was not given it")),
        (false, true) => Err(Error::stage(what, "does not read the machine, and was given it")),
        _ => Ok(()),
    }
}

/// Each family whole, as one region.
struct Whole {
    reads: bool,
}

impl Discretiser for Whole {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>> {
        check(ctx, self.reads, "discretise")?;
        let polygon = ctx.polygon().clone();
        Ok(vec![SubRegion::new(ctx.family, 0, 1, 0.0, polygon)])
    }

    fn reads_machine(&self) -> bool {
        self.reads
    }
}

/// Every region the first material.
struct First {
    reads: bool,
}

impl Grader for First {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        check(ctx, self.reads, "grade")?;
        let n = ctx.info.parts[ctx.part].materials.len();
        for r in regions {
            r.composition = Some(Composition::pure(0, n));
        }
        Ok(())
    }

    fn reads_machine(&self) -> bool {
        self.reads
    }

    fn reads_geometry(&self) -> bool {
        false
    }
}

macro_rules! stages {
    ($($kind:ident, $variant:ident, $name:literal, $stage:expr;)*) => {$(
        lamina_core::register_stage!(StageFactory {
            info: StageInfo {
                kind: StageKind::$kind,
                name: $name,
                doc: "Checks whether it is given the machine.",
                options: &[],
                example: concat!("use = \"", $name, "\""),
            },
            build: |_: &StageConfig<'_>| Ok(AnyStage::$variant(Box::new($stage))),
        });
    )*};
}

stages! {
    Discretise, Discretise, "test-machine-discretiser", Whole { reads: true };
    Discretise, Discretise, "test-blind-discretiser", Whole { reads: false };
    Grade, Grade, "test-machine-grader", First { reads: true };
    Grade, Grade, "test-blind-grader", First { reads: false };
}

/// Runs the box on a mixing machine with `discretise` and `grade`.
fn run(discretise: &str, grade: &str, registry: Registry) -> Result<()> {
    let dir = tempfile::tempdir().expect("tempdir");
    lamina_test_support::write_models(dir.path());
    let text = format!(
        "machine = \"marlin-mixing-2in1\"\n\n[model]\nuse = \"box\"\nsize = [10.0, 6.0, 1.0]\n\n\
         [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 255, 0]\n\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.25\n\n[discretise]\nuse = \"{discretise}\"\n\n\
         [grade]\nuse = \"{grade}\"\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
    );
    let file = SourceFile::new(dir.path().join("pipeline.toml"), text);
    let pipeline = Pipeline::parse(file, dir.path().to_path_buf(), &[]).expect("pipeline");
    let engine = Engine::build(pipeline, registry, &RunOptions::default()).expect("builds");
    let out: PathBuf = dir.path().join("out");
    engine.run(&out, &Silent).map(|_| ())
}

#[test]
fn the_machine_is_given_to_the_discretisers_and_graders_that_read_it_only() {
    for (how, registry) in lamina_test_support::linked_and_remote() {
        for (discretise, grade) in [
            ("test-machine-discretiser", "test-blind-grader"),
            ("test-blind-discretiser", "test-machine-grader"),
        ] {
            if let Err(e) = run(discretise, grade, registry.clone()) {
                panic!("{how}, {discretise} and {grade}: {e}");
            }
        }
    }
}
