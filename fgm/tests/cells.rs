//! A microstructure read from a stage's `cell` table, as the stages that use it read
//! it (cmpm-process-planning 4.3): shapes, sizes, turns and insertion given as numbers
//! or as scripts of the inserting point, checked where the table says them.

use std::path::Path;

use lamina_api::geom::{BBox2, Contour, Point2};
use lamina_api::limits::Limits;
use lamina_api::model::ModelFrame;
use lamina_api::reach::Reach;
use lamina_api::stage::StageConfig;
use lamina_api::table::TableRef;
use lamina_fgm::microstructure::{BaseCellSpec, Microstructure};
use serde::Deserialize;

#[derive(Deserialize)]
struct Table {
    cell: BaseCellSpec,
}

/// The microstructure of a `cell = { ... }` table, or the error building it.
fn read(cell: &str) -> Result<Microstructure, String> {
    let table = TableRef::parse_snippet("export", &format!("cell = {cell}")).map_err(|e| e.to_string())?;
    let scripts = lamina_core::script::local(".", Default::default());
    let reach = Reach::folder(Path::new("."));
    let config = StageConfig {
        table: &table,
        scripts: &scripts,
        base_dir: Path::new("."),
        reach: &reach,
        machine: None,
        limits: Limits::default(),
    };
    let spec: Table = config.parse().map_err(|e| e.to_string())?;
    Microstructure::new(&spec.cell, &config, "cell").map_err(|e| e.to_string())
}

fn cells(cell: &str) -> Microstructure {
    read(cell).unwrap_or_else(|e| panic!("{cell}: {e}"))
}

fn square(lo: f64, hi: f64) -> BBox2 {
    BBox2 {
        min: Point2::new(lo, lo),
        max: Point2::new(hi, hi),
    }
}

/// Centre and size (width, depth) of a void's bounding box.
fn boxed(c: &Contour) -> ((f64, f64), (f64, f64)) {
    let b = c.bbox();
    (
        ((b.min.x + b.max.x) / 2.0, (b.min.y + b.max.y) / 2.0),
        (b.max.x - b.min.x, b.max.y - b.min.y),
    )
}

