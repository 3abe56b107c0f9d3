//! Stages that misbehave, linked into this test program: the runtime holds their plans
//! to what a machine can follow and turns their panics into errors naming them, linked
//! or behind the plugin boundary alike.

use std::path::PathBuf;

use lamina_core::pipeline::Pipeline;
use lamina_core::runtime::{Engine, RunOptions, Silent};
use lamina_core::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, Planner, StageConfig, StageInfo, StageKind,
};
use lamina_core::{Error, LayerPlan, PathKind, Point2, Registry, Result, RunInfo, SourceFile, StageFactory};
use lamina_core::{TimedPoint, Toolpath};

/// Plans one bead through a point at NaN.
struct NanPlanner;

impl Planner for NanPlanner {
    fn plan(&self, _info: &RunInfo, plan: &mut LayerPlan) -> Result<()> {
        plan.toolpaths.push(Toolpath {
            tool: 0,
            material: None,
            kind: PathKind::Extrude,
            points: vec![
                TimedPoint {
                    p: Point2::new(0.0, 0.0),
                    t: 0.0,
                },
                TimedPoint {
                    p: Point2::new(f64::NAN, 1.0),
                    t: 1.0,
                },
            ],
            width: 0.4,
            widths: Vec::new(),
            composition: None,
            part: None,
            sub_region: None,
        });
        Ok(())
    }
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Plan,
        name: "test-nan-planner",
        doc: "Plans a bead through a point at NaN.",
        options: &[],
        example: "use = \"test-nan-planner\"",
    },
    build: |_: &StageConfig<'_>| Ok(AnyStage::Plan(Box::new(NanPlanner))),
});

/// Panics on the second layer.
struct PanickingExporter;

struct PanickingSink(usize);

impl Exporter for PanickingExporter {
    fn open(&self, _ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        Ok(Box::new(PanickingSink(0)))
    }
}

impl LayerSink for PanickingSink {
    fn layer(&mut self, _info: &RunInfo, _plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        self.0 += 1;
        assert!(self.0 < 2, "the second layer is one too many");
        Ok(())
    }

    fn finish(self: Box<Self>, _info: &RunInfo, _files: &mut dyn OutputFiles) -> Result<()> {
        Ok(())
    }
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "test-panicking-exporter",
        doc: "Panics on the second layer.",
        options: &[],
        example: "use = \"test-panicking-exporter\"",
    },
    build: |_: &StageConfig<'_>| Ok(AnyStage::Export(Box::new(PanickingExporter))),
});

const MODEL: &str = "[model]\nuse = \"box\"\nsize = [10.0, 6.0, 1.0]\n\n[materials.a]\ncolour = [255, 0, 0]\n\n\
                     [slice]\nuse = \"uniform\"\nthickness = 0.5\n\n";

/// Runs `text` with the stages of `registry`; the error, and whether the output
/// folder holds any file.
fn run(text: &str, registry: Registry) -> (Error, bool) {
    let dir = tempfile::tempdir().expect("tempdir");
    lamina_test_support::write_models(dir.path());
    let file = SourceFile::new(dir.path().join("pipeline.toml"), text);
    let pipeline = Pipeline::parse(file, dir.path().to_path_buf(), &[]).expect("pipeline");
    let engine = Engine::build(pipeline, registry, &RunOptions::default()).expect("builds");
    let out: PathBuf = dir.path().join("out");
    let error = engine.run(&out, &Silent).expect_err("refused");
    let written = std::fs::read_dir(&out).map(|d| d.count() > 0).unwrap_or(false);
    (error, written)
}

/// The linked stages, and the same stages behind the plugin boundary.
fn registries() -> [(&'static str, Registry); 2] {
    [
        ("linked", lamina_test_support::registry()),
        (
            "remote",
            lamina_test_support::registry_through_boundary("loopback"),
        ),
    ]
}

#[test]
fn a_plan_no_machine_can_follow_fails_the_run() {
    let text = format!(
        "{MODEL}[plan]\nuse = \"test-nan-planner\"\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
    );
    for (how, registry) in registries() {
        let (e, written) = run(&text, registry);
        let message = e.to_string();
        assert!(
            message.contains("the plan stage left a plan no machine can follow")
                && message.contains("toolpath 0: point 1 at (NaN, 1)"),
            "{how}: {message}"
        );
        assert!(!written, "{how}: a refused plan left files behind");
    }
}

#[test]
fn a_panicking_exporter_is_an_error_naming_it() {
    let text = format!(
        "{MODEL}[[output]]\nuse = \"json\"\npath = \"plan.json\"\n\n[[output]]\nuse = \"test-panicking-exporter\"\n"
    );
    for (how, registry) in registries() {
        let (e, written) = run(&text, registry);
        let message = e.to_string();
        assert!(
            message.contains("panicked")
                && message.contains("test-panicking-exporter")
                && message.contains("the second layer is one too many"),
            "{how}: {message}"
        );
        assert!(!written, "{how}: the failed run left files behind");
    }
}
