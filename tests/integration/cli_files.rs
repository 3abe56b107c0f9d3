//! CLI layer files read back by an independent reader written here from the format's
//! description (CLI 2.0: an ASCII header between $$HEADERSTART and $$HEADEREND, then
//! ASCII commands or binary commands: a little-endian u16 command index followed by
//! its parameters). The contours it reads must give the plan's areas.

use crate::support::{run_text, try_run_text};
use std::path::Path;

#[derive(Debug, Default)]
struct CliFile {
    binary: bool,
    units: f64,
    layers_declared: usize,
    labels: Vec<(i64, String)>,
    layers: Vec<CliLayer>,
}

#[derive(Debug, Default)]
struct CliLayer {
    z: f64,
    polylines: Vec<Polyline>,
}

#[derive(Debug, Default, Clone)]
struct Polyline {
    id: i64,
    dir: i64,
    points: Vec<[f64; 2]>,
    /// Modified CLI: the `$$MATERIAL` values before the polyline.
    material: Option<Vec<f64>>,
}

fn read_cli(bytes: &[u8]) -> CliFile {
    let end_marker = b"$$HEADEREND";
    let end = bytes
        .windows(end_marker.len())
        .position(|w| w == end_marker)
        .expect("$$HEADEREND present");
    let header = std::str::from_utf8(&bytes[..end]).expect("ASCII header");
    let start = header.find("$$HEADERSTART").expect("$$HEADERSTART present");
    let mut file = CliFile {
        units: 1.0,
        ..Default::default()
    };
    for line in header[start..].lines().map(str::trim) {
        if line == "$$BINARY" {
            file.binary = true;
        } else if let Some(v) = line.strip_prefix("$$UNITS/") {
            file.units = v.parse().expect("units");
        } else if let Some(v) = line.strip_prefix("$$LAYERS/") {
            file.layers_declared = v.parse().expect("layers");
        } else if let Some(v) = line.strip_prefix("$$LABEL/") {
            let (id, text) = v.split_once(',').expect("id,text");
            file.labels
                .push((id.parse().expect("label id"), text.to_string()));
        }
    }
    let body = &bytes[end + end_marker.len()..];
    if file.binary {
        read_binary(body, &mut file);
    } else {
        read_ascii(std::str::from_utf8(body).expect("ASCII geometry"), &mut file);
    }
    file
}

fn read_ascii(text: &str, file: &mut CliFile) {
    let mut material = None;
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if line.starts_with("//") {
            continue;
        }
        let (cmd, args) = line.split_once('/').unwrap_or((line, ""));
        let nums = || -> Vec<f64> {
            args.split(',')
                .map(|v| v.trim().parse().expect("number"))
                .collect()
        };
        match cmd {
            "$$GEOMETRYSTART" | "$$GEOMETRYEND" => {}
            "$$LAYER" => file.layers.push(CliLayer {
                z: nums()[0],
                polylines: Vec::new(),
            }),
            "$$MATERIAL" => material = Some(nums()),
            "$$POLYLINE" => {
                let v = nums();
                let n = v[2] as usize;
                assert_eq!(v.len(), 3 + 2 * n, "point count of {line}");
                let points = (0..n).map(|i| [v[3 + 2 * i], v[4 + 2 * i]]).collect();
                file.layers
                    .last_mut()
                    .expect("a layer first")
                    .polylines
                    .push(Polyline {
                        id: v[0] as i64,
                        dir: v[1] as i64,
                        points,
                        material: material.take(),
                    });
            }
            other => panic!("unknown command {other}"),
        }
    }
}

