//! Raster pictures of layers with tiny-skia: `png` (one picture per layer),
//! `contact-sheet` (chosen layers side by side in one picture) and `stack` (an isometric
//! overview of all layers piled up, painted from the bottom so upper layers cover lower
//! ones as they do in the part).

use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{Contour, Error, LayerPlan, PathKind, Result, RunInfo, StageFactory};
use tiny_skia::{Color, FillRule, Paint, PathBuilder, Pixmap, Stroke, Transform};

use crate::draw::{EachLayer, MAX_LAYER, layer_bounds, write_file};

/// Most pixels on a picture's longer side.
const MAX_SIZE: u32 = 8192;

/// A region ready to paint: its rings and colour.
struct Shape {
    rings: Vec<Vec<[f32; 2]>>,
    rgb: [u8; 3],
}

fn colour_of(info: &RunInfo, part: usize, r: &lamina_api::SubRegion) -> [u8; 3] {
    r.composition
        .as_ref()
        .map_or([128; 3], |c| c.colour(&info.part_materials(part)))
}

fn ring(c: &Contour) -> Vec<[f32; 2]> {
    c.points.iter().map(|p| [p.x as f32, p.y as f32]).collect()
}

fn shapes(info: &RunInfo, plan: &LayerPlan) -> Vec<Shape> {
    plan.parts
        .iter()
        .flat_map(|pl| {
            pl.regions.iter().map(move |r| Shape {
                rings: r.polygon.contours().map(ring).collect(),
                rgb: colour_of(info, pl.part, r),
            })
        })
        .collect()
}

fn path_of(rings: &[Vec<[f32; 2]>], map: impl Fn([f32; 2]) -> (f32, f32)) -> Option<tiny_skia::Path> {
    let mut pb = PathBuilder::new();
    for r in rings.iter().filter(|r| r.len() >= 3) {
        let (x, y) = map(r[0]);
        pb.move_to(x, y);
        for &p in &r[1..] {
            let (x, y) = map(p);
            pb.line_to(x, y);
        }
        pb.close();
    }
    pb.finish()
}

fn paint(rgb: [u8; 3]) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color_rgba8(rgb[0], rgb[1], rgb[2], 255);
    p.anti_alias = true;
    p
}

/// Paints one layer into `pixmap` inside the box (x, y, w, h) in pixels, the bounds `b`
/// (min x, min y, max x, max y: the layer's own, or the whole part's so that tiles share
/// one scale) fitted with a margin, y up. What lies beyond the box is not drawn.
fn paint_layer(
    pixmap: &mut Pixmap,
    cell: [f32; 4],
    b: [f64; 4],
    plan: &LayerPlan,
    info: &RunInfo,
    toolpaths: bool,
) {
    let [cx, cy, cw, ch] = cell;
    let (Some(rect), Some(mut mask)) = (
        tiny_skia::Rect::from_xywh(cx, cy, cw, ch),
        tiny_skia::Mask::new(pixmap.width(), pixmap.height()),
    ) else {
        return;
    };
    mask.fill_path(
        &PathBuilder::from_rect(rect),
        FillRule::Winding,
        false,
        Transform::identity(),
    );
    let mask = Some(&mask);
    let (bw, bh) = ((b[2] - b[0]).max(1e-6) as f32, (b[3] - b[1]).max(1e-6) as f32);
    let s = 0.94 * (cw / bw).min(ch / bh);
    let ox = cx + (cw - s * bw) / 2.0 - s * b[0] as f32;
    let oy = cy + (ch + s * bh) / 2.0 + s * b[1] as f32;
    let map = |p: [f32; 2]| (ox + s * p[0], oy - s * p[1]);
    for shape in shapes(info, plan) {
        if let Some(path) = path_of(&shape.rings, map) {
            pixmap.fill_path(
                &path,
                &paint(shape.rgb),
                FillRule::EvenOdd,
                Transform::identity(),
                mask,
            );
        }
    }
    let stroke = Stroke {
        width: 1.0,
        ..Stroke::default()
    };
    for pl in &plan.parts {
        let rings: Vec<Vec<[f32; 2]>> = pl.contours.iter().map(ring).collect();
        if let Some(path) = path_of(&rings, map) {
            pixmap.stroke_path(&path, &paint([0, 0, 0]), &stroke, Transform::identity(), mask);
        }
    }
    if toolpaths {
        for t in plan
            .toolpaths
            .iter()
            .filter(|t| t.kind == PathKind::Extrude && t.points.len() >= 2)
        {
            let mut pb = PathBuilder::new();
            let (x, y) = map([t.points[0].p.x as f32, t.points[0].p.y as f32]);
            pb.move_to(x, y);
            for p in &t.points[1..] {
                let (x, y) = map([p.p.x as f32, p.p.y as f32]);
                pb.line_to(x, y);
            }
            if let Some(path) = pb.finish() {
                let hue = [[200, 40, 40], [40, 120, 40], [40, 40, 200], [160, 120, 0]][t.tool % 4];
                pixmap.stroke_path(
                    &path,
                    &paint(hue),
                    &Stroke::default(),
                    Transform::identity(),
                    mask,
                );
            }
        }
    }
}

