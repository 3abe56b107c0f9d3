//! Pipeline files: the TOML a user writes to assemble stages, parsed with spans so that
//! every error names file, line and column, and `--set` overrides applied on top.

mod overrides;
use lamina_api::table;

pub use overrides::Override;
use overrides::paths_touch;
pub use table::*;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::machine::Machine;
use crate::machine::load::MachineSpec;
use crate::model::Material;
use crate::reach::Reach;
use crate::source::{Location, SourceFile, Span};
use crate::stage::StageKind;

/// A material colour: `[r, g, b]` or `"#rrggbb"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum RawColour {
    Rgb([u8; 3]),
    Hex(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    colour: RawColour,
    layer_thickness: Option<f64>,
    #[serde(default)]
    #[expect(dead_code, reason = "documentation for the reader of the pipeline")]
    description: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPipeline {
    name: Option<String>,
    #[serde(default)]
    #[expect(dead_code, reason = "documentation for the reader of the pipeline")]
    description: Option<String>,
    #[serde(default)]
    plugins: Vec<String>,
    /// Refused: the command line's `--allow` widens where scripts are read.
    script_dirs: Option<toml::Value>,
    model: Option<toml::Table>,
    machine: Option<toml::Value>,
    #[serde(default)]
    materials: toml::Table,
    #[serde(default)]
    parts: Vec<toml::Table>,
    orient: Option<toml::Table>,
    slice: Option<toml::Table>,
    sort: Option<toml::Table>,
    discretise: Option<toml::Table>,
    grade: Option<toml::Table>,
    sequence: Option<toml::Table>,
    plan: Option<toml::Table>,
    #[serde(default)]
    process: Vec<toml::Table>,
    #[serde(default)]
    output: Vec<toml::Table>,
    limits: Option<toml::Table>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPart {
    name: Option<String>,
    materials: Option<Vec<String>>,
    mesh: Option<usize>,
    family_at: Option<[f64; 3]>,
    #[serde(default)]
    #[expect(dead_code, reason = "read through its TableRef")]
    model: Option<toml::Table>,
    #[serde(default)]
    #[expect(dead_code, reason = "read through its TableRef")]
    discretise: Option<toml::Table>,
    #[serde(default)]
    #[expect(dead_code, reason = "read through its TableRef")]
    grade: Option<toml::Table>,
}

/// How the `[model]` table places meshes on the bed; consumed by the host.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Placement {
    /// Keep the file's coordinates.
    Keep,
    /// Drop the lowest point to z = 0, keep x and y.
    #[default]
    Bed,
    /// Drop to z = 0 and centre x and y on the origin.
    Centre,
}

/// The unit a model file's coordinates are in; Lamina works in millimetres.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Units {
    Mm,
    Cm,
    M,
    In,
}

impl Units {
    /// Millimetres in one unit.
    pub fn millimetres(self) -> f64 {
        match self {
            Units::Mm => 1.0,
            Units::Cm => 10.0,
            Units::M => 1000.0,
            Units::In => 25.4,
        }
    }
}

/// A part as the pipeline describes it.
#[derive(Debug, Clone)]
pub struct PartSpec {
    pub name: String,
    /// Indices into [`Pipeline::materials`].
    pub materials: Vec<usize>,
    /// The part's own model; when absent, the pipeline's `[model]`.
    pub model: Option<ModelSpec>,
    /// Which mesh of the model; `None` takes all its meshes as one.
    pub mesh: Option<usize>,
    /// Selects the family containing this point (x, y at height z) and the families
    /// that overlap it layer after layer, instead of every family of the mesh.
    pub family_at: Option<[f64; 3]>,
    pub discretise: Option<TableRef>,
    pub grade: Option<TableRef>,
    pub table: Option<TableRef>,
}

/// A model table with the host's placement settings read out.
#[derive(Debug, Clone)]
pub struct ModelSpec {
    pub table: TableRef,
    /// `scale` as written: a factor on top of `units`.
    pub scale: Option<f64>,
    /// The unit of the file's coordinates as written.
    pub units: Option<Units>,
    pub place: Placement,
}

