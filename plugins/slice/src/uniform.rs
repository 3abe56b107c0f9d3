//! `uniform`: layers of one thickness from the bottom of the model to its top.

use std::sync::Arc;

use lamina_core::stage::{AnyStage, MeshSlicer, Slicer, StageConfig, StageInfo, StageKind};
use lamina_core::{Error, Layer, LayerSlot, Mesh, Result, RunInfo, Sequence, StageFactory};
use serde::Deserialize;

use crate::cut::{CutMesh, CutOptions};

/// Where in its thickness a layer is cut.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(untagged)]
enum CutAt {
    Named(CutName),
    /// Fraction of the thickness above the layer's bottom, in [0, 1].
    Fraction(f64),
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum CutName {
    Bottom,
    Mid,
    Top,
}

impl CutAt {
    fn fraction(self) -> f64 {
        match self {
            CutAt::Named(CutName::Bottom) => 0.0,
            CutAt::Named(CutName::Mid) => 0.5,
            CutAt::Named(CutName::Top) => 1.0,
            CutAt::Fraction(f) => f,
        }
    }
}

lamina_core::option_type!(CutAt = "string or float");

lamina_core::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// layer thickness (mm)
        thickness: f64 = "0.2",
        /// thickness of the first layer (mm); unset: the machine's `first_layer.height`, else `thickness`
        first_layer: Option<f64>,
        /// where a layer is cut: "bottom", "mid", "top" or a fraction of its thickness
        cut: CutAt = r#""mid""#,
        close_gaps: f64 = use crate::cut::CLOSE_GAPS,
        fill_rule: crate::cut::FillRule = use crate::cut::FILL_RULE,
        max_layers: usize = use crate::cut::MAX_LAYERS,
    }
}

pub(crate) struct Uniform {
    thickness: f64,
    first: f64,
    cut: f64,
    options: CutOptions,
    max_layers: usize,
}

/// Slots covering `z_min..z_max`: the first `first` thick, the others `t`; the last
/// layer's top is at or above `z_max`.
pub fn uniform_slots(
    z_min: f64,
    z_max: f64,
    first: f64,
    t: f64,
    cut: f64,
    max_layers: usize,
) -> Result<Vec<LayerSlot>> {
    let height = z_max - z_min;
    if height.is_nan() || height <= 0.0 {
        return Ok(Vec::new());
    }
    // Tolerate a height that is a whole number of layers up to rounding.
    let rest = ((height - first) / t - 1e-9).ceil().max(0.0);
    if rest + 1.0 > max_layers as f64 {
        return Err(Error::stage(
            "slice:uniform",
            format!("{} layers of {t} mm exceed max_layers = {max_layers}", rest + 1.0),
        ));
    }
    let n = rest as usize + 1;
    Ok((0..n)
        .map(|i| {
            let (bottom, thickness) = if i == 0 {
                (z_min, first)
            } else {
                (z_min + first + t * (i - 1) as f64, t)
            };
            LayerSlot::new(
                i,
                bottom + thickness,
                thickness,
                (bottom + thickness * cut).min(z_max),
            )
        })
        .collect())
}

impl Slicer for Uniform {
    fn layers(
        &self,
        _meshes: &[Arc<Mesh>],
        info: &RunInfo,
        _sequence: Option<&Sequence>,
    ) -> Result<Vec<LayerSlot>> {
        uniform_slots(
            info.z_min,
            info.z_max,
            self.first,
            self.thickness,
            self.cut,
            self.max_layers,
        )
    }

    fn prepare(&self, mesh: Arc<Mesh>) -> Result<Box<dyn MeshSlicer>> {
        Ok(Box::new(Prepared(CutMesh::new(mesh, self.options))))
    }
}

pub(crate) struct Prepared(pub CutMesh);

impl MeshSlicer for Prepared {
    fn slice(&self, slot: &LayerSlot) -> Result<Layer> {
        self.0.cut(slot)
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    if !(o.thickness.is_finite() && o.thickness > 0.0) {
        return Err(config.error("thickness", "must be a positive number of mm"));
    }
    let first = match o.first_layer {
        Some(f) if !(f.is_finite() && f > 0.0) => {
            return Err(config.error("first_layer", "must be a positive number of mm"));
        }
        Some(f) => f,
        None => config
            .machine
            .and_then(|m| m.first_layer.height)
            .unwrap_or(o.thickness),
    };
    crate::cut::check_layer_height(config, "thickness", o.thickness)?;
    crate::cut::check_layer_height(config, "first_layer", first)?;
    let cut = o.cut.fraction();
    if !(0.0..=1.0).contains(&cut) {
        return Err(config.error(
            "cut",
            "must be \"bottom\", \"mid\", \"top\" or a fraction in [0, 1]",
        ));
    }
    Ok(AnyStage::Slice(Box::new(Uniform {
        thickness: o.thickness,
        first,
        cut,
        options: CutOptions::from_table(config, o.close_gaps, o.fill_rule)?,
        max_layers: o.max_layers,
    })))
}

// A pipeline without a [slice] table gets this stage.
lamina_core::register_default!(StageKind::Slice, "uniform");

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Slice,
        name: "uniform",
        doc: "Layers of one thickness from the bottom of the model to its top, each cut at a chosen height within it.",
        options: Options::SPECS,
        example: "use = \"uniform\"\nthickness = 0.5\ncut = \"mid\"",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_cover_the_height() {
        let s = uniform_slots(0.0, 1.0, 0.2, 0.2, 0.5, 100).expect("slots");
        assert_eq!(s.len(), 5);
        assert!((s[4].z - 1.0).abs() < 1e-12);
        assert!((s[0].cut_z - 0.1).abs() < 1e-12);
        let s = uniform_slots(0.0, 1.05, 0.2, 0.2, 1.0, 100).expect("slots");
        assert_eq!(s.len(), 6);
        assert!((s[5].cut_z - 1.05).abs() < 1e-12);
        assert!(uniform_slots(0.0, 1.0, 1e-9, 1e-9, 0.5, 100).is_err());
    }

    #[test]
    fn a_first_layer_of_its_own_thickness_then_the_others() {
        // 0.3 mm, then 0.2 mm layers up to 1.1 mm: 0.3, 0.5, 0.7, 0.9, 1.1.
        let s = uniform_slots(0.0, 1.1, 0.3, 0.2, 0.5, 100).expect("slots");
        let tops: Vec<f64> = s.iter().map(|l| l.z).collect();
        let thick: Vec<f64> = s.iter().map(|l| l.thickness).collect();
        assert_eq!(s.len(), 5, "{tops:?}");
        assert!((thick[0] - 0.3).abs() < 1e-12 && thick[1..].iter().all(|t| (t - 0.2).abs() < 1e-12));
        assert!(
            (tops[0] - 0.3).abs() < 1e-12 && (tops[4] - 1.1).abs() < 1e-12,
            "{tops:?}"
        );
        assert!((s[0].cut_z - 0.15).abs() < 1e-12 && (s[1].cut_z - 0.4).abs() < 1e-12);
        // A part thinner than the first layer is that one layer.
        assert_eq!(
            uniform_slots(0.0, 0.25, 0.3, 0.2, 0.5, 100).expect("slots").len(),
            1
        );
    }
}
