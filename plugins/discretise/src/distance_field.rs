//! `distance-field` (distance-field paper): per family, a distance field on a grid to a
//! chosen material feature (all boundaries, the outer contour, the holes, the centre or
//! a point), normalised to [0, 1]; the iso-contours at the chosen levels, clipped to the
//! family, bound the sub-regions. With `step`, the levels follow the grading step-width
//! truncation instead of equal parts.

use lamina_api::mesh::Point3;
use lamina_api::stage::{AnyStage, Discretiser, FamilyContext, StageConfig, StageInfo, StageKind};
use lamina_api::{Contour, Error, Point2, Polygon, Result, StageFactory, SubRegion};
use lamina_fgm::steps::Truncation;
use lamina_fgm::surface::{FaceSelection, Surface, Surfaces};
use serde::Deserialize;

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::ShapeType;

use crate::bands::{clean, nested_bands};
use crate::cells::Cells;
use crate::grid::Grid;
use crate::measure::pole;
use crate::regions::{from_bands, whole};
use lamina_geom::field::Field;
use lamina_geom::iso::iso_levels;
use lamina_geom::simplify::simplify_into;

const STAGE: &str = "discretise:distance-field";

/// Iso-loops are simplified within this share of a cell before the band booleans: the
/// field itself is exact only within a cell of the boundary and within half a cell
/// beyond, so a tenth of a cell moves no loop by more than its own uncertainty, and
/// the booleans, regions and files carry several times fewer vertices.
const SIMPLIFY: f64 = 0.1;

/// Below every level: keeps iso-loops closed at the grid's border.
const FLOOR: f64 = -1e300;

lamina_api::option_type!(Feature = "string");

/// The material feature distances are measured from (r = 0 there).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Feature {
    /// Every contour of the family: the signed distance to the boundary.
    Boundary,
    Outer,
    Holes,
    /// The pole of inaccessibility (the most inland point).
    Centre,
    /// The point `point = [x, y]`.
    Point,
    /// The straight line through the two `points` (extended across the family).
    Line,
    /// The open polyline through `points` (a curve given by its points).
    Polyline,
    /// Chosen faces of the part's mesh (`faces`): the distance in space from the
    /// layer's mid-plane to them.
    Surface,
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// where r = 0: `boundary` (signed), `outer`, `holes`, `centre`, `point`, `line`, `polyline` or `surface` (chosen faces of the part's mesh, measured in space)
        feature: Feature = r#""boundary""#,
        /// [x, y] (mm) of the feature `point`
        #[range(-1e6, 1e6)]
        point: Option<[f64; 2]>,
        /// [[x, y], ...] (mm): two points of the feature `line`, or the points of the `polyline`
        #[range(-1e6, 1e6)]
        points: Option<Vec<[f64; 2]>>,
        /// the faces of the feature `surface`: `{ normal = [x, y, z], within = 30.0 }` (outward normal within that many degrees) and/or `{ groups = ["name"] }` (named face groups of a 3MF)
        faces: Option<FaceSelection>,
        /// number of equal parts of r; each part's level is Eq. 2's d / max(d) where it starts: k / count
        #[range(1, 1e6)]
        count: usize = "10",
        /// grading step-width t_g: levels 0, t_g, ..., 1 at half steps
        #[range(0.001, 1.0)]
        step: Option<f64>,
        /// iso-contours every `spacing` mm of distance (Fig. 7) instead of `count` parts of r; levels d / max(d) (Eq. 2)
        #[range(0.001, 1e6)]
        spacing: Option<f64>,
        /// distance (mm) that r = 1 stands for (farther is r = 1); default each family's largest distance (Eq. 2's max(d_ij))
        #[range(0.001, 1e6)]
        width: Option<f64>,
        /// samples of the distance along the family's longer side (formerly `cells`)
        #[range(8, 65536)]
        #[formerly("cells")]
        samples: usize = "256",
        /// spacing of the samples (mm) instead of `samples` (formerly `cell_size`)
        #[range(0.0001, 1e6)]
        #[formerly("cell_size")]
        sample_spacing: Option<f64>,
        cells_around: Option<usize> = use crate::cells::AROUND_OPTION,
        cell_length: Option<f64> = use crate::cells::LENGTH_OPTION,
        cell_cuts: Option<crate::cells::Cuts> = use crate::cells::CUTS_OPTION,
    }
}

