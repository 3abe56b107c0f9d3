//! Summaries of the outputs that are not machine programs or plans: 3MF packages, PNG
//! pictures, bitmap layers, SVG pictures, the HTML viewer, and any other file.

use std::fmt::Write;
use std::io::Read;
use std::path::Path;

use super::{clipped_ends, digest_bytes, digest_text, normalise};

/// Text this short is kept whole; longer text is a digest and its ends.
const WHOLE: usize = 8 * 1024;

/// A 3MF package (a ZIP, 3MF core specification §2): each part's name, size and digest,
/// and for each model part the count of each element and its first and last lines.
pub fn threemf(bytes: &[u8]) -> String {
    let mut s = String::new();
    let mut archive = match zip::ZipArchive::new(std::io::Cursor::new(bytes)) {
        Ok(archive) => archive,
        Err(e) => return format!("not a ZIP package: {e}\n"),
    };
    let mut models = Vec::new();
    for i in 0..archive.len() {
        let mut entry = match archive.by_index(i) {
            Ok(entry) => entry,
            Err(e) => {
                writeln!(s, "part {i}: unreadable: {e}").ok();
                continue;
            }
        };
        let name: String = match entry.name() {
            Ok(name) => name.into_owned(),
            Err(e) => format!("(part {i}: unreadable name: {e})"),
        };
        let mut content = Vec::new();
        if let Err(e) = entry.read_to_end(&mut content) {
            writeln!(s, "part {name}: unreadable: {e}").ok();
            continue;
        }
        let text = String::from_utf8_lossy(&content).into_owned();
        let digest = if name.ends_with(".png") {
            digest_bytes(&content)
        } else {
            digest_text(&text)
        };
        writeln!(s, "part {name}: {} bytes, {digest}", content.len()).ok();
        if name.ends_with(".model") {
            models.push((name, text));
        } else if !name.ends_with(".png") && content.len() <= WHOLE {
            writeln!(s, "{}", normalise::text(&text)).ok();
        }
    }
    for (name, text) in models {
        writeln!(s, "model {name}: elements {}", element_counts(&text)).ok();
        s.push_str(&clipped_ends(&text, 50));
    }
    s
}

/// How many of each XML element a document holds, by name, in name order.
fn element_counts(xml: &str) -> String {
    let mut counts = std::collections::BTreeMap::<&str, usize>::new();
    for piece in xml.split('<').skip(1) {
        if piece.starts_with(['/', '?', '!']) {
            continue;
        }
        let name_end = piece
            .find(|c: char| c.is_whitespace() || c == '>' || c == '/')
            .unwrap_or(piece.len());
        *counts.entry(&piece[..name_end]).or_default() += 1;
    }
    let counts: Vec<String> = counts.iter().map(|(n, c)| format!("{n} {c}")).collect();
    counts.join(", ")
}

/// A PNG picture: its header (PNG specification §11.2.2) and digest.
pub fn png(bytes: &[u8]) -> String {
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    if bytes.len() < 33 || &bytes[..8] != SIGNATURE || &bytes[12..16] != b"IHDR" {
        return format!("not a PNG file: {} bytes, {}\n", bytes.len(), digest_bytes(bytes));
    }
    let be = |at: usize| u32::from_be_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
    format!(
        "PNG {} x {}, bit depth {}, colour type {}; {} bytes, {}\n",
        be(16),
        be(20),
        bytes[24],
        bytes[25],
        bytes.len(),
        digest_bytes(bytes)
    )
}

/// A bitmap layer file's data (`docs/formats.md`): per layer of its header (the `.hdr`
/// beside it), how many pixels hold material.
pub fn bitmap_data(bytes: &[u8], path: &Path) -> String {
    let mut s = format!("{} bytes, {}\n", bytes.len(), digest_bytes(bytes));
    let Ok(header) = std::fs::read_to_string(path.with_extension("hdr")) else {
        s.push_str("no header beside it\n");
        return s;
    };
    let rows: Vec<(String, usize)> = header
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .filter_map(|l| {
            let columns: Vec<&str> = l.split_whitespace().collect();
            Some((columns.first()?.to_string(), columns.last()?.parse().ok()?))
        })
        .collect();
    for (i, (layer, offset)) in rows.iter().enumerate() {
        let end = rows.get(i + 1).map_or(bytes.len(), |r| r.1);
        let data = bytes.get(*offset..end.min(bytes.len())).unwrap_or(&[]);
        let material = data.iter().filter(|&&b| b == b'1').count();
        let void = data.iter().filter(|&&b| b == b'0').count();
        writeln!(s, "  layer {layer}: {material} material, {void} void").ok();
    }
    s
}

/// An SVG picture: its size, digest, paths, and its first and last lines.
pub fn svg(text: &str) -> String {
    format!(
        "bytes: {}\ndigest: {}\nelements: {}\n{}",
        text.len(),
        digest_text(text),
        element_counts(text),
        clipped_ends(text, 20)
    )
}

/// Any other text: whole when short, else its digest and ends.
pub fn text(text: &str) -> String {
    if text.len() <= WHOLE {
        return normalise::text(text);
    }
    format!(
        "bytes: {}\nlines: {}\ndigest: {}\n{}",
        text.len(),
        text.lines().count(),
        digest_text(text),
        clipped_ends(text, 50)
    )
}

/// Any other binary file: its size and digest.
pub fn binary(bytes: &[u8]) -> String {
    format!("{} bytes, {}\n", bytes.len(), digest_bytes(bytes))
}
