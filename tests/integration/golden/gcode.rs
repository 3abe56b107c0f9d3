//! A G-code file summarised as a firmware would run it: positions and extrusion followed
//! word by word (`G0`/`G1`, `G90`/`G91`, `M82`/`M83`, `G92`, `T`, and RepRapFirmware's
//! `M596` motion systems, each with its own position, tool and extrusion mode, the second
//! on its own U and V axes), so that a
//! changed file says which layer, which tool or which kind of deposit changed.

use std::collections::BTreeMap;
use std::fmt::Write;

use super::{clipped_ends, digest_text};

/// One motion system's state.
#[derive(Default)]
struct Head {
    x: f64,
    y: f64,
    e: f64,
    relative_xyz: bool,
    relative_e: bool,
    tool: Option<i64>,
    kind: String,
    layer: Option<i64>,
    in_bead: bool,
}

#[derive(Default)]
struct Layer {
    label: String,
    beads: usize,
    length: f64,
    e: f64,
    travels: usize,
    retractions: usize,
}

/// The summary of a G-code file: digest, command counts, filament per tool and per
/// `;TYPE:`, one line per layer (beads, their length, filament, travels, retractions),
/// and the first and last 50 lines.
pub fn summary(text: &str) -> String {
    let mut heads: Vec<Head> = vec![Head::default()];
    let mut system = 0usize;
    let mut layers: BTreeMap<Option<i64>, Layer> = BTreeMap::new();
    let mut commands: BTreeMap<String, usize> = BTreeMap::new();
    let mut per_tool: BTreeMap<Option<i64>, f64> = BTreeMap::new();
    let mut per_kind: BTreeMap<String, f64> = BTreeMap::new();
    let mut zero_e_moves = 0usize;
    let mut diameter = None;
    let mut estimates = Vec::new();
    let mut lines = 0usize;

    for raw in text.lines() {
        lines += 1;
        let (code, comment) = match raw.find(';') {
            Some(i) => (&raw[..i], Some(raw[i + 1..].trim())),
            None => (raw, None),
        };
        let head = &mut heads[system];
        if let Some(comment) = comment {
            if let Some(rest) = comment.strip_prefix("LAYER:") {
                let number = rest.split_whitespace().next().and_then(|n| n.parse().ok());
                head.layer = number;
                head.in_bead = false;
                let layer = layers.entry(number).or_default();
                if layer.label.is_empty() {
                    layer.label = rest.to_string();
                }
            } else if let Some(kind) = comment.strip_prefix("TYPE:") {
                head.kind = kind.to_string();
            } else if let Some(rest) = comment.split("filament diameter ").nth(1) {
                diameter =
                    diameter.or_else(|| rest.split_whitespace().next().and_then(|d| d.parse::<f64>().ok()));
            }
            if comment.contains("estimated printing time") {
                estimates.push(comment.to_string());
            }
        }
        let mut words = code.split_whitespace();
        let Some(command) = words.next() else {
            continue;
        };
        let command = command.to_ascii_uppercase();
        let word = |letter: char| {
            code.split_whitespace()
                .skip(1)
                .find(|w| w.starts_with(letter) || w.starts_with(letter.to_ascii_lowercase()))
                .and_then(|w| w[1..].parse::<f64>().ok())
        };
        if let Some(tool) = command.strip_prefix('T') {
            *commands.entry("T".into()).or_default() += 1;
            head.tool = tool.parse().ok();
            head.in_bead = false;
            continue;
        }
        *commands.entry(command.clone()).or_default() += 1;
        match command.as_str() {
            "G90" => head.relative_xyz = false,
            "G91" => head.relative_xyz = true,
            "M82" => head.relative_e = false,
            "M83" => head.relative_e = true,
            "G92" => {
                if let Some(e) = word('E') {
                    head.e = e;
                }
            }
            "M596" => {
                system = word('P').map_or(0, |p| p as usize);
                if heads.len() <= system {
                    heads.resize_with(system + 1, Head::default);
                }
            }
            "G0" | "G1" => {
                // A second motion system drives its own axes, U and V (RRF 3.5).
                let (x, y) = (word('X').or(word('U')), word('Y').or(word('V')));
                let (x, y) = match (x, y, head.relative_xyz) {
                    (x, y, false) => (x.unwrap_or(head.x), y.unwrap_or(head.y)),
                    (x, y, true) => (head.x + x.unwrap_or(0.0), head.y + y.unwrap_or(0.0)),
                };
                let de = match (word('E'), head.relative_e) {
                    (Some(e), false) => e - head.e,
                    (Some(e), true) => e,
                    (None, _) => 0.0,
                };
                head.e += de;
                let moved = (x - head.x).hypot(y - head.y);
                head.x = x;
                head.y = y;
                let layer = layers.entry(head.layer).or_default();
                if de > 0.0 && moved > 0.0 {
                    if !head.in_bead {
                        layer.beads += 1;
                        head.in_bead = true;
                    }
                    layer.length += moved;
                    layer.e += de;
                    *per_tool.entry(head.tool).or_default() += de;
                    *per_kind.entry(head.kind.clone()).or_default() += de;
                } else {
                    head.in_bead = false;
                    if de < 0.0 {
                        layer.retractions += 1;
                    } else if moved > 0.0 {
                        layer.travels += 1;
                        if word('E').is_some() {
                            zero_e_moves += 1;
                        }
                    }
                }
            }
            _ => {}
        }
    }

    let mut s = String::new();
    writeln!(s, "lines: {lines}\ndigest: {}", digest_text(text)).ok();
    for estimate in &estimates {
        writeln!(s, "file's estimate: {estimate}").ok();
    }
    let counts: Vec<String> = commands.iter().map(|(c, n)| format!("{c} {n}")).collect();
    writeln!(s, "commands: {}", counts.join(", ")).ok();
    writeln!(s, "moves with an E word that extrude nothing: {zero_e_moves}").ok();
    let volume = |mm: f64| match diameter {
        Some(d) => format!("{mm:.3} mm ({:.3} mm³)", mm * std::f64::consts::PI * d * d / 4.0),
        None => format!("{mm:.3} mm"),
    };
    for (tool, mm) in &per_tool {
        let tool = tool.map_or("no tool".to_string(), |t| format!("T{t}"));
        writeln!(s, "filament {tool}: {}", volume(*mm)).ok();
    }
    for (kind, mm) in &per_kind {
        let kind = if kind.is_empty() { "(no type)" } else { kind };
        writeln!(s, "filament ;TYPE:{kind}: {}", volume(*mm)).ok();
    }
    let numbered = layers.keys().filter(|k| k.is_some()).count();
    writeln!(s, "layers: {numbered}").ok();
    for (number, l) in &layers {
        let label = match number {
            Some(_) => format!("LAYER:{}", l.label),
            None => "before the first layer".to_string(),
        };
        writeln!(
            s,
            "  {label}: beads {}, length {:.3} mm, E {:.5} mm, travels {}, retractions {}",
            l.beads, l.length, l.e, l.travels, l.retractions
        )
        .ok();
    }
    s.push_str(&clipped_ends(text, 50));
    s
}
