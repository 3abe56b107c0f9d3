//! Reading a machine profile: the pipeline's `machine` key names a built-in profile or a
//! file, or holds an inline table; a profile may start from another with `base`, and
//! overrides it key by key (tables merge recursively, the `tools` array merges tool by
//! tool, anything else is replaced). Each layer's types are checked against its own
//! file, and the merged profile's values are checked with the place of the layer that
//! wrote them, so an error names the file, line and field that is wrong.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::raw::{RawAxes, RawMachine, RawPlacement, RawShape, Switch};
use super::template::{Template, TemplateKind};
use super::*;
use crate::error::{Error, Result};
use crate::pipeline::{PathElem, TableRef};
use crate::source::{Location, SourceFile};

/// How deep `base` chains may go, which also stops cycles that change names.
const MAX_BASE_DEPTH: usize = 8;
/// Hotter than any FFF hotend goes (°C).
const MAX_NOZZLE_TEMPERATURE: f64 = 500.0;
const MAX_BED_TEMPERATURE: f64 = 200.0;

/// What a pipeline's `machine` key says.
#[derive(Debug, Clone)]
pub enum MachineSpec {
    /// A built-in profile's name, or a path ending in `.toml`, relative to the pipeline.
    Named { reference: String, at: Option<Location> },
    /// An inline table, perhaps with `base`.
    Inline(TableRef),
}

/// Reads, merges and validates the machine a pipeline names; relative paths resolve
/// against `base_dir` (the pipeline's folder).
pub fn resolve(spec: &MachineSpec, base_dir: &Path) -> Result<Machine> {
    let (top, at) = match spec {
        MachineSpec::Named { reference, at } => (load_named(reference, base_dir, at.clone())?, at.clone()),
        MachineSpec::Inline(table) => {
            let layer = inline_layer(table, base_dir)?;
            let at = layer.root.clone();
            (layer, at)
        }
    };
    let mut layers = vec![top];
    loop {
        let last = layers.last().expect("at least the top layer");
        let Some(base) = last.table.get("base") else { break };
        let Some(reference) = base.as_str() else {
            return Err(last.error(
                "base",
                "must be a string: a built-in profile's name or a `.toml` path",
            ));
        };
        if layers.len() > MAX_BASE_DEPTH {
            return Err(last.error(
                "base",
                format!("profiles extend each other more than {MAX_BASE_DEPTH} deep"),
            ));
        }
        let next = load_named(reference, &last.dir, last.locations.get("base").cloned())?;
        if layers.iter().any(|l| l.label == next.label) {
            return Err(last.error(
                "base",
                format!("`{reference}` extends itself (through its bases)"),
            ));
        }
        layers.push(next);
    }

    let mut merged = toml::Table::new();
    let mut locations = BTreeMap::new();
    let label = layers[0].label.clone();
    let root = layers[0].root.clone();
    for layer in layers.into_iter().rev() {
        let mut table = layer.table;
        table.remove("base");
        merge_tables(&mut merged, table, "");
        locations.extend(layer.locations);
    }
    let raw: RawMachine = toml::Value::Table(merged)
        .try_into()
        .map_err(|e: toml::de::Error| Error::config(format!("{label}: {}", e.message().trim())))?;
    let check = Check {
        locations: &locations,
        root,
        label: label.clone(),
    };
    let mut machine = validate(raw, &check)?;
    machine.origin = MachineOrigin { label, at };
    Ok(machine)
}

/// One profile of a `base` chain: its table and where each of its keys is written.
struct Layer {
    table: toml::Table,
    /// Dotted path (`tools.1.nozzle_temperature`) → where the key is written.
    locations: BTreeMap<String, Location>,
    /// Where the profile's table is: a file's start, or the pipeline's `machine` key.
    root: Option<Location>,
    /// `profiles/x.toml`, `[machine] in p.toml`: tells layers apart and names them.
    label: String,
    /// Folder that a `base` path in this layer resolves against.
    dir: PathBuf,
}

impl Layer {
    fn error(&self, key: &str, message: impl Into<String>) -> Error {
        let location = self.locations.get(key).cloned().or_else(|| self.root.clone());
        config(location, format!("{}: {key}: {}", self.label, message.into()))
    }
}

fn config(location: Option<Location>, message: String) -> Error {
    Error::Config {
        location,
        message,
        help: None,
    }
}