fn near(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// The size as a script of x: each void's radius follows its inserting point.
#[test]
fn a_scripted_size_follows_the_inserting_point() {
    let m = cells("{ size = \"0.2 + 0.1 * x\", period = [2.0, 2.0, 2.0] }");
    let voids = m.voids(0.0, &square(-0.1, 4.1), None).unwrap();
    assert_eq!(voids.len(), 9);
    for v in &voids {
        let ((x, _), (w, d)) = boxed(v);
        let r = 0.2 + 0.1 * x.round();
        assert!(
            near(w, 2.0 * r, 1e-9) && near(d, 2.0 * r, 0.01 * r),
            "at x = {x}: {w} x {d}, radius {r}"
        );
    }
    assert_eq!(
        m.describe(),
        "sphere cells of size `0.2 + 0.1 * x` mm x [1, 1, 1] on a lattice of period [2, 2, 2] mm \
         from [0, 0, 0], tilted 0 deg about x"
    );
}

/// The inserting function leaves out the cells where it is not above zero, read at
/// the model's own coordinates when the model was turned and moved.
#[test]
fn cells_go_only_where_the_inserting_function_is_positive() {
    let m = cells("{ size = 0.3, period = [2.0, 2.0, 2.0], insert = \"x - 1.0\" }");
    let xs = |voids: Vec<Contour>| {
        let mut xs: Vec<i64> = voids.iter().map(|v| boxed(v).0.0.round() as i64).collect();
        xs.sort_unstable();
        xs.dedup();
        xs
    };
    assert_eq!(xs(m.voids(0.0, &square(-0.1, 4.1), None).unwrap()), [2, 4]);
    // Moved 10 mm along x: the function still reads the model's x.
    let frame = ModelFrame {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        offset: [10.0, 0.0, 0.0],
    };
    let bbox = BBox2 {
        min: Point2::new(9.9, -0.1),
        max: Point2::new(14.1, 4.1),
    };
    assert_eq!(xs(m.voids(0.0, &bbox, Some(&frame)).unwrap()), [12, 14]);
    // A size of zero or less leaves a cell out as well.
    let m = cells("{ size = \"if x > 1.0 { 0.5 } else { 0.0 }\", period = [4.0, 4.0, 4.0] }");
    assert_eq!(xs(m.voids(0.0, &square(-0.1, 8.1), None).unwrap()), [4, 8]);
}

/// A box cell 1.0 x 0.4 (half-edges 0.5 and 0.2) turned a quarter about the vertical
/// where x > 1: its section swaps width and depth there.
#[test]
fn a_box_turns_and_leans_where_its_scripts_say() {
    let m = cells(
        "{ shape = \"box\", size = 0.2, aspect = [2.5, 1.0, 1.0], period = [3.0, 3.0, 3.0], \
         turn = \"if x > 1.0 { 90.0 } else { 0.0 }\" }",
    );
    for v in m.voids(0.0, &square(-0.1, 3.1), None).unwrap() {
        let ((x, _), (w, d)) = boxed(&v);
        let (want_w, want_d) = if x > 1.5 { (0.4, 1.0) } else { (1.0, 0.4) };
        assert!(
            near(w, want_w, 1e-9) && near(d, want_d, 1e-9),
            "at x = {x}: {w} x {d}"
        );
    }
    // Leaning 90 degrees about x lays the box's z axis along -y: a box 0.4 x 0.4 x 1.6
    // (half-edges 0.2, 0.2, 0.8) is then 0.4 wide and 1.6 deep.
    let m = cells(
        "{ shape = \"box\", size = 0.2, aspect = [1.0, 1.0, 4.0], period = [3.0, 3.0, 3.0], lean = 90.0 }",
    );
    let v = m.voids(0.0, &square(-0.1, 0.1), None).unwrap();
    assert_eq!(v.len(), 1);
    let (_, (w, d)) = boxed(&v[0]);
    assert!(near(w, 0.4, 1e-9) && near(d, 1.6, 1e-9), "{w} x {d}");
    assert_eq!(
        m.describe(),
        "box cells of size 0.2 mm x [1, 1, 4], leaning 90 deg on a lattice of period [3, 3, 3] mm \
         from [0, 0, 0], tilted 0 deg about x"
    );
    // Leaning 45 degrees toward -y: a plane 0.3 above the centre cuts the box about
    // its axis at y = -0.3.
    let m = cells(
        "{ shape = \"box\", size = 0.2, aspect = [1.0, 1.0, 4.0], period = [3.0, 3.0, 3.0], lean = 45.0 }",
    );
    let v = m.voids(0.3, &square(-0.1, 0.1), None).unwrap();
    assert_eq!(v.len(), 1);
    let ((x, y), _) = boxed(&v[0]);
    assert!(near(x, 0.0, 1e-9) && near(y, -0.3, 1e-9), "({x}, {y})");
}

/// A cylinder's radius is size x aspect[0], its half-height size x aspect[2].
#[test]
fn a_cylinder_is_cut_within_its_height() {
    let m = cells(
        "{ shape = \"cylinder\", size = 0.5, aspect = [0.8, 1.0, 1.5], period = [10.0, 10.0, 4.0], turn = 30.0 }",
    );
    let at = |z: f64| m.voids(z, &square(-0.1, 0.1), None).unwrap();
    for z in [0.0, 0.7, -0.7] {
        let v = at(z);
        assert_eq!(v.len(), 1, "{z}");
        let (_, (w, _)) = boxed(&v[0]);
        assert!(near(w, 0.8, 0.01), "{z}: {w}");
    }
    assert!(at(0.8).is_empty());
    assert!(
        m.describe()
            .starts_with("cylinder cells of size 0.5 mm x [0.8, 1, 1.5], turned 30 deg on")
    );
}

/// The lattice may stand tilted against the layers (Fig. 5): its z axis leans about x.
#[test]
fn a_tilted_lattice_moves_its_rows_along_y() {
    let m = cells("{ size = 0.3, period = [10.0, 10.0, 2.0], tilt = 30.0 }");
    // The lattice point (0, 0, 2) stands at y = -2 sin 30 = -1, z = 2 cos 30 = 1.732.
    let around = BBox2 {
        min: Point2::new(-0.5, -1.5),
        max: Point2::new(0.5, 0.5),
    };
    let near_origin = |z: f64| -> Vec<((f64, f64), (f64, f64))> {
        m.voids(z, &around, None)
            .unwrap()
            .iter()
            .map(boxed)
            .filter(|((x, y), _)| x.abs() < 1.0 && (-1.5..0.5).contains(y))
            .collect()
    };
    let v = near_origin(3f64.sqrt());
    assert_eq!(v.len(), 1, "{v:?}");
    let ((x, y), (w, _)) = v[0];
    assert!(
        near(x, 0.0, 1e-9) && near(y, -1.0, 1e-9) && near(w, 0.6, 1e-9),
        "{x}, {y}: {w}"
    );
    // Upright, that row would stand at z = 2 over the origin, and cut a plane at 2.1.
    assert!(near_origin(2.1).is_empty());
    assert!(m.describe().ends_with("tilted 30 deg about x"));
}

#[test]
fn bad_cells_are_refused_at_their_key() {
    for (cell, says) in [
        (
            "{ shape = \"cone\", size = 1.0, period = [3.0, 3.0, 3.0] }",
            "`shape` is `cone`: use `sphere`, `box` or `cylinder`",
        ),
        (
            "{ size = 1.0, period = [3.0, 0.0, 3.0] }",
            "`period`: every spacing must be a positive number of mm",
        ),
        ("{ size = 1.0, period = [3.0, 3.0, -1.0] }", "`period`"),
        (
            "{ size = 1.0, period = [3.0, 3.0, 3.0], aspect = [1.0, 0.0, 1.0] }",
            "`aspect`: every multiplier must be positive",
        ),
        (
            "{ size = 1.0, period = [3.0, 3.0, 3.0], tilt = 90.0 }",
            "`tilt` within (-90, 90) degrees",
        ),
        (
            "{ size = 1.0, period = [3.0, 3.0, 3.0], tilt = -90.0 }",
            "`tilt` within (-90, 90) degrees",
        ),
        (
            "{ size = 1.0, period = [3.0, 3.0, 3.0], origin = [0.0, inf, 0.0] }",
            "`origin` must be finite",
        ),
        (
            "{ size = nan, period = [3.0, 3.0, 3.0] }",
            "`cell.cell` must be a finite number",
        ),
        (
            "{ size = 1.0, period = [3.0, 3.0, 3.0], turn = inf }",
            "must be a finite number",
        ),
        ("{ size = 1.0, period = [3.0, 3.0, 3.0], lean = \"x +\" }", ""),
        ("{ size = 1.0, period = [3.0, 3.0, 3.0], insert = \"(\" }", ""),
    ] {
        match read(cell) {
            Ok(_) => panic!("{cell} was accepted"),
            Err(e) => assert!(e.contains(says), "{cell}: {e}"),
        }
    }
    // Near the bounds: accepted.
    for cell in [
        "{ size = 0.1, period = [3.0, 3.0, 3.0], tilt = 89.9 }",
        "{ size = 0.1, period = [3.0, 3.0, 3.0], tilt = -89.9 }",
        "{ size = 0.1, period = [0.5, 0.5, 0.5] }",
    ] {
        read(cell).unwrap_or_else(|e| panic!("{cell}: {e}"));
    }
    // A script that gives no finite number where a cell is placed fails the layer.
    let m = cells("{ size = \"1.0 / x\", period = [3.0, 3.0, 3.0] }");
    let e = m.voids(0.0, &square(-0.1, 0.1), None).unwrap_err().to_string();
    assert!(e.contains("returned inf") && e.contains("size"), "{e}");
}

/// Scripts read every coordinate of the inserting point.
#[test]
fn scripts_read_y_and_z_as_well() {
    let m = cells("{ size = 0.3, period = [2.0, 2.0, 2.0], insert = \"y + z - 3.0\" }");
    // At z = 2: cells where y > 1.
    let mut ys: Vec<i64> = m
        .voids(2.0, &square(-0.1, 4.1), None)
        .unwrap()
        .iter()
        .map(|v| boxed(v).0.1.round() as i64)
        .collect();
    ys.sort_unstable();
    ys.dedup();
    assert_eq!(ys, [2, 4]);
}

/// A box cell's half-edges are its size times the aspect along each of its axes, and
/// on a tilted lattice it leans with the lattice: a plane 0.3 above its centre cuts it
/// about the point of its axis there, 0.3 tan 30 toward -y.
#[test]
fn a_box_on_a_tilted_lattice_leans_with_it() {
    let m = cells("{ shape = \"box\", size = 0.2, aspect = [1.0, 2.0, 4.0], period = [10.0, 10.0, 10.0] }");
    let v = m.voids(0.0, &square(-0.1, 0.1), None).unwrap();
    let (_, (w, d)) = boxed(&v[0]);
    assert!(near(w, 0.4, 1e-9) && near(d, 0.8, 1e-9), "{w} x {d}");
    let m = cells(
        "{ shape = \"box\", size = 0.2, aspect = [1.0, 1.0, 4.0], period = [10.0, 10.0, 10.0], tilt = 30.0 }",
    );
    let v = m.voids(0.3, &square(-0.1, 0.1), None).unwrap();
    assert_eq!(v.len(), 1);
    let ((x, y), _) = boxed(&v[0]);
    let want = -0.3 * 30f64.to_radians().tan();
    assert!(
        near(x, 0.0, 1e-9) && near(y, want, 1e-9),
        "({x}, {y}) against (0, {want})"
    );
}
