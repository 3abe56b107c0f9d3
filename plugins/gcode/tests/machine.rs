//! The G-code written for the shipped machine profiles, read back line by line with a
//! reader written here from the firmwares' documented behaviour (not from the
//! exporter): tools are selected and heated before they move filament, idle tools wait
//! at standby, every move stays on the bed, the parts land where the placement says,
//! purges go to the tower, names cannot inject commands, and the footer's time is that
//! of the moves.

use std::collections::BTreeMap;

mod support;

use fastrand::Rng;
use support::{export, layer_plan, run_info};

use lamina_core::machine::{BedPlacement, Machine};
use lamina_core::{BBox2, Composition, LayerPlan, PathKind, Point2, Registry, RunInfo, TimedPoint, Toolpath};

fn machine(name: &str) -> Machine {
    lamina_core::machine::load::builtin(name).expect("built-in profile")
}

const PROFILES: [&str; 3] = ["marlin-mixing-2in1", "marlin-toolchanger-2", "rrf-idex-2"];

/// Half the side of the square the synthetic parts fill, centred on the origin.
const HALF: f64 = 20.0;

fn info(machine: Option<Machine>, names: [&str; 2]) -> RunInfo {
    run_info(
        names,
        names[0].to_string() + " part",
        BBox2::from_points([Point2::new(-HALF, -HALF), Point2::new(HALF, HALF)]),
        machine,
    )
}

/// Five layers of graded paths inside the square, each path's tool the material it is
/// mostly made of.
fn layers(seed: u64) -> Vec<LayerPlan> {
    let mut rng = Rng::with_seed(seed);
    (0..5)
        .map(|index| {
            let mut t = 0.0;
            let toolpaths = (0..8)
                .map(|k| {
                    let f = ((k * 3 + index) % 5) as f64 / 4.0;
                    let points = (0..2 + (rng.f64() * 5.0) as usize)
                        .map(|_| {
                            t += 0.4;
                            TimedPoint {
                                p: Point2::new(
                                    (rng.f64() * 2.0 - 1.0) * HALF,
                                    (rng.f64() * 2.0 - 1.0) * HALF,
                                ),
                                t,
                            }
                        })
                        .collect();
                    Toolpath {
                        tool: usize::from(f < 0.5),
                        material: None,
                        kind: PathKind::Extrude,
                        points,
                        width: 0.45,
                        widths: Vec::new(),
                        composition: Some(Composition::binary(f).expect("valid")),
                        part: Some(0),
                        sub_region: Some(k),
                    }
                })
                .collect();
            layer_plan(index, toolpaths, t)
        })
        .collect()
}

/// The synthetic layers on machine `name`, every transition purged on the tower.
fn export_for(name: &str) -> (Machine, String) {
    let m = machine(name);
    let info = info(Some(m.clone()), ["red", "green"]);
    let text = export(TOWER, &info, &layers(11), "test").expect("exports");
    (m, text)
}

/// The exporter with every transition on the wipe tower.
const TOWER: &str = "use = \"gcode\"\npurge_into = \"tower\"";

/// A move or command as the firmware reads it.
#[derive(Debug, Clone)]
struct Line {
    number: usize,
    command: String,
    words: BTreeMap<char, f64>,
}

fn read(text: &str) -> Vec<Line> {
    text.lines()
        .enumerate()
        .filter_map(|(i, l)| {
            let code = l.split(';').next().unwrap_or("").trim();
            let mut parts = code.split_whitespace();
            let command = parts.next()?.to_string();
            let words = parts
                .filter_map(|w| {
                    let mut c = w.chars();
                    let k = c.next()?;
                    Some((k, c.as_str().parse().ok()?))
                })
                .collect();
            Some(Line {
                number: i + 1,
                command,
                words,
            })
        })
        .collect()
}

/// What the firmware would do with the file, as far as safety and geometry go.
#[derive(Debug, Default)]
struct Replay {
    /// Moves that extrude or retract, with the selected tool and its heater state:
    /// (line, tool, target, waited-for).
    filament_moves: Vec<(usize, Option<i64>, f64, f64)>,
    /// Points extruded to, per `;TYPE:` feature.
    extruded: BTreeMap<String, Vec<Point2>>,
    /// Filament fed per feature (mm).
    fed: BTreeMap<String, f64>,
    /// Every XY position the head is sent to.
    visited: Vec<Point2>,
    /// Z of each `;LAYER:` line.
    layer_z: Vec<f64>,
    /// Lines where a tool is selected, in order.
    selections: Vec<(usize, i64)>,
    /// Standby settings: (line, tool, temperature).
    standby: Vec<(usize, i64, f64)>,
}

