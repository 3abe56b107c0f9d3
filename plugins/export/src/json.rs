//! `json`: the whole plan as one JSON document, or as JSON Lines (one header line, then
//! one line per layer) for tools that stream. The schema is documented in
//! docs/formats.md; it is what tools built on Lamina read.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{Contour, Error, LayerPlan, Polygon, Result, RunInfo, StageFactory, Toolpath};
use serde::{Deserialize, Serialize};

/// Version of the JSON schema; bumped on incompatible changes. 2: a family's
/// sub-regions are `sub_regions` and a toolpath's is `sub_region` (`region` is only ever
/// a sequence region), toolpaths name the material their tool carries, and diagnostics
/// their code.
pub const SCHEMA_VERSION: u32 = 2;

lamina_api::option_type!(Form = "string");

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Form {
    Document,
    Lines,
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// output file, relative to the output folder
        path: PathBuf = r#""plan.json""#,
        /// "document" (one JSON value) or "lines" (JSON Lines: header, then one line per layer)
        form: Form = r#""document""#,
        /// indent the document
        pretty: bool = "false",
        /// include planned toolpaths
        toolpaths: bool = "true",
    }
}

#[derive(Serialize)]
struct Header<'a> {
    lamina: &'a str,
    schema: u32,
    pipeline: &'a str,
    layer_count: usize,
    materials: &'a [lamina_api::Material],
    parts: Vec<PartHeader<'a>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sequence: Option<&'a lamina_api::Sequence>,
    #[serde(skip_serializing_if = "Option::is_none")]
    orientation: Option<&'a lamina_api::Orientation>,
}

#[derive(Serialize)]
struct PartHeader<'a> {
    name: &'a str,
    materials: Vec<&'a str>,
    z_min: f64,
    z_max: f64,
}

#[derive(Serialize)]
struct LayerOut<'a> {
    index: usize,
    z: f64,
    thickness: f64,
    /// Index into `sequence.regions` of the material region this layer deposits.
    #[serde(skip_serializing_if = "Option::is_none")]
    region: Option<usize>,
    parts: Vec<PartOut<'a>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    toolpaths: Option<Vec<ToolpathOut<'a>>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    build_time: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sequential_time: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pauses: Option<lamina_api::Pauses>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fill: Option<lamina_api::Fill>,
    #[serde(skip_serializing_if = "<[lamina_api::Operation]>::is_empty")]
    operations: &'a [lamina_api::Operation],
    #[serde(skip_serializing_if = "<[lamina_api::Diagnostic]>::is_empty")]
    diagnostics: &'a [lamina_api::Diagnostic],
}

#[derive(Serialize)]
struct PartOut<'a> {
    part: &'a str,
    families: Vec<FamilyOut<'a>>,
}

#[derive(Serialize)]
struct FamilyOut<'a> {
    /// Level of the outer contour in the layer's hierarchy.
    level: usize,
    outer: &'a Contour,
    holes: Vec<&'a Contour>,
    area: f64,
    sub_regions: Vec<RegionOut<'a>>,
}

/// A toolpath as files write it: the wire's `region` is `sub_region` here.
#[derive(Serialize)]
struct ToolpathOut<'a> {
    tool: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    material: Option<usize>,
    kind: lamina_api::PathKind,
    points: &'a [lamina_api::TimedPoint],
    width: f64,
    #[serde(skip_serializing_if = "<[f64]>::is_empty")]
    widths: &'a [f64],
    #[serde(skip_serializing_if = "Option::is_none")]
    composition: Option<&'a lamina_api::Composition>,
    #[serde(skip_serializing_if = "Option::is_none")]
    part: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sub_region: Option<usize>,
}

impl<'a> From<&'a Toolpath> for ToolpathOut<'a> {
    fn from(t: &'a Toolpath) -> Self {
        ToolpathOut {
            tool: t.tool,
            material: t.material,
            kind: t.kind,
            points: &t.points,
            width: t.width,
            widths: &t.widths,
            composition: t.composition.as_ref(),
            part: t.part,
            sub_region: t.sub_region,
        }
    }
}

#[derive(Serialize)]
struct RegionOut<'a> {
    index: usize,
    count: usize,
    level: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    cell: Option<usize>,
    reference: [f64; 2],
    polygon: &'a Polygon,
    area: f64,
    composition: BTreeMap<&'a str, f64>,
    colour: [u8; 3],
}