fn read_binary(mut b: &[u8], file: &mut CliFile) {
    fn take<const N: usize>(b: &mut &[u8]) -> [u8; N] {
        let (head, rest) = b.split_at(N);
        *b = rest;
        head.try_into().expect("length")
    }
    let u16_ = |b: &mut &[u8]| u16::from_le_bytes(take::<2>(b));
    let i32_ = |b: &mut &[u8]| i32::from_le_bytes(take::<4>(b));
    let f32_ = |b: &mut &[u8]| f32::from_le_bytes(take::<4>(b));
    while !b.is_empty() {
        match u16_(&mut b) {
            127 => file.layers.push(CliLayer {
                z: f64::from(f32_(&mut b)),
                polylines: Vec::new(),
            }),
            128 => file.layers.push(CliLayer {
                z: f64::from(u16_(&mut b)),
                polylines: Vec::new(),
            }),
            // A polyline: 129 of 16-bit integers, 130 of 32-bit integers and floats.
            command @ (129 | 130) => {
                let long = command == 130;
                let int = |b: &mut &[u8]| {
                    if long {
                        i64::from(i32_(b))
                    } else {
                        i64::from(u16_(b))
                    }
                };
                let coord = |b: &mut &[u8]| {
                    if long {
                        f64::from(f32_(b))
                    } else {
                        f64::from(u16_(b))
                    }
                };
                let (id, dir, n) = (int(&mut b), int(&mut b), int(&mut b));
                let points = (0..n).map(|_| [coord(&mut b), coord(&mut b)]).collect();
                file.layers.last_mut().expect("layer").polylines.push(Polyline {
                    id,
                    dir,
                    points,
                    material: None,
                });
            }
            other => panic!("unknown binary command {other}"),
        }
    }
}

/// Shoelace area in file units², positive counter-clockwise.
fn signed_area(points: &[[f64; 2]]) -> f64 {
    points
        .windows(2)
        .map(|w| w[0][0] * w[1][1] - w[1][0] * w[0][1])
        .sum::<f64>()
        / 2.0
}

fn run(pipeline: &str) -> (tempfile::TempDir, serde_json::Value) {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run_text(dir.path(), pipeline, "plan.json");
    (dir, plan)
}

fn check_against_plan(file: &CliFile, plan: &serde_json::Value, tolerance: f64) {
    let layers = plan["layers"].as_array().expect("layers");
    assert_eq!(file.layers_declared, layers.len());
    assert_eq!(file.layers.len(), layers.len());
    let names: Vec<String> = plan["parts"]
        .as_array()
        .expect("parts")
        .iter()
        .map(|p| p["name"].as_str().expect("name").to_string())
        .collect();
    assert_eq!(
        file.labels,
        names
            .iter()
            .enumerate()
            .map(|(i, n)| (i as i64 + 1, n.clone()))
            .collect::<Vec<_>>()
    );
    for (cli, json) in file.layers.iter().zip(layers) {
        let z = json["z"].as_f64().expect("z");
        assert!((cli.z * file.units - z).abs() < 1e-5, "layer at {} vs {z}", cli.z);
        for (pi, part) in json["parts"].as_array().expect("parts").iter().enumerate() {
            let label = names
                .iter()
                .position(|n| part["part"] == n.as_str())
                .expect("part") as i64
                + 1;
            let want: f64 = part["families"]
                .as_array()
                .expect("families")
                .iter()
                .map(|f| f["area"].as_f64().expect("area"))
                .sum();
            let mut got = 0.0;
            for p in cli.polylines.iter().filter(|p| p.id == label) {
                assert_eq!(p.points.first(), p.points.last(), "closed polyline");
                let a = signed_area(&p.points) * file.units * file.units;
                assert_eq!(
                    p.dir,
                    if a > 0.0 { 1 } else { 0 },
                    "direction matches orientation"
                );
                got += a;
            }
            assert!(
                (got - want).abs() <= tolerance * want,
                "layer {} part {pi}: {got} vs {want}",
                json["index"]
            );
        }
    }
}

const ASSEMBLY: &str = "[model]\nuse = \"gear-shaft\"\nteeth = 12\nheight = 2.0\nshaft_length = 3.0\n\
    [materials.a]\ncolour = [200, 0, 0]\n[materials.b]\ncolour = [0, 0, 200]\n\
    [[parts]]\nname = \"gear\"\nmesh = 0\nmaterials = [\"a\"]\n\
    [[parts]]\nname = \"shaft, steel\"\nmesh = 1\nmaterials = [\"b\"]\n\
    [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
    [[output]]\nuse = \"json\"\npath = \"plan.json\"\n\
    [[output]]\nuse = \"cli\"\npath = \"ascii.cli\"\n\
    [[output]]\nuse = \"cli\"\npath = \"binary.cli\"\nformat = \"binary\"\n\
    [[output]]\nuse = \"cli\"\npath = \"mm.cli\"\nunits = 1.0\n";