/// Replays Marlin or RepRapFirmware semantics: `M104/M109 [T] S` set (and wait for) a
/// tool's heater; `G10 P S R` gives a RepRapFirmware tool its active and standby
/// temperatures, `T` makes the new tool active and the old one standby, `M116 P` waits.
fn replay(text: &str, rrf: bool) -> Replay {
    let mut r = Replay::default();
    let (mut x, mut y, mut e) = (0.0f64, 0.0f64, 0.0f64);
    let mut relative_e = false;
    let mut tool: Option<i64> = None;
    let mut target: BTreeMap<i64, f64> = BTreeMap::new();
    let mut waited: BTreeMap<i64, f64> = BTreeMap::new();
    let mut rrf_temps: BTreeMap<i64, (f64, f64)> = BTreeMap::new();
    let mut feature = String::from("NONE");
    for line in text.lines() {
        if let Some(f) = line.strip_prefix(";TYPE:") {
            feature = f.trim().to_string();
        }
        if let Some(rest) = line.strip_prefix(";LAYER:") {
            let z = rest
                .split_whitespace()
                .find_map(|w| w.strip_prefix('Z'))
                .and_then(|z| z.parse().ok())
                .expect("layer z");
            r.layer_z.push(z);
        }
    }
    let lines = read(text);
    let mut feature_at = BTreeMap::new();
    let mut f = String::from("NONE");
    for (i, l) in text.lines().enumerate() {
        if let Some(x) = l.strip_prefix(";TYPE:") {
            f = x.trim().to_string();
        }
        feature_at.insert(i + 1, f.clone());
    }
    let _ = feature;
    for l in lines {
        let w = &l.words;
        let cooling = |target: &BTreeMap<i64, f64>, waited: &mut BTreeMap<i64, f64>, t: i64| {
            let now = target.get(&t).copied().unwrap_or(0.0);
            let entry = waited.entry(t).or_insert(0.0);
            *entry = entry.min(now);
        };
        match l.command.as_str() {
            "M82" => relative_e = false,
            "M83" => relative_e = true,
            "G92" => {
                if let Some(v) = w.get(&'E') {
                    e = *v;
                }
            }
            "M104" | "M109" => {
                let t = w.get(&'T').map_or(tool.unwrap_or(0), |t| *t as i64);
                let s = w.get(&'S').copied().unwrap_or(0.0);
                target.insert(t, s);
                if l.command == "M109" {
                    waited.insert(t, s);
                } else {
                    cooling(&target, &mut waited, t);
                    if Some(t) != tool {
                        r.standby.push((l.number, t, s));
                    }
                }
            }
            "G10" if rrf => {
                let p = w[&'P'] as i64;
                let old = rrf_temps.get(&p).copied().unwrap_or((0.0, 0.0));
                let temps = (
                    w.get(&'S').copied().unwrap_or(old.0),
                    w.get(&'R').copied().unwrap_or(old.1),
                );
                rrf_temps.insert(p, temps);
                if tool == Some(p) {
                    target.insert(p, temps.0);
                    cooling(&target, &mut waited, p);
                }
            }
            "M116" => {
                let p = w.get(&'P').map_or(tool.unwrap_or(0), |p| *p as i64);
                waited.insert(p, target.get(&p).copied().unwrap_or(0.0));
            }
            "G0" | "G1" => {
                let nx = w.get(&'X').copied().unwrap_or(x);
                let ny = w.get(&'Y').copied().unwrap_or(y);
                if let Some(v) = w.get(&'E') {
                    let de = if relative_e { *v } else { v - e };
                    e = if relative_e { e + v } else { *v };
                    let t = tool.unwrap_or(-1);
                    r.filament_moves.push((
                        l.number,
                        tool,
                        target.get(&t).copied().unwrap_or(0.0),
                        waited.get(&t).copied().unwrap_or(0.0),
                    ));
                    if (nx, ny) != (x, y) && de > 0.0 {
                        let feat = feature_at[&l.number].clone();
                        r.extruded
                            .entry(feat.clone())
                            .or_default()
                            .push(Point2::new(nx, ny));
                        *r.fed.entry(feat).or_default() += de;
                    }
                }
                if w.contains_key(&'X') || w.contains_key(&'Y') {
                    r.visited.push(Point2::new(nx, ny));
                }
                x = nx;
                y = ny;
            }
            c if c.starts_with('T') => {
                let Ok(t) = c[1..].parse::<i64>() else { continue };
                if rrf {
                    if let Some(old) = tool.filter(|o| *o != t)
                        && let Some((_, standby)) = rrf_temps.get(&old)
                    {
                        target.insert(old, *standby);
                        cooling(&target, &mut waited, old);
                    }
                    if let Some((active, _)) = rrf_temps.get(&t) {
                        target.insert(t, *active);
                        cooling(&target, &mut waited, t);
                    }
                }
                tool = (t >= 0).then_some(t);
                r.selections.push((l.number, t));
            }
            _ => {}
        }
    }
    r
}

