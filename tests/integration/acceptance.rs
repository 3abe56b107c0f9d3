//! Acceptance over the real meshes in ../shared/models (or $LAMINA_MODELS): every model
//! is sliced and sorted, and the invariants every layer must keep are checked. The tests
//! are `#[ignore]`d in the ordinary suite and run by .ci/run in release mode; they skip
//! with a printed note when the models are absent.

use std::path::Path;
use std::sync::Arc;

use crate::support::{models_dir, skip};
use lamina_core::stage::{MeshSlicer, Slicer};
use lamina_core::{Contour, Mesh, Point2, RunInfo};

fn load(dir: &Path, file: &str, scale: f64) -> Mesh {
    let mut meshes = lamina_test_support::meshes(&format!("use = \"stl\"\nfile = \"{file}\""), dir);
    lamina_core::runtime::place(&mut meshes, scale, lamina_core::pipeline::Placement::Bed);
    assert_eq!(meshes.len(), 1);
    meshes.remove(0)
}

fn slicer(thickness: f64) -> Box<dyn Slicer> {
    lamina_test_support::slicer(&format!("use = \"uniform\"\nthickness = {thickness}"))
}

fn sorter() -> Box<dyn lamina_core::stage::Sorter> {
    lamina_test_support::sorter("use = \"hierarchy\"")
}

/// Proper crossings between edges of the given contours (shared endpoints excluded),
/// found through a uniform grid so large layers stay fast.
fn crossings(contours: &[Contour]) -> usize {
    let edges: Vec<(Point2, Point2)> = contours.iter().flat_map(|c| c.edges()).collect();
    if edges.is_empty() {
        return 0;
    }
    let bb = contours
        .iter()
        .fold(lamina_core::BBox2::EMPTY, |b, c| b.union(&c.bbox()));
    let cells = (edges.len() as f64).sqrt().ceil().max(1.0) as usize;
    let cw = (bb.width() / cells as f64).max(1e-9);
    let ch = (bb.height() / cells as f64).max(1e-9);
    let mut grid: Vec<Vec<u32>> = vec![Vec::new(); cells * cells];
    let cell = |p: Point2| {
        (
            (((p.x - bb.min.x) / cw) as usize).min(cells - 1),
            (((p.y - bb.min.y) / ch) as usize).min(cells - 1),
        )
    };
    for (i, (a, b)) in edges.iter().enumerate() {
        let (x0, y0) = cell(Point2::new(a.x.min(b.x), a.y.min(b.y)));
        let (x1, y1) = cell(Point2::new(a.x.max(b.x), a.y.max(b.y)));
        for y in y0..=y1 {
            for x in x0..=x1 {
                grid[y * cells + x].push(i as u32);
            }
        }
    }
    let orient = |a: Point2, b: Point2, c: Point2| (b - a).perp(&(c - a));
    let mut pairs = std::collections::HashSet::new();
    for bucket in &grid {
        for (k, &i) in bucket.iter().enumerate() {
            for &j in &bucket[k + 1..] {
                let (a, b) = edges[i as usize];
                let (c, d) = edges[j as usize];
                if a == c || a == d || b == c || b == d {
                    continue;
                }
                let (o1, o2) = (orient(a, b, c), orient(a, b, d));
                let (o3, o4) = (orient(c, d, a), orient(c, d, b));
                if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
                    pairs.insert((i.min(j), i.max(j)));
                }
            }
        }
    }
    pairs.len()
}

struct Expect {
    file: &'static str,
    scale: f64,
    /// Loops at 10/30/50/70/90 % of the height, where the reference checker agrees.
    loops: Option<[usize; 5]>,
    max_level: Option<usize>,
}

/// A model's expectations, in [`MODELS`]' order of fields.
const fn model(
    file: &'static str,
    scale: f64,
    loops: Option<[usize; 5]>,
    max_level: Option<usize>,
) -> Expect {
    Expect {
        file,
        scale,
        loops,
        max_level,
    }
}

