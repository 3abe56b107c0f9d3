//! What the G-code tests share: the exporter run in memory on given layer plans, the
//! run of one part of two materials, and a layer plan of given toolpaths.

use std::io::Write;
use std::path::Path;
use std::sync::{Arc, Mutex};

use lamina_core::machine::Machine;
use lamina_core::stage::{ExportContext, OutputFiles};
use lamina_core::{BBox2, LayerPlan, Material, PartInfo, Registry, RunInfo, Toolpath};

/// One in-memory file every output of the exporter writes into.
#[derive(Clone, Default)]
struct Buffer(Arc<Mutex<Vec<u8>>>);

impl Write for Buffer {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().expect("lock").extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

struct Files(Buffer);

impl OutputFiles for Files {
    fn create(&mut self, _name: &Path) -> lamina_core::Result<Box<dyn Write + Send>> {
        Ok(Box::new(self.0.clone()))
    }
}

/// The G-code the exporter configured by `table` writes for `plans`, built against the
/// run's machine (if any) as a pipeline would.
pub fn export(
    table: &str,
    info: &RunInfo,
    plans: &[LayerPlan],
    pipeline: &str,
) -> lamina_core::Result<String> {
    use lamina_gcode as _;
    let registry = Registry::linked().expect("registry");
    let dir = std::env::temp_dir();
    let scripts = lamina_core::script::local(&dir, Default::default());
    let table = lamina_core::pipeline::TableRef::parse_snippet("gcode", table).expect("table");
    let exporter = registry.build_for::<dyn lamina_core::Exporter>(
        &table,
        &scripts,
        &dir,
        lamina_core::stage::PipelineContext {
            machine: info.machine.as_ref(),
            ..Default::default()
        },
    )?;
    let buffer = Buffer::default();
    let mut files = Files(buffer.clone());
    let mut ctx = ExportContext {
        info,
        sequence: None,
        orientation: None,
        layer_count: plans.len(),
        pipeline_name: pipeline,
        files: &mut files,
    };
    let mut sink = exporter.open(&mut ctx)?;
    for p in plans {
        sink.layer(info, p, &mut files)?;
    }
    sink.finish(info, &mut files)?;
    let bytes = buffer.0.lock().expect("lock").clone();
    Ok(String::from_utf8(bytes).expect("utf-8"))
}

/// A run of one part (`part`, 1 mm high) of two materials named `names` (red and green),
/// within `xy_bounds`, on `machine`.
pub fn run_info(names: [&str; 2], part: String, xy_bounds: BBox2, machine: Option<Machine>) -> RunInfo {
    let mat = |name: &str, colour| Material {
        name: name.into(),
        colour,
        layer_thickness: None,
    };
    RunInfo {
        base_dir: std::path::PathBuf::from("."),
        materials: vec![mat(names[0], [255, 0, 0]), mat(names[1], [0, 255, 0])],
        parts: vec![PartInfo {
            name: part,
            materials: vec![0, 1],
            mesh: 0,
            z_min: 0.0,
            z_max: 1.0,
            z_gradient: None,
        }],
        z_min: 0.0,
        z_max: 1.0,
        xy_bounds,
        machine,
        model_frame: None,
    }
}

/// Layer `index` of 0.2 mm layers (its top at 0.2 (index + 1)), of `toolpaths` that
/// take `build_time` seconds.
pub fn layer_plan(index: usize, toolpaths: Vec<Toolpath>, build_time: f64) -> LayerPlan {
    LayerPlan {
        index,
        z: 0.2 * (index + 1) as f64,
        thickness: 0.2,
        material_region: None,
        parts: Vec::new(),
        toolpaths,
        build_time: Some(build_time),
        sequential_time: None,
        fill: None,
        pauses: None,
        operations: Vec::new(),
        diagnostics: Vec::new(),
    }
}