#[test]
fn tools_are_selected_and_heated_before_they_move_filament_in_every_flavour() {
    for name in PROFILES {
        let (m, text) = export_for(name);
        let rrf = m.firmware == lamina_core::machine::Firmware::RepRapFirmware;
        let r = replay(&text, rrf);
        assert!(!r.filament_moves.is_empty(), "{name}");
        for (line, tool, target, waited) in &r.filament_moves {
            let t =
                tool.unwrap_or_else(|| panic!("{name}: line {line} moves filament with no tool selected"));
            // A mixing head has one heater; a tool changer's tool needs its own.
            let need = if m.flavor.is_mixing() {
                m.tools[0].nozzle_temperature
            } else {
                m.tools[t as usize].nozzle_temperature
            };
            assert!(
                *target >= need - 0.5 && *waited >= need - 0.5,
                "{name}: line {line} moves filament of T{t} at target {target}, waited {waited} (needs {need}):\n{}",
                text.lines().nth(line - 1).unwrap_or("")
            );
        }
        // The very first filament move comes after a tool selection and a wait.
        let first = r.filament_moves[0].0;
        let lines: Vec<&str> = text.lines().take(first).collect();
        let wait = if rrf { "M116" } else { "M109" };
        assert!(
            lines.iter().any(|l| l.starts_with(wait)),
            "{name}: no {wait} before line {first}"
        );
        assert!(
            lines.iter().any(|l| l.starts_with('T')),
            "{name}: no tool selected before line {first}"
        );
        assert!(
            lines.iter().position(|l| l.starts_with("G28")) < lines.iter().position(|l| l.starts_with("G0")),
            "{name}: homes before it moves"
        );
    }
}

#[test]
fn idle_tools_wait_at_standby_and_are_heated_again_before_printing() {
    for name in ["marlin-toolchanger-2", "rrf-idex-2"] {
        let (m, text) = export_for(name);
        let rrf = m.firmware == lamina_core::machine::Firmware::RepRapFirmware;
        let r = replay(&text, rrf);
        assert!(r.selections.len() >= 4, "{name}: the layers use both tools");
        if rrf {
            // The firmware parks the deselected tool at its G10 R temperature.
            for t in 0..2 {
                let standby = m.tools[t].standby_temperature.expect("standby");
                assert!(
                    text.lines()
                        .any(|l| l.starts_with(&format!("G10 P{t} ")) && l.contains(&format!(" R{standby}"))),
                    "{name}: no G10 R{standby} for T{t}"
                );
            }
        } else {
            assert!(!r.standby.is_empty(), "{name}: idle tools are set to standby");
            // Every temperature set for a tool not in use is its standby, its first
            // layer's (heating up before its first use) or 0 (off at the end).
            let lines: Vec<&str> = text.lines().collect();
            for (line, t, s) in &r.standby {
                let tool = &m.tools[*t as usize];
                let expected = tool.standby_temperature.expect("standby");
                // Or its printing temperature, heating ahead of its change.
                let ahead = lines[line - 1].contains("heat ahead of its change")
                    && (*s == tool.nozzle_temperature || *s == tool.first_layer_temperature);
                assert!(
                    *s == expected || *s == tool.first_layer_temperature || *s == 0.0 || ahead,
                    "{name}: T{t} waits at {s}: {}",
                    lines[line - 1]
                );
            }
            assert!(
                r.standby
                    .iter()
                    .any(|(_, t, s)| m.tools[*t as usize].standby_temperature == Some(*s))
            );
        }
    }
}

