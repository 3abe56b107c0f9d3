//! Proxies for a plugin's stages, prepared meshes and open outputs: every trait call
//! becomes a request to the library, and its reply the call's result.

use std::borrow::Cow;
use std::collections::HashSet;
use std::io::Write;
use std::path::Path;
use std::sync::{Arc, Mutex};

use super::super::wire::*;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::model::*;
use crate::stage::*;

use super::*;

/// A stage (or prepared mesh, or open output) living in a plugin.
struct Remote {
    library: Arc<Library>,
    handle: u64,
    label: Arc<str>,
    scripts: Arc<ScriptTable>,
    files: Arc<FileTable>,
    /// For a discretiser: whether its regions come graded (asked once, when built).
    grades: bool,
    /// For a discretiser or grader: whether it reads the part's mesh (asked once, when
    /// built); the mesh is sent to those only.
    reads_mesh: bool,
    /// For a grader: whether it reads contours and polygons (asked once, when built);
    /// those that do not are sent neither.
    reads_geometry: bool,
    /// For a discretiser or grader: whether it reads the run's machine (asked once,
    /// when built, of plugins of ABI 7.4 on; older ones are sent it, as they always
    /// were).
    reads_machine: bool,
    /// For a process stage: whether it needs the higher regions (asked once, when built);
    /// for a sequencer, whether it needs the parts' gradients.
    needs_higher: bool,
    /// Meshes the plugin has been sent, by address: a run's meshes stay where they are
    /// for as long as its stages live.
    meshes_sent: Mutex<HashSet<usize>>,
}

impl Drop for Remote {
    fn drop(&mut self) {
        self.library.release_raw(self.handle);
    }
}

impl Remote {
    fn request(&self, request: &Request<'_>) -> Result<Response> {
        self.request_with(request, None)
    }

    fn request_with(&self, request: &Request<'_>, files: Option<&mut dyn OutputFiles>) -> Result<Response> {
        let ctx = HostCtx::new(&self.scripts, &self.files, files);
        self.library.request(&self.label, request, &ctx)
    }

    fn unexpected(&self, r: &Response) -> Error {
        Error::stage(
            self.label.to_string(),
            format!("the plugin answered {}", name_of(r)),
        )
    }

    /// The stage's answer to a yes-or-no question about itself.
    fn ask(&self, question: Request<'_>) -> Result<bool> {
        match self.request(&question)? {
            Response::Bool(b) => Ok(b),
            other => Err(self.unexpected(&other)),
        }
    }

    /// A reply that holds `got` of what `asked` were sent for.
    fn miscounted(&self, what: &str, got: usize, asked: usize, of: &str) -> Error {
        Error::stage(
            self.label.to_string(),
            format!("{what} {got} {of}, it was given {asked}"),
        )
    }

    /// Another object of the same plugin stage (a prepared mesh, an open output).
    fn child(&self, handle: u64) -> Remote {
        Remote {
            library: self.library.clone(),
            handle,
            label: self.label.clone(),
            scripts: self.scripts.clone(),
            files: self.files.clone(),
            grades: false,
            reads_mesh: false,
            reads_geometry: true,
            reads_machine: false,
            needs_higher: false,
            meshes_sent: Mutex::new(HashSet::new()),
        }
    }

    fn family<'a>(&self, ctx: &'a FamilyContext<'a>) -> (WireFamily<'a>, Option<usize>) {
        let mut sent = None;
        let mesh = ctx.mesh.map(|m| {
            let address = std::ptr::from_ref(m) as usize;
            let known = self
                .meshes_sent
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .contains(&address);
            if !known {
                sent = Some(address);
            }
            MeshRef {
                id: address as u64,
                mesh: (!known).then_some(Cow::Borrowed(m)),
            }
        });
        (
            WireFamily {
                info: Cow::Borrowed(ctx.info),
                layer: Cow::Borrowed(ctx.layer),
                tree: Cow::Borrowed(ctx.tree),
                mesh,
                part: ctx.part,
            },
            sent,
        )
    }

    /// Remembers that the plugin holds a mesh, once a request carrying it succeeded.
    fn mesh_sent(&self, address: Option<usize>) {
        if let Some(a) = address {
            self.meshes_sent
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .insert(a);
        }
    }
}

