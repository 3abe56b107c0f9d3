//! `zxy`: grading along Z and across the layer at once (the turbine blade of Fig. 19 of
//! the topological-hierarchy paper): the Z control function of the layer's level and
//! the X-Y control function of the sub-region's level each give a composition, and the
//! two are combined by the weighted operator of the grading-step-width paper (Eq. 8),
//! (k_z M_z + k_xy M_xy) / (k_z + k_xy).

use lamina_api::stage::{AnyStage, FamilyContext, Grader, StageConfig, StageInfo, StageKind};
use lamina_api::{Composition, Error, Result, StageFactory, SubRegion};

use crate::control::{Control, ControlOptions, region_args};
use crate::xy::index_level;
use crate::z::{Span, level, span};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// control function of the layer's level (a built-in name with its defaults, or Rhai): default f = r
        z_f: String = r#""linear""#,
        /// control function of the region's level: default f = 1 - r (first material outside)
        xy_f: String = r#""linear""#,
        /// layer index where r_z = 0
        #[range(0, 1e7)]
        from_layer: Option<usize>,
        /// layer index where r_z = 1
        #[range(0, 1e7)]
        to_layer: Option<usize>,
        /// height (mm) where r_z = 0
        #[range(-1e6, 1e6)]
        from_z: Option<f64>,
        /// height (mm) where r_z = 1
        #[range(-1e6, 1e6)]
        to_z: Option<f64>,
        /// k_z and k_xy of Eq. 8
        #[range(0, 1e6)]
        weights: [f64; 2] = "[1.0, 1.0]",
        /// use the discretiser's level for r_xy instead of j / (N_R - 1)
        xy_level: bool = "false",
        /// the part's materials the Z grading runs over (Fig. 19: ["red", "green"]); unset: all of them
        z_materials: Option<Vec<String>>,
        /// the part's materials the X-Y grading runs over (Fig. 19: ["ceramic", "metal"]); unset: all of them
        xy_materials: Option<Vec<String>>,
    }
}

struct Both {
    z: Control,
    xy: Control,
    span: Span,
    weights: [f64; 2],
    /// Use the discretiser's level instead of j / (N_R - 1).
    xy_level: bool,
    /// The materials each grading runs over (Fig. 19: red to green along Z, ceramic to
    /// metal across); `None` for all of the part's materials.
    z_materials: Option<Vec<String>>,
    xy_materials: Option<Vec<String>>,
}

impl Both {
    /// Indices into the part's materials of the names a grading runs over; all of them
    /// when none are named.
    fn indices(&self, ctx: &FamilyContext<'_>, names: &Option<Vec<String>>, key: &str) -> Result<Vec<usize>> {
        let part = &ctx.info.parts[ctx.part];
        match names {
            None => Ok((0..part.materials.len()).collect()),
            Some(names) => names
                .iter()
                .map(|name| {
                    part.materials
                        .iter()
                        .position(|&m| ctx.info.materials[m].name == *name)
                        .ok_or_else(|| {
                            Error::stage(
                                "grade:zxy",
                                format!("`{key}`: part `{}` has no material `{name}`", part.name),
                            )
                        })
                })
                .collect(),
        }
    }
}

impl Grader for Both {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        let rz = level(
            self.span,
            ctx.layer.index,
            ctx.layer.z,
            ctx.layer.thickness,
            (part.z_min, part.z_max),
        );
        let [kz, kxy] = self.weights;
        let zi = self.indices(ctx, &self.z_materials, "z_materials")?;
        let xyi = self.indices(ctx, &self.xy_materials, "xy_materials")?;
        // A grading's composition over its own materials, placed among the part's.
        let spread = |c: Composition, at: &[usize]| {
            let mut f = vec![0.0; n];
            for (&i, v) in at.iter().zip(c.fractions) {
                f[i] += v;
            }
            f
        };
        for region in regions.iter_mut() {
            let rxy = if self.xy_level {
                region.level
            } else {
                index_level(region.index, region.count)
            };
            let args = |r: f64| region_args(ctx, region, r);
            let context = || {
                format!(
                    "part `{}`, layer {} (z = {:.4}, r_z = {rz}), region {} (r_xy = {rxy})",
                    part.name, ctx.layer.index, ctx.layer.z, region.index
                )
            };
            let mz = spread(self.z.composition(&args(rz), zi.len(), context)?, &zi);
            let mxy = spread(self.xy.composition(&args(rxy), xyi.len(), context)?, &xyi);
            let mut f: Vec<f64> = mz
                .iter()
                .zip(&mxy)
                .map(|(a, b)| ((kz * a + kxy * b) / (kz + kxy)).clamp(0.0, 1.0))
                .collect();
            let sum: f64 = f.iter().sum();
            f.iter_mut().for_each(|v| *v /= sum);
            region.composition = Some(Composition::new(f)?);
        }
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let span = span(config, (o.from_layer, o.to_layer), (o.from_z, o.to_z))?;
    if !o.weights.iter().all(|w| w.is_finite() && *w >= 0.0) || o.weights[0] + o.weights[1] <= 0.0 {
        return Err(config.error("weights", "must be two non-negative numbers, not both 0"));
    }
    let control = |f: Option<String>, default: (f64, f64)| {
        Control::from_options(
            config,
            &ControlOptions {
                f,
                mu: None,
                lambda: None,
                alpha: None,
                k: None,
            },
            default,
        )
    };
    Ok(AnyStage::Grade(Box::new(Both {
        z: control(Some(o.z_f), (1.0, 0.0))?,
        xy: control(Some(o.xy_f), (-1.0, 1.0))?,
        span,
        weights: o.weights,
        xy_level: o.xy_level,
        z_materials: pair(config, o.z_materials, "z_materials")?,
        xy_materials: pair(config, o.xy_materials, "xy_materials")?,
    })))
}

