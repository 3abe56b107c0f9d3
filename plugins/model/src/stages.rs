//! The model stages this crate registers.

use std::path::{Path, PathBuf};

use lamina_api::options::SharedOption;
use lamina_api::stage::{AnyStage, ModelSource, StageConfig, StageInfo, StageKind};
use lamina_api::{Contour, Error, Limit, Limits, Mesh, Point2, Result, StageFactory};
use serde::Deserialize;

use crate::blade::{Blade, Naca};
use crate::extrude::extrude;
use crate::profile::{GearProfile, polygon};
use crate::weld::{Soup, weld};

/// Largest `weld` (mm).
const MAX_WELD: f64 = 1.0;

const WELD: SharedOption =
    SharedOption::new("1e-5", "vertices closer than this (mm) are merged").within(0.0, MAX_WELD);

// ---------------------------------------------------------------- file readers

lamina_api::stage_options! {
    #[derive(Debug)]
    struct FileOptions {
        /// mesh file, relative to the pipeline file
        file: PathBuf,
        weld: f64 = use WELD,
    }
}

#[derive(Debug, Clone, Copy)]
enum Format {
    Stl,
    Obj,
    ThreeMf,
}

struct FileSource {
    file: PathBuf,
    weld: f64,
    format: Format,
    limits: Limits,
}

/// The file, at most `cap` bytes: a device or a FIFO named as a model is refused
/// before it is read.
fn read(path: &Path, cap: u64) -> Result<Vec<u8>> {
    lamina_api::source::read_regular(path, cap).map_err(|e| Error::io(path, e))
}

impl ModelSource for FileSource {
    fn load(&self, base_dir: &Path) -> Result<Vec<Mesh>> {
        let path = base_dir.join(&self.file);
        let meshes = self.read(&path)?;
        let triangles: usize = meshes.iter().map(|m| m.triangles.len()).sum();
        self.limits
            .check(Limit::Triangles, triangles as f64, &path.display().to_string())?;
        Ok(meshes)
    }
}

impl FileSource {
    fn read(&self, path: &Path) -> Result<Vec<Mesh>> {
        let path = path.to_path_buf();
        let bytes = lamina_api::source::regular_file(&path).map_err(|e| Error::io(&path, e))?;
        self.limits
            .check(Limit::ModelBytes, bytes as f64, &path.display().to_string())?;
        let soups: Vec<(String, Soup)> = match self.format {
            Format::Stl => return crate::stl::read_welded(&path, self.weld),
            Format::ThreeMf => {
                return Ok(crate::threemf::read_within(
                    &path,
                    &read(&path, self.limits.model_bytes)?,
                    &self.limits,
                )?
                .iter()
                .map(|m| crate::weld::weld_mesh(m, self.weld))
                .collect());
            }
            Format::Obj => {
                let bytes = read(&path, self.limits.model_bytes)?;
                let text = String::from_utf8_lossy(&bytes);
                crate::obj::parse(&path, &text)?
                    .into_iter()
                    .map(|m| {
                        let soup = Soup {
                            triangles: (0..m.triangles.len()).map(|i| m.triangle(i)).collect(),
                        };
                        (m.name, soup)
                    })
                    .collect()
            }
        };
        Ok(soups
            .into_iter()
            .map(|(name, soup)| weld(&name, &soup, self.weld).0)
            .collect())
    }
}

