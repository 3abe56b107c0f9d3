//! The previews end to end: an SVG per layer with the regions' colours, and the HTML
//! viewer driven in headless Chromium (moving the slider, reading back the shown layer
//! and a region's composition, taking a screenshot). The Chromium test is skipped with
//! a printed reason when no Chromium is installed.

use crate::support::{lamina, model, pipelines, run_text, skip, text, try_run_text};
use std::path::{Path, PathBuf};
use std::process::Command;

const PIPELINE: &str = "name = \"viewer-test\"\n[model]\nuse = \"tube\"\nouter_radius = 10.0\ninner_radius = 5.0\nheight = 2.0\n\
    [materials.green]\ncolour = [0, 255, 0]\n[materials.black]\ncolour = [0, 0, 0]\n\
    [discretise]\nuse = \"offset\"\ncount = 4\nfrom = \"outer\"\n[grade]\nuse = \"xy\"\n\
    [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
    [[output]]\nuse = \"json\"\npath = \"plan.json\"\n\
    [[output]]\nuse = \"html\"\npath = \"viewer.html\"\n\
    [[output]]\nuse = \"svg\"\npath = \"svg/layer\"\n";

fn run(dir: &Path) -> serde_json::Value {
    run_text(dir, PIPELINE, "plan.json")
}

fn regions(layer: &serde_json::Value) -> &Vec<serde_json::Value> {
    layer["parts"][0]["families"][0]["sub_regions"]
        .as_array()
        .expect("regions")
}

#[test]
fn every_layer_gets_an_svg_in_its_regions_colours() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run(dir.path());
    for layer in plan["layers"].as_array().expect("layers") {
        let i = layer["index"].as_u64().expect("index");
        let svg = std::fs::read_to_string(dir.path().join(format!("out/svg/layer-{i}.svg"))).expect("svg");
        assert!(svg.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\""));
        assert!(svg.trim_end().ends_with("</svg>"));
        for r in regions(layer) {
            let c = &r["colour"];
            let hex = format!(
                "fill=\"#{:02x}{:02x}{:02x}\"",
                c[0].as_u64().expect("r"),
                c[1].as_u64().expect("g"),
                c[2].as_u64().expect("b")
            );
            assert!(svg.contains(&hex), "layer {i}: {hex} missing");
        }
    }
}

fn chromium() -> Option<PathBuf> {
    for name in ["chromium", "chromium-browser", "google-chrome"] {
        if let Ok(out) = Command::new("which").arg(name).output()
            && out.status.success()
        {
            return Some(PathBuf::from(String::from_utf8_lossy(&out.stdout).trim()));
        }
    }
    None
}

/// Chromium, or a printed note (a failure under `LAMINA_REQUIRE`) when there is none.
fn browser() -> Option<PathBuf> {
    let found = chromium();
    if found.is_none() {
        skip("no Chromium is installed (Debian: apt-get install chromium)");
    }
    found
}

fn headless(browser: &Path, profile: &Path) -> Command {
    let mut c = Command::new(browser);
    c.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--window-size=900,700",
        // WebGL on the software rasteriser when there is no GPU (the 3D view).
        "--enable-unsafe-swiftshader",
    ])
    .arg(format!("--user-data-dir={}", profile.display()));
    c
}

/// Opens `url` in headless Chromium and reads what the viewer's test hook reports.
fn page_report(browser: &Path, profile: &Path, url: &str) -> serde_json::Value {
    let out = headless(browser, profile)
        .arg("--dump-dom")
        .arg(url)
        .output()
        .expect("chromium runs");
    let dom = String::from_utf8_lossy(&out.stdout);
    let start = dom
        .find("<pre id=\"test-result\">")
        .expect("the page reports what it shows")
        + 22;
    let end = start + dom[start..].find("</pre>").expect("end of the report");
    serde_json::from_str(&dom[start..end].replace("&quot;", "\"").replace("&amp;", "&")).expect("json")
}