#[test]
fn every_move_stays_on_the_bed_and_layers_rise() {
    for name in PROFILES {
        let (m, text) = export_for(name);
        let r = replay(
            &text,
            m.firmware == lamina_core::machine::Firmware::RepRapFirmware,
        );
        let bed = m.bed.bounds();
        for p in &r.visited {
            assert!(
                p.x >= bed.min.x && p.x <= bed.max.x && p.y >= bed.min.y && p.y <= bed.max.y,
                "{name}: {p:?} is off the bed"
            );
        }
        assert_eq!(r.layer_z.len(), 5);
        assert!(
            r.layer_z.windows(2).all(|w| w[1] > w[0]),
            "{name}: {:?}",
            r.layer_z
        );
        for feature in ["PART", "SKIRT", "PRIME", "TOWER", "PURGE"] {
            assert!(r.extruded.contains_key(feature), "{name}: no {feature}");
        }
    }
}

#[test]
fn the_parts_land_where_the_placement_says_and_the_tower_beside_them() {
    for (placement, centre) in [
        (None, Point2::new(110.0, 110.0)),
        (Some([60.0, 150.0]), Point2::new(60.0, 150.0)),
    ] {
        let mut m = machine("marlin-mixing-2in1");
        if let Some(p) = placement {
            m.placement = BedPlacement::At(p);
        }
        let info = info(Some(m.clone()), ["red", "green"]);
        let text = export("use = \"gcode\"", &info, &layers(5), "test").expect("exports");
        let r = replay(&text, false);
        let part = BBox2::from_points(r.extruded["PART"].iter().copied());
        // The synthetic paths reach almost to the square's edges.
        assert!(
            (part.center() - centre).norm() < 3.0,
            "{placement:?}: parts centred at {:?}",
            part.center()
        );
        assert!(part.width() <= 2.0 * HALF + 1e-9 && part.height() <= 2.0 * HALF + 1e-9);
        let tower = BBox2::from_points(r.extruded["TOWER"].iter().copied());
        assert!(!tower.overlaps(&part), "tower {tower:?} on the parts {part:?}");
        let placed = BBox2::from_points([
            centre - lamina_core::Vector2::new(HALF, HALF),
            centre + lamina_core::Vector2::new(HALF, HALF),
        ]);
        assert!(!tower.overlaps(&placed));
    }
}

#[test]
fn without_a_machine_negative_plans_move_onto_the_positive_quadrant() {
    let info = info(None, ["red", "green"]);
    let text = export(
        "use = \"gcode\"\nflavor = \"tool-change\"",
        &info,
        &layers(3),
        "test",
    )
    .expect("exports");
    let r = replay(&text, false);
    let part = BBox2::from_points(r.extruded["PART"].iter().copied());
    assert!(part.min.x >= 10.0 - 1e-9 && part.min.y >= 10.0 - 1e-9, "{part:?}");
    assert!(text.contains("so that none is negative"));
    assert!(!text.contains("G28"), "no machine, no homing");
}

