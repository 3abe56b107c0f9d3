//! The messages between the host and a dynamic plugin, and their encoding.
//!
//! Every stage call becomes a [`Request`] the plugin answers with a [`Reply`]; during a
//! call the plugin may ask the host for services with a [`HostRequest`] (compile or
//! run a script under the host's sandbox, create and write output files). Messages
//! are MessagePack with named fields: a field one side does not know is ignored, and a
//! missing or malformed one is an error naming it, never a misread value.
//!
//! Requests borrow what the host already holds (`Cow::Borrowed`); the plugin decodes
//! them into owned values.

mod error;
mod table;

pub use error::{WireError, WireLocation};

use std::borrow::Cow;
use std::path::Path;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::limits::Limits;
use crate::machine::Machine;
use crate::mesh::Mesh;
use crate::model::*;
use crate::source::SourceFile;
use crate::stage::{RunInfo, StageKind};

/// A call of the host into a plugin.
#[derive(Debug, Serialize, Deserialize)]
pub enum Request<'a> {
    /// The plugin's stages, in the order `Build` numbers them.
    Describe,
    /// Builds stage number `stage` from its configuration; replies with a handle.
    Build {
        stage: usize,
        label: Cow<'a, str>,
        config: WireConfig<'a>,
    },
    Load {
        handle: u64,
        base_dir: Cow<'a, Path>,
    },
    Orient {
        handle: u64,
        meshes: Vec<Cow<'a, Mesh>>,
    },
    Layers {
        handle: u64,
        meshes: Vec<Cow<'a, Mesh>>,
        info: Cow<'a, RunInfo>,
        sequence: Option<Cow<'a, Sequence>>,
    },
    /// Prepares a mesh for slicing; replies with the handle of the prepared mesh.
    Prepare {
        handle: u64,
        mesh: Cow<'a, Mesh>,
    },
    Slice {
        handle: u64,
        slot: LayerSlot,
    },
    Sort {
        handle: u64,
        layer: Cow<'a, Layer>,
    },
    /// Discretises the families `families` of one part's layer; replies with their
    /// regions, a list per family.
    Discretise {
        handle: u64,
        family: WireFamily<'a>,
        families: Cow<'a, [usize]>,
    },
    Grades {
        handle: u64,
    },
    /// Asks a discretiser or grader whether it reads the part's mesh.
    ReadsMesh {
        handle: u64,
    },
    /// Asks a grader whether it reads contours and polygons.
    ReadsGeometry {
        handle: u64,
    },
    /// Grades the regions of the families `families` of one part's layer
    /// (`regions[i]` those of `families[i]`); replies with them graded, without their
    /// polygons: the host keeps its own and takes the compositions and samples.
    Grade {
        handle: u64,
        family: WireFamily<'a>,
        families: Cow<'a, [usize]>,
        regions: Cow<'a, [Vec<SubRegion>]>,
    },
    Sequence {
        handle: u64,
        info: Cow<'a, RunInfo>,
    },
    Plan {
        handle: u64,
        info: Cow<'a, RunInfo>,
        plan: Cow<'a, LayerPlan>,
    },
    /// Asks a sequencer whether it needs the parts' gradients along z.
    NeedsGradients {
        handle: u64,
    },
    /// Asks a process stage whether it needs the higher regions' outlines.
    NeedsHigher {
        handle: u64,
    },
    /// Plans a process stage's operations on a layer; replies with the plan.
    Process {
        handle: u64,
        info: Cow<'a, RunInfo>,
        context: WireProcess<'a>,
        plan: Cow<'a, LayerPlan>,
    },
    /// Opens an exporter's output; replies with the handle of its layer sink.
    Open {
        handle: u64,
        export: WireExport<'a>,
    },
    Layer {
        handle: u64,
        info: Cow<'a, RunInfo>,
        plan: Cow<'a, LayerPlan>,
    },
    /// Completes a layer sink's output; the sink is released with it.
    Finish {
        handle: u64,
        info: Cow<'a, RunInfo>,
    },
    /// (ABI 7.2) [`Request::Grade`] for a grader that reads no geometry: each region
    /// as its facts, the family's layer without contours. Replies with
    /// [`Response::Graded`].
    GradeFacts {
        handle: u64,
        family: WireFamily<'a>,
        families: Cow<'a, [usize]>,
        regions: Vec<Vec<RegionFacts>>,
    },
    /// (ABI 7.4) Asks a discretiser or grader whether it reads the run's machine:
    /// the run is sent without it to those that do not. Older plugins are not asked,
    /// and are sent it.
    ReadsMachine {
        handle: u64,
    },
}

