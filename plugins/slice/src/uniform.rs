//! `uniform`: layers of one thickness from the bottom of the model to its top.

use std::sync::Arc;

use lamina_api::stage::{AnyStage, MeshSlicer, Slicer, StageConfig, StageInfo, StageKind};
use lamina_api::{Error, Layer, LayerSlot, Mesh, Result, RunInfo, Sequence, StageFactory};
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

lamina_api::option_type!(CutAt = "string or float");

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// layer thickness (mm)
        #[range(0.001, 100.0)]
        thickness: f64 = "0.2",
        /// thickness of the first layer (mm); unset: the machine's `first_layer.height`, else `thickness`
        #[range(0.001, 100.0)]
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

/// The thinnest and thickest layers a top may be fitted with (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub min: f64,
    pub max: f64,
}

impl Range {
    /// What a machine's nozzle lays: from 0.175 of its bore (PrusaSlicer's 0.07 mm for
    /// a 0.4 mm nozzle) to its `max_layer_height`; without a machine, half to one and a
    /// half of the layer thickness `t`.
    pub fn of(machine: Option<&lamina_api::Machine>, t: f64) -> Self {
        match machine {
            Some(m) => Range {
                min: (0.175 * m.nozzle_diameter).min(t),
                max: m.max_layer_height.max(t),
            },
            None => Range {
                min: 0.5 * t,
                max: 1.5 * t,
            },
        }
    }
}

/// Where the parts end, and the layers that may be fitted to end there.
#[derive(Debug, Clone, Copy)]
pub struct Tops<'a> {
    /// Each part's top (mm).
    pub parts: &'a [f64],
    pub range: Range,
}

/// Slots covering `z_min..z_max`: the first `first` thick, the others `t`, cut at
/// `cut` of their thickness. Every part ends at its top: each of `tops` (the parts'
/// tops; `z_max` is one) that falls inside a layer by more than a tenth of its
/// thickness moves the nearer boundary there when both layers it bounds stay within
/// `range`, and else splits the layer (or shares the two layers under it); the last
/// layer ends at `z_max` unless no layer within `range` can.
pub fn uniform_slots(
    z_min: f64,
    z_max: f64,
    first: f64,
    t: f64,
    cut: f64,
    max_layers: usize,
    tops: Tops<'_>,
) -> Result<Vec<LayerSlot>> {
    let range = tops.range;
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
    // Layer boundaries from the bottom up.
    let mut at: Vec<f64> = std::iter::once(z_min)
        .chain((0..n).map(|i| z_min + first + t * i as f64))
        .collect();
    let mut tops: Vec<f64> = tops
        .parts
        .iter()
        .copied()
        .filter(|z| z.is_finite() && *z > z_min && *z < z_max)
        .chain([z_max])
        .collect();
    tops.sort_by(f64::total_cmp);
    tops.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    for top in tops {
        fit(&mut at, top, range);
    }
    // Nothing above the highest top.
    while at.len() > 2 && at[at.len() - 2] >= z_max - 1e-9 {
        at.pop();
    }
    if at.len() - 1 > max_layers {
        return Err(Error::stage(
            "slice:uniform",
            format!("{} layers exceed max_layers = {max_layers}", at.len() - 1),
        ));
    }
    Ok(at
        .windows(2)
        .enumerate()
        .map(|(i, w)| {
            let thickness = w[1] - w[0];
            LayerSlot::new(i, w[1], thickness, (w[0] + thickness * cut).min(z_max))
        })
        .collect())
}

/// Puts a boundary at `top` (see [`uniform_slots`]).
fn fit(at: &mut Vec<f64>, top: f64, range: Range) {
    let ok = |t: f64| t >= range.min - 1e-9 && t <= range.max + 1e-9;
    // The layer `k` that holds `top`: at[k] < top <= at[k + 1].
    let Some(k) = at.windows(2).position(|w| w[0] < top && top <= w[1] + 1e-12) else {
        return;
    };
    let (bottom, upper) = (at[k], at[k + 1]);
    let thickness = upper - bottom;
    if upper - top <= 0.1 * thickness || top - bottom <= 1e-9 {
        return;
    }
    // Move the boundary above down, the one below up (not the bed), or split.
    let above = at.get(k + 2).copied();
    let down = ok(top - bottom) && above.is_none_or(|a| ok(a - top));
    let up = k >= 1 && ok(top - at[k - 1]) && ok(upper - top);
    let moved_down = upper - top;
    let moved_up = top - bottom;
    if down && (!up || moved_down <= moved_up) {
        at[k + 1] = top;
    } else if up {
        at[k] = top;
    } else if ok(top - bottom) && ok(upper - top) {
        at.insert(k + 1, top);
    } else if k >= 1 && ok((top - at[k - 1]) / 2.0) && ok(upper - top) {
        // The two layers below the top share what is under it.
        at[k] = (at[k - 1] + top) / 2.0;
        at.insert(k + 1, top);
    }
    // Else no layer within the nozzle's range ends at the top (a part thinner than the
    // thinnest layer, say): the layer stays whole, and the slicer says the part is
    // thinner than a layer.
}