#[test]
fn every_change_is_purged_on_the_tower() {
    // Tool changer: the purge after each change is the profile's volume.
    let (m, text) = export_for("marlin-toolchanger-2");
    let area = std::f64::consts::PI * m.filament_diameter.powi(2) / 4.0;
    let changes = text.lines().filter(|l| l.starts_with("; tool change to")).count();
    let r = replay(&text, false);
    let purge = m.wipe_tower.expect("tower").purge_volume;
    let primes = 2;
    assert!(changes > primes);
    let purged = r.fed["PURGE"] * area;
    let expected = (changes - primes) as f64 * purge;
    assert!(
        (purged - expected).abs() <= 0.01 * expected,
        "{purged} mm³ purged for {changes} selections"
    );
    // Mixing head: after each change of mix of `blend_below` or more, the transition
    // volume before the part; smaller steps are set in place, unpurged.
    for blend in [0.0, 0.1, 0.3] {
        let mut m = machine("marlin-mixing-2in1");
        m.mixer.as_mut().expect("mixer").blend_below = blend;
        let transition = m.mixer.expect("mixer").transition_volume;
        let info = info(Some(m), ["red", "green"]);
        let text = export(TOWER, &info, &layers(11), "test").expect("exports");
        let lines: Vec<&str> = text.lines().collect();
        let (mut purged_mixes, mut blended) = (0, 0);
        let mut mix: Vec<f64> = Vec::new();
        let mut last: Option<Vec<f64>> = None;
        for (i, l) in lines.iter().enumerate() {
            if let Some(rest) = l.strip_prefix("M163 ") {
                let words: Vec<&str> = rest.split_whitespace().collect();
                let ch: usize = words[0][1..].parse().expect("channel");
                let f: f64 = words[1][1..].parse().expect("factor");
                if mix.len() <= ch {
                    mix.resize(ch + 1, 0.0);
                }
                mix[ch] = f;
            }
            if !l.starts_with("M164") {
                continue;
            }
            let before = last.replace(mix.clone());
            if !lines[..i].iter().any(|l| l.starts_with(";LAYER:")) {
                continue;
            }
            let Some(before) = before else { continue };
            let moved: f64 = before.iter().zip(&mix).map(|(a, b)| (a - b).abs()).sum::<f64>() / 2.0;
            // Up to the next change of mix or layer: a purge there follows this change.
            let end = lines[i + 1..]
                .iter()
                .position(|l| l.starts_with("M164") || l.starts_with(";LAYER:"))
                .map_or(lines.len(), |k| i + 1 + k);
            let purge = lines[i..end].contains(&";TYPE:PURGE");
            if moved >= blend - 1e-9 {
                purged_mixes += 1;
                assert!(
                    purge,
                    "blend {blend}: no purge between the mix at line {} and the part",
                    i + 1
                );
            } else {
                blended += 1;
                assert!(!purge, "blend {blend}: a {moved} step purged at line {}", i + 1);
            }
        }
        let r = replay(&text, false);
        // A job whose every change blends in place purges nothing and has no tower.
        let purged = r.fed.get("PURGE").copied().unwrap_or(0.0) * area;
        if blend == 0.0 {
            assert!(purged_mixes > 5 && blended == 0);
        } else if blend > 0.2 {
            assert!(blended > 0, "blend {blend}: every step was purged");
        }
        assert!(
            (purged - purged_mixes as f64 * transition).abs() <= 0.01 * purged.max(1.0),
            "blend {blend}: {purged} mm³ for {purged_mixes} mixes"
        );
    }
}

#[test]
fn names_with_line_breaks_cannot_write_commands() {
    let mut m = machine("marlin-toolchanger-2");
    m.name = "evil\nM300 S1 P1000".into();
    m.tools[1].name = Some("right\rM300 S2".into());
    let info = info(Some(m), ["red\nM300 S3", "green\u{2028}M300 S4"]);
    let text = export("use = \"gcode\"", &info, &layers(2), "pipeline\nM300 S5").expect("exports");
    for l in text.lines() {
        assert!(!l.trim_start().starts_with("M300"), "injected: {l}");
    }
    assert!(
        text.contains("red M300 S3"),
        "the name is kept, on one comment line"
    );
}