/// The models of [`MODELS`] that are in `dir`; each one missing skips with a note (or
/// fails under `LAMINA_REQUIRE`).
fn present(dir: &Path) -> impl Iterator<Item = &'static Expect> + '_ {
    MODELS.iter().filter(move |m| {
        let path = dir.join(m.file);
        let there = path.exists();
        if !there {
            skip(&format!("{} not found", path.display()));
        }
        there
    })
}

// One model a line: file, scale to mm, loops, deepest nesting.
#[rustfmt::skip]
const MODELS: &[Expect] = &[
    model("xyz_calibration_cube_20mm.stl",      1.0,    Some([1, 1, 1, 1, 1]), Some(0)),
    model("tube_round.stl",                     1.0,    Some([2, 2, 2, 2, 2]), Some(1)),
    model("gearwheel_40t_keyed_bore.ascii.stl", 1.0,    Some([2, 2, 2, 2, 2]), Some(1)),
    model("planetary_gear_bearing.ascii.stl",   1.0,    Some([9, 9, 9, 9, 9]), Some(3)),
    model("turbine_blade_vtk.stl",              1.0,    Some([1, 1, 1, 1, 1]), Some(0)),
    model("3DBenchy.stl",                       1.0,    None,                  None),
    model("stanford_bunny.stl",                 1000.0, None,                  None),
    model("octagonal_pocket_plate.stl",         1000.0, None,                  None),
    model("openfoam_buildings_400k.stl",        1.0,    None,                  None),
    model("broken_extra_surface.ascii.stl",     1.0,    None,                  None),
];

#[test]
#[ignore = "needs ../shared/models; run by .ci/run"]
fn real_models_slice_into_closed_simple_nested_contours() {
    let Some(dir) = models_dir() else { return };
    let sorter = sorter();
    for m in present(&dir) {
        let start = std::time::Instant::now();
        let mesh = Arc::new(load(&dir, m.file, m.scale));
        let bb = mesh.bbox();
        let height = bb.max.z - bb.min.z;
        let slicer = slicer(height / 100.0);
        let prepared: Box<dyn MeshSlicer> = slicer.prepare(mesh.clone()).expect("prepare");
        let info = lamina_test_support::mesh_info(&dir, &mesh);
        let slots = slicer
            .layers(std::slice::from_ref(&mesh), &info, None)
            .expect("slots");
        let mut warnings = 0;
        let mut volume = 0.0;
        for slot in &slots {
            let layer = prepared.slice(slot).expect("slices");
            warnings += layer.warnings.len();
            let tree = sorter.sort(&layer).expect("sorts");
            for c in &layer.contours {
                assert!(c.len() >= 3, "{}: a contour with {} points", m.file, c.len());
                assert!(c.area() > 0.0);
            }
            for (f, fam) in tree.families.iter().enumerate() {
                let poly = tree.family_polygon(&layer.contours, f);
                volume += poly.area() * slot.thickness;
                assert!(
                    poly.area() > 0.0,
                    "{}: family {f} of layer {} has no area",
                    m.file,
                    slot.index
                );
                for &h in &fam.holes {
                    let p = layer.contours[h].interior_point().expect("hole has an inside");
                    assert!(
                        layer.contours[fam.outer].contains(p),
                        "{}: hole outside its outer",
                        m.file
                    );
                    assert_eq!(tree.nodes[h].level, tree.nodes[fam.outer].level + 1);
                }
            }
            let crossing = crossings(&layer.contours);
            assert_eq!(crossing, 0, "{}: contours of layer {} cross", m.file, slot.index);
            if let (Some(loops), Some(max_level)) = (m.loops, m.max_level) {
                let k = [10, 30, 50, 70, 90].iter().position(|&p| slot.index == p);
                if let Some(k) = k {
                    assert_eq!(
                        layer.contours.len(),
                        loops[k],
                        "{}: loops at layer {}",
                        m.file,
                        slot.index
                    );
                    let deepest = tree.nodes.iter().map(|n| n.level).max().unwrap_or(0);
                    assert_eq!(deepest, max_level, "{}: depth at layer {}", m.file, slot.index);
                }
            }
        }
        if m.loops.is_some() {
            // Watertight: the layers' midpoint-rule volume matches the mesh's volume (1 %
            // at 100 layers: the blade's rounded ends cost 0.6 %).
            let exact = mesh.signed_volume().abs();
            let rel = (volume - exact).abs() / exact;
            assert!(
                rel < 1e-2,
                "{}: layer volume {volume} vs mesh volume {exact}",
                m.file
            );
        }
        println!(
            "{:<36} {:>7} triangles {:>4} layers {:>4} warnings {:>8.1} ms",
            m.file,
            mesh.triangles.len(),
            slots.len(),
            warnings,
            start.elapsed().as_secs_f64() * 1e3
        );
    }
}