/// A profile named by a string: a built-in name, or a `.toml` path relative to `dir`.
fn load_named(reference: &str, dir: &Path, at: Option<Location>) -> Result<Layer> {
    let (file, dir, label) = if reference.ends_with(".toml") {
        let path = dir.join(reference);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            config(
                at.clone(),
                format!("machine profile `{}` cannot be read: {e}", path.display()),
            )
        })?;
        let label = path.display().to_string();
        let dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        (SourceFile::new(path, text), dir, label)
    } else {
        let profile = builtin::get(reference).ok_or_else(|| {
            config(
                at.clone(),
                format!("no built-in machine profile named `{reference}`"),
            )
            .with_help(format!(
                "built in: {}; a profile file's path ends in `.toml`",
                builtin::names()
            ))
        })?;
        (
            SourceFile::new(profile.path, profile.text),
            PathBuf::from("."),
            format!("built-in profile `{reference}` ({})", profile.path),
        )
    };
    let doc = DeTable::parse(&file.text).map_err(|e| {
        config(
            e.span().map(|s| Location::new(file.clone(), s)),
            format!("machine profile: {}", e.message().trim()),
        )
    })?;
    let table: toml::Table = toml::from_str(&file.text).map_err(|e| {
        config(
            e.span().map(|s| Location::new(file.clone(), s)),
            format!("machine profile: {}", e.message().trim()),
        )
    })?;
    let mut locations = BTreeMap::new();
    let span = doc.span();
    let value = Spanned::new(span.clone(), DeValue::Table(doc.into_inner()));
    record(&value, "", &file, &mut locations);
    let de = toml::de::ValueDeserializer::from(value);
    RawMachine::deserialize(de).map_err(|e| {
        config(
            e.span().map(|s| Location::new(file.clone(), s)),
            format!("machine profile {label}: {}", e.message().trim()),
        )
    })?;
    Ok(Layer {
        table,
        locations,
        root: Some(Location::new(file.clone(), 0..0)),
        label,
        dir,
    })
}

/// The pipeline's own `[machine]` table.
fn inline_layer(table: &TableRef, base_dir: &Path) -> Result<Layer> {
    table.parse::<RawMachine>()?;
    let mut locations = BTreeMap::new();
    if !table.is_overridden()
        && let Some(doc) = table.file().toml()
        && let Some(value) = crate::pipeline::navigate_de(doc, table.path())
    {
        record(&value, "", table.file(), &mut locations);
    }
    let path: Vec<String> = table.path().iter().map(PathElem::to_string).collect();
    Ok(Layer {
        table: table.table.clone(),
        locations,
        root: table.location_of(None),
        label: format!("[{}] of {}", path.join("."), table.file().path.display()),
        dir: base_dir.to_path_buf(),
    })
}

/// Records where every key and array element below `value` is written.
fn record(
    value: &Spanned<DeValue<'_>>,
    prefix: &str,
    file: &Arc<SourceFile>,
    out: &mut BTreeMap<String, Location>,
) {
    let join = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match value.get_ref() {
        DeValue::Table(t) => {
            for (k, v) in t {
                let path = join(k.get_ref());
                out.insert(path.clone(), Location::new(file.clone(), k.span()));
                record(v, &path, file, out);
            }
        }
        DeValue::Array(a) => {
            for (i, v) in a.iter().enumerate() {
                let path = join(&i.to_string());
                out.insert(path.clone(), Location::new(file.clone(), v.span()));
                record(v, &path, file, out);
            }
        }
        _ => {}
    }
}

/// Keys of which a profile gives one: setting one in an override drops the others.
const ALTERNATIVES: &[(&str, &[&str])] = &[
    ("motion", &["junction_deviation", "jerk"]),
    ("bed", &["shape", "size", "diameter"]),
    ("first_layer", &["speed", "speed_factor"]),
];

