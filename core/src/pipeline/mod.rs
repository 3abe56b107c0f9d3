//! Pipeline files: the TOML a user writes to assemble stages, parsed with spans so that
//! every error names file, line and column, and `--set` overrides applied on top.

mod overrides;
mod read;
use lamina_api::table;

pub use overrides::Override;
pub use table::*;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use crate::error::Result;
use crate::limits::Limits;
use crate::machine::Machine;
use crate::model::Material;
use crate::reach::Reach;
use crate::source::SourceFile;
use crate::stage::StageKind;

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
    /// How many of the part the plate holds (1: the part alone). The copies are laid
    /// out beside the part's model in a grid, `copy_gap` apart, and each is the part's
    /// plan moved there: graded in the part's own frame, so every copy is the same.
    pub copies: usize,
    /// The gap between neighbouring copies (mm).
    pub copy_gap: f64,
    /// Columns of the copies' grid (along X); `None`: about as many as rows. One
    /// column lays the copies out front to back, as two gantries ordered in Y want.
    pub copy_columns: Option<usize>,
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

    /// The grid limit is `grid_samples` in the file and on the command line, and its
    /// former name `grid_cells` still reads; one of the two, not both.
    #[test]
    fn the_grid_limit_reads_by_its_name_and_its_former_name() {
        let with = |limits: &str| GOOD.replace("[slice]", &format!("[limits]\n{limits}\n[slice]"));
        let p = parse(&with("grid_samples = 54"), &[]).expect("grid_samples");
        assert_eq!(p.limits.grid_samples, 54);
        let p = parse(&with("grid_cells = 55"), &[]).expect("grid_cells");
        assert_eq!(p.limits.grid_samples, 55);
        let o: Override = "limits.grid_samples=56".parse().expect("override");
        let p = parse(&with("regions = 7"), std::slice::from_ref(&o)).expect("overridden");
        assert_eq!((p.limits.grid_samples, p.limits.regions), (56, 7));
        let e = parse(&with("grid_samples = 1\ngrid_cells = 2"), &[]).expect_err("both");
        assert!(e.to_string().contains("not both"), "{e}");
        let e = parse(&with("grid_sample = 1"), &[]).expect_err("a misspelling");
        assert!(e.to_string().contains("grid_sample"), "{e}");
        // The choices name the key as the file does.
        assert!(e.to_string().contains("`grid_samples`"), "{e}");
        assert!(!e.to_string().contains("grid_cells"), "{e}");
        // An error in the renamed key is placed at its value in the file, named as
        // the file names it.
        let text = with("regions = 7\ngrid_samples = \"many\"");
        let e = parse(&text, &[]).expect_err("a string");
        let at = e.location().expect("placed");
        assert_eq!(at.file.path, PathBuf::from("p.toml"));
        let line = text
            .lines()
            .position(|l| l.starts_with("grid_samples"))
            .expect("line");
        assert_eq!(at.line_col().0, line + 1, "{e}");
        assert_eq!(&text[at.span.start..at.span.end], "\"many\"", "{e}");
        let e = parse(&with("grid_cells = 2"), std::slice::from_ref(&o)).expect_err("both, one by --set");
        assert!(e.to_string().contains("not both"), "{e}");
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
