//! Properties that must hold for every input, not only for the examples the other
//! suites pick, checked on random inputs with `proptest`:
//!
//! - every discretiser, with random options, divides a random family (a star-shaped
//!   outer contour with star-shaped or convex holes) into valid sub-regions that tile
//!   it: the same area, no overlap, nothing outside;
//! - random closed solids (boxes, tubes, gears) at random places and turns, overlapping
//!   or not, slice at random layer heights into closed simple contours that the sort
//!   stage nests consistently;
//! - for random layer thicknesses a work cycle is exactly their least common multiple,
//!   every region fills it, and a block repeats it.
//!
//! Geometry is judged by the `geo` crate and the expected nesting and cycles are
//! recomputed here, so that a property does not rest on the code it checks. Each
//! property runs a few hundred cases, a few seconds in all in a debug build;
//! PROPTEST_CASES sets another number for every property.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::f64::consts::TAU;
use std::path::Path;
use std::sync::{Arc, OnceLock};

use geo::orient::Direction;
use geo::{Area, InteriorPoint, Intersects, Orient, Validation};
use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::float::overlay::FloatOverlay;
use lamina_core::pipeline::TableRef;
use lamina_core::stage::{Discretiser, FamilyContext};
use lamina_core::{
    AnyStage, Contour, ContourTree, Family, Layer, LayerSlot, Material, Mesh, PartInfo, Point2, Polygon,
    Registry, RunInfo, StageKind, SubRegion,
};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

// ------------------------------------------------------------------ shared helpers

fn registry() -> &'static Registry {
    use lamina_discretise as _;
    use lamina_model as _;
    use lamina_sequence as _;
    use lamina_slice as _;
    use lamina_sort as _;
    use lamina_sources as _;
    static REGISTRY: OnceLock<Registry> = OnceLock::new();
    REGISTRY.get_or_init(|| Registry::linked().expect("registry"))
}

/// A stage built from a TOML table, as a pipeline file would give it.
fn stage(kind: StageKind, text: &str) -> lamina_core::Result<AnyStage> {
    let table = TableRef::parse_snippet(kind.name(), text)?;
    let scripts = lamina_core::script::local(".", Default::default());
    registry().build_any(kind, &table, &scripts, Path::new("."))
}

/// The default number of cases, or PROPTEST_CASES when it is set.
fn config(cases: u32) -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(cases);
    ProptestConfig {
        cases,
        // A failing case is kept as a named regression test, not as a seed file.
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn ring(c: &Contour) -> geo::LineString<f64> {
    geo::LineString::from(c.points.iter().map(|q| (q.x, q.y)).collect::<Vec<_>>())
}

fn geo_polygon(p: &Polygon) -> geo::Polygon<f64> {
    geo::Polygon::new(ring(&p.outer), p.holes.iter().map(ring).collect())
}

/// OGC validity by `geo`: simple rings, holes inside the outer, touching it or each
/// other at most at points.
fn ogc_errors(p: &geo::Polygon<f64>) -> Vec<String> {
    p.validation_errors().iter().map(|e| e.to_string()).collect()
}

/// A polygon set as i_overlay reads it: shapes of rings (outer first), each ring open.
type Shapes = Vec<Vec<Vec<[f64; 2]>>>;

/// Polygons as i_overlay shapes, each oriented first (outer counter-clockwise, holes
/// clockwise): the non-zero rule reads the winding.
fn shapes_of<'a>(polygons: impl IntoIterator<Item = &'a geo::Polygon<f64>>) -> Shapes {
    let open = |l: &geo::LineString<f64>| {
        let mut r: Vec<[f64; 2]> = l.0.iter().map(|c| [c.x, c.y]).collect();
        r.pop();
        r
    };
    polygons
        .into_iter()
        .map(|p| {
            let p = p.orient(Direction::Default);
            std::iter::once(p.exterior())
                .chain(p.interiors())
                .map(open)
                .collect()
        })
        .collect()
}

/// The area a shape set covers: each outer less its holes.
fn net_area(shapes: &Shapes) -> f64 {
    let ring = |r: &Vec<[f64; 2]>| {
        let n = r.len();
        (0..n)
            .map(|i| r[i][0] * r[(i + 1) % n][1] - r[(i + 1) % n][0] * r[i][1])
            .sum::<f64>()
            .abs()
            / 2.0
    };
    shapes
        .iter()
        .map(|s| {
            s.split_first()
                .map_or(0.0, |(o, holes)| ring(o) - holes.iter().map(ring).sum::<f64>())
        })
        .sum()
}

/// The tiling checks' booleans, by i_overlay in its plain mode rather than by `geo`.
/// Sub-regions made by separate booleans meet along shared edges to within rounding, and
/// `geo` 0.33's OGC extraction (i_overlay 4.5) turns such a union into thousands of
/// hairline slivers and then trips its own assertion (iOverlay issue 78). Only areas are
/// read here, which the plain mode gives without the OGC ring rules.
fn overlay(subject: &Shapes, clip: &Shapes, rule: OverlayRule) -> Shapes {
    FloatOverlay::with_subj_and_clip(subject, clip).overlay(rule, FillRule::NonZero)
}

/// The union of polygons.
fn union_of<'a>(polygons: impl IntoIterator<Item = &'a geo::Polygon<f64>>) -> Shapes {
    overlay(&shapes_of(polygons), &Vec::new(), OverlayRule::Subject)
}

fn pt(x: f64, y: f64) -> Point2 {
    Point2::new(x, y)
}

// ------------------------------------------------------------ random families

/// A star-shaped ring about a centre: each entry is (angular gap weight, radius as a
/// share of the ring's size). Gap weights in [1, 1.9) keep every gap under half a
/// turn, so the vertices in angular order make a simple ring around the centre.
type Star = Vec<(f64, f64)>;

fn star(vertices: std::ops::Range<usize>, smallest: f64) -> impl Strategy<Value = Star> {
    prop::collection::vec((1.0f64..1.9, smallest..1.0), vertices)
}

/// The star's vertices, counter-clockwise; `round` puts them all on one circle, which
/// makes the ring convex.
fn star_points(shape: &Star, centre: Point2, radius: f64, turn: f64, round: bool) -> Vec<Point2> {
    let total: f64 = shape.iter().map(|s| s.0).sum();
    let mut angle = turn;
    let mut out = Vec::with_capacity(shape.len());
    for &(gap, r) in shape {
        let r = if round { radius } else { radius * r };
        out.push(pt(centre.x + r * angle.cos(), centre.y + r * angle.sin()));
        angle += TAU * gap / total;
    }
    out
}

fn segment_distance(p: Point2, a: Point2, b: Point2) -> f64 {
    let d = b - a;
    let t = ((p - a).dot(&d) / d.norm_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
    (p - (a + d * t)).norm()
}

/// Even-odd point in ring, written here so the generator does not lean on Lamina.
fn inside(points: &[Point2], p: Point2) -> bool {
    let mut odd = false;
    for i in 0..points.len() {
        let (a, b) = (points[i], points[(i + 1) % points.len()]);
        if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) {
            odd = !odd;
        }
    }
    odd
}

/// A hole candidate: where in the outer's box (shares of its width and height), its
/// size (share of the outer's size), its shape and turn, and whether it is convex.
type HoleSpec = (f64, f64, f64, Star, f64, bool);

