//! `bitmap`: the bitmap layers of periodic-microstructure regions (cmpm-process-planning
//! 4.3 and Fig. 10). A microstructure is an array of spherical voids at the inserting
//! points of a lattice; each layer of the chosen parts is a grid of pixels, 1 where
//! there is material and 0 in the voids or outside the part.
//!
//! Only the inserting points near the layer are visited: a void of radius r centred at
//! height z_k meets the cutting plane z_c only when |z_k - z_c| < r, so the lattice rows
//! k inside that narrow band (the paper's two auxiliary planes at distance L_max = r
//! around the layer, Fig. 5) are computed directly instead of testing every cell.
//!
//! Two files stream out: a header with one line per layer (layer number, height,
//! thickness, cut height, pixel size, origin, size and the offset of its bitmap in the
//! data file), and the data file of all bitmaps, one row of `0`/`1` characters per
//! pixel row from the origin's row upward.

use std::io::Write;
use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{BBox2, Contour, Error, LayerPlan, Limit, Limits, Result, RunInfo, StageFactory};
use lamina_fgm::microstructure::{BaseCellSpec, Microstructure};
use lamina_geom::lattice::Lattice;
use std::sync::Arc;

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// output name: `<path>.hdr` (one line per layer) and `<path>.dat` (the bitmaps)
        path: PathBuf = r#""bitmap""#,
        /// the microstructure parts; default: all
        parts: Vec<String> = "[]",
        /// pixel size (mm)
        #[range(1e-4, 100.0)]
        pixel: f64 = "0.05",
        /// lattice spacing in x, y, z (mm)
        #[range(0.001, 1000.0)]
        period: [f64; 3] = "[1.0, 1.0, 1.0]",
        /// one inserting point of the lattice (mm)
        #[range(-1e4, 1e4)]
        origin: [f64; 3] = "[0.0, 0.0, 0.0]",
        /// radius of the spherical void at each inserting point (mm)
        #[range(0.0, 1000.0)]
        void_radius: f64 = "0.3",
        /// the base cell instead of spheres: `{ shape = "sphere" | "box" | "cylinder", size, aspect, turn, lean, insert, period, origin, tilt }`, sizes and angles numbers or Rhai expressions of x, y, z (formerly `cell`)
        #[formerly("cell")]
        base_cell: Option<BaseCellSpec>,
    }
}

/// A pixel grid over a layer.
pub struct Raster {
    pub origin: [f64; 2],
    pub pixel: f64,
    pub width: usize,
    pub height: usize,
    pub bits: Vec<bool>,
}

impl Raster {
    /// A grid aligned to multiples of `pixel` covering `bbox`, refused when it would
    /// hold more pixels than `limits.grid_samples`.
    pub fn covering(bbox: &BBox2, pixel: f64, limits: &Limits) -> Result<Self> {
        let x0 = (bbox.min.x / pixel).floor();
        let y0 = (bbox.min.y / pixel).floor();
        let w = (bbox.max.x / pixel).ceil() - x0;
        let h = (bbox.max.y / pixel).ceil() - y0;
        // NaN (an empty box) fails the check too.
        limits.check(
            Limit::GridSamples,
            w * h,
            &format!("a bitmap layer of {w} x {h} pixels of {pixel} mm"),
        )?;
        let (width, height) = (w.max(0.0) as usize, h.max(0.0) as usize);
        Ok(Self {
            origin: [x0 * pixel, y0 * pixel],
            pixel,
            width,
            height,
            bits: vec![false; width * height],
        })
    }