/// How the normalised distance is cut into levels.
#[derive(Debug, Clone)]
pub enum Levels {
    /// `n` equal parts of r; the part [k/n, (k+1)/n) has Eq. 2's f = d / max(d) at its
    /// start, k / n, as the regions between Fig. 7's iso-contours do (the same reading
    /// as [`Levels::Spacing`]): the innermost part stops short of 1.
    Equal(usize),
    Steps(Truncation),
    /// Iso-contours every `s` mm of distance from the feature (Fig. 7: 0, 1.5, ...,
    /// 10.5 over a maximum of 11.76); the region from the contour at d = j s on has the
    /// level j s / max(d) of Eq. 2, and the last one runs to the maximum.
    Spacing(f64),
}

/// The cut of one family's field: where each band starts (values of r) and each
/// band's level.
#[derive(Debug, Clone, PartialEq)]
pub struct Cut {
    /// Values of r where band k starts, k in 1..count.
    pub thresholds: Vec<f64>,
    /// The level of every band, outermost first.
    pub levels: Vec<f64>,
}

impl Levels {
    /// The cut for a field whose largest distance inside the family is `max` mm, with at
    /// most `most` levels.
    pub fn cut(&self, max: f64, most: usize) -> Cut {
        match self {
            Levels::Equal(n) => Cut {
                thresholds: (1..*n).map(|k| k as f64 / *n as f64).collect(),
                levels: (0..*n).map(|k| k as f64 / *n as f64).collect(),
            },
            Levels::Steps(t) => Cut {
                thresholds: t.thresholds(),
                levels: t.levels(),
            },
            Levels::Spacing(s) => {
                // Contours strictly below the maximum: one at the maximum itself would
                // bound nothing.
                let n = ((max / s).ceil() as usize).clamp(1, most.max(1));
                let levels: Vec<f64> = (0..n).map(|k| (k as f64 * s / max).min(1.0)).collect();
                Cut {
                    thresholds: levels[1..].to_vec(),
                    levels,
                }
            }
        }
    }
}

/// One family's field and its iso-loops.
#[derive(Debug, Clone)]
pub struct IsoSets {
    /// Normalised distances r.
    pub field: Field,
    /// max(d_ij) (mm).
    pub max: f64,
    pub cut: Cut,
    /// The loops of every threshold of `cut`.
    pub sets: Vec<Vec<Contour>>,
}

/// The distance-field discretiser.
#[derive(Debug, Clone)]
pub struct DistanceField {
    pub feature: Feature,
    pub point: Option<Point2>,
    /// The points of a `line` (two) or a `polyline`.
    pub points: Vec<Point2>,
    /// The faces of a `surface` feature.
    pub faces: FaceSelection,
    /// The chosen faces of each mesh met so far (by address), built once per run.
    pub surfaces: Surfaces,
    pub levels: Levels,
    /// Samples along the longer side of a family's box, or their spacing (mm).
    pub samples: usize,
    pub sample_spacing: Option<f64>,
    /// Circumferential cells of every sub-region.
    pub around: Cells,
    /// The distance (mm) that r = 1 stands for, instead of each family's largest
    /// distance: one scale for every layer (a surface feature's distance varies along
    /// Z, not only in the layer).
    pub width: Option<f64>,
    /// The run's limits: a grid that `sample_spacing` makes too fine is refused.
    pub limits: lamina_api::Limits,
}

impl DistanceField {
    /// Samples along the longer side of the family's box: `samples`, or what
    /// `sample_spacing` gives.
    fn resolution(&self, bbox: &lamina_api::BBox2) -> usize {
        match self.sample_spacing {
            Some(s) => ((bbox.width().max(bbox.height()) / s).ceil() as usize + 3).clamp(4, 1 << 15),
            None => self.samples,
        }
    }

    /// The line or polyline as a closed contour that runs there and back, so that its
    /// edges are the path's segments (a line extended across the family).
    fn path(&self, polygon: &Polygon) -> Contour {
        let mut pts = self.points.clone();
        if self.feature == Feature::Line && pts.len() == 2 {
            let (a, b) = (pts[0], pts[1]);
            let u = (b - a).normalize();
            let bbox = polygon.bbox();
            let reach = (bbox.center() - a).norm() + bbox.diagonal();
            pts = vec![a - u * reach, b + u * reach];
        }
        let back: Vec<Point2> = pts
            .iter()
            .rev()
            .skip(1)
            .take(pts.len().saturating_sub(2))
            .copied()
            .collect();
        pts.extend(back);
        Contour::new(pts)
    }