/// Builds a dynamic plugin's stage: the plugin builds it from the stage's
/// configuration and keeps it; the host gets a proxy.
pub(crate) fn build(
    remote: &RemoteFactory,
    kind: StageKind,
    label: &str,
    config: &StageConfig<'_>,
) -> Result<AnyStage> {
    let scripts = Arc::new(ScriptTable::new(Some(config.scripts.clone())));
    let files = Arc::new(FileTable::default());
    let request = Request::Build {
        stage: remote.index,
        label: Cow::Borrowed(label),
        config: WireConfig {
            table: config.table.to_wire()?,
            base_dir: Cow::Borrowed(config.base_dir),
            reach: Cow::Borrowed(config.reach),
            machine: config.machine.map(Cow::Borrowed),
            limits: config.limits,
        },
    };
    let handle = match remote
        .library
        .request(label, &request, &HostCtx::new(&scripts, &files, None))?
    {
        Response::Handle(h) => h,
        other => {
            return Err(Error::stage(
                label.to_string(),
                format!("the plugin answered {}", name_of(&other)),
            ));
        }
    };
    let mut stage = Remote {
        library: remote.library.clone(),
        handle,
        label: label.into(),
        scripts,
        files,
        grades: false,
        reads_mesh: false,
        reads_geometry: true,
        reads_machine: false,
        needs_higher: false,
        meshes_sent: Mutex::new(HashSet::new()),
    };
    // What the stage says about itself once, when built.
    if matches!(kind, StageKind::Discretise | StageKind::Grade) {
        stage.reads_mesh = stage.ask(Request::ReadsMesh { handle })?;
        stage.reads_machine = stage.library.minor < 4 || stage.ask(Request::ReadsMachine { handle })?;
    }
    match kind {
        StageKind::Grade => stage.reads_geometry = stage.ask(Request::ReadsGeometry { handle })?,
        StageKind::Discretise => stage.grades = stage.ask(Request::Grades { handle })?,
        StageKind::Sequence => stage.needs_higher = stage.ask(Request::NeedsGradients { handle })?,
        StageKind::Process => stage.needs_higher = stage.ask(Request::NeedsHigher { handle })?,
        _ => {}
    }
    let b = Box::new(stage);
    Ok(match kind {
        StageKind::Model => AnyStage::Model(b),
        StageKind::Orient => AnyStage::Orient(b),
        StageKind::Slice => AnyStage::Slice(b),
        StageKind::Sort => AnyStage::Sort(b),
        StageKind::Discretise => AnyStage::Discretise(b),
        StageKind::Grade => AnyStage::Grade(b),
        StageKind::Sequence => AnyStage::Sequence(b),
        StageKind::Plan => AnyStage::Plan(b),
        StageKind::Process => AnyStage::Process(b),
        StageKind::Export => AnyStage::Export(b),
    })
}

