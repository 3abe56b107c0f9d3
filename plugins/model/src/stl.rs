//! STL, binary and ASCII. A binary file may begin with the word `solid` in its 80-byte
//! header, so the format is decided by size first: a file whose length is exactly
//! 84 + 50 n for the triangle count n in its header is binary. Nothing is ever
//! allocated from the header's count before that count is checked against the file size.

use std::path::Path;

use lamina_api::{Error, Mesh, Point3, Result};

use crate::weld::{MeshWelder, Soup};

/// Parses STL bytes into a triangle soup. `path` names the file in errors.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Vec<(String, Soup)>> {
    if let Some(count) = binary_count(bytes) {
        let expected = 84u64 + 50 * u64::from(count);
        if expected == bytes.len() as u64 {
            return Ok(vec![(name_of(path), parse_binary(path, bytes, count as usize)?)]);
        }
        if !looks_ascii(bytes) {
            return Err(model_error(
                path,
                format!(
                    "binary STL header claims {count} triangles ({expected} bytes) but the file holds {} bytes{}",
                    bytes.len(),
                    if (bytes.len() as u64) < expected {
                        ": truncated?"
                    } else {
                        ""
                    }
                ),
            ));
        }
    }
    if looks_ascii(bytes) {
        return parse_ascii(path, bytes);
    }
    Err(model_error(
        path,
        format!(
            "{} bytes: too short for a binary STL and not ASCII STL",
            bytes.len()
        ),
    ))
}

fn name_of(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "stl".into())
}

fn model_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Model {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn binary_count(bytes: &[u8]) -> Option<u32> {
    let c = bytes.get(80..84)?;
    Some(u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
}

fn looks_ascii(bytes: &[u8]) -> bool {
    let start = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(bytes.len());
    bytes[start..].starts_with(b"solid")
        && bytes
            .iter()
            .take(4096)
            .all(|&b| b.is_ascii() && (b >= 0x20 || b.is_ascii_whitespace()))
}

fn parse_binary(path: &Path, bytes: &[u8], count: usize) -> Result<Soup> {
    let mut triangles = Vec::with_capacity(count);
    for (i, rec) in bytes[84..].chunks_exact(50).enumerate() {
        triangles.push(record(path, i, rec)?);
    }
    Ok(Soup { triangles })
}

/// The corners of binary record `i`, refused when a coordinate is not finite.
fn record(path: &Path, i: usize, rec: &[u8]) -> Result<[Point3; 3]> {
    let f = |k: usize| {
        let o = 12 + 4 * k;
        f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]])
    };
    let mut tri = [Point3::origin(); 3];
    for (v, corner) in tri.iter_mut().enumerate() {
        let (x, y, z) = (f(3 * v), f(3 * v + 1), f(3 * v + 2));
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            return Err(model_error(
                path,
                format!("triangle {i} (byte {}) has a non-finite coordinate", 84 + 50 * i),
            ));
        }
        *corner = Point3::new(f64::from(x), f64::from(y), f64::from(z));
    }
    Ok(tri)
}

/// Reads an STL file into welded meshes (see [`crate::weld::weld`]): the same meshes
/// as [`parse`] and welding, but a binary file is welded while it is read, a block of
/// records at a time, so neither the file nor its soup of corners is ever held whole.
/// On large meshes those two buffers cost more than the welding (fresh memory is
/// faulted in page by page).
pub fn read_welded(path: &Path, tolerance: f64) -> Result<Vec<Mesh>> {
    use std::io::Read;
    let io = |e| Error::io(path, e);
    let mut file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    let mut header = [0u8; 84];
    if len >= 84 {
        file.read_exact(&mut header).map_err(io)?;
        let count = binary_count(&header).unwrap_or(0);
        if 84 + 50 * u64::from(count) == len {
            return Ok(vec![weld_binary(path, &mut file, count as usize, tolerance)?]);
        }
    }
    let mut bytes = Vec::with_capacity(len as usize);
    if len >= 84 {
        bytes.extend_from_slice(&header);
    }
    file.read_to_end(&mut bytes).map_err(io)?;
    Ok(parse(path, &bytes)?
        .into_iter()
        .map(|(name, soup)| crate::weld::weld(&name, &soup, tolerance).0)
        .collect())
}