#[test]
fn the_footer_states_the_time_the_moves_take() {
    for name in PROFILES {
        let (m, text) = export_for(name);
        let footer: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("; estimated printing time: "))
            .collect();
        assert_eq!(footer.len(), 1, "{name}");
        let seconds: f64 = footer[0]
            .strip_prefix("; estimated printing time: ")
            .and_then(|s| s.strip_suffix(" s"))
            .and_then(|s| s.parse().ok())
            .expect("seconds");
        assert!(text.contains("planned build time not stated"), "{name}");
        // Each move takes at least its length at its feed, and at most that plus the
        // time to reach the feed from rest and stop again.
        let rrf = m.firmware == lamina_core::machine::Firmware::RepRapFirmware;
        let accel = m
            .motion
            .max_acceleration
            .expect("axis accelerations")
            .as_array()
            .into_iter()
            .fold(
                m.motion
                    .print_acceleration
                    .min(m.motion.travel_acceleration)
                    .min(m.motion.retract_acceleration),
                f64::min,
            );
        let max = m.motion.max_speed.expect("max speeds");
        let (mut lower, mut upper) = (0.0, 0.0);
        let (mut pos, mut feed, mut relative_e) = ([0.0f64; 4], 3000.0f64, false);
        for l in read(&text) {
            match l.command.as_str() {
                "M83" => relative_e = true,
                "M82" => relative_e = false,
                "G92" => {
                    if let Some(e) = l.words.get(&'E') {
                        pos[3] = *e;
                    }
                }
                "G0" | "G1" => {
                    if let Some(f) = l.words.get(&'F') {
                        feed = *f;
                    }
                    let mut next = pos;
                    for (i, k) in ['X', 'Y', 'Z', 'E'].into_iter().enumerate() {
                        if let Some(v) = l.words.get(&k) {
                            next[i] = if i == 3 && relative_e { pos[3] + v } else { *v };
                        }
                    }
                    let d: Vec<f64> = (0..4).map(|i| next[i] - pos[i]).collect();
                    let xyz = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    let length = if xyz > 0.0 { xyz } else { d[3].abs() };
                    if length > 0.0 {
                        let mut v = feed / 60.0;
                        for (i, limit) in max.as_array().into_iter().enumerate() {
                            if d[i] != 0.0 {
                                v = v.min(limit * length / d[i].abs());
                            }
                        }
                        lower += length / v;
                        upper += length / v + v / accel;
                    }
                    pos = next;
                }
                _ => {}
            }
        }
        let _ = rrf;
        // Besides the moves, the waits the file states (heaters, tool changes).
        let waits: f64 = text
            .lines()
            .find_map(|l| l.strip_prefix("; of the time below: "))
            .map(|l| {
                l.split(" s ")
                    .filter_map(|w| w.rsplit(' ').next()?.parse::<f64>().ok())
                    .sum()
            })
            .expect("the waits' line");
        assert!(waits > 0.0, "{name}: the start heats the bed and a tool");
        let (lower, upper) = (lower + waits, upper + waits);
        assert!(
            seconds >= lower * 0.999 && seconds <= upper * 1.001,
            "{name}: {seconds} s outside {lower}..{upper}"
        );
    }
}

#[test]
fn options_the_machine_sets_are_refused_at_their_key() {
    let m = machine("marlin-mixing-2in1");
    let registry = Registry::linked().expect("registry");
    let dir = std::env::temp_dir();
    let scripts = lamina_core::script::local(&dir, Default::default());
    for key in [
        "flavor = \"tool-change\"",
        "temperature = 200.0",
        "channels = [\"red\"]",
    ] {
        let text = format!("use = \"gcode\"\n{key}");
        let table = lamina_core::pipeline::TableRef::parse_snippet("gcode", &text).expect("table");
        let err = registry
            .build_for::<dyn lamina_core::Exporter>(
                &table,
                &scripts,
                &dir,
                lamina_core::stage::PipelineContext {
                    machine: Some(&m),
                    ..Default::default()
                },
            )
            .err()
            .unwrap_or_else(|| panic!("{key} accepted"));
        let k = key.split(' ').next().unwrap_or("");
        assert!(err.to_string().contains(k), "{err}");
        assert_eq!(err.location().expect("located").line_col().0, 2, "{err}");
    }
}

#[test]
fn a_material_no_tool_carries_is_refused() {
    let mut m = machine("marlin-toolchanger-2");
    m.tools[0].material = Some("pla".into());
    m.tools[1].material = Some("petg".into());
    let info = info(Some(m), ["red", "green"]);
    let err = export("use = \"gcode\"", &info, &layers(1), "test").expect_err("red has no tool");
    assert!(
        err.to_string().contains("`red`") && err.to_string().contains("pla"),
        "{err}"
    );
}

#[test]
fn a_layer_thicker_than_the_nozzle_presses_is_refused() {
    let m = machine("marlin-toolchanger-2");
    let mut plans = layers(3);
    plans[2].thickness = 0.45;
    let e = export(
        "use = \"gcode\"",
        &info(Some(m), ["red", "green"]),
        &plans,
        "test",
    )
    .expect_err("too thick")
    .to_string();
    assert!(
        e.contains("layer 2 is 0.45 mm thick") && e.contains("max_layer_height"),
        "{e}"
    );
}

