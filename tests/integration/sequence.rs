//! Fabrication sequences end to end: the three-region pipe of the CMPM process-planning
//! paper (Fig. 11) is deposited in 3.0 mm work cycles of 18 steps, each region cut at
//! its own heights and thickness.

use crate::support::{box_stl, pipelines, run_plan, run_text, try_run_text, write};
use std::path::Path;

fn run_pipe(out: &Path) -> serde_json::Value {
    run_plan(
        &pipelines().join("pipe-work-cycles.toml"),
        out,
        &[],
        "pipe-work-cycles.json",
    )
}

#[test]
fn three_region_pipe_follows_the_work_cycles() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run_pipe(dir.path());
    let seq = &plan["sequence"];
    let regions: Vec<(&str, u64)> = seq["regions"]
        .as_array()
        .expect("regions")
        .iter()
        .map(|r| {
            (
                r["name"].as_str().expect("name"),
                r["thickness_um"].as_u64().expect("um"),
            )
        })
        .collect();
    assert_eq!(regions, [("inner", 200), ("middle", 500), ("outer", 1500)]);
    let blocks = seq["blocks"].as_array().expect("blocks");
    assert_eq!(blocks.len(), 1, "all three regions span the same height");
    assert_eq!(blocks[0]["cycle"]["height_um"], 3000);
    assert_eq!(blocks[0]["cycle"]["steps"].as_array().expect("steps").len(), 18);
    // Two cycles over 6 mm: 30 + 12 + 4 layers, in deposition order.
    let layers = plan["layers"].as_array().expect("layers");
    assert_eq!(layers.len(), 46);
    assert_eq!(plan["layer_count"], 46);
    let mut per_region = [0usize; 3];
    let mut last_z = 0.0;
    for (i, l) in layers.iter().enumerate() {
        assert_eq!(l["index"], i);
        let r = l["region"].as_u64().expect("each layer names its region") as usize;
        per_region[r] += 1;
        let z = l["z"].as_f64().expect("z");
        let t = l["thickness"].as_f64().expect("thickness");
        assert!(z >= last_z - 1e-12, "layers in build order");
        last_z = z;
        assert!((t - [0.2, 0.5, 1.5][r]).abs() < 1e-12, "layer {i}: {t} mm");
        // A region's multiple of its thickness.
        let k = z / t;
        assert!(
            (k - k.round()).abs() < 1e-9,
            "layer {i} at z = {z} is not on its grid"
        );
        // Only the region's own part is cut in its layers.
        let parts = l["parts"].as_array().expect("parts");
        assert_eq!(parts.len(), 1);
        assert_eq!(parts[0]["part"], regions[r].0);
        let families = parts[0]["families"].as_array().expect("families");
        assert_eq!(families.len(), 1);
        let area = families[0]["area"].as_f64().expect("area");
        let (ro, ri) = [(7.0, 5.0), (9.0, 7.0), (10.0, 9.0)][r];
        let ring = std::f64::consts::PI * (ro * ro - ri * ri);
        assert!((area - ring).abs() / ring < 0.01, "region {r}: {area} vs {ring}");
    }
    assert_eq!(per_region, [30, 12, 4]);
    // Ties deposit in region order: at z = 1.5 the middle, then the outer region.
    let at_1_5: Vec<u64> = layers
        .iter()
        .filter(|l| (l["z"].as_f64().unwrap_or(0.0) - 1.5).abs() < 1e-9)
        .map(|l| l["region"].as_u64().unwrap_or(9))
        .collect();
    assert_eq!(at_1_5, [1, 2]);
    let at_3: Vec<u64> = layers
        .iter()
        .filter(|l| (l["z"].as_f64().unwrap_or(0.0) - 3.0).abs() < 1e-9)
        .map(|l| l["region"].as_u64().unwrap_or(9))
        .collect();
    assert_eq!(at_3, [0, 1, 2]);
}

#[test]
fn material_mode_without_a_sequence_is_an_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = try_run_text(
        dir.path(),
        "[model]\nuse = \"tube\"\nheight = 2.0\n[materials.a]\ncolour = [1, 2, 3]\n\
         [slice]\nuse = \"adaptive\"\nmode = \"material\"\n",
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("[sequence]"), "{err}");
    assert!(!dir.path().join("out").exists(), "no partial output");
}