    /// Sets the pixels whose centres lie inside the contours (even-odd), by scanlines:
    /// each edge adds its crossing to the rows it spans.
    pub fn fill(&mut self, contours: &[&Contour]) {
        let mut crossings: Vec<Vec<f64>> = vec![Vec::new(); self.height];
        for c in contours {
            for (a, b) in c.edges() {
                let (lo, hi) = if a.y < b.y { (a, b) } else { (b, a) };
                // Rows whose centre y lies in [lo.y, hi.y).
                let first = ((lo.y - self.origin[1]) / self.pixel - 0.5).ceil().max(0.0) as usize;
                let last = ((hi.y - self.origin[1]) / self.pixel - 0.5).ceil().max(0.0) as usize;
                for (row, xs) in crossings
                    .iter_mut()
                    .enumerate()
                    .take(last.min(self.height))
                    .skip(first)
                {
                    let y = self.origin[1] + (row as f64 + 0.5) * self.pixel;
                    xs.push(lo.x + (y - lo.y) * (hi.x - lo.x) / (hi.y - lo.y));
                }
            }
        }
        for (row, xs) in crossings.iter_mut().enumerate() {
            xs.sort_by(f64::total_cmp);
            for pair in xs.chunks_exact(2) {
                let (a, b) = (self.column(pair[0]), self.column(pair[1]));
                let line = &mut self.bits[row * self.width..(row + 1) * self.width];
                for bit in &mut line[a..b] {
                    *bit = !*bit;
                }
            }
        }
    }

    /// First column whose centre is at or right of `x`.
    fn column(&self, x: f64) -> usize {
        (((x - self.origin[0]) / self.pixel - 0.5).ceil().max(0.0) as usize).min(self.width)
    }

    /// Clears the pixels whose centres lie inside the contour (even-odd).
    pub fn clear(&mut self, contour: &Contour) {
        let row_of = |y: f64| (y - self.origin[1]) / self.pixel - 0.5;
        let b = contour.bbox();
        let first = row_of(b.min.y).ceil().max(0.0) as usize;
        let last = (row_of(b.max.y).floor() + 1.0).max(0.0) as usize;
        let mut xs = Vec::new();
        for row in first..last.min(self.height) {
            let y = self.origin[1] + (row as f64 + 0.5) * self.pixel;
            xs.clear();
            for (a, b) in contour.edges() {
                if (a.y <= y) != (b.y <= y) {
                    xs.push(a.x + (y - a.y) * (b.x - a.x) / (b.y - a.y));
                }
            }
            xs.sort_by(f64::total_cmp);
            for pair in xs.chunks_exact(2) {
                let (a, b) = (self.column(pair[0]), self.column(pair[1]));
                for bit in &mut self.bits[row * self.width + a..row * self.width + b.max(a)] {
                    *bit = false;
                }
            }
        }
    }

    /// Clears the pixels whose centres lie in the circle.
    pub fn clear_circle(&mut self, cx: f64, cy: f64, r: f64) {
        let row_of = |y: f64| (y - self.origin[1]) / self.pixel - 0.5;
        let first = row_of(cy - r).ceil().max(0.0) as usize;
        let last = (row_of(cy + r).floor() + 1.0).max(0.0) as usize;
        for row in first..last.min(self.height) {
            let y = self.origin[1] + (row as f64 + 0.5) * self.pixel;
            let half = (r * r - (y - cy) * (y - cy)).max(0.0).sqrt();
            let (a, b) = (self.column(cx - half), self.column(cx + half));
            for bit in &mut self.bits[row * self.width + a..row * self.width + b.max(a)] {
                *bit = false;
            }
        }
    }

    pub fn count(&self) -> usize {
        self.bits.iter().filter(|&&b| b).count()
    }
}

/// The voids: the spheres of the shorthand, exact circles, or base cells.
#[derive(Clone)]
enum Voids {
    Spheres(Lattice),
    Cells(Arc<Microstructure>),
}

struct Bitmap {
    options: Options,
    voids: Voids,
    limits: Limits,
}

