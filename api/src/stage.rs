//! One trait per stage kind, the self-description every stage implementation carries,
//! and the contexts stages receive. All stage traits are object safe and `Send + Sync`:
//! the runtime holds them as `Box<dyn ...>` and calls them from many threads at once.

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

pub use crate::kind::StageKind;

use crate::error::Result;
use crate::geom::{BBox2, Polygon};
use crate::machine::Machine;
use crate::mesh::Mesh;
use crate::model::*;
use crate::script::ScriptHost;

/// One option a stage accepts, for documentation and validation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OptionSpec {
    pub name: &'static str,
    /// The TOML type, e.g. `float`, `integer`, `string`, `bool`, `array of float`.
    pub ty: &'static str,
    /// The default as a TOML literal; `None` when the option has none.
    pub default: Option<&'static str>,
    pub doc: &'static str,
    /// True when the user must give the option; one without a default that is not
    /// required has no value when absent (its doc says what that means).
    pub required: bool,
    /// The physical range every number of the value lies in, both ends included; a
    /// value outside it is refused naming the key and the range.
    pub range: Option<(f64, f64)>,
}

impl OptionSpec {
    /// An option the user must give.
    pub const fn required(name: &'static str, ty: &'static str, doc: &'static str) -> Self {
        Self {
            name,
            ty,
            default: None,
            doc,
            required: true,
            range: None,
        }
    }

    /// An option the user may leave out, without a default value.
    pub const fn optional(name: &'static str, ty: &'static str, doc: &'static str) -> Self {
        Self {
            name,
            ty,
            default: None,
            doc,
            required: false,
            range: None,
        }
    }

    /// An option with a default (written as a TOML literal).
    pub const fn new(name: &'static str, ty: &'static str, default: &'static str, doc: &'static str) -> Self {
        Self {
            name,
            ty,
            default: Some(default),
            doc,
            required: false,
            range: None,
        }
    }

    /// The option, its numbers held to `min..=max`.
    pub const fn within(self, min: f64, max: f64) -> Self {
        Self {
            range: Some((min, max)),
            ..self
        }
    }
}

/// What a stage implementation says about itself: shown by `lamina plugins` and used
/// to generate the pipeline reference.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StageInfo {
    pub kind: StageKind,
    pub name: &'static str,
    /// One line.
    pub doc: &'static str,
    pub options: &'static [OptionSpec],
    /// A complete table for this stage (without the `[kind]` header) that a test builds
    /// and runs.
    pub example: &'static str,
}

/// A stage built from its pipeline table.
pub enum AnyStage {
    Model(Box<dyn ModelSource>),
    Orient(Box<dyn Orienter>),
    Slice(Box<dyn Slicer>),
    Sort(Box<dyn Sorter>),
    Discretise(Box<dyn Discretiser>),
    Grade(Box<dyn Grader>),
    Sequence(Box<dyn Sequencer>),
    Plan(Box<dyn Planner>),
    Process(Box<dyn Process>),
    Export(Box<dyn Exporter>),
}

impl AnyStage {
    pub fn kind(&self) -> StageKind {
        match self {
            AnyStage::Model(_) => StageKind::Model,
            AnyStage::Orient(_) => StageKind::Orient,
            AnyStage::Slice(_) => StageKind::Slice,
            AnyStage::Sort(_) => StageKind::Sort,
            AnyStage::Discretise(_) => StageKind::Discretise,
            AnyStage::Grade(_) => StageKind::Grade,
            AnyStage::Sequence(_) => StageKind::Sequence,
            AnyStage::Plan(_) => StageKind::Plan,
            AnyStage::Process(_) => StageKind::Process,
            AnyStage::Export(_) => StageKind::Export,
        }
    }
}

/// A stage trait as a registry builds it, by type: `registry.build::<dyn Grader>(..)`
/// gives a `Box<dyn Grader>`, with no match on [`AnyStage`] at the call.
pub trait StageType {
    const KIND: StageKind;
    /// The stage inside `stage`, or `stage` back when it is of another kind.
    fn from_any(stage: AnyStage) -> std::result::Result<Box<Self>, AnyStage>;
}