/// Welds the `count` records that follow the header in `file`.
fn weld_binary(path: &Path, file: &mut impl std::io::Read, count: usize, tolerance: f64) -> Result<Mesh> {
    const BLOCK: usize = 4096;
    let mut welder = MeshWelder::new(tolerance, count);
    let mut buf = vec![0u8; 50 * BLOCK.min(count)];
    let mut triangles = Vec::with_capacity(MeshWelder::BLOCK);
    let mut done = 0;
    while done < count {
        let n = BLOCK.min(count - done);
        let block = &mut buf[..50 * n];
        file.read_exact(block).map_err(|e| Error::io(path, e))?;
        for (k, recs) in block.chunks(50 * MeshWelder::BLOCK).enumerate() {
            triangles.clear();
            for (j, rec) in recs.chunks_exact(50).enumerate() {
                triangles.push(record(path, done + k * MeshWelder::BLOCK + j, rec)?);
            }
            welder.push(&triangles);
        }
        done += n;
    }
    Ok(welder.finish(&name_of(path)).0)
}

fn parse_ascii(path: &Path, bytes: &[u8]) -> Result<Vec<(String, Soup)>> {
    let text =
        std::str::from_utf8(bytes).map_err(|e| model_error(path, format!("ASCII STL is not UTF-8: {e}")))?;
    let mut solids = Vec::new();
    let mut current: Option<(String, Soup)> = None;
    let mut corners: Vec<Point3> = Vec::with_capacity(3);
    let mut in_loop = false;
    let mut line_no = 0;
    for line in text.lines() {
        line_no += 1;
        let mut words = line.split_ascii_whitespace();
        let Some(keyword) = words.next() else { continue };
        let err = |m: String| model_error(path, format!("line {line_no}: {m}"));
        match keyword {
            "solid" => {
                if current.is_some() {
                    return Err(err("`solid` inside a solid (missing `endsolid`)".into()));
                }
                let name = words.collect::<Vec<_>>().join(" ");
                let name = if name.is_empty() { name_of(path) } else { name };
                current = Some((name, Soup::default()));
            }
            "endsolid" => match current.take() {
                Some(s) => solids.push(s),
                None => return Err(err("`endsolid` without `solid`".into())),
            },
            "facet" | "endfacet" => {
                if current.is_none() {
                    return Err(err(format!("`{keyword}` outside a solid")));
                }
            }
            "outer" => {
                in_loop = true;
                corners.clear();
            }
            "vertex" => {
                if !in_loop {
                    return Err(err("`vertex` outside `outer loop`".into()));
                }
                let mut c = [0.0f64; 3];
                for v in &mut c {
                    let w = words
                        .next()
                        .ok_or_else(|| err("`vertex` needs three coordinates".into()))?;
                    *v = w.parse().map_err(|_| err(format!("`{w}` is not a number")))?;
                    if !v.is_finite() {
                        return Err(err(format!("non-finite coordinate `{w}`")));
                    }
                }
                if corners.len() == 3 {
                    return Err(err("a facet with more than three vertices".into()));
                }
                corners.push(Point3::new(c[0], c[1], c[2]));
            }
            "endloop" => {
                if corners.len() != 3 {
                    return Err(err(format!("a facet with {} vertices", corners.len())));
                }
                in_loop = false;
                let soup = &mut current
                    .as_mut()
                    .ok_or_else(|| err("facet outside a solid".into()))?
                    .1;
                soup.triangles.push([corners[0], corners[1], corners[2]]);
            }
            other => return Err(err(format!("unexpected `{other}`"))),
        }
    }
    if let Some((name, soup)) = current {
        if in_loop || !corners.is_empty() && corners.len() < 3 {
            return Err(model_error(
                path,
                format!("truncated: file ends inside a facet (line {line_no})"),
            ));
        }
        // A missing `endsolid` is common and harmless.
        solids.push((name, soup));
    }
    if solids.is_empty() {
        return Err(model_error(path, "no solid in ASCII STL"));
    }
    Ok(solids)
}

