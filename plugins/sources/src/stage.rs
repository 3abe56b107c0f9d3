//! `sources`: the discretiser that cuts each family along the step boundaries of its
//! grading sources and gives every homogeneous region its composition.

use lamina_api::stage::{AnyStage, Discretiser, FamilyContext, StageConfig, StageInfo, StageKind};
use lamina_api::{Composition, Error, Polygon, Result, StageFactory, SubRegion};
use lamina_fgm::steps::Truncation;
use lamina_fgm::surface::{FaceSelection, Surfaces};
use serde::Deserialize;

use lamina_geom::ring::{polygons_of, shape_of};

use crate::shapes::{Set, Shapes, SurfaceField, clean, closer_than, union};
use crate::source::{Datum, Source, combine};

/// The stage's name in errors.
const STAGE: &str = "discretise:sources";

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

lamina_api::option_type!(SourceSpec = "table", array "array of table");

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
    /// `kind = "surface"`: which faces of the part's mesh are the outer surface (all
    /// when absent).
    faces: Option<FaceSelection>,
    /// `kind = "surface"`: `space` (the paper's: the distance in space to the chosen
    /// faces) or `layer` (the distance within the layer to the family's boundary).
    #[serde(default)]
    measure: Measure,
}

/// Where the distance to an outer surface is measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Measure {
    #[default]
    Space,
    Layer,
}

fn one() -> f64 {
    1.0
}
fn d_step() -> f64 {
    0.25
}
lamina_api::option_type!(Combine = "string");

/// Where the sources' compositions are combined by Eq. 8.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Combine {
    /// The paper's regularised booleans: a source counts where a point lies in its
    /// effective grading region (0 <= f <= 1). R12 = R1 ∩* R2 blends the sources, R1' =
    /// R1 /* R12 keeps source 1's composition alone, and where no source grades the
    /// complementary compositions (Ms, Me) of every source are blended.
    #[default]
    Intersection,
    /// Every source blends everywhere, with its complementary composition outside its
    /// effective region.
    Everywhere,
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// each `{ kind = "point" | "axis" | "plane" | "surface", at = [x, y, z], direction = [x, y, z] (axis direction or plane normal), width (or alpha), k = 1, start, end (material name or fractions), step = 0.25, weight = 1 }`; a `surface` source measures d in space from chosen faces of the part's mesh (Fig. 1d): `faces = { normal = [x, y, z], within = 30.0, groups = ["name"] }` (all faces when absent), or within the layer to the family's boundary with `measure = "layer"`
        sources: Vec<SourceSpec>,
        /// samples along a family's longer side where the distance in space to a `surface` source's faces is sampled (formerly `surface_cells`)
        #[range(8, 4096)]
        #[formerly("surface_cells")]
        surface_samples: usize = "256",
        /// largest chord error of curved step boundaries (mm)
        #[range(0.0001, 10.0)]
        tolerance: f64 = "0.001",
        /// where Eq. 8 blends: `intersection` (the paper's regularised booleans: only where effective grading regions 0 <= f <= 1 overlap; a source alone keeps its own composition) or `everywhere` (every source at every point)
        combine: Combine = r#""intersection""#,
    }
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
    combine: Combine,
    /// Per source, the faces of a `surface` source measured in space, and their
    /// surface per mesh, built once per run.
    faces: Vec<Option<(FaceSelection, Surfaces)>>,
    surface_samples: usize,
}

/// A piece of the family with, per source, its step and whether it lies in that
/// source's effective grading region.
struct Patch {
    shapes: Shapes,
    steps: Vec<usize>,
    effective: Vec<bool>,
}

/// `shapes` cut by `set`: the pieces inside it (tagged `true`) and outside.
fn split(shapes: Shapes, set: &Set) -> Vec<(Shapes, bool)> {
    match set {
        Set::Whole => vec![(shapes, true)],
        Set::Empty => vec![(shapes, false)],
        Set::Shapes(_) => {
            let inside = set.intersect(&shapes);
            let outside = set.subtract_from(&shapes);
            [(inside, true), (outside, false)]
                .into_iter()
                .filter(|(s, _)| !s.is_empty())
                .collect()
        }
    }
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
    /// A `surface` source measured in space reads faces of the part's mesh.
    fn reads_mesh(&self) -> bool {
        self.faces.iter().any(Option::is_some)
    }

    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>> {
        let family = ctx.polygon();
        let family_area = family.area();
        let z = ctx.layer.z - ctx.layer.thickness / 2.0;
        let mut bbox = family.bbox();
        let margin = bbox.diagonal().max(1.0);
        bbox.include(lamina_api::Point2::new(bbox.min.x - margin, bbox.min.y - margin));
        bbox.include(lamina_api::Point2::new(bbox.max.x + margin, bbox.max.y + margin));
        let sources = self.resolved_sources(ctx)?;
        // Patches of the overlay: a piece of the family, the step of each source and
        // whether it is in that source's effective grading region.
        let family_shapes = clean(&vec![shape_of(family)]);
        let mut patches = vec![Patch {
            shapes: family_shapes.clone(),
            steps: Vec::new(),
            effective: Vec::new(),
        }];
        let fields = self.surface_fields(ctx, &sources, family, z)?;
        let closer = |i: usize, d: f64| match &fields[i] {
            Some(field) => field.closer_than(d, &family_shapes),
            None => closer_than(&sources[i].datum, d, z, &bbox, self.tolerance, &family_shapes),
        };
        for (i, s) in sources.iter().enumerate() {
            let sets: Vec<_> = s.thresholds().iter().map(|&d| closer(i, d)).collect();
            // The effective region 0 <= f <= 1: within the grading width, and in front
            // of a plane.
            let (within, behind) = match self.combine {
                Combine::Everywhere => (Set::Whole, Set::Empty),
                Combine::Intersection => (
                    closer(i, s.d_at(1.0)),
                    match s.datum {
                        Datum::Plane { .. } => closer(i, 0.0),
                        _ => Set::Empty,
                    },
                ),
            };
            patches = cut_patches(patches, &sets, &within, &behind);
        }
        let pieces = homogeneous_pieces(&sources, patches);
        sub_regions(pieces, family_area, ctx.family)
    }

    fn grades(&self) -> bool {
        true
    }
}