fn discretiser(text: &str) -> Box<dyn lamina_core::stage::Discretiser> {
    lamina_test_support::discretiser(text)
}

/// OGC validity (simple rings, holes inside their outer and touching it at most at a
/// point), checked by the `geo` crate: independent of Lamina's own geometry.
///
/// The checks are those of geo's `Validation` for a polygon (geo 0.33), in its order and
/// with its messages, but a ring's self-intersection is found with geo's sweep
/// (`sweep::Intersections`) instead of by testing every pair of the ring's segments, by
/// the same rule: two segments that meet, other than where one ends and the other
/// starts. Rings of real models have thousands of points; the pairwise test took five
/// sixths of this suite's time.
fn ogc_errors(p: &lamina_core::Polygon) -> Vec<String> {
    use geo::algorithm::validation::{CoordIndex, InvalidPolygon, RingRole};
    use geo::coordinate_position::CoordPos;
    use geo::dimensions::Dimensions;
    use geo::{HasDimensions, PreparedGeometry, Relate, RemoveRepeatedPoints};
    let ring = |c: &lamina_core::Contour| {
        geo::LineString::from(c.points.iter().map(|q| (q.x, q.y)).collect::<Vec<_>>())
    };
    let polygon = geo::Polygon::new(ring(&p.outer), p.holes.iter().map(ring).collect());
    let mut errors: Vec<InvalidPolygon> = Vec::new();
    if polygon.is_empty() {
        return Vec::new();
    }
    let rings = std::iter::once(polygon.exterior()).chain(polygon.interiors());
    for (i, r) in rings.enumerate().filter(|(_, r)| !r.0.is_empty()) {
        let role = if i == 0 {
            RingRole::Exterior
        } else {
            RingRole::Interior(i - 1)
        };
        if r.remove_repeated_points().0.len() < 4 {
            errors.push(InvalidPolygon::TooFewPointsInRing(role));
        }
        let lines: Vec<geo::Line> = r.lines().collect();
        // The sweep sorts by x, which a coordinate that is no number breaks: such a
        // ring is tested pair by pair, as geo does.
        let crossing = |a: &geo::Line, b: &geo::Line| a.start != b.end && a.end != b.start;
        let self_intersects = if r.0.iter().all(|c| c.x.is_finite() && c.y.is_finite()) {
            geo::algorithm::sweep::Intersections::from_iter(lines.iter()).any(|(a, b, _)| crossing(a, b))
        } else {
            use geo::Intersects;
            lines.iter().enumerate().any(|(i, a)| {
                lines
                    .iter()
                    .enumerate()
                    .any(|(j, b)| i != j && a.intersects(b) && crossing(a, b))
            })
        };
        if self_intersects {
            errors.push(InvalidPolygon::SelfIntersection(role));
        }
        for (k, c) in r.0.iter().enumerate() {
            if !(c.x.is_finite() && c.y.is_finite()) {
                errors.push(InvalidPolygon::NonFiniteCoord(role, CoordIndex(k)));
            }
        }
    }
    let holes: Vec<(usize, geo::Polygon)> = polygon
        .interiors()
        .iter()
        .enumerate()
        .filter(|(_, r)| !r.0.is_empty())
        .map(|(i, r)| (i, geo::Polygon::new(r.clone(), vec![])))
        .collect();
    if !holes.is_empty() {
        let outer = geo::Polygon::new(polygon.exterior().clone(), vec![]);
        let outer = PreparedGeometry::from(&outer);
        for (k, (i, hole)) in holes.iter().enumerate() {
            let prepared = PreparedGeometry::from(hole);
            let m = outer.relate(&prepared);
            if !m.is_contains() {
                errors.push(InvalidPolygon::InteriorRingNotContainedInExteriorRing(
                    RingRole::Interior(*i),
                ));
            }
            if m.get(CoordPos::OnBoundary, CoordPos::OnBoundary) == Dimensions::OneDimensional {
                errors.push(InvalidPolygon::IntersectingRingsOnALine(
                    RingRole::Exterior,
                    RingRole::Interior(*i),
                ));
            }
            for (j, other) in &holes[k + 1..] {
                let m = prepared.relate(other);
                if m.get(CoordPos::Inside, CoordPos::Inside) == Dimensions::TwoDimensional {
                    errors.push(InvalidPolygon::IntersectingRingsOnAnArea(
                        RingRole::Interior(*i),
                        RingRole::Interior(*j),
                    ));
                }
                if m.get(CoordPos::OnBoundary, CoordPos::OnBoundary) == Dimensions::OneDimensional {
                    errors.push(InvalidPolygon::IntersectingRingsOnALine(
                        RingRole::Interior(*i),
                        RingRole::Interior(*j),
                    ));
                }
            }
        }
    }
    errors.iter().map(ToString::to_string).collect()
}