/// Merges `over` into `base`: tables key by key, `tools` tool by tool, `true` for a
/// switchable feature keeps the base's table, anything else replaces.
fn merge_tables(base: &mut toml::Table, over: toml::Table, path: &str) {
    for (_, group) in ALTERNATIVES.iter().filter(|(p, _)| *p == path) {
        if group.iter().any(|k| over.contains_key(*k)) {
            for k in group.iter().filter(|k| !over.contains_key(**k)) {
                base.remove(*k);
            }
        }
    }
    for (key, value) in over {
        let child = if path.is_empty() {
            key.clone()
        } else {
            format!("{path}.{key}")
        };
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_tables(b, o, &child),
            (Some(toml::Value::Table(_)), toml::Value::Boolean(true)) => {}
            (Some(toml::Value::Array(b)), toml::Value::Array(o)) if child == "tools" => {
                for (i, item) in o.into_iter().enumerate() {
                    match (b.get_mut(i), item) {
                        (Some(toml::Value::Table(bt)), toml::Value::Table(ot)) => {
                            merge_tables(bt, ot, &format!("{child}.{i}"))
                        }
                        (Some(slot), item) => *slot = item,
                        (None, item) => b.push(item),
                    }
                }
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Errors at the place each merged key was written.
struct Check<'a> {
    locations: &'a BTreeMap<String, Location>,
    root: Option<Location>,
    label: String,
}

impl Check<'_> {
    /// An error at `path`, or at the nearest enclosing key that is written, or at the
    /// profile itself.
    fn err(&self, path: &str, message: impl Into<String>) -> Error {
        let mut p = path;
        let location = loop {
            if let Some(l) = self.locations.get(p) {
                break Some(l.clone());
            }
            match p.rsplit_once('.') {
                Some((head, _)) => p = head,
                None => break self.root.clone(),
            }
        };
        config(location, format!("{}: {path}: {}", self.label, message.into()))
    }

    fn required<T>(&self, v: Option<T>, path: &str, what: &str) -> Result<T> {
        v.ok_or_else(|| self.err(path, format!("missing: {what}")))
    }

    fn positive(&self, v: f64, path: &str) -> Result<f64> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(path, format!("must be a positive number, not {v}")))
        }
    }

    fn within(&self, v: f64, lo: f64, hi: f64, path: &str, unit: &str) -> Result<f64> {
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(self.err(path, format!("must lie in {lo}..={hi} {unit}, not {v}")))
        }
    }

    fn axes(&self, a: RawAxes, path: &str) -> Result<Axes> {
        let get = |v: Option<f64>, k: &str| -> Result<f64> {
            let p = format!("{path}.{k}");
            self.positive(self.required(v, &p, "a value for every axis x, y, z, e")?, &p)
        };
        Ok(Axes {
            x: get(a.x, "x")?,
            y: get(a.y, "y")?,
            z: get(a.z, "z")?,
            e: get(a.e, "e")?,
        })
    }

    fn template(
        &self,
        text: Option<String>,
        path: &str,
        kind: TemplateKind,
        tools: usize,
    ) -> Result<Template> {
        let t = Template::new(text.unwrap_or_default());
        t.check(kind, tools).map_err(|e| self.err(path, e.message))?;
        Ok(t)
    }
}