#[test]
fn a_part_without_thickness_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = try_run_text(
        dir.path(),
        "[model]\nuse = \"tube\"\nheight = 2.0\n[materials.a]\ncolour = [1, 2, 3]\n\
         [[parts]]\nname = \"pipe\"\n[sequence]\nuse = \"work-cycles\"\n[slice]\nuse = \"adaptive\"\n",
    );
    assert_eq!(out.status.code(), Some(2), "a configuration error");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("part `pipe` has no layer thickness"), "{err}");
    assert!(err.contains("p.toml"), "names the file: {err}");
}

#[test]
fn the_pipes_microstructure_is_written_as_bitmap_layers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run_pipe(dir.path());
    let header = std::fs::read_to_string(dir.path().join("inner-bitmap.hdr")).expect("header");
    let data = std::fs::read(dir.path().join("inner-bitmap.dat")).expect("data");
    for file in [
        "pipe-work-cycles.json",
        "pipe-work-cycles.cli",
        "pipe-work-cycles-binary.cli",
        "pipe-work-cycles-materials.cli",
        "pipe-work-cycles.3mf",
        "inner-bitmap.hdr",
        "inner-bitmap.dat",
    ] {
        let len = std::fs::metadata(dir.path().join(file))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(len > 0, "{file} written");
    }
    let records: Vec<Vec<f64>> = header
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().map(|v| v.parse().expect("number")).collect())
        .collect();
    // One bitmap per layer of the inner region, in build order.
    let inner_layers: Vec<u64> = plan["layers"]
        .as_array()
        .expect("layers")
        .iter()
        .filter(|l| l["region"] == 0)
        .map(|l| l["index"].as_u64().expect("index"))
        .collect();
    assert_eq!(
        records.iter().map(|r| r[0] as u64).collect::<Vec<_>>(),
        inner_layers
    );
    let (pi, r_void, period) = (std::f64::consts::PI, 0.25, [1.0, 1.0, 0.6]);
    for rec in &records {
        let (cut_z, pixel, ox, oy) = (rec[3], rec[4], rec[5], rec[6]);
        let (w, h, offset) = (rec[7] as usize, rec[8] as usize, rec[9] as usize);
        let bits = &data[offset..offset + h * (w + 1)];
        let bit = |col: usize, row: usize| bits[row * (w + 1) + col] == b'1';
        let mut ones = 0usize;
        for row in 0..h {
            assert_eq!(bits[row * (w + 1) + w], b'\n');
            for col in 0..w {
                let (x, y) = (ox + (col as f64 + 0.5) * pixel, oy + (row as f64 + 0.5) * pixel);
                let rad = x.hypot(y);
                if bit(col, row) {
                    ones += 1;
                    assert!(
                        (5.0 - pixel..=7.0 + pixel).contains(&rad),
                        "material outside the ring"
                    );
                }
            }
        }
        // The voids this layer cuts: lattice rows within the radius of the cut height.
        let k = (cut_z / period[2]).round();
        let dz = k * period[2] - cut_z;
        let rc2 = r_void * r_void - dz * dz;
        let ring = pi * (49.0 - 25.0);
        let area = ones as f64 * pixel * pixel;
        if rc2 > 0.0 {
            // A void centre well inside the ring is empty: (6, 0) is a lattice point.
            let (col, row) = (((6.0 - ox) / pixel) as usize, ((0.0 - oy) / pixel) as usize);
            assert!(!bit(col, row), "void at (6, 0), z = {cut_z}");
            // The voids take material away.
            assert!(area < ring * 0.99, "{area} of {ring}");
        } else {
            assert!((area - ring).abs() < 0.01 * ring, "solid layer: {area} vs {ring}");
        }
    }
}

/// Fig. 3 of the CMPM paper as five boxes side by side along x: (name, x0, z0, z1,
/// thickness).
const FIG3: [(&str, f64, f64, f64, f64); 5] = [
    ("matrix", 0.0, 0.0, 10.0, 0.5),
    ("lower", 10.0, 0.0, 4.0, 0.2),
    ("upper", 10.0, 4.0, 10.0, 1.5),
    ("band", 20.0, 2.0, 8.0, 0.5),
    ("shell", 30.0, 0.0, 10.0, 1.0),
];

/// Fig. 3's pipeline in `dir`, its boxes written there, with `extra` tables.
fn fig3(dir: &Path, extra: &str) -> String {
    let mut text =
        String::from("name = \"fig3\"\n[sequence]\nuse = \"work-cycles\"\n[slice]\nuse = \"adaptive\"\n");
    for (name, x0, z0, z1, t) in FIG3 {
        write(
            dir,
            &format!("{name}.stl"),
            &box_stl([x0, 0.0, z0], [x0 + 10.0, 10.0, z1]),
        );
        text += &format!(
            "[materials.{name}]\ncolour = [100, 100, 100]\nlayer_thickness = {t}\n\
             [[parts]]\nname = \"{name}\"\nmaterials = [\"{name}\"]\n\
             [parts.model]\nfile = \"{name}.stl\"\nplace = \"keep\"\n"
        );
    }
    text += "[[output]]\nuse = \"json\"\npath = \"plan.json\"\n";
    text + extra
}