struct Sink {
    header: Box<dyn Write + Send>,
    data: Box<dyn Write + Send>,
    header_path: PathBuf,
    data_path: PathBuf,
    parts: Vec<usize>,
    pixel: f64,
    voids: Voids,
    limits: Limits,
    offset: u64,
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

impl Exporter for Bitmap {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let parts = if self.options.parts.is_empty() {
            (0..ctx.info.parts.len()).collect()
        } else {
            self.options
                .parts
                .iter()
                .map(|name| {
                    ctx.info
                        .parts
                        .iter()
                        .position(|p| &p.name == name)
                        .ok_or_else(|| {
                            Error::stage(
                                "export:bitmap",
                                format!("`parts` names `{name}`, which is no part"),
                            )
                        })
                })
                .collect::<Result<Vec<_>>>()?
        };
        let header_path = self.options.path.with_extension("hdr");
        let data_path = self.options.path.with_extension("dat");
        let mut header = ctx.files.create(&header_path)?;
        let data = ctx.files.create(&data_path)?;
        let names: Vec<&str> = parts.iter().map(|&p| ctx.info.parts[p].name.as_str()).collect();
        let voids = match &self.voids {
            Voids::Spheres(l) => format!(
                "spheres of radius {} mm at origin [{}, {}, {}] + lattice period [{}, {}, {}] mm",
                l.radius, l.origin[0], l.origin[1], l.origin[2], l.period[0], l.period[1], l.period[2]
            ),
            Voids::Cells(m) => m.describe(),
        };
        writeln!(
            header,
            "# lamina bitmap layers 1: 1 = material, 0 = void or outside; data rows from the origin upward\n\
             # parts: {}\n\
             # voids: {}\n\
             # layer z thickness cut_z pixel origin_x origin_y width height offset",
            // A part's name is the pipeline's text: one line, or it would add records.
            lamina_api::text::one_line(&names.join(", ")),
            lamina_api::text::one_line(&voids),
        )
        .map_err(io(&header_path))?;
        Ok(Box::new(Sink {
            header,
            data,
            header_path,
            data_path,
            parts,
            pixel: self.options.pixel,
            voids: self.voids.clone(),
            limits: self.limits,
            offset: 0,
        }))
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        let mut contours: Vec<&Contour> = Vec::new();
        for pl in plan.parts.iter().filter(|pl| self.parts.contains(&pl.part)) {
            for &f in &pl.families {
                let fam = &pl.tree.families[f];
                contours.push(&pl.contours[fam.outer]);
                contours.extend(fam.holes.iter().map(|&h| &pl.contours[h]));
            }
        }
        if contours.is_empty() {
            return Ok(());
        }
        let bbox = contours.iter().fold(BBox2::EMPTY, |b, c| b.union(&c.bbox()));
        let mut raster = Raster::covering(&bbox, self.pixel, &self.limits)?;
        raster.fill(&contours);
        // The voids are cut at the layer's mid-height, as the contours are.
        let cut_z = plan.z - plan.thickness / 2.0;
        match &self.voids {
            Voids::Spheres(l) => {
                for (cx, cy, r) in l.circles(cut_z, &bbox) {
                    raster.clear_circle(cx, cy, r);
                }
            }
            Voids::Cells(m) => {
                for c in m.voids(cut_z, &bbox, info.model_frame.as_ref())? {
                    raster.clear(&c);
                }
            }
        }
        writeln!(
            self.header,
            "{} {} {} {} {} {} {} {} {} {}",
            plan.index,
            plan.z,
            plan.thickness,
            cut_z,
            self.pixel,
            raster.origin[0],
            raster.origin[1],
            raster.width,
            raster.height,
            self.offset
        )
        .map_err(io(&self.header_path))?;
        let mut row = Vec::with_capacity(raster.width + 1);
        for r in 0..raster.height {
            row.clear();
            row.extend(
                raster.bits[r * raster.width..(r + 1) * raster.width]
                    .iter()
                    .map(|&b| if b { b'1' } else { b'0' }),
            );
            row.push(b'\n');
            self.data.write_all(&row).map_err(io(&self.data_path))?;
        }
        self.offset += (raster.height * (raster.width + 1)) as u64;
        Ok(())
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, _files: &mut dyn OutputFiles) -> Result<()> {
        self.header.flush().map_err(io(&self.header_path))?;
        self.data.flush().map_err(io(&self.data_path))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    // Each number within its declared range (`config.parse`): a positive pixel and
    // period, a finite origin, a void radius of zero or more.
    let options: Options = config.parse()?;
    let voids = match &options.base_cell {
        Some(spec) => {
            if let Some(k) = ["period", "origin", "void_radius"]
                .into_iter()
                .find(|k| config.has(k))
            {
                return Err(config.error(
                    k,
                    "give either `base_cell` or the spheres' `period`, `origin` and `void_radius`",
                ));
            }
            if spec.period.iter().any(|&p| p < options.pixel) {
                return Err(config.error(
                    "base_cell",
                    format!("every period must be at least the pixel ({} mm)", options.pixel),
                ));
            }
            Voids::Cells(Arc::new(Microstructure::new(spec, config, "base_cell")?))
        }
        None => spheres(config, &options)?,
    };
    Ok(AnyStage::Export(Box::new(Bitmap {
        options,
        voids,
        limits: config.limits,
    })))
}

/// The shorthand's spheres, each option checked.
fn spheres(config: &StageConfig<'_>, options: &Options) -> Result<Voids> {
    // Each void must be drawable and the voids of one layer countable: a period below
    // the pixel, or a void wider than the lattice (which already removes all
    // material), would only multiply the circles to clear.
    if options.period.iter().any(|&p| p < options.pixel) {
        return Err(config.error(
            "period",
            format!("every period must be at least the pixel ({} mm)", options.pixel),
        ));
    }
    let smallest = options.period.iter().copied().fold(f64::INFINITY, f64::min);
    if options.void_radius > smallest {
        return Err(config.error(
            "void_radius",
            format!(
                "must be at most the smallest period ({smallest} mm): voids that large leave no material"
            ),
        ));
    }
    Ok(Voids::Spheres(Lattice {
        period: options.period,
        origin: options.origin,
        radius: options.void_radius,
    }))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "bitmap",
        doc: "Bitmap layers of periodic-microstructure parts: 1 for material, 0 for the voids of the lattice's base cells (spheres, or shapes sized and turned by Rhai functions); one header and one data file.",
        options: Options::SPECS,
        example: "use = \"bitmap\"\npixel = 0.1\nperiod = [2.0, 2.0, 1.0]\nvoid_radius = 0.4",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::Point2;

    fn square(x0: f64, y0: f64, s: f64) -> Contour {
        Contour::rectangle(Point2::new(x0, y0), Point2::new(x0 + s, y0 + s))
    }

    #[test]
    fn a_square_with_a_hole_fills_its_area() {
        let outer = square(0.0, 0.0, 10.0);
        let hole = square(3.0, 3.0, 4.0).oriented(false);
        let bbox = outer.bbox();
        let mut r = Raster::covering(&bbox, 0.1, &Limits::default()).expect("raster");
        r.fill(&[&outer, &hole]);
        assert_eq!(r.count(), 10_000 - 1_600);
    }

    #[test]
    fn voids_remove_their_circles() {
        let outer = square(0.0, 0.0, 10.0);
        let mut r = Raster::covering(&outer.bbox(), 0.01, &Limits::default()).expect("raster");
        r.fill(&[&outer]);
        r.clear_circle(5.0, 5.0, 2.0);
        let area = r.count() as f64 * 1e-4;
        let want = 100.0 - std::f64::consts::PI * 4.0;
        assert!((area - want).abs() < 2e-3 * want, "{area} vs {want}");
    }

    #[test]
    fn huge_grids_are_refused() {
        let bbox = BBox2::from_points([Point2::new(0.0, 0.0), Point2::new(1000.0, 1000.0)]);
        assert!(Raster::covering(&bbox, 1e-4, &Limits::default()).is_err());
    }
}