/// Writes a mesh as binary STL (used by the generators' `lamina` tooling and tests).
pub fn write_binary(mesh: &lamina_api::Mesh, out: &mut impl std::io::Write) -> std::io::Result<()> {
    let mut header = [0u8; 80];
    let title = format!("lamina binary STL: {}", mesh.name);
    let n = title.len().min(80);
    header[..n].copy_from_slice(&title.as_bytes()[..n]);
    out.write_all(&header)?;
    out.write_all(&(mesh.triangles.len() as u32).to_le_bytes())?;
    for i in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.triangle(i);
        let n = (b - a).cross(&(c - a));
        let n = if n.norm() > 0.0 { n.normalize() } else { n };
        for v in [n.x, n.y, n.z, a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z] {
            out.write_all(&(v as f32).to_le_bytes())?;
        }
        out.write_all(&[0, 0])?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII: &str = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n";

    fn binary(count_claim: u32, triangles: usize, header: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8; 80];
        b[..header.len()].copy_from_slice(header);
        b.extend_from_slice(&count_claim.to_le_bytes());
        for _ in 0..triangles {
            let mut rec = vec![0u8; 50];
            rec[24..28].copy_from_slice(&1.0f32.to_le_bytes());
            rec[40..44].copy_from_slice(&1.0f32.to_le_bytes());
            b.extend_from_slice(&rec);
        }
        b
    }

    #[test]
    fn ascii_is_read() {
        let s = parse(Path::new("t.stl"), ASCII.as_bytes()).expect("parses");
        assert_eq!(s.len(), 1);
        assert_eq!(s[0].1.triangles.len(), 1);
    }

    #[test]
    fn binary_with_solid_header_is_binary() {
        let b = binary(2, 2, b"solid but binary");
        let s = parse(Path::new("t.stl"), &b).expect("parses");
        assert_eq!(s[0].1.triangles.len(), 2);
    }

    #[test]
    fn lying_header_is_an_error_not_an_allocation() {
        let b = binary(u32::MAX, 2, b"x");
        let e = parse(Path::new("t.stl"), &b).expect_err("refused");
        assert!(e.to_string().contains("claims 4294967295 triangles"), "{e}");
    }

    #[test]
    fn truncated_and_non_finite_are_errors() {
        let mut b = binary(2, 2, b"x");
        b.truncate(b.len() - 10);
        assert!(parse(Path::new("t.stl"), &b).is_err());
        let mut b = binary(1, 1, b"x");
        b[84 + 12..84 + 16].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = parse(Path::new("t.stl"), &b).expect_err("nan");
        assert!(e.to_string().contains("non-finite"), "{e}");
        let text = ASCII.replace("vertex 1 0 0", "vertex 1 nan 0");
        assert!(parse(Path::new("t.stl"), text.as_bytes()).is_err());
        let text = &ASCII[..ASCII.find("vertex 0 1 0").expect("in text")];
        let e = parse(Path::new("t.stl"), text.as_bytes()).expect_err("truncated ascii");
        assert!(e.to_string().contains("truncated"), "{e}");
        assert!(parse(Path::new("t.stl"), b"").is_err());
    }

    /// Welding while reading gives the meshes of parsing and welding, for binary files
    /// of several blocks (a partial last one) and for the files that are read whole.
    #[test]
    fn read_welded_is_parse_then_weld() {
        let dir = tempfile::tempdir().expect("temporary directory");
        // A strip of triangles sharing corners, one of them degenerate.
        let count = 4096 + 100;
        let mut b = vec![0u8; 80];
        b.extend_from_slice(&(count as u32).to_le_bytes());
        for i in 0..count {
            let x = (i / 2) as f32;
            let corners = if i == 7 {
                [[x, 0.0, 0.0], [x, 0.0, 0.0], [x, 1.0, 0.0]]
            } else if i % 2 == 0 {
                [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.5]]
            } else {
                [[x + 1.0, 0.0, 0.0], [x + 1.0, 1.0, 0.5], [x, 1.0, 0.5]]
            };
            b.extend_from_slice(&[0u8; 12]);
            for c in corners.as_flattened() {
                b.extend_from_slice(&c.to_le_bytes());
            }
            b.extend_from_slice(&[0u8; 2]);
        }
        let mut nan = binary(1, 1, b"x");
        nan[84 + 12..84 + 16].copy_from_slice(&f32::NAN.to_le_bytes());
        for (name, bytes) in [
            ("strip.stl", b.clone()),
            ("solid.stl", binary(2, 2, b"solid but binary")),
            ("t.stl", ASCII.as_bytes().to_vec()),
            ("truncated.stl", b[..b.len() - 10].to_vec()),
            ("nan.stl", nan),
            ("empty.stl", Vec::new()),
        ] {
            let path = dir.path().join(name);
            std::fs::write(&path, &bytes).expect("write");
            let expected = parse(&path, &bytes).map(|soups| {
                soups
                    .into_iter()
                    .map(|(n, soup)| crate::weld::weld(&n, &soup, 1e-5).0)
                    .collect::<Vec<_>>()
            });
            match (read_welded(&path, 1e-5), expected) {
                (Ok(got), Ok(expected)) => {
                    assert_eq!(got.len(), expected.len(), "{name}");
                    for (g, e) in got.iter().zip(&expected) {
                        assert_eq!(g.name, e.name, "{name}");
                        assert_eq!(g.vertices, e.vertices, "{name}");
                        assert_eq!(g.triangles, e.triangles, "{name}");
                        assert_eq!(g.warnings, e.warnings, "{name}");
                    }
                }
                (Err(got), Err(expected)) => assert_eq!(got.to_string(), expected.to_string(), "{name}"),
                (got, expected) => panic!("{name}: {:?} vs {:?}", got.is_ok(), expected.is_ok()),
            }
        }
    }
}
