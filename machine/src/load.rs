//! Reading a machine profile: the pipeline's `machine` key names a built-in profile or a
//! file, or holds an inline table; a profile may start from another with `base`, and
//! overrides it key by key (tables merge recursively, the `tools` array merges tool by
//! tool, anything else is replaced). Each layer's types are checked against its own
//! file, and the merged profile's values are checked with the place of the layer that
//! wrote them, so an error names the file, line and field that is wrong.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::check::{Check, config};
use super::raw::RawMachine;
use super::validate::validate;
use super::*;
use lamina_api::error::{Error, Result};
use lamina_api::reach::Reach;
use lamina_api::source::{Location, SourceFile};
use lamina_api::table::{PathElem, TableRef};

/// How deep `base` chains may go, which also stops cycles that change names.
const MAX_BASE_DEPTH: usize = 8;

/// What a pipeline's `machine` key says.
#[derive(Debug, Clone)]
pub enum MachineSpec {
    /// A built-in profile's name, or a path ending in `.toml`, relative to the pipeline.
    Named { reference: String, at: Option<Location> },
    /// An inline table, perhaps with `base`.
    Inline(TableRef),
}

/// The built-in profile `name`, resolved and validated (it reads no file).
pub fn builtin(name: &str) -> Result<Machine> {
    let spec = MachineSpec::Named {
        reference: name.to_string(),
        at: None,
    };
    resolve(&spec, Path::new("."), &Reach::folder(Path::new(".")))
}

/// Reads, merges and validates the machine a pipeline names; relative paths resolve
/// against `base_dir` (the pipeline's folder), and profile files are read within
/// `reach` only.
pub fn resolve(spec: &MachineSpec, base_dir: &Path, reach: &Reach) -> Result<Machine> {
    let (top, at) = match spec {
        MachineSpec::Named { reference, at } => {
            (load_named(reference, base_dir, reach, at.clone())?, at.clone())
        }
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
        let next = load_named(reference, &last.dir, reach, last.locations.get("base").cloned())?;
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

/// A profile named by a string: a built-in name, or a `.toml` path relative to `dir`
/// (within `reach`).
fn load_named(reference: &str, dir: &Path, reach: &Reach, at: Option<Location>) -> Result<Layer> {
    let (file, dir, label) = if reference.ends_with(".toml") {
        let path = dir.join(reference);
        let text = reach.read_text(&path).map_err(|e| {
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
    if let Some(value) = table.written() {
        record(&value, "", table.file(), &mut locations);
    }
    let path: Vec<String> = table.path().iter().map(PathElem::to_string).collect();
    Ok(Layer {
        table: table.values().clone(),
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
            &Reach::folder(dir),
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

    #[test]
    fn kinematics_order_gantries_by_their_homes_and_keep_one_beam_to_one_system() {
        let dir = tempfile::tempdir().expect("tempdir");
        let m = named("rrf-dual-gantry-2", dir.path()).expect("valid");
        assert_eq!(m.kinematics.class, super::super::HeadClass::DualGantry);
        assert_eq!(m.kinematics.margin, 1.0);
        assert_eq!(m.tools[0].envelope, Some(15.0));
        let free = named("rrf-two-systems-2", dir.path()).expect("valid");
        assert_eq!(free.kinematics.class, super::super::HeadClass::Free);
        // A profile without the table: free heads, 1 mm.
        let idex = named("rrf-idex-2", dir.path()).expect("valid");
        assert_eq!(idex.kinematics, super::super::Kinematics::default());
        for (text, field) in [
            // Both gantries homing at the same Y have no order.
            (
                "base = \"rrf-dual-gantry-2\"\n[[tools]]\n[[tools]]\nhome = [300.0, 0.0]\n",
                "kinematics.class",
            ),
            (
                "base = \"rrf-two-systems-2\"\n[kinematics]\nclass = \"shared-beam\"\n",
                "kinematics.class",
            ),
            (
                "base = \"rrf-two-systems-2\"\n[kinematics]\nmargin = -1.0\n",
                "kinematics.margin",
            ),
            (
                "base = \"rrf-two-systems-2\"\n[kinematics]\nclass = \"robot\"\n",
                "unknown variant `robot`, expected one of `free`, `dual-gantry`, `shared-beam`",
            ),
        ] {
            std::fs::write(dir.path().join("kin.toml"), text).expect("write");
            let e = named("kin.toml", dir.path()).expect_err(text);
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }
}