impl Sources {
    /// The sources with their compositions resolved over the part's materials.
    fn resolved_sources(&self, ctx: &FamilyContext<'_>) -> Result<Vec<Source>> {
        let mut sources = Vec::with_capacity(self.sources.len());
        for (i, p) in self.sources.iter().enumerate() {
            let mut s = p.source.clone();
            s.start = self.resolve(ctx, &p.start, i)?;
            s.end = self.resolve(ctx, &p.end, i)?;
            sources.push(s);
        }
        Ok(sources)
    }

    /// Per source, the distance in space to its outer surface, sampled once over the
    /// family at height `z`; `None` for a source measured otherwise.
    fn surface_fields(
        &self,
        ctx: &FamilyContext<'_>,
        sources: &[Source],
        family: &Polygon,
        z: f64,
    ) -> Result<Vec<Option<SurfaceField>>> {
        let mut fields = Vec::with_capacity(sources.len());
        for (i, s) in sources.iter().enumerate() {
            fields.push(match &self.faces[i] {
                Some((faces, surfaces)) => {
                    let mesh = ctx.mesh.ok_or_else(|| {
                        Error::stage(
                            STAGE,
                            format!("source {i}: a `surface` source needs the part's mesh"),
                        )
                    })?;
                    let surface = surfaces
                        .of(mesh, faces)
                        .map_err(|e| Error::stage(STAGE, format!("source {i}: {e}")))?
                        .ok_or_else(|| {
                            Error::stage(
                                STAGE,
                                format!("source {i}: `faces` selects no face of the part's mesh"),
                            )
                        })?;
                    // Every distance the source's sets are cut at: its steps and the
                    // end of its effective region.
                    let mut levels = s.thresholds();
                    levels.push(s.d_at(1.0));
                    Some(SurfaceField::new(
                        &surface,
                        &family.bbox(),
                        z,
                        self.surface_samples,
                        &levels,
                    ))
                }
                None => None,
            });
        }
        Ok(fields)
    }
}

/// `patches` cut by one more source: by the sets closer than each of its step
/// thresholds (nearest first), then by its effective region, `within` it and not
/// `behind` its plane. Each piece keeps its patch's steps and flags, with this source's
/// appended.
fn cut_patches(patches: Vec<Patch>, sets: &[Set], within: &Set, behind: &Set) -> Vec<Patch> {
    let mut next = Vec::new();
    for patch in patches {
        let mut stepped = Vec::new();
        let mut rest = patch.shapes;
        for (u, set) in sets.iter().enumerate() {
            let inside = set.intersect(&rest);
            if !inside.is_empty() {
                stepped.push((inside, u));
            }
            rest = set.subtract_from(&rest);
            if rest.is_empty() {
                break;
            }
        }
        if !rest.is_empty() {
            stepped.push((rest, sets.len()));
        }
        for (shapes, u) in stepped {
            for (shapes, w) in split(shapes, within) {
                for (shapes, b) in split(shapes, behind) {
                    next.push(Patch {
                        shapes,
                        steps: [patch.steps.as_slice(), &[u]].concat(),
                        effective: [patch.effective.as_slice(), &[w && !b]].concat(),
                    });
                }
            }
        }
    }
    next
}

/// A homogeneous region in the making: its shapes, the step of each source, its
/// composition's fractions and its level.
type Piece = (Shapes, Vec<usize>, Vec<f64>, f64);

