//! An NC program summarised as a controller would run it (RS-274: `G0`/`G1` in absolute
//! `G90` or incremental `G91` coordinates, `T… M6` tool changes, spindle and outputs):
//! per layer comment, the moves, their feed length, tool changes and switched outputs.

use std::collections::BTreeMap;
use std::fmt::Write;

use super::{clipped_ends, digest_text};

#[derive(Default)]
struct Layer {
    label: String,
    rapids: usize,
    feeds: usize,
    feed_length: f64,
    tool_changes: usize,
    outputs_on: usize,
}

/// Digest, command counts, feed length per tool, one line per `(layer …)` comment, and
/// the first and last 50 lines.
pub fn summary(text: &str) -> String {
    let mut layers: Vec<Layer> = vec![Layer {
        label: "before the first layer".into(),
        ..Layer::default()
    }];
    let mut commands: BTreeMap<String, usize> = BTreeMap::new();
    let mut per_tool: BTreeMap<String, f64> = BTreeMap::new();
    let (mut pos, mut relative, mut tool) = ([0.0f64; 3], false, "none".to_string());
    let mut lines = 0usize;
    for raw in text.lines() {
        lines += 1;
        // Comments are `( … )`; a layer's opens it.
        let mut code = String::new();
        let mut depth = 0;
        let mut comment = String::new();
        for c in raw.chars() {
            match c {
                '(' => depth += 1,
                ')' => depth -= 1,
                _ if depth > 0 => comment.push(c),
                _ => code.push(c),
            }
        }
        if let Some(rest) = comment.strip_prefix("layer ") {
            layers.push(Layer {
                label: rest.to_string(),
                ..Layer::default()
            });
        }
        let layer = layers.last_mut().expect("one layer at least");
        let words: Vec<(char, &str)> = code
            .split_whitespace()
            .filter_map(|w| {
                let letter = w.chars().next()?.to_ascii_uppercase();
                Some((letter, &w[1..]))
            })
            .collect();
        let value = |letter: char| {
            words
                .iter()
                .find(|(l, _)| *l == letter)
                .and_then(|(_, v)| v.parse::<f64>().ok())
        };
        let mut motion = None;
        for &(letter, v) in &words {
            if matches!(letter, 'G' | 'M' | 'T' | 'S') {
                let key = if letter == 'S' {
                    "S".to_string()
                } else {
                    format!("{letter}{v}")
                };
                *commands.entry(key).or_default() += 1;
            }
            match (letter, v) {
                ('G', "0" | "00") => motion = Some(0),
                ('G', "1" | "01") => motion = Some(1),
                ('G', "90") => relative = false,
                ('G', "91") => relative = true,
                ('M', "6" | "06") => {
                    layer.tool_changes += 1;
                    if let Some(t) = value('T') {
                        tool = format!("T{t}");
                    }
                }
                ('M', "64") => layer.outputs_on += 1,
                _ => {}
            }
        }
        let Some(motion) = motion else {
            continue;
        };
        let mut next = pos;
        for (axis, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            if let Some(v) = value(letter) {
                next[axis] = if relative { pos[axis] + v } else { v };
            }
        }
        let length =
            ((next[0] - pos[0]).powi(2) + (next[1] - pos[1]).powi(2) + (next[2] - pos[2]).powi(2)).sqrt();
        pos = next;
        if motion == 0 {
            layer.rapids += 1;
        } else {
            layer.feeds += 1;
            layer.feed_length += length;
            *per_tool.entry(tool.clone()).or_default() += length;
        }
    }
    let mut s = String::new();
    writeln!(s, "lines: {lines}\ndigest: {}", digest_text(text)).ok();
    let counts: Vec<String> = commands.iter().map(|(c, n)| format!("{c} {n}")).collect();
    writeln!(s, "words: {}", counts.join(", ")).ok();
    for (tool, length) in &per_tool {
        writeln!(s, "feed length {tool}: {length:.3} mm").ok();
    }
    writeln!(s, "layers: {}", layers.len() - 1).ok();
    for l in &layers {
        writeln!(
            s,
            "  {}: rapids {}, feeds {} ({:.3} mm), tool changes {}, outputs on {}",
            l.label, l.rapids, l.feeds, l.feed_length, l.tool_changes, l.outputs_on
        )
        .ok();
    }
    s.push_str(&clipped_ends(text, 50));
    s
}