impl ModelSpec {
    /// What the model's coordinates are multiplied by to be millimetres.
    pub fn factor(&self) -> f64 {
        self.units.map_or(1.0, Units::millimetres) * self.scale.unwrap_or(1.0)
    }

    /// True when the pipeline says what size the model is (`scale` or `units`), which
    /// turns off the check for models that look like metres or micrometres.
    pub fn size_given(&self) -> bool {
        self.scale.is_some() || self.units.is_some()
    }
}

/// A parsed pipeline: what to make, from what, and with which stages.
#[derive(Debug, Clone)]
pub struct Pipeline {
    pub file: Arc<SourceFile>,
    /// Folder of the pipeline file; relative paths resolve against it.
    pub base_dir: PathBuf,
    pub name: String,
    /// Where the files the pipeline names may be read from: its folder, and what the
    /// command line allows besides (never what the pipeline says).
    pub reach: Reach,
    /// Dynamic plugin libraries the pipeline needs, resolved against `base_dir`: a
    /// declaration only, since a pipeline alone cannot make code run. The command line
    /// loads them (`--plugin`), and a run without them is refused.
    pub plugins: Vec<PathBuf>,
    pub model: Option<ModelSpec>,
    pub materials: Vec<Material>,
    pub parts: Vec<PartSpec>,
    /// Stage tables by kind (slice, sort, discretise, grade, sequence, plan).
    pub stages: BTreeMap<StageKind, TableRef>,
    /// `[[process]]` tables, one operation stage each, in the order they run.
    pub process: Vec<TableRef>,
    /// `[[output]]` tables, one exporter each.
    pub outputs: Vec<TableRef>,
    /// The machine the `machine` key names, resolved and validated.
    pub machine: Option<Machine>,
    /// The `[limits]` table: the resource limits every stage checks sizes against.
    pub limits: Limits,
}