/// A list of material names given for one grading: not empty, no name twice.
fn pair(config: &StageConfig<'_>, names: Option<Vec<String>>, key: &str) -> Result<Option<Vec<String>>> {
    if let Some(n) = &names {
        if n.is_empty() {
            return Err(config.error(key, "name at least one material"));
        }
        if n.iter().enumerate().any(|(i, a)| n[..i].contains(a)) {
            return Err(config.error(key, "a material is named twice"));
        }
    }
    Ok(names)
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: "zxy",
        doc: "Grades along Z and across the layer at once: the Z and X-Y control functions' compositions combined by weights (Eq. 8 of the step-width paper).",
        options: Options::SPECS,
        example: "use = \"zxy\"\nz_f = \"r\"\nxy_f = \"1.0 - r\"\nweights = [1.0, 3.0]",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{self, info, regions};
    use lamina_api::{ContourTree, Layer, RunInfo};

    /// The fractions `both` gives the `n` regions of a family on layer `index`.
    fn grade(both: &Both, info: &RunInfo, index: usize, n: usize) -> Result<Vec<Vec<f64>>> {
        let layer = Layer {
            index,
            ..Layer::default()
        };
        let tree = ContourTree::default();
        let ctx = fixtures::context(info, &layer, &tree, &[]);
        let mut rs = regions(n);
        both.grade(&ctx, &mut rs)?;
        Ok(rs
            .into_iter()
            .map(|r| r.composition.expect("graded").fractions)
            .collect())
    }

    /// f = r along Z from layer 0 to 10, f = 1 - r across, weighted `weights`.
    fn both(weights: [f64; 2], z: Option<&[&str]>, xy: Option<&[&str]>) -> Both {
        let names = |v: Option<&[&str]>| v.map(|v| v.iter().map(|s| s.to_string()).collect());
        Both {
            z: Control::Linear { mu: 1.0, lambda: 0.0 },
            xy: Control::Linear {
                mu: -1.0,
                lambda: 1.0,
            },
            span: Span::Layers(0, 10),
            weights,
            xy_level: false,
            z_materials: names(z),
            xy_materials: names(xy),
        }
    }

    fn near(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    /// Eq. 8, (k_z M_z + k_xy M_xy) / (k_z + k_xy), with weights 1 : 3. On layer 3 of
    /// 0-10 (r_z = 0.3) the Z grading gives the first material 0.3; across, region j
    /// of 5 gets 1 - j/4. Over the same two materials the first takes
    /// (0.3 + 3 (1 - j/4)) / 4; over Fig. 19's two pairs, red 0.3 / 4, green 0.7 / 4,
    /// ceramic 3 (1 - j/4) / 4, metal 3 (j/4) / 4.
    #[test]
    fn eq_8_weighs_the_z_and_the_x_y_grading() {
        let two = info(&[("a", [255, 0, 0]), ("b", [0, 0, 255])]);
        let got = grade(&both([1.0, 3.0], None, None), &two, 3, 5).expect("grades");
        for (j, f) in got.iter().enumerate() {
            let want = (0.3 + 3.0 * (1.0 - j as f64 / 4.0)) / 4.0;
            assert!(near(f, &[want, 1.0 - want]), "region {j}: {f:?} vs {want}");
        }
        let four = info(&[
            ("red", [255, 0, 0]),
            ("green", [0, 255, 0]),
            ("ceramic", [255, 255, 0]),
            ("metal", [0, 0, 255]),
        ]);
        let fig19 = both([1.0, 3.0], Some(&["red", "green"]), Some(&["ceramic", "metal"]));
        let got = grade(&fig19, &four, 3, 5).expect("grades");
        for (j, f) in got.iter().enumerate() {
            let r = j as f64 / 4.0;
            let want = [0.3 / 4.0, 0.7 / 4.0, 3.0 * (1.0 - r) / 4.0, 3.0 * r / 4.0];
            assert!(near(f, &want), "region {j}: {f:?} vs {want:?}");
        }
        // The pairs named the other way round: the Z grading runs green to red.
        let swapped = both([1.0, 3.0], Some(&["green", "red"]), Some(&["ceramic", "metal"]));
        let got = grade(&swapped, &four, 3, 5).expect("grades");
        assert!(near(&got[0], &[0.7 / 4.0, 0.3 / 4.0, 0.75, 0.0]), "{:?}", got[0]);
    }

    /// A weight of 0 leaves the other grading alone, pure materials included.
    #[test]
    fn a_zero_weight_leaves_the_other_grading_alone() {
        let two = info(&[("a", [255, 0, 0]), ("b", [0, 0, 255])]);
        // Along Z alone on layer 0 (r_z = 0): the second material only.
        let got = grade(&both([1.0, 0.0], None, None), &two, 0, 3).expect("grades");
        assert!(got.iter().all(|f| near(f, &[0.0, 1.0])), "{got:?}");
        // Across alone: the outer region is the first material, whatever the layer.
        let got = grade(&both([0.0, 1.0], None, None), &two, 7, 3).expect("grades");
        assert!(
            near(&got[0], &[1.0, 0.0]) && near(&got[2], &[0.0, 1.0]),
            "{got:?}"
        );
    }

    #[test]
    fn a_material_the_part_lacks_is_named() {
        let two = info(&[("a", [255, 0, 0]), ("b", [0, 0, 255])]);
        let err = grade(&both([1.0, 1.0], None, Some(&["a", "gold"])), &two, 0, 2).expect_err("no gold");
        assert!(
            err.to_string()
                .contains("`xy_materials`: part `plate` has no material `gold`"),
            "{err}"
        );
    }
}