impl AnyStage {
    /// The stage as its trait, or an error naming both kinds.
    pub fn into_type<S: StageType + ?Sized>(self) -> Result<Box<S>> {
        S::from_any(self).map_err(|other| {
            crate::error::Error::stage(
                S::KIND.name(),
                format!("expected a {} stage, got {}", S::KIND, other.kind()),
            )
        })
    }
}

macro_rules! stage_types {
    ($($variant:ident => $trait:ident),* $(,)?) => {$(
        impl StageType for dyn $trait {
            const KIND: StageKind = StageKind::$variant;
            fn from_any(stage: AnyStage) -> std::result::Result<Box<Self>, AnyStage> {
                match stage {
                    AnyStage::$variant(s) => Ok(s),
                    other => Err(other),
                }
            }
        }
    )*};
}

stage_types! {
    Model => ModelSource,
    Orient => Orienter,
    Slice => Slicer,
    Sort => Sorter,
    Discretise => Discretiser,
    Grade => Grader,
    Sequence => Sequencer,
    Plan => Planner,
    Process => Process,
    Export => Exporter,
}

impl fmt::Debug for AnyStage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AnyStage({})", self.kind())
    }
}

/// What a process stage knows about the layer it plans.
#[derive(Debug, Clone, Copy)]
pub struct ProcessContext<'a> {
    pub info: &'a RunInfo,
    /// The fabrication sequence, when the layers follow one.
    pub sequence: Option<&'a Sequence>,
    /// The surface height of every material region when this layer begins (finished
    /// layers end at their design height); `None` for a region not begun yet.
    pub surfaces: &'a [Option<f64>],
    /// The other regions that stand higher than this layer's base, cut at the layer's
    /// height; filled only when some process stage asks for them.
    pub higher: &'a [crate::process::RegionOutline],
    /// True for the job's last layer, where what ends the job goes.
    pub last: bool,
}

/// Read-only facts about the run every stage may consult.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunInfo {
    /// Folder of the pipeline file: relative paths resolve against it.
    pub base_dir: PathBuf,
    pub materials: Vec<Material>,
    pub parts: Vec<PartInfo>,
    /// Height range of all parts (mm).
    pub z_min: f64,
    pub z_max: f64,
    /// XY bounding box of all the meshes as placed by their model tables (mm): what a
    /// machine's placement moves onto its bed.
    pub xy_bounds: BBox2,
    /// The machine the pipeline names, if any.
    pub machine: Option<Machine>,
    /// How the model's own coordinates became the build's, when an `[orient]` stage
    /// turned it: what the model describes in its own frame (a microstructure's base
    /// cells) turns with it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_frame: Option<ModelFrame>,
}

impl RunInfo {
    pub fn resolve(&self, path: &Path) -> PathBuf {
        self.base_dir.join(path)
    }

    /// Materials of a part, in the part's order.
    pub fn part_materials(&self, part: usize) -> Vec<Material> {
        self.parts[part]
            .materials
            .iter()
            .map(|&m| self.materials[m].clone())
            .collect()
    }
}

/// Produces the meshes of a model: a file reader or a generator.
pub trait ModelSource: Send + Sync {
    fn load(&self, base_dir: &Path) -> Result<Vec<Mesh>>;
}

/// Chooses the build direction of the whole object (every mesh of every model, moved
/// together) before it is sliced.
pub trait Orienter: Send + Sync {
    /// The rotation to apply and the alternatives weighed, for the report.
    fn orient(&self, meshes: &[&Mesh]) -> Result<Orientation>;
}

/// Decides the layer heights, then cuts meshes into layers.
pub trait Slicer: Send + Sync {
    /// Layer slots over `z_min..z_max`, following the sequence's work cycles when the
    /// slicer is adaptive and a sequence is given.
    fn layers(
        &self,
        meshes: &[Arc<Mesh>],
        info: &RunInfo,
        sequence: Option<&Sequence>,
    ) -> Result<Vec<LayerSlot>>;