/// The CMPM paper's Fig. 3 divides an object of five material regions into four
/// blocks at the regions' heights, each block holding whole (parts of) regions. Here
/// five regions of their own thicknesses span 0-10, 0-4, 4-10, 2-8 and 0-10 mm: the
/// blocks are 0-2, 2-4, 4-8 and 8-10 mm with the regions present in each, and every
/// region's deposits in a block add up to the block's height.
#[test]
fn five_material_regions_make_four_blocks() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run_text(dir.path(), &fig3(dir.path(), ""), "plan.json");
    let blocks = plan["sequence"]["blocks"].as_array().expect("blocks");
    let got: Vec<(f64, f64, Vec<u64>)> = blocks
        .iter()
        .map(|b| {
            (
                b["z_start"].as_f64().expect("start"),
                b["z_end"].as_f64().expect("end"),
                b["regions"]
                    .as_array()
                    .expect("regions")
                    .iter()
                    .map(|r| r.as_u64().expect("index"))
                    .collect(),
            )
        })
        .collect();
    assert_eq!(
        got,
        [
            (0.0, 2.0, vec![0, 1, 4]),
            (2.0, 4.0, vec![0, 1, 3, 4]),
            (4.0, 8.0, vec![0, 2, 3, 4]),
            (8.0, 10.0, vec![0, 2, 4]),
        ]
    );
    for b in blocks {
        let height = ((b["z_end"].as_f64().expect("end") - b["z_start"].as_f64().expect("start")) * 1000.0)
            .round() as u64;
        for r in b["regions"].as_array().expect("regions") {
            let sum: u64 = b["steps"]
                .as_array()
                .expect("steps")
                .iter()
                .flat_map(|s| s["deposits"].as_array().expect("deposits"))
                .filter(|d| d["region"] == *r)
                .map(|d| d["thickness_um"].as_u64().expect("um"))
                .sum();
            assert_eq!(sum, height, "region {r} in block {b}");
        }
    }
}

#[test]
fn auto_thicknesses_follow_the_base_cell_and_the_sampled_gradient() {
    // cmpm 4.1: the microstructure a tenth of its 1 mm base cell; the FGM, graded
    // z / 6 (a sixth per mm), thick enough for a change of 0.1 per layer: 0.6 mm; the
    // composite, one material, the thickest: 2 mm. A steeper FGM (z / 2) stops at 0.5.
    let dir = tempfile::tempdir().expect("tempdir");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    let auto = "[sequence]\nuse = \"work-cycles\"\nthickness = { inner = \"auto\", middle = \"auto\", outer = \"auto\" }\nbase_cell = { inner = 1.0 }\nstep = 0.1\n";
    let text = pipe.replace("[sequence]\nuse = \"work-cycles\"\n", auto);
    assert_ne!(text, pipe);
    let plan = run_text(dir.path(), &text, "pipe-work-cycles.json");
    let regions = plan["sequence"]["regions"].as_array().expect("regions");
    let got: Vec<u64> = regions
        .iter()
        .map(|r| r["thickness_um"].as_u64().expect("um"))
        .collect();
    assert_eq!(got, [100, 600, 2000]);
    let rule = |i: usize| regions[i]["rule"].as_str().expect("rule").to_string();
    assert!(rule(0).contains("1/10 of the 1 mm base cell"), "{}", rule(0));
    assert!(rule(1).contains("0.1667 per mm"), "{}", rule(1));
    assert!(rule(2).contains("constant composition"), "{}", rule(2));
    // One 6 mm cycle: 60 + 10 + 3 layers.
    assert_eq!(plan["sequence"]["blocks"][0]["cycle"]["height_um"], 6000);
    assert_eq!(plan["layer_count"], 73);
    let steep = text.replace("f = \"z / 6.0\"", "f = \"clamp01(z / 2.0)\"");
    let plan = run_text(dir.path(), &steep, "pipe-work-cycles.json");
    assert_eq!(plan["sequence"]["regions"][1]["thickness_um"], 500);
    // A quadratic grading changes fastest at the top. The gradient is the steepest
    // change between neighbouring sample cuts, 24 over the part's 6 mm: graded at
    // their layers' tops, the last two (5.75 and 6 mm) differ by (36 - 33.0625) / 36
    // over 0.25 mm, 0.3264 per mm; a change of 0.5 per layer then takes 1.5 mm layers.
    let quadratic = text
        .replace("f = \"z / 6.0\"", "f = \"(z / 6.0) * (z / 6.0)\"")
        .replace("step = 0.1", "step = 0.5");
    let plan = run_text(dir.path(), &quadratic, "pipe-work-cycles.json");
    let middle = &plan["sequence"]["regions"][1];
    assert_eq!(middle["thickness_um"], 1500, "{middle}");
    assert!(
        middle["rule"].as_str().expect("rule").contains("0.3264 per mm"),
        "{middle}"
    );
    // A base cell for a name that is neither a part nor a region is named.
    let wrong = text.replace("base_cell = { inner = 1.0 }", "base_cell = { core = 1.0 }");
    let err = crate::support::text(&try_run_text(dir.path(), &wrong).stderr);
    assert!(err.contains("no part or region named `core`"), "{err}");
}

