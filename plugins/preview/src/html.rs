//! `html`: one self-contained HTML file that shows the plan layer by layer: a slider, zoom
//! and pan, the composition of the region under the pointer, toggles for toolpaths and
//! tools, the machine's moves read back from the run's G-code (`moves`), the process
//! operations of each layer (listed, and their paths drawn), and a 3D view
//! (`assets/view3d.js`). The page needs no network: the viewer's script and style are
//! inside, and the layers are streamed into it as packed `<script>` blocks as they come
//! (`pack`), so memory stays flat and the page decodes only the layer it shows.

use std::io::Write;
use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{Contour, Error, LayerPlan, PathKind, Result, RunInfo, StageFactory};
use serde::Serialize;

use crate::draw::{MAX_LAYER, composition_text, escape, hex, round};
use crate::pack::Packer;

const VIEWER_JS: &str = include_str!("../assets/viewer.js");
const VIEW3D_JS: &str = include_str!("../assets/view3d.js");
const VIEWER_CSS: &str = include_str!("../assets/viewer.css");

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct Options {
        /// output file, relative to the output folder
        path: PathBuf = r#""viewer.html""#,
        /// keep every n-th layer (large models)
        #[range(1, MAX_LAYER)]
        every: usize = "1",
        /// decimals kept of the coordinates (mm): the grid the geometry is packed on
        #[range(0, 9)]
        digits: i32 = "2",
        /// include the planned toolpaths
        toolpaths: bool = "true",
        /// read back the G-code this run wrote and show the machine's moves, with a
        /// player (list this output after the `gcode` output)
        moves: bool = "true",
        /// the G-code output to read back (a path as given to its exporter); unset:
        /// the first `.gcode`, `.gco` or `.g` output written before this one (an `nc` file of a hybrid cell is not read unless named)
        gcode: Option<PathBuf>,
    }
}

struct Html {
    options: Options,
}

struct Sink {
    out: Box<dyn Write + Send>,
    path: PathBuf,
    options: Options,
    /// The outputs opened before this one: the only ones complete when it finishes
    /// (sinks finish in the order they were opened).
    earlier: Vec<PathBuf>,
}

#[derive(Serialize)]
struct Header<'a> {
    name: &'a str,
    layer_count: usize,
    materials: Vec<MaterialOut<'a>>,
    parts: Vec<PartOut<'a>>,
    /// The model's extent in X-Y (min x, min y, max x, max y), so the page can frame
    /// the view without reading every layer; `None` for an empty run.
    bounds: Option<[f64; 4]>,
    /// Decimals of the geometry grid (`pack`).
    digits: i32,
    /// The machine's tools, for the legend (empty without a machine).
    tools: Vec<ToolOut>,
}

#[derive(Serialize)]
struct ToolOut {
    index: usize,
    name: String,
}

#[derive(Serialize)]
struct MaterialOut<'a> {
    name: &'a str,
    colour: [u8; 3],
}

#[derive(Serialize)]
struct PartOut<'a> {
    name: &'a str,
    materials: Vec<&'a str>,
}

/// One layer: small data as JSON, geometry packed (`pack`), decoded by the page only
/// when the layer is shown.
#[derive(Serialize)]
struct LayerOut {
    i: usize,
    z: f64,
    t: f64,
    parts: Vec<PartLayerOut>,
    /// Tools with paths in this layer.
    tools: Vec<usize>,
    /// The toolpaths, packed.
    p: String,
    /// The process operations, in order, when `[[process]]` stages ran.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    ops: Vec<OpOut>,
    /// The operations' paths, packed: each path's head is its operation's index.
    #[serde(skip_serializing_if = "String::is_empty")]
    q: String,
}

/// One process operation of a layer.
#[derive(Serialize)]
struct OpOut {
    /// Kind, and pass when there is one (`grind/rough`).
    k: String,
    /// What it was planned with, as text.
    s: String,
    /// Number of packed paths.
    n: usize,
}

/// An operation's kind and pass as the viewer lists them.
fn op_label(op: &lamina_api::Operation) -> String {
    if op.pass.is_empty() {
        op.kind.clone()
    } else {
        format!("{}/{}", op.kind, op.pass)
    }
}

/// What an operation was planned with, in a line.
fn op_summary(op: &lamina_api::Operation) -> String {
    let mut s = Vec::new();
    if let Some(t) = &op.tool {
        s.push(format!("{} ({} mm)", t.name, round(t.diameter, 3)));
    }
    if let Some(h) = op.surface {
        s.push(format!("surface to {} mm", round(h, 4)));
    }
    for (k, v) in &op.values {
        s.push(format!("{k} {}", round(*v, 4)));
    }
    s.push(format!(
        "{} paths, {} mm",
        op.paths.len(),
        round(op.path_length(), 1)
    ));
    s.join(", ")
}

