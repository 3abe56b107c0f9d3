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
        /// largest page (MB): a larger viewer is split into pages of consecutive
        /// layers (`viewer.html`, `viewer-2.html`, …), each linking to its neighbours;
        /// machine moves that would not fit their layer's page are left out, with a note
        #[range(0.5, 4096.0)]
        page_mb: f64 = "64",
    }
}

/// What a layer's machine moves are expected to take in its page per byte of its
/// packed toolpaths: measured 1.43-1.56 (median, 3DBenchy and the Stanford bunny), at
/// most 2.6. Pages are cut with this room kept, so that the moves seldom miss it.
const MOVES_PER_PATH_BYTE: f64 = 1.6;

/// Room kept at the end of every page for what is written there when the run ends:
/// the scripts, and the few lines that link the pages and name the G-code.
fn trailer_room() -> u64 {
    (VIEW3D_JS.len() + VIEWER_JS.len() + 4096) as u64
}

struct Html {
    options: Options,
}

struct Sink {
    /// The pages written so far, in layer order; all stay open until the run ends,
    /// when each gets its layers' machine moves and the scripts.
    pages: Vec<Page>,
    /// The output's name: the first page's, from which the others' are made.
    path: PathBuf,
    /// Everything a page holds before its layers (style, header, the bar).
    head: String,
    options: Options,
    /// The outputs opened before this one: the only ones complete when it finishes
    /// (sinks finish in the order they were opened).
    earlier: Vec<PathBuf>,
    /// Whether machine moves will be read back into the pages: room is kept for them.
    moves_expected: bool,
}

/// One page of the viewer: a run of consecutive layers.
struct Page {
    out: Counted,
    name: PathBuf,
    /// The plan indices of its first and last layer.
    layers: Option<(usize, usize)>,
    /// Bytes written, and those expected of the moves of its layers.
    planned: u64,
    /// Layers whose machine moves did not fit.
    moves_left_out: Vec<usize>,
}

impl Page {
    /// A page written to `out` as far as `head`, holding no layer yet.
    fn start(mut out: Box<dyn Write + Send>, name: PathBuf, head: &str) -> Result<Page> {
        out.write_all(head.as_bytes()).map_err(io(&name))?;
        let bytes = head.len() as u64;
        Ok(Page {
            out: Counted { inner: out, bytes },
            name,
            layers: None,
            planned: bytes,
            moves_left_out: Vec::new(),
        })
    }
}

/// A writer that counts what passes through it.
struct Counted {
    inner: Box<dyn Write + Send>,
    bytes: u64,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// The name of page `k` (from 0) of the viewer named `first`: `viewer.html`,
/// `viewer-2.html`, … in the same folder.
fn page_name(first: &std::path::Path, k: usize) -> PathBuf {
    if k == 0 {
        return first.to_path_buf();
    }
    let stem = first.file_stem().and_then(|s| s.to_str()).unwrap_or("viewer");
    let name = match first.extension().and_then(|e| e.to_str()) {
        Some(ext) => format!("{stem}-{}.{ext}", k + 1),
        None => format!("{stem}-{}", k + 1),
    };
    first.with_file_name(name)
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
        let earlier: Vec<PathBuf> = ctx.files.written().into_iter().map(|(name, _)| name).collect();
        let out = ctx.files.create(&path)?;
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
        let head = format!(
            "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{name} - Lamina</title>\n<style>\n{VIEWER_CSS}</style>\n</head>\n<body>\n<div id=\"bar\"><strong>{name}</strong><input id=\"layer\" type=\"range\" min=\"0\" max=\"0\" value=\"0\" aria-label=\"layer\"><span id=\"label\"></span><span id=\"pages\" hidden></span><label><input id=\"paths\" type=\"checkbox\" checked> toolpaths</label><span id=\"tools\"></span>{legend}<span id=\"player\" hidden><label><input id=\"moves\" type=\"checkbox\" checked> machine moves</label> <button id=\"play\" type=\"button\">play</button> <input id=\"time\" type=\"range\" min=\"0\" max=\"1000\" value=\"1000\" aria-label=\"time in the layer\"> <select id=\"speed\" aria-label=\"speed\"><option value=\"1\">1x</option><option value=\"10\" selected>10x</option><option value=\"100\">100x</option></select> <span id=\"clock\"></span></span><label><input id=\"v3d\" type=\"checkbox\"> 3D</label><span id=\"cutbox\" hidden><label><input id=\"cut\" type=\"checkbox\"> cut</label> <input id=\"cutat\" type=\"range\" min=\"0\" max=\"1000\" value=\"500\" aria-label=\"cut plane across x\"></span><span id=\"opsbox\" hidden><label><input id=\"ops\" type=\"checkbox\" checked> operations</label> <select id=\"op\" aria-label=\"operation shown\"></select></span><span id=\"cursor\"></span></div>\n<ol id=\"oplist\" hidden></ol>\n<canvas id=\"view\"></canvas>\n<canvas id=\"view3d\" hidden></canvas>\n<div id=\"tip\"></div>\n<pre id=\"test-result\" hidden></pre>\n<script>const LAMINA = {header}; const LAYERS = []; const MOVES = new Map(); let GCODE = null; let PAGES = null;</script>\n",
            name = escape(ctx.pipeline_name),
        );
        let moves_expected = self.options.moves && gcode_candidate(&self.options, &earlier);
        Ok(Box::new(Sink {
            pages: vec![Page::start(out, path.clone(), &head)?],
            path,
            head,
            options: self.options.clone(),
            earlier,
            moves_expected,
        }))
    }
}