    /// Prepares one mesh for cutting (indexes, repairs); the result is shared by all
    /// threads.
    fn prepare(&self, mesh: Arc<Mesh>) -> Result<Box<dyn MeshSlicer>>;
}

/// A mesh prepared for cutting.
pub trait MeshSlicer: Send + Sync {
    fn slice(&self, slot: &LayerSlot) -> Result<Layer>;
}

/// Orders a layer's contours into their containment hierarchy.
pub trait Sorter: Send + Sync {
    fn sort(&self, layer: &Layer) -> Result<ContourTree>;
}

/// What a discretiser or grader knows about the family it works on.
#[derive(Debug, Clone, Copy)]
pub struct FamilyContext<'a> {
    /// The run; without its machine for a stage that does not say it reads it
    /// (`reads_machine`).
    pub info: &'a RunInfo,
    pub layer: &'a Layer,
    pub tree: &'a ContourTree,
    /// The polygon of every family of the layer ([`ContourTree::family_polygons`]),
    /// built once by whoever calls the stage and shared by its discretiser and grader:
    /// read the one worked on with [`FamilyContext::polygon`].
    pub polygons: &'a [Polygon],
    /// The part's mesh as it was sliced (placed and oriented), for stages that measure
    /// in space (distances to chosen faces) and say so (`reads_mesh`); `None` for the
    /// others, and where no mesh exists (tests of a stage on a drawn family).
    pub mesh: Option<&'a crate::mesh::Mesh>,
    pub part: usize,
    pub family: usize,
}

impl<'a> FamilyContext<'a> {
    /// The polygon of the family worked on: its outer contour counter-clockwise, its
    /// holes clockwise.
    pub fn polygon(&self) -> &'a Polygon {
        &self.polygons[self.family]
    }
}

/// Divides one contour family into sub-regions of constant material that tile it. A
/// discretiser whose regions follow the material (grading sources) may set their
/// compositions too; a grader, when the pipeline has one, overrides them.
pub trait Discretiser: Send + Sync {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>>;

    /// True when the regions come with their compositions, so a part of several
    /// materials needs no grader.
    fn grades(&self) -> bool {
        false
    }

    /// True when the stage measures the part's mesh ([`FamilyContext::mesh`]): only
    /// then is the mesh given to it (and, behind the plugin boundary, sent to it).
    fn reads_mesh(&self) -> bool {
        false
    }

    /// True when the stage reads the machine of the run ([`RunInfo::machine`] in
    /// [`FamilyContext::info`]): only then is it given to it (and, behind the plugin
    /// boundary, sent with every call). The stage's configuration carries the machine
    /// when it is built, which is where a bead width or a nozzle is best read.
    fn reads_machine(&self) -> bool {
        false
    }

    /// The sub-regions of each of `families` of one part's layer, in their order (the
    /// context's own `family` is not read). This is what the runtime calls: by default
    /// it discretises the families one by one; a stage behind the plugin boundary is
    /// asked for them all in one call, the layer sent once.
    fn discretise_families(
        &self,
        ctx: &FamilyContext<'_>,
        families: &[usize],
    ) -> Result<Vec<Vec<SubRegion>>> {
        families
            .iter()
            .map(|&family| self.discretise(&FamilyContext { family, ..*ctx }))
            .collect()
    }
}

/// Gives every sub-region of a family its composition.
pub trait Grader: Send + Sync {
    /// Sets `composition` on every region; fractions are over the part's materials.
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()>;

    /// True when the stage measures the part's mesh ([`FamilyContext::mesh`]): only
    /// then is the mesh given to it (and, behind the plugin boundary, sent to it).
    fn reads_mesh(&self) -> bool {
        false
    }

    /// True when the stage reads the machine of the run ([`RunInfo::machine`] in
    /// [`FamilyContext::info`]): only then is it given to it (and, behind the plugin
    /// boundary, sent with every call).
    fn reads_machine(&self) -> bool {
        false
    }

