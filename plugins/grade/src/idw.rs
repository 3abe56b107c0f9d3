//! `idw`: several contours of a family each carry a primary material, and a region's
//! composition is the inverse-distance weighting of those materials at its reference
//! point (topological-hierarchy-fgm Eq. 22-24): with d_k the shortest distance from
//! the point to contour k, the weight of contour i is the product of the other
//! distances over the sum of such products, which is (1/d_i) / sum_j (1/d_j) and
//! gives a point on a contour that contour's material alone. With circumferential cells
//! (each with its own reference point) the composition varies around the family too.

use lamina_api::stage::{AnyStage, FamilyContext, Grader, StageConfig, StageInfo, StageKind};
use lamina_api::{Composition, Contour, Error, Point2, Result, RunInfo, StageFactory, SubRegion};
use serde::Deserialize;

lamina_api::option_type!(HolesSpec = "string or array of table");

#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum HolesSpec {
    /// One material for every hole.
    All(String),
    /// Each hole takes the material of the listed point nearest to it.
    Near(Vec<NearSpec>),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NearSpec {
    near: [f64; 2],
    material: String,
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// material of the family's outer contour
        outer: String,
        /// material of every hole (unset: the outer's material), or `[{ near = [x, y], material = "m" }, ...]`: each hole takes the material of the nearest listed point
        holes: Option<HolesSpec>,
        /// exponent of the distances (1 in the paper)
        #[range(0.01, 100.0)]
        power: f64 = "1.0",
    }
}

struct Idw {
    outer: String,
    holes: Option<HolesSpec>,
    power: f64,
}

/// Inverse-distance weights (Eq. 23 for `power` = 1): zero distances share the whole
/// weight, so a point on a contour takes that contour's material.
pub fn weights(distances: &[f64], power: f64) -> Vec<f64> {
    let zeros = distances.iter().filter(|&&d| d <= 0.0).count();
    if zeros > 0 {
        let w = 1.0 / zeros as f64;
        return distances
            .iter()
            .map(|&d| if d <= 0.0 { w } else { 0.0 })
            .collect();
    }
    let inv: Vec<f64> = distances.iter().map(|d| d.powf(-power)).collect();
    let sum: f64 = inv.iter().sum();
    inv.iter().map(|w| w / sum).collect()
}

impl Idw {
    /// Index among the part's materials of the material named `name`.
    fn material(&self, info: &RunInfo, part: usize, name: &str) -> Result<usize> {
        let p = &info.parts[part];
        p.materials
            .iter()
            .position(|&m| info.materials[m].name == name)
            .ok_or_else(|| Error::stage("grade:idw", format!("part `{}` has no material `{name}`", p.name)))
    }

    /// The material of each contour of the family: outer first, then the holes.
    fn contour_materials(&self, ctx: &FamilyContext<'_>, contours: &[&Contour]) -> Result<Vec<usize>> {
        let mut out = vec![self.material(ctx.info, ctx.part, &self.outer)?];
        for hole in &contours[1..] {
            let m = match &self.holes {
                None => self.material(ctx.info, ctx.part, &self.outer)?,
                Some(HolesSpec::All(name)) => self.material(ctx.info, ctx.part, name)?,
                Some(HolesSpec::Near(list)) => {
                    let nearest = list
                        .iter()
                        .min_by(|a, b| {
                            let da = hole.distance(Point2::new(a.near[0], a.near[1]));
                            let db = hole.distance(Point2::new(b.near[0], b.near[1]));
                            da.total_cmp(&db)
                        })
                        .ok_or_else(|| Error::stage("grade:idw", "`holes` lists no material"))?;
                    self.material(ctx.info, ctx.part, &nearest.material)?
                }
            };
            out.push(m);
        }
        Ok(out)
    }
}