fn new_pixmap(w: u32, h: u32) -> Result<Pixmap> {
    let mut p = Pixmap::new(w.clamp(1, MAX_SIZE), h.clamp(1, MAX_SIZE))
        .ok_or_else(|| Error::stage("export:png", format!("cannot make a {w} x {h} picture")))?;
    p.fill(Color::WHITE);
    Ok(p)
}

fn encode(pixmap: &Pixmap, name: &std::path::Path) -> Result<Vec<u8>> {
    pixmap
        .encode_png()
        .map_err(|e| Error::io(name, std::io::Error::other(e.to_string())))
}

// ---- png: one picture per layer ------------------------------------------------------

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct PngOptions {
        /// file stem: layer 7 of 240 is `png/layer-007.png`
        path: PathBuf = r#""png/layer""#,
        /// write every n-th layer
        #[range(1, MAX_LAYER)]
        every: usize = "1",
        /// only these layers (indices from 0)
        #[range(0, MAX_LAYER)]
        layers: Vec<usize> = "[]",
        /// pixels on the longer side
        #[range(16, MAX_SIZE)]
        size: u32 = "800",
        /// draw the planned extrusion paths
        toolpaths: bool = "true",
    }
}

struct Png {
    options: PngOptions,
}

impl Exporter for Png {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let o = self.options.clone();
        Ok(Box::new(EachLayer {
            stem: o.path.clone(),
            every: o.every,
            layers: o.layers.clone(),
            ext: "png",
            layer_count: ctx.layer_count,
            render: Box::new(move |info, plan, name| {
                let Some(b) = layer_bounds(plan) else {
                    return Ok(Vec::new());
                };
                let aspect = ((b[3] - b[1]) / (b[2] - b[0]).max(1e-9)).clamp(0.05, 20.0);
                let (w, h) = if aspect <= 1.0 {
                    (o.size, ((o.size as f64 * aspect).ceil() as u32).max(16))
                } else {
                    (((o.size as f64 / aspect).ceil() as u32).max(16), o.size)
                };
                let mut pixmap = new_pixmap(w, h)?;
                paint_layer(
                    &mut pixmap,
                    [0.0, 0.0, w as f32, h as f32],
                    b,
                    plan,
                    info,
                    o.toolpaths,
                );
                encode(&pixmap, name)
            }),
        }))
    }
}