/// (ABI 7.2) What a grader that reads no geometry knows of a sub-region: all but its
/// polygon and family (the request's list says that). A tuple on the wire: graders
/// are sent thousands of these a layer, and field names would be most of the bytes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RegionFacts(
    /// [`SubRegion::index`]
    pub usize,
    /// [`SubRegion::count`]
    pub usize,
    /// [`SubRegion::level`]
    pub f64,
    /// [`SubRegion::cell`]
    pub Option<usize>,
    /// [`SubRegion::reference`]
    pub crate::geom::Point2,
    /// [`SubRegion::composition`]
    pub Option<Composition>,
    /// [`SubRegion::samples`]
    pub Vec<Sample>,
);

impl RegionFacts {
    pub fn of(r: &SubRegion) -> Self {
        Self(
            r.index,
            r.count,
            r.level,
            r.cell,
            r.reference,
            r.composition.clone(),
            r.samples.clone(),
        )
    }

    /// The region of family `family` these are the facts of, without a polygon.
    pub fn region(self, family: usize) -> SubRegion {
        SubRegion {
            family,
            index: self.0,
            count: self.1,
            level: self.2,
            polygon: Default::default(),
            cell: self.3,
            reference: self.4,
            composition: self.5,
            samples: self.6,
        }
    }
}

/// (ABI 7.2) What grading gave a sub-region: its composition and samples.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Graded(pub Option<Composition>, pub Vec<Sample>);

impl Graded {
    /// What grading set in each region of `sets`, a list per family as they came.
    pub fn of_sets(sets: Vec<Vec<SubRegion>>) -> Vec<Vec<Graded>> {
        sets.into_iter()
            .map(|set| {
                set.into_iter()
                    .map(|r| Graded(r.composition, r.samples))
                    .collect()
            })
            .collect()
    }
}

/// A plugin's answer to a [`Request`].
#[derive(Debug, Serialize, Deserialize)]
pub enum Response {
    Stages(Vec<WireStage>),
    Handle(u64),
    Meshes(Vec<WireMesh>),
    Orientation(Orientation),
    Slots(Vec<LayerSlot>),
    Layer(Layer),
    Tree(ContourTree),
    /// Regions, a list per family asked for.
    RegionSets(Vec<Vec<SubRegion>>),
    Bool(bool),
    Sequence(Sequence),
    /// What a planner or a process stage added to the layer it was sent.
    Planned(crate::planned::PlanDelta),
    Done,
    /// (ABI 7.2) The answer to [`Request::Grade`] and [`Request::GradeFacts`]: what
    /// grading set in each region, a list per family asked for, in order.
    Graded(Vec<Vec<Graded>>),
}

/// What a plugin writes back for every request.
pub type Reply = Result<Response, WireError>;