    /// The field of normalised distances r (border samples at `FLOOR`), the largest
    /// distance inside the family (mm, Eq. 2's max(d_ij)), the cut into levels and the
    /// iso-loops of every threshold, without clipping. `None` when the family has no
    /// inside at the grid's resolution.
    pub fn iso_sets(&self, polygon: &Polygon, space: Option<(&Surface, f64)>) -> Option<IsoSets> {
        let bbox = polygon.bbox();
        let mut field = Field::over(&bbox, self.resolution(&bbox));
        let all: Vec<&Contour> = polygon.contours().collect();
        let inside = field.inside(&all);
        match self.feature {
            // Outside the family only the first cell is read (negated).
            Feature::Boundary => field.distance_within(&all, &inside),
            Feature::Outer => field.distance_to(&[&polygon.outer]),
            Feature::Holes => {
                if polygon.holes.is_empty() {
                    return None;
                }
                let holes: Vec<&Contour> = polygon.holes.iter().collect();
                field.distance_to(&holes);
            }
            Feature::Line | Feature::Polyline => {
                let path = self.path(polygon);
                field.distance_to(&[&path]);
            }
            Feature::Surface => {
                let (surface, z) = space?;
                for j in 0..field.ny {
                    for i in 0..field.nx {
                        let p = field.point(i, j);
                        field.values[j * field.nx + i] = surface.distance(Point3::new(p.x, p.y, z));
                    }
                }
            }
            Feature::Centre | Feature::Point => {
                let c = match (self.feature, self.point) {
                    (Feature::Point, Some(p)) => p,
                    _ => pole(polygon, field.h * 0.5)?.0,
                };
                for j in 0..field.ny {
                    for i in 0..field.nx {
                        field.values[j * field.nx + i] = (field.point(i, j) - c).norm();
                    }
                }
            }
        }
        // Eight running maxima, so that no comparison waits for the one before (the
        // largest of them is the same whatever the grouping).
        let mut maxima = [0.0f64; 8];
        for (values, inside) in field.values.chunks(8).zip(inside.chunks(8)) {
            for ((m, &v), &inside) in maxima.iter_mut().zip(values).zip(inside) {
                if inside {
                    *m = m.max(v);
                }
            }
        }
        let max = maxima.into_iter().fold(0.0f64, f64::max);
        let max = self.width.unwrap_or(max);
        if max.is_nan() || max <= 0.0 || max.is_infinite() {
            return None;
        }
        let (nx, ny) = (field.nx, field.ny);
        let signed = self.feature == Feature::Boundary;
        for (j, (row, inside)) in field
            .values
            .chunks_exact_mut(nx)
            .zip(inside.chunks_exact(nx))
            .enumerate()
        {
            if j == 0 || j == ny - 1 {
                row.fill(FLOOR);
                continue;
            }
            // Negating after dividing is exact: one division for every sample.
            for (v, &inside) in row.iter_mut().zip(inside) {
                let r = *v / max;
                *v = if signed && !inside { -r } else { r };
            }
            row[0] = FLOOR;
            row[nx - 1] = FLOOR;
        }
        // Never more iso-levels than the limit allows (the discretiser refuses the
        // family when a spacing asks for more): the iso-lines cost per level.
        let cut = self
            .levels
            .cut(max, self.limits.regions.saturating_add(1) as usize);
        let sets = iso_levels(&field, &field.values, &cut.thresholds);
        Some(IsoSets {
            field,
            max,
            cut,
            sets,
        })
    }
}