/// One family: its outer contour (counter-clockwise) and holes (clockwise), and the
/// outer's size (mm), which scales the discretisers' options.
#[derive(Debug, Clone)]
struct RandomFamily {
    outer: Vec<Point2>,
    holes: Vec<Vec<Point2>>,
    size: f64,
    centre: Point2,
}

impl RandomFamily {
    fn layer(&self) -> Layer {
        let mut contours = vec![Contour::new(self.outer.clone())];
        contours.extend(self.holes.iter().map(|h| {
            let mut h = h.clone();
            h.reverse();
            Contour::new(h)
        }));
        Layer {
            index: 0,
            z: 1.0,
            thickness: 0.2,
            contours,
            warnings: Vec::new(),
            section_area: None,
        }
    }
}

/// Holes are kept only where a disc around them stays `gap * size` away from the outer
/// contour and from every hole kept before, so no two contours touch.
fn place_family(
    outer: &Star,
    size: f64,
    gap: f64,
    centre: Point2,
    turn: f64,
    candidates: &[HoleSpec],
) -> RandomFamily {
    let outer = star_points(outer, centre, size, turn, false);
    let (mut lo, mut hi) = (outer[0], outer[0]);
    for p in &outer {
        lo = pt(lo.x.min(p.x), lo.y.min(p.y));
        hi = pt(hi.x.max(p.x), hi.y.max(p.y));
    }
    let margin = gap * size;
    let mut discs: Vec<(Point2, f64)> = Vec::new();
    let mut holes = Vec::new();
    for (u, v, share, shape, turn, round) in candidates {
        let c = pt(lo.x + u * (hi.x - lo.x), lo.y + v * (hi.y - lo.y));
        let r = share * size;
        let to_outer = (0..outer.len())
            .map(|i| segment_distance(c, outer[i], outer[(i + 1) % outer.len()]))
            .fold(f64::INFINITY, f64::min);
        let clear = inside(&outer, c)
            && to_outer > r + margin
            && discs.iter().all(|&(q, rq)| (c - q).norm() > r + rq + margin);
        if clear {
            discs.push((c, r));
            holes.push(star_points(shape, c, r, *turn, *round));
        }
    }
    RandomFamily {
        outer,
        holes,
        size,
        centre,
    }
}

fn family() -> impl Strategy<Value = RandomFamily> {
    let hole = (
        0.0f64..1.0,
        0.0f64..1.0,
        0.03f64..0.25,
        star(3..10, 0.4),
        0.0f64..TAU,
        any::<bool>(),
    );
    // The narrowest gap between contours, as a share of the size: wide, or down to a
    // few micrometres.
    let gap = prop_oneof![0.02f64..0.1, 0.001f64..0.02];
    (
        star(3..24, 0.3),
        (2.0f64..40.0, gap),
        (-200.0f64..200.0, -200.0f64..200.0),
        0.0f64..TAU,
        prop::collection::vec(hole, 0..10),
    )
        .prop_map(|(outer, (size, gap), (x, y), turn, holes)| {
            place_family(&outer, size, gap, pt(x, y), turn, &holes)
        })
}

// ------------------------------------------------------- random discretisers

/// Circumferential cells: none, a number around, or a length (share of the size).
#[derive(Debug, Clone)]
enum CellSpec {
    None,
    Around(usize, Option<&'static str>),
    Length(f64, Option<&'static str>),
}

fn cells() -> impl Strategy<Value = CellSpec> {
    let cuts = prop::option::of(prop::sample::select(vec!["sectors", "arc"]));
    prop_oneof![
        2 => Just(CellSpec::None),
        1 => (1usize..8, cuts.clone()).prop_map(|(n, c)| CellSpec::Around(n, c)),
        1 => (0.3f64..2.0, cuts).prop_map(|(l, c)| CellSpec::Length(l, c)),
    ]
}

fn cells_text(c: &CellSpec, size: f64) -> String {
    let cuts = |c: &Option<&str>| c.map(|c| format!("cell_cuts = \"{c}\"\n")).unwrap_or_default();
    match c {
        CellSpec::None => String::new(),
        CellSpec::Around(n, c) => format!("cells_around = {n}\n{}", cuts(c)),
        CellSpec::Length(l, c) => format!("cell_length = {:?}\n{}", l * size, cuts(c)),
    }
}

/// A grading source of the `sources` stage; lengths are shares of the family's size.
#[derive(Debug, Clone)]
struct SourceSpec {
    kind: &'static str,
    at: (f64, f64, f64),
    direction: (f64, f64, f64),
    width: f64,
    k: f64,
    step: f64,
    weight: f64,
    reversed: bool,
}

fn source() -> impl Strategy<Value = SourceSpec> {
    (
        prop::sample::select(vec!["point", "axis", "plane", "surface"]),
        (-1.5f64..1.5, -1.5f64..1.5, -1.0f64..1.0),
        (-1.0f64..1.0, -1.0f64..1.0, tilt()),
        0.1f64..2.0,
        0.5f64..2.0,
        0.2f64..=1.0,
        0.5f64..2.0,
        any::<bool>(),
    )
        .prop_map(
            |(kind, at, direction, width, k, step, weight, reversed)| SourceSpec {
                kind,
                at,
                direction,
                width,
                k,
                step,
                weight,
                reversed,
            },
        )
}

/// The z part of a source's direction: any, or none or almost none, where an axis or a
/// plane lies in or nearly in the layer.
fn tilt() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => -1.0f64..1.0,
        1 => Just(0.0),
        1 => (-9.0f64..-3.0, any::<bool>()).prop_map(|(e, up)| if up { 10f64.powf(e) } else { -10f64.powf(e) }),
    ]
}

/// A discretiser with random options, as a `[discretise]` table for a given family.
#[derive(Debug, Clone)]
enum Spec {
    Offset(OffsetSpec),
    Radial {
        nozzle: f64,
        count: Option<usize>,
        cells: CellSpec,
    },
    StepWidth(StepWidthSpec),
    DistanceField(DistanceFieldSpec),
    Sources {
        sources: Vec<SourceSpec>,
        combine: &'static str,
    },
}

/// `offset`'s options (lengths in units of the family's size).
#[derive(Debug, Clone)]
struct OffsetSpec {
    nozzle: f64,
    count: Option<usize>,
    spacing: Option<f64>,
    from: &'static str,
    join: &'static str,
    cells: CellSpec,
}

/// `step-width`'s options.
#[derive(Debug, Clone)]
struct StepWidthSpec {
    step: f64,
    power: f64,
    width: Option<f64>,
    from: &'static str,
    join: &'static str,
    cells: CellSpec,
}

/// `distance-field`'s options; `points` about the family's centre, in its size.
#[derive(Debug, Clone)]
struct DistanceFieldSpec {
    feature: &'static str,
    points: Vec<(f64, f64)>,
    levels: Levels,
    samples: usize,
    width: Option<f64>,
    cells: CellSpec,
}

#[derive(Debug, Clone)]
enum Levels {
    Count(usize),
    Step(f64),
    Spacing(f64),
}

fn from() -> impl Strategy<Value = &'static str> {
    prop::sample::select(vec!["outer", "all"])
}

fn join() -> impl Strategy<Value = &'static str> {
    prop::sample::select(vec!["round", "miter", "bevel"])
}