fn build_file(config: &StageConfig<'_>, format: Format) -> Result<AnyStage> {
    let o: FileOptions = config.parse()?;
    // Welding merges corners closer than this; a millimetre would already close the
    // gaps a part is made of.
    if !(o.weld.is_finite() && (0.0..=MAX_WELD).contains(&o.weld)) {
        return Err(config.error(
            "weld",
            format!("must lie in [0, {MAX_WELD}] mm (0 merges only equal corners)"),
        ));
    }
    // What `run` will read, `check` finds readable: a missing or unreadable model is
    // said before anything runs.
    // A device or a FIFO is refused before it is opened (opening a FIFO waits for a
    // writer).
    // A pipeline reads models within its reach only (its folder, and what the command
    // line allows), links followed.
    let path = config.base_dir.join(&o.file);
    let cannot = |e: std::io::Error| config.error("file", format!("cannot read `{}`: {e}", path.display()));
    let real = config.reach.check(&path).map_err(cannot)?;
    lamina_api::source::regular_file(&real).map_err(cannot)?;
    std::fs::File::open(&real).map_err(cannot)?;
    Ok(AnyStage::Model(Box::new(FileSource {
        file: o.file,
        weld: o.weld,
        format,
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "stl",
        doc: "Reads a binary or ASCII STL file (chosen automatically for `file = \"*.stl\"`).",
        options: FileOptions::SPECS,
        example: "use = \"stl\"\nfile = \"part.stl\"",
    },
    build: |c| build_file(c, Format::Stl),
});

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "obj",
        doc: "Reads a Wavefront OBJ file; each `o` object is one mesh (chosen automatically for `file = \"*.obj\"`).",
        options: FileOptions::SPECS,
        example: "use = \"obj\"\nfile = \"part.obj\"",
    },
    build: |c| build_file(c, Format::Obj),
});

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "3mf",
        doc: "Reads a 3MF package: one mesh per build item, in millimetres, with its base materials per triangle (chosen automatically for `file = \"*.3mf\"`).",
        options: FileOptions::SPECS,
        example: "use = \"3mf\"\nfile = \"part.3mf\"",
    },
    build: |c| build_file(c, Format::ThreeMf),
});

// ---------------------------------------------------------------- generators

/// Shortest length of a generated model: a micrometre, or a millimetre of a part given
/// in metres.
const MIN_LENGTH: f64 = 1e-3;
/// Longest length of a generated model: 100 m, or 100 mm of a part given in
/// micrometres (with `scale = 0.001`).
const MAX_LENGTH: f64 = 1e5;

struct Generated(Vec<Mesh>);

impl ModelSource for Generated {
    fn load(&self, _base_dir: &Path) -> Result<Vec<Mesh>> {
        Ok(self.0.clone())
    }
}

fn positive(config: &StageConfig<'_>, key: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(config.error(key, format!("must be a positive number, not {v}")))
    }
}

/// Most sides of a generated circle: 4096 keep a 10 mm radius within 3 nm of the
/// circle, and every stage after pays for each side on every layer.
const MAX_SEGMENTS: usize = 4096;

fn segments_ok(config: &StageConfig<'_>, v: usize) -> Result<()> {
    if (3..=MAX_SEGMENTS).contains(&v) {
        Ok(())
    } else {
        Err(config.error("segments", format!("must lie in 3..={MAX_SEGMENTS}")))
    }
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct GearOptions {
        /// number of teeth
        #[range(3, 10_000)]
        teeth: usize = "20",
        /// radius of the tooth tips (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        tip_radius: f64 = "20.0",
        /// radius of the tooth roots (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        root_radius: f64 = "16.0",
        /// radius of the central bore (mm); 0 for none (`gear-shaft`: the shaft fills it)
        #[range(0.0, MAX_LENGTH)]
        bore: f64 = "5.0",
        /// thickness of the gear (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        height: f64 = "8.0",
        /// share of the pitch a tooth takes at its tip
        #[range(0.0, 1.0)]
        tip_share: f64 = "0.3",
        /// share of the pitch a tooth takes at its root
        #[range(0.0, 1.0)]
        root_share: f64 = "0.55",
        /// vertices per tip or root land
        #[range(1, 1000)]
        arc_segments: usize = "4",
        // `gear-shaft` only, after the GEAR_OPTIONS that `gear` documents.
        /// length of the shaft from the bed (mm); unset: 2 * height
        #[range(MIN_LENGTH, MAX_LENGTH)]
        shaft_length: Option<f64>,
        /// radial gap between shaft and bore (mm)
        #[range(0.0, MAX_LENGTH)]
        clearance: f64 = "0.2",
    }
}