#[test]
fn fig3_runs_the_hybrid_process_through_its_four_blocks() {
    // Every layer of every block milled where a neighbouring box stands higher, sprayed
    // with allowances (a finish allowance on the thin `lower` region), ground back; the
    // run's check that no wheel levels a surface below another holds across the blocks,
    // and every region ends at the top of its box.
    let dir = tempfile::tempdir().expect("tempdir");
    let process = "[[process]]\nuse = \"end-mill\"\ndiameter = 1.0\n\
                   [[process]]\nuse = \"spray\"\nrough_allowance = 0.1\nfinish_allowance = { lower = 0.02 }\n\
                   [[process]]\nuse = \"grind\"\npass = \"rough\"\n\
                   [[process]]\nuse = \"grind\"\npass = \"finish\"\n";
    let plan = run_text(dir.path(), &fig3(dir.path(), process), "plan.json");
    let layers = plan["layers"].as_array().expect("layers");
    let mut top = [None::<f64>; 5];
    let mut milled = 0;
    for (i, l) in layers.iter().enumerate() {
        let r = l["region"].as_u64().expect("region") as usize;
        let (z, t) = (l["z"].as_f64().expect("z"), l["thickness"].as_f64().expect("t"));
        let ops = l["operations"].as_array().expect("operations");
        // Boxes meet at x = 10, 20 and 30: `matrix` touches `lower`/`upper`, they touch
        // `band`, `band` touches `shell`.
        let x0 = FIG3[r].1;
        let neighbours: Vec<usize> = (0..5)
            .filter(|&q| q != r && (FIG3[q].1 - x0).abs() == 10.0)
            .filter(|&q| FIG3[q].2 <= z - t / 2.0 && z - t / 2.0 <= FIG3[q].3)
            .collect();
        let higher: Vec<usize> = neighbours
            .iter()
            .copied()
            .filter(|&q| top[q].is_some_and(|s| s > z - t + 1e-9))
            .collect();
        let mill = ops.iter().find(|o| o["kind"] == "end-mill");
        assert_eq!(
            mill.is_some(),
            !higher.is_empty(),
            "layer {i} ({}), higher {higher:?}",
            FIG3[r].0
        );
        if let Some(m) = mill {
            // Along the shared faces only, half a cutter inside this box.
            let xs: Vec<f64> = higher
                .iter()
                .map(|&q| if FIG3[q].1 > x0 { x0 + 10.0 - 0.5 } else { x0 + 0.5 })
                .collect();
            for p in m["paths"].as_array().expect("paths") {
                for q in p["points"].as_array().expect("points") {
                    let x = q[0].as_f64().expect("x");
                    assert!(
                        xs.iter().any(|w| (x - w).abs() < 1e-6),
                        "layer {i}: end-mill at x = {x}, not {xs:?}"
                    );
                }
            }
            milled += 1;
        }
        for o in ops {
            if let Some(s) = o["surface"].as_f64() {
                top[r] = Some(s);
            }
        }
        assert!(
            (top[r].expect("sprayed") - z).abs() < 1e-9,
            "layer {i} ends at its height"
        );
    }
    for (r, (name, _, _, z1, _)) in FIG3.iter().enumerate() {
        assert!(
            (top[r].expect("deposited") - z1).abs() < 1e-9,
            "{name}: {:?}",
            top[r]
        );
    }
    assert!(milled > 20, "{milled}");
}