/// Whether `name` is a G-code file by its extension.
fn is_gcode(name: &std::path::Path) -> bool {
    name.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["gcode", "gco", "g"].contains(&e.to_ascii_lowercase().as_str()))
}

/// Whether the viewer will find a G-code to read back among the outputs opened before
/// it.
fn gcode_candidate(options: &Options, earlier: &[PathBuf]) -> bool {
    match &options.gcode {
        Some(name) => earlier.contains(name),
        None => earlier.iter().any(|n| is_gcode(n)),
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, files: &mut dyn OutputFiles) -> Result<()> {
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
        // Packed even when not shown: their size foretells that of the moves.
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
        let mut p = pack.take_base64();
        let expected_moves = if self.moves_expected {
            (p.len() as f64 * MOVES_PER_PATH_BYTE) as u64
        } else {
            0
        };
        if !self.options.toolpaths {
            p.clear();
            tools.clear();
        }
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
        let line = format!("<script>LAYERS.push({json});</script>\n");
        let need = line.len() as u64 + expected_moves;
        let limit = self.limit();
        let page = self.pages.last().expect("a page is opened with the sink");
        if page.layers.is_some() && page.planned + need + trailer_room() > limit {
            self.open_page(files)?;
        }
        let page = self.pages.last_mut().expect("a page is opened with the sink");
        page.out.write_all(line.as_bytes()).map_err(io(&page.name))?;
        page.planned += need;
        page.layers = Some(match page.layers {
            Some((first, _)) => (first, plan.index),
            None => (plan.index, plan.index),
        });
        Ok(())
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let gcode = if self.options.moves {
            self.write_moves(files)?
        } else {
            None
        };
        let count = self.pages.len();
        let names: Vec<String> = self
            .pages
            .iter()
            .map(|p| {
                p.name
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .collect();
        for (k, page) in self.pages.iter_mut().enumerate() {
            let name = page.name.clone();
            if let Some(about) = &gcode {
                writeln!(page.out, "<script>GCODE = {about};</script>").map_err(io(&name))?;
            }
            if count > 1 || !page.moves_left_out.is_empty() {
                let (first, last) = page.layers.unwrap_or((0, 0));
                let about = script_json(&serde_json::json!({
                    "index": k,
                    "count": count,
                    "first": first,
                    "last": last,
                    "prev": k.checked_sub(1).map(|j| &names[j]),
                    "next": names.get(k + 1),
                    "moves_left_out": page.moves_left_out.len(),
                    "page_mb": self.options.page_mb,
                }))
                .map_err(|e| Error::io(&name, std::io::Error::other(e)))?;
                writeln!(page.out, "<script>PAGES = {about};</script>").map_err(io(&name))?;
            }
            write!(
                page.out,
                "<script>\n{VIEW3D_JS}</script>\n<script>\n{VIEWER_JS}</script>\n</body>\n</html>\n"
            )
            .map_err(io(&name))?;
            page.out.flush().map_err(io(&name))?;
        }
        self.tell(files);
        Ok(())
    }
}

impl Sink {
    /// The largest page, in bytes.
    fn limit(&self) -> u64 {
        (self.options.page_mb * 1e6) as u64
    }

    /// Starts the next page.
    fn open_page(&mut self, files: &mut dyn OutputFiles) -> Result<()> {
        let name = page_name(&self.path, self.pages.len());
        let out = files.create(&name)?;
        self.pages.push(Page::start(out, name, &self.head)?);
        Ok(())
    }

    /// Says how the viewer was split and what it left out, once for the run.
    fn tell(&self, files: &mut dyn OutputFiles) {
        let limit = format!("{} MB", round(self.options.page_mb, 3));
        if self.pages.len() > 1 {
            let shown: Vec<String> = self
                .pages
                .iter()
                .take(4)
                .map(|p| {
                    let (a, b) = p.layers.unwrap_or((0, 0));
                    format!("{} (layers {a}-{b})", p.name.display())
                })
                .collect();
            let more = if self.pages.len() > 4 {
                format!(" and {} more", self.pages.len() - 4)
            } else {
                String::new()
            };
            files.tell(
                &self.path,
                lamina_api::Severity::Note,
                lamina_api::Warning::new(
                    "pages-split",
                    format!(
                        "the viewer is split into {} pages of at most {limit}, each linking to its neighbours: {}{more} (`page_mb` sets the size)",
                        self.pages.len(),
                        shown.join(", ")
                    ),
                ),
            );
        }
        let left_out: Vec<usize> = self
            .pages
            .iter()
            .flat_map(|p| p.moves_left_out.iter().copied())
            .collect();
        if !left_out.is_empty() {
            files.tell(
                &self.path,
                lamina_api::Severity::Warning,
                lamina_api::Warning::new(
                    "moves-left-out",
                    format!(
                        "the machine's moves of {} layer(s) ({}) are left out of the viewer to keep its pages under {limit}: raise `page_mb`, or show every n-th layer (`every`)",
                        left_out.len(),
                        lamina_api::text::layer_ranges(&left_out, 6)
                    ),
                ),
            );
        }
    }

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
        Ok(written.into_iter().find(|(n, _)| is_gcode(n)))
    }

    /// Appends the machine's moves, read back from the G-code, one block per layer to
    /// the page holding the layer, as the file is read: memory holds the moves of a
    /// few layers, whatever its size. Returns what the pages say of the G-code, when
    /// one was read.
    fn write_moves(&mut self, files: &dyn OutputFiles) -> Result<Option<String>> {
        use std::io::BufRead;
        let Some((name, file)) = self.gcode_file(files)? else {
            return Ok(None);
        };
        let mut input = std::io::BufReader::new(std::fs::File::open(&file).map_err(|e| Error::io(&name, e))?);
        let mut reader = crate::moves::Reader::new();
        let mut written: Result<()> = Ok(());
        let limit = self.limit();
        let mut layers = LayerMoves {
            pages: &mut self.pages,
            limit,
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
        Ok(Some(about))
    }
}

/// Writes the machine's moves layer by layer as the G-code reader hands them over,
/// each into the page that holds its layer while the page has room.
struct LayerMoves<'a> {
    pages: &'a mut [Page],
    limit: u64,
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
        let line = format!(
            "<script>MOVES.set({layer}, \"{}\");</script>\n",
            self.pack.take_base64()
        );
        // The page whose layers reach furthest without passing this one.
        let k = self
            .pages
            .iter()
            .rposition(|p| p.layers.is_some_and(|(first, _)| first <= layer))
            .unwrap_or(0);
        let page = &mut self.pages[k];
        if page.layers.is_some() && page.out.bytes + line.len() as u64 + trailer_room() > self.limit {
            page.moves_left_out.push(layer);
            return Ok(());
        }
        page.out.write_all(line.as_bytes()).map_err(io(&page.name))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::moves::Move;

    fn page(name: &str, layers: (usize, usize)) -> Page {
        Page {
            out: Counted {
                inner: Box::new(Vec::new()),
                bytes: 0,
            },
            name: PathBuf::from(name),
            layers: Some(layers),
            planned: 0,
            moves_left_out: Vec::new(),
        }
    }

    /// `n` extruding moves in a zigzag, a second each.
    fn zigzag(n: usize) -> Vec<Move> {
        (0..n)
            .map(|i| Move {
                system: 0,
                tool: 0,
                extrude: true,
                from: [i as f64, (i % 2) as f64 * 10.0],
                to: [i as f64 + 1.0, ((i + 1) % 2) as f64 * 10.0],
                t0: i as f64,
                t1: i as f64 + 1.0,
            })
            .collect()
    }

    /// Each layer's moves go to the page holding the layer; those that would take a
    /// page past its size are left out and counted on that page, and the next page
    /// still takes its own.
    #[test]
    fn moves_go_to_their_layers_page_and_are_left_out_where_it_is_full() {
        let mut pages = vec![page("v.html", (0, 4)), page("v-2.html", (5, 9))];
        let mut moves = LayerMoves {
            pages: &mut pages,
            limit: trailer_room() + 2000,
            every: 1,
            pack: Packer::new(2),
        };
        moves.write(0, &zigzag(10), [0.0, 0.0]).expect("written");
        moves.write(3, &zigzag(1000), [0.0, 0.0]).expect("left out");
        moves.write(4, &zigzag(10), [0.0, 0.0]).expect("written");
        moves.write(7, &zigzag(10), [0.0, 0.0]).expect("written");
        let [first, second] = &pages[..] else {
            unreachable!()
        };
        assert_eq!(first.moves_left_out, vec![3]);
        assert!(second.moves_left_out.is_empty());
        assert!(first.out.bytes > 0 && first.out.bytes <= 2000);
        assert!(second.out.bytes > 0);
    }

    #[test]
    fn pages_are_named_after_the_first() {
        let first = std::path::Path::new("out/viewer.html");
        assert_eq!(page_name(first, 0), PathBuf::from("out/viewer.html"));
        assert_eq!(page_name(first, 2), PathBuf::from("out/viewer-3.html"));
        assert_eq!(
            page_name(std::path::Path::new("view"), 1),
            PathBuf::from("view-2")
        );
    }
}