#[derive(Serialize)]
struct PartLayerOut {
    part: usize,
    /// How many of the packed rings are the part's contours (they come first).
    nc: usize,
    regions: Vec<RegionOut>,
    /// The contours, then each region's rings, packed.
    g: String,
}

#[derive(Serialize)]
struct RegionOut {
    /// Colour.
    c: String,
    /// Composition, as text.
    m: String,
    /// Level r.
    l: f64,
    /// Index.
    k: usize,
    /// Number of packed rings.
    n: usize,
}

fn xy(c: &Contour) -> Vec<[f64; 2]> {
    c.points.iter().map(|p| [p.x, p.y]).collect()
}

/// The legend's names of the machine's tools: "T0 left (pla)".
fn tools(info: &RunInfo) -> Vec<ToolOut> {
    let Some(machine) = &info.machine else {
        return Vec::new();
    };
    machine
        .tools
        .iter()
        .enumerate()
        .map(|(index, slot)| {
            let material = slot
                .material
                .clone()
                .or_else(|| info.materials.get(index).map(|m| m.name.clone()));
            let mut name = format!("T{index}");
            if let Some(head) = &slot.name {
                name = format!("{name} {head}");
            }
            if let Some(m) = material {
                name = format!("{name} ({m})");
            }
            ToolOut { index, name }
        })
        .collect()
}

