//! `adaptive`: layer thickness that follows the surface, as variable layer height does
//! in PrusaSlicer or Cura. A layer of thickness t on a facet whose normal makes angle θ
//! with the build direction leaves a stair step (cusp) of height t |cos θ|; each layer is
//! as thick as the facets it spans allow for the chosen cusp, within [min, max]. Layers
//! end exactly on horizontal faces when the thickness bounds let them.
//!
//! With a `[sequence]` whose material regions want their own thicknesses (work cycles),
//! the layers follow the sequence instead: each region is cut at its own heights, with
//! its own thickness, in the sequence's deposition order.

use std::sync::Arc;

use lamina_api::stage::{AnyStage, MeshSlicer, Slicer, StageConfig, StageInfo, StageKind};
use lamina_api::{Error, LayerSlot, Mesh, Result, RunInfo, Sequence, StageFactory};
use serde::Deserialize;

use crate::cut::{CutMesh, CutOptions, FillRule};
use crate::uniform::Prepared;

/// What decides the layer heights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Mode {
    /// The sequence's work cycles when the pipeline has a `[sequence]`, else the
    /// surface slope.
    #[default]
    Auto,
    /// The surface slope and the cusp height.
    Surface,
    /// The material regions' thicknesses, following the sequence's work cycles.
    Material,
}

lamina_api::option_type!(Mode = "string");

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// "surface" (slope and cusp), "material" (the [sequence]'s work cycles) or "auto" (material when there is a [sequence])
        mode: Mode = r#""auto""#,
        /// thinnest layer (mm, surface mode)
        #[range(0.001, 100.0)]
        min_thickness: f64 = "0.05",
        /// thickest layer (mm, surface mode)
        #[range(0.001, 100.0)]
        max_thickness: f64 = "0.3",
        /// thickness of the first layer (mm, surface mode); unset: the machine's `first_layer.height`, else from the surface
        #[range(0.001, 100.0)]
        first_layer: Option<f64>,
        /// largest stair-step height allowed on sloped surfaces (mm)
        #[range(0.0001, 10.0)]
        cusp: f64 = "0.05",
        close_gaps: f64 = use crate::cut::CLOSE_GAPS,
        fill_rule: FillRule = use crate::cut::FILL_RULE,
        max_layers: usize = use crate::cut::MAX_LAYERS,
    }
}

struct Adaptive {
    mode: Mode,
    heights: Heights,
    options: CutOptions,
    max_layers: usize,
}

/// A facet as the height planner sees it.
#[derive(Debug, Clone, Copy)]
struct Facet {
    lo: f64,
    hi: f64,
    /// |cos θ| of the facet normal with the build direction.
    nz: f64,
}

/// Facets closer to horizontal than this are flat faces: layers end on them instead of
/// thinning around them.
const FLAT: f64 = 1.0 - 1e-9;

/// The bounds of the surface mode's layer heights (mm).
#[derive(Debug, Clone, Copy)]
struct Heights {
    min: f64,
    max: f64,
    cusp: f64,
    /// The first layer's thickness, whatever the surface.
    first: Option<f64>,
}

