//! `xy`: grading across a layer (topological-hierarchy-fgm Eq. 18-21): the sub-regions
//! of a family, numbered j = 0 .. N_R - 1 from the grading reference (the outer
//! contour) inward, get the level r_j = j / (N_R - 1), or the level the discretiser
//! measured, and a control function of r gives their compositions. The default,
//! f = 1 - r, puts the part's first material at the outer contour and the second at the
//! far end, as the paper's green-to-black example does.

use lamina_core::stage::{AnyStage, FamilyContext, Grader, OptionSpec, StageConfig, StageInfo, StageKind};
use lamina_core::{Region, Result, StageFactory};
use serde::Deserialize;

use crate::control::{CONTROL_OPTIONS, Control, ControlOptions, region_args};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
enum LevelSource {
    /// r_j = j / (N_R - 1) from the region's index (Eq. 21).
    #[default]
    Index,
    /// The level the discretiser gave the region (a distance ratio).
    Level,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Options {
    f: Option<String>,
    mu: Option<f64>,
    lambda: Option<f64>,
    alpha: Option<f64>,
    k: Option<f64>,
    #[serde(default)]
    r: LevelSource,
}

struct InPlane {
    control: Control,
    source: LevelSource,
}

/// Eq. 21: r_j = j / (N_R - 1); a family that is one region sits at r = 0.
pub fn index_level(index: usize, count: usize) -> f64 {
    if count <= 1 {
        0.0
    } else {
        index as f64 / (count - 1) as f64
    }
}

impl Grader for InPlane {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [Region]) -> Result<()> {
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        for region in regions.iter_mut() {
            let r = match self.source {
                LevelSource::Index => index_level(region.index, region.count),
                LevelSource::Level => region.level,
            };
            let args = region_args(ctx, region, r);
            let context = format!(
                "part `{}`, layer {} (z = {:.4}), family {}, region {} (r = {r})",
                part.name, ctx.layer.index, ctx.layer.z, ctx.family, region.index
            );
            region.composition = Some(self.control.composition(&args, n, &context)?);
        }
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let control = Control::from_options(
        config,
        &ControlOptions {
            f: o.f,
            mu: o.mu,
            lambda: o.lambda,
            alpha: o.alpha,
            k: o.k,
        },
        (-1.0, 1.0),
    )?;
    Ok(AnyStage::Grade(Box::new(InPlane { control, source: o.r })))
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: "xy",
        doc: "Grades across the layer: each sub-region j of N_R gets r = j / (N_R - 1) (or the discretiser's level), fractions from a control function of r (default f = 1 - r: first material at the outer contour).",
        options: &[
            CONTROL_OPTIONS[0],
            CONTROL_OPTIONS[1],
            CONTROL_OPTIONS[2],
            CONTROL_OPTIONS[3],
            CONTROL_OPTIONS[4],
            OptionSpec::new(
                "r",
                "string",
                "\"index\"",
                "\"index\" (j / (N_R - 1), Eq. 21) or \"level\" (the discretiser's distance ratio)"
            ),
        ],
        example: "use = \"xy\"\nf = \"linear\"\nmu = -1.0\nlambda = 1.0",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_core::{Contour, ContourTree, Layer, Material, PartInfo, Point2, Polygon, RunInfo};

    fn info() -> RunInfo {
        let mat = |name: &str, colour| Material {
            name: name.into(),
            colour,
            layer_thickness: None,
        };
        RunInfo {
            base_dir: ".".into(),
            materials: vec![mat("green", [0, 255, 0]), mat("black", [0, 0, 0])],
            parts: vec![PartInfo {
                name: "plate".into(),
                materials: vec![0, 1],
                mesh: 0,
                z_min: 0.0,
                z_max: 1.0,
            }],
            z_min: 0.0,
            z_max: 1.0,
            xy_bounds: lamina_core::BBox2::EMPTY,
            machine: None,
        }
    }

    fn regions(n: usize) -> Vec<Region> {
        let square = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(0.0, 1.0),
        ]);
        (0..n)
            .map(|j| Region {
                family: 0,
                index: j,
                count: n,
                level: index_level(j, n),
                polygon: Polygon::new(square.clone(), vec![]),
                cell: None,
                reference: Point2::new(0.5, 0.5),
                composition: None,
            })
            .collect()
    }

    /// topological-hierarchy-fgm Eq. 20-21 and Fig. 8: ten sub-regions from green at
    /// the outer contour to black at the inner one.
    #[test]
    fn ten_sub_regions_from_green_to_black() {
        let info = info();
        let layer = Layer::default();
        let tree = ContourTree::default();
        let ctx = FamilyContext {
            info: &info,
            layer: &layer,
            tree: &tree,
            mesh: None,
            part: 0,
            family: 0,
        };
        let grader = InPlane {
            control: Control::Linear {
                mu: -1.0,
                lambda: 1.0,
            },
            source: LevelSource::Index,
        };
        let mut rs = regions(10);
        grader.grade(&ctx, &mut rs).expect("grades");
        let colours: Vec<[u8; 3]> = rs
            .iter()
            .map(|r| r.composition.as_ref().expect("graded").colour(&info.materials))
            .collect();
        let greens: Vec<u8> = colours.iter().map(|c| c[1]).collect();
        assert_eq!(greens, [255, 227, 198, 170, 142, 113, 85, 57, 28, 0]);
        assert!(colours.iter().all(|c| c[0] == 0 && c[2] == 0));
        for r in &rs {
            let f = &r.composition.as_ref().expect("graded").fractions;
            assert!((f[0] + f[1] - 1.0).abs() < 1e-12);
            assert!((f[0] - (1.0 - r.index as f64 / 9.0)).abs() < 1e-12);
        }
    }

    #[test]
    fn a_single_region_is_the_first_material() {
        assert_eq!(index_level(0, 1), 0.0);
        assert_eq!(index_level(4, 5), 1.0);
    }

    #[test]
    fn three_materials_need_a_script() {
        let mut info = info();
        info.materials.push(Material {
            name: "blue".into(),
            colour: [0, 0, 255],
            layer_thickness: None,
        });
        info.parts[0].materials = vec![0, 1, 2];
        let layer = Layer::default();
        let tree = ContourTree::default();
        let ctx = FamilyContext {
            info: &info,
            layer: &layer,
            tree: &tree,
            mesh: None,
            part: 0,
            family: 0,
        };
        let grader = InPlane {
            control: Control::Wave {
                mu: 1.0,
                lambda: std::f64::consts::PI,
            },
            source: LevelSource::Index,
        };
        let err = grader.grade(&ctx, &mut regions(3)).expect_err("three materials");
        assert!(err.to_string().contains("returns 3 fractions"), "{err}");
    }
}
