//! `svg`: a picture of each layer (or of every n-th): sub-regions filled with their
//! property colour, each titled with its composition (browsers show it on hover), the
//! contours drawn over them, and the toolpaths when the plan has them. Files are
//! written as the layers come and appear when the run succeeds.

use std::fmt::Write as _;
use std::path::PathBuf;

use lamina_api::stage::{AnyStage, ExportContext, Exporter, LayerSink, StageConfig, StageInfo, StageKind};
use lamina_api::{LayerPlan, PathKind, Result, RunInfo, StageFactory};

use crate::draw::{EachLayer, MAX_LAYER, composition_text, escape, hex, layer_bounds, path_data, round};

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct Options {
        /// file stem: layer 7 of 240 is written to `svg/layer-007.svg`
        path: PathBuf = r#""svg/layer""#,
        /// write every n-th layer
        #[range(1, MAX_LAYER)]
        every: usize = "1",
        /// only these layers (indices from 0)
        #[range(0, MAX_LAYER)]
        layers: Vec<usize> = "[]",
        /// draw the planned toolpaths
        toolpaths: bool = "true",
        /// size of the longer side in pixels
        #[range(16.0, 20_000.0)]
        size: f64 = "800.0",
    }
}

struct Svg {
    options: Options,
}

/// The SVG text of one layer.
pub fn layer_svg(info: &RunInfo, plan: &LayerPlan, toolpaths: bool, size: f64) -> String {
    let [x0, y0, x1, y1] = layer_bounds(plan).unwrap_or([0.0, 0.0, 1.0, 1.0]);
    let margin = 0.03 * (x1 - x0).max(y1 - y0).max(1e-3);
    let (w, h) = (x1 - x0 + 2.0 * margin, y1 - y0 + 2.0 * margin);
    let scale = size / w.max(h);
    let stroke = round(1.0 / scale, 5);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" viewBox=\"{} {} {} {}\">",
        round(w * scale, 1),
        round(h * scale, 1),
        round(x0 - margin, 4),
        round(-(y1 + margin), 4),
        round(w, 4),
        round(h, 4)
    );
    let _ = writeln!(
        s,
        "<title>layer {} at z = {} mm ({} mm thick)</title>\n<clipPath id=\"view\"><rect x=\"{vx}\" y=\"{vy}\" width=\"{vw}\" height=\"{vh}\"/></clipPath>\n<rect x=\"{vx}\" y=\"{vy}\" width=\"{vw}\" height=\"{vh}\" fill=\"#ffffff\"/>\n<g clip-path=\"url(#view)\">\n<g transform=\"scale(1,-1)\">",
        plan.index,
        round(plan.z, 4),
        round(plan.thickness, 4),
        vx = round(x0 - margin, 4),
        vy = round(-(y1 + margin), 4),
        vw = round(w, 4),
        vh = round(h, 4)
    );
    for pl in &plan.parts {
        let part = &info.parts[pl.part];
        for r in &pl.regions {
            let mut d = String::new();
            for c in r.polygon.contours() {
                path_data(&mut d, c, 4);
            }
            let _ = writeln!(
                s,
                "<path d=\"{d}\" fill=\"{}\" fill-rule=\"evenodd\"><title>{}, region {} (r = {}): {}</title></path>",
                hex(info, pl.part, r),
                escape(&part.name),
                r.index,
                round(r.level, 4),
                escape(&composition_text(info, pl.part, r))
            );
        }
        let mut d = String::new();
        for &f in &pl.families {
            let fam = &pl.tree.families[f];
            path_data(&mut d, &pl.contours[fam.outer], 4);
            for &hole in &fam.holes {
                path_data(&mut d, &pl.contours[hole], 4);
            }
        }
        let _ = writeln!(
            s,
            "<path d=\"{d}\" fill=\"none\" stroke=\"#000000\" stroke-width=\"{stroke}\"/>"
        );
    }
    if toolpaths {
        for t in &plan.toolpaths {
            if t.points.len() < 2 || t.kind == PathKind::Pause {
                continue;
            }
            let mut d = String::new();
            for (i, p) in t.points.iter().enumerate() {
                let _ = write!(
                    d,
                    "{}{} {}",
                    if i == 0 { "M" } else { " L" },
                    round(p.p.x, 4),
                    round(p.p.y, 4)
                );
            }
            let (colour, dash) = match t.kind {
                PathKind::Travel => (
                    "#808080",
                    format!(" stroke-dasharray=\"{}\"", round(4.0 * stroke, 5)),
                ),
                _ => ("#202020", String::new()),
            };
            let _ = writeln!(
                s,
                "<path d=\"{d}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"{stroke}\"{dash}><title>tool {}</title></path>",
                t.tool
            );
        }
    }
    // Travel to a park or a wipe tower leaves the part's bounds: the view stays on the
    // part (and its margin), wherever the SVG is shown.
    s.push_str("</g>\n</g>\n</svg>\n");
    s
}

impl Exporter for Svg {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let o = self.options.clone();
        Ok(Box::new(EachLayer {
            stem: o.path.clone(),
            every: o.every,
            layers: o.layers.clone(),
            ext: "svg",
            layer_count: ctx.layer_count,
            render: Box::new(
                move |info, plan, _| Ok(layer_svg(info, plan, o.toolpaths, o.size).into_bytes()),
            ),
        }))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    if options.every == 0 {
        return Err(config.error("every", "must be at least 1"));
    }
    if !(options.size.is_finite() && options.size >= 16.0 && options.size <= 20_000.0) {
        return Err(config.error("size", "must be between 16 and 20000 pixels"));
    }
    if options.path.file_name().is_none() {
        return Err(config.error("path", "must end in a file name stem, e.g. \"svg/layer\""));
    }
    Ok(AnyStage::Export(Box::new(Svg { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "svg",
        doc: "An SVG picture per layer: sub-regions in their property colours titled with their compositions, contours, toolpaths.",
        options: Options::SPECS,
        example: "use = \"svg\"\npath = \"svg/layer\"\nevery = 2",
    },
    build,
});
