//! Previews of a plan, for people rather than machines:
//!
//! - `svg`: one SVG picture per layer, sub-regions filled with their property colour,
//!   contours drawn, toolpaths optionally, each region titled with its composition;
//! - `png`, `contact-sheet`, `stack`: raster pictures (tiny-skia): a PNG per layer,
//!   chosen layers side by side, an isometric overview of the stacked layers;
//! - `html`: one self-contained HTML file (no network access) with a layer slider,
//!   zoom and pan, a region's composition on hover, and toggles for toolpaths and tools.

mod draw;
mod html;
mod label;
mod moves;
mod pack;
mod raster;
mod svg;
