//! Several of a part on one plate (`copies` on a `[[parts]]` entry): each copy is the
//! part's plan moved to its place in the grid, graded as the part is, and a plate that
//! does not fit, or a copy that would overlap another part, is refused by name.

use crate::support::{run_text, text, try_run_text};

/// A tube 20 mm across, graded green to black from the rim, as a part with `extra`.
fn pipeline(extra: &str) -> String {
    format!(
        "name = \"plate\"\n[model]\nuse = \"tube\"\nouter_radius = 10.0\ninner_radius = 5.0\nheight = 1.0\n\
         [materials.green]\ncolour = [0, 255, 0]\n[materials.black]\ncolour = [0, 0, 0]\n\
         [[parts]]\nname = \"tube\"\n{extra}\n\
         [discretise]\nuse = \"offset\"\ncount = 4\nfrom = \"outer\"\n[grade]\nuse = \"xy\"\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
         [[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
    )
}

fn xy(v: &serde_json::Value) -> [f64; 2] {
    [v[0].as_f64().expect("x"), v[1].as_f64().expect("y")]
}

/// Every point of a ring list (`outer`, then `holes`) of a sub-region's polygon.
fn points(polygon: &serde_json::Value) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = polygon["outer"]
        .as_array()
        .expect("outer")
        .iter()
        .map(xy)
        .collect();
    for h in polygon["holes"].as_array().into_iter().flatten() {
        out.extend(h.as_array().expect("hole").iter().map(xy));
    }
    out
}

/// Three copies of the tube, 5 mm apart: two columns (20 + 5 mm apart) and a second
/// row; each copy's sub-regions, reference points and compositions are the tube's
/// moved by that step, layer by layer.
#[test]
fn copies_are_the_parts_plan_moved_to_a_grid_a_gap_apart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run_text(dir.path(), &pipeline("copies = 3\ncopy_gap = 5.0"), "plan.json");
    let names: Vec<&str> = plan["parts"]
        .as_array()
        .expect("parts")
        .iter()
        .map(|p| p["name"].as_str().expect("name"))
        .collect();
    assert_eq!(names, ["tube", "tube#2", "tube#3"]);
    // `check` says what the plate holds.
    let o = crate::support::lamina(&["check", dir.path().join("p.toml").to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let said = format!("{}{}", text(&o.stdout), text(&o.stderr));
    assert!(said.contains("x 1 mm, and 2 copies on the plate"), "{said}");
    let steps = [[0.0, 0.0], [25.0, 0.0], [0.0, 25.0]];
    for layer in plan["layers"].as_array().expect("layers") {
        let parts = layer["parts"].as_array().expect("parts");
        assert_eq!(parts.len(), 3, "{layer}");
        let own = &parts[0]["families"][0]["sub_regions"];
        assert_eq!(own.as_array().expect("regions").len(), 4);
        for (copy, [dx, dy]) in parts.iter().zip(steps) {
            let regions = &copy["families"][0]["sub_regions"];
            for (a, b) in own
                .as_array()
                .expect("regions")
                .iter()
                .zip(regions.as_array().expect("regions"))
            {
                assert_eq!(a["composition"], b["composition"]);
                assert_eq!(a["level"], b["level"]);
                let [ax, ay] = xy(&a["reference"]);
                let [bx, by] = xy(&b["reference"]);
                assert!((bx - ax - dx).abs() < 1e-9 && (by - ay - dy).abs() < 1e-9);
                let (pa, pb) = (points(&a["polygon"]), points(&b["polygon"]));
                assert_eq!(pa.len(), pb.len());
                for ([ax, ay], [bx, by]) in pa.iter().zip(&pb) {
                    assert!((bx - ax - dx).abs() < 1e-9 && (by - ay - dy).abs() < 1e-9);
                }
            }
        }
    }
}

/// Bad counts and gaps are errors at their key; a plate larger than the bed names the
/// copy that falls off it; a copy laid over another model's part is refused.
#[test]
fn a_plate_that_cannot_be_made_is_refused_naming_the_copy() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (extra, key) in [
        ("copies = 0", "copies"),
        ("copies = 2\ncopy_gap = -1.0", "copy_gap"),
    ] {
        let o = try_run_text(dir.path(), &pipeline(extra));
        assert_eq!(o.status.code(), Some(2), "{extra}: {}", text(&o.stderr));
        assert!(text(&o.stderr).contains(key), "{extra}: {}", text(&o.stderr));
    }
    let on_a_machine = format!("machine = \"marlin-mixing-2in1\"\n{}", pipeline("copies = 81"))
        .replace("thickness = 0.5", "thickness = 0.25");
    let o = try_run_text(dir.path(), &on_a_machine);
    let said = text(&o.stderr);
    assert!(!o.status.success(), "81 tubes 20 mm wide fit a 220 mm bed?");
    assert!(
        said.contains("the plate (part `tube` and 80 copies, 260 x 260 mm) does not fit"),
        "{said}"
    );
    assert!(!dir.path().join("out/plan.json").exists());
    // A second part on its own model, a box where the tube's copy goes (x 25-35 mm).
    std::fs::write(dir.path().join("box.stl"), box_stl([25.0, -5.0], [35.0, 5.0])).expect("box");
    let crowded = pipeline("copies = 2").replace(
        "[discretise]",
        "[[parts]]\nname = \"box\"\nmaterials = [\"green\"]\n[parts.model]\nuse = \"stl\"\nfile = \"box.stl\"\nplace = \"keep\"\n[discretise]",
    );
    let o = try_run_text(dir.path(), &crowded);
    let said = text(&o.stderr);
    assert!(!o.status.success(), "a copy over another part");
    assert!(
        said.contains("part `tube`'s copy 2") && said.contains("overlaps part `box`"),
        "{said}"
    );
}

/// An ASCII STL of a box 1 mm tall over the rectangle from `lo` to `hi`.
fn box_stl(lo: [f64; 2], hi: [f64; 2]) -> String {
    let c = |i: usize| {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { 0.0 } else { 1.0 },
        ]
    };
    // Each face as two triangles wound outward, corners by their bits (x 1, y 2, z 4).
    let faces = [
        [0, 2, 3, 1], // bottom
        [4, 5, 7, 6], // top
        [0, 1, 5, 4], // front
        [2, 6, 7, 3], // back
        [0, 4, 6, 2], // left
        [1, 3, 7, 5], // right
    ];
    let mut out = String::from("solid box\n");
    for [a, b, cc, d] in faces {
        for t in [[a, b, cc], [a, cc, d]] {
            out.push_str("facet normal 0 0 0\nouter loop\n");
            for v in t {
                let [x, y, z] = c(v);
                out.push_str(&format!("vertex {x} {y} {z}\n"));
            }
            out.push_str("endloop\nendfacet\n");
        }
    }
    out + "endsolid box\n"
}

/// On two gantries the rear head cannot come nearer the bed's front edge than the two
/// envelopes (the front head at the edge), nor the front head nearer the back edge: a
/// column of gears on shafts that fills the bed in Y is refused with the head, the
/// edge and how far it reaches, and writes nothing.
#[test]
fn a_plate_beyond_the_gantries_reach_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let pipeline = crate::support::pipelines().join("assembly-two-tools.toml");
    let mut args = vec![
        "run",
        pipeline.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "--set",
        "machine=\"rrf-dual-gantry-2\"",
    ];
    for o in [
        "parts.0.copies=4",
        "parts.1.copies=4",
        "parts.0.copy_columns=1",
        "parts.1.copy_columns=1",
        "parts.0.copy_gap=35.0",
        "parts.1.copy_gap=35.0",
    ] {
        args.extend(["--set", o]);
    }
    let o = crate::support::lamina(&args);
    let said = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{said}");
    assert!(
        said.contains("head (tool ") && said.contains("on two gantries it reaches no nearer the bed's"),
        "{said}"
    );
    assert!(!out.join("assembly-two-tools.gcode").exists());
}