impl Grader for Idw {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        let family = &ctx.tree.families[ctx.family];
        let contours: Vec<&Contour> = std::iter::once(family.outer)
            .chain(family.holes.iter().copied())
            .map(|c| &ctx.layer.contours[c])
            .collect();
        let materials = self.contour_materials(ctx, &contours)?;
        let n = ctx.info.parts[ctx.part].materials.len();
        for region in regions.iter_mut() {
            let d: Vec<f64> = contours.iter().map(|c| c.distance(region.reference)).collect();
            let w = weights(&d, self.power);
            let mut fractions = vec![0.0; n];
            for (m, w) in materials.iter().zip(&w) {
                fractions[*m] += w;
            }
            // The weights sum to 1 up to rounding; make it exact for the check.
            let sum: f64 = fractions.iter().sum();
            fractions.iter_mut().for_each(|f| *f /= sum);
            region.composition = Some(Composition::new(fractions).map_err(|e| {
                Error::stage(
                    "grade:idw",
                    format!(
                        "layer {}, family {}, region {}: {e}",
                        ctx.layer.index, ctx.family, region.index
                    ),
                )
            })?);
        }
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    // `power` is positive by its declared range.
    let o: Options = config.parse()?;
    if let Some(HolesSpec::Near(list)) = &o.holes {
        if list.is_empty() {
            return Err(config.error("holes", "lists no material"));
        }
        if list.iter().any(|n| !n.near.iter().all(|v| v.is_finite())) {
            return Err(config.error("holes", "`near` must be two finite numbers [x, y]"));
        }
    }
    Ok(AnyStage::Grade(Box::new(Idw {
        outer: o.outer,
        holes: o.holes,
        power: o.power,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: "idw",
        doc: "Each contour of a family carries a material; a region's composition is the inverse-distance weighting (Eq. 22-23) of them at its reference point (cell centre).",
        options: Options::SPECS,
        example: "use = \"idw\"\nouter = \"red\"\nholes = \"green\"",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures;

    /// Eq. 23 written as the paper does: the product of the other distances over the
    /// sum of such products.
    fn eq23(d: &[f64]) -> Vec<f64> {
        let prod_except = |i: usize| -> f64 {
            d.iter()
                .enumerate()
                .filter(|&(k, _)| k != i)
                .map(|(_, v)| v)
                .product()
        };
        let denom: f64 = (0..d.len()).map(prod_except).sum();
        (0..d.len()).map(|i| prod_except(i) / denom).collect()
    }

    #[test]
    fn weights_match_eq_23_for_three_and_four_contours() {
        for d in [vec![1.0, 2.0, 3.0], vec![0.5, 4.0, 2.5, 1.25]] {
            let w = weights(&d, 1.0);
            let e = eq23(&d);
            for (a, b) in w.iter().zip(&e) {
                assert!((a - b).abs() < 1e-12, "{w:?} vs {e:?}");
            }
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        // Three contours at 1, 2, 3: omega_1 = d2 d3 / (d1 d2 + d1 d3 + d2 d3) = 6/11.
        let w = weights(&[1.0, 2.0, 3.0], 1.0);
        assert!((w[0] - 6.0 / 11.0).abs() < 1e-12);
        assert!((w[1] - 3.0 / 11.0).abs() < 1e-12);
        assert!((w[2] - 2.0 / 11.0).abs() < 1e-12);
    }

    #[test]
    fn a_point_on_a_contour_takes_its_material() {
        assert_eq!(weights(&[0.0, 2.0, 3.0], 1.0), [1.0, 0.0, 0.0]);
        assert_eq!(weights(&[0.0, 0.0, 3.0], 1.0), [0.5, 0.5, 0.0]);
    }

    /// Grades regions whose references are `points` in a 10 mm square with two 2 mm
    /// square holes, about (3, 5) and (7, 5), by `idw` over materials a, b, c.
    fn grade_points(idw: &Idw, points: &[(f64, f64)]) -> Result<Vec<Vec<f64>>> {
        let info = fixtures::info(&[("a", [255, 0, 0]), ("b", [0, 255, 0]), ("c", [0, 0, 255])]);
        let square = |x0: f64, y0: f64, side: f64| {
            Contour::rectangle(Point2::new(x0, y0), Point2::new(x0 + side, y0 + side))
        };
        let layer = lamina_api::Layer {
            contours: vec![
                square(0.0, 0.0, 10.0),
                square(2.0, 4.0, 2.0).oriented(false),
                square(6.0, 4.0, 2.0).oriented(false),
            ],
            ..lamina_api::Layer::default()
        };
        let tree = lamina_api::ContourTree {
            nodes: Vec::new(),
            families: vec![lamina_api::Family {
                outer: 0,
                holes: vec![1, 2],
            }],
        };
        let ctx = fixtures::context(&info, &layer, &tree, &[]);
        let mut regions = fixtures::regions(points.len());
        for (r, &(x, y)) in regions.iter_mut().zip(points) {
            r.reference = Point2::new(x, y);
        }
        idw.grade(&ctx, &mut regions)?;
        Ok(regions
            .into_iter()
            .map(|r| r.composition.expect("graded").fractions)
            .collect())
    }

    fn near(holes: &[((f64, f64), &str)]) -> Option<HolesSpec> {
        Some(HolesSpec::Near(
            holes
                .iter()
                .map(|&((x, y), m)| NearSpec {
                    near: [x, y],
                    material: m.into(),
                })
                .collect(),
        ))
    }

    /// Eq. 23 at a region's reference: at (5, 1) the outer contour is 1 mm away and
    /// each hole sqrt(10); at (5, 5), 5 mm and 1 mm and 1 mm; at (9, 9), 1 mm, sqrt(34)
    /// and sqrt(10); on a hole, that hole's
    /// material alone. Each hole takes the material of the listed point nearest it,
    /// whatever the list's order; contours of one material add up.
    #[test]
    fn each_contour_weighs_its_material_by_eq_23() {
        let points = [(5.0, 1.0), (5.0, 5.0), (2.0, 5.0), (9.0, 9.0)];
        let s10 = 10f64.sqrt();
        let eq23 = |d: [f64; 3]| {
            let inv = d.map(|d| 1.0 / d);
            let sum: f64 = inv.iter().sum();
            inv.map(|w| w / sum)
        };
        let check = |got: &[Vec<f64>], want: &[[f64; 3]]| {
            for (g, w) in got.iter().zip(want) {
                assert!(
                    g.iter().zip(w).all(|(a, b)| (a - b).abs() < 1e-12),
                    "{got:?} vs {want:?}"
                );
            }
        };
        let (d0, d1, d3) = (
            eq23([1.0, s10, s10]),
            eq23([5.0, 1.0, 1.0]),
            eq23([1.0, 34f64.sqrt(), s10]),
        );
        for holes in [
            near(&[((1.0, 5.0), "b"), ((9.0, 5.0), "c")]),
            near(&[((9.0, 5.0), "c"), ((1.0, 5.0), "b")]),
        ] {
            let idw = Idw {
                outer: "a".into(),
                holes,
                power: 1.0,
            };
            let got = grade_points(&idw, &points).expect("grades");
            check(&got, &[d0, d1, [0.0, 1.0, 0.0], d3]);
        }
        // Every hole of one material: the two holes' weights add up.
        let idw = Idw {
            outer: "a".into(),
            holes: Some(HolesSpec::All("c".into())),
            power: 1.0,
        };
        let got = grade_points(&idw, &points).expect("grades");
        let both = |d: [f64; 3]| [d[0], 0.0, d[1] + d[2]];
        check(&got, &[both(d0), both(d1), [0.0, 0.0, 1.0], both(d3)]);
        // Holes of the outer's material (unset): the whole family is that material.
        let idw = Idw {
            outer: "b".into(),
            holes: None,
            power: 1.0,
        };
        let got = grade_points(&idw, &points).expect("grades");
        check(&got, &[[0.0, 1.0, 0.0]; 4]);
        // A material the part lacks is named.
        let idw = Idw {
            outer: "gold".into(),
            holes: None,
            power: 1.0,
        };
        let err = grade_points(&idw, &points).expect_err("no gold").to_string();
        assert!(err.contains("part `plate` has no material `gold`"), "{err}");
    }

    /// The exponent: with power 2, weights go as 1 / d^2.
    #[test]
    fn the_power_sharpens_the_weights() {
        let w = weights(&[1.0, 2.0], 2.0);
        assert!((w[0] - 0.8).abs() < 1e-12 && (w[1] - 0.2).abs() < 1e-12, "{w:?}");
    }
}
