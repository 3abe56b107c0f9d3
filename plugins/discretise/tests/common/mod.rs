//! Shared by the discretiser tests: families built from generated contours, stages built
//! from TOML snippets through the registry, and the tiling assertion.

#![allow(dead_code)]

use lamina_core::stage::{Discretiser, FamilyContext};
use lamina_core::{Contour, ContourNode, ContourTree, Family, Layer, Polygon, Registry, RunInfo, SubRegion};
use lamina_discretise::check::tiling;

pub use lamina_discretise::shapes::{circle, rect};

pub fn stage(text: &str) -> Box<dyn Discretiser> {
    stage_with_limits(text, lamina_core::Limits::default())
}

/// A stage built under a run's `limits`.
pub fn stage_with_limits(text: &str, limits: lamina_core::Limits) -> Box<dyn Discretiser> {
    try_stage_with_limits(text, limits).unwrap_or_else(|e| panic!("{text}: {e}"))
}

/// A stage built under a run's `limits`, or the error building it.
pub fn try_stage_with_limits(
    text: &str,
    limits: lamina_core::Limits,
) -> lamina_core::Result<Box<dyn Discretiser>> {
    let table = lamina_core::pipeline::TableRef::parse_snippet("discretise", text).expect("snippet");
    let scripts = lamina_core::script::local(".", Default::default());
    let context = lamina_core::stage::PipelineContext {
        limits,
        ..Default::default()
    };
    Registry::linked()
        .expect("registry")
        .build_for::<dyn Discretiser>(&table, &scripts, std::path::Path::new("."), context)
}

pub fn build_error(text: &str) -> String {
    let table = lamina_core::pipeline::TableRef::parse_snippet("discretise", text).expect("snippet");
    let scripts = lamina_core::script::local(".", Default::default());
    match Registry::linked().expect("registry").build::<dyn Discretiser>(
        &table,
        &scripts,
        std::path::Path::new("."),
    ) {
        Ok(_) => panic!("{text}: should be refused"),
        Err(e) => e.to_string(),
    }
}

/// Asserts that each `(table, key)` is refused when built, with an error naming `key`.
pub fn assert_refused(cases: &[(&str, &str)]) {
    for (text, key) in cases {
        let err = build_error(text);
        assert!(err.contains(key), "{text:?}: {err}");
    }
}

/// One layer holding one family: `outer` and its holes.
pub struct OneFamily {
    pub info: RunInfo,
    pub layer: Layer,
    pub tree: ContourTree,
    /// The part's mesh, for stages that measure in space.
    pub mesh: Option<lamina_core::Mesh>,
}

impl OneFamily {
    pub fn new(outer: Contour, holes: Vec<Contour>) -> Self {
        let n = holes.len();
        let mut contours = vec![outer.oriented(true)];
        contours.extend(holes.into_iter().map(|h| h.oriented(false)));
        let mut nodes = vec![ContourNode {
            contour: 0,
            level: 0,
            parent: None,
            children: (1..=n).collect(),
        }];
        nodes.extend((1..=n).map(|i| ContourNode {
            contour: i,
            level: 1,
            parent: Some(0),
            children: vec![],
        }));
        Self {
            info: RunInfo {
                base_dir: ".".into(),
                materials: vec![],
                parts: vec![],
                z_min: 0.0,
                z_max: 1.0,
                xy_bounds: lamina_core::BBox2::EMPTY,
                machine: None,
                model_frame: None,
            },
            layer: Layer {
                index: 0,
                z: 0.2,
                thickness: 0.2,
                contours,
                warnings: vec![],
                section_area: None,
            },
            tree: ContourTree {
                nodes,
                families: vec![Family {
                    outer: 0,
                    holes: (1..=n).collect(),
                }],
            },
            mesh: None,
        }
    }

    pub fn polygon(&self) -> Polygon {
        self.tree.family_polygon(&self.layer.contours, 0)
    }

    pub fn run(&self, d: &dyn Discretiser) -> Vec<SubRegion> {
        self.try_run(d).expect("discretises")
    }

    /// The regions of the discretiser `text` builds, asserted to tile the family
    /// ([`assert_tiles`]).
    pub fn tiles(&self, text: &str) -> Vec<SubRegion> {
        let regions = self.run(&*stage(text));
        assert_tiles(&self.polygon(), &regions);
        regions
    }

    #[allow(dead_code)]
    pub fn try_run(&self, d: &dyn Discretiser) -> lamina_core::Result<Vec<SubRegion>> {
        let polygons = self.tree.family_polygons(&self.layer.contours);
        let ctx = FamilyContext {
            info: &self.info,
            layer: &self.layer,
            tree: &self.tree,
            polygons: &polygons,
            mesh: self.mesh.as_ref(),
            part: 0,
            family: 0,
        };
        d.discretise(&ctx)
    }
}

/// Asserts the regions tile the family (1e-3 of its area, no overlap, valid polygons)
/// and that every reference point lies inside its region.
pub fn assert_tiles(family: &Polygon, regions: &[SubRegion]) {
    assert!(!regions.is_empty());
    let t = tiling(family, regions);
    assert!(t.is_ok(1e-3), "{t:?}");
    assert!(t.overlap < 1e-6, "{t:?}");
    for r in regions {
        assert!(
            r.polygon.contains(r.reference),
            "reference outside region {}",
            r.index
        );
        assert!((0.0..=1.0).contains(&r.level));
        assert!(r.index < r.count);
        assert!(r.composition.is_none());
    }
}

/// Distinct indices, in order.
pub fn indices(regions: &[SubRegion]) -> Vec<usize> {
    let mut v: Vec<usize> = regions.iter().map(|r| r.index).collect();
    v.dedup();
    v
}

/// Asserts that each region is the ring of width `width` whose outer radius is
/// `outer - width * index` (concentric about the origin), within `tol` of its area.
pub fn assert_ring_areas(regions: &[SubRegion], outer: f64, width: f64, tol: f64) {
    for r in regions {
        let a = outer - width * r.index as f64;
        let b = a - width;
        let want = std::f64::consts::PI * (a * a - b * b);
        assert!(
            (r.area() - want).abs() / want < tol,
            "ring {}: {} vs {want}",
            r.index,
            r.area()
        );
    }
}

/// Two 10 x 10 squares joined by a bridge 10 long and 1 wide: not star-shaped, and
/// split into two islands by the first ring thicker than half a millimetre.
pub fn dumbbell() -> Contour {
    Contour::new(
        [
            (0.0, 0.0),
            (10.0, 0.0),
            (10.0, 4.5),
            (20.0, 4.5),
            (20.0, 0.0),
            (30.0, 0.0),
            (30.0, 10.0),
            (20.0, 10.0),
            (20.0, 5.5),
            (10.0, 5.5),
            (10.0, 10.0),
            (0.0, 10.0),
        ]
        .map(|(x, y)| lamina_core::Point2::new(x, y))
        .to_vec(),
    )
}

/// A family of no area: three points on a line.
pub fn flat_family() -> OneFamily {
    OneFamily::new(
        Contour::new(vec![
            lamina_core::Point2::new(0.0, 0.0),
            lamina_core::Point2::new(1.0, 0.0),
            lamina_core::Point2::new(2.0, 0.0),
        ]),
        vec![],
    )
}
