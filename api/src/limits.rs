//! Resource limits of a run: every buffer whose size comes from the input (a model's
//! triangles, a grid's samples, a family's sub-regions) is checked against one of these
//! before it is allocated, so a typo or a hostile file ends in an error that names the
//! limit, never in an allocation the machine cannot make.
//!
//! The defaults fit a 2 GiB machine with room to spare and are far above what real
//! parts need; a pipeline raises one in its `[limits]` table.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Largest coordinate or length (mm) a model or an option may have: a kilometre.
/// Larger numbers are typos or hostile, and beyond about 1e150 the polygon booleans
/// cannot represent them at all.
pub const MAX_COORDINATE: f64 = 1.0e6;

/// True when `v` is a finite coordinate within ±[`MAX_COORDINATE`].
pub fn is_coordinate(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_COORDINATE
}

/// The `[limits]` table of a pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Limits {
    /// Triangles of one model (a 3MF counts every component instance).
    pub triangles: u64,
    /// Bytes of one model file, or of a 3MF package's uncompressed model part.
    pub model_bytes: u64,
    /// Samples of one grid a stage allocates for a layer (a distance field's samples, a
    /// bitmap's pixels). `grid_samples` in a pipeline (the host reads its former name
    /// `grid_cells` too, [`GRID_SAMPLES_FORMERLY`]); on the plugin wire it keeps the
    /// former name, which plugins of ABI 7.0-7.3 know.
    #[serde(rename = "grid_cells")]
    pub grid_samples: u64,
    /// Sub-regions (rings, levels, cells) a discretiser makes in one family.
    pub regions: u64,
}

/// The name `grid_samples` had in a pipeline's `[limits]` table, and still has in its
/// serde form.
pub const GRID_SAMPLES_FORMERLY: &str = "grid_cells";

impl Default for Limits {
    fn default() -> Self {
        Self {
            triangles: 20_000_000,
            model_bytes: 1 << 30,
            grid_samples: 1 << 24,
            regions: 1_000,
        }
    }
}

/// One of the limits, for [`Limits::check`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Limit {
    Triangles,
    ModelBytes,
    GridSamples,
    Regions,
}

impl Limit {
    pub const ALL: [Limit; 4] = [
        Limit::Triangles,
        Limit::ModelBytes,
        Limit::GridSamples,
        Limit::Regions,
    ];

    /// What the limit counts.
    pub fn unit(self) -> &'static str {
        match self {
            Limit::Triangles => "triangles",
            Limit::ModelBytes => "bytes",
            Limit::GridSamples => "grid samples",
            Limit::Regions => "sub-regions",
        }
    }

    /// The key in the `[limits]` table.
    pub fn key(self) -> &'static str {
        match self {
            Limit::Triangles => "triangles",
            Limit::ModelBytes => "model_bytes",
            Limit::GridSamples => "grid_samples",
            Limit::Regions => "regions",
        }
    }
}

impl Limits {
    /// The value of one limit.
    pub fn get(&self, limit: Limit) -> u64 {
        match limit {
            Limit::Triangles => self.triangles,
            Limit::ModelBytes => self.model_bytes,
            Limit::GridSamples => self.grid_samples,
            Limit::Regions => self.regions,
        }
    }

    /// Refuses `needed` (a count that may be a float computed from options: NaN and
    /// infinity are refused too) when it exceeds the limit; `what` says what needed it.
    pub fn check(&self, limit: Limit, needed: f64, what: &str) -> Result<()> {
        let allowed = self.get(limit);
        if needed.is_finite() && needed <= allowed as f64 {
            return Ok(());
        }
        Err(Error::Limit {
            what: what.to_string(),
            needed: if needed.is_finite() {
                format!("{needed:.0} {}", limit.unit())
            } else {
                format!("unboundedly many {}", limit.unit())
            },
            key: limit.key(),
            allowed,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_count_over_the_limit_names_the_key_that_raises_it() {
        let limits = Limits::default();
        assert!(limits.check(Limit::Regions, 1000.0, "rings").is_ok());
        let e = limits.check(Limit::Regions, 1001.0, "rings").expect_err("over");
        let text = e.to_string();
        assert!(
            text.contains("limits.regions") && text.contains("1001") && text.contains("rings"),
            "{text}"
        );
        assert!(limits.check(Limit::GridSamples, f64::NAN, "a grid").is_err());
        assert!(limits.check(Limit::GridSamples, f64::INFINITY, "a grid").is_err());
    }

    #[test]
    fn a_pipeline_table_raises_one_limit_and_keeps_the_others() {
        let l: Limits = toml::from_str("regions = 50000").expect("parses");
        assert_eq!(l.regions, 50_000);
        assert_eq!(l.triangles, Limits::default().triangles);
        assert!(toml::from_str::<Limits>("region = 5").is_err());
    }
}