/// JSON that may sit inside a `<script>` element: no `<`, `>` or `&` appears in it
/// (each is written as a `\u` escape, which only a JSON string can hold), so no name
/// can close the element or switch the HTML parser into another state (`<!--` then
/// `<script` would hide the closing tag).
fn script_json<T: Serialize>(v: &T) -> std::result::Result<String, serde_json::Error> {
    Ok(serde_json::to_string(v)?
        .replace('<', "\\u003c")
        .replace('>', "\\u003e")
        .replace('&', "\\u0026"))
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

impl Exporter for Html {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let path = self.options.path.clone();
        let earlier = ctx.files.written().into_iter().map(|(name, _)| name).collect();
        let mut out = ctx.files.create(&path)?;
        let header = Header {
            name: ctx.pipeline_name,
            layer_count: ctx.layer_count,
            materials: ctx
                .info
                .materials
                .iter()
                .map(|m| MaterialOut {
                    name: &m.name,
                    colour: m.colour,
                })
                .collect(),
            parts: ctx
                .info
                .parts
                .iter()
                .map(|p| PartOut {
                    name: &p.name,
                    materials: p
                        .materials
                        .iter()
                        .map(|&m| ctx.info.materials[m].name.as_str())
                        .collect(),
                })
                .collect(),
            bounds: (!ctx.info.xy_bounds.is_empty()).then(|| {
                let b = &ctx.info.xy_bounds;
                [b.min.x, b.min.y, b.max.x, b.max.y].map(|v| round(v, 3))
            }),
            digits: self.options.digits,
            tools: tools(ctx.info),
        };
        let header = script_json(&header).map_err(|e| Error::io(&path, std::io::Error::other(e)))?;
        let legend: String = ctx
            .info
            .materials
            .iter()
            .map(|m| {
                let [r, g, b] = m.colour;
                format!(
                    "<span><i style=\"display:inline-block;width:10px;height:10px;background:#{r:02x}{g:02x}{b:02x};border:1px solid #555\"></i> {}</span>",
                    escape(&m.name)
                )
            })
            .collect::<Vec<_>>()
            .join(" ");
        write!(
            out,
            "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{name} - Lamina</title>\n<style>\n{VIEWER_CSS}</style>\n</head>\n<body>\n<div id=\"bar\"><strong>{name}</strong><input id=\"layer\" type=\"range\" min=\"0\" max=\"0\" value=\"0\" aria-label=\"layer\"><span id=\"label\"></span><label><input id=\"paths\" type=\"checkbox\" checked> toolpaths</label><span id=\"tools\"></span>{legend}<span id=\"player\" hidden><label><input id=\"moves\" type=\"checkbox\" checked> machine moves</label> <button id=\"play\" type=\"button\">play</button> <input id=\"time\" type=\"range\" min=\"0\" max=\"1000\" value=\"1000\" aria-label=\"time in the layer\"> <select id=\"speed\" aria-label=\"speed\"><option value=\"1\">1x</option><option value=\"10\" selected>10x</option><option value=\"100\">100x</option></select> <span id=\"clock\"></span></span><label><input id=\"v3d\" type=\"checkbox\"> 3D</label><span id=\"cutbox\" hidden><label><input id=\"cut\" type=\"checkbox\"> cut</label> <input id=\"cutat\" type=\"range\" min=\"0\" max=\"1000\" value=\"500\" aria-label=\"cut plane across x\"></span><span id=\"opsbox\" hidden><label><input id=\"ops\" type=\"checkbox\" checked> operations</label> <select id=\"op\" aria-label=\"operation shown\"></select></span><span id=\"cursor\"></span></div>\n<ol id=\"oplist\" hidden></ol>\n<canvas id=\"view\"></canvas>\n<canvas id=\"view3d\" hidden></canvas>\n<div id=\"tip\"></div>\n<pre id=\"test-result\" hidden></pre>\n<script>const LAMINA = {header}; const LAYERS = []; const MOVES = new Map(); let GCODE = null;</script>\n",
            name = escape(ctx.pipeline_name),
        )
        .map_err(io(&path))?;
        Ok(Box::new(Sink {
            out,
            path,
            options: self.options.clone(),
            earlier,
        }))
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        if !plan.index.is_multiple_of(self.options.every) {
            return Ok(());
        }
        let mut pack = Packer::new(self.options.digits);
        let parts = plan
            .parts
            .iter()
            .map(|pl| {
                let mut nc = 0;
                for &f in &pl.families {
                    let fam = &pl.tree.families[f];
                    for c in std::iter::once(fam.outer).chain(fam.holes.iter().copied()) {
                        pack.ring(&xy(&pl.contours[c]));
                        nc += 1;
                    }
                }
                let regions = pl
                    .regions
                    .iter()
                    .map(|r| {
                        let mut n = 0;
                        for c in r.polygon.contours() {
                            pack.ring(&xy(c));
                            n += 1;
                        }
                        RegionOut {
                            c: hex(info, pl.part, r),
                            m: composition_text(info, pl.part, r),
                            l: round(r.level, 4),
                            k: r.index,
                            n,
                        }
                    })
                    .collect();
                PartLayerOut {
                    part: pl.part,
                    nc,
                    regions,
                    g: pack.take_base64(),
                }
            })
            .collect();
        let mut tools = Vec::new();
        if self.options.toolpaths {
            for t in &plan.toolpaths {
                let kind = match t.kind {
                    PathKind::Extrude => 0,
                    PathKind::Travel => 1,
                    PathKind::Pause => 2,
                };
                pack.path(t.tool, kind, t.points.iter().map(|p| [p.p.x, p.p.y]));
                if !tools.contains(&t.tool) {
                    tools.push(t.tool);
                }
            }
            tools.sort_unstable();
        }
        let p = pack.take_base64();
        let mut ops = Vec::new();
        for (k, op) in plan.operations.iter().enumerate() {
            for path in &op.paths {
                let closing = (path.closed && path.points.len() > 2).then(|| path.points[0]);
                pack.path(k, 0, path.points.iter().chain(closing.iter()).map(|q| [q.x, q.y]));
            }
            ops.push(OpOut {
                k: op_label(op),
                s: op_summary(op),
                n: op.paths.len(),
            });
        }
        let layer = LayerOut {
            i: plan.index,
            z: round(plan.z, 4),
            t: round(plan.thickness, 4),
            parts,
            tools,
            p,
            ops,
            q: pack.take_base64(),
        };
        let json = script_json(&layer).map_err(|e| Error::io(&self.path, std::io::Error::other(e)))?;
        let path = self.path.clone();
        writeln!(self.out, "<script>LAYERS.push({json});</script>").map_err(io(&path))
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let path = self.path.clone();
        if self.options.moves {
            self.write_moves(files)?;
        }
        write!(
            self.out,
            "<script>\n{VIEW3D_JS}</script>\n<script>\n{VIEWER_JS}</script>\n</body>\n</html>\n"
        )
        .map_err(io(&path))?;
        self.out.flush().map_err(io(&path))
    }
}

