//! CLI layer files read back by an independent reader written here from the format's
//! description (CLI 2.0: an ASCII header between $$HEADERSTART and $$HEADEREND, then
//! ASCII commands or binary commands: a little-endian u16 command index followed by
//! its parameters). The contours it reads must give the plan's areas.

use std::path::Path;
use std::process::Command;

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
            129 => {
                let (id, dir, n) = (u16_(&mut b), u16_(&mut b), u16_(&mut b));
                let points = (0..n)
                    .map(|_| [f64::from(u16_(&mut b)), f64::from(u16_(&mut b))])
                    .collect();
                file.layers.last_mut().expect("layer").polylines.push(Polyline {
                    id: id.into(),
                    dir: dir.into(),
                    points,
                    material: None,
                });
            }
            130 => {
                let (id, dir, n) = (i32_(&mut b), i32_(&mut b), i32_(&mut b));
                let points = (0..n)
                    .map(|_| [f64::from(f32_(&mut b)), f64::from(f32_(&mut b))])
                    .collect();
                file.layers.last_mut().expect("layer").polylines.push(Polyline {
                    id: id.into(),
                    dir: dir.into(),
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
    let path = dir.path().join("p.toml");
    std::fs::write(&path, pipeline).expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(["run", "--quiet", "--out"])
        .arg(dir.path().join("out"))
        .arg(&path)
        .output()
        .expect("lamina runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let plan = std::fs::read_to_string(dir.path().join("out/plan.json")).expect("json");
    let plan = serde_json::from_str(&plan).expect("valid json");
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

#[test]
fn modified_cli_carries_contour_ids_colours_and_fractions() {
    let pipeline = "[model]\nuse = \"tube\"\nouter_radius = 10.0\ninner_radius = 5.0\nheight = 1.0\n\
        [materials.green]\ncolour = [0, 255, 0]\n[materials.black]\ncolour = [0, 0, 0]\n\
        [discretise]\nuse = \"offset\"\ncount = 10\nfrom = \"outer\"\n\
        [grade]\nuse = \"xy\"\n\
        [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
        [[output]]\nuse = \"json\"\npath = \"plan.json\"\n\
        [[output]]\nuse = \"cli\"\npath = \"fgm.cli\"\nformat = \"modified\"\n";
    let (dir, plan) = run(pipeline);
    let file = read_cli(&std::fs::read(dir.path().join("out/fgm.cli")).expect("cli"));
    assert_eq!(file.layers.len(), 2);
    let regions = plan["layers"][0]["parts"][0]["families"][0]["regions"]
        .as_array()
        .expect("regions");
    assert!(regions.iter().all(|r| r["count"] == 10));
    let layer = &file.layers[0];
    // Outer boundaries (counter-clockwise) in order, each with its region's colour:
    // 1 for the family's outer contour, then the offsets 2..N from the outside in (a
    // region in several pieces repeats its id).
    let mut outer: Vec<(i64, f64)> = layer
        .polylines
        .iter()
        .filter(|p| p.dir == 1)
        .map(|p| (p.id, p.material.as_ref().expect("material")[1]))
        .collect();
    outer.dedup();
    assert_eq!(
        outer,
        [
            (1, 255.0),
            (2, 227.0),
            (3, 198.0),
            (4, 170.0),
            (5, 142.0),
            (6, 113.0),
            (7, 85.0),
            (8, 57.0),
            (9, 28.0),
            (10, 0.0)
        ],
        "ids and the green-to-black colours of Eq. 20-21"
    );
    // The innermost contour (the bore) is 0.
    let last_hole = layer.polylines.iter().rev().find(|p| p.dir == 0).expect("holes");
    assert_eq!(last_hole.id, 0);
    for p in &layer.polylines {
        let m = p.material.as_ref().expect("every polyline has its material");
        assert_eq!(m.len(), 5);
        assert!((m[3] + m[4] - 1.0).abs() < 1e-9);
    }
    // The regions tile the ring: their signed areas add up to the family's.
    let total: f64 = layer
        .polylines
        .iter()
        .map(|p| signed_area(&p.points))
        .sum::<f64>()
        * file.units.powi(2);
    let family = plan["layers"][0]["parts"][0]["families"][0]["area"]
        .as_f64()
        .expect("area");
    assert!((total - family).abs() < 1e-3 * family, "{total} vs {family}");
}

#[test]
fn an_output_path_leaving_the_output_folder_is_refused() {
    // A path that leaves the output folder is refused before anything is written.
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("p.toml");
    std::fs::write(
        &path,
        "[model]\nuse = \"tube\"\nheight = 1.0\n[materials.a]\ncolour = [1, 2, 3]\n\
         [[output]]\nuse = \"cli\"\npath = \"../escape.cli\"\n",
    )
    .expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(["run", "--quiet", "--out"])
        .arg(dir.path().join("out"))
        .arg(&path)
        .output()
        .expect("lamina runs");
    assert!(!out.status.success());
    assert!(!dir.path().join("escape.cli").exists());
    assert!(!Path::new(&dir.path().join("out")).join("escape.cli").exists());
}
