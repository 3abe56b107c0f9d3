//! `work-cycles`: the fabrication sequence of an object whose material regions want
//! different layer thicknesses (cmpm-process-planning 4.1). Each part (or group of
//! parts) is a material region with its own thickness; the object is cut into blocks at
//! the regions' heights, each block is deposited in work cycles, and the sequence lists
//! every layer of every region in build order for the adaptive slicer to cut.

use std::collections::BTreeMap;

use lamina_api::stage::{AnyStage, Sequencer, StageConfig, StageInfo, StageKind};
use lamina_api::table::TableRef;
use lamina_api::{Error, MaterialRegion, Result, RunInfo, Sequence, StageFactory};
use serde::Deserialize;

use crate::cycle::{blocks, mm_to_um};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// layer thickness by part name (mm), or "auto" (from the material: see `base_cell` and `step`); default: the thinnest `layer_thickness` of the part's materials
        thickness: BTreeMap<String, Thickness> = "{}",
        /// regions grouping parts: `{ name, parts = [...], thickness }` (mm or "auto"); default: one region per part
        regions: Vec<RegionSpec> = "[]",
        /// base-cell dimension (mm) by part or region name: an "auto" thickness there is a microstructure's, 1/10 to 1/20 of the cell (formerly `cell`)
        #[formerly("cell")]
        base_cell: BTreeMap<String, f64> = "{}",
        /// largest change of a material's fraction one layer may hold: an "auto" thickness elsewhere is this over the composition's gradient along z (sampled from the grading), within 0.5 to 2 mm
        #[range(0.001, 1.0)]
        step: f64 = "0.1",
        /// thickness (mm) of parts that neither `thickness` nor their materials give one
        #[range(0.001, 100.0)]
        default_thickness: Option<f64>,
    }
}

lamina_api::option_type!(RegionSpec = "table", array "array of table");
lamina_api::option_type!(Thickness = "float or \"auto\"");

/// A thickness in mm, or `"auto"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum Thickness {
    Mm(f64),
    Auto(String),
}