fn build_png(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: PngOptions = config.parse()?;
    if options.every == 0 {
        return Err(config.error("every", "must be at least 1"));
    }
    if !(16..=MAX_SIZE).contains(&options.size) {
        return Err(config.error("size", format!("must be between 16 and {MAX_SIZE} pixels")));
    }
    if options.path.file_name().is_none() {
        return Err(config.error("path", "must end in a file name stem, e.g. \"png/layer\""));
    }
    Ok(AnyStage::Export(Box::new(Png { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "png",
        doc: "A PNG picture per layer: sub-regions in their property colours, contours, toolpaths.",
        options: PngOptions::SPECS,
        example: "use = \"png\"\nevery = 2\nsize = 256",
    },
    build: build_png,
});

// ---- contact sheet -------------------------------------------------------------------

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct SheetOptions {
        /// output file
        path: PathBuf = r#""contact-sheet.png""#,
        /// the layers to show; default: `count` spread evenly
        #[range(0, MAX_LAYER)]
        layers: Vec<usize> = "[]",
        /// how many layers, first and last included
        #[range(1, 10_000)]
        count: usize = "12",
        /// tiles per row
        #[range(1, 256)]
        columns: usize = "4",
        /// tile size in pixels
        #[range(32, 2048)]
        tile: u32 = "256",
    }
}

struct Sheet {
    options: SheetOptions,
}

struct SheetSink {
    options: SheetOptions,
    /// The layers to show, in order.
    chosen: Vec<usize>,
    pixmap: Pixmap,
}

impl Exporter for Sheet {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let o = &self.options;
        let n = ctx.layer_count;
        let chosen: Vec<usize> = if o.layers.is_empty() {
            // `count` layers evenly spread, first and last included.
            let k = o.count.min(n).max(1);
            let mut v: Vec<usize> = (0..k)
                .map(|i| {
                    if k == 1 {
                        0
                    } else {
                        i * (n.saturating_sub(1)) / (k - 1)
                    }
                })
                .collect();
            v.dedup();
            v
        } else {
            o.layers.iter().copied().filter(|&l| l < n).collect()
        };
        let rows = chosen.len().div_ceil(o.columns).max(1) as u32;
        let pixmap = new_pixmap(o.tile * o.columns as u32, o.tile * rows)?;
        Ok(Box::new(SheetSink {
            options: o.clone(),
            chosen,
            pixmap,
        }))
    }
}

impl LayerSink for SheetSink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        if let Some(slot) = self.chosen.iter().position(|&l| l == plan.index) {
            let t = self.options.tile as f32;
            let (col, row) = (slot % self.options.columns, slot / self.options.columns);
            // Every tile at the scale of the whole model, so that sizes compare across
            // tiles; below it, the layer's caption.
            let scale = (t / 128.0).floor().max(1.0);
            let caption_h = 9.0 * scale;
            let cell = [
                col as f32 * t + 2.0,
                row as f32 * t + 2.0,
                t - 4.0,
                t - 4.0 - caption_h,
            ];
            let b = &info.xy_bounds;
            let bounds = if b.is_empty() {
                layer_bounds(plan)
            } else {
                Some([b.min.x, b.min.y, b.max.x, b.max.y])
            };
            if let Some(bounds) = bounds {
                paint_layer(&mut self.pixmap, cell, bounds, plan, info, false);
            }
            let caption = crate::label::layer_caption(plan.index, plan.z);
            let (w, _) = crate::label::size(&caption, scale);
            let x = col as f32 * t + ((t - w) / 2.0).max(2.0);
            let y = row as f32 * t + t - caption_h - 1.0;
            crate::label::draw(&mut self.pixmap, &caption, x, y, scale);
        }
        Ok(())
    }

    fn finish(self: Box<Self>, _info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let bytes = encode(&self.pixmap, &self.options.path)?;
        write_file(files, &self.options.path, &bytes)
    }
}