/// The validity check above says what geo's own `Validation` says, on polygons valid
/// and invalid in each way it tells apart, and on random ones: rings of many points
/// around a centre (valid) and with points thrown anywhere (mostly crossing).
#[test]
fn the_swept_validity_check_agrees_with_geos_own() {
    use geo::Validation;
    let contour = |points: &[(f64, f64)]| {
        lamina_core::Contour::new(
            points
                .iter()
                .map(|&(x, y)| lamina_core::Point2::new(x, y))
                .collect(),
        )
    };
    let square = |x: f64, y: f64, s: f64, cw: bool| {
        let mut p = vec![(x, y), (x + s, y), (x + s, y + s), (x, y + s)];
        if cw {
            p.reverse();
        }
        contour(&p)
    };
    let polygon = |outer, holes| lamina_core::Polygon { outer, holes };
    let mut cases = vec![
        polygon(square(0.0, 0.0, 10.0, false), vec![]),
        // A bow tie, a spike, too few points, a point that is no number.
        polygon(contour(&[(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 1.0)]), vec![]),
        polygon(
            contour(&[
                (0.0, 0.0),
                (2.0, 0.0),
                (2.0, 2.0),
                (3.0, 2.0),
                (2.0, 2.0),
                (0.0, 2.0),
            ]),
            vec![],
        ),
        polygon(contour(&[(0.0, 0.0), (1.0, 0.0), (0.0, 0.0)]), vec![]),
        polygon(contour(&[(0.0, 0.0), (1.0, 0.0), (f64::NAN, 1.0)]), vec![]),
        // A ring that touches itself at a point.
        polygon(
            contour(&[
                (0.0, 0.0),
                (4.0, 0.0),
                (2.0, 2.0),
                (4.0, 4.0),
                (0.0, 4.0),
                (2.0, 2.0),
            ]),
            vec![],
        ),
        // Holes: inside, outside, touching the outer at a point and along a side,
        // overlapping each other, and sharing a side.
        polygon(square(0.0, 0.0, 10.0, false), vec![square(2.0, 2.0, 2.0, true)]),
        polygon(square(0.0, 0.0, 10.0, false), vec![square(20.0, 2.0, 2.0, true)]),
        polygon(
            square(0.0, 0.0, 10.0, false),
            vec![contour(&[(0.0, 5.0), (2.0, 6.0), (2.0, 4.0)])],
        ),
        polygon(square(0.0, 0.0, 10.0, false), vec![square(0.0, 2.0, 2.0, true)]),
        polygon(
            square(0.0, 0.0, 10.0, false),
            vec![square(2.0, 2.0, 3.0, true), square(3.0, 3.0, 3.0, true)],
        ),
        polygon(
            square(0.0, 0.0, 10.0, false),
            vec![square(2.0, 2.0, 2.0, true), square(4.0, 2.0, 2.0, true)],
        ),
    ];
    let mut rng = fastrand::Rng::with_seed(0x5eed_0fba_11ed);
    for n in [5, 12, 40, 200] {
        for _ in 0..25 {
            let star: Vec<(f64, f64)> = (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    let r = 5.0 + 5.0 * rng.f64();
                    (r * a.cos(), r * a.sin())
                })
                .collect();
            let scattered: Vec<(f64, f64)> = (0..n).map(|_| (10.0 * rng.f64(), 10.0 * rng.f64())).collect();
            cases.push(polygon(contour(&star), vec![square(-1.0, -1.0, 2.0, true)]));
            cases.push(polygon(contour(&scattered), vec![]));
        }
    }
    let mut invalid = 0;
    for (k, p) in cases.iter().enumerate() {
        let ring = |c: &lamina_core::Contour| {
            geo::LineString::from(c.points.iter().map(|q| (q.x, q.y)).collect::<Vec<_>>())
        };
        let theirs: Vec<String> = geo::Polygon::new(ring(&p.outer), p.holes.iter().map(ring).collect())
            .validation_errors()
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(ogc_errors(p), theirs, "case {k}");
        invalid += usize::from(!theirs.is_empty());
    }
    // Both kinds are there in numbers.
    assert!(
        invalid > 50 && invalid < cases.len() - 50,
        "{invalid} of {}",
        cases.len()
    );
}