#[test]
fn the_viewer_shows_the_chosen_layer_and_a_regions_composition_in_chromium() {
    let Some(browser) = browser() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run(dir.path());
    let page = dir.path().join("out/viewer.html");
    let html = std::fs::read_to_string(&page).expect("viewer written");
    assert!(
        !html.contains("http://") && !html.contains("https://"),
        "the page fetches nothing"
    );
    // Layer 2, the third region from the outside: its reference point and composition.
    let layer = &plan["layers"][2];
    let region = &regions(layer)[2];
    let at = region["reference"].as_array().expect("reference");
    let (x, y) = (at[0].as_f64().expect("x"), at[1].as_f64().expect("y"));
    let composition = region["composition"].as_object().expect("composition");
    let url = format!("file://{}#test:layer=2;at={x},{y}", page.display());
    let shown = page_report(&browser, &dir.path().join("profile-dom"), &url);
    assert_eq!(shown["layer"], 2, "{shown}");
    assert_eq!(shown["layers"], plan["layers"].as_array().expect("layers").len());
    assert!(
        shown["label"]
            .as_str()
            .expect("label")
            .starts_with("layer 2 of 4, z = 1.5 mm"),
        "{shown}"
    );
    let text = shown["region"]["composition"]
        .as_str()
        .expect("a region under the point");
    for (name, f) in composition {
        let want = format!("{name} {}", (f.as_f64().expect("fraction") * 1e4).round() / 1e4);
        assert!(text.contains(&want), "{text} lacks {want}");
    }
    assert_eq!(shown["region"]["index"], region["index"]);

    let shot = dir.path().join("shot.png");
    let status = headless(&browser, &dir.path().join("profile-shot"))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(format!("file://{}#test:layer=1", page.display()))
        .output()
        .expect("chromium runs");
    assert!(status.status.success() || shot.exists());
    let png = std::fs::read(&shot).expect("screenshot");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    assert!(
        png.len() > 10_000,
        "a drawn layer, not a blank page ({} bytes)",
        png.len()
    );
}

/// Runs of at least `min` equal pixels along the middle row, from the centre rightward.
fn colour_runs(png: &[u8], min: usize) -> Vec<[u8; 3]> {
    let pixmap = tiny_skia::Pixmap::decode_png(png).expect("a PNG");
    let (w, h) = (pixmap.width() as usize, pixmap.height() as usize);
    let row = h / 2;
    let mut runs: Vec<([u8; 3], usize)> = Vec::new();
    for x in w / 2..w {
        let p = pixmap.pixel(x as u32, row as u32).expect("pixel");
        let c = [p.red(), p.green(), p.blue()];
        match runs.last_mut() {
            Some((last, n)) if *last == c => *n += 1,
            _ => runs.push((c, 1)),
        }
    }
    let mut out: Vec<[u8; 3]> = runs
        .into_iter()
        .filter(|&(_, n)| n >= min)
        .map(|(c, _)| c)
        .collect();
    out.dedup();
    out
}

#[test]
fn pngs_show_the_regions_from_the_bore_outward() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = PIPELINE.to_string()
        + "[[output]]\nuse = \"png\"\nsize = 400\n\
           [[output]]\nuse = \"contact-sheet\"\ncount = 4\ncolumns = 2\ntile = 128\n\
           [[output]]\nuse = \"stack\"\nsize = 300\n";
    let plan = run_text(dir.path(), &text, "plan.json");
    for layer in plan["layers"].as_array().expect("layers") {
        let i = layer["index"].as_u64().expect("index");
        let png = std::fs::read(dir.path().join(format!("out/png/layer-{i}.png"))).expect("png");
        // From the centre: the white bore, the regions from the innermost out, white.
        let mut want = vec![[255, 255, 255]];
        for r in regions(layer).iter().rev() {
            let c = &r["colour"];
            want.push([0, 1, 2].map(|k| c[k].as_u64().expect("channel") as u8));
        }
        want.push([255, 255, 255]);
        assert_eq!(colour_runs(&png, 5), want, "layer {i}");
    }
    for name in ["contact-sheet.png", "stack.png"] {
        let png = std::fs::read(dir.path().join("out").join(name)).expect(name);
        let pixmap = tiny_skia::Pixmap::decode_png(&png).expect("a PNG");
        let coloured = pixmap
            .pixels()
            .iter()
            .filter(|p| p.green() > 100 && p.red() < 50)
            .count();
        assert!(
            coloured > 100,
            "{name}: the green regions are drawn ({coloured} pixels)"
        );
    }
    let sheet = tiny_skia::Pixmap::decode_png(
        &std::fs::read(dir.path().join("out/contact-sheet.png")).expect("sheet"),
    )
    .expect("png");
    assert_eq!((sheet.width(), sheet.height()), (256, 256), "2 x 2 tiles of 128");
}