fn offset_spec() -> impl Strategy<Value = Spec> {
    (
        0.01f64..0.2,
        prop::option::of(1usize..12),
        prop::option::of(0.01f64..0.2),
        from(),
        join(),
        cells(),
    )
        .prop_map(|(nozzle, count, spacing, from, join, cells)| {
            Spec::Offset(OffsetSpec {
                nozzle,
                count,
                spacing,
                from,
                join,
                cells,
            })
        })
}

fn radial_spec() -> impl Strategy<Value = Spec> {
    (0.01f64..0.2, prop::option::of(1usize..10), cells()).prop_map(|(nozzle, count, cells)| Spec::Radial {
        nozzle,
        count,
        cells,
    })
}

fn step_width_spec() -> impl Strategy<Value = Spec> {
    (
        0.1f64..=1.0,
        0.5f64..3.0,
        prop::option::of(0.1f64..1.5),
        from(),
        join(),
        cells(),
    )
        .prop_map(|(step, power, width, from, join, cells)| {
            Spec::StepWidth(StepWidthSpec {
                step,
                power,
                width,
                from,
                join,
                cells,
            })
        })
}

fn distance_field_spec() -> impl Strategy<Value = Spec> {
    let levels = prop_oneof![
        (1usize..10).prop_map(Levels::Count),
        (0.1f64..=1.0).prop_map(Levels::Step),
        (0.05f64..0.5).prop_map(Levels::Spacing),
    ];
    (
        prop::sample::select(vec![
            "boundary", "outer", "holes", "centre", "point", "line", "polyline",
        ]),
        prop::collection::vec((-1.5f64..1.5, -1.5f64..1.5), 2..5),
        levels,
        16usize..96,
        prop::option::of(0.1f64..1.5),
        cells(),
    )
        .prop_map(|(feature, points, levels, samples, width, cells)| {
            Spec::DistanceField(DistanceFieldSpec {
                feature,
                points,
                levels,
                samples,
                width,
                cells,
            })
        })
}

fn sources_spec() -> impl Strategy<Value = Spec> {
    (
        prop::collection::vec(source(), 1..4),
        prop::sample::select(vec!["intersection", "everywhere"]),
    )
        .prop_map(|(sources, combine)| Spec::Sources { sources, combine })
}

impl Spec {
    /// The table for `f`: lengths scaled by its size, points about its centre.
    fn text(&self, f: &RandomFamily) -> String {
        let s = f.size;
        let at = |(u, v): (f64, f64)| format!("[{:?}, {:?}]", f.centre.x + u * s, f.centre.y + v * s);
        match self {
            Spec::Offset(o) => {
                let mut t = format!(
                    "use = \"offset\"\nnozzle = {:?}\nfrom = \"{}\"\njoin = \"{}\"\n",
                    o.nozzle * s,
                    o.from,
                    o.join
                );
                if let Some(n) = o.count {
                    t += &format!("count = {n}\n");
                }
                if let Some(d) = o.spacing {
                    t += &format!("spacing = {:?}\n", d * s);
                }
                t + cells_text(&o.cells, s).as_str()
            }
            Spec::Radial { nozzle, count, cells } => {
                let mut t = format!("use = \"radial\"\nnozzle = {:?}\n", nozzle * s);
                if let Some(n) = count {
                    t += &format!("count = {n}\n");
                }
                t + cells_text(cells, s).as_str()
            }
            Spec::StepWidth(w) => {
                let mut t = format!(
                    "use = \"step-width\"\nstep = {:?}\npower = {:?}\nfrom = \"{}\"\njoin = \"{}\"\n",
                    w.step, w.power, w.from, w.join
                );
                if let Some(w) = w.width {
                    t += &format!("width = {:?}\n", w * s);
                }
                t + cells_text(&w.cells, s).as_str()
            }
            Spec::DistanceField(d) => {
                let (feature, points, levels, width, cells) =
                    (d.feature, &d.points, &d.levels, d.width, &d.cells);
                let mut t = format!(
                    "use = \"distance-field\"\nfeature = \"{feature}\"\ncells = {}\n",
                    d.samples
                );
                match feature {
                    "point" => t += &format!("point = {}\n", at(points[0])),
                    "line" => t += &format!("points = [{}, {}]\n", at(points[0]), at(points[1])),
                    "polyline" => {
                        let all: Vec<String> = points.iter().map(|&p| at(p)).collect();
                        t += &format!("points = [{}]\n", all.join(", "));
                    }
                    _ => {}
                }
                match levels {
                    Levels::Count(n) => t += &format!("count = {n}\n"),
                    Levels::Step(g) => t += &format!("step = {g:?}\n"),
                    Levels::Spacing(d) => t += &format!("spacing = {:?}\n", d * s),
                }
                if let Some(w) = width {
                    t += &format!("width = {:?}\n", w * s);
                }
                t + cells_text(cells, s).as_str()
            }
            Spec::Sources { sources, combine } => {
                let items: Vec<String> = sources
                    .iter()
                    .map(|q| {
                        let (x, y, z) = q.at;
                        let (dx, dy, dz) = q.direction;
                        let direction = if (dx * dx + dy * dy + dz * dz).sqrt() > 1e-3 {
                            format!("direction = [{dx:?}, {dy:?}, {dz:?}], ")
                        } else {
                            String::new()
                        };
                        let (start, end) = if q.reversed { ("b", "a") } else { ("a", "b") };
                        format!(
                            "{{ kind = \"{}\", at = [{:?}, {:?}, {:?}], {direction}width = {:?}, k = {:?}, \
                             step = {:?}, weight = {:?}, start = \"{start}\", end = \"{end}\" }}",
                            q.kind,
                            f.centre.x + x * s,
                            f.centre.y + y * s,
                            1.0 + z * s,
                            q.width * s,
                            q.k,
                            q.step,
                            q.weight,
                        )
                    })
                    .collect();
                format!(
                    "use = \"sources\"\ncombine = \"{combine}\"\nsources = [{}]\n",
                    items.join(", ")
                )
            }
        }
    }
}

/// A run of one part in two materials, for the stages that grade.
fn run_info() -> RunInfo {
    let material = |name: &str| Material {
        name: name.into(),
        colour: [0, 0, 0],
        layer_thickness: None,
    };
    RunInfo {
        base_dir: ".".into(),
        materials: vec![material("a"), material("b")],
        parts: vec![PartInfo {
            name: "part".into(),
            materials: vec![0, 1],
            mesh: 0,
            z_min: 0.0,
            z_max: 2.0,
            z_gradient: None,
        }],
        z_min: 0.0,
        z_max: 2.0,
        xy_bounds: lamina_core::BBox2::EMPTY,
        machine: None,
        model_frame: None,
    }
}

/// Largest relative error of areas (and share of overlap) a tiling may have.
const TILING: f64 = 1e-6;

/// The sort stage's answer for the layer of a generated family: one family, the outer
/// contour with every hole.
fn sorted(layer: &Layer) -> Result<ContourTree, TestCaseError> {
    let AnyStage::Sort(sorter) = stage(StageKind::Sort, "use = \"hierarchy\"").expect("sorter") else {
        panic!("not a sorter")
    };
    let tree = sorter.sort(layer).expect("sorts");
    let holes: Vec<usize> = (1..layer.contours.len()).collect();
    prop_assert_eq!(&tree.families, &vec![Family { outer: 0, holes }]);
    Ok(tree)
}