#[test]
fn ascii_and_binary_cli_read_back_with_the_plans_areas() {
    let (dir, plan) = run(ASSEMBLY);
    let out = dir.path().join("out");
    let ascii = read_cli(&std::fs::read(out.join("ascii.cli")).expect("ascii"));
    assert!(!ascii.binary);
    assert_eq!(ascii.units, 0.001);
    check_against_plan(&ascii, &plan, 1e-9);
    let mm = read_cli(&std::fs::read(out.join("mm.cli")).expect("mm"));
    check_against_plan(&mm, &plan, 1e-9);
    let binary = read_cli(&std::fs::read(out.join("binary.cli")).expect("binary"));
    assert!(binary.binary);
    // 32-bit floats: about seven significant digits.
    check_against_plan(&binary, &plan, 1e-5);
}

/// A closed ring as the plan or the file gives it, in mm.
#[derive(Debug, Clone)]
struct Ring {
    area: f64,
    min: [f64; 2],
    max: [f64; 2],
}

impl Ring {
    fn new(points: &[[f64; 2]]) -> Self {
        let mut closed = points.to_vec();
        if closed.first() != closed.last() {
            closed.push(points[0]);
        }
        let mut min = [f64::INFINITY; 2];
        let mut max = [f64::NEG_INFINITY; 2];
        for p in points {
            for k in 0..2 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        Ring {
            area: signed_area(&closed).abs(),
            min,
            max,
        }
    }

    /// The same closed curve (the file rounds nothing: shortest decimal forms).
    fn same(&self, o: &Ring) -> bool {
        (self.area - o.area).abs() <= 1e-7 * self.area.max(o.area)
            && (0..2).all(|k| (self.min[k] - o.min[k]).abs() < 1e-6 && (self.max[k] - o.max[k]).abs() < 1e-6)
    }
}

fn points(v: &serde_json::Value) -> Vec<[f64; 2]> {
    v.as_array()
        .expect("points")
        .iter()
        .map(|p| [p[0].as_f64().expect("x"), p[1].as_f64().expect("y")])
        .collect()
}

/// Checks a modified CLI layer against the plan's layer, from Fig. 9's rules: every
/// boundary of every sub-region is in the file exactly once; the family's outer
/// contour is 1 and its holes 0; a contour between two sub-regions is the one at
/// which the deeper region j starts (id j + 1) and carries its material; any other
/// boundary of region j is j + 1 (its outer) or j + 2 (its holes, 0 for the last
/// region); and each family's contours run from the outside in (1, 2, ..., 0).
/// Returns the file's (id, area) per family.
fn check_modified_layer(
    cli: &CliLayer,
    units: f64,
    plan: &serde_json::Value,
    layer: &serde_json::Value,
) -> Vec<Vec<(i64, f64)>> {
    let lines: Vec<(Ring, &Polyline)> = cli
        .polylines
        .iter()
        .map(|p| {
            let pts: Vec<[f64; 2]> = p.points.iter().map(|q| [q[0] * units, q[1] * units]).collect();
            (Ring::new(&pts), p)
        })
        .collect();
    for (i, (a, _)) in lines.iter().enumerate() {
        for (b, _) in &lines[i + 1..] {
            assert!(!a.same(b), "a contour is written twice: {a:?}");
        }
    }
    let mut used = vec![false; lines.len()];
    let mut out = Vec::new();
    let mut at = 0;
    for part in layer["parts"].as_array().expect("parts") {
        // The part's materials, in the order the file gives the fractions.
        let names: Vec<&str> = plan["parts"]
            .as_array()
            .expect("parts")
            .iter()
            .find(|p| p["name"] == part["part"])
            .expect("the layer's part")["materials"]
            .as_array()
            .expect("materials")
            .iter()
            .map(|m| m.as_str().expect("name"))
            .collect();
        for family in part["families"].as_array().expect("families") {
            let outer = Ring::new(&points(&family["outer"]));
            let holes: Vec<Ring> = family["holes"]
                .as_array()
                .expect("holes")
                .iter()
                .map(|h| Ring::new(&points(h)))
                .collect();
            let regions = family["sub_regions"].as_array().expect("regions");
            // (ring, region index, count, is outer, fractions)
            let mut rings = Vec::new();
            for r in regions {
                let fractions: Vec<f64> = names
                    .iter()
                    .map(|n| r["composition"][n].as_f64().expect("graded"))
                    .collect();
                let (j, n) = (
                    r["index"].as_i64().expect("index"),
                    r["count"].as_i64().expect("count"),
                );
                rings.push((
                    Ring::new(&points(&r["polygon"]["outer"])),
                    j,
                    n,
                    true,
                    fractions.clone(),
                ));
                for h in r["polygon"]["holes"].as_array().expect("holes") {
                    rings.push((Ring::new(&points(h)), j, n, false, fractions.clone()));
                }
            }
            let mut ids = Vec::new();
            for (ring, j, n, is_outer, fractions) in &rings {
                let k = lines
                    .iter()
                    .position(|(l, _)| l.same(ring))
                    .expect("every sub-region boundary is in the file");
                used[k] = true;
                let (l, p) = &lines[k];
                // The deepest region bounded by this contour.
                let deepest = rings
                    .iter()
                    .filter(|o| o.0.same(ring))
                    .map(|o| o.1)
                    .max()
                    .expect("itself");
                let want = if ring.same(&outer) {
                    1
                } else if holes.iter().any(|h| h.same(ring)) {
                    0
                } else if deepest > *j {
                    continue; // written by the deeper region
                } else if *is_outer || rings.iter().filter(|o| o.0.same(ring)).count() > 1 {
                    j + 1
                } else if j + 1 >= *n {
                    0
                } else {
                    j + 2
                };
                assert_eq!(
                    p.id, want,
                    "contour of region {j} (outer: {is_outer}), area {}",
                    l.area
                );
                let m = p.material.as_ref().expect("material");
                let got = &m[3..];
                if deepest == *j {
                    assert_eq!(got.len(), fractions.len());
                    for (a, b) in got.iter().zip(fractions) {
                        assert!(
                            (a - b).abs() < 1e-9,
                            "material of the region that starts at contour {}",
                            p.id
                        );
                    }
                }
            }
            // The family's contours come together, from the outside in.
            let n = rings.len()
                - rings
                    .iter()
                    .enumerate()
                    .filter(|(i, o)| rings[..*i].iter().any(|e| e.0.same(&o.0)))
                    .count();
            let seq: Vec<(i64, f64)> = lines[at..at + n].iter().map(|(l, p)| (p.id, l.area)).collect();
            let order: Vec<i64> = seq
                .iter()
                .map(|s| if s.0 == 0 { i64::MAX } else { s.0 })
                .collect();
            assert!(
                order.windows(2).all(|w| w[0] <= w[1]),
                "ids from the outside in: {seq:?}"
            );
            at += n;
            ids.extend(seq);
            out.push(ids);
        }
    }
    assert!(
        used.iter().all(|u| *u),
        "every contour in the file bounds a sub-region"
    );
    assert_eq!(at, lines.len());
    out
}

fn modified(discretise: &str, model: &str) -> (CliFile, serde_json::Value, tempfile::TempDir) {
    let pipeline = format!(
        "[model]\n{model}\n\
        [materials.green]\ncolour = [0, 255, 0]\n[materials.black]\ncolour = [0, 0, 0]\n\
        [discretise]\n{discretise}\n\
        [grade]\nuse = \"xy\"\n\
        [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
        [[output]]\nuse = \"json\"\npath = \"plan.json\"\n\
        [[output]]\nuse = \"cli\"\npath = \"fgm.cli\"\nformat = \"modified\"\n"
    );
    let (dir, plan) = run(&pipeline);
    let file = read_cli(&std::fs::read(dir.path().join("out/fgm.cli")).expect("cli"));
    for (cli, layer) in file.layers.iter().zip(plan["layers"].as_array().expect("layers")) {
        check_modified_layer(cli, file.units, &plan, layer);
    }
    (file, plan, dir)
}

const TUBE: &str = "use = \"tube\"\nouter_radius = 10.0\ninner_radius = 5.0\nheight = 1.0";

/// Fig. 5 and 9: ten rings from the outer contour C_3 to the bore C_2: the contours 1,
/// 2, ..., 10 and 0, each once, with the green-to-black colours of Eq. 20-21.
#[test]
fn modified_cli_carries_contour_ids_colours_and_fractions() {
    let (file, plan, _dir) = modified("use = \"offset\"\ncount = 10", TUBE);
    assert_eq!(file.layers.len(), 2);
    let regions = plan["layers"][0]["parts"][0]["families"][0]["sub_regions"]
        .as_array()
        .expect("regions");
    assert!(regions.iter().all(|r| r["count"] == 10));
    let layer = &file.layers[0];
    let got: Vec<(i64, i64, f64)> = layer
        .polylines
        .iter()
        .map(|p| (p.id, p.dir, p.material.as_ref().expect("material")[1]))
        .collect();
    assert_eq!(
        got,
        [
            (1, 1, 255.0),
            (2, 1, 227.0),
            (3, 1, 198.0),
            (4, 1, 170.0),
            (5, 1, 142.0),
            (6, 1, 113.0),
            (7, 1, 85.0),
            (8, 1, 57.0),
            (9, 1, 28.0),
            (10, 1, 0.0),
            (0, 0, 0.0),
        ],
        "ids and the green-to-black colours of Eq. 20-21"
    );
    for p in &layer.polylines {
        let m = p.material.as_ref().expect("every polyline has its material");
        assert_eq!(m.len(), 5);
        assert!((m[3] + m[4] - 1.0).abs() < 1e-9);
    }
    // Ring j lies between contour j + 1 and the next one: the areas read back.
    let areas: Vec<f64> = layer
        .polylines
        .iter()
        .map(|p| signed_area(&p.points).abs() * file.units.powi(2))
        .collect();
    for (j, r) in regions.iter().enumerate() {
        let want = r["area"].as_f64().expect("area");
        let got = areas[j] - areas[j + 1];
        assert!((got - want).abs() < 1e-6 * want, "ring {j}: {got} vs {want}");
    }
}

/// From every boundary, the rings about the bore are contours of their own: 1 and 0 for
/// the rim and the bore, then each offset contour id twice (once on each side).
#[test]
fn modified_cli_from_every_boundary() {
    let (file, _plan, _dir) = modified("use = \"offset\"\ncount = 4\nfrom = \"all\"", TUBE);
    let mut ids: Vec<i64> = file.layers[0].polylines.iter().map(|p| p.id).collect();
    assert_eq!(ids, [1, 2, 2, 3, 3, 4, 4, 0]);
    ids.dedup();
    // Contour k lies (k - 1) spacings in from the rim or out from the bore (0.625 mm).
    for p in &file.layers[0].polylines {
        let r = (signed_area(&p.points).abs() * file.units.powi(2) / std::f64::consts::PI).sqrt();
        let k = if p.id == 0 { 1.0 } else { p.id as f64 };
        let (rim, bore) = (10.0 - (k - 1.0) * 0.625, 5.0 + (k - 1.0) * 0.625);
        let near = if p.id == 0 {
            (r - 5.0).abs()
        } else {
            (r - rim).abs().min((r - bore).abs())
        };
        assert!(near < 0.01, "contour {} at radius {r}", p.id);
    }
}

/// Circumferential cells (Fig. 13) and islands: every boundary once, ids from the rings
/// they lie in.
#[test]
fn modified_cli_with_cells_and_islands() {
    let (file, _plan, _dir) = modified("use = \"offset\"\ncount = 3\ncells_around = 4", TUBE);
    // Four cells per ring, each an outline of its own opening its ring.
    let ids: Vec<i64> = file.layers[0].polylines.iter().map(|p| p.id).collect();
    assert_eq!(ids, [1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3]);
    // The blade with two cavities: the rings split into islands between the cavities.
    let (file, plan, _dir) = modified(
        "use = \"offset\"\ncount = 8\nspacing = 0.5",
        "use = \"blade\"\ncavities = 2\nspan = 1.5\nroot_height = 0.5",
    );
    let last = plan["layers"].as_array().expect("layers").len() - 1;
    let regions = plan["layers"][last]["parts"][0]["families"][0]["sub_regions"]
        .as_array()
        .expect("regions");
    let islands = (0..8)
        .filter(|&j| regions.iter().filter(|r| r["index"] == j).count() > 1)
        .count();
    assert!(islands > 0, "some rings are islands");
    // The islands' own outlines open their rings (checked above); the rim is 1.
    assert_eq!(file.layers[last].polylines[0].id, 1);
    assert!(file.layers[last].polylines.iter().any(|p| p.id >= 3));
}

#[test]
fn an_output_path_leaving_the_output_folder_is_refused() {
    // A path that leaves the output folder is refused before anything is written.
    let dir = tempfile::tempdir().expect("tempdir");
    let out = try_run_text(
        dir.path(),
        "[model]\nuse = \"tube\"\nheight = 1.0\n[materials.a]\ncolour = [1, 2, 3]\n\
         [[output]]\nuse = \"cli\"\npath = \"../escape.cli\"\n",
    );
    assert!(!out.status.success());
    assert!(!dir.path().join("escape.cli").exists());
    assert!(!Path::new(&dir.path().join("out")).join("escape.cli").exists());
}