/// The contact sheet of the gear on its shaft: every tile at the scale of the whole
/// model (the shaft's tiles show a small disc, not one blown up to the tile), each
/// captioned with its layer and z under the picture.
#[test]
fn contact_sheet_tiles_share_one_scale_and_carry_captions() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(pipelines().join("gear-z-gradient.toml")).expect("example")
        + "[[output]]\nuse = \"json\"\npath = \"sheet-plan.json\"\n\
           [[output]]\nuse = \"contact-sheet\"\npath = \"sheet.png\"\ncount = 4\ncolumns = 4\ntile = 128\n";
    let plan = run_text(dir.path(), &text, "sheet-plan.json");
    let layers = plan["layers"].as_array().expect("layers");
    let n = layers.len();
    let chosen: Vec<usize> = (0..4).map(|i| i * (n - 1) / 3).collect();
    let sheet =
        tiny_skia::Pixmap::decode_png(&std::fs::read(dir.path().join("out/sheet.png")).expect("sheet"))
            .expect("png");
    let t = 128u32;
    let caption = 10u32;
    // Drawn pixels over the layer's area: the same for every tile at one scale.
    let mut per_mm2 = Vec::new();
    for (slot, &l) in chosen.iter().enumerate() {
        let x0 = slot as u32 * t;
        let drawn = (2..t - caption - 2)
            .flat_map(|y| (x0 + 2..x0 + t - 2).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let p = sheet.pixel(x, y).expect("pixel");
                (p.red(), p.green(), p.blue()) != (255, 255, 255)
            })
            .count() as f64;
        let area: f64 = layers[l]["parts"]
            .as_array()
            .expect("parts")
            .iter()
            .flat_map(|p| p["families"].as_array().expect("families"))
            .flat_map(|f| f["sub_regions"].as_array().expect("regions"))
            .map(|r| r["area"].as_f64().expect("area"))
            .sum();
        per_mm2.push(drawn / area);
        // The caption strip carries ink (black text on white).
        let ink = (t - caption..t)
            .flat_map(|y| (x0..x0 + t).map(move |x| (x, y)))
            .filter(|&(x, y)| sheet.pixel(x, y).expect("pixel").red() < 80)
            .count();
        assert!(ink > 20, "tile {slot} (layer {l}) has no caption");
    }
    let (lo, hi) = per_mm2
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(
        hi / lo < 1.25,
        "tiles at different scales: pixels per mm² {per_mm2:?}"
    );
}