impl Pipeline {
    /// What every stage of this pipeline is built with besides its own table.
    pub fn context(&self) -> crate::stage::PipelineContext<'_> {
        crate::stage::PipelineContext {
            machine: self.machine.as_ref(),
            reach: Some(&self.reach),
            limits: self.limits,
        }
    }

    /// Reads and parses a pipeline file, applying `--set` overrides; the files it names
    /// are read from its own folder only.
    pub fn load(path: &Path, overrides: &[Override]) -> Result<Pipeline> {
        Self::load_allowing(path, overrides, &[] as &[PathBuf])
    }

    /// [`load`](Self::load), the files it names read from its folder and `allowed`
    /// (folders or files the command line names).
    pub fn load_allowing(
        path: &Path,
        overrides: &[Override],
        allowed: &[impl AsRef<Path>],
    ) -> Result<Pipeline> {
        let file = SourceFile::read(path)?;
        let base_dir = path
            .parent()
            .map(Path::to_path_buf)
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or_else(|| PathBuf::from("."));
        let reach = Reach::folder(&base_dir).with(allowed);
        Self::parse_within(file, base_dir, reach, overrides)
    }

    /// Parses pipeline text; `base_dir` resolves relative paths, and the files named are
    /// read from it only.
    pub fn parse(file: Arc<SourceFile>, base_dir: PathBuf, overrides: &[Override]) -> Result<Pipeline> {
        let reach = Reach::folder(&base_dir);
        Self::parse_within(file, base_dir, reach, overrides)
    }

    /// [`parse`](Self::parse), the files named read within `reach`.
    pub fn parse_within(
        file: Arc<SourceFile>,
        base_dir: PathBuf,
        reach: Reach,
        overrides: &[Override],
    ) -> Result<Pipeline> {
        let doc: toml::Table = toml::from_str(&file.text).map_err(|e| toml_error(&file, &e))?;
        let mut root = toml::Value::Table(doc);
        for o in overrides {
            o.apply(&mut root)?;
        }
        let toml::Value::Table(doc) = root else {
            return Err(Error::config("pipeline root is not a table"));
        };
        let table_ref = |path: Vec<PathElem>, table: toml::Table| {
            let overridden = overrides.iter().any(|o| paths_touch(&o.path, &path));
            TableRef::new(table, file.clone(), path, overridden)
        };
        let root_ref = table_ref(Vec::new(), doc.clone()).with_host_keys(&[]);
        let raw: RawPipeline = root_ref.parse()?;
        if raw.script_dirs.is_some() {
            return Err(root_ref
                .error_at(
                    "script_dirs",
                    "a pipeline cannot widen the folders its scripts are read from",
                )
                .with_help(
                    "keep the scripts beside the pipeline, or name their folder on the command line with `--allow <folder>`",
                ));
        }

        let model = match raw.model {
            Some(t) => {
                let tr = table_ref(vec![key("model")], t).with_host_keys(MODEL_HOST_KEYS);
                Some(model_spec(tr)?)
            }
            None => None,
        };

        let machine = match raw.machine {
            None => None,
            Some(value) => {
                let machine_path = vec![key("machine")];
                let spec = match value {
                    toml::Value::String(reference) => MachineSpec::Named {
                        reference,
                        at: root_ref.location_of(Some("machine")),
                    },
                    toml::Value::Table(t) => {
                        MachineSpec::Inline(table_ref(machine_path, t).with_host_keys(&[]))
                    }
                    _ => {
                        return Err(root_ref
                            .error_at(
                                "machine",
                                "must name a built-in profile, a `.toml` profile file, or be a table",
                            )
                            .with_help(format!("built-in profiles: {}", crate::machine::builtin::names())));
                    }
                };
                Some(crate::machine::resolve(&spec, &base_dir, &reach)?)
            }
        };

        let mut materials = Vec::new();
        for (name, _) in &raw.materials {
            let tr = table_ref(
                vec![key("materials"), key(name)],
                raw.materials
                    .get(name)
                    .and_then(|v| v.as_table())
                    .cloned()
                    .ok_or_else(|| root_ref.error_at("materials", format!("`{name}` must be a table")))?,
            )
            .with_host_keys(&[]);
            let m: RawMaterial = tr.parse()?;
            let colour = match m.colour {
                RawColour::Rgb(c) => c,
                RawColour::Hex(h) => {
                    parse_hex(&h).ok_or_else(|| tr.error_at("colour", format!("`{h}` is not #rrggbb")))?
                }
            };
            if let Some(t) = m.layer_thickness
                && !(t.is_finite() && t > 0.0)
            {
                return Err(tr.error_at("layer_thickness", "must be a positive number of mm"));
            }
            materials.push(Material {
                name: name.clone(),
                colour,
                layer_thickness: m.layer_thickness,
            });
        }

        let mut parts = Vec::new();
        for (i, t) in raw.parts.iter().enumerate() {
            let path = vec![key("parts"), PathElem::Index(i)];
            let tr = table_ref(path.clone(), t.clone()).with_host_keys(&[]);
            let p: RawPart = tr.parse()?;
            let sub = |k: &str, host: &'static [&'static str]| {
                t.get(k).and_then(|v| v.as_table()).map(|st| {
                    let mut p = path.clone();
                    p.push(key(k));
                    table_ref(p, st.clone()).with_host_keys(host)
                })
            };
            let part_materials = match &p.materials {
                Some(names) => names
                    .iter()
                    .map(|n| {
                        materials.iter().position(|m| &m.name == n).ok_or_else(|| {
                            tr.error_at("materials", format!("no material named `{n}` in [materials]"))
                        })
                    })
                    .collect::<Result<Vec<_>>>()?,
                None => (0..materials.len()).collect(),
            };
            if part_materials.is_empty() {
                return Err(tr.error_at("materials", "a part needs at least one material"));
            }
            parts.push(PartSpec {
                name: p.name.unwrap_or_else(|| format!("part{i}")),
                materials: part_materials,
                model: sub("model", MODEL_HOST_KEYS).map(model_spec).transpose()?,
                mesh: p.mesh,
                family_at: match p.family_at {
                    Some(at) if at.iter().all(|v| v.is_finite()) => Some(at),
                    Some(_) => return Err(tr.error_at("family_at", "must be three finite numbers [x, y, z]")),
                    None => None,
                },
                discretise: sub("discretise", &["use"]),
                grade: sub("grade", &["use"]),
                table: Some(tr),
            });
        }
        if materials.is_empty() {
            return Err(root_ref
                .error_at("materials", "the pipeline names no materials")
                .with_help("add e.g. [materials.red] colour = [255, 0, 0]"));
        }
        if parts.is_empty() {
            parts.push(PartSpec {
                name: "part".into(),
                materials: (0..materials.len()).collect(),
                model: None,
                mesh: None,
                family_at: None,
                discretise: None,
                grade: None,
                table: None,
            });
        }
        if model.is_none() && parts.iter().any(|p| p.model.is_none()) {
            return Err(Error::config_at(
                Location::new(file.clone(), Span::default()),
                "no [model] table, and a part has no model of its own",
            ));
        }

        let mut stages = BTreeMap::new();
        for (kind, t) in [
            (StageKind::Orient, raw.orient),
            (StageKind::Slice, raw.slice),
            (StageKind::Sort, raw.sort),
            (StageKind::Discretise, raw.discretise),
            (StageKind::Grade, raw.grade),
            (StageKind::Sequence, raw.sequence),
            (StageKind::Plan, raw.plan),
        ] {
            if let Some(t) = t {
                stages.insert(kind, table_ref(vec![key(kind.name())], t));
            }
        }
        let process = raw
            .process
            .into_iter()
            .enumerate()
            .map(|(i, t)| table_ref(vec![key("process"), PathElem::Index(i)], t))
            .collect();
        let outputs = raw
            .output
            .into_iter()
            .enumerate()
            .map(|(i, t)| table_ref(vec![key("output"), PathElem::Index(i)], t))
            .collect();
        for t in &outputs {
            let t: &TableRef = t;
            if let Some(path) = t.get("path").and_then(|v| v.as_str())
                && let Err(m) = crate::output::check_name(std::path::Path::new(path))
            {
                return Err(t.error_at("path", m));
            }
        }
        let name = raw.name.unwrap_or_else(|| {
            file.path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "pipeline".into())
        });
        let plugins = raw.plugins.iter().map(|p| base_dir.join(p)).collect();
        let limits = match raw.limits {
            Some(t) => table_ref(vec![key("limits")], t).with_host_keys(&[]).parse()?,
            None => Limits::default(),
        };
        Ok(Pipeline {
            file,
            base_dir,
            reach,
            name,
            plugins,
            model,
            materials,
            parts,
            stages,
            process,
            outputs,
            machine,
            limits,
        })
    }
}