/// A call of a plugin into the host, made during a [`Request`].
#[derive(Debug, Serialize, Deserialize)]
pub enum HostRequest<'a> {
    /// Compiles a script reference (`"expression"` or `"file.rhai#function"`) with the
    /// host's engine; replies with the script's number.
    Compile {
        spec: Cow<'a, str>,
        origin: Option<WireLocation>,
    },
    /// Runs a script for one number, within the host's limits.
    Number {
        script: u64,
        args: WireArgs<'a>,
        context: Cow<'a, str>,
    },
    /// Runs a script for the fractions of `n` materials, within the host's limits.
    Fractions {
        script: u64,
        args: WireArgs<'a>,
        n: usize,
        context: Cow<'a, str>,
    },
    /// Runs a script for the fractions of `n` materials once for each of `calls` (its
    /// values and what is being computed), in order, stopping at the first error.
    FractionsEach {
        script: u64,
        calls: Vec<(WireArgs<'a>, Cow<'a, str>)>,
        n: usize,
    },
    /// Creates an output file (a name relative to the output folder); replies with
    /// the file's number.
    Create {
        name: Cow<'a, Path>,
    },
    Write {
        file: u64,
        bytes: Cow<'a, serde_bytes::Bytes>,
    },
    Flush {
        file: u64,
    },
    Close {
        file: u64,
    },
    /// (ABI 7.2) [`HostRequest::FractionsEach`] without the contexts: replies with
    /// [`HostResponse::FractionSets`], or with [`HostResponse::FailedAt`] naming the
    /// call that failed, for the plugin to describe.
    FractionsBatch {
        script: u64,
        /// The parts' names the calls refer to.
        parts: Vec<Cow<'a, str>>,
        calls: Vec<WireCall>,
        n: usize,
    },
    /// (ABI 7.5) What an exporter tells the user about an output file
    /// ([`crate::stage::OutputFiles::tell`]); replies with [`HostResponse::Done`].
    Tell {
        file: Cow<'a, Path>,
        severity: crate::diagnostic::Severity,
        said: crate::diagnostic::Warning,
    },
    /// (ABI 7.5) What a machine file says of itself, for the run's summary
    /// ([`crate::stage::OutputFiles::report`]); replies with [`HostResponse::Done`].
    Report(crate::stage::MachineFileReport),
}

/// (ABI 7.2) One call of a [`HostRequest::FractionsBatch`]: `r`, `d`, `x`, `y`, `z`,
/// `layer` and the number of its part in the request's list.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct WireCall(pub f64, pub f64, pub f64, pub f64, pub f64, pub i64, pub usize);

/// The host's answer to a [`HostRequest`].
#[derive(Debug, Serialize, Deserialize)]
pub enum HostResponse {
    Script(u64),
    /// The fractions of each call of a [`HostRequest::FractionsEach`].
    FractionSets(Vec<Vec<f64>>),
    Number(f64),
    Fractions(Vec<f64>),
    File(u64),
    Done,
    /// (ABI 7.2) Call `index` of a [`HostRequest::FractionsBatch`] failed with `error`.
    FailedAt {
        index: usize,
        error: WireError,
    },
}

/// What the host writes back for every host request.
pub type HostReply = Result<HostResponse, WireError>;

/// A stage's self-description.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WireStage {
    pub kind: StageKind,
    pub name: String,
    pub doc: String,
    pub options: Vec<WireOption>,
    pub example: String,
}

/// One option of a [`WireStage`].
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WireOption {
    pub name: String,
    pub ty: String,
    pub default: Option<String>,
    pub doc: String,
    pub required: bool,
    /// The physical range of its numbers (ABI 7.1; absent from older plugins).
    #[serde(default)]
    pub range: Option<(f64, f64)>,
}

/// A mesh a model stage made, with what its reader repaired.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireMesh {
    pub mesh: Mesh,
    pub warnings: Vec<crate::diagnostic::Warning>,
}

/// A stage's configuration: its table (as the file has it and as overrides left it),
/// the pipeline's folder, machine and limits.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireConfig<'a> {
    pub table: WireTable<'a>,
    pub base_dir: Cow<'a, Path>,
    pub reach: Cow<'a, crate::reach::Reach>,
    pub machine: Option<Cow<'a, Machine>>,
    pub limits: Limits,
}

/// A stage's table: the file it is in (so that errors point into it), its path in the
/// file and its values after `--set` overrides, as TOML text.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireTable<'a> {
    pub file: WireFile<'a>,
    pub path: Vec<WireStep>,
    pub values: String,
    pub overridden: bool,
    pub host_keys: Vec<String>,
}

/// A user's file: its path and text.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireFile<'a> {
    pub path: Cow<'a, Path>,
    pub text: Cow<'a, str>,
}

/// One step of a table's path in its file.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum WireStep {
    Key(String),
    Index(usize),
}