/// The viewer of a real plan stays small and opens fast: 3DBenchy graded in ten rings
/// per solid area with both tools' paths (39 MB as JSON numbers before the geometry
/// was packed) at most 8 MB, the buildings mesh at most 25 MB, and each interactive in
/// headless Chromium within 1.5 s of navigation (the layer drawn, the page answering).
#[test]
#[ignore = "needs ../shared/models; run by .ci/run"]
fn viewers_of_real_plans_stay_small_and_open_fast() {
    let (Some(benchy), Some(buildings)) = (model("3DBenchy.stl"), model("openfoam_buildings_400k.stl"))
    else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("benchy");
    let o = lamina(&[
        "view",
        "--no-open",
        "--out",
        out.to_str().expect("utf-8"),
        "--model",
        benchy.to_str().expect("utf-8"),
        pipelines().join("benchy-two-tools.toml").to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let benchy_page = out.join("benchy-two-tools.html");
    let city = dir.path().join("city");
    std::fs::create_dir_all(&city).expect("dir");
    let pipeline = format!(
        "name = \"buildings\"\n[model]\nuse = \"stl\"\nfile = {:?}\n\
         [materials.a]\ncolour = [200, 60, 40]\n[materials.b]\ncolour = [40, 60, 200]\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.2\n\
         [discretise]\nuse = \"offset\"\ncount = 10\nfrom = \"all\"\n\
         [grade]\nuse = \"xy\"\n\
         [[output]]\nuse = \"html\"\npath = \"viewer.html\"\n",
        buildings.display()
    );
    let o = try_run_text(&city, &pipeline);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let city_page = city.join("out/viewer.html");
    let browser = browser();
    // Benchy's pipeline writes G-code: its page carries the machine's moves too.
    for (page, limit, moves) in [(benchy_page, 8e6, true), (city_page, 25e6, false)] {
        let bytes = std::fs::metadata(&page).expect("viewer written").len() as f64;
        println!("{}: {:.2} MB", page.display(), bytes / 1e6);
        assert!(bytes <= limit, "{}: {bytes} bytes", page.display());
        let Some(browser) = &browser else { continue };
        let profile = tempfile::tempdir().expect("profile");
        let url = format!("file://{}#test:layer=40;walk=1", page.display());
        let shown = page_report(browser, profile.path(), &url);
        let ready = shown["ready_ms"].as_f64().expect("ready_ms");
        let walk = shown["walk_ms_per_layer"].as_f64().expect("walk");
        println!("  interactive after {ready:.0} ms; {walk:.1} ms to decode and draw a layer");
        assert_eq!(shown["layer"], 40, "{shown}");
        assert_eq!(shown["moves"].is_object(), moves, "{}", page.display());
        assert!(
            ready <= 1500.0,
            "{}: interactive after {ready} ms",
            page.display()
        );
        let profile = tempfile::tempdir().expect("profile");
        let url = format!("file://{}#test:layer=120;view=3d", page.display());
        let shown = page_report(browser, profile.path(), &url);
        let stats = &shown["view3d"]["stats"];
        println!("  3D view: {stats}");
        assert!(
            stats["wall_triangles"].as_f64().expect("triangles") > 1000.0,
            "{shown}"
        );
    }
}

/// The machine's moves in the viewer, read back from the G-code of a machine with two
/// motion systems (RepRapFirmware 3.5): per tool, the extruded length the page draws
/// for a layer matches the plan's beads of that tool, both heads are shown, and they
/// move at the same time for a large part of the layer (45 % of its 66 s in today's
/// plan; one tool at a time would be none).
#[test]
fn the_viewer_plays_both_motion_systems_of_the_written_gcode() {
    let Some(browser) = browser() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(pipelines().join("assembly-two-tools.toml"))
        .expect("example")
        .replace("machine = \"rrf-idex-2\"", "machine = \"rrf-two-systems-2\"")
        .replace("height = 5.0", "height = 1.5")
        .replace("shaft_length = 9.0", "shaft_length = 3.0")
        + "[[output]]\nuse = \"gcode\"\npath = \"two.gcode\"\n\
           [[output]]\nuse = \"html\"\npath = \"viewer.html\"\n";
    let plan = run_text(dir.path(), &text, "assembly-two-tools.json");
    let page = dir.path().join("out/viewer.html");
    let layer = 2;
    let url = format!("file://{}#test:layer={layer};t=0.5", page.display());
    let shown = page_report(&browser, &dir.path().join("profile"), &url);
    let moves = &shown["moves"];
    assert_eq!(moves["systems"], 2, "{shown}");
    let heads = moves["heads"].as_array().expect("heads");
    assert_eq!(heads.len(), 2, "{shown}");
    assert_eq!(
        (heads[0]["tool"].as_u64(), heads[1]["tool"].as_u64()),
        (Some(0), Some(1))
    );
    let together = moves["together"].as_f64().expect("together");
    assert!(
        together > 0.4,
        "both heads move at once only {together} of the layer"
    );
    // The plan's bead length per tool on that layer.
    let mut planned = [0.0f64; 2];
    for t in plan["layers"][layer]["toolpaths"].as_array().expect("toolpaths") {
        if t["kind"] != "extrude" {
            continue;
        }
        let pts = t["points"].as_array().expect("points");
        let len: f64 = pts
            .windows(2)
            .map(|w| {
                let a = &w[0]["p"];
                let b = &w[1]["p"];
                (a[0].as_f64().expect("x") - b[0].as_f64().expect("x"))
                    .hypot(a[1].as_f64().expect("y") - b[1].as_f64().expect("y"))
            })
            .sum();
        planned[t["tool"].as_u64().expect("tool") as usize] += len;
    }
    for (tool, want) in planned.iter().enumerate() {
        let drawn = moves["extruded_mm"][tool.to_string()].as_f64().expect("extruded");
        println!("tool {tool}: {drawn:.1} mm drawn, {want:.1} mm planned; together {together}");
        assert!(
            (drawn - want).abs() <= 0.02 * want,
            "tool {tool}: the page draws {drawn:.1} mm of beads, the plan has {want:.1}"
        );
    }
    // Half way through the layer the clock says so.
    let clock = moves["clock"].as_str().expect("clock");
    let duration = moves["duration_s"].as_f64().expect("duration");
    assert!(
        clock.starts_with(&format!("t = {:.1} of", duration / 2.0)),
        "{clock}"
    );
}

/// The 3D view in headless Chromium (WebGL): seen from the top with layer 2 as the
/// highest shown, each region's reference point shows that region's colour on the top
/// face; with the cut plane half-way across X, a point beyond it shows the background
/// and its mirror point still the outer region.
#[test]
fn the_3d_view_shows_each_regions_colour_where_it_lies_and_cuts_across_x() {
    let Some(browser) = browser() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run(dir.path());
    let page = dir.path().join("out/viewer.html");
    let close = |got: &serde_json::Value, want: [u64; 3]| {
        (0..3).all(|k| got[k].as_u64().expect("channel").abs_diff(want[k]) <= 8)
    };
    let layer = &plan["layers"][2];
    for (k, region) in regions(layer).iter().enumerate() {
        let at = region["reference"].as_array().expect("reference");
        let (x, y) = (at[0].as_f64().expect("x"), at[1].as_f64().expect("y"));
        let url = format!(
            "file://{}#test:layer=2;view=3d;camera=top;probe={x},{y}",
            page.display()
        );
        let shown = page_report(&browser, &dir.path().join(format!("profile-{k}")), &url);
        let v = &shown["view3d"];
        assert!(v["error"].is_null(), "{shown}");
        let want = [0, 1, 2].map(|c| region["colour"][c].as_u64().expect("channel"));
        assert!(
            close(&v["probe"]["rgb"], want),
            "region {k} at ({x:.2}, {y:.2}): drew {} at pixel {}, the region is {want:?}",
            v["probe"]["rgb"],
            v["probe"]["px"]
        );
    }
    let outer = &regions(layer)[0];
    let want = [0, 1, 2].map(|c| outer["colour"][c].as_u64().expect("channel"));
    let url = format!(
        "file://{}#test:layer=2;view=3d;camera=top;cut=0.5;probe=9.5,0;probe2=-9.5,0",
        page.display()
    );
    let shown = page_report(&browser, &dir.path().join("profile-cut"), &url);
    let v = &shown["view3d"];
    // The page's background, #f4f4f2.
    assert!(
        close(&v["probe"]["rgb"], [244, 244, 242]),
        "beyond the cut: {shown}"
    );
    assert!(close(&v["probe2"]["rgb"], want), "before the cut: {shown}");
}

#[test]
fn the_viewer_lists_each_layers_process_operations_and_draws_the_chosen_ones_paths() {
    let Some(browser) = browser() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = crate::support::run_plan(
        &pipelines().join("pipe-work-cycles.toml"),
        &dir.path().join("out"),
        &[],
        "pipe-work-cycles.json",
    );
    // Layer 3: the microstructure at 0.6 mm, milled along the FGM standing at 0.5 mm.
    let layer = &plan["layers"][3];
    let ops = layer["operations"].as_array().expect("operations");
    let labels: Vec<String> = ops
        .iter()
        .map(|o| match o["pass"].as_str() {
            Some(p) => format!("{}/{p}", o["kind"].as_str().expect("kind")),
            None => o["kind"].as_str().expect("kind").to_string(),
        })
        .collect();
    assert_eq!(
        labels,
        [
            "end-mill",
            "spray",
            "grind/rough",
            "engrave",
            "fill",
            "grind/finish"
        ]
    );
    let page = dir.path().join("out/pipe-work-cycles.html");
    for (op, want) in [
        ("0".to_string(), ops[0]["paths"].as_array().expect("paths").len()),
        (
            "all".into(),
            ops.iter()
                .map(|o| o["paths"].as_array().map_or(0, Vec::len))
                .sum(),
        ),
    ] {
        let url = format!("file://{}#test:layer=3;op={op}", page.display());
        let shown = page_report(&browser, &dir.path().join(format!("profile-{op}")), &url);
        assert_eq!(shown["operations"], serde_json::json!(labels), "{shown}");
        assert_eq!(shown["op_paths_drawn"], want, "{shown}");
        let list = shown["op_list"].as_array().expect("list");
        assert_eq!(list.len(), 6);
        assert!(
            list[0]
                .as_str()
                .expect("text")
                .starts_with("end-mill: end-mill (0.8 mm)"),
            "{shown}"
        );
    }
}

/// The lines of a viewer page that start with `prefix`.
fn lines_starting<'a>(page: &'a str, prefix: &str) -> Vec<&'a str> {
    page.lines().filter(|l| l.starts_with(prefix)).collect()
}