/// How many of [`GearOptions::SPECS`], from the first, the `gear` model documents.
const GEAR_OPTIONS: usize = 8;

fn gear_profile(config: &StageConfig<'_>, o: &GearOptions) -> Result<GearProfile> {
    if o.teeth < 3 || o.teeth > 10_000 {
        return Err(config.error("teeth", "must lie in 3..=10000"));
    }
    positive(config, "tip_radius", o.tip_radius)?;
    positive(config, "root_radius", o.root_radius)?;
    positive(config, "height", o.height)?;
    if o.root_radius >= o.tip_radius {
        return Err(config.error("root_radius", "must be smaller than tip_radius"));
    }
    if !(o.bore >= 0.0 && o.bore < o.root_radius * 0.95) {
        return Err(config.error("bore", "must lie in [0, 0.95 root_radius)"));
    }
    for (k, v) in [("tip_share", o.tip_share), ("root_share", o.root_share)] {
        if !(v > 0.0 && v < 1.0) {
            return Err(config.error(k, "must lie in (0, 1)"));
        }
    }
    if o.tip_share > o.root_share {
        return Err(config.error(
            "tip_share",
            "must not exceed root_share (teeth narrow towards the tip)",
        ));
    }
    if o.arc_segments == 0 || o.arc_segments > 1000 {
        return Err(config.error("arc_segments", "must lie in 1..=1000"));
    }
    Ok(GearProfile {
        teeth: o.teeth,
        tip_radius: o.tip_radius,
        root_radius: o.root_radius,
        tip_share: o.tip_share,
        root_share: o.root_share,
        arc_segments: o.arc_segments,
    })
}

fn bore_segments(o: &GearOptions) -> usize {
    (o.teeth * (2 * o.arc_segments + 2)).clamp(32, 512)
}

fn build_gear(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: GearOptions = config.parse()?;
    if o.shaft_length.is_some() {
        return Err(config.error("shaft_length", "only the `gear-shaft` model has a shaft"));
    }
    let g = gear_profile(config, &o)?;
    let holes = if o.bore > 0.0 {
        vec![Contour::circle(Point2::origin(), o.bore, bore_segments(&o))]
    } else {
        vec![]
    };
    let mesh = extrude("gear", &polygon(g.outline(), holes), 0.0, o.height)?;
    Ok(AnyStage::Model(Box::new(Generated(vec![mesh]))))
}

fn build_gear_shaft(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: GearOptions = config.parse()?;
    let g = gear_profile(config, &o)?;
    if o.bore <= 0.0 {
        return Err(config.error("bore", "the gear of a gear-shaft assembly needs a bore"));
    }
    if !(o.clearance >= 0.0 && o.clearance < o.bore * 0.5) {
        return Err(config.error("clearance", "must lie in [0, bore / 2)"));
    }
    let length = o.shaft_length.unwrap_or(2.0 * o.height);
    positive(config, "shaft_length", length)?;
    let seg = bore_segments(&o);
    let gear = extrude(
        "gear",
        &polygon(g.outline(), vec![Contour::circle(Point2::origin(), o.bore, seg)]),
        0.0,
        o.height,
    )?;
    let shaft = extrude(
        "shaft",
        &polygon(
            Contour::circle(Point2::origin(), o.bore - o.clearance, seg),
            vec![],
        ),
        0.0,
        length,
    )?;
    Ok(AnyStage::Model(Box::new(Generated(vec![gear, shaft]))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "gear",
        doc: "Generates a spur gear with trapezoidal teeth and an optional bore, standing on the bed.",
        options: GearOptions::SPECS.split_at(GEAR_OPTIONS).0,
        example: "use = \"gear\"\nteeth = 12\nheight = 4.0",
    },
    build: build_gear,
});

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "gear-shaft",
        doc: "Generates a gear (mesh 0) on a shaft through its bore (mesh 1): a two-part assembly.",
        options: GearOptions::SPECS,
        example: "use = \"gear-shaft\"\nteeth = 12\nheight = 4.0\nshaft_length = 10.0",
    },
    build: build_gear_shaft,
});