impl Sink {
    /// The G-code output to read back: the one `gcode` names, or the first written.
    fn gcode_file(&self, files: &dyn OutputFiles) -> Result<Option<(PathBuf, PathBuf)>> {
        let written: Vec<(PathBuf, PathBuf)> = files
            .written()
            .into_iter()
            .filter(|(name, _)| self.earlier.contains(name))
            .collect();
        if let Some(name) = &self.options.gcode {
            return match written.into_iter().find(|(n, _)| n == name) {
                Some(found) => Ok(Some(found)),
                None => Err(Error::config(format!(
                    "[[output]] html: `gcode = \"{}\"` names no output written before the viewer (list the `html` output after that `gcode` output)",
                    name.display()
                ))),
            };
        }
        Ok(written.into_iter().find(|(n, _)| {
            n.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| ["gcode", "gco", "g"].contains(&e.to_ascii_lowercase().as_str()))
        }))
    }

    /// Appends the machine's moves, read back from the G-code, one block per layer,
    /// as the file is read: memory holds the moves of a few layers, whatever its size.
    fn write_moves(&mut self, files: &dyn OutputFiles) -> Result<()> {
        use std::io::BufRead;
        let Some((name, file)) = self.gcode_file(files)? else {
            return Ok(());
        };
        let mut input = std::io::BufReader::new(std::fs::File::open(&file).map_err(|e| Error::io(&name, e))?);
        let mut reader = crate::moves::Reader::new();
        let mut written: Result<()> = Ok(());
        let mut layers = LayerMoves {
            out: &mut self.out,
            path: &self.path,
            every: self.options.every,
            pack: Packer::new(self.options.digits),
        };
        let mut put = |layer: usize, list: Vec<crate::moves::Move>, offset: [f64; 2]| {
            if written.is_ok() {
                written = layers.write(layer, &list, offset);
            }
        };
        let mut line = Vec::new();
        loop {
            line.clear();
            let read = input
                .read_until(b'\n', &mut line)
                .map_err(|e| Error::io(&name, e))?;
            if read == 0 {
                break;
            }
            reader.line(&String::from_utf8_lossy(&line), &mut put);
        }
        let (systems, offset) = reader.finish(&mut put);
        written?;
        let about = script_json(&serde_json::json!({
            "file": name.display().to_string(),
            "systems": systems,
            "offset": offset,
        }))
        .map_err(|e| Error::io(&self.path, std::io::Error::other(e)))?;
        writeln!(self.out, "<script>GCODE = {about};</script>").map_err(io(&self.path))
    }
}

/// Writes the machine's moves layer by layer as the G-code reader hands them over.
struct LayerMoves<'a> {
    out: &'a mut Box<dyn Write + Send>,
    path: &'a std::path::Path,
    every: usize,
    pack: Packer,
}

impl LayerMoves<'_> {
    fn write(&mut self, layer: usize, list: &[crate::moves::Move], [ox, oy]: [f64; 2]) -> Result<()> {
        if !layer.is_multiple_of(self.every) {
            return Ok(());
        }
        let start = list.iter().map(|m| m.t0).fold(f64::INFINITY, f64::min);
        let mut run: Vec<([f64; 2], f64)> = Vec::new();
        let mut key = None;
        for m in list {
            let k = (m.system, m.tool, if m.extrude { 0u8 } else { 1 });
            let from = [m.from[0] - ox, m.from[1] - oy];
            let to = [m.to[0] - ox, m.to[1] - oy];
            // A run goes on only without a pause (a dwell or a wait at a barrier is
            // shown as the head standing, not as a slow move).
            let joined = key == Some(k)
                && run
                    .last()
                    .is_some_and(|(p, t)| *p == from && (t - (m.t0 - start)).abs() < 1e-9);
            if !joined {
                if let Some((s, t, kind)) = key {
                    self.pack.timed(s, t, kind, &run);
                }
                run.clear();
                run.push((from, m.t0 - start));
                key = Some(k);
            }
            run.push((to, m.t1 - start));
        }
        if let Some((s, t, kind)) = key {
            self.pack.timed(s, t, kind, &run);
        }
        writeln!(
            self.out,
            "<script>MOVES.set({layer}, \"{}\");</script>",
            self.pack.take_base64()
        )
        .map_err(io(self.path))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    if options.every == 0 {
        return Err(config.error("every", "must be at least 1"));
    }
    if !(0..=9).contains(&options.digits) {
        return Err(config.error("digits", "must be between 0 and 9"));
    }
    Ok(AnyStage::Export(Box::new(Html { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "html",
        doc: "A self-contained HTML layer viewer: slider, zoom and pan, composition on hover, cursor coordinates and a scale bar, toolpath and tool toggles, the machine's moves read back from the run's G-code with a player, and a 3D view of the graded layer stack (WebGL: orbit, zoom, cut plane); no network needed.",
        options: Options::SPECS,
        example: "use = \"html\"\npath = \"viewer.html\"",
    },
    build,
});