/// A viewer larger than its page size is split into pages of consecutive layers, each
/// within the size, that together hold every layer and every machine move of the
/// whole viewer, byte for byte, link to their neighbours, and are told of in the
/// summary; in Chromium a later page shows its own first layer and its links.
#[test]
fn a_viewer_larger_than_its_page_size_is_split_into_linked_pages_holding_it_all() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = pipelines().join("gear-mixing-gcode.toml");
    let pipeline = pipeline.to_str().expect("utf-8");
    let whole = dir.path().join("whole");
    let split = dir.path().join("split");
    let o = lamina(&[
        "run",
        "--quiet",
        "--out",
        whole.to_str().expect("utf-8"),
        pipeline,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let o = lamina(&[
        "run",
        "--out",
        split.to_str().expect("utf-8"),
        "--set",
        "output.1.page_mb=0.5",
        pipeline,
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let said = format!("{}{}", text(&o.stderr), text(&o.stdout));
    let one = std::fs::read_to_string(whole.join("gear-mixing.html")).expect("whole viewer");
    assert!(one.len() > 1_000_000, "the whole viewer is {} bytes", one.len());
    let mut pages = vec![std::fs::read_to_string(split.join("gear-mixing.html")).expect("page 1")];
    while let Ok(page) = std::fs::read_to_string(split.join(format!("gear-mixing-{}.html", pages.len() + 1)))
    {
        pages.push(page);
    }
    let count = pages.len();
    assert!(count >= 3, "{count} pages");
    assert!(
        said.contains(&format!(
            "note[export.pages-split]: gear-mixing.html: the viewer is split into {count} pages of at most 0.5 MB"
        )),
        "{said}"
    );
    let mut layers = Vec::new();
    let mut moves = Vec::new();
    for (k, page) in pages.iter().enumerate() {
        assert!(page.len() <= 500_000, "page {} is {} bytes", k + 1, page.len());
        assert!(page.ends_with("</html>\n"), "page {} is not whole", k + 1);
        let own = lines_starting(page, "<script>LAYERS.push(");
        assert!(!own.is_empty(), "page {} holds no layer", k + 1);
        layers.extend(own);
        moves.extend(lines_starting(page, "<script>MOVES.set("));
        let about = lines_starting(page, "<script>PAGES = ");
        assert_eq!(about.len(), 1, "page {}", k + 1);
        let json = about[0]
            .strip_prefix("<script>PAGES = ")
            .and_then(|l| l.strip_suffix(";</script>"))
            .expect("PAGES line");
        let about: serde_json::Value = serde_json::from_str(json).expect("PAGES json");
        let name = |j: usize| {
            if j == 0 {
                "gear-mixing.html".to_string()
            } else {
                format!("gear-mixing-{}.html", j + 1)
            }
        };
        assert_eq!(about["index"], k, "{about}");
        assert_eq!(about["count"], count, "{about}");
        assert_eq!(
            about["prev"],
            serde_json::json!(k.checked_sub(1).map(name)),
            "{about}"
        );
        assert_eq!(
            about["next"],
            serde_json::json!((k + 1 < count).then(|| name(k + 1))),
            "{about}"
        );
        assert_eq!(about["moves_left_out"], 0, "{about}");
    }
    assert_eq!(layers, lines_starting(&one, "<script>LAYERS.push("));
    assert_eq!(moves, lines_starting(&one, "<script>MOVES.set("));
    let Some(browser) = browser() else { return };
    let page = split.join("gear-mixing-2.html");
    let url = format!("file://{}#test:layer=0", page.display());
    let shown = page_report(&browser, &dir.path().join("profile"), &url);
    let first = shown["pages"]["first"].as_u64().expect("first");
    assert!(first > 0, "{shown}");
    assert!(
        shown["label"]
            .as_str()
            .expect("label")
            .starts_with(&format!("layer {first} of ")),
        "{shown}"
    );
    assert!(shown["moves"].is_object(), "{shown}");
}