    /// False when the grader reads no contour and no polygon (only the layer's height
    /// and index, and the regions' levels, references and cells): behind the plugin
    /// boundary it is then sent the layer without its contours and the regions without
    /// their polygons, which is most of a call's bytes.
    fn reads_geometry(&self) -> bool {
        true
    }

    /// Grades the regions of each of `families` of one part's layer: `regions[i]` are
    /// those of `families[i]` (the context's own `family` is not read). This is what
    /// the runtime calls: by default it grades the families one by one; a stage behind
    /// the plugin boundary is asked for them all in one call, the layer sent once.
    fn grade_families(
        &self,
        ctx: &FamilyContext<'_>,
        families: &[usize],
        regions: &mut [Vec<SubRegion>],
    ) -> Result<()> {
        for (&family, regions) in families.iter().zip(regions) {
            self.grade(&FamilyContext { family, ..*ctx }, regions)?;
        }
        Ok(())
    }
}

/// Plans the fabrication sequence of the whole object, before slicing.
pub trait Sequencer: Send + Sync {
    fn sequence(&self, info: &RunInfo) -> Result<Sequence>;

    /// True when the sequence needs each part's composition gradient along z
    /// (`PartInfo::z_gradient`), which the runtime samples from the part's grading
    /// before it asks for the sequence.
    fn needs_gradients(&self) -> bool {
        false
    }
}

/// Plans toolpaths for one layer.
pub trait Planner: Send + Sync {
    /// Fills `plan.toolpaths` (and `plan.build_time`).
    fn plan(&self, info: &RunInfo, plan: &mut LayerPlan) -> Result<()>;
}

/// Plans one kind of operation of a hybrid process on each layer (`[[process]]`
/// tables, run in their order after the planner): appends to `plan.operations`.
pub trait Process: Send + Sync {
    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()>;

    /// True when the stage needs the outlines of the higher regions around the layer
    /// (`ProcessContext::higher`), which costs a cut of their meshes.
    fn needs_higher(&self) -> bool {
        false
    }
}

/// What an exporter knows when it opens its output.
pub struct ExportContext<'a> {
    pub info: &'a RunInfo,
    pub sequence: Option<&'a Sequence>,
    /// The build direction chosen by an `[orient]` stage, if any.
    pub orientation: Option<&'a Orientation>,
    pub layer_count: usize,
    pub pipeline_name: &'a str,
    /// Creates output files that appear under their final name only when the whole run
    /// succeeds.
    pub files: &'a mut dyn OutputFiles,
}

/// Creates output files for an exporter. The names are relative to the output folder.
pub trait OutputFiles {
    fn create(&mut self, name: &Path) -> Result<Box<dyn Write + Send>>;
    /// The files of this run created so far: each name as given to [`Self::create`],
    /// and a path its content can be read from. Sinks finish in the pipeline's order of
    /// outputs, so at `finish` every earlier output is complete: a viewer can read back
    /// the G-code the run wrote. Empty where the files cannot be read back (a plugin
    /// loaded as a library writes through the host).
    fn written(&self) -> Vec<(PathBuf, PathBuf)> {
        Vec::new()
    }
    /// Records what a machine file says of itself (its own time estimate, what it
    /// deposits), for the run's summary: what a user reads there is what the machine
    /// will do. A host that keeps no summary ignores it.
    fn report(&mut self, _report: MachineFileReport) {}
    /// Tells the user something about an output file that is neither an error nor part
    /// of the file (a page split in two, data left out to keep it in bounds): the run
    /// prints it with the export stage's other diagnostics, naming the file. A host
    /// that prints nothing ignores it.
    fn tell(
        &mut self,
        _file: &Path,
        _severity: crate::diagnostic::Severity,
        _said: crate::diagnostic::Warning,
    ) {
    }
}