impl Slicer for Uniform {
    fn layers(
        &self,
        _meshes: &[Arc<Mesh>],
        info: &RunInfo,
        _sequence: Option<&Sequence>,
    ) -> Result<Vec<LayerSlot>> {
        let tops: Vec<f64> = info.parts.iter().map(|p| p.z_max).collect();
        uniform_slots(
            info.z_min,
            info.z_max,
            self.first,
            self.thickness,
            self.cut,
            self.max_layers,
            Tops {
                parts: &tops,
                range: Range::of(info.machine.as_ref(), self.thickness),
            },
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
lamina_api::register_default!(StageKind::Slice, "uniform");

lamina_api::register_stage!(StageFactory {
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
        let s = uniform_slots(
            0.0,
            1.0,
            0.2,
            0.2,
            0.5,
            100,
            Tops {
                parts: &[],
                range: Range::of(None, 0.2),
            },
        )
        .expect("slots");
        assert_eq!(s.len(), 5);
        assert!((s[4].z - 1.0).abs() < 1e-12);
        assert!((s[0].cut_z - 0.1).abs() < 1e-12);
        // 1.05 mm at 0.2: the last layer is 0.25 thick and ends at the top.
        let s = uniform_slots(
            0.0,
            1.05,
            0.2,
            0.2,
            1.0,
            100,
            Tops {
                parts: &[],
                range: Range::of(None, 0.2),
            },
        )
        .expect("slots");
        assert_eq!(s.len(), 5);
        assert!((s[4].z - 1.05).abs() < 1e-12 && (s[4].thickness - 0.25).abs() < 1e-12);
        assert!(
            uniform_slots(
                0.0,
                1.0,
                1e-9,
                1e-9,
                0.5,
                100,
                Tops {
                    parts: &[],
                    range: Range::of(None, 1e-9)
                }
            )
            .is_err()
        );
    }

    #[test]
    fn a_first_layer_of_its_own_thickness_then_the_others() {
        // 0.3 mm, then 0.2 mm layers up to 1.1 mm: 0.3, 0.5, 0.7, 0.9, 1.1.
        let s = uniform_slots(
            0.0,
            1.1,
            0.3,
            0.2,
            0.5,
            100,
            Tops {
                parts: &[],
                range: Range::of(None, 0.2),
            },
        )
        .expect("slots");
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
            uniform_slots(
                0.0,
                0.25,
                0.3,
                0.2,
                0.5,
                100,
                Tops {
                    parts: &[],
                    range: Range::of(None, 0.2)
                }
            )
            .expect("slots")
            .len(),
            1
        );
    }

    /// A nozzle's range: 0.07 to 0.3 mm.
    const NOZZLE: Range = Range { min: 0.07, max: 0.3 };

    fn tops(s: &[LayerSlot]) -> Vec<f64> {
        s.iter().map(|l| l.z).collect()
    }

    #[test]
    fn every_part_ends_at_its_top() {
        // A gear 5.05 mm and a shaft 9.0 mm tall, 0.2 mm first and 0.3 mm layers: the
        // stack ran 0.2, 0.5, ..., 9.2 and the shaft ended 0.2 mm high.
        let s = uniform_slots(
            0.0,
            9.0,
            0.2,
            0.3,
            0.5,
            1000,
            Tops {
                parts: &[5.05, 9.0],
                range: NOZZLE,
            },
        )
        .expect("slots");
        let z = tops(&s);
        for top in [5.05, 9.0] {
            let near = z.iter().map(|z| (z - top).abs()).fold(f64::MAX, f64::min);
            assert!(near <= 0.03 + 1e-12, "{top}: {z:?}");
        }
        assert!((z.last().copied().unwrap_or(0.0) - 9.0).abs() < 1e-12);
        // Every layer within the nozzle's range, and the stack unbroken.
        assert!(
            s.iter()
                .all(|l| l.thickness >= 0.07 - 1e-9 && l.thickness <= 0.3 + 1e-9),
            "{z:?}"
        );
        assert!(
            s.windows(2)
                .all(|w| (w[1].z - w[1].thickness - w[0].z).abs() < 1e-12)
        );
        // A part 1.375 mm tall at 1 mm layers is one layer of 1.375 mm, not 2 mm.
        let s = uniform_slots(
            0.0,
            1.375,
            1.0,
            1.0,
            0.5,
            100,
            Tops {
                parts: &[],
                range: Range::of(None, 1.0),
            },
        )
        .expect("slots");
        assert_eq!(tops(&s), vec![1.375]);
        // A top that only a thin layer reaches within the range splits a layer.
        let s = uniform_slots(
            0.0,
            2.0,
            0.2,
            0.2,
            0.5,
            100,
            Tops {
                parts: &[1.1],
                range: NOZZLE,
            },
        )
        .expect("slots");
        assert!(tops(&s).iter().any(|z| (z - 1.1).abs() < 1e-12), "{:?}", tops(&s));
    }

    #[test]
    fn a_part_thinner_than_the_thinnest_layer_keeps_one_whole_layer() {
        let s = uniform_slots(
            0.0,
            0.001,
            0.2,
            0.2,
            0.5,
            100,
            Tops {
                parts: &[],
                range: NOZZLE,
            },
        )
        .expect("slots");
        assert_eq!(tops(&s), vec![0.2]);
        assert!((s[0].cut_z - 0.001).abs() < 1e-12);
    }
}