/// What a discretiser or grader knows about the families of a part's layer. The mesh
/// travels once per stage, and only to a stage that reads it: later requests name it by
/// `id` only.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireFamily<'a> {
    pub info: Cow<'a, RunInfo>,
    pub layer: Cow<'a, Layer>,
    pub tree: Cow<'a, ContourTree>,
    pub mesh: Option<MeshRef<'a>>,
    pub part: usize,
}

/// A mesh named by a number, with its data the first time the stage sees it.
#[derive(Debug, Serialize, Deserialize)]
pub struct MeshRef<'a> {
    pub id: u64,
    pub mesh: Option<Cow<'a, Mesh>>,
}

/// What a process stage knows about its layer, besides the run.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireProcess<'a> {
    pub sequence: Option<Cow<'a, Sequence>>,
    pub surfaces: Cow<'a, [Option<f64>]>,
    pub higher: Cow<'a, [crate::process::RegionOutline]>,
    pub last: bool,
}

/// What an exporter knows when it opens its output.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireExport<'a> {
    pub info: Cow<'a, RunInfo>,
    pub sequence: Option<Cow<'a, Sequence>>,
    pub orientation: Option<Cow<'a, Orientation>>,
    pub layer_count: usize,
    pub pipeline_name: Cow<'a, str>,
}

/// The values a script call receives.
#[derive(Debug, Serialize, Deserialize)]
pub struct WireArgs<'a> {
    pub r: f64,
    pub d: f64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub layer: i64,
    pub part: Cow<'a, str>,
}

impl<'a> From<&crate::script::ScriptArgs<'a>> for WireArgs<'a> {
    fn from(a: &crate::script::ScriptArgs<'a>) -> Self {
        Self {
            r: a.r,
            d: a.d,
            x: a.x,
            y: a.y,
            z: a.z,
            layer: a.layer,
            part: Cow::Borrowed(a.part),
        }
    }
}

impl WireArgs<'_> {
    pub fn args(&self) -> crate::script::ScriptArgs<'_> {
        crate::script::ScriptArgs {
            r: self.r,
            d: self.d,
            x: self.x,
            y: self.y,
            z: self.z,
            layer: self.layer,
            part: &self.part,
        }
    }
}

/// Encodes a message.
pub fn encode<T: Serialize + ?Sized>(message: &T) -> Result<Vec<u8>, String> {
    rmp_serde::to_vec_named(message).map_err(|e| format!("cannot encode a message: {e}"))
}

/// Deepest nesting a message may have: the deepest message (a layer's plan) nests about
/// ten levels; a peer's bytes nested deeper are refused before they can exhaust the
/// stack.
pub const MAX_DEPTH: usize = 64;

/// Decodes a message from the other side, which may be anything.
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    let mut de = rmp_serde::Deserializer::from_read_ref(bytes);
    de.set_max_depth(MAX_DEPTH);
    T::deserialize(&mut de).map_err(|e| format!("malformed message: {e}"))
}

