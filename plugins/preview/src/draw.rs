//! What the previews share: the region's colour and composition as text, and coordinates
//! rounded for output.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use lamina_core::{Contour, LayerPlan, Region, RunInfo};

/// `#rrggbb` of a region's property colour (grey when ungraded).
pub fn hex(info: &RunInfo, part: usize, r: &Region) -> String {
    let [red, green, blue] = r
        .composition
        .as_ref()
        .map_or([128; 3], |c| c.colour(&info.part_materials(part)));
    format!("#{red:02x}{green:02x}{blue:02x}")
}

/// "ceramic 0.75, metal 0.25".
pub fn composition_text(info: &RunInfo, part: usize, r: &Region) -> String {
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
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
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