/// Every discretiser's sub-regions tile every family of every model at 0.2 mm: areas
/// within 1e-3 of the family's, no overlap, simple polygons oriented outer
/// counter-clockwise and holes clockwise, and valid polygons by an independent check
/// (`geo`). The families the slicer gives and the default discretiser's sub-regions are
/// checked on every layer; the other discretisers on 12 layers per model, spread over
/// its height, to keep the run short.
#[test]
#[ignore = "needs ../shared/models; run by .ci/run"]
fn real_models_discretise_into_tiling_sub_regions() {
    let Some(dir) = models_dir() else { return };
    let sorter = sorter();
    let slicer = slicer(0.2);
    let stages: Vec<(&str, Box<dyn lamina_core::stage::Discretiser>)> = DISCRETISERS
        .iter()
        .map(|&text| (text, discretiser(text)))
        .collect();
    for m in present(&dir) {
        let start = std::time::Instant::now();
        let mesh = Arc::new(load(&dir, m.file, m.scale));
        let bb = mesh.bbox();
        let prepared: Box<dyn MeshSlicer> = slicer.prepare(mesh.clone()).expect("prepare");
        // One part of two materials, for the stages that grade (sources).
        let material = |name: &str| lamina_core::Material {
            name: name.into(),
            colour: [0, 0, 0],
            layer_thickness: None,
        };
        let info = RunInfo {
            materials: vec![material("a"), material("b")],
            parts: vec![lamina_core::PartInfo {
                name: m.file.into(),
                materials: vec![0, 1],
                mesh: 0,
                z_min: bb.min.z,
                z_max: bb.max.z,
                z_gradient: None,
            }],
            ..lamina_test_support::mesh_info(&dir, &mesh)
        };
        let slots = slicer
            .layers(std::slice::from_ref(&mesh), &info, None)
            .expect("slots");
        let step = slots.len().div_ceil(12).max(1);
        // Layers are independent: checked on every core, the figures combined.
        use rayon::prelude::*;
        let (families, regions, worst_area, worst_overlap) = slots
            .par_iter()
            .map(|slot| {
                let (mut families, mut regions, mut worst_area, mut worst_overlap) = (0, 0, 0.0f64, 0.0f64);
                let sampled = slot.index % step == 0;
                let layer = prepared.slice(slot).expect("slices");
                let tree = sorter.sort(&layer).expect("sorts");
                let polygons = tree.family_polygons(&layer.contours);
                for (f, family) in polygons.iter().enumerate() {
                    let invalid = ogc_errors(family);
                    assert!(
                        invalid.is_empty(),
                        "{}: layer {} family {f} is not a valid polygon: {invalid:?}",
                        m.file,
                        slot.index
                    );
                    families += 1;
                    let ctx = lamina_core::stage::FamilyContext {
                        info: &info,
                        layer: &layer,
                        tree: &tree,
                        polygons: &polygons,
                        // The stages that measure in space (the outer-surface source) read it.
                        mesh: Some(&mesh),
                        part: 0,
                        family: f,
                    };
                    for (k, (text, stage)) in stages.iter().enumerate() {
                        // The first is the default (the paper's Method 1): on every layer.
                        if k > 0 && !sampled {
                            continue;
                        }
                        let out = stage.discretise(&ctx).expect("discretises");
                        regions += out.len();
                        for r in &out {
                            let invalid = ogc_errors(&r.polygon);
                            assert!(
                                invalid.is_empty(),
                                "{}: layer {} family {f} ({text}): region {} is not a valid polygon: {invalid:?}",
                                m.file,
                                slot.index,
                                r.index
                            );
                        }
                        let t = lamina_discretise::check::tiling(family, &out);
                        assert!(
                            t.is_ok(1e-3),
                            "{}: layer {} family {f} ({text}): {t:?}",
                            m.file,
                            slot.index
                        );
                        worst_area = worst_area.max(t.area_error);
                        worst_overlap = worst_overlap.max(t.overlap);
                    }
                }
                (families, regions, worst_area, worst_overlap)
            })
            .reduce(
                || (0, 0, 0.0f64, 0.0f64),
                |a, b| (a.0 + b.0, a.1 + b.1, a.2.max(b.2), a.3.max(b.3)),
            );
        println!(
            "{:<36} {:>4} layers {:>5} families {:>7} regions  area error <= {:.1e}  overlap <= {:.1e} {:>8.1} ms",
            m.file,
            slots.len(),
            families,
            regions,
            worst_area,
            worst_overlap,
            start.elapsed().as_secs_f64() * 1e3
        );
    }
}

/// The discretisers the tiling acceptance runs on every family: both offset references
/// (the nozzle rule makes dozens of rings on the large models), radial lines,
/// step-width with circumferential cells of both cuts, a distance field, and grading
/// sources (the outer surface and a plane, overlaid).
const DISCRETISERS: &[&str] = &[
    "use = \"offset\"\nnozzle = 0.4",
    "use = \"offset\"\ncount = 10\nspacing = 0.4\nfrom = \"all\"",
    "use = \"radial\"\ncount = 10",
    "use = \"step-width\"\nstep = 0.25\ncells_around = 6",
    "use = \"distance-field\"\ncount = 5",
    "use = \"step-width\"\nstep = 0.5\ncell_length = 5.0\ncell_cuts = \"arc\"",
    "use = \"sources\"\nsources = [{ kind = \"surface\", width = 3.0, start = [1.0, 0.0], end = [0.0, 1.0] }, \
     { kind = \"plane\", at = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], width = 50.0, start = [0.0, 1.0], end = [1.0, 0.0] }]",
];
