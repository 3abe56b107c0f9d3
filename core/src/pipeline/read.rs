//! Reading a pipeline file: its TOML, with `--set` overrides applied, checked table by
//! table (the machine, materials, parts, stage tables, outputs) so that an error points
//! at the key that is wrong.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use serde::Deserialize;

use super::overrides::paths_touch;
use super::{Override, PartSpec, Pipeline, model_spec};
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::machine::Machine;
use crate::machine::load::MachineSpec;
use crate::model::Material;
use crate::reach::Reach;
use crate::source::{Location, SourceFile, Span};
use crate::stage::StageKind;
use lamina_api::table::{MODEL_HOST_KEYS, PathElem, TableRef, key, toml_error};

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
    copies: Option<i64>,
    copy_gap: Option<f64>,
    copy_columns: Option<i64>,
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

/// The pipeline file being read: what every table's reference is made from.
struct Reader<'a> {
    file: &'a Arc<SourceFile>,
    overrides: &'a [Override],
}

impl Reader<'_> {
    /// The table at `path`, marked as overridden when a `--set` touches it.
    fn table(&self, path: Vec<PathElem>, table: toml::Table) -> TableRef {
        let overridden = self.overrides.iter().any(|o| paths_touch(&o.path, &path));
        TableRef::new(table, self.file.clone(), path, overridden)
    }

    /// The `machine` key: a built-in profile's name, a profile file, or a table,
    /// resolved and validated.
    fn machine(
        &self,
        value: toml::Value,
        root: &TableRef,
        base_dir: &std::path::Path,
        reach: &Reach,
    ) -> Result<Machine> {
        let spec = match value {
            toml::Value::String(reference) => MachineSpec::Named {
                reference,
                at: root.location_of(Some("machine")),
            },
            toml::Value::Table(t) => {
                MachineSpec::Inline(self.table(vec![key("machine")], t).with_host_keys(&[]))
            }
            _ => {
                return Err(root
                    .error_at(
                        "machine",
                        "must name a built-in profile, a `.toml` profile file, or be a table",
                    )
                    .with_help(format!("built-in profiles: {}", crate::machine::builtin::names())));
            }
        };
        crate::machine::resolve(&spec, base_dir, reach)
    }

    /// The `[materials]` tables, in the order they are written.
    fn materials(&self, raw: &toml::Table, root: &TableRef) -> Result<Vec<Material>> {
        let mut materials = Vec::new();
        for (name, value) in raw {
            let table = value
                .as_table()
                .cloned()
                .ok_or_else(|| root.error_at("materials", format!("`{name}` must be a table")))?;
            let tr = self
                .table(vec![key("materials"), key(name)], table)
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
        Ok(materials)
    }

    /// `[[parts]]` entry `i`: its materials by name, its own model and stage tables.
    fn part(&self, i: usize, t: &toml::Table, materials: &[Material]) -> Result<PartSpec> {
        let path = vec![key("parts"), PathElem::Index(i)];
        let tr = self.table(path.clone(), t.clone()).with_host_keys(&[]);
        let p: RawPart = tr.parse()?;
        let sub = |k: &str, host: &'static [&'static str]| {
            t.get(k).and_then(|v| v.as_table()).map(|st| {
                let mut p = path.clone();
                p.push(key(k));
                self.table(p, st.clone()).with_host_keys(host)
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
        let copies = match p.copies {
            None => 1,
            Some(n) if (1..=MAX_COPIES as i64).contains(&n) => n as usize,
            Some(_) => {
                return Err(tr.error_at("copies", format!("must be a whole number from 1 to {MAX_COPIES}")));
            }
        };
        let copy_gap = match p.copy_gap {
            None => DEFAULT_COPY_GAP,
            Some(g) if g.is_finite() && (0.0..=1000.0).contains(&g) => g,
            Some(_) => return Err(tr.error_at("copy_gap", "must be a distance from 0 to 1000 mm")),
        };
        let copy_columns = match p.copy_columns {
            None => None,
            Some(n) if (1..=MAX_COPIES as i64).contains(&n) => Some(n as usize),
            Some(_) => {
                return Err(tr.error_at(
                    "copy_columns",
                    format!("must be a whole number from 1 to {MAX_COPIES}"),
                ));
            }
        };
        Ok(PartSpec {
            name: p.name.unwrap_or_else(|| format!("part{i}")),
            materials: part_materials,
            model: sub("model", MODEL_HOST_KEYS).map(model_spec).transpose()?,
            mesh: p.mesh,
            family_at: match p.family_at {
                Some(at) if at.iter().all(|v| v.is_finite()) => Some(at),
                Some(_) => return Err(tr.error_at("family_at", "must be three finite numbers [x, y, z]")),
                None => None,
            },
            copies,
            copy_gap,
            copy_columns,
            discretise: sub("discretise", &["use"]),
            grade: sub("grade", &["use"]),
            table: Some(tr),
        })
    }

    /// The tables of the kinds a pipeline holds one of, by kind.
    fn stages(&self, raw: &mut RawPipeline) -> BTreeMap<StageKind, TableRef> {
        let mut stages = BTreeMap::new();
        for (kind, t) in [
            (StageKind::Orient, raw.orient.take()),
            (StageKind::Slice, raw.slice.take()),
            (StageKind::Sort, raw.sort.take()),
            (StageKind::Discretise, raw.discretise.take()),
            (StageKind::Grade, raw.grade.take()),
            (StageKind::Sequence, raw.sequence.take()),
            (StageKind::Plan, raw.plan.take()),
        ] {
            if let Some(t) = t {
                stages.insert(kind, self.table(vec![key(kind.name())], t));
            }
        }
        stages
    }

    /// `[[process]]` or `[[output]]` tables, in their order.
    fn list(&self, name: &str, tables: Vec<toml::Table>) -> Vec<TableRef> {
        tables
            .into_iter()
            .enumerate()
            .map(|(i, t)| self.table(vec![key(name), PathElem::Index(i)], t))
            .collect()
    }
}

/// The part a pipeline without `[[parts]]` makes: its model, all its materials.
fn whole_part(materials: &[Material]) -> PartSpec {
    PartSpec {
        name: "part".into(),
        materials: (0..materials.len()).collect(),
        model: None,
        mesh: None,
        family_at: None,
        copies: 1,
        copy_gap: DEFAULT_COPY_GAP,
        copy_columns: None,
        discretise: None,
        grade: None,
        table: None,
    }
}

/// Most copies of one part a pipeline may ask for.
pub const MAX_COPIES: usize = 256;
/// The gap between copies of a part on the plate (mm) when the pipeline gives none.
pub const DEFAULT_COPY_GAP: f64 = 10.0;

impl Pipeline {
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
        let reader = Reader {
            file: &file,
            overrides,
        };
        let root_ref = reader.table(Vec::new(), doc.clone()).with_host_keys(&[]);
        let mut raw: RawPipeline = root_ref.parse()?;
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
        let model = match raw.model.take() {
            Some(t) => Some(model_spec(
                reader
                    .table(vec![key("model")], t)
                    .with_host_keys(MODEL_HOST_KEYS),
            )?),
            None => None,
        };
        let machine = match raw.machine.take() {
            Some(value) => Some(reader.machine(value, &root_ref, &base_dir, &reach)?),
            None => None,
        };
        let materials = reader.materials(&raw.materials, &root_ref)?;
        let mut parts = raw
            .parts
            .iter()
            .enumerate()
            .map(|(i, t)| reader.part(i, t, &materials))
            .collect::<Result<Vec<_>>>()?;
        if materials.is_empty() {
            return Err(root_ref
                .error_at("materials", "the pipeline names no materials")
                .with_help("add e.g. [materials.red] colour = [255, 0, 0]"));
        }
        if parts.is_empty() {
            parts.push(whole_part(&materials));
        }
        if model.is_none() && parts.iter().any(|p| p.model.is_none()) {
            return Err(Error::config_at(
                Location::new(file.clone(), Span::default()),
                "no [model] table, and a part has no model of its own",
            ));
        }
        let stages = reader.stages(&mut raw);
        let process = reader.list("process", std::mem::take(&mut raw.process));
        let outputs = reader.list("output", std::mem::take(&mut raw.output));
        for t in &outputs {
            if let Some(path) = t.get("path").and_then(|v| v.as_str())
                && let Err(m) = crate::output::check_name(std::path::Path::new(path))
            {
                return Err(t.error_at("path", m));
            }
        }
        let name = raw.name.take().unwrap_or_else(|| {
            file.path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "pipeline".into())
        });
        let plugins = raw.plugins.iter().map(|p| base_dir.join(p)).collect();
        let limits = match raw.limits.take() {
            Some(t) => {
                // The table names the grid limit `grid_samples` (or, as before,
                // `grid_cells`); its serde form (the plugin wire's) keeps the former
                // name.
                const RENAMED: &[(&str, &str)] =
                    &[("grid_samples", lamina_api::limits::GRID_SAMPLES_FORMERLY)];
                reader
                    .table(vec![key("limits")], t)
                    .with_host_keys(&[])
                    .with_renamed_keys(RENAMED)
                    .parse()?
            }
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

fn parse_hex(h: &str) -> Option<[u8; 3]> {
    let h = h.strip_prefix('#')?;
    if h.len() != 6 || !h.is_ascii() {
        return None;
    }
    let c = |i: usize| u8::from_str_radix(&h[i..i + 2], 16).ok();
    Some([c(0)?, c(2)?, c(4)?])
}