fn build_sheet(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: SheetOptions = config.parse()?;
    if options.columns == 0 || options.count == 0 {
        return Err(config.error("columns", "`columns` and `count` must be at least 1"));
    }
    if !(32..=2048).contains(&options.tile) {
        return Err(config.error("tile", "must be between 32 and 2048 pixels"));
    }
    Ok(AnyStage::Export(Box::new(Sheet { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "contact-sheet",
        doc: "Chosen layers side by side in one PNG, left to right and top to bottom in build order, all at the scale of the whole model, each captioned with its layer and z.",
        options: SheetOptions::SPECS,
        example: "use = \"contact-sheet\"\ncount = 4\ncolumns = 2\ntile = 128",
    },
    build: build_sheet,
});

// ---- stack: isometric overview -------------------------------------------------------

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct StackOptions {
        /// output file
        path: PathBuf = r#""stack.png""#,
        /// pixels on the longer side
        #[range(64, MAX_SIZE)]
        size: u32 = "800",
        /// draw at most this many layers (every n-th beyond), which bounds the memory kept
        #[range(1, 100_000)]
        max_layers: usize = "400",
    }
}

struct Stack {
    options: StackOptions,
}

/// The layers kept for the overview: their height and painted shapes.
struct StackSink {
    options: StackOptions,
    every: usize,
    layers: Vec<(f32, Vec<Shape>)>,
}

/// Isometric projection of (x, y, z): x to the right-down, y to the left-down, z up.
fn iso(p: [f32; 2], z: f32) -> (f32, f32) {
    const C: f32 = 0.866_025_4;
    ((p[0] - p[1]) * C, (p[0] + p[1]) * 0.5 - z)
}

impl Exporter for Stack {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        Ok(Box::new(StackSink {
            options: self.options.clone(),
            every: ctx.layer_count.div_ceil(self.options.max_layers).max(1),
            layers: Vec::new(),
        }))
    }
}

impl LayerSink for StackSink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        if plan.index.is_multiple_of(self.every) {
            self.layers.push((plan.z as f32, shapes(info, plan)));
        }
        Ok(())
    }

    fn finish(self: Box<Self>, _info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let mut b = [f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY];
        for (z, shapes) in &self.layers {
            for s in shapes {
                for r in &s.rings {
                    for &p in r {
                        let (x, y) = iso(p, *z);
                        b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
                    }
                }
            }
        }
        let name = self.options.path.clone();
        if b[0].is_nan() || b[0] > b[2] {
            return write_file(files, &name, &encode(&new_pixmap(16, 16)?, &name)?);
        }
        let (bw, bh) = ((b[2] - b[0]).max(1e-6), (b[3] - b[1]).max(1e-6));
        let size = self.options.size as f32;
        let s = 0.94 * (size / bw).min(size / bh);
        let (w, h) = ((bw * s / 0.94).ceil() as u32, (bh * s / 0.94).ceil() as u32);
        let mut pixmap = new_pixmap(w, h)?;
        let (ox, oy) = (
            (w as f32 - s * bw) / 2.0 - s * b[0],
            (h as f32 - s * bh) / 2.0 - s * b[1],
        );
        let z0 = self.layers.first().map_or(0.0, |l| l.0);
        let z1 = self.layers.last().map_or(1.0, |l| l.0);
        // Bottom to top: each layer covers what lies below it.
        for (z, shapes) in &self.layers {
            for shape in shapes {
                let map = |p: [f32; 2]| {
                    let (x, y) = iso(p, *z);
                    (ox + s * x, oy + s * y)
                };
                if let Some(path) = path_of(&shape.rings, map) {
                    // A little darker toward the bottom, so the layers read as a pile.
                    let k = 0.7 + 0.3 * ((*z - z0) / (z1 - z0).max(1e-6)).clamp(0.0, 1.0);
                    let rgb = shape.rgb.map(|c| (c as f32 * k) as u8);
                    pixmap.fill_path(&path, &paint(rgb), FillRule::EvenOdd, Transform::identity(), None);
                }
            }
        }
        write_file(files, &name, &encode(&pixmap, &name)?)
    }
}

fn build_stack(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: StackOptions = config.parse()?;
    if !(64..=MAX_SIZE).contains(&options.size) {
        return Err(config.error("size", format!("must be between 64 and {MAX_SIZE} pixels")));
    }
    if options.max_layers == 0 {
        return Err(config.error("max_layers", "must be at least 1"));
    }
    Ok(AnyStage::Export(Box::new(Stack { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "stack",
        doc: "An isometric overview of the stacked layers as one PNG, each sub-region in its property colour.",
        options: StackOptions::SPECS,
        example: "use = \"stack\"\nsize = 256",
    },
    build: build_stack,
});