fn layer_out<'a>(info: &'a RunInfo, plan: &'a LayerPlan, toolpaths: bool) -> LayerOut<'a> {
    let parts = plan
        .parts
        .iter()
        .map(|pl| {
            let part = &info.parts[pl.part];
            let materials = info.part_materials(pl.part);
            let families = pl
                .families
                .iter()
                .map(|&f| {
                    let fam = &pl.tree.families[f];
                    let regions = pl
                        .regions
                        .iter()
                        .filter(|r| r.family == f)
                        .map(|r| {
                            let composition = r
                                .composition
                                .as_ref()
                                .map(|c| {
                                    part.materials
                                        .iter()
                                        .zip(&c.fractions)
                                        .map(|(&m, &x)| (info.materials[m].name.as_str(), x))
                                        .collect()
                                })
                                .unwrap_or_default();
                            RegionOut {
                                index: r.index,
                                count: r.count,
                                level: r.level,
                                cell: r.cell,
                                reference: [r.reference.x, r.reference.y],
                                polygon: &r.polygon,
                                area: r.area(),
                                composition,
                                colour: r.composition.as_ref().map_or([0; 3], |c| c.colour(&materials)),
                            }
                        })
                        .collect();
                    FamilyOut {
                        level: pl.tree.nodes[fam.outer].level,
                        outer: &pl.contours[fam.outer],
                        holes: fam.holes.iter().map(|&h| &pl.contours[h]).collect(),
                        area: pl.tree.family_area(&pl.contours, f),
                        sub_regions: regions,
                    }
                })
                .collect();
            PartOut {
                part: &part.name,
                families,
            }
        })
        .collect();
    LayerOut {
        index: plan.index,
        z: plan.z,
        thickness: plan.thickness,
        region: plan.material_region,
        parts,
        toolpaths: (toolpaths && !plan.toolpaths.is_empty())
            .then(|| plan.toolpaths.iter().map(ToolpathOut::from).collect()),
        build_time: plan.build_time,
        sequential_time: plan.sequential_time,
        pauses: plan.pauses,
        fill: plan.fill,
        operations: &plan.operations,
        diagnostics: &plan.diagnostics,
    }
}

struct Json {
    options: Options,
}

struct Sink {
    out: Box<dyn Write + Send>,
    path: PathBuf,
    form: Form,
    pretty: bool,
    toolpaths: bool,
    first: bool,
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

fn json_err(path: &std::path::Path) -> impl Fn(serde_json::Error) -> Error + '_ {
    move |e| Error::io(path, std::io::Error::other(e))
}

impl Exporter for Json {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let mut out = ctx.files.create(&self.options.path)?;
        let header = Header {
            lamina: lamina_api::VERSION,
            schema: SCHEMA_VERSION,
            pipeline: ctx.pipeline_name,
            layer_count: ctx.layer_count,
            materials: &ctx.info.materials,
            parts: ctx
                .info
                .parts
                .iter()
                .map(|p| PartHeader {
                    name: &p.name,
                    materials: p
                        .materials
                        .iter()
                        .map(|&m| ctx.info.materials[m].name.as_str())
                        .collect(),
                    z_min: p.z_min,
                    z_max: p.z_max,
                })
                .collect(),
            sequence: ctx.sequence,
            orientation: ctx.orientation,
        };
        let path = self.options.path.clone();
        let text = if self.options.pretty && self.options.form == Form::Document {
            serde_json::to_string_pretty(&header)
        } else {
            serde_json::to_string(&header)
        }
        .map_err(json_err(&path))?;
        match self.options.form {
            Form::Document => {
                // The header's fields, then the layers array, streamed.
                let body = text.strip_suffix('}').unwrap_or(&text);
                write!(out, "{body},\"layers\":[").map_err(io(&path))?;
            }
            Form::Lines => writeln!(out, "{text}").map_err(io(&path))?,
        }
        Ok(Box::new(Sink {
            out,
            path,
            form: self.options.form,
            pretty: self.options.pretty,
            toolpaths: self.options.toolpaths,
            first: true,
        }))
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        let layer = layer_out(info, plan, self.toolpaths);
        let path = self.path.clone();
        match self.form {
            Form::Document => {
                if !self.first {
                    self.out.write_all(b",").map_err(io(&path))?;
                }
                if self.pretty {
                    self.out.write_all(b"\n").map_err(io(&path))?;
                    serde_json::to_writer_pretty(&mut self.out, &layer).map_err(json_err(&path))?;
                } else {
                    serde_json::to_writer(&mut self.out, &layer).map_err(json_err(&path))?;
                }
            }
            Form::Lines => {
                serde_json::to_writer(&mut self.out, &layer).map_err(json_err(&path))?;
                self.out.write_all(b"\n").map_err(io(&path))?;
            }
        }
        self.first = false;
        Ok(())
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, _files: &mut dyn OutputFiles) -> Result<()> {
        let path = self.path.clone();
        if self.form == Form::Document {
            self.out.write_all(b"]}\n").map_err(io(&path))?;
        }
        self.out.flush().map_err(io(&path))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    Ok(AnyStage::Export(Box::new(Json { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "json",
        doc: "The plan as JSON: materials, parts, sequence, and per layer the families, sub-regions with compositions and colours, and toolpaths.",
        options: Options::SPECS,
        example: "use = \"json\"\npath = \"plan.json\"",
    },
    build,
});
