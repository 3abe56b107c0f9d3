//! A Common Layer Interface file summarised from the CLI specification (version 2.0):
//! the header whole, and per layer its height, polylines, points, hatches and the
//! polylines' length in the file's units. ASCII and binary geometry are both read.

use std::fmt::Write;

use super::{clipped_ends, digest_bytes, digest_text, normalise};

#[derive(Default)]
struct Layer {
    z: String,
    polylines: usize,
    points: usize,
    hatches: usize,
    length: f64,
    other: usize,
}

fn polyline_length(xy: &[f64]) -> f64 {
    xy.chunks_exact(2)
        .zip(xy.chunks_exact(2).skip(1))
        .map(|(a, b)| (b[0] - a[0]).hypot(b[1] - a[1]))
        .sum()
}

/// The summary of a CLI file, ASCII or binary.
pub fn summary(bytes: &[u8]) -> String {
    const END: &[u8] = b"$$HEADEREND";
    let header_end = bytes
        .windows(END.len())
        .position(|w| w == END)
        .map_or(bytes.len(), |i| i + END.len());
    let header = String::from_utf8_lossy(&bytes[..header_end]);
    let mut s = String::new();
    writeln!(s, "bytes: {}", bytes.len()).ok();
    if header.contains("$$BINARY") {
        writeln!(s, "digest: {}", digest_bytes(bytes)).ok();
        writeln!(s, "header:\n{}", normalise::text(&header)).ok();
        let (layers, error) = binary_layers(&bytes[header_end..]);
        write_layers(&mut s, &layers);
        if let Some(error) = error {
            writeln!(s, "unreadable: {error}").ok();
        }
        return s;
    }
    let text = String::from_utf8_lossy(bytes);
    writeln!(s, "digest: {}", digest_text(&text)).ok();
    writeln!(s, "header:\n{}", normalise::text(&header)).ok();
    let mut layers: Vec<Layer> = Vec::new();
    for line in text[header_end.min(text.len())..].lines() {
        let line = line.trim();
        let (command, args) = line.split_once('/').unwrap_or((line, ""));
        let numbers = || {
            args.split(',')
                .map(|v| v.trim().parse::<f64>().unwrap_or(f64::NAN))
        };
        match command {
            "$$LAYER" => layers.push(Layer {
                z: normalise::text(args),
                ..Layer::default()
            }),
            "$$POLYLINE" => {
                if let Some(layer) = layers.last_mut() {
                    let v: Vec<f64> = numbers().collect();
                    let n = v.get(2).copied().unwrap_or(0.0) as usize;
                    layer.polylines += 1;
                    layer.points += n;
                    layer.length += polyline_length(&v[3.min(v.len())..]);
                }
            }
            "$$HATCHES" => {
                if let Some(layer) = layers.last_mut() {
                    layer.hatches += numbers().nth(1).unwrap_or(0.0) as usize;
                }
            }
            "" | "$$GEOMETRYSTART" | "$$GEOMETRYEND" => {}
            _ => {
                if let Some(layer) = layers.last_mut() {
                    layer.other += 1;
                }
            }
        }
    }
    write_layers(&mut s, &layers);
    s.push_str(&clipped_ends(&text, 50));
    s
}

fn write_layers(s: &mut String, layers: &[Layer]) {
    writeln!(s, "layers: {}", layers.len()).ok();
    for l in layers {
        writeln!(
            s,
            "  z {}: polylines {}, points {}, length {:.3}, hatches {}, other lines {}",
            l.z, l.polylines, l.points, l.length, l.hatches, l.other
        )
        .ok();
    }
}

/// Binary geometry, little-endian: a `u16` command, then its parameters. Long forms
/// (127 layer `f32`; 130 polyline `i32` id, dir, n, 2n `f32`; 132 hatches `i32` id, n,
/// 4n `f32`) and short forms (128 layer `u16`; 129 polyline `u16` id, dir, n, 2n `u16`;
/// 131 hatches `u16` id, n, 4n `u16`).
/// A number read from its little-endian bytes.
type Reader<'a> = &'a dyn Fn(&[u8]) -> f64;

fn binary_layers(data: &[u8]) -> (Vec<Layer>, Option<String>) {
    let mut layers: Vec<Layer> = Vec::new();
    let mut at = 0usize;
    let take = |at: &mut usize, n: usize| -> Option<&[u8]> {
        let bytes = data.get(*at..*at + n)?;
        *at += n;
        Some(bytes)
    };
    let u16_at = |b: &[u8]| f64::from(u16::from_le_bytes([b[0], b[1]]));
    let i32_at = |b: &[u8]| f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let f32_at = |b: &[u8]| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    while at < data.len() {
        let start = at;
        let Some(cmd) = take(&mut at, 2) else {
            return (layers, Some(format!("a command cut at byte {start}")));
        };
        let cmd = u16::from_le_bytes([cmd[0], cmd[1]]);
        let (word, read): (usize, Reader) = match cmd {
            127 | 130 | 132 => (4, &f32_at),
            128 | 129 | 131 => (2, &u16_at),
            _ => return (layers, Some(format!("command {cmd} at byte {start}"))),
        };
        let int: Reader = if word == 4 { &i32_at } else { &u16_at };
        let cut = || format!("command {cmd} at byte {start} cut short");
        match cmd {
            127 | 128 => {
                let Some(z) = take(&mut at, word) else {
                    return (layers, Some(cut()));
                };
                layers.push(Layer {
                    z: normalise::text(&format!("{}", read(z))),
                    ..Layer::default()
                });
            }
            129 | 130 => {
                let Some(head) = take(&mut at, 3 * word) else {
                    return (layers, Some(cut()));
                };
                let n = int(&head[2 * word..]) as usize;
                let Some(points) = take(&mut at, 2 * n * word) else {
                    return (layers, Some(cut()));
                };
                let xy: Vec<f64> = points.chunks_exact(word).map(read).collect();
                if let Some(layer) = layers.last_mut() {
                    layer.polylines += 1;
                    layer.points += n;
                    layer.length += polyline_length(&xy);
                }
            }
            _ => {
                let Some(head) = take(&mut at, 2 * word) else {
                    return (layers, Some(cut()));
                };
                let n = int(&head[word..]) as usize;
                if take(&mut at, 4 * n * word).is_none() {
                    return (layers, Some(cut()));
                }
                if let Some(layer) = layers.last_mut() {
                    layer.hatches += n;
                }
            }
        }
    }
    (layers, None)
}
