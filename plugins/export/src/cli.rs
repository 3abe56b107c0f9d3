//! `cli`: Common Layer Interface (CLI 2.0) layer files, ASCII or binary, and the
//! topological-hierarchy paper's modified CLI that carries material data.
//!
//! Standard files hold, per layer, the contours of every part: outer contours
//! counter-clockwise (direction 1), holes clockwise (direction 0), each polyline closed
//! by repeating its first point, labelled with its part (`$$LABEL`). Coordinates are
//! written in `$$UNITS` (mm per unit). The binary form uses the long commands (127:
//! layer with a 32-bit float z; 130: polyline with 32-bit integers and float points),
//! little-endian, right after `$$HEADEREND`.
//!
//! The modified CLI (ASCII) writes the sub-regions' contours instead, each once and from
//! the outside in, with the paper's contour identifying number (1 for the family's
//! outer contour, 2..N for the offset contours, 0 for its innermost contours; see
//! [`crate::contour_ids`]), each polyline preceded by `$$MATERIAL/R,G,B,f1,...,fn`: the
//! property colour and the volume fractions of the region that starts at it.

use std::io::Write;
use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{Contour, Error, LayerPlan, Result, RunInfo, StageFactory};
use serde::Deserialize;

lamina_api::option_type!(Format = "string");

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Format {
    Ascii,
    Binary,
    /// The paper's modified CLI: sub-regions with contour ids and material data.
    Modified,
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// output file, relative to the output folder
        path: PathBuf = r#""layers.cli""#,
        /// "ascii", "binary" (long commands, little-endian) or "modified" (sub-regions with material data)
        format: Format = r#""ascii""#,
        /// mm per coordinate unit ($$UNITS)
        #[range(MIN_UNITS, MAX_UNITS)]
        units: f64 = "0.001",
    }
}

/// CLI 2.0 binary command indices.
const LAYER_LONG: u16 = 127;
const POLYLINE_LONG: u16 = 130;

/// Polyline directions.
const CLOCKWISE: i32 = 0;
const COUNTER_CLOCKWISE: i32 = 1;

struct Cli {
    options: Options,
}

struct Sink {
    out: Box<dyn Write + Send>,
    path: PathBuf,
    format: Format,
    units: f64,
    /// Reused text buffer for one polyline.
    line: String,
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

/// A number in the shortest form that reads back to the same `f64`, never in
/// exponent notation (CLI readers parse plain decimals).
fn push_number(out: &mut String, v: f64) {
    use std::fmt::Write as _;
    let v = if v == 0.0 { 0.0 } else { v };
    if v.abs() >= 1e-4 || v == 0.0 {
        let _ = write!(out, "{v}");
    } else {
        let _ = write!(out, "{v:.12}");
    }
}

impl Sink {
    fn polyline_ascii(&mut self, id: usize, dir: i32, c: &Contour) {
        let n = c.points.len() + 1;
        self.line.clear();
        self.line.push_str(&format!("$$POLYLINE/{id},{dir},{n}"));
        for p in c.points.iter().chain(c.points.first()) {
            self.line.push(',');
            push_number(&mut self.line, p.x / self.units);
            self.line.push(',');
            push_number(&mut self.line, p.y / self.units);
        }
        self.line.push('\n');
    }

    fn polyline_binary(&mut self, id: usize, dir: i32, c: &Contour) -> Result<()> {
        let n = c.points.len() + 1;
        let mut buf = Vec::with_capacity(14 + 8 * n);
        buf.extend_from_slice(&POLYLINE_LONG.to_le_bytes());
        buf.extend_from_slice(&(id as i32).to_le_bytes());
        buf.extend_from_slice(&dir.to_le_bytes());
        buf.extend_from_slice(&(n as i32).to_le_bytes());
        for p in c.points.iter().chain(c.points.first()) {
            buf.extend_from_slice(&((p.x / self.units) as f32).to_le_bytes());
            buf.extend_from_slice(&((p.y / self.units) as f32).to_le_bytes());
        }
        self.out.write_all(&buf).map_err(io(&self.path))
    }

