//! A JSON plan summarised as its reader would check it: everything above the layers
//! whole (materials, parts, sequence), then one entry per layer: its families and
//! sub-regions with their area and the area of each material, its toolpaths by tool and
//! kind with their length, its operations by kind, and its other fields.

use std::collections::BTreeMap;
use std::fmt::Write;

use serde_json::Value;

use super::{digest_text, normalise};

/// The summary of a plan file (see `docs/formats.md` for its fields).
pub fn summary(text: &str) -> String {
    let mut s = String::new();
    writeln!(s, "bytes: {}\ndigest: {}", text.len(), digest_text(text)).ok();
    let plan: Value = match serde_json::from_str(text) {
        Ok(plan) => plan,
        Err(e) => {
            writeln!(s, "not JSON: {e}").ok();
            return s;
        }
    };
    let Some(object) = plan.as_object() else {
        writeln!(s, "not an object").ok();
        return s;
    };
    for (key, value) in object {
        if key != "layers" {
            let whole = serde_json::to_string_pretty(value).unwrap_or_default();
            writeln!(s, "{key}: {}", normalise::text(&whole)).ok();
        }
    }
    let layers = plan["layers"].as_array().map_or(&[][..], Vec::as_slice);
    writeln!(s, "layers: {}", layers.len()).ok();
    for layer in layers {
        layer_summary(&mut s, layer);
    }
    s
}

/// The area of a ring of `[x, y]` points (shoelace), unsigned.
fn ring_area(ring: &Value) -> f64 {
    let Some(points) = ring.as_array() else {
        return 0.0;
    };
    let xy: Vec<(f64, f64)> = points
        .iter()
        .filter_map(|p| Some((p[0].as_f64()?, p[1].as_f64()?)))
        .collect();
    let twice: f64 = xy
        .iter()
        .zip(xy.iter().cycle().skip(1))
        .map(|(a, b)| a.0 * b.1 - b.0 * a.1)
        .sum();
    twice.abs() / 2.0
}

fn polygon_area(polygon: &Value) -> f64 {
    let holes: f64 = polygon["holes"]
        .as_array()
        .map_or(0.0, |h| h.iter().map(ring_area).sum());
    ring_area(&polygon["outer"]) - holes
}

fn path_length(points: &Value) -> f64 {
    let xy: Vec<(f64, f64)> = points
        .as_array()
        .map_or(&[][..], Vec::as_slice)
        .iter()
        .filter_map(|p| {
            // Toolpath points are `{ "p": [x, y], "t": … }`, machining points `[x, y]`.
            let p = if p.is_object() { &p["p"] } else { p };
            Some((p[0].as_f64()?, p[1].as_f64()?))
        })
        .collect();
    xy.windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .sum()
}

fn scalar(value: &Value) -> String {
    normalise::text(&value.to_string())
}

fn layer_summary(s: &mut String, layer: &Value) {
    let Some(fields) = layer.as_object() else {
        writeln!(s, "  (not an object)").ok();
        return;
    };
    let mut head = Vec::new();
    for (key, value) in fields {
        if !value.is_array() && !value.is_object() {
            head.push(format!("{key} {}", scalar(value)));
        }
    }
    writeln!(s, "  layer {}", head.join(", ")).ok();
    for (key, value) in fields {
        match (key.as_str(), value) {
            ("parts", Value::Array(parts)) => {
                for part in parts {
                    part_summary(s, part);
                }
            }
            ("toolpaths", Value::Array(paths)) => {
                let mut by: BTreeMap<(String, String), (usize, usize, f64)> = BTreeMap::new();
                for path in paths {
                    let key = (scalar(&path["tool"]), scalar(&path["kind"]));
                    let entry = by.entry(key).or_default();
                    entry.0 += 1;
                    entry.1 += path["points"].as_array().map_or(0, Vec::len);
                    entry.2 += path_length(&path["points"]);
                }
                for ((tool, kind), (n, points, length)) in by {
                    writeln!(
                        s,
                        "    tool {tool} {kind}: {n} paths, {points} points, {length:.4} mm"
                    )
                    .ok();
                }
            }
            ("operations", Value::Array(operations)) => {
                for op in operations {
                    let paths = op["paths"].as_array().map_or(&[][..], Vec::as_slice);
                    let points: usize = paths
                        .iter()
                        .map(|p| p["points"].as_array().map_or(0, Vec::len))
                        .sum();
                    let length: f64 = paths.iter().map(|p| path_length(&p["points"])).sum();
                    let scalars: Vec<String> = op
                        .as_object()
                        .into_iter()
                        .flatten()
                        .filter(|(k, v)| *k != "paths" && !v.is_array())
                        .map(|(k, v)| format!("{k} {}", scalar(v)))
                        .collect();
                    writeln!(
                        s,
                        "    operation {}: {} paths, {points} points, {length:.4} mm",
                        scalars.join(", "),
                        paths.len()
                    )
                    .ok();
                }
            }
            (_, Value::Array(items)) => {
                writeln!(
                    s,
                    "    {key}: {} items, {}",
                    items.len(),
                    digest_text(&value.to_string())
                )
                .ok();
            }
            (_, Value::Object(_)) => {
                writeln!(s, "    {key}: {}", scalar(value)).ok();
            }
            _ => {}
        }
    }
}

fn part_summary(s: &mut String, part: &Value) {
    let families = part["families"].as_array().map_or(&[][..], Vec::as_slice);
    let mut regions = 0;
    let mut family_area = 0.0;
    let mut region_area = 0.0;
    let mut vertices = 0;
    let mut materials: BTreeMap<String, f64> = BTreeMap::new();
    for family in families {
        family_area += ring_area(&family["outer"])
            - family["holes"]
                .as_array()
                .map_or(0.0, |h| h.iter().map(ring_area).sum::<f64>());
        for region in family["sub_regions"].as_array().map_or(&[][..], Vec::as_slice) {
            regions += 1;
            let area = polygon_area(&region["polygon"]);
            region_area += area;
            vertices += region["polygon"]["outer"].as_array().map_or(0, Vec::len);
            for (material, fraction) in region["composition"].as_object().into_iter().flatten() {
                *materials.entry(material.clone()).or_default() +=
                    fraction.as_f64().unwrap_or(f64::NAN) * area;
            }
        }
    }
    let materials: Vec<String> = materials.iter().map(|(m, a)| format!("{m} {a:.4}")).collect();
    writeln!(
        s,
        "    part {}: {} families ({family_area:.4} mm²), {regions} sub-regions ({region_area:.4} mm², {vertices} outer vertices); area by material: {}",
        scalar(&part["part"]),
        families.len(),
        materials.join(", ")
    )
    .ok();
}