fn validate(raw: RawMachine, c: &Check<'_>) -> Result<Machine> {
    let name = c.required(raw.name, "name", "the profile's name")?;
    if name.trim().is_empty() {
        return Err(c.err("name", "must not be empty"));
    }
    let flavor = c.required(
        raw.flavor,
        "flavor",
        "how the firmware changes material: \"tool-change\", \"marlin-mixing\" or \"reprap-mixing\"",
    )?;
    let firmware = match (flavor, raw.firmware) {
        (Flavor::MarlinMixing, Some(Firmware::RepRapFirmware))
        | (Flavor::ReprapMixing, Some(Firmware::Marlin)) => {
            return Err(c.err(
                "firmware",
                format!("the `{}` flavor is for another firmware", flavor.name()),
            ));
        }
        (_, Some(f)) => f,
        (Flavor::ReprapMixing, None) => Firmware::RepRapFirmware,
        (_, None) => Firmware::Marlin,
    };

    let raw_bed = c.required(raw.bed, "bed", "the [bed] table (size or diameter, max_height)")?;
    let shape = match (raw_bed.shape, raw_bed.size, raw_bed.diameter) {
        (Some(RawShape::Circle), Some(_), _)
        | (Some(RawShape::Rectangle), _, Some(_))
        | (None, Some(_), Some(_)) => {
            return Err(c.err(
                "bed",
                "a rectangular bed has `size = [x, y]`, a circular one `diameter`: give one",
            ));
        }
        (Some(RawShape::Rectangle) | None, Some(size), None) => {
            c.positive(size[0], "bed.size")?;
            c.positive(size[1], "bed.size")?;
            BedShape::Rectangle { size }
        }
        (Some(RawShape::Circle) | None, None, Some(d)) => BedShape::Circle {
            diameter: c.positive(d, "bed.diameter")?,
        },
        (_, None, None) => {
            return Err(c.err(
                "bed.size",
                "missing: `size = [x, y]` (mm), or `diameter` for a round bed",
            ));
        }
    };
    let origin = raw_bed.origin.unwrap_or(match shape {
        BedShape::Rectangle { .. } => BedOrigin::FrontLeft,
        BedShape::Circle { .. } => BedOrigin::Centre,
    });
    let max_height = c.positive(
        c.required(
            raw_bed.max_height,
            "bed.max_height",
            "how high the machine builds (mm)",
        )?,
        "bed.max_height",
    )?;
    let bed = Bed {
        shape,
        origin,
        max_height,
    };
    let placement = match raw.placement.unwrap_or(RawPlacement::Centre) {
        RawPlacement::Centre => BedPlacement::Centre,
        RawPlacement::At(p) => {
            if !bed.contains(Point2::new(p[0], p[1]), 0.0) {
                return Err(c.err(
                    "placement",
                    format!("[{}, {}] is not on the {} bed", p[0], p[1], bed.describe()),
                ));
            }
            BedPlacement::At(p)
        }
    };

    let nozzle_diameter = c.within(
        raw.nozzle_diameter.unwrap_or(0.4),
        0.05,
        3.0,
        "nozzle_diameter",
        "mm",
    )?;
    let filament_diameter = c.within(
        raw.filament_diameter.unwrap_or(1.75),
        0.5,
        5.0,
        "filament_diameter",
        "mm",
    )?;
    let bed_temperature = c.within(
        raw.bed_temperature.unwrap_or(0.0),
        0.0,
        MAX_BED_TEMPERATURE,
        "bed_temperature",
        "°C",
    )?;
    let first_layer_bed_temperature = c.within(
        raw.first_layer_bed_temperature.unwrap_or(bed_temperature),
        0.0,
        MAX_BED_TEMPERATURE,
        "first_layer_bed_temperature",
        "°C",
    )?;

    let raw_tools = c.required(
        raw.tools,
        "tools",
        "the tool table, one [[tools]] per tool or mixing channel",
    )?;
    if raw_tools.is_empty() {
        return Err(c.err("tools", "a machine has at least one tool"));
    }
    let mut tools = Vec::new();
    let mut seen = BTreeSet::new();
    for (i, t) in raw_tools.into_iter().enumerate() {
        let p = |k: &str| format!("tools.{i}.{k}");
        if let Some(m) = &t.material
            && !seen.insert(m.clone())
        {
            return Err(c.err(&p("material"), format!("`{m}` is carried by an earlier tool too")));
        }
        let nozzle = c.within(
            c.required(
                t.nozzle_temperature,
                &p("nozzle_temperature"),
                "the printing temperature (°C)",
            )?,
            1.0,
            MAX_NOZZLE_TEMPERATURE,
            &p("nozzle_temperature"),
            "°C",
        )?;
        let first = c.within(
            t.first_layer_temperature.unwrap_or(nozzle),
            1.0,
            MAX_NOZZLE_TEMPERATURE,
            &p("first_layer_temperature"),
            "°C",
        )?;
        let standby = t
            .standby_temperature
            .map(|s| {
                c.within(
                    s,
                    0.0,
                    nozzle.max(first),
                    &p("standby_temperature"),
                    "°C (at most the printing temperature)",
                )
            })
            .transpose()?;
        if flavor == Flavor::ToolChange && standby.is_none() {
            return Err(c.err(
                &p("standby_temperature"),
                "missing: the temperature the tool waits at while another prints (°C)",
            ));
        }
        if let Some(axis) = &t.axis
            && !(axis.len() == 1 && axis.chars().all(|ch| ch.is_ascii_uppercase()))
        {
            return Err(c.err(&p("axis"), format!("`{axis}` is not an axis letter (X, U, ...)")));
        }
        if let Some(axis) = &t.y_axis
            && !(axis.len() == 1 && axis.chars().all(|ch| ch.is_ascii_uppercase()))
        {
            return Err(c.err(
                &p("y_axis"),
                format!("`{axis}` is not an axis letter (Y, V, ...)"),
            ));
        }
        let envelope = t.envelope.map(|e| c.positive(e, &p("envelope"))).transpose()?;
        let home = match t.home {
            Some([x, y]) if x.is_finite() && y.is_finite() => Some([x, y]),
            Some(_) => return Err(c.err(&p("home"), "must be two finite numbers [x, y] (mm)")),
            None => None,
        };
        tools.push(ToolSlot {
            material: t.material,
            nozzle_temperature: nozzle,
            first_layer_temperature: first,
            standby_temperature: standby,
            name: t.name,
            axis: t.axis,
            y_axis: t.y_axis,
            home,
            envelope,
        });
    }

    let raw_fan = raw.fan.unwrap_or_default();
    let fan = Fan {
        speed: c.within(raw_fan.speed.unwrap_or(100.0), 0.0, 100.0, "fan.speed", "%")?,
        first_layer: raw_fan.first_layer.unwrap_or(false),
        full_speed_layer: raw_fan.full_speed_layer.unwrap_or(1),
    };
    let raw_first = raw.first_layer.unwrap_or_default();
    let max_layer_height = c.within(
        raw.max_layer_height.unwrap_or(0.75 * nozzle_diameter),
        0.01,
        nozzle_diameter,
        "max_layer_height",
        "mm (at most the nozzle's bore)",
    )?;
    let first_layer = FirstLayer {
        height: raw_first
            .height
            .map(|h| {
                c.within(
                    h,
                    0.01,
                    max_layer_height,
                    "first_layer.height",
                    "mm (at most max_layer_height)",
                )
            })
            .transpose()?,
        speed: match (raw_first.speed, raw_first.speed_factor) {
            (Some(_), Some(_)) => {
                return Err(c.err("first_layer", "give `speed` (mm/s) or `speed_factor`, not both"));
            }
            (Some(s), None) => FirstLayerSpeed::Speed(c.positive(s, "first_layer.speed")?),
            (None, Some(f)) => {
                FirstLayerSpeed::Factor(c.within(f, 0.05, 1.0, "first_layer.speed_factor", "")?)
            }
            (None, None) => FirstLayerSpeed::Factor(0.5),
        },
    };
    let raw_retraction = raw.retraction.unwrap_or_default();
    let length = c.within(
        raw_retraction.length.unwrap_or(1.0),
        0.0,
        30.0,
        "retraction.length",
        "mm",
    )?;
    let retraction = Retraction {
        length,
        tool_change_length: c.within(
            raw_retraction.tool_change_length.unwrap_or(length),
            0.0,
            100.0,
            "retraction.tool_change_length",
            "mm",
        )?,
        speed: c.positive(raw_retraction.speed.unwrap_or(35.0), "retraction.speed")?,
        z_hop: c.within(
            raw_retraction.z_hop.unwrap_or(0.0),
            0.0,
            10.0,
            "retraction.z_hop",
            "mm",
        )?,
    };
    let travel_speed = c.positive(raw.travel_speed.unwrap_or(150.0), "travel_speed")?;

    let raw_motion = c.required(
        raw.motion,
        "motion",
        "the [motion] table (accelerations, junction_deviation or jerk)",
    )?;
    let print_acceleration = c.positive(
        c.required(
            raw_motion.print_acceleration,
            "motion.print_acceleration",
            "mm/s²",
        )?,
        "motion.print_acceleration",
    )?;
    let cornering = match (raw_motion.junction_deviation, raw_motion.jerk) {
        (Some(_), Some(_)) => {
            return Err(c.err("motion", "give `junction_deviation` or `jerk`, not both"));
        }
        (Some(_), None) if firmware == Firmware::RepRapFirmware => {
            return Err(c.err(
                "motion.junction_deviation",
                "RepRapFirmware corners by jerk (M566): give `jerk = { x, y, z, e }` (mm/s)",
            ));
        }
        (Some(jd), None) => {
            Cornering::JunctionDeviation(c.within(jd, 0.001, 1.0, "motion.junction_deviation", "mm")?)
        }
        (None, Some(j)) => Cornering::Jerk(c.axes(j, "motion.jerk")?),
        (None, None) => {
            return Err(c.err(
                "motion.junction_deviation",
                "missing: how the firmware corners, `junction_deviation` (Marlin) or `jerk = { x, y, z, e }`",
            ));
        }
    };
    let motion = Motion {
        print_acceleration,
        travel_acceleration: c.positive(
            raw_motion.travel_acceleration.unwrap_or(print_acceleration),
            "motion.travel_acceleration",
        )?,
        retract_acceleration: c.positive(
            raw_motion.retract_acceleration.unwrap_or(print_acceleration),
            "motion.retract_acceleration",
        )?,
        cornering,
        max_speed: raw_motion
            .max_speed
            .map(|a| c.axes(a, "motion.max_speed"))
            .transpose()?,
        max_acceleration: raw_motion
            .max_acceleration
            .map(|a| c.axes(a, "motion.max_acceleration"))
            .transpose()?,
    };

    let skirt = match raw.skirt {
        None | Some(Switch::Off) => None,
        Some(Switch::On) => {
            return Err(c.err(
                "skirt",
                "`true` needs a base profile's [skirt], or give the table",
            ));
        }
        Some(Switch::Table(s)) => {
            let loops = s.loops.unwrap_or(1);
            if loops == 0 {
                return Err(c.err("skirt.loops", "at least one loop (or `skirt = false`)"));
            }
            let layers = s.layers.unwrap_or(1);
            if layers == 0 {
                return Err(c.err("skirt.layers", "at least one layer (or `skirt = false`)"));
            }
            Some(Skirt {
                loops,
                distance: c.within(s.distance.unwrap_or(3.0), 0.0, 100.0, "skirt.distance", "mm")?,
                layers,
            })
        }
    };
    let prime_line = match raw.prime_line {
        None | Some(Switch::Off) => None,
        Some(Switch::On) => {
            return Err(c.err(
                "prime_line",
                "`true` needs a base profile's [prime_line], or give the table",
            ));
        }
        Some(Switch::Table(p)) => Some(PrimeLine {
            length: c.positive(
                c.required(p.length, "prime_line.length", "mm")?,
                "prime_line.length",
            )?,
            width: c.within(
                p.width.unwrap_or(nozzle_diameter * 1.5),
                nozzle_diameter * 0.5,
                nozzle_diameter * 3.0,
                "prime_line.width",
                "mm",
            )?,
        }),
    };
    let wipe_tower = match raw.wipe_tower {
        None | Some(Switch::Off) => None,
        Some(Switch::On) => {
            return Err(c.err(
                "wipe_tower",
                "`true` needs a base profile's [wipe_tower], or give the table",
            ));
        }
        Some(Switch::Table(w)) => {
            let size = c.required(w.size, "wipe_tower.size", "the footprint [x, y] (mm)")?;
            let min = 6.0 * nozzle_diameter;
            c.within(size[0], min, 1000.0, "wipe_tower.size", "mm")?;
            c.within(size[1], min, 1000.0, "wipe_tower.size", "mm")?;
            if let Some(p) = w.position {
                let b = BBox2 {
                    min: Point2::new(p[0], p[1]),
                    max: Point2::new(p[0] + size[0], p[1] + size[1]),
                };
                if !bed.contains_box(&b, 0.0) {
                    return Err(c.err(
                        "wipe_tower.position",
                        format!(
                            "a {} x {} mm tower at [{}, {}] is not on the {} bed",
                            size[0],
                            size[1],
                            p[0],
                            p[1],
                            bed.describe()
                        ),
                    ));
                }
            }
            Some(WipeTower {
                position: w.position,
                size,
                purge_volume: match (flavor.is_mixing(), w.purge_volume) {
                    (true, Some(_)) => {
                        return Err(c.err(
                            "wipe_tower.purge_volume",
                            "a mixing head purges `mixer.transition_volume` after each mix change; remove this key",
                        ));
                    }
                    (true, None) => 0.0,
                    (false, v) => c.within(
                        c.required(v, "wipe_tower.purge_volume", "mm³ purged after each tool change")?,
                        0.0,
                        10_000.0,
                        "wipe_tower.purge_volume",
                        "mm³",
                    )?,
                },
            })
        }
    };
    let mixer = match (flavor.is_mixing(), raw.mixer) {
        (true, Some(m)) => {
            let transition_volume = c.within(
                c.required(
                    m.transition_volume,
                    "mixer.transition_volume",
                    "mm³ purged after a mix change",
                )?,
                0.0,
                10_000.0,
                "mixer.transition_volume",
                "mm³",
            )?;
            if transition_volume > 0.0 && wipe_tower.is_none() {
                return Err(c.err(
                    "mixer.transition_volume",
                    "the transition is purged on the wipe tower: add a [wipe_tower] with its size",
                ));
            }
            let blend_below = c.within(m.blend_below.unwrap_or(0.0), 0.0, 1.0, "mixer.blend_below", "")?;
            Some(Mixer {
                transition_volume,
                blend_below,
            })
        }
        (true, None) => {
            return Err(c.err(
                "mixer",
                "missing: a mixing head's [mixer] with transition_volume (mm³ purged after a mix change)",
            ));
        }
        (false, Some(_)) => return Err(c.err("mixer", "only a mixing flavor has a mixer")),
        (false, None) => None,
    };

    let raw_gcode = raw.gcode.unwrap_or_default();
    let n = tools.len();
    let gcode = Templates {
        start: c.template(raw_gcode.start, "gcode.start", TemplateKind::Start, n)?,
        end: c.template(raw_gcode.end, "gcode.end", TemplateKind::End, n)?,
        tool_change: c.template(
            raw_gcode.tool_change.or_else(|| Some("T{next_tool}".into())),
            "gcode.tool_change",
            TemplateKind::ToolChange,
            n,
        )?,
    };

    let motion_systems = raw.motion_systems.unwrap_or(1);
    check_motion_systems(c, motion_systems, firmware, flavor, &tools)?;
    Ok(Machine {
        name,
        motion_systems,
        description: raw.description.unwrap_or_default(),
        flavor,
        firmware,
        bed,
        placement,
        nozzle_diameter,
        max_layer_height,
        filament_diameter,
        tools,
        bed_temperature,
        first_layer_bed_temperature,
        fan,
        first_layer,
        retraction,
        travel_speed,
        motion,
        skirt,
        prime_line,
        wipe_tower,
        mixer,
        gcode,
        origin: MachineOrigin::default(),
    })
}