/// Reads the host's placement keys of a model table (`scale`, `units`, `place`), each
/// on its own so that an error points at the key that is wrong.
pub fn model_spec(table: TableRef) -> Result<ModelSpec> {
    let scale = match table.get("scale") {
        None => None,
        Some(v) => match v.as_float().or_else(|| v.as_integer().map(|i| i as f64)) {
            Some(s) if s.is_finite() && s > 0.0 => Some(s),
            _ => return Err(table.error_at("scale", "must be a positive number")),
        },
    };
    let units = match table.get("units") {
        None => None,
        Some(v) => Some(v.clone().try_into::<Units>().map_err(|_| {
            table
                .error_at("units", format!("{v} is not a unit"))
                .with_help("units = \"mm\", \"cm\", \"m\" or \"in\"")
        })?),
    };
    let place = match table.get("place") {
        None => Placement::default(),
        Some(v) => v.clone().try_into::<Placement>().map_err(|_| {
            table
                .error_at("place", format!("{v} is not a placement"))
                .with_help("place = \"bed\" (drop to z = 0), \"centre\" (and centre on the origin) or \"keep\" (the file's coordinates); a machine's `placement` sets where on its bed")
        })?,
    };
    Ok(ModelSpec {
        table,
        scale,
        units,
        place,
    })
}