impl Discretiser for DistanceField {
    /// A `surface` feature measures in space, from faces of the part's mesh.
    fn reads_mesh(&self) -> bool {
        self.feature == Feature::Surface
    }

    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<SubRegion>> {
        let polygon = ctx.polygon();
        if self.sample_spacing.is_some() {
            let bbox = polygon.bbox();
            let n = self.resolution(&bbox) as f64;
            let (w, h) = (bbox.width(), bbox.height());
            self.limits.check(
                lamina_api::Limit::GridSamples,
                n * n * w.min(h) / w.max(h).max(f64::MIN_POSITIVE),
                &format!(
                    "a distance field of {w:.1} x {h:.1} mm sampled every {} mm",
                    self.sample_spacing.unwrap_or(0.0)
                ),
            )?;
        }
        let Ok(grid) = Grid::for_polygon(polygon, STAGE) else {
            return Ok(whole(ctx));
        };
        let base = clean(&vec![grid.shape(polygon)]);
        let surface = match (self.feature, ctx.mesh) {
            (Feature::Surface, Some(mesh)) => self
                .surfaces
                .of(mesh, &self.faces)
                .map_err(|e| Error::stage(STAGE, e))?,
            (Feature::Surface, None) => {
                return Err(Error::stage(
                    STAGE,
                    "`feature = \"surface\"` needs the part's mesh",
                ));
            }
            _ => None,
        };
        if self.feature == Feature::Surface && surface.is_none() {
            return Err(Error::stage(STAGE, "`faces` selects no face of the part's mesh"));
        }
        let z = ctx.layer.z - ctx.layer.thickness / 2.0;
        let space = surface.as_deref().map(|s| (s, z));
        let Some(IsoSets {
            cut,
            sets,
            max,
            field,
            ..
        }) = self.iso_sets(polygon, space).filter(|_| !base.is_empty())
        else {
            return Ok(whole(ctx));
        };
        if let Levels::Spacing(s) = self.levels {
            self.limits.check(
                lamina_api::Limit::Regions,
                (max / s).ceil(),
                &format!("iso-contours every {s} mm over a largest distance of {max:.3} mm"),
            )?;
        }
        let count = cut.levels.len();
        // Loops keep the set on their left: the non-zero rule in the band overlay reads
        // them as outers and holes.
        let eps = SIMPLIFY * field.h;
        let mut ring = Vec::new();
        let bands = nested_bands(&base, count, FillRule::NonZero, |k, _, overlay| {
            let mut any = false;
            for c in &sets[k - 1] {
                simplify_into(c.len(), |i| [c.points[i].x, c.points[i].y], eps, &mut ring);
                let c = grid.ring(&ring);
                if c.len() >= 3 {
                    overlay.add_contour(&c, ShapeType::Clip);
                    any = true;
                }
            }
            Ok(any)
        })?;
        let mut regions = from_bands(ctx, &grid, &bands, count, |k| cut.levels[k]);
        self.around.split(&grid, polygon, &mut regions, &self.limits)?;
        Ok(regions)
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let levels = match (o.step, o.spacing) {
        (Some(_), Some(_)) => return Err(config.error("spacing", "give `step` or `spacing`, not both")),
        (Some(step), None) => Levels::Steps(Truncation::new(step).map_err(|e| config.error("step", e))?),
        (None, Some(s)) => Levels::Spacing(s),
        (None, None) => {
            crate::options::count(config, Some(o.count))?;
            Levels::Equal(o.count)
        }
    };
    if let Levels::Steps(t) = &levels {
        crate::options::regions(config, "step", t.count as f64)?;
    }
    // A `sample_spacing` grid is counted family by family, as it is made; `samples`
    // is then unused and not counted.
    if o.sample_spacing.is_none() {
        config
            .limits
            .check(
                lamina_api::Limit::GridSamples,
                (o.samples as f64).powi(2),
                "`samples` squared",
            )
            .map_err(|e| config.error("samples", e.to_string()))?;
    }
    let point = match (o.feature, o.point) {
        (Feature::Point, None) => {
            return Err(config.error("point", "`feature = \"point\"` needs `point = [x, y]`"));
        }
        (_, p) => p.map(|[x, y]| Point2::new(x, y)),
    };
    let points: Vec<Point2> = o
        .points
        .unwrap_or_default()
        .into_iter()
        .map(|[x, y]| Point2::new(x, y))
        .collect();
    match o.feature {
        Feature::Line if points.len() != 2 || (points[1] - points[0]).norm() == 0.0 => {
            return Err(config.error(
                "points",
                "`feature = \"line\"` needs two distinct `points = [[x, y], [x, y]]`",
            ));
        }
        Feature::Polyline if points.len() < 2 => {
            return Err(config.error("points", "`feature = \"polyline\"` needs at least two `points`"));
        }
        _ => {}
    }
    let faces = o.faces.unwrap_or_default();
    faces.check().map_err(|e| config.error("faces", e))?;
    Ok(AnyStage::Discretise(Box::new(DistanceField {
        feature: o.feature,
        point,
        points,
        faces,
        surfaces: Surfaces::default(),
        width: o.width,
        levels,
        samples: o.samples,
        sample_spacing: o.sample_spacing,
        around: Cells::checked(o.cells_around, o.cell_length, o.cell_cuts, config)?,
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Discretise,
        name: "distance-field",
        doc: "Iso-contours of a normalised distance field to a material feature bound the sub-regions, clipped to the family.",
        options: Options::SPECS,
        example: "use = \"distance-field\"\nfeature = \"outer\"\ncount = 4",
    },
    build,
});