/// What a machine file (G-code, NC) says of itself.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MachineFileReport {
    /// The file, as its exporter created it.
    pub file: PathBuf,
    /// The time the file takes by its own estimate, every wait included (s).
    pub time: f64,
    /// Volume deposited as part (mm³).
    pub part: f64,
    /// Of `part`: transitions after a change of tool or mix that the part's beads took.
    pub transition: f64,
    /// Volume deposited beside the part, by kind (`purge`, `tower`, `prime`, `skirt`).
    pub waste: Vec<(String, f64)>,
    /// Of `time`: what it is spent on (s), by operation, where the file knows (an NC
    /// program's spraying, grinding, tool changes).
    pub shares: Vec<(String, f64)>,
    /// What the machine will do otherwise than the plan asks (a wheel that cannot
    /// reach its surface speed); the run prints them as warnings of the export stage.
    pub notes: Vec<crate::diagnostic::Warning>,
}

impl MachineFileReport {
    /// What is deposited beside the part over all that is deposited (0 when nothing is).
    pub fn waste_share(&self) -> f64 {
        let waste: f64 = self.waste.iter().map(|(_, v)| v).sum();
        let total = self.part + waste;
        if total > 0.0 { waste / total } else { 0.0 }
    }
}

/// Writes one kind of output.
pub trait Exporter: Send + Sync {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>>;
}

/// Receives the layers of a run in build order, as they are finished.
///
/// Both calls get the run's files: a sink that writes one stream keeps what it
/// created at `open` and ignores them; one that writes a file per layer, or a picture
/// drawn from all layers at the end, creates it here. Files appear under their final
/// names only when the whole run succeeds, as those made at `open` do.
pub trait LayerSink: Send {
    /// Takes the next layer in build order.
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, files: &mut dyn OutputFiles) -> Result<()>;
    /// Completes the output (trailers, flushing, a picture of all layers).
    fn finish(self: Box<Self>, info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()>;
}

/// The configuration a stage factory receives: its pipeline table and the services it
/// may need (scripts compiled by the host).
pub struct StageConfig<'a> {
    pub table: &'a crate::table::TableRef,
    pub scripts: &'a ScriptHost,
    pub base_dir: &'a Path,
    /// Where the files the stage's options name may be read from (checked with
    /// [`Reach::check`](crate::reach::Reach::check) or read with
    /// [`Reach::read`](crate::reach::Reach::read)): a pipeline is untrusted data.
    pub reach: &'a crate::reach::Reach,
    /// The machine the pipeline names, so a stage can check its options against it
    /// when the pipeline is checked rather than when it runs.
    pub machine: Option<&'a Machine>,
    /// The run's resource limits: a stage checks the sizes its options imply when it
    /// is built, and the sizes its input implies before it allocates.
    pub limits: crate::Limits,
}

/// What a pipeline gives every stage it builds besides the stage's own table.
#[derive(Debug, Clone, Copy, Default)]
pub struct PipelineContext<'a> {
    pub machine: Option<&'a Machine>,
    /// Where the files a stage's options name may be read from; `None` is the stage's
    /// base folder only.
    pub reach: Option<&'a crate::reach::Reach>,
    pub limits: crate::Limits,
}

impl StageConfig<'_> {
    /// Deserialises the table into the stage's options struct (one declared with
    /// [`stage_options!`](crate::stage_options), or with
    /// `#[serde(deny_unknown_fields)]`); errors point at the offending key or value.
    pub fn parse<T: serde::de::DeserializeOwned>(&self) -> Result<T> {
        self.table.parse()
    }

    /// An error pointing at `key` of this stage's table.
    pub fn error(&self, key: &str, message: impl Into<String>) -> crate::Error {
        self.table.error_at(key, message)
    }

    /// True when the stage's table sets `key` (rather than leaving its default).
    pub fn has(&self, key: &str) -> bool {
        self.table.has(key)
    }

    /// Where the string value of `key` is written in the user's file (for a script
    /// written inline, so that its errors point into the file); `None` when a `--set`
    /// override gave the value.
    pub fn string_location(&self, key: &str) -> Option<crate::source::Location> {
        self.table.string_location(key)
    }
}