/// A file's path and text as a [`WireFile`].
pub fn file_of(file: &Arc<SourceFile>) -> WireFile<'_> {
    WireFile {
        path: Cow::Borrowed(&file.path),
        text: Cow::Borrowed(&file.text),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;
    use crate::limits::Limit;
    use crate::source::Location;

    /// Hostile replies are refused, not followed: errors nested past the depth limit,
    /// lengths past the end, truncations.
    #[test]
    fn malformed_messages_are_errors() {
        let mut e = WireError::Composition("x".into());
        for i in 0..(MAX_DEPTH + 10) {
            e = WireError::Layer {
                index: i,
                z: 0.0,
                source: Box::new(e),
            };
        }
        let deep: Reply = Err(e);
        let bytes = encode(&deep).expect("encodes");
        assert!(
            decode::<Reply>(&bytes)
                .expect_err("too deep")
                .contains("malformed")
        );
        let fine: Reply = Ok(Response::RegionSets(Vec::new()));
        let bytes = encode(&fine).expect("encodes");
        for cut in 0..bytes.len() {
            assert!(decode::<Reply>(&bytes[..cut]).is_err(), "{cut}");
        }
        // An array that claims four billion entries, with none there.
        assert!(decode::<Vec<f64>>(&[0xdd, 0xff, 0xff, 0xff, 0xff]).is_err());
    }

    /// An error keeps its kind, place and text across the boundary.
    #[test]
    fn errors_read_back_with_their_place() {
        let file = SourceFile::new("p.toml", "[grade]\nf = \"x\"\n");
        let e = Error::config_at(Location::new(file, 8..9), "bad").in_layer(3, 1.5);
        let back = Error::from(
            decode::<WireError>(&encode(&WireError::from(&e)).expect("encodes")).expect("decodes"),
        );
        assert_eq!(back.to_string(), e.to_string());
        assert!(back.is_usage());
        let limit = Limits::default()
            .check(Limit::Regions, 1e9, "the offsets")
            .expect_err("over");
        let back = Error::from(
            decode::<WireError>(&encode(&WireError::from(&limit)).expect("encodes")).expect("decodes"),
        );
        assert_eq!(back.to_string(), limit.to_string());
    }

    /// A sample of every direction's messages reads back as it was written. With
    /// `LAMINA_FUZZ_CORPUS` set to a folder, they are written there as the seeds of the
    /// `plugin_messages` fuzz target (fuzz/make-corpus.sh).
    #[test]
    fn sample_messages_read_back() {
        use crate::geom::{Contour, Point2, Polygon};
        let square = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(0.0, 1.0),
        ]);
        let layer = Layer {
            index: 2,
            z: 0.75,
            thickness: 0.25,
            contours: vec![square.clone()],
            warnings: Vec::new(),
            section_area: None,
        };
        let region = SubRegion {
            family: 0,
            index: 0,
            count: 1,
            level: 0.5,
            polygon: Polygon::new(square, Vec::new()),
            cell: None,
            reference: Point2::new(0.5, 0.5),
            composition: Some(Composition::binary(0.25).expect("fractions")),
            samples: Vec::new(),
        };
        let file = SourceFile::new("p.toml", "[grade]\nf = \"x\"\n");
        let samples: Vec<(&str, Vec<u8>)> = vec![
            ("describe", encode(&Request::Describe).expect("encodes")),
            (
                "sort",
                encode(&Request::Sort {
                    handle: 3,
                    layer: Cow::Borrowed(&layer),
                })
                .expect("encodes"),
            ),
            (
                "regions",
                encode(&Ok::<_, WireError>(Response::RegionSets(vec![vec![region]]))).expect("encodes"),
            ),
            (
                "error",
                encode(&Err::<Response, _>(WireError::from(
                    &Error::config_at(Location::new(file, 8..9), "bad").in_layer(2, 0.75),
                )))
                .expect("encodes"),
            ),
            (
                "fractions",
                encode(&HostRequest::Fractions {
                    script: 0,
                    args: WireArgs {
                        r: 0.5,
                        d: 0.0,
                        x: 1.0,
                        y: 2.0,
                        z: 0.75,
                        layer: 2,
                        part: Cow::Borrowed("part"),
                    },
                    n: 2,
                    context: Cow::Borrowed("region 0"),
                })
                .expect("encodes"),
            ),
            (
                "host-reply",
                encode(&Ok::<_, WireError>(HostResponse::Fractions(vec![0.25, 0.75]))).expect("encodes"),
            ),
        ];
        for (name, bytes) in &samples {
            let again = match *name {
                "describe" | "sort" => encode(&decode::<Request<'static>>(bytes).expect("decodes")),
                "regions" | "error" => encode(&decode::<Reply>(bytes).expect("decodes")),
                "fractions" => encode(&decode::<HostRequest<'static>>(bytes).expect("decodes")),
                _ => encode(&decode::<HostReply>(bytes).expect("decodes")),
            };
            assert_eq!(&again.expect("encodes"), bytes, "{name}");
        }
        if let Some(dir) = std::env::var_os("LAMINA_FUZZ_CORPUS") {
            let dir = std::path::PathBuf::from(dir);
            std::fs::create_dir_all(&dir).expect("corpus folder");
            for (name, bytes) in samples {
                std::fs::write(dir.join(name), bytes).expect("seed");
            }
        }
    }
}