/// Runs the discretiser of `text` on the family and checks that its regions tile it.
fn discretise_and_check(f: &RandomFamily, text: &str) -> Result<(), TestCaseError> {
    let layer = f.layer();
    let tree = sorted(&layer)?;
    let family = tree.family_polygon(&layer.contours, 0);
    let invalid = ogc_errors(&geo_polygon(&family));
    prop_assert!(invalid.is_empty(), "the generated family is invalid: {invalid:?}");
    let AnyStage::Discretise(stage) =
        stage(StageKind::Discretise, text).unwrap_or_else(|e| panic!("{text}: {e}"))
    else {
        panic!("not a discretiser")
    };
    let info = run_info();
    // The family extruded into a prism about the layer, reaching past its top less far
    // than past its bottom, for the stages that measure in space from the mesh.
    let mid = layer.z - layer.thickness / 2.0;
    let prism = lamina_model::extrude("prism", &family, mid - 2.0 * f.size, mid + 0.5 * f.size).ok();
    let polygons = tree.family_polygons(&layer.contours);
    let ctx = FamilyContext {
        info: &info,
        layer: &layer,
        tree: &tree,
        polygons: &polygons,
        mesh: prism.as_ref(),
        part: 0,
        family: 0,
    };
    let regions = match stage.discretise(&ctx) {
        Ok(regions) => regions,
        // Options that ask for more sub-regions than the run's limits allow (a fine
        // nozzle times many cells) are refused by name: the answer the limits promise.
        Err(lamina_core::Error::Limit { key: "regions", .. }) => return Ok(()),
        Err(e) => return Err(TestCaseError::fail(format!("{text}: {e}"))),
    };
    check_tiling(&family, &regions, stage.as_ref())
}

/// The regions tile the family: each a valid polygon with its reference point in it,
/// their areas adding up to the family's, no overlap and nothing outside or missed,
/// by Lamina's `Tiling` check and again by `geo`.
fn check_tiling(
    family: &Polygon,
    regions: &[SubRegion],
    stage: &dyn Discretiser,
) -> Result<(), TestCaseError> {
    prop_assert!(!regions.is_empty(), "no regions");
    let area = family.area();
    let mut polygons = Vec::with_capacity(regions.len());
    let mut sum = 0.0;
    for (k, r) in regions.iter().enumerate() {
        prop_assert_eq!(r.family, 0);
        prop_assert!(r.index < r.count, "region {k}: index {} of {}", r.index, r.count);
        prop_assert!((0.0..=1.0).contains(&r.level), "region {k}: level {}", r.level);
        prop_assert_eq!(
            r.composition.is_some(),
            stage.grades(),
            "region {}: a grading stage gives compositions, others leave them",
            k
        );
        let p = geo_polygon(&r.polygon);
        let invalid = ogc_errors(&p);
        prop_assert!(
            invalid.is_empty(),
            "region {k} is not a valid polygon: {invalid:?}"
        );
        let a = p.unsigned_area();
        prop_assert!(a > 0.0, "region {k} has no area");
        prop_assert!(
            p.intersects(&geo::Point::new(r.reference.x, r.reference.y)),
            "region {k}: reference {:?} outside it",
            r.reference
        );
        sum += a;
        polygons.push(p);
    }
    let t = lamina_discretise::check::tiling(family, regions);
    prop_assert!(t.is_ok(TILING), "{t:?}");
    prop_assert!(
        (sum - area).abs() <= TILING * area,
        "regions cover {sum} of {area} mm²"
    );
    let union = union_of(&polygons);
    let overlap = sum - net_area(&union);
    prop_assert!(
        overlap <= TILING * area,
        "regions overlap by {overlap} mm² of {area}"
    );
    let whole = shapes_of([&geo_polygon(family)]);
    let outside = net_area(&overlay(&union, &whole, OverlayRule::Difference));
    let missed = net_area(&overlay(&whole, &union, OverlayRule::Difference));
    prop_assert!(
        outside <= TILING * area && missed <= TILING * area,
        "regions lie {outside} mm² outside the family and miss {missed} mm² of it"
    );
    Ok(())
}

/// Runs the discretiser `spec` describes on `f` and checks its tiling, naming the
/// stage's table in a failure.
fn tiles(f: &RandomFamily, spec: &Spec) -> Result<(), TestCaseError> {
    let text = spec.text(f);
    discretise_and_check(f, &text).map_err(|e| TestCaseError::fail(format!("{text}\n{e}")))
}

