//! `sources`: the discretiser that cuts each family along the step boundaries of its
//! grading sources and gives every homogeneous region its composition.

use lamina_core::stage::{
    AnyStage, Discretiser, FamilyContext, OptionSpec, StageConfig, StageInfo, StageKind,
};
use lamina_core::steps::Truncation;
use lamina_core::{Composition, Error, Region, Result, StageFactory};
use serde::Deserialize;

use crate::shapes::{Shapes, closer_than, inside_point, polygon_shapes, to_polygons};
use crate::source::{Datum, Source, combine};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Kind {
    Point,
    Axis,
    Plane,
    Surface,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum CompositionSpec {
    Material(String),
    Fractions(Vec<f64>),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SourceSpec {
    kind: Kind,
    #[serde(default)]
    at: [f64; 3],
    direction: Option<[f64; 3]>,
    width: Option<f64>,
    alpha: Option<f64>,
    #[serde(default = "one")]
    k: f64,
    start: CompositionSpec,
    end: CompositionSpec,
    #[serde(default = "d_step")]
    step: f64,
    #[serde(default = "one")]
    weight: f64,
}

fn one() -> f64 {
    1.0
}
fn d_step() -> f64 {
    0.25
}
fn d_tolerance() -> f64 {
    0.001
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Options {
    sources: Vec<SourceSpec>,
    #[serde(default = "d_tolerance")]
    tolerance: f64,
}

/// A source whose compositions are still named (materials are resolved per part).
struct Pending {
    source: Source,
    start: CompositionSpec,
    end: CompositionSpec,
}

struct Sources {
    sources: Vec<Pending>,
    tolerance: f64,
}

impl Sources {
    /// The fractions over the part's materials that a spec names.
    fn resolve(&self, ctx: &FamilyContext<'_>, spec: &CompositionSpec, which: usize) -> Result<Vec<f64>> {
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        match spec {
            CompositionSpec::Material(name) => part
                .materials
                .iter()
                .position(|&m| ctx.info.materials[m].name == *name)
                .map(|i| Composition::pure(i, n).fractions)
                .ok_or_else(|| {
                    Error::stage(
                        "discretise:sources",
                        format!("source {which}: part `{}` has no material `{name}`", part.name),
                    )
                }),
            CompositionSpec::Fractions(f) if f.len() == n => Ok(f.clone()),
            CompositionSpec::Fractions(f) => Err(Error::stage(
                "discretise:sources",
                format!(
                    "source {which}: {} fractions, part `{}` has {n} materials",
                    f.len(),
                    part.name
                ),
            )),
        }
    }
}

impl Discretiser for Sources {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<Region>> {
        let family = ctx.tree.family_polygon(&ctx.layer.contours, ctx.family);
        let family_area = family.area();
        let z = ctx.layer.z - ctx.layer.thickness / 2.0;
        let mut bbox = family.bbox();
        let margin = bbox.diagonal().max(1.0);
        bbox.include(lamina_core::Point2::new(bbox.min.x - margin, bbox.min.y - margin));
        bbox.include(lamina_core::Point2::new(bbox.max.x + margin, bbox.max.y + margin));
        let mut sources = Vec::with_capacity(self.sources.len());
        for (i, p) in self.sources.iter().enumerate() {
            let mut s = p.source.clone();
            s.start = self.resolve(ctx, &p.start, i)?;
            s.end = self.resolve(ctx, &p.end, i)?;
            sources.push(s);
        }
        // Cells of the overlay: a piece of the family and the step of each source.
        let family_shapes = polygon_shapes(&family);
        let mut cells: Vec<(Shapes, Vec<usize>)> = vec![(family_shapes.clone(), Vec::new())];
        for s in &sources {
            let sets: Vec<_> = s
                .thresholds()
                .iter()
                .map(|&d| closer_than(&s.datum, d, z, &bbox, self.tolerance, &family_shapes))
                .collect();
            let mut next = Vec::new();
            for (cell, steps) in cells {
                let mut rest = cell;
                for (u, set) in sets.iter().enumerate() {
                    let inside = set.intersect(&rest);
                    if !inside.is_empty() {
                        next.push((inside, [steps.as_slice(), &[u]].concat()));
                    }
                    rest = set.subtract_from(&rest);
                    if rest.is_empty() {
                        break;
                    }
                }
                if !rest.is_empty() {
                    next.push((rest, [steps.as_slice(), &[sets.len()]].concat()));
                }
            }
            cells = next;
        }
        let sliver = family_area.abs() * 1e-12;
        let mut pieces = Vec::new();
        for (shapes, steps) in &cells {
            let polygons: Vec<_> = to_polygons(shapes)
                .into_iter()
                .filter(|p| p.area() > sliver)
                .collect();
            if !polygons.is_empty() {
                pieces.push((polygons, steps));
            }
        }
        let count = pieces.len();
        let total_weight: f64 = sources.iter().map(|s| s.weight).sum();
        let mut regions = Vec::new();
        for (index, (polygons, steps)) in pieces.into_iter().enumerate() {
            let levels: Vec<f64> = sources.iter().zip(steps).map(|(s, &u)| s.levels()[u]).collect();
            let parts: Vec<(f64, Vec<f64>)> = sources
                .iter()
                .zip(&levels)
                .map(|(s, &l)| (s.weight, s.composition(l)))
                .collect();
            let mut fractions = combine(&parts);
            // Clear the rounding of the blend so the sum check sees exactly 1.
            for f in &mut fractions {
                *f = f.clamp(0.0, 1.0);
            }
            let sum: f64 = fractions.iter().sum();
            fractions.iter_mut().for_each(|f| *f /= sum);
            let composition = Composition::new(fractions)?;
            let level = sources
                .iter()
                .zip(&levels)
                .map(|(s, l)| s.weight * l)
                .sum::<f64>()
                / total_weight;
            for polygon in polygons {
                regions.push(Region {
                    family: ctx.family,
                    index,
                    count,
                    level,
                    reference: inside_point(&polygon),
                    polygon,
                    cell: None,
                    composition: Some(composition.clone()),
                });
            }
        }
        Ok(regions)
    }

    fn grades(&self) -> bool {
        true
    }
}

fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (n.is_finite() && n > 0.0).then(|| v.map(|c| c / n))
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    if o.sources.is_empty() {
        return Err(config.error("sources", "give at least one grading source"));
    }
    if !(o.tolerance.is_finite() && o.tolerance > 0.0) {
        return Err(config.error("tolerance", "must be a positive number of mm"));
    }
    let mut sources = Vec::new();
    for (i, s) in o.sources.into_iter().enumerate() {
        let bad = |m: &str| config.error("sources", format!("source {i}: {m}"));
        if !s.at.iter().all(|v| v.is_finite()) {
            return Err(bad("`at` must be three finite numbers"));
        }
        let datum = match s.kind {
            Kind::Point => Datum::Point(s.at),
            Kind::Axis => Datum::Axis {
                at: s.at,
                direction: unit(s.direction.unwrap_or([0.0, 0.0, 1.0]))
                    .ok_or_else(|| bad("`direction` must be a non-zero vector"))?,
            },
            Kind::Surface => Datum::Surface,
            Kind::Plane => Datum::Plane {
                at: s.at,
                normal: unit(s.direction.unwrap_or([0.0, 0.0, 1.0]))
                    .ok_or_else(|| bad("`direction` (the normal) must be a non-zero vector"))?,
            },
        };
        let alpha = match (s.alpha, s.width) {
            (Some(a), None) => a,
            (None, Some(w)) if w > 0.0 => 1.0 / w,
            (None, None) => return Err(bad("give `width` (mm over which f runs from 0 to 1) or `alpha`")),
            _ => return Err(bad("give either `width` (positive) or `alpha`, not both")),
        };
        if !(alpha.is_finite() && alpha > 0.0) {
            return Err(bad("`alpha` must be a positive number"));
        }
        if !(s.k.is_finite() && s.k > 0.0) {
            return Err(bad("`k` must be a positive number"));
        }
        let steps = Truncation::new(s.step).map_err(|e| bad(&e))?;
        if !(s.weight.is_finite() && s.weight > 0.0) {
            return Err(bad("`weight` must be a positive number"));
        }
        for spec in [&s.start, &s.end] {
            if let CompositionSpec::Fractions(f) = spec {
                Composition::check(f).map_err(|e| bad(&e.to_string()))?;
            }
        }
        sources.push(Pending {
            source: Source {
                datum,
                alpha,
                k: s.k,
                start: Vec::new(),
                end: Vec::new(),
                steps,
                weight: s.weight,
            },
            start: s.start,
            end: s.end,
        });
    }
    Ok(AnyStage::Discretise(Box::new(Sources {
        sources,
        tolerance: o.tolerance,
    })))
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "sources",
        doc: "Grading sources (point, axis, plane, outer surface): f(d) = (alpha d)^k truncated in steps of t_g, regions cut along the steps and overlaid, compositions by Eq. 2 and 8.",
        options: &[
            OptionSpec::required(
                "sources",
                "array of table",
                "each `{ kind = \"point\" | \"axis\" | \"plane\" | \"surface\" (the layer's boundary), at = [x, y, z], direction = [x, y, z] (axis direction or plane normal), width (or alpha), k = 1, start, end (material name or fractions), step = 0.25, weight = 1 }`"
            ),
            OptionSpec::new(
                "tolerance",
                "float",
                "0.001",
                "largest chord error of curved step boundaries (mm)"
            ),
        ],
        example: "use = \"sources\"\nsources = [{ kind = \"axis\", at = [0.0, 0.0, 0.0], width = 10.0, start = \"red\", end = \"green\" }]",
    },
    build,
});