/// Two motion systems: a RepRapFirmware tool changer whose two tools each have their
/// own X and Y axis letters and envelope.
fn check_motion_systems(
    c: &Check<'_>,
    n: usize,
    firmware: Firmware,
    flavor: Flavor,
    tools: &[ToolSlot],
) -> Result<()> {
    match n {
        1 => return Ok(()),
        2 => {}
        _ => {
            return Err(c.err(
                "motion_systems",
                format!("must be 1 or 2 (RepRapFirmware 3.5 runs two), not {n}"),
            ));
        }
    }
    if firmware != Firmware::RepRapFirmware {
        return Err(c.err(
            "motion_systems",
            "several motion systems in one job are a RepRapFirmware 3.5 feature (M596): set firmware = \"reprapfirmware\"",
        ));
    }
    if flavor != Flavor::ToolChange || tools.len() != 2 {
        return Err(c.err(
            "motion_systems",
            format!(
                "two motion systems drive two tools of a tool-change machine, one each; this profile is {} with {} tools",
                flavor.name(),
                tools.len()
            ),
        ));
    }
    let mut letters: Vec<&str> = Vec::new();
    for (i, t) in tools.iter().enumerate() {
        let p = |k: &str| format!("tools.{i}.{k}");
        for (key, v) in [("axis", &t.axis), ("y_axis", &t.y_axis)] {
            let Some(v) = v else {
                return Err(c.err(
                    &p(key),
                    "missing: each motion system's head names its axis letters",
                ));
            };
            if ["Z", "E"].contains(&v.as_str()) || letters.contains(&v.as_str()) {
                return Err(c.err(
                    &p(key),
                    format!("`{v}` is not free: each head moves on axes of its own, Z is shared"),
                ));
            }
            letters.push(v);
        }
        if t.envelope.is_none() {
            return Err(c.err(
                &p("envelope"),
                "missing: the radius (mm) around the nozzle that the other head must keep out of",
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn named(reference: &str, dir: &Path) -> Result<Machine> {
        resolve(
            &MachineSpec::Named {
                reference: reference.into(),
                at: None,
            },
            dir,
        )
    }

    #[test]
    fn every_builtin_profile_is_valid_and_named_after_itself() {
        for p in builtin::PROFILES {
            let m = named(p.name, Path::new(".")).unwrap_or_else(|e| panic!("{}: {e}", p.name));
            assert_eq!(m.name, p.name);
            assert!(!m.description.is_empty(), "{}", p.name);
            assert!(m.tools.len() >= 2, "{}", p.name);
        }
    }

    #[test]
    fn a_file_extends_a_builtin_key_by_key() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(
            dir.path().join("mine.toml"),
            "base = \"marlin-toolchanger-2\"\nname = \"mine\"\n[bed]\nmax_height = 100.0\n\
             [[tools]]\nmaterial = \"pla\"\n[[tools]]\nnozzle_temperature = 250\n",
        )
        .expect("write");
        let base = named("marlin-toolchanger-2", Path::new(".")).expect("base");
        let m = named("mine.toml", dir.path()).expect("extends");
        assert_eq!(m.name, "mine");
        assert_eq!(m.bed.max_height, 100.0);
        assert_eq!(m.bed.shape, base.bed.shape, "the rest of [bed] is the base's");
        assert_eq!(m.tools[0].material.as_deref(), Some("pla"));
        assert_eq!(m.tools[0].nozzle_temperature, base.tools[0].nozzle_temperature);
        assert_eq!(m.tools[1].nozzle_temperature, 250.0);
        assert_eq!(m.tools[1].standby_temperature, base.tools[1].standby_temperature);
    }

    #[test]
    fn errors_name_the_file_line_and_field() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bad.toml");
        std::fs::write(
            &path,
            "base = \"rrf-idex-2\"\nname = \"bad\"\n\n[[tools]]\nnozzle_temperature = -5\n",
        )
        .expect("write");
        let e = named("bad.toml", dir.path()).expect_err("negative temperature");
        let loc = e.location().expect("located");
        assert_eq!(loc.file.path, path);
        assert_eq!(loc.line_col(), (5, 1), "{e}");
        assert!(e.to_string().contains("tools.0.nozzle_temperature"), "{e}");

        std::fs::write(&path, "base = \"rrf-idex-2\"\n[bed]\nsize = \"big\"\n").expect("write");
        let e = named("bad.toml", dir.path()).expect_err("wrong type");
        assert_eq!(e.location().expect("located").line_col().0, 3, "{e}");

        std::fs::write(
            &path,
            "base = \"rrf-idex-2\"\n[motion]\njunction_deviation = 0.02\n",
        )
        .expect("write");
        let e = named("bad.toml", dir.path()).expect_err("RRF has no junction deviation");
        assert_eq!(e.location().expect("located").line_col().0, 3, "{e}");
        assert!(e.to_string().contains("M566"), "{e}");

        std::fs::write(&path, "base = \"rrf-idex-2\"\n[gcode]\nstart = \"M140 S{bed}\"\n").expect("write");
        let e = named("bad.toml", dir.path()).expect_err("unknown variable");
        assert_eq!(e.location().expect("located").line_col().0, 3, "{e}");
        assert!(e.to_string().contains("{bed}"), "{e}");

        std::fs::write(&path, "name = \"x\"\nflavor = \"tool-change\"\n").expect("write");
        let e = named("bad.toml", dir.path()).expect_err("no bed");
        assert!(e.to_string().contains("bed: missing"), "{e}");

        let e = named("nonesuch", dir.path()).expect_err("unknown name");
        assert!(e.help().is_some_and(|h| h.contains("marlin-mixing-2in1")), "{e}");
    }

    #[test]
    fn a_base_that_extends_itself_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("a.toml"), "base = \"b.toml\"\n").expect("write");
        std::fs::write(dir.path().join("b.toml"), "base = \"a.toml\"\n").expect("write");
        let e = named("a.toml", dir.path()).expect_err("cycle");
        assert!(e.to_string().contains("extends itself"), "{e}");
    }

    #[test]
    fn alternatives_replace_each_other() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(
            dir.path().join("round.toml"),
            "base = \"marlin-mixing-2in1\"\n[bed]\ndiameter = 180.0\norigin = \"centre\"\n\
             [motion]\njerk = { x = 10, y = 10, z = 0.3, e = 5 }\n[first_layer]\nspeed = 15\n",
        )
        .expect("write");
        let m = named("round.toml", dir.path()).expect("valid");
        assert_eq!(m.bed.shape, BedShape::Circle { diameter: 180.0 });
        assert!(matches!(m.motion.cornering, Cornering::Jerk(_)));
        assert_eq!(m.first_layer.speed, FirstLayerSpeed::Speed(15.0));
    }

    #[test]
    fn layer_heights_stay_within_what_the_nozzle_presses() {
        let dir = tempfile::tempdir().expect("tempdir");
        let m = named("marlin-toolchanger-2", dir.path()).expect("valid");
        assert_eq!((m.max_layer_height, m.first_layer.height), (0.3, Some(0.2)));
        for (text, field) in [
            ("max_layer_height = 0.5\n", "max_layer_height"),
            ("[first_layer]\nheight = 0.35\n", "first_layer.height"),
        ] {
            let path = dir.path().join("thick.toml");
            std::fs::write(&path, format!("base = \"marlin-toolchanger-2\"\n{text}")).expect("write");
            let e = named("thick.toml", dir.path()).expect_err("too thick");
            assert!(e.to_string().contains(field), "{e}");
        }
        // A finer nozzle takes limits of its own.
        let path = dir.path().join("fine.toml");
        std::fs::write(&path, "base = \"marlin-toolchanger-2\"\nnozzle_diameter = 0.25\nmax_layer_height = 0.18\n[first_layer]\nheight = 0.15\n").expect("write");
        let m = named("fine.toml", dir.path()).expect("valid");
        assert_eq!((m.max_layer_height, m.first_layer.height), (0.18, Some(0.15)));
    }

    #[test]
    fn two_motion_systems_need_reprapfirmware_and_a_head_each_with_its_axes() {
        let dir = tempfile::tempdir().expect("tempdir");
        let m = named("rrf-two-systems-2", dir.path()).expect("valid");
        assert_eq!(m.motion_systems, 2);
        assert_eq!(m.tools[1].axis.as_deref(), Some("U"));
        assert_eq!(m.tools[1].y_axis.as_deref(), Some("V"));
        assert_eq!(m.tools[1].envelope, Some(4.0));
        for (text, field) in [
            (
                "base = \"rrf-two-systems-2\"\nfirmware = \"marlin\"\n",
                "motion_systems",
            ),
            (
                "base = \"rrf-two-systems-2\"\nmotion_systems = 3\n",
                "motion_systems",
            ),
            (
                "base = \"rrf-two-systems-2\"\n[[tools]]\n[[tools]]\ny_axis = \"Y\"\n",
                "tools.1.y_axis",
            ),
            (
                "base = \"rrf-two-systems-2\"\n[[tools]]\n[[tools]]\naxis = \"Z\"\n",
                "tools.1.axis",
            ),
            ("base = \"rrf-idex-2\"\nmotion_systems = 2\n", "tools.0.y_axis"),
        ] {
            std::fs::write(dir.path().join("mms.toml"), text).expect("write");
            let e = named("mms.toml", dir.path()).expect_err(text);
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }
}