/// Layer slots over `z_min..z_max` for the given facets.
fn plan_heights(
    facets: &mut [Facet],
    z_min: f64,
    z_max: f64,
    heights: &Heights,
    max_layers: usize,
) -> Result<Vec<LayerSlot>> {
    let Heights {
        min,
        max,
        cusp,
        first,
    } = *heights;
    facets.sort_by(|a, b| a.lo.total_cmp(&b.lo));
    let mut flats: Vec<f64> = facets.iter().filter(|f| f.nz >= FLAT).map(|f| f.lo).collect();
    flats.sort_by(f64::total_cmp);
    flats.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let mut slots = Vec::new();
    let mut active: Vec<Facet> = Vec::new();
    let mut next = 0;
    let mut z = z_min;
    while z < z_max - 1e-9 {
        // Facets reaching into (z, z + max].
        while next < facets.len() && facets[next].lo < z + max {
            active.push(facets[next]);
            next += 1;
        }
        active.retain(|f| f.hi > z);
        let mut t = max;
        for f in &active {
            if f.lo < z + t && f.nz < FLAT && f.nz > 0.0 {
                t = t.min(cusp / f.nz);
            }
        }
        t = t.clamp(min, max);
        if let (Some(f), true) = (first, slots.is_empty()) {
            // The machine's first layer, whatever the surface.
            let t = f.min(z_max - z);
            slots.push(LayerSlot::new(0, z + t, t, z + t / 2.0));
            z += t;
            continue;
        }
        // End on a flat face inside the layer when that keeps the thickness legal.
        let first_flat = flats.partition_point(|&h| h <= z + 1e-9);
        if let Some(&h) = flats.get(first_flat)
            && h < z + t - 1e-9
            && h - z >= min
        {
            t = h - z;
        }
        let remaining = z_max - z;
        if remaining <= t + 1e-9 {
            t = remaining;
        } else if remaining - t < min {
            // Do not leave a sliver thinner than `min` for the last layer.
            t = if remaining <= max + 1e-9 {
                remaining
            } else {
                remaining / 2.0
            };
        }
        if slots.len() >= max_layers {
            return Err(Error::stage(
                "slice:adaptive",
                format!("more than max_layers = {max_layers} layers"),
            ));
        }
        slots.push(LayerSlot::new(slots.len(), z + t, t, z + t / 2.0));
        z += t;
    }
    Ok(slots)
}

impl Slicer for Adaptive {
    fn layers(
        &self,
        meshes: &[Arc<Mesh>],
        info: &RunInfo,
        sequence: Option<&Sequence>,
    ) -> Result<Vec<LayerSlot>> {
        match (self.mode, sequence) {
            (Mode::Material | Mode::Auto, Some(seq)) => {
                let slots = seq.slots();
                if slots.len() > self.max_layers {
                    return Err(Error::stage(
                        "slice:adaptive",
                        format!(
                            "the sequence deposits {} layers, more than max_layers = {}",
                            slots.len(),
                            self.max_layers
                        ),
                    ));
                }
                return Ok(slots);
            }
            (Mode::Material, None) => {
                return Err(Error::stage(
                    "slice:adaptive",
                    "mode = \"material\" follows the work cycles of a [sequence] table, and the \
                     pipeline has none",
                ));
            }
            _ => {}
        }
        let mut facets = Vec::new();
        for m in meshes {
            for i in 0..m.triangles.len() {
                let [a, b, c] = m.triangle(i);
                let n = (b - a).cross(&(c - a));
                let len = n.norm();
                if len <= 0.0 {
                    continue;
                }
                facets.push(Facet {
                    lo: a.z.min(b.z).min(c.z),
                    hi: a.z.max(b.z).max(c.z),
                    nz: (n.z / len).abs(),
                });
            }
        }
        plan_heights(
            &mut facets,
            info.z_min,
            info.z_max,
            &self.heights,
            self.max_layers,
        )
    }