impl Thickness {
    fn is_auto(&self) -> bool {
        matches!(self, Thickness::Auto(_))
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RegionSpec {
    name: String,
    parts: Vec<String>,
    #[serde(default)]
    thickness: Option<Thickness>,
}

/// The longest work cycle accepted (1 m): thicknesses like 0.201 and 0.199 mm have a
/// least common multiple of 40 mm, and worse choices quickly exceed any part.
const MAX_CYCLE_UM: u64 = 1_000_000;

struct WorkCycles {
    options: Options,
    table: TableRef,
}

/// A thickness in mm as whole micrometres, refused when it is not one.
fn thickness_um(mm: f64) -> std::result::Result<u64, String> {
    if !(mm.is_finite() && mm > 0.0) {
        return Err(format!("{mm} is not a positive number of mm"));
    }
    let um = (mm * 1000.0).round();
    if um < 1.0 || (mm * 1000.0 - um).abs() > 1e-6 || um > MAX_CYCLE_UM as f64 {
        return Err(format!(
            "{mm} mm is not a whole number of micrometres between 0.001 and {} mm",
            MAX_CYCLE_UM / 1000
        ));
    }
    Ok(um as u64)
}

impl WorkCycles {
    /// An `auto` thickness for the region or part `name` of `parts`: a microstructure's
    /// where `base_cell` gives its base cell, else a graded region's from the parts'
    /// sampled gradients.
    fn auto(&self, info: &RunInfo, name: &str, parts: &[usize]) -> Result<(u64, String)> {
        match self.options.base_cell.get(name) {
            Some(&cell) => crate::auto::microstructure_um(cell).ok_or_else(|| {
                self.table.error_at(
                    "base_cell",
                    format!("`{name}`: a base cell of {cell} mm is under 10 µm; its layers would be under a micrometre"),
                )
            }),
            None => {
                let g = parts
                    .iter()
                    .filter_map(|&p| info.parts[p].z_gradient)
                    .fold(None, |acc: Option<f64>, g| Some(acc.map_or(g, |a| a.max(g))));
                Ok(crate::auto::graded_um(g, self.options.step))
            }
        }
    }

    /// The thickness of a part: the `thickness` table, else the thinnest preferred
    /// thickness among its materials; with how it was chosen when derived.
    fn part_thickness_rule(&self, info: &RunInfo, part: usize) -> Result<(u64, Option<String>)> {
        let p = &info.parts[part];
        if let Some(Thickness::Auto(_)) = self.options.thickness.get(&p.name) {
            let (um, rule) = self.auto(info, &p.name, &[part])?;
            return Ok((um, Some(rule)));
        }
        self.part_thickness(info, part).map(|t| (t, None))
    }

    /// The thickness of a part: the `thickness` table, else the thinnest preferred
    /// thickness among its materials.
    fn part_thickness(&self, info: &RunInfo, part: usize) -> Result<u64> {
        let p = &info.parts[part];
        match self.options.thickness.get(&p.name) {
            Some(Thickness::Mm(t)) => {
                return thickness_um(*t)
                    .map_err(|m| self.table.error_at("thickness", format!("`{}`: {m}", p.name)));
            }
            Some(Thickness::Auto(_)) => return Ok(self.auto(info, &p.name, &[part])?.0),
            None => {}
        }
        let preferred = p
            .materials
            .iter()
            .filter_map(|&m| info.materials[m].layer_thickness)
            .fold(None, |acc: Option<f64>, t| Some(acc.map_or(t, |a| a.min(t))));
        match preferred.or(self.options.default_thickness) {
            Some(t) => thickness_um(t).map_err(|m| {
                Error::stage(
                    "sequence:work-cycles",
                    format!("layer_thickness of part `{}`'s materials: {m}", p.name),
                )
            }),
            None => Err(self.table.error_at(
                "thickness",
                format!(
                    "part `{}` has no layer thickness: give `thickness.{} = ...` or \
                     `default_thickness` here, or `layer_thickness` on one of its materials",
                    p.name, p.name
                ),
            )),
        }
    }

    fn part_index(&self, info: &RunInfo, name: &str) -> Result<usize> {
        info.parts.iter().position(|p| p.name == name).ok_or_else(|| {
            let known: Vec<&str> = info.parts.iter().map(|p| p.name.as_str()).collect();
            self.table.error_at(
                "regions",
                format!("no part named `{name}` (parts: {})", known.join(", ")),
            )
        })
    }

    fn regions(&self, info: &RunInfo) -> Result<Vec<MaterialRegion>> {
        for name in self.options.thickness.keys() {
            if !info.parts.iter().any(|p| &p.name == name) {
                return Err(self
                    .table
                    .error_at("thickness", format!("no part named `{name}`")));
            }
        }
        let span = |parts: &[usize]| -> (f64, f64) {
            let lo = parts
                .iter()
                .map(|&p| info.parts[p].z_min)
                .fold(f64::INFINITY, f64::min);
            let hi = parts
                .iter()
                .map(|&p| info.parts[p].z_max)
                .fold(f64::NEG_INFINITY, f64::max);
            (round_um(lo), round_um(hi))
        };
        if self.options.regions.is_empty() {
            return (0..info.parts.len())
                .map(|p| {
                    let (z_start, z_end) = span(&[p]);
                    let (thickness_um, rule) = self.part_thickness_rule(info, p)?;
                    Ok(MaterialRegion {
                        name: info.parts[p].name.clone(),
                        parts: vec![p],
                        thickness_um,
                        z_start,
                        z_end,
                        rule,
                    })
                })
                .collect();
        }
        let mut owner: Vec<Option<&str>> = vec![None; info.parts.len()];
        let mut out = Vec::new();
        for r in &self.options.regions {
            if r.parts.is_empty() {
                return Err(self
                    .table
                    .error_at("regions", format!("region `{}` lists no parts", r.name)));
            }
            let mut parts = Vec::new();
            for name in &r.parts {
                let p = self.part_index(info, name)?;
                if let Some(other) = owner[p] {
                    return Err(self.table.error_at(
                        "regions",
                        format!(
                            "part `{name}` is in both region `{other}` and region `{}`",
                            r.name
                        ),
                    ));
                }
                owner[p] = Some(&r.name);
                parts.push(p);
            }
            let (thickness, rule) = match &r.thickness {
                Some(Thickness::Mm(t)) => (
                    thickness_um(*t).map_err(|m| {
                        self.table
                            .error_at("regions", format!("region `{}`: {m}", r.name))
                    })?,
                    None,
                ),
                Some(Thickness::Auto(_)) => {
                    let (um, rule) = self.auto(info, &r.name, &parts)?;
                    (um, Some(rule))
                }
                None => {
                    // The thinnest of its parts' thicknesses.
                    let mut t = u64::MAX;
                    for &p in &parts {
                        t = t.min(self.part_thickness(info, p)?);
                    }
                    (t, None)
                }
            };
            let (z_start, z_end) = span(&parts);
            out.push(MaterialRegion {
                name: r.name.clone(),
                parts,
                thickness_um: thickness,
                z_start,
                z_end,
                rule,
            });
        }
        if let Some(p) = owner.iter().position(Option::is_none) {
            return Err(self.table.error_at(
                "regions",
                format!(
                    "part `{}` is in no region and would never be deposited",
                    info.parts[p].name
                ),
            ));
        }
        Ok(out)
    }
}

fn round_um(mm: f64) -> f64 {
    mm_to_um(mm) as f64 / 1000.0
}

impl Sequencer for WorkCycles {
    fn needs_gradients(&self) -> bool {
        // An `auto` thickness without a base cell follows the grading.
        let graded = |name: &str, t: &Thickness| t.is_auto() && !self.options.base_cell.contains_key(name);
        self.options.thickness.iter().any(|(n, t)| graded(n, t))
            || self
                .options
                .regions
                .iter()
                .any(|r| r.thickness.as_ref().is_some_and(|t| graded(&r.name, t)))
    }

    fn sequence(&self, info: &RunInfo) -> Result<Sequence> {
        for name in self.options.base_cell.keys() {
            let known = info.parts.iter().any(|p| &p.name == name)
                || self.options.regions.iter().any(|r| &r.name == name);
            if !known {
                return Err(self
                    .table
                    .error_at("base_cell", format!("no part or region named `{name}`")));
            }
        }
        let regions = self.regions(info)?;
        let blocks = blocks(&regions, MAX_CYCLE_UM).ok_or_else(|| {
            let t: Vec<String> = regions
                .iter()
                .map(|r| format!("{} {} mm", r.name, r.thickness_um as f64 / 1000.0))
                .collect();
            Error::stage(
                "sequence:work-cycles",
                format!(
                    "the work cycle of {} is longer than {} mm: choose thicknesses with a \
                         smaller common multiple",
                    t.join(", "),
                    MAX_CYCLE_UM / 1000
                ),
            )
        })?;
        Ok(Sequence { regions, blocks })
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    if let Some(t) = options.default_thickness {
        thickness_um(t).map_err(|m| config.error("default_thickness", m))?;
    }
    let check = |key: &str, what: String, t: &Thickness| -> Result<()> {
        match t {
            Thickness::Mm(t) => thickness_um(*t)
                .map(|_| ())
                .map_err(|m| config.error(key, format!("{what}: {m}"))),
            Thickness::Auto(s) if s == "auto" => Ok(()),
            Thickness::Auto(s) => Err(config.error(
                key,
                format!("{what}: `{s}` is neither a number of mm nor \"auto\""),
            )),
        }
    };
    for (name, t) in &options.thickness {
        check("thickness", format!("`{name}`"), t)?;
    }
    for r in &options.regions {
        if let Some(t) = &r.thickness {
            check("regions", format!("region `{}`", r.name), t)?;
        }
    }
    for (name, &d) in &options.base_cell {
        if !(d.is_finite() && d > 0.0 && d <= 1000.0) {
            return Err(config.error(
                "base_cell",
                format!("`{name}`: the base cell must be a positive number of mm"),
            ));
        }
    }
    Ok(AnyStage::Sequence(Box::new(WorkCycles {
        options,
        table: config.table.clone(),
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Sequence,
        name: "work-cycles",
        doc: "Material regions with their own layer thickness: blocks at the regions' heights, work cycles of the least common multiple, every region cut at its own heights (with the `adaptive` slicer).",
        options: Options::SPECS,
        example: "use = \"work-cycles\"\ndefault_thickness = 0.5",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thicknesses_must_be_whole_micrometres() {
        assert_eq!(thickness_um(0.2), Ok(200));
        assert_eq!(thickness_um(1.5), Ok(1500));
        assert!(thickness_um(0.0002).is_err());
        assert!(thickness_um(0.00025).is_err());
        assert!(thickness_um(-1.0).is_err());
        assert!(thickness_um(f64::NAN).is_err());
        assert!(thickness_um(5000.0).is_err());
        // The bounds: one micrometre, and one metre (the longest cycle).
        assert_eq!(thickness_um(0.001), Ok(1));
        assert_eq!(thickness_um(1000.0), Ok(1_000_000));
        assert!(thickness_um(1000.001).is_err());
        // Zero, and a thickness that rounds to zero micrometres, are no thickness.
        assert_eq!(
            thickness_um(0.0),
            Err("0 is not a positive number of mm".to_string())
        );
        assert!(thickness_um(1e-10).is_err());
    }
}
