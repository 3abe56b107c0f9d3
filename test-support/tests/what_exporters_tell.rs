//! What an exporter tells the user about its files (`OutputFiles::tell`) and what a
//! machine file says of itself (`OutputFiles::report`) reach the run's report, linked
//! or behind the plugin boundary alike.

use std::io::Write;
use std::path::{Path, PathBuf};

use lamina_core::pipeline::Pipeline;
use lamina_core::runtime::{Engine, RunOptions, RunReport, Silent};
use lamina_core::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, MachineFileReport, OutputFiles, StageConfig, StageInfo,
    StageKind,
};
use lamina_core::{LayerPlan, Registry, Result, RunInfo, Severity, SourceFile, StageFactory, Warning};

/// Writes the layer count, then tells a note and reports the file when it finishes.
struct Telling;

struct Sink {
    out: Box<dyn Write + Send>,
    layers: usize,
}

impl Exporter for Telling {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let out = ctx.files.create(Path::new("told.txt"))?;
        Ok(Box::new(Sink { out, layers: 0 }))
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, _: &RunInfo, _: &LayerPlan, _: &mut dyn OutputFiles) -> Result<()> {
        self.layers += 1;
        Ok(())
    }

    fn finish(mut self: Box<Self>, _: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        writeln!(self.out, "{} layers", self.layers)
            .map_err(|e| lamina_core::Error::stage("export", e.to_string()))?;
        self.out
            .flush()
            .map_err(|e| lamina_core::Error::stage("export", e.to_string()))?;
        let file = Path::new("told.txt");
        files.tell(
            file,
            Severity::Note,
            Warning::new("told", format!("{} layers, counted", self.layers)),
        );
        files.report(MachineFileReport {
            file: file.to_path_buf(),
            time: 12.5,
            part: 60.0,
            waste: vec![("purge".into(), 1.5)],
            ..MachineFileReport::default()
        });
        Ok(())
    }
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "test-telling",
        doc: "Tells a note and reports its file.",
        options: &[],
        example: "use = \"test-telling\"",
    },
    build: |_: &StageConfig<'_>| Ok(AnyStage::Export(Box::new(Telling))),
});

fn run(registry: Registry) -> RunReport {
    let dir = tempfile::tempdir().expect("tempdir");
    lamina_test_support::write_models(dir.path());
    let text = "[model]\nuse = \"box\"\nsize = [10.0, 6.0, 1.0]\n\n\
                [materials.a]\ncolour = [255, 0, 0]\n\n\
                [slice]\nuse = \"uniform\"\nthickness = 0.25\n\n[[output]]\nuse = \"test-telling\"\n";
    let file = SourceFile::new(dir.path().join("pipeline.toml"), text.to_string());
    let pipeline = Pipeline::parse(file, dir.path().to_path_buf(), &[]).expect("pipeline");
    let engine = Engine::build(pipeline, registry, &RunOptions::default()).expect("builds");
    let out: PathBuf = dir.path().join("out");
    let report = engine.run(&out, &Silent).expect("runs");
    let written = std::fs::read_to_string(out.join("told.txt")).expect("the file");
    assert_eq!(written, "4 layers\n");
    report
}

#[test]
fn an_exporters_notes_and_reports_reach_the_run_linked_and_loaded() {
    for (how, registry) in lamina_test_support::linked_and_remote() {
        let report = run(registry);
        let told: Vec<_> = report
            .diagnostics
            .iter()
            .filter(|d| d.message.contains("4 layers, counted"))
            .collect();
        assert_eq!(told.len(), 1, "{how}: {:?}", report.diagnostics);
        assert_eq!(told[0].severity, Severity::Note, "{how}");
        assert!(told[0].message.contains("told.txt"), "{how}: {}", told[0].message);
        assert_eq!(
            report.machine_files,
            vec![MachineFileReport {
                file: PathBuf::from("told.txt"),
                time: 12.5,
                part: 60.0,
                waste: vec![("purge".into(), 1.5)],
                ..MachineFileReport::default()
            }],
            "{how}"
        );
    }
}
