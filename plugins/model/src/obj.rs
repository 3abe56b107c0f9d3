//! Wavefront OBJ: `v` vertices and `f` faces (any of `v`, `v/vt`, `v//vn`, `v/vt/vn`,
//! negative indices counting back), polygons fanned into triangles, `o` objects as
//! separate meshes and `usemtl` names as per-triangle materials.

use std::path::Path;

use lamina_api::{Error, Mesh, Point3, Result};

fn model_error(path: &Path, line: usize, message: impl Into<String>) -> Error {
    Error::Model {
        path: path.to_path_buf(),
        message: format!("line {line}: {}", message.into()),
    }
}

/// Parses OBJ text into one mesh per object (vertices are shared file-wide in OBJ, so
/// each mesh keeps only the vertices its faces use).
pub fn parse(path: &Path, text: &str) -> Result<Vec<Mesh>> {
    let mut vertices: Vec<Point3> = Vec::new();
    let mut objects: Vec<(String, Vec<[u32; 3]>, Vec<u32>)> = Vec::new();
    let mut materials: Vec<String> = Vec::new();
    let mut current_material: Option<u32> = None;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "obj".into());
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = line.split('#').next().unwrap_or("");
        let mut words = line.split_ascii_whitespace();
        match words.next() {
            Some("v") => {
                let mut c = [0.0f64; 3];
                for v in &mut c {
                    let w = words
                        .next()
                        .ok_or_else(|| model_error(path, line_no, "`v` needs three coordinates"))?;
                    *v = w
                        .parse()
                        .map_err(|_| model_error(path, line_no, format!("`{w}` is not a number")))?;
                    if !v.is_finite() {
                        return Err(model_error(path, line_no, format!("non-finite coordinate `{w}`")));
                    }
                }
                vertices.push(Point3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let mut ids = Vec::new();
                for w in words {
                    let first = w.split('/').next().unwrap_or("");
                    let k: i64 = first.parse().map_err(|_| {
                        model_error(path, line_no, format!("`{w}` is not a vertex reference"))
                    })?;
                    let n = vertices.len() as i64;
                    let idx = if k > 0 { k - 1 } else { n + k };
                    if k == 0 || idx < 0 || idx >= n {
                        return Err(model_error(
                            path,
                            line_no,
                            format!("vertex {k} does not exist ({n} vertices so far)"),
                        ));
                    }
                    ids.push(idx as u32);
                }
                if ids.len() < 3 {
                    return Err(model_error(path, line_no, "a face needs at least three vertices"));
                }
                if objects.is_empty() {
                    objects.push((stem.clone(), Vec::new(), Vec::new()));
                }
                let obj = objects.last_mut().expect("pushed above");
                for k in 1..ids.len() - 1 {
                    obj.1.push([ids[0], ids[k], ids[k + 1]]);
                    if let Some(m) = current_material {
                        obj.2.push(m);
                    }
                }
            }
            Some("o") => {
                let name = words.collect::<Vec<_>>().join(" ");
                objects.push((
                    if name.is_empty() { stem.clone() } else { name },
                    Vec::new(),
                    Vec::new(),
                ));
            }
            Some("usemtl") => {
                let name = words.collect::<Vec<_>>().join(" ");
                let id = match materials.iter().position(|m| *m == name) {
                    Some(i) => i,
                    None => {
                        materials.push(name);
                        materials.len() - 1
                    }
                };
                current_material = Some(id as u32);
            }
            _ => {}
        }
    }
    let mut meshes = Vec::new();
    for (name, tris, mats) in objects {
        if tris.is_empty() {
            continue;
        }
        // Keep only the vertices this object uses, renumbered.
        let mut map = vec![u32::MAX; vertices.len()];
        let mut verts = Vec::new();
        let tris: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| {
                t.map(|v| {
                    let slot = &mut map[v as usize];
                    if *slot == u32::MAX {
                        verts.push(vertices[v as usize]);
                        *slot = (verts.len() - 1) as u32;
                    }
                    *slot
                })
            })
            .collect();
        let mut mesh = Mesh::new(name, verts, tris);
        if mats.len() == mesh.triangles.len() {
            mesh.triangle_materials = mats;
            mesh.material_names = materials.clone();
        }
        meshes.push(mesh);
    }
    if meshes.is_empty() {
        return Err(Error::Model {
            path: path.to_path_buf(),
            message: "no faces".into(),
        });
    }
    Ok(meshes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_are_fanned_and_objects_split() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\no a\nusemtl red\nf 1/1/1 2/2/2 3/3/3 4/4/4\no b\nf -4 -3 -2\n";
        let m = parse(Path::new("t.obj"), text).expect("parses");
        assert_eq!(m.len(), 2);
        assert_eq!(m[0].triangles.len(), 2);
        assert_eq!(m[0].material_names, vec!["red".to_string()]);
        assert_eq!(m[1].vertices.len(), 3);
    }

    #[test]
    fn bad_references_are_located() {
        let e = parse(Path::new("t.obj"), "v 0 0 0\nf 1 2 3\n").expect_err("bad");
        assert!(e.to_string().contains("line 2"), "{e}");
    }
}