    fn prepare(&self, mesh: Arc<Mesh>) -> Result<Box<dyn MeshSlicer>> {
        Ok(Box::new(Prepared(CutMesh::new(mesh, self.options))))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    for (k, v) in [
        ("min_thickness", o.min_thickness),
        ("max_thickness", o.max_thickness),
        ("cusp", o.cusp),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(config.error(k, "must be a positive number of mm"));
        }
    }
    if o.min_thickness > o.max_thickness {
        return Err(config.error("min_thickness", "must not exceed max_thickness"));
    }
    if let Some(f) = o.first_layer
        && !(f.is_finite() && f > 0.0)
    {
        return Err(config.error("first_layer", "must be a positive number of mm"));
    }
    if o.first_layer.is_some() && o.mode == Mode::Material {
        return Err(config.error(
            "first_layer",
            "with mode = \"material\" the work cycles set every layer's thickness",
        ));
    }
    let first = o
        .first_layer
        .or_else(|| config.machine.and_then(|m| m.first_layer.height));
    crate::cut::check_layer_height(config, "max_thickness", o.max_thickness)?;
    if let Some(f) = first {
        crate::cut::check_layer_height(config, "first_layer", f)?;
    }
    Ok(AnyStage::Slice(Box::new(Adaptive {
        mode: o.mode,
        heights: Heights {
            min: o.min_thickness,
            max: o.max_thickness,
            cusp: o.cusp,
            first,
        },
        options: CutOptions::from_table(config, o.close_gaps, o.fill_rule)?,
        max_layers: o.max_layers,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Slice,
        name: "adaptive",
        doc: "Layer thickness from the surface slope (thin where a stair step would show, ending on flat faces), or per material region following the work cycles of a [sequence].",
        options: Options::SPECS,
        example: "use = \"adaptive\"\nmin_thickness = 0.1\nmax_thickness = 0.5\ncusp = 0.1",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;

    fn facet(lo: f64, hi: f64, nz: f64) -> Facet {
        Facet { lo, hi, nz }
    }

    #[test]
    fn vertical_walls_get_the_thickest_layers() {
        let mut f = vec![facet(0.0, 3.0, 0.0), facet(0.0, 0.0, 1.0), facet(3.0, 3.0, 1.0)];
        let s = plan_heights(
            &mut f,
            0.0,
            3.0,
            &Heights {
                min: 0.05,
                max: 0.3,
                cusp: 0.05,
                first: None,
            },
            1000,
        )
        .expect("plans");
        assert_eq!(s.len(), 10, "{s:?}");
        assert!(s.iter().all(|l| (l.thickness - 0.3).abs() < 1e-9));
        assert!((s[9].z - 3.0).abs() < 1e-9);
    }

    #[test]
    fn slopes_thin_the_layers_by_the_cusp() {
        // A 45° slope from z = 1 to 2 between vertical walls.
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let mut f = vec![facet(0.0, 3.0, 0.0), facet(1.0, 2.0, c)];
        let s = plan_heights(
            &mut f,
            0.0,
            3.0,
            &Heights {
                min: 0.05,
                max: 0.3,
                cusp: 0.1,
                first: None,
            },
            1000,
        )
        .expect("plans");
        let on_slope: Vec<_> = s
            .iter()
            .filter(|l| l.z - l.thickness >= 1.0 && l.z <= 2.0)
            .collect();
        assert!(!on_slope.is_empty());
        for l in on_slope {
            assert!((l.thickness - 0.1 / c).abs() < 1e-9, "{l:?}");
        }
        assert!((s.last().expect("layers").z - 3.0).abs() < 1e-9);
        let total: f64 = s.iter().map(|l| l.thickness).sum();
        assert!((total - 3.0).abs() < 1e-9);
    }

    #[test]
    fn layers_end_on_flat_faces() {
        let mut f = vec![facet(0.0, 2.0, 0.0), facet(1.05, 1.05, 1.0)];
        let s = plan_heights(
            &mut f,
            0.0,
            2.0,
            &Heights {
                min: 0.05,
                max: 0.3,
                cusp: 0.05,
                first: None,
            },
            1000,
        )
        .expect("plans");
        assert!(s.iter().any(|l| (l.z - 1.05).abs() < 1e-9), "{s:?}");
    }

    #[test]
    fn the_first_layer_has_the_thickness_asked_for() {
        // Vertical walls: every layer is max_thickness but the first.
        let mut f = vec![facet(0.0, 2.0, 0.0)];
        let s = plan_heights(
            &mut f,
            0.0,
            2.0,
            &Heights {
                min: 0.05,
                max: 0.3,
                cusp: 0.05,
                first: Some(0.2),
            },
            1000,
        )
        .expect("plans");
        assert!((s[0].thickness - 0.2).abs() < 1e-12 && (s[0].cut_z - 0.1).abs() < 1e-12);
        assert!((s[1].thickness - 0.3).abs() < 1e-12, "{s:?}");
        let total: f64 = s.iter().map(|l| l.thickness).sum();
        assert!((total - 2.0).abs() < 1e-9);
    }
}