/// Each patch's composition (Eq. 2 per source, Eq. 8 over the sources that grade it);
/// patches of equal steps and composition are one homogeneous region.
fn homogeneous_pieces(sources: &[Source], patches: Vec<Patch>) -> Vec<Piece> {
    let mut pieces: Vec<Piece> = Vec::new();
    for patch in patches {
        let levels: Vec<f64> = sources
            .iter()
            .zip(&patch.steps)
            .map(|(s, &u)| s.steps.level(u))
            .collect();
        let any = patch.effective.iter().any(|&e| e);
        let counted: Vec<usize> = (0..sources.len())
            .filter(|&i| !any || patch.effective[i])
            .collect();
        let parts: Vec<(f64, Vec<f64>)> = counted
            .iter()
            .map(|&i| (sources[i].weight, sources[i].composition(levels[i])))
            .collect();
        let mut fractions = combine(&parts);
        // Clear the rounding of the blend so the sum check sees exactly 1.
        for f in &mut fractions {
            *f = f.clamp(0.0, 1.0);
        }
        let sum: f64 = fractions.iter().sum();
        fractions.iter_mut().for_each(|f| *f /= sum);
        let weight: f64 = counted.iter().map(|&i| sources[i].weight).sum();
        let level = counted
            .iter()
            .map(|&i| sources[i].weight * levels[i])
            .sum::<f64>()
            / weight;
        match pieces.iter_mut().find(|p| p.1 == patch.steps && p.2 == fractions) {
            Some(p) => p.0 = union(&p.0, &patch.shapes),
            None => pieces.push((patch.shapes, patch.steps, fractions, level)),
        }
    }
    pieces
}

/// The sub-regions of family `family` (of area `family_area`), one index per piece;
/// slivers a rounding of the family's area are dropped.
fn sub_regions(pieces: Vec<Piece>, family_area: f64, family: usize) -> Result<Vec<SubRegion>> {
    let sliver = family_area.abs() * 1e-12;
    let pieces: Vec<_> = pieces
        .into_iter()
        .filter_map(|(shapes, _, fractions, level)| {
            let polygons: Vec<_> = polygons_of(&shapes)
                .into_iter()
                .filter(|p| p.area() > sliver)
                .collect();
            (!polygons.is_empty()).then_some((polygons, fractions, level))
        })
        .collect();
    let count = pieces.len();
    let mut regions = Vec::new();
    for (index, (polygons, fractions, level)) in pieces.into_iter().enumerate() {
        let composition = Composition::new(fractions)?;
        for polygon in polygons {
            regions.push(SubRegion {
                composition: Some(composition.clone()),
                ..SubRegion::new(family, index, count, level, polygon)
            });
        }
    }
    Ok(regions)
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
    if !(8..=4096).contains(&o.surface_samples) {
        return Err(config.error("surface_samples", "must be between 8 and 4096"));
    }
    let mut sources = Vec::new();
    let mut faces = Vec::new();
    for (i, s) in o.sources.into_iter().enumerate() {
        let bad = |m: &str| config.error("sources", format!("source {i}: {m}"));
        if !s.at.iter().all(|&v| lamina_api::limits::is_coordinate(v)) {
            return Err(bad(&format!(
                "`at` must be three numbers within ±{} mm",
                lamina_api::limits::MAX_COORDINATE
            )));
        }
        let datum = match s.kind {
            Kind::Point => Datum::Point(s.at),
            Kind::Axis => Datum::Axis {
                at: s.at,
                direction: unit(s.direction.unwrap_or([0.0, 0.0, 1.0]))
                    .ok_or_else(|| bad("`direction` must be a non-zero vector"))?,
            },
            Kind::Surface if s.measure == Measure::Layer => {
                if s.faces.is_some() {
                    return Err(bad(
                        "`faces` are chosen on the mesh; `measure = \"layer\"` measures to the layer's boundary",
                    ));
                }
                Datum::LayerBoundary
            }
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
        if !(alpha.is_finite() && alpha >= 1.0 / lamina_api::limits::MAX_COORDINATE) {
            return Err(bad(&format!(
                "`alpha` must be at least 1e-6 per mm (a `width` of at most {} mm)",
                lamina_api::limits::MAX_COORDINATE
            )));
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
        if s.kind != Kind::Surface && (s.faces.is_some() || s.measure != Measure::Space) {
            return Err(bad("`faces` and `measure` belong to `kind = \"surface\"`"));
        }
        faces.push(match datum {
            Datum::Surface => {
                let f = s.faces.clone().unwrap_or_default();
                f.check().map_err(|e| bad(&format!("`faces`: {e}")))?;
                Some((f, Surfaces::default()))
            }
            _ => None,
        });
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
        combine: o.combine,
        faces,
        surface_samples: o.surface_samples,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "sources",
        doc: "Grading sources (point, axis, plane, outer surface in space): f(d) = (alpha d)^k truncated in steps of t_g, regions cut along the steps and overlaid, compositions by Eq. 2 and 8.",
        options: Options::SPECS,
        example: "use = \"sources\"\nsources = [{ kind = \"axis\", at = [0.0, 0.0, 0.0], width = 10.0, start = \"red\", end = \"green\" }]",
    },
    build,
});