#[test]
fn a_tools_own_beads_take_its_prime_and_no_tower_is_built() {
    let m = machine("marlin-toolchanger-2");
    let info = info(Some(m.clone()), ["red", "green"]);
    let part = export("use = \"gcode\"", &info, &layers(11), "test").expect("exports");
    let (_, tower) = export_for("marlin-toolchanger-2");
    let (rp, rt) = (replay(&part, false), replay(&tower, false));
    // The same tool changes and the same beads of the part, without purge or tower.
    assert_eq!(rp.selections.len(), rt.selections.len());
    assert!((rp.fed["PART"] - rt.fed["PART"]).abs() < 1e-6);
    assert!(!rp.fed.contains_key("PURGE") && !rp.fed.contains_key("TOWER"));
    assert!(part.contains("; transition: the next"));
    assert!(
        !part.contains("; wipe tower:"),
        "no tower is placed for the tool changer"
    );
}

/// Rings graded in steps of `step` from the rim inward, one layer each way, as the
/// offset discretiser and a mixing head's planner make them: each ring one bead of
/// `volume` mm³ at 0.2 mm, with its sub-region graded.
fn rings(step: u32, volume: f64) -> Vec<LayerPlan> {
    let levels: Vec<u32> = (0..=100 / step).map(|i| i * step).collect();
    (0..4)
        .map(|index| {
            let mut t = 0.0;
            let mut regions = Vec::new();
            let mut toolpaths = Vec::new();
            for (k, share) in levels.iter().enumerate() {
                let f = f64::from(*share) / 100.0;
                let composition = Composition::binary(f).expect("valid");
                regions.push(lamina_core::SubRegion {
                    family: 0,
                    index: k,
                    count: levels.len(),
                    level: k as f64 / (levels.len() - 1) as f64,
                    polygon: lamina_core::Polygon::default(),
                    cell: None,
                    reference: Point2::origin(),
                    composition: Some(composition.clone()),
                    samples: Vec::new(),
                });
                // A square loop of the bead's length, smaller inward.
                let side = volume / (0.45 * 0.2) / 4.0;
                let h = side / 2.0;
                let corners = [(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)];
                let points = corners
                    .iter()
                    .map(|&(x, y)| {
                        t += 1.0;
                        TimedPoint {
                            p: Point2::new(x * (1.0 - 0.05 * k as f64), y * (1.0 - 0.05 * k as f64)),
                            t,
                        }
                    })
                    .collect();
                toolpaths.push(Toolpath {
                    tool: 0,
                    material: None,
                    kind: PathKind::Extrude,
                    points,
                    width: 0.45,
                    widths: Vec::new(),
                    composition: Some(composition),
                    part: Some(0),
                    sub_region: Some(k),
                });
            }
            let mut plan = layer_plan(index, toolpaths, t);
            plan.parts = vec![lamina_core::PartLayer {
                part: 0,
                contours: Vec::new(),
                tree: Default::default(),
                families: vec![0],
                regions,
            }];
            plan
        })
        .collect()
}

#[test]
fn a_graded_parts_next_beads_take_its_transitions() {
    let m = machine("marlin-mixing-2in1");
    let info = info(Some(m.clone()), ["red", "green"]);
    let area = std::f64::consts::PI * m.filament_diameter.powi(2) / 4.0;
    let transition = m.mixer.expect("mixer").transition_volume;
    // Rings of 20 % steps holding 30 mm³ each: every transition fits the next ring.
    let text = export("use = \"gcode\"", &info, &rings(20, 30.0), "test").expect("exports");
    let r = replay(&text, false);
    assert!(
        !r.fed.contains_key("PURGE") && !r.fed.contains_key("TOWER"),
        "{:?}",
        r.fed.keys()
    );
    assert!(text.lines().filter(|l| l.starts_with("M164")).count() > 10);
    // Rings of 2 mm³ cannot take a 15 mm³ transition within half a step: the tower
    // takes some, never more than a full flush a change.
    let text = export("use = \"gcode\"", &info, &rings(20, 2.0), "test").expect("exports");
    let r = replay(&text, false);
    let purged = r.fed.get("PURGE").copied().unwrap_or(0.0) * area;
    let changes = text.lines().filter(|l| l.starts_with("M164")).count();
    assert!(purged > 0.0, "small rings purge");
    assert!(
        purged < changes as f64 * transition,
        "{purged} mm³ for {changes} changes"
    );
    let tower = export(TOWER, &info, &rings(20, 2.0), "test").expect("exports");
    let full = replay(&tower, false).fed["PURGE"] * area;
    assert!(purged < full, "{purged} against {full} on the tower alone");
}
