//! What the previews share: the region's colour and composition as text, coordinates
//! rounded for output, and the sink of the one-picture-per-layer exporters.

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use lamina_api::stage::{LayerSink, OutputFiles};
use lamina_api::{Contour, Error, LayerPlan, Result, RunInfo, SubRegion};

/// Highest layer number (and layer step) an option names: a slicer makes at most
/// ten million layers (its `max_layers`).
pub const MAX_LAYER: usize = 10_000_000;

/// `#rrggbb` of a region's property colour (grey when ungraded).
pub fn hex(info: &RunInfo, part: usize, r: &SubRegion) -> String {
    let [red, green, blue] = r
        .composition
        .as_ref()
        .map_or([128; 3], |c| c.colour(&info.part_materials(part)));
    format!("#{red:02x}{green:02x}{blue:02x}")
}

/// "ceramic 0.75, metal 0.25".
pub fn composition_text(info: &RunInfo, part: usize, r: &SubRegion) -> String {
    let Some(c) = &r.composition else {
        return "ungraded".into();
    };
    let names = &info.parts[part].materials;
    names
        .iter()
        .zip(&c.fractions)
        .map(|(&m, f)| format!("{} {}", info.materials[m].name, round(*f, 4)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `v` rounded to `digits` decimals, as the shortest text.
pub fn round(v: f64, digits: i32) -> f64 {
    let s = 10f64.powi(digits);
    let r = (v * s).round() / s;
    if r == 0.0 { 0.0 } else { r }
}

/// Appends `M x y L ... Z` for a closed contour, y kept as is (the SVG flips the frame).
pub fn path_data(out: &mut String, c: &Contour, digits: i32) {
    for (i, p) in c.points.iter().enumerate() {
        let _ = write!(
            out,
            "{}{} {}",
            if i == 0 { "M" } else { " L" },
            round(p.x, digits),
            round(p.y, digits)
        );
    }
    out.push_str(" Z ");
}

/// Bounding box (min x, min y, max x, max y) of everything in the layer; `None` when
/// the layer is empty.
pub fn layer_bounds(plan: &LayerPlan) -> Option<[f64; 4]> {
    let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for pl in &plan.parts {
        for c in &pl.contours {
            for p in &c.points {
                b = [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)];
            }
        }
    }
    (b[0] <= b[2]).then_some(b)
}

/// Text safe inside XML and HTML.
pub fn escape(s: &str) -> String {
    // XML 1.0 allows no control character but tab and line breaks, not even as a
    // reference, and a name is one line: each becomes a space.
    lamina_api::text::one_line(s)
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Draws one layer's picture as the bytes of its file (named for errors).
pub type Render = Box<dyn Fn(&RunInfo, &LayerPlan, &Path) -> Result<Vec<u8>> + Send>;

/// The sink of the exporters that write one picture per layer (PNG, SVG): it picks the
/// layers (every n-th, or a list), names their files `stem-007.ext`, skips layers with
/// nothing to draw, and writes what `render` draws.
pub struct EachLayer {
    pub stem: PathBuf,
    pub every: usize,
    pub layers: Vec<usize>,
    pub ext: &'static str,
    pub layer_count: usize,
    pub render: Render,
}

impl LayerSink for EachLayer {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, files: &mut dyn OutputFiles) -> Result<()> {
        let name = layer_file(
            &self.stem,
            self.every,
            &self.layers,
            self.layer_count,
            plan.index,
            self.ext,
        );
        let Some(name) = name else { return Ok(()) };
        if layer_bounds(plan).is_none() {
            return Ok(());
        }
        let bytes = (self.render)(info, plan, &name)?;
        write_file(files, &name, &bytes)
    }

    fn finish(self: Box<Self>, _info: &RunInfo, _files: &mut dyn OutputFiles) -> Result<()> {
        Ok(())
    }
}

/// Writes one whole file of the run's output.
pub fn write_file(files: &mut dyn OutputFiles, name: &Path, bytes: &[u8]) -> Result<()> {
    let mut out = files.create(name)?;
    out.write_all(bytes)
        .and_then(|()| out.flush())
        .map_err(|e| Error::io(name, e))
}

/// The file of a layer for exporters that write one picture per layer: `stem-007.ext`
/// for layer 7 of up to 999, or `None` when the options leave the layer out (every
/// n-th layer, or an explicit list).
pub fn layer_file(
    path: &Path,
    every: usize,
    layers: &[usize],
    layer_count: usize,
    index: usize,
    ext: &str,
) -> Option<PathBuf> {
    let wanted = if layers.is_empty() {
        index.is_multiple_of(every)
    } else {
        layers.contains(&index)
    };
    let stem = path.file_name()?.to_string_lossy().into_owned();
    let digits = layer_count.max(1).to_string().len();
    wanted.then(|| path.with_file_name(format!("{stem}-{index:0digits$}.{ext}")))
}