lamina_api::stage_options! {
    #[derive(Debug)]
    struct TubeOptions {
        /// outer radius (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        outer_radius: f64 = "10.0",
        /// inner radius (mm); 0 makes a rod
        #[range(0.0, MAX_LENGTH)]
        inner_radius: f64 = "7.0",
        /// height (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        height: f64 = "20.0",
        /// vertices per circle
        #[range(3, MAX_SEGMENTS)]
        segments: usize = "128",
    }
}

fn build_tube(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: TubeOptions = config.parse()?;
    positive(config, "outer_radius", o.outer_radius)?;
    positive(config, "height", o.height)?;
    segments_ok(config, o.segments)?;
    if !(o.inner_radius >= 0.0 && o.inner_radius < o.outer_radius) {
        return Err(config.error("inner_radius", "must lie in [0, outer_radius)"));
    }
    let holes = if o.inner_radius > 0.0 {
        vec![Contour::circle(Point2::origin(), o.inner_radius, o.segments)]
    } else {
        vec![]
    };
    let outer = Contour::circle(Point2::origin(), o.outer_radius, o.segments);
    let mesh = extrude("tube", &polygon(outer, holes), 0.0, o.height)?;
    Ok(AnyStage::Model(Box::new(Generated(vec![mesh]))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "tube",
        doc: "Generates a round tube (or a rod with inner_radius = 0) standing on the bed.",
        options: TubeOptions::SPECS,
        example: "use = \"tube\"\nouter_radius = 10.0\ninner_radius = 7.0\nheight = 5.0",
    },
    build: build_tube,
});

lamina_api::stage_options! {
    #[derive(Debug)]
    struct CubeOptions {
        /// edge length (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        size: f64 = "20.0",
    }
}

/// A box with equal sides; its own stage so that `size` is one number.
fn build_cube(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: CubeOptions = config.parse()?;
    positive(config, "size", o.size)?;
    let r = Contour::rectangle(Point2::new(0.0, 0.0), Point2::new(o.size, o.size));
    let mesh = extrude("cube", &polygon(r, vec![]), 0.0, o.size)?;
    Ok(AnyStage::Model(Box::new(Generated(vec![mesh]))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "cube",
        doc: "Generates a cube with one corner at the origin.",
        options: CubeOptions::SPECS,
        example: "use = \"cube\"\nsize = 5.0",
    },
    build: build_cube,
});

lamina_api::option_type!(NacaCode = "string");

/// A NACA designation as written in TOML: `"2412"`, or `2412` (a code with leading
/// zeros such as `0012` is no TOML integer and arrives as a string anyway).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum NacaCode {
    Text(String),
    Number(u32),
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct BladeOptions {
        /// 4-digit NACA section: camber %, its position in tenths, thickness %; unset: 2412
        naca: Option<NacaCode>,
        /// maximum camber (fraction of the chord); overrides naca's first digit; unset: from naca
        #[range(0.0, 0.1)]
        max_camber: Option<f64>,
        /// chordwise position of the maximum camber (fraction); overrides naca's second digit; unset: from naca
        #[range(0.0, 1.0)]
        camber_position: Option<f64>,
        /// maximum thickness (fraction of the chord); overrides naca's last two digits; unset: from naca
        #[range(0.001, 0.4)]
        thickness: Option<f64>,
        /// chord length (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        chord: f64 = "40.0",
        /// height of the airfoil above the root (mm); unset: 1.5 * chord
        #[range(MIN_LENGTH, MAX_LENGTH)]
        span: Option<f64>,
        /// rotation of the tip against the base (degrees, about the quarter-chord line), linear along the span
        #[range(-90.0, 90.0)]
        twist: f64 = "20.0",
        /// airfoil sections along the span, both ends included
        #[range(2, 10_000)]
        sections: usize = "21",
        /// vertices per airfoil surface, cosine spaced
        #[range(4, 10_000)]
        points: usize = "48",
        /// root block size along x and y (mm), centred under the airfoil; unset: [1.25 * chord, 0.5 * chord]
        #[range(MIN_LENGTH, MAX_LENGTH)]
        root_size: Option<[f64; 2]>,
        /// root block height (mm); 0 for a bare airfoil; unset: 0.25 * chord
        #[range(0.0, MAX_LENGTH)]
        root_height: Option<f64>,
        /// cooling cavities: 0, 1 or 2
        #[range(0, 2)]
        cavities: usize = "0",
        /// skin thickness around the cavities (mm); unset: 0.03 * chord
        #[range(MIN_LENGTH, MAX_LENGTH)]
        wall: Option<f64>,
        /// rib thickness between two cavities (mm); unset: `wall`
        #[range(MIN_LENGTH, MAX_LENGTH)]
        rib: Option<f64>,
    }
}