impl ModelSource for Remote {
    fn load(&self, base_dir: &Path) -> Result<Vec<Mesh>> {
        match self.request(&Request::Load {
            handle: self.handle,
            base_dir: Cow::Borrowed(base_dir),
        })? {
            Response::Meshes(meshes) => Ok(meshes
                .into_iter()
                .map(|w| Mesh {
                    warnings: w.warnings,
                    ..w.mesh
                })
                .collect()),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Orienter for Remote {
    fn orient(&self, meshes: &[&Mesh]) -> Result<Orientation> {
        match self.request(&Request::Orient {
            handle: self.handle,
            meshes: meshes.iter().map(|m| Cow::Borrowed(*m)).collect(),
        })? {
            Response::Orientation(o) => Ok(o),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Slicer for Remote {
    fn layers(
        &self,
        meshes: &[Arc<Mesh>],
        info: &RunInfo,
        sequence: Option<&Sequence>,
    ) -> Result<Vec<LayerSlot>> {
        match self.request(&Request::Layers {
            handle: self.handle,
            meshes: meshes.iter().map(|m| Cow::Borrowed(&**m)).collect(),
            info: Cow::Borrowed(info),
            sequence: sequence.map(Cow::Borrowed),
        })? {
            Response::Slots(s) => Ok(s),
            other => Err(self.unexpected(&other)),
        }
    }

    fn prepare(&self, mesh: Arc<Mesh>) -> Result<Box<dyn MeshSlicer>> {
        match self.request(&Request::Prepare {
            handle: self.handle,
            mesh: Cow::Borrowed(&mesh),
        })? {
            Response::Handle(h) => Ok(Box::new(self.child(h))),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl MeshSlicer for Remote {
    fn slice(&self, slot: &LayerSlot) -> Result<Layer> {
        match self.request(&Request::Slice {
            handle: self.handle,
            slot: *slot,
        })? {
            Response::Layer(l) => Ok(l),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Sorter for Remote {
    fn sort(&self, layer: &Layer) -> Result<ContourTree> {
        match self.request(&Request::Sort {
            handle: self.handle,
            layer: Cow::Borrowed(layer),
        })? {
            Response::Tree(t) => Ok(t),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Discretiser for Remote {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>> {
        Ok(self
            .discretise_families(ctx, &[ctx.family])?
            .pop()
            .unwrap_or_default())
    }

    fn grades(&self) -> bool {
        self.grades
    }

    fn reads_mesh(&self) -> bool {
        self.reads_mesh
    }

    fn reads_machine(&self) -> bool {
        self.reads_machine
    }

    fn discretise_families(
        &self,
        ctx: &FamilyContext<'_>,
        families: &[usize],
    ) -> Result<Vec<Vec<SubRegion>>> {
        let (family, sent) = self.family(ctx);
        match self.request(&Request::Discretise {
            handle: self.handle,
            family,
            families: Cow::Borrowed(families),
        })? {
            Response::RegionSets(r) if r.len() == families.len() => {
                self.mesh_sent(sent);
                Ok(r)
            }
            Response::RegionSets(r) => {
                Err(self.miscounted("discretised", r.len(), families.len(), "families"))
            }
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Grader for Remote {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        let mut sets = vec![regions.to_vec()];
        self.grade_families(ctx, &[ctx.family], &mut sets)?;
        match sets.pop() {
            Some(graded) if graded.len() == regions.len() => {
                regions.clone_from_slice(&graded);
                Ok(())
            }
            _ => Err(self.miscounted("graded", 0, regions.len(), "regions")),
        }
    }

    fn reads_mesh(&self) -> bool {
        self.reads_mesh
    }

    fn reads_machine(&self) -> bool {
        self.reads_machine
    }

    fn reads_geometry(&self) -> bool {
        self.reads_geometry
    }

    fn grade_families(
        &self,
        ctx: &FamilyContext<'_>,
        families: &[usize],
        regions: &mut [Vec<SubRegion>],
    ) -> Result<()> {
        let (mut family, sent) = self.family(ctx);
        let request = if self.reads_geometry {
            Request::Grade {
                handle: self.handle,
                family,
                families: Cow::Borrowed(families),
                regions: Cow::Borrowed(&*regions),
            }
        } else {
            // A grader that reads no geometry is sent none: the layer's height, the
            // regions' levels and references.
            family.layer = Cow::Owned(Layer {
                index: ctx.layer.index,
                z: ctx.layer.z,
                thickness: ctx.layer.thickness,
                contours: Vec::new(),
                warnings: Vec::new(),
                section_area: None,
            });
            family.tree = Cow::Owned(ContourTree::default());
            if self.library.minor >= 2 {
                Request::GradeFacts {
                    handle: self.handle,
                    family,
                    families: Cow::Borrowed(families),
                    regions: regions
                        .iter()
                        .map(|set| set.iter().map(RegionFacts::of).collect())
                        .collect(),
                }
            } else {
                Request::Grade {
                    handle: self.handle,
                    family,
                    families: Cow::Borrowed(families),
                    regions: Cow::Owned(
                        regions
                            .iter()
                            .map(|set| set.iter().map(without_polygon).collect())
                            .collect(),
                    ),
                }
            }
        };
        let graded: Vec<Vec<Graded>> = match self.request(&request)? {
            Response::Graded(g) => g,
            // Plugins of ABI 7.0 and 7.1 send the regions back.
            Response::RegionSets(r) => Graded::of_sets(r),
            other => return Err(self.unexpected(&other)),
        };
        if graded.len() != regions.len() || graded.iter().zip(regions.iter()).any(|(a, b)| a.len() != b.len())
        {
            return Err(self.miscounted(
                "graded",
                graded.iter().map(Vec::len).sum(),
                regions.iter().map(Vec::len).sum(),
                "regions",
            ));
        }
        self.mesh_sent(sent);
        for (ours, Graded(composition, samples)) in
            regions.iter_mut().flatten().zip(graded.into_iter().flatten())
        {
            ours.composition = composition;
            ours.samples = samples;
        }
        Ok(())
    }
}

/// A region as a grader that reads no geometry sees it.
fn without_polygon(r: &SubRegion) -> SubRegion {
    SubRegion {
        polygon: crate::geom::Polygon::default(),
        composition: r.composition.clone(),
        samples: r.samples.clone(),
        ..*r
    }
}

impl Sequencer for Remote {
    fn sequence(&self, info: &RunInfo) -> Result<Sequence> {
        match self.request(&Request::Sequence {
            handle: self.handle,
            info: Cow::Borrowed(info),
        })? {
            Response::Sequence(s) => Ok(s),
            other => Err(self.unexpected(&other)),
        }
    }

    fn needs_gradients(&self) -> bool {
        self.needs_higher
    }
}

impl Planner for Remote {
    fn plan(&self, info: &RunInfo, plan: &mut LayerPlan) -> Result<()> {
        match self.request(&Request::Plan {
            handle: self.handle,
            info: Cow::Borrowed(info),
            plan: Cow::Borrowed(plan),
        })? {
            Response::Planned(delta) => {
                delta.apply(plan);
                Ok(())
            }
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Process for Remote {
    fn process(&self, ctx: &crate::process::ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        match self.request(&Request::Process {
            handle: self.handle,
            info: Cow::Borrowed(ctx.info),
            context: WireProcess {
                sequence: ctx.sequence.map(Cow::Borrowed),
                surfaces: Cow::Borrowed(ctx.surfaces),
                higher: Cow::Borrowed(ctx.higher),
                last: ctx.last,
            },
            plan: Cow::Borrowed(plan),
        })? {
            Response::Planned(delta) => {
                delta.apply(plan);
                Ok(())
            }
            other => Err(self.unexpected(&other)),
        }
    }

    fn needs_higher(&self) -> bool {
        self.needs_higher
    }
}

impl Exporter for Remote {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let request = Request::Open {
            handle: self.handle,
            export: WireExport {
                info: Cow::Borrowed(ctx.info),
                sequence: ctx.sequence.map(Cow::Borrowed),
                orientation: ctx.orientation.map(Cow::Borrowed),
                layer_count: ctx.layer_count,
                pipeline_name: Cow::Borrowed(ctx.pipeline_name),
            },
        };
        match self.request_with(&request, Some(&mut *ctx.files))? {
            Response::Handle(h) => Ok(Box::new(self.child(h))),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl LayerSink for Remote {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, files: &mut dyn OutputFiles) -> Result<()> {
        self.send_layer(info, plan, files)
    }

    fn finish(self: Box<Self>, info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        self.send_finish(info, files)
    }
}

impl Remote {
    fn send_layer(&self, info: &RunInfo, plan: &LayerPlan, files: &mut dyn OutputFiles) -> Result<()> {
        let request = Request::Layer {
            handle: self.handle,
            info: Cow::Borrowed(info),
            plan: Cow::Borrowed(plan),
        };
        match self.request_with(&request, Some(files))? {
            Response::Done => Ok(()),
            other => Err(self.unexpected(&other)),
        }
    }

    fn send_finish(&self, info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let request = Request::Finish {
            handle: self.handle,
            info: Cow::Borrowed(info),
        };
        match self.request_with(&request, Some(files))? {
            Response::Done => {
                let left = std::mem::take(&mut *self.files.open.lock().unwrap_or_else(|e| e.into_inner()));
                for (file, mut w) in left {
                    w.flush()
                        .map_err(|e| Error::io(format!("output file {file}"), e))?;
                }
                Ok(())
            }
            other => Err(self.unexpected(&other)),
        }
    }
}