fn parse_hex(h: &str) -> Option<[u8; 3]> {
    let h = h.strip_prefix('#')?;
    if h.len() != 6 || !h.is_ascii() {
        return None;
    }
    let c = |i: usize| u8::from_str_radix(&h[i..i + 2], 16).ok();
    Some([c(0)?, c(2)?, c(4)?])
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r##"
name = "t"
[model]
use = "cube"
size = 2.0

[materials.red]
colour = [255, 0, 0]
[materials.green]
colour = "#00ff00"
layer_thickness = 0.5

[slice]
use = "uniform"
thickness = 0.2

[[output]]
use = "json"
path = "out.json"
"##;

    fn parse(text: &str, overrides: &[Override]) -> Result<Pipeline> {
        Pipeline::parse(SourceFile::new("p.toml", text), PathBuf::from("."), overrides)
    }

    #[test]
    fn parses_a_pipeline() {
        let p = parse(GOOD, &[]).expect("parses");
        assert_eq!(p.materials.len(), 2);
        assert_eq!(p.materials[1].colour, [0, 255, 0]);
        assert_eq!(p.parts.len(), 1);
        assert_eq!(p.parts[0].materials, vec![0, 1]);
        assert_eq!(p.stages[&StageKind::Slice].use_name(), Some("uniform"));
        assert_eq!(p.outputs.len(), 1);
    }

    #[test]
    fn unknown_top_level_key_names_line_and_column() {
        let text = GOOD.replace("[slice]", "[slise]");
        let e = parse(&text, &[]).expect_err("must fail");
        let loc = e.location().expect("located");
        assert_eq!(loc.line_col(), (13, 2), "{e}");
    }

    #[test]
    fn stage_options_errors_point_at_key() {
        #[derive(Deserialize, Debug)]
        #[serde(deny_unknown_fields)]
        #[expect(dead_code, reason = "only parsed")]
        struct Opts {
            thickness: f64,
        }
        let text = GOOD.replace("thickness = 0.2", "thicknes = 0.2");
        let p = parse(&text, &[]).expect("parses");
        let e = p.stages[&StageKind::Slice]
            .parse::<Opts>()
            .expect_err("unknown key");
        let (line, col) = e.location().expect("located").line_col();
        assert_eq!((line, col), (15, 1), "{e}");
        let text = GOOD.replace("thickness = 0.2", "thickness = \"thin\"");
        let p = parse(&text, &[]).expect("parses");
        let e = p.stages[&StageKind::Slice]
            .parse::<Opts>()
            .expect_err("wrong type");
        assert_eq!(e.location().expect("located").line_col().0, 15, "{e}");
    }

    #[test]
    fn overrides_replace_values() {
        let o: Override = "slice.thickness=0.3".parse().expect("override");
        let p = parse(GOOD, &[o]).expect("parses");
        assert_eq!(
            p.stages[&StageKind::Slice]
                .get("thickness")
                .and_then(|v| v.as_float()),
            Some(0.3)
        );
        let o: Override = "output.0.path=other.json".parse().expect("override");
        let p = parse(GOOD, &[o]).expect("parses");
        assert_eq!(
            p.outputs[0].get("path").and_then(|v| v.as_str()),
            Some("other.json")
        );
    }

    #[test]
    fn unknown_material_in_part_is_located() {
        let text = format!("{GOOD}\n[[parts]]\nname = \"a\"\nmaterials = [\"blue\"]\n");
        let e = parse(&text, &[]).expect_err("unknown material");
        assert!(e.to_string().contains("blue"), "{e}");
        assert!(e.location().is_some());
    }
}