fn build_blade(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: BladeOptions = config.parse()?;
    positive(config, "chord", o.chord)?;
    let mut blade = Blade::with_chord(o.chord);
    if let Some(code) = &o.naca {
        let text = match code {
            NacaCode::Text(t) => t.clone(),
            NacaCode::Number(n) => format!("{n:04}"),
        };
        blade.profile = Naca::from_code(&text).ok_or_else(|| {
            config.error(
                "naca",
                format!("`{text}` is not a 4-digit NACA code such as \"2412\""),
            )
        })?;
    }
    let p = &mut blade.profile;
    p.m = o.max_camber.unwrap_or(p.m);
    p.p = o.camber_position.unwrap_or(p.p);
    p.t = o.thickness.unwrap_or(p.t);
    blade.span = o.span.unwrap_or(blade.span);
    blade.twist = o.twist;
    blade.sections = o.sections;
    blade.points = o.points;
    blade.root_size = o.root_size.unwrap_or(blade.root_size);
    blade.root_height = o.root_height.unwrap_or(blade.root_height);
    blade.cavities = o.cavities;
    blade.wall = o.wall.unwrap_or(blade.wall);
    blade.rib = o.rib.unwrap_or(blade.wall);
    let mesh = blade.mesh().map_err(|e| {
        // The profile's checks name the parameters; a code sets all three.
        let option = match e.option {
            "max_camber" | "camber_position" | "thickness" if o.naca.is_some() && !config.has(e.option) => {
                "naca"
            }
            other => other,
        };
        config.error(option, e.message)
    })?;
    Ok(AnyStage::Model(Box::new(Generated(vec![mesh]))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "blade",
        doc: "Generates a turbine-blade-like model: a NACA 4-digit airfoil twisted linearly along its span on a rectangular root block, with 0, 1 or 2 cooling cavities that run from the bed through the root and the airfoil and open at the tip (every layer is one area with `cavities` holes).",
        options: BladeOptions::SPECS,
        example: "use = \"blade\"\ncavities = 2\nchord = 20.0\nspan = 10.0\nsections = 6",
    },
    build: build_blade,
});

lamina_api::stage_options! {
    #[derive(Debug)]
    struct BoxOptions {
        /// size along x, y, z (mm)
        #[range(MIN_LENGTH, MAX_LENGTH)]
        size: [f64; 3] = "[20.0, 20.0, 10.0]",
    }
}

fn build_box(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: BoxOptions = config.parse()?;
    for v in o.size {
        positive(config, "size", v)?;
    }
    let r = Contour::rectangle(Point2::new(0.0, 0.0), Point2::new(o.size[0], o.size[1]));
    let mesh = extrude("box", &polygon(r, vec![]), 0.0, o.size[2])?;
    Ok(AnyStage::Model(Box::new(Generated(vec![mesh]))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Model,
        name: "box",
        doc: "Generates a rectangular box with one corner at the origin.",
        options: BoxOptions::SPECS,
        example: "use = \"box\"\nsize = [10.0, 5.0, 2.0]",
    },
    build: build_box,
});