/// One property per discretiser, so that a failure in one does not hide the others:
/// each named test runs [`tiles`] on random families and its strategy's specs.
macro_rules! tiling_properties {
    ($($(#[$doc:meta])* $name:ident: $spec:ident;)*) => {
        proptest! {
            #![proptest_config(config(256))]
            $(
                $(#[$doc])*
                #[test]
                fn $name(f in family(), spec in $spec()) {
                    tiles(&f, &spec)?;
                }
            )*
        }
    };
}

tiling_properties! {
    /// `offset`, from the outer contour or from all, by nozzle, count or spacing, with
    /// any join and cells.
    offset_tiles_random_families: offset_spec;
    radial_tiles_random_families: radial_spec;
    step_width_tiles_random_families: step_width_spec;
    /// `distance-field` to every planar feature, by count, step or spacing.
    distance_field_tiles_random_families: distance_field_spec;
    /// `sources` of every kind, one to three of them, combined either way.
    sources_tile_random_families: sources_spec;
}

// ---------------------------------------------------------- random solids

#[derive(Debug, Clone)]
enum Solid {
    Box([f64; 3]),
    Tube {
        outer: f64,
        inner: f64,
        height: f64,
        segments: usize,
    },
    Gear {
        teeth: usize,
        tip: f64,
        root: f64,
        bore: f64,
        height: f64,
        arc: usize,
    },
}

impl Solid {
    fn text(&self) -> String {
        match self {
            Solid::Box([x, y, z]) => format!("use = \"box\"\nsize = [{x:?}, {y:?}, {z:?}]"),
            Solid::Tube {
                outer,
                inner,
                height,
                segments,
            } => format!(
                "use = \"tube\"\nouter_radius = {outer:?}\ninner_radius = {inner:?}\nheight = {height:?}\nsegments = {segments}"
            ),
            Solid::Gear {
                teeth,
                tip,
                root,
                bore,
                height,
                arc,
            } => format!(
                "use = \"gear\"\nteeth = {teeth}\ntip_radius = {tip:?}\nroot_radius = {root:?}\nbore = {bore:?}\nheight = {height:?}\narc_segments = {arc}"
            ),
        }
    }

    fn mesh(&self) -> Mesh {
        let text = self.text();
        let AnyStage::Model(source) =
            stage(StageKind::Model, &text).unwrap_or_else(|e| panic!("{text}: {e}"))
        else {
            panic!("not a model")
        };
        let mut meshes = source.load(Path::new(".")).expect("generates");
        assert_eq!(meshes.len(), 1);
        meshes.remove(0)
    }
}

/// Whole millimetres when `snap`, so that faces of different solids can coincide.
fn length(lo: f64, hi: f64, snap: bool) -> impl Strategy<Value = f64> {
    (lo..hi).prop_map(move |v| if snap { v.round().max(1.0) } else { v })
}

fn solid(snap: bool) -> impl Strategy<Value = Solid> {
    prop_oneof![
        [
            length(1.0, 20.0, snap),
            length(1.0, 20.0, snap),
            length(1.0, 12.0, snap)
        ]
        .prop_map(Solid::Box),
        (
            length(2.0, 12.0, snap),
            0.0f64..0.9,
            length(1.0, 12.0, snap),
            3usize..40
        )
            .prop_map(|(outer, share, height, segments)| Solid::Tube {
                outer,
                inner: outer * share,
                height,
                segments,
            }),
        (
            3usize..24,
            length(4.0, 14.0, snap),
            0.6f64..0.95,
            0.0f64..0.9,
            length(1.0, 10.0, snap),
            1usize..4
        )
            .prop_map(|(teeth, tip, share, bore, height, arc)| Solid::Gear {
                teeth,
                tip,
                root: tip * share,
                bore: tip * share * bore * 0.94,
                height,
                arc,
            }),
    ]
}

/// A solid and where it goes: its turn as a quaternion (none, about z, or any), and
/// its offset.
#[derive(Debug, Clone)]
struct Placed {
    solid: Solid,
    turn: [f64; 4],
    offset: [f64; 3],
}

fn placed(snap: bool) -> impl Strategy<Value = Placed> {
    let turn = if snap {
        // Quarter turns about z keep whole-millimetre faces on the grid.
        (0u8..4)
            .prop_map(|q| {
                let a = f64::from(q) * TAU / 8.0;
                [a.cos(), 0.0, 0.0, a.sin()]
            })
            .boxed()
    } else {
        prop_oneof![
            Just([1.0, 0.0, 0.0, 0.0]),
            (0.0f64..TAU).prop_map(|a| [(a / 2.0).cos(), 0.0, 0.0, (a / 2.0).sin()]),
            [-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0],
        ]
        .boxed()
    };
    // A third of the solids stand on the origin's vertical, where a rod in a tube's bore
    // makes an island in a hole.
    let offset = prop_oneof![
        1 => length(-4.0, 4.0, snap).prop_map(|z| [0.0, 0.0, z]),
        2 => [length(-12.0, 12.0, snap), length(-12.0, 12.0, snap), length(-4.0, 4.0, snap)],
    ];
    (solid(snap), turn, offset).prop_map(|(solid, turn, offset)| Placed { solid, turn, offset })
}

fn rotation([w, x, y, z]: [f64; 4]) -> [[f64; 3]; 3] {
    let n = (w * w + x * x + y * y + z * z).sqrt();
    let (w, x, y, z) = if n < 0.1 {
        (1.0, 0.0, 0.0, 0.0)
    } else {
        (w / n, x / n, y / n, z / n)
    };
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

impl Placed {
    /// The solid's mesh turned about its own middle (about its corner when snapped to
    /// the grid, so that faces stay on whole millimetres) and moved.
    fn mesh(&self, snap: bool) -> Mesh {
        let mut m = self.solid.mesh();
        if !snap {
            let b = m.bbox();
            m.transform(1.0, -(b.min.coords + b.max.coords) * 0.5);
        }
        m.rotate(&rotation(self.turn));
        m.transform(1.0, self.offset.into());
        m
    }
}

/// All meshes as one: overlapping shells are the slicer's to merge.
fn merge(meshes: &[Mesh]) -> Mesh {
    let mut out = Mesh::new("solids", Vec::new(), Vec::new());
    for m in meshes {
        let base = u32::try_from(out.vertices.len()).expect("small meshes");
        out.vertices.extend(&m.vertices);
        out.triangles
            .extend(m.triangles.iter().map(|t| t.map(|i| i + base)));
    }
    out
}

#[derive(Debug, Clone)]
struct Scene {
    snap: bool,
    solids: Vec<Placed>,
    thickness: f64,
    first: Option<f64>,
    cut: f64,
    /// Which layers to check, as shares of the layer count.
    picks: Vec<f64>,
}

fn scene() -> impl Strategy<Value = Scene> {
    any::<bool>().prop_flat_map(|snap| {
        // On the grid, layers of round thickness cut at their bottom, middle or top meet
        // the solids' flat tops and bottoms exactly.
        let (thickness, first, cut) = if snap {
            (
                prop::sample::select(vec![0.25, 0.5, 1.0]).boxed(),
                Just(None).boxed(),
                prop::sample::select(vec![0.0, 0.5, 1.0]).boxed(),
            )
        } else {
            (
                (0.05f64..3.0).boxed(),
                prop::option::of(0.05f64..3.0).boxed(),
                (0.0f64..=1.0).boxed(),
            )
        };
        (
            prop::collection::vec(placed(snap), 1..5),
            thickness,
            first,
            cut,
            prop::collection::vec(0.0f64..1.0, 1..8),
        )
            .prop_map(move |(solids, thickness, first, cut, picks)| Scene {
                snap,
                solids,
                thickness,
                first,
                cut,
                picks,
            })
    })
}

fn slicer(s: &Scene) -> Box<dyn lamina_core::stage::Slicer> {
    let mut text = format!(
        "use = \"uniform\"\nthickness = {:?}\ncut = {:?}\n",
        s.thickness, s.cut
    );
    if let Some(f) = s.first {
        text += &format!("first_layer = {f:?}\n");
    }
    match stage(StageKind::Slice, &text).unwrap_or_else(|e| panic!("{text}: {e}")) {
        AnyStage::Slice(s) => s,
        _ => panic!("not a slicer"),
    }
}

fn info_for(mesh: &Mesh) -> RunInfo {
    let b = mesh.bbox();
    RunInfo {
        base_dir: ".".into(),
        materials: Vec::new(),
        parts: Vec::new(),
        z_min: b.min.z,
        z_max: b.max.z,
        xy_bounds: lamina_core::BBox2::EMPTY,
        machine: None,
        model_frame: None,
    }
}

/// The layers stack without gaps from the bottom of the model to at least its top, each
/// cut within its own thickness.
fn check_slots(slots: &[LayerSlot], info: &RunInfo) -> Result<(), TestCaseError> {
    prop_assert!(!slots.is_empty());
    let eps = 1e-9 * (1.0 + info.z_max.abs());
    let mut bottom = info.z_min;
    for (i, s) in slots.iter().enumerate() {
        prop_assert_eq!(s.index, i);
        prop_assert!(s.thickness > 0.0);
        prop_assert!(
            (s.z - s.thickness - bottom).abs() <= eps,
            "layer {i} starts at {} after {bottom}",
            s.z - s.thickness
        );
        prop_assert!(
            s.cut_z >= s.z - s.thickness - eps && s.cut_z <= s.z + eps,
            "layer {i} cut at {} outside {}..{}",
            s.cut_z,
            s.z - s.thickness,
            s.z
        );
        bottom = s.z;
    }
    prop_assert!(
        bottom >= info.z_max - eps,
        "layers end at {bottom} below {}",
        info.z_max
    );
    prop_assert!(
        slots.len() == 1 || slots[slots.len() - 2].z < info.z_max,
        "a layer wholly above the model"
    );
    Ok(())
}

/// Checks one layer's contours and the sort stage's tree of them: closed simple rings
/// wound as their depth says, families that are valid polygons and do not overlap,
/// and each contour's parent the smallest contour around it, found here with `geo`.
fn check_layer(layer: &Layer, tree: &ContourTree) -> Result<Vec<geo::Polygon<f64>>, TestCaseError> {
    let n = layer.contours.len();
    prop_assert_eq!(tree.nodes.len(), n);
    let rings: Vec<geo::Polygon<f64>> = layer
        .contours
        .iter()
        .map(|c| geo::Polygon::new(ring(c), Vec::new()))
        .collect();
    let mut areas = Vec::with_capacity(n);
    for (i, (c, p)) in layer.contours.iter().zip(&rings).enumerate() {
        prop_assert!(c.len() >= 3, "contour {i} has {} points", c.len());
        prop_assert!(
            c.points.iter().all(|q| q.x.is_finite() && q.y.is_finite()),
            "contour {i} is not finite"
        );
        let invalid = ogc_errors(p);
        prop_assert!(
            invalid.is_empty(),
            "contour {i} is not a simple ring: {invalid:?}"
        );
        let a = p.unsigned_area();
        prop_assert!(a > 0.0, "contour {i} encloses nothing");
        areas.push(a);
    }
    // Depth and parent of each contour from the contours that hold a point inside it.
    for i in 0..n {
        let Some(probe) = rings[i].interior_point() else {
            return Err(TestCaseError::fail(format!("contour {i} has no interior point")));
        };
        let around: Vec<usize> = (0..n)
            .filter(|&j| j != i && areas[j] > areas[i] && rings[j].intersects(&probe))
            .collect();
        let parent = around
            .iter()
            .copied()
            .min_by(|&a, &b| areas[a].total_cmp(&areas[b]));
        let node = &tree.nodes[i];
        prop_assert_eq!(node.contour, i);
        prop_assert_eq!(node.level, around.len(), "depth of contour {}", i);
        prop_assert_eq!(node.parent, parent, "parent of contour {}", i);
        if let Some(p) = parent {
            prop_assert!(tree.nodes[p].children.contains(&i));
        }
        prop_assert_eq!(
            layer.contours[i].is_ccw(),
            node.level.is_multiple_of(2),
            "contour {} at depth {} is wound the wrong way",
            i,
            node.level
        );
    }
    // Families: each contour at an even depth with its direct children as holes.
    let mut expected: Vec<Family> = (0..n)
        .filter(|&i| tree.nodes[i].level.is_multiple_of(2))
        .map(|i| {
            let mut holes: Vec<usize> = (0..n).filter(|&j| tree.nodes[j].parent == Some(i)).collect();
            holes.sort_unstable();
            Family { outer: i, holes }
        })
        .collect();
    let mut got: Vec<Family> = tree
        .families
        .iter()
        .map(|f| {
            let mut f = f.clone();
            f.holes.sort_unstable();
            f
        })
        .collect();
    expected.sort_by_key(|f| f.outer);
    got.sort_by_key(|f| f.outer);
    prop_assert_eq!(&got, &expected);
    // Each family is a valid polygon with its holes inside its outer contour, and
    // families meet at most at points.
    let families: Vec<geo::Polygon<f64>> = (0..tree.families.len())
        .map(|f| geo_polygon(&tree.family_polygon(&layer.contours, f)))
        .collect();
    for (f, p) in families.iter().enumerate() {
        let invalid = ogc_errors(p);
        prop_assert!(
            invalid.is_empty(),
            "family {f} is not a valid polygon: {invalid:?}"
        );
    }
    let all = geo::MultiPolygon::new(families.clone());
    let invalid: Vec<String> = all.validation_errors().iter().map(|e| e.to_string()).collect();
    prop_assert!(invalid.is_empty(), "families overlap: {invalid:?}");
    Ok(families)
}

fn sorter() -> Box<dyn lamina_core::stage::Sorter> {
    match stage(StageKind::Sort, "use = \"hierarchy\"").expect("sorter") {
        AnyStage::Sort(s) => s,
        _ => panic!("not a sorter"),
    }
}

fn check_scene(s: &Scene) -> Result<(), TestCaseError> {
    let meshes: Vec<Mesh> = s.solids.iter().map(|p| p.mesh(s.snap)).collect();
    let mesh = Arc::new(merge(&meshes));
    let info = info_for(&mesh);
    let slicer = slicer(s);
    let slots = slicer
        .layers(std::slice::from_ref(&mesh), &info, None)
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    check_slots(&slots, &info)?;
    let whole = slicer.prepare(mesh.clone()).expect("prepares");
    let parts: Vec<_> = meshes
        .iter()
        .map(|m| slicer.prepare(Arc::new(m.clone())).expect("prepares"))
        .collect();
    let sorter = sorter();
    let mut picked: Vec<usize> = s
        .picks
        .iter()
        .map(|f| ((f * slots.len() as f64) as usize).min(slots.len() - 1))
        .collect();
    picked.sort_unstable();
    picked.dedup();
    for &k in &picked {
        let slot = &slots[k];
        let layer = whole.slice(slot).expect("slices");
        let tree = sorter.sort(&layer).expect("sorts");
        let families = check_layer(&layer, &tree)
            .map_err(|e| TestCaseError::fail(format!("layer {k} cut at z = {}: {e}", slot.cut_z)))?;
        // The solids' own cuts, united here, cover what the merged cut covers; skipped
        // where the plane passes within a micrometre of a vertex, where either cut may
        // take a face lying in it as above or below.
        let near = mesh.vertices.iter().any(|v| (v.z - slot.cut_z).abs() < 1e-3);
        if near {
            continue;
        }
        let mut pieces = Vec::new();
        for part in &parts {
            let l = part.slice(slot).expect("slices");
            let t = sorter.sort(&l).expect("sorts");
            pieces.extend((0..t.families.len()).map(|f| geo_polygon(&t.family_polygon(&l.contours, f))));
        }
        let expected = net_area(&union_of(&pieces));
        let got: f64 = families.iter().map(|p| p.unsigned_area()).sum();
        prop_assert!(
            (got - expected).abs() <= 1e-6 * expected.max(1.0),
            "layer {k} cut at z = {}: {got} mm² where the solids' union has {expected}",
            slot.cut_z
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(256))]

    /// Random closed solids, overlapping or not, slice into closed simple contours that
    /// the sort stage nests as `geo` does.
    #[test]
    fn random_solids_slice_into_consistently_nested_contours(s in scene()) {
        check_scene(&s)?;
    }
}

// ---------------------------------------------------------- work cycles

fn gcd(mut a: u128, mut b: u128) -> u128 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

fn lcm(values: impl IntoIterator<Item = u64>) -> u128 {
    values
        .into_iter()
        .fold(1u128, |acc, v| acc / gcd(acc, u128::from(v)) * u128::from(v))
}

/// Where a part's layer thickness comes from: the stage's `thickness` table, its
/// materials' preferred thicknesses (the thinnest wins), or `default_thickness`.
#[derive(Debug, Clone)]
enum ThicknessFrom {
    Table(u64),
    Materials(Vec<u64>),
    Default,
}

#[derive(Debug, Clone)]
struct CyclePart {
    from: ThicknessFrom,
    /// Height range in micrometres.
    z: (u64, u64),
}

#[derive(Debug, Clone)]
struct CycleCase {
    parts: Vec<CyclePart>,
    default: u64,
}

/// Thicknesses in micrometres: mostly multiples of a round step, whose common multiples
/// stay short, sometimes any whole number, whose common multiples often exceed the
/// stage's limit.
fn micrometres() -> impl Strategy<Value = u64> {
    prop_oneof![
        3 => (1u64..=20, prop::sample::select(vec![10u64, 20, 25, 50, 100])).prop_map(|(k, b)| k * b),
        1 => 1u64..=3000,
    ]
}

fn cycle_case() -> impl Strategy<Value = CycleCase> {
    let from = prop_oneof![
        2 => micrometres().prop_map(ThicknessFrom::Table),
        1 => prop::collection::vec(micrometres(), 1..3).prop_map(ThicknessFrom::Materials),
        1 => Just(ThicknessFrom::Default),
    ];
    let part = (from, 0u64..20_000, 1u64..20_000).prop_map(|(from, lo, len)| CyclePart {
        from,
        z: (lo, lo + len),
    });
    (prop::collection::vec(part, 1..6), micrometres())
        .prop_map(|(parts, default)| CycleCase { parts, default })
        .prop_filter("a cycle of over a million layers", |c| {
            c.layers_per_cycle() <= MAX_LAYERS
        })
}

/// The most layers the cases' work cycles may hold, refused ones included: the bound
/// keeps each case's time and memory small whatever a stage does with it.
const MAX_LAYERS: u128 = 1_000_000;

fn mm(um: u64) -> f64 {
    um as f64 / 1000.0
}

impl CycleCase {
    fn thickness(&self, p: usize) -> u64 {
        match &self.parts[p].from {
            ThicknessFrom::Table(t) => *t,
            ThicknessFrom::Materials(ts) => ts.iter().copied().min().unwrap_or(self.default),
            ThicknessFrom::Default => self.default,
        }
    }

    fn stage_text(&self) -> String {
        let mut t = format!(
            "use = \"work-cycles\"\ndefault_thickness = {:?}\n[thickness]\n",
            mm(self.default)
        );
        for (i, p) in self.parts.iter().enumerate() {
            if let ThicknessFrom::Table(um) = p.from {
                t += &format!("p{i} = {:?}\n", mm(um));
            }
        }
        t
    }

    fn info(&self) -> RunInfo {
        let mut materials = Vec::new();
        let mut parts = Vec::new();
        for (i, p) in self.parts.iter().enumerate() {
            let mut own = Vec::new();
            if let ThicknessFrom::Materials(ts) = &p.from {
                for &t in ts {
                    own.push(materials.len());
                    materials.push(Material {
                        name: format!("m{}", materials.len()),
                        colour: [0, 0, 0],
                        layer_thickness: Some(mm(t)),
                    });
                }
            }
            parts.push(PartInfo {
                name: format!("p{i}"),
                materials: own,
                mesh: 0,
                z_min: mm(p.z.0),
                z_max: mm(p.z.1),
                z_gradient: None,
            });
        }
        RunInfo {
            base_dir: ".".into(),
            materials,
            parts,
            z_min: 0.0,
            z_max: 40.0,
            xy_bounds: lamina_core::BBox2::EMPTY,
            machine: None,
            model_frame: None,
        }
    }

    /// The layers of the longest work cycle, summed over its regions.
    fn layers_per_cycle(&self) -> u128 {
        self.blocks()
            .iter()
            .map(|(_, _, present)| {
                let c = lcm(present.iter().map(|&r| self.thickness(r)));
                present
                    .iter()
                    .map(|&r| c / u128::from(self.thickness(r)))
                    .sum::<u128>()
            })
            .max()
            .unwrap_or(0)
    }

    /// The blocks as the work-cycle model has them: cut at every part's bottom and
    /// top, each holding the parts that span it (none: no block).
    fn blocks(&self) -> Vec<(u64, u64, Vec<usize>)> {
        let mut planes: Vec<u64> = self.parts.iter().flat_map(|p| [p.z.0, p.z.1]).collect();
        planes.sort_unstable();
        planes.dedup();
        planes
            .windows(2)
            .filter_map(|w| {
                let present: Vec<usize> = (0..self.parts.len())
                    .filter(|&i| self.parts[i].z.0 <= w[0] && self.parts[i].z.1 >= w[1])
                    .collect();
                (!present.is_empty()).then_some((w[0], w[1], present))
            })
            .collect()
    }
}

/// Most bytes the stage may allocate to refuse a sequence: its messages and its
/// regions, nothing in proportion to the cycle it refuses.
const REFUSAL_BYTES: u64 = 1 << 20;

/// Counts the bytes each thread allocates, so that a property can bound what a stage
/// allocates for its answer.
struct Counting;

thread_local! {
    static ALLOCATED: Cell<u64> = const { Cell::new(0) };
}

fn count(bytes: usize) {
    // The counter needs no allocation and has no destructor, so the allocator may use
    // it; after the thread's end `try_with` just skips.
    let _ = ALLOCATED.try_with(|a| a.set(a.get().saturating_add(bytes as u64)));
}

// SAFETY: every call is passed to the system allocator unchanged.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        // SAFETY: the caller keeps `alloc`'s contract, which `System` shares.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System` through this allocator.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count(new_size.saturating_sub(layout.size()));
        // SAFETY: as for `dealloc`, with the caller's valid `new_size`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// What `f` returns and the bytes it allocated on this thread.
fn allocated_by<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let before = ALLOCATED.with(Cell::get);
    let out = f();
    (out, ALLOCATED.with(Cell::get) - before)
}

/// Longest work cycle the stage accepts (µm).
const MAX_CYCLE_UM: u128 = 1_000_000;

fn um(mm: f64) -> u64 {
    (mm * 1000.0).round() as u64
}

/// The thicknesses (µm) of region `r`'s layers among `steps`, in order.
fn region_layers(steps: &[lamina_core::model::CycleStep], r: usize) -> Vec<u64> {
    steps
        .iter()
        .flat_map(|s| &s.deposits)
        .filter(|d| d.region == r)
        .map(|d| d.thickness_um)
        .collect()
}

fn check_cycles(case: &CycleCase) -> Result<(), TestCaseError> {
    let text = case.stage_text();
    let AnyStage::Sequence(stage) =
        stage(StageKind::Sequence, &text).unwrap_or_else(|e| panic!("{text}: {e}"))
    else {
        panic!("not a sequencer")
    };
    let info = case.info();
    let blocks = case.blocks();
    let thickness: Vec<u64> = (0..case.parts.len()).map(|p| case.thickness(p)).collect();
    let cycles: Vec<u128> = blocks
        .iter()
        .map(|(_, _, present)| lcm(present.iter().map(|&r| thickness[r])))
        .collect();
    let (result, bytes) = allocated_by(|| stage.sequence(&info));
    if cycles.iter().any(|&c| c > MAX_CYCLE_UM) {
        let Err(e) = result else {
            return Err(TestCaseError::fail(format!(
                "a cycle of {} µm is over the limit, yet the stage accepted it",
                cycles.iter().max().copied().unwrap_or(0)
            )));
        };
        prop_assert!(e.to_string().contains("longer than"), "{e}");
        // Refusing must not cost what the cycle would: thicknesses of 0.997, 0.998,
        // 0.999 and 1.001 mm have a cycle of about 1e12 µm, whose steps no memory holds.
        prop_assert!(
            bytes <= REFUSAL_BYTES,
            "refusing a cycle of {} µm allocated {bytes} bytes",
            cycles.iter().max().copied().unwrap_or(0)
        );
        return Ok(());
    }
    let seq = result.map_err(|e| TestCaseError::fail(e.to_string()))?;
    prop_assert_eq!(seq.regions.len(), case.parts.len());
    for (r, region) in seq.regions.iter().enumerate() {
        prop_assert_eq!(&region.parts, &vec![r]);
        prop_assert_eq!(region.thickness_um, thickness[r], "thickness of region {}", r);
    }
    prop_assert_eq!(seq.blocks.len(), blocks.len());
    let mut deposits = 0;
    for (b, (block, (lo, hi, present))) in seq.blocks.iter().zip(&blocks).enumerate() {
        prop_assert_eq!((um(block.z_start), um(block.z_end)), (*lo, *hi), "block {}", b);
        prop_assert_eq!(&block.regions, present, "regions of block {}", b);
        let cycle = &block.cycle;
        prop_assert_eq!(
            u128::from(cycle.height_um),
            cycles[b],
            "cycle height of block {}",
            b
        );
        let c = cycle.height_um;
        // The cycle: a step wherever some thickness divides the height, in which
        // exactly the regions whose thickness divides it deposit one whole layer, in
        // region order; every region stacks up to exactly the cycle height.
        prop_assert!(cycle.steps.windows(2).all(|w| w[0].height_um < w[1].height_um));
        prop_assert_eq!(cycle.steps.last().map(|s| s.height_um), Some(c));
        for step in &cycle.steps {
            let due: Vec<usize> = present
                .iter()
                .copied()
                .filter(|&r| step.height_um % thickness[r] == 0)
                .collect();
            let got: Vec<usize> = step.deposits.iter().map(|d| d.region).collect();
            prop_assert_eq!(&got, &due, "deposits at {} µm of block {}", step.height_um, b);
            for d in &step.deposits {
                prop_assert_eq!(d.thickness_um, thickness[d.region]);
            }
        }
        for &r in present {
            let layers = region_layers(&cycle.steps, r);
            prop_assert_eq!(layers.len() as u64, c / thickness[r]);
            prop_assert_eq!(
                layers.iter().sum::<u64>(),
                c,
                "region {} in the cycle of block {}",
                r,
                b
            );
        }
        // The block: the cycle repeated, each region's last layer trimmed to end at the
        // block's top.
        let height = hi - lo;
        prop_assert!(block.steps.windows(2).all(|w| w[0].height_um < w[1].height_um));
        prop_assert_eq!(block.steps.last().map(|s| s.height_um), Some(height));
        for k in 0..height / c {
            let shifted: Vec<_> = block
                .steps
                .iter()
                .filter(|s| s.height_um > k * c && s.height_um <= (k + 1) * c)
                .map(|s| (s.height_um - k * c, s.deposits.clone()))
                .collect();
            let once: Vec<_> = cycle
                .steps
                .iter()
                .map(|s| (s.height_um, s.deposits.clone()))
                .collect();
            prop_assert_eq!(shifted, once, "cycle {} of block {}", k, b);
        }
        for &r in present {
            let layers = region_layers(&block.steps, r);
            prop_assert_eq!(layers.iter().sum::<u64>(), height, "region {} in block {}", r, b);
            prop_assert_eq!(layers.len() as u64, height.div_ceil(thickness[r]));
            let (last, whole) = layers.split_last().expect("a layer");
            prop_assert!(whole.iter().all(|&t| t == thickness[r]));
            prop_assert!(*last > 0 && *last <= thickness[r]);
        }
        deposits += block.steps.iter().map(|s| s.deposits.len()).sum::<usize>();
    }
    // Every deposit is one layer of its region, in build order.
    let slots = seq.slots();
    prop_assert_eq!(slots.len(), deposits);
    for w in slots.windows(2) {
        prop_assert!(w[0].z <= w[1].z + 1e-12);
    }
    for s in &slots {
        let r = s.material_region.expect("each layer names its region");
        let part = &case.parts[r];
        prop_assert!(
            um(s.z - s.thickness) >= part.z.0 && um(s.z) <= part.z.1,
            "a layer of region {} at {}..{} mm",
            r,
            s.z - s.thickness,
            s.z
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(512))]

    /// Work cycles are the least common multiple of the thicknesses present, and every
    /// block repeats its cycle.
    #[test]
    fn work_cycles_are_least_common_multiples(case in cycle_case()) {
        check_cycles(&case)?;
    }
}

/// Found by `work_cycles_are_least_common_multiples`: three parts over the same height
/// at 0.031, 0.091 and 0.4 mm have a work cycle of 1128.4 mm, over the 1 m limit. The
/// stage refuses it, but only after building the whole cycle (some 50,000 steps) and
/// checking its height; at 0.997, 0.998, 0.999 and 1.001 mm (a cycle of about 1e12 µm)
/// it runs out of memory before it can refuse.
#[test]
fn an_over_long_cycle_is_refused_before_it_is_built() {
    let part = |um| CyclePart {
        from: ThicknessFrom::Table(um),
        z: (0, 1000),
    };
    let case = CycleCase {
        parts: vec![part(31), part(91), part(400)],
        default: 100,
    };
    if let Err(e) = check_cycles(&case) {
        panic!("{e}");
    }
}

/// Found by `sources_tile_random_families`, shrunk: an axis source tilted 0.06° out of
/// the layer. Its set {d < D} in the layer is an ellipse some 1000 times longer than
/// wide, not clipped to the family's box as a horizontal axis's strip is, and the
/// booleans on the grid such a long ellipse needs move the family's own edges: the
/// 0.47 mm² triangle's regions come out 1.8e-6 of its area too large. Tilted by 1e-9,
/// the 2 mm square gets no region at all.
#[test]
fn an_axis_source_almost_in_the_layer_still_tiles() {
    let triangle = RandomFamily {
        outer: vec![
            pt(0.6, 0.0),
            pt(-0.3, 0.6 * 0.75f64.sqrt()),
            pt(-0.3, -0.6 * 0.75f64.sqrt()),
        ],
        holes: Vec::new(),
        size: 2.0,
        centre: pt(0.0, 0.0),
    };
    let square = RandomFamily {
        outer: vec![pt(-1.0, -1.0), pt(1.0, -1.0), pt(1.0, 1.0), pt(-1.0, 1.0)],
        ..triangle.clone()
    };
    for (family, direction, width) in [
        (&triangle, "[0.0, -0.1, 0.001]", 2.8),
        (&square, "[0.0, 1.0, -1e-9]", 2.0),
    ] {
        let text = format!(
            "use = \"sources\"\nsources = [{{ kind = \"axis\", at = [0.0, 0.0, 1.0], direction = {direction}, \
             width = {width:?}, k = 0.5, step = 0.2, start = \"a\", end = \"b\" }}]"
        );
        if let Err(e) = discretise_and_check(family, &text) {
            panic!("{text}\n{e}");
        }
    }
}