    fn contour(&mut self, id: usize, dir: i32, c: &Contour) -> Result<()> {
        if c.points.len() < 2 {
            return Ok(());
        }
        if self.format == Format::Binary {
            return self.polyline_binary(id, dir, c);
        }
        self.polyline_ascii(id, dir, c);
        let path = self.path.clone();
        self.out.write_all(self.line.as_bytes()).map_err(io(&path))
    }
}

impl Exporter for Cli {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let mut out = ctx.files.create(&self.options.path)?;
        let path = self.options.path.clone();
        let mut header = String::from("$$HEADERSTART\n");
        header.push_str(match self.options.format {
            Format::Binary => "$$BINARY\n",
            _ => "$$ASCII\n",
        });
        header.push_str(&format!("$$UNITS/{}\n", self.options.units));
        header.push_str("$$VERSION/200\n");
        header.push_str(&format!("$$LAYERS/{}\n", ctx.layer_count));
        for (i, p) in ctx.info.parts.iter().enumerate() {
            // Labels are text up to the end of the line: keep them on one line.
            header.push_str(&format!(
                "$$LABEL/{},{}\n",
                i + 1,
                lamina_api::text::one_line(&p.name)
            ));
        }
        if self.options.format == Format::Modified {
            // Inside a `//...//` comment: one line, and no `//` that would end it.
            let names: Vec<String> = ctx
                .info
                .materials
                .iter()
                .map(|m| lamina_api::text::one_line(&m.name).replace("//", "/ /"))
                .collect();
            header.push_str(&format!(
                "//modified CLI: $$MATERIAL/R,G,B then the fractions of the polyline's part materials; materials: {}//\n",
                names.join(", ")
            ));
        }
        match self.options.format {
            Format::Binary => header.push_str("$$HEADEREND"),
            _ => header.push_str("$$HEADEREND\n$$GEOMETRYSTART\n"),
        }
        out.write_all(header.as_bytes()).map_err(io(&path))?;
        Ok(Box::new(Sink {
            out,
            path,
            format: self.options.format,
            units: self.options.units,
            line: String::new(),
        }))
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        let path = self.path.clone();
        let z = plan.z / self.units;
        match self.format {
            Format::Binary => {
                let mut buf = LAYER_LONG.to_le_bytes().to_vec();
                buf.extend_from_slice(&(z as f32).to_le_bytes());
                self.out.write_all(&buf).map_err(io(&path))?;
            }
            _ => {
                let mut line = String::from("$$LAYER/");
                push_number(&mut line, z);
                line.push('\n');
                self.out.write_all(line.as_bytes()).map_err(io(&path))?;
            }
        }
        for pl in &plan.parts {
            let id = pl.part + 1;
            if self.format != Format::Modified {
                for &f in &pl.families {
                    let fam = &pl.tree.families[f];
                    let outer = pl.contours[fam.outer].clone().oriented(true);
                    self.contour(id, COUNTER_CLOCKWISE, &outer)?;
                    for &h in &fam.holes {
                        let hole = pl.contours[h].clone().oriented(false);
                        self.contour(id, CLOCKWISE, &hole)?;
                    }
                }
                continue;
            }
            let materials = info.part_materials(pl.part);
            for entry in crate::contour_ids::entries(pl) {
                let Some(c) = &pl.regions[entry.region].composition else {
                    continue;
                };
                let rgb = c.colour(&materials);
                let mut material = format!("$$MATERIAL/{},{},{}", rgb[0], rgb[1], rgb[2]);
                for f in &c.fractions {
                    material.push(',');
                    push_number(&mut material, *f);
                }
                material.push('\n');
                self.out.write_all(material.as_bytes()).map_err(io(&path))?;
                let dir = if entry.ccw { COUNTER_CLOCKWISE } else { CLOCKWISE };
                let contour = entry.contour.clone().oriented(entry.ccw);
                self.contour(entry.id, dir, &contour)?;
            }
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, _files: &mut dyn OutputFiles) -> Result<()> {
        let path = self.path.clone();
        if self.format != Format::Binary {
            self.out.write_all(b"$$GEOMETRYEND\n").map_err(io(&path))?;
        }
        self.out.flush().map_err(io(&path))
    }
}

/// Smallest and largest `units` (mm per unit).
const MIN_UNITS: f64 = 1e-6;
const MAX_UNITS: f64 = 1000.0;

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    // `units` within its declared range, a nanometre to a metre per unit: the
    // coordinates stay numbers a reader takes (1e300 would write words of 300 digits,
    // 5e-324 divide every coordinate to infinity).
    let options: Options = config.parse()?;
    Ok(AnyStage::Export(Box::new(Cli { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "cli",
        doc: "Common Layer Interface layer files: ASCII or binary contours per layer, or the modified CLI with sub-regions, contour ids, colours and fractions.",
        options: Options::SPECS,
        example: "use = \"cli\"\npath = \"layers.cli\"\nformat = \"binary\"",
    },
    build,
});
