//! 3MF: the ZIP package's model part (`3D/3dmodel.model`, or the part named by the
//! package relationships), its meshes, components and build items with their
//! transforms, the model's unit, and the base materials of the materials extension as
//! per-triangle material names.
//!
//! Nothing is sized from the file's numbers: vectors grow with what is actually read,
//! the model part is read through a size cap, and component nesting is bounded.

use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

use lamina_api::{Error, Limit, Limits, Mesh, Point3, Result};
use quick_xml::events::{BytesStart, Event};

/// Deepest component nesting followed.
const MAX_DEPTH: usize = 32;

fn err(path: &Path, message: impl Into<String>) -> Error {
    Error::Model {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// A 3x4 affine transform in 3MF's order (row vectors: p' = p M).
type Transform = [f64; 12];

const IDENTITY: Transform = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];

fn apply(m: &Transform, p: Point3) -> Point3 {
    Point3::new(
        p.x * m[0] + p.y * m[3] + p.z * m[6] + m[9],
        p.x * m[1] + p.y * m[4] + p.z * m[7] + m[10],
        p.x * m[2] + p.y * m[5] + p.z * m[8] + m[11],
    )
}

/// `a` then `b`.
fn compose(a: &Transform, b: &Transform) -> Transform {
    let mut out = [0.0; 12];
    for row in 0..4 {
        for col in 0..3 {
            let mut v = if row == 3 { b[9 + col] } else { 0.0 };
            for k in 0..3 {
                v += a[row * 3 + k] * b[k * 3 + col];
            }
            out[row * 3 + col] = v;
        }
    }
    out
}

#[derive(Default)]
struct Object {
    name: Option<String>,
    vertices: Vec<Point3>,
    triangles: Vec<[u32; 3]>,
    /// Per triangle: (property group id, index) when set.
    properties: Vec<Option<(u32, u32)>>,
    default_property: Option<(u32, u32)>,
    components: Vec<(u32, Transform)>,
}

/// Reads a 3MF file into one mesh per build item, within the default limits.
pub fn read(path: &Path, bytes: &[u8]) -> Result<Vec<Mesh>> {
    read_within(path, bytes, &Limits::default())
}

/// Reads a 3MF file into one mesh per build item. The model part is read only up to
/// `limits.model_bytes` uncompressed (a ZIP bomb stops there), and the triangles the
/// build items expand to (components instantiate their objects again and again) are
/// counted before any is copied.
pub fn read_within(path: &Path, bytes: &[u8], limits: &Limits) -> Result<Vec<Mesh>> {
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| err(path, format!("not a 3MF (ZIP) package: {e}")))?;
    let model_name = model_part_name(&mut archive).unwrap_or_else(|| "3D/3dmodel.model".to_string());
    let mut text = String::new();
    {
        let entry = archive
            .by_name(model_name.trim_start_matches('/'))
            .map_err(|e| err(path, format!("no model part `{model_name}`: {e}")))?;
        let what = format!("the model part {model_name} of {}", path.display());
        limits.check(Limit::ModelBytes, entry.size() as f64, &what)?;
        // The declared size may lie: read one byte past the limit to know.
        entry
            .take(limits.model_bytes.saturating_add(1))
            .read_to_string(&mut text)
            .map_err(|e| err(path, format!("{model_name}: cannot read: {e}")))?;
        limits.check(Limit::ModelBytes, text.len() as f64, &what)?;
    }
    parse_model(path, &model_name, &text, limits)
}

/// The model part named by `_rels/.rels` (the 3D model relationship), if any.
fn model_part_name(archive: &mut zip::ZipArchive<std::io::Cursor<&[u8]>>) -> Option<String> {
    let mut rels = String::new();
    archive
        .by_name("_rels/.rels")
        .ok()?
        .take(1 << 20)
        .read_to_string(&mut rels)
        .ok()?;
    let mut reader = quick_xml::Reader::from_str(&rels);
    loop {
        match reader.read_event() {
            Ok(Event::Empty(e) | Event::Start(e)) if e.local_name().as_ref() == "Relationship" => {
                let attrs = attributes(&e).ok()?;
                if attrs.get("Type").is_some_and(|t| t.ends_with("/3dmodel")) {
                    return attrs.get("Target").cloned();
                }
            }
            Ok(Event::Eof) | Err(_) => return None,
            _ => {}
        }
    }
}

fn attributes(e: &BytesStart<'_>) -> std::result::Result<HashMap<String, String>, String> {
    let mut out = HashMap::new();
    for a in e.attributes() {
        let a = a.map_err(|e| e.to_string())?;
        let key = a.key.local_name().as_ref().to_string();
        let value = a
            .normalized_value(quick_xml::XmlVersion::Implicit1_0)
            .map_err(|e| e.to_string())?
            .into_owned();
        out.insert(key, value);
    }
    Ok(out)
}

fn unit_scale(unit: &str) -> Option<f64> {
    Some(match unit {
        "micron" => 0.001,
        "millimeter" => 1.0,
        "centimeter" => 10.0,
        "inch" => 25.4,
        "foot" => 304.8,
        "meter" => 1000.0,
        _ => return None,
    })
}

fn parse_model(path: &Path, part: &str, text: &str, limits: &Limits) -> Result<Vec<Mesh>> {
    let mut reader = quick_xml::Reader::from_str(text);
    let mut doc = Document::new(path, limits);
    loop {
        let site = Site {
            path,
            part,
            text,
            pos: reader.buffer_position(),
        };
        let event = reader
            .read_event()
            .map_err(|e| site.error(format!("malformed XML: {e}")))?;
        match event {
            Event::Start(e) | Event::Empty(e) => {
                let attrs = attributes(&e).map_err(|m| site.error(m))?;
                doc.start(e.local_name().as_ref(), &Element { attrs, site })?;
            }
            Event::End(e) => doc.end(e.local_name().as_ref()),
            Event::Eof => break,
            _ => {}
        }
    }
    doc.into_meshes(part)
}

/// Where an element of the model part starts, for messages that name its line.
#[derive(Clone, Copy)]
struct Site<'a> {
    path: &'a Path,
    part: &'a str,
    text: &'a str,
    /// Byte offset into `text`.
    pos: u64,
}

impl Site<'_> {
    /// `message` at this place. The line is counted only for a message: counting it
    /// for every element would read the part again and again.
    fn error(&self, message: String) -> Error {
        let line = self.text.as_bytes()[..(self.pos as usize).min(self.text.len())]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1;
        err(self.path, format!("{} line {line}: {message}", self.part))
    }
}

/// An element's attributes, with where it starts.
struct Element<'a> {
    attrs: HashMap<String, String>,
    site: Site<'a>,
}

impl Element<'_> {
    /// `message` at the element.
    fn at(&self, message: String) -> Error {
        self.site.error(message)
    }

    fn get(&self, k: &str) -> Option<&String> {
        self.attrs.get(k)
    }

    fn has(&self, k: &str) -> bool {
        self.attrs.contains_key(k)
    }

    /// Attribute `k`, which must be present.
    fn required(&self, k: &str) -> Result<&String> {
        self.get(k)
            .ok_or_else(|| self.at(format!("missing attribute `{k}`")))
    }

    /// Attribute `k` as a finite number.
    fn num(&self, k: &str) -> Result<f64> {
        let v = self.required(k)?;
        let f: f64 = v
            .trim()
            .parse()
            .map_err(|_| self.at(format!("`{k}` = `{v}` is not a number")))?;
        if f.is_finite() {
            Ok(f)
        } else {
            Err(self.at(format!("`{k}` is not finite")))
        }
    }

    /// Attribute `k` as an id or index.
    fn id(&self, k: &str) -> Result<u32> {
        let v = self.required(k)?;
        v.trim()
            .parse()
            .map_err(|_| self.at(format!("`{k}` = `{v}` is not an index")))
    }

    /// The `transform` attribute, the identity when absent.
    fn transform(&self) -> Result<Transform> {
        match self.get("transform") {
            None => Ok(IDENTITY),
            Some(t) => {
                let v: Vec<f64> = t
                    .split_ascii_whitespace()
                    .filter_map(|x| x.parse().ok())
                    .collect();
                if v.len() != 12 || v.iter().any(|x| !x.is_finite()) {
                    return Err(self.at(format!("transform `{t}` is not 12 finite numbers")));
                }
                let mut m = [0.0; 12];
                m.copy_from_slice(&v);
                Ok(m)
            }
        }
    }
}

/// What the model part declares, gathered as its elements are read.
struct Document<'a> {
    path: &'a Path,
    limits: &'a Limits,
    /// Millimetres per model unit.
    scale: f64,
    objects: HashMap<u32, Object>,
    /// The object being read.
    current: Option<(u32, Object)>,
    base_groups: HashMap<u32, Vec<String>>,
    /// The base materials group being read.
    current_group: Option<(u32, Vec<String>)>,
    items: Vec<(u32, Transform)>,
    /// Vertices read so far, over every object.
    vertices: usize,
}

impl<'a> Document<'a> {
    fn new(path: &'a Path, limits: &'a Limits) -> Self {
        Document {
            path,
            limits,
            scale: 1.0,
            objects: HashMap::new(),
            current: None,
            base_groups: HashMap::new(),
            current_group: None,
            items: Vec::new(),
            vertices: 0,
        }
    }

    /// Reads the start of element `name` (or an empty one).
    fn start(&mut self, name: &str, el: &Element<'_>) -> Result<()> {
        match name {
            "model" => {
                if let Some(u) = el.get("unit") {
                    self.scale = unit_scale(u).ok_or_else(|| el.at(format!("unknown unit `{u}`")))?;
                }
            }
            "basematerials" => self.current_group = Some((el.id("id")?, Vec::new())),
            "base" => {
                if let Some((_, names)) = &mut self.current_group {
                    names.push(
                        el.get("name")
                            .cloned()
                            .unwrap_or_else(|| format!("material {}", names.len())),
                    );
                }
            }
            "object" => {
                let mut o = Object {
                    name: el.get("name").cloned(),
                    ..Object::default()
                };
                if el.has("pid") {
                    o.default_property = Some((
                        el.id("pid")?,
                        el.get("pindex").map_or(Ok(0), |_| el.id("pindex"))?,
                    ));
                }
                self.current = Some((el.id("id")?, o));
            }
            "vertex" => self.vertex(el)?,
            "triangle" => self.triangle(el)?,
            "component" => {
                let (_, o) = self
                    .current
                    .as_mut()
                    .ok_or_else(|| el.at("component outside an object".into()))?;
                o.components.push((el.id("objectid")?, el.transform()?));
            }
            "item" => self.items.push((el.id("objectid")?, el.transform()?)),
            _ => {}
        }
        Ok(())
    }

    /// A vertex of the object being read.
    fn vertex(&mut self, el: &Element<'_>) -> Result<()> {
        let (_, o) = self
            .current
            .as_mut()
            .ok_or_else(|| el.at("vertex outside an object".into()))?;
        o.vertices
            .push(Point3::new(el.num("x")?, el.num("y")?, el.num("z")?));
        // More vertices than the allowed triangles could use are refused as they
        // come, before they take the memory.
        self.vertices += 1;
        if self.vertices.is_multiple_of(65_536) {
            vertex_cap(self.path, self.vertices, self.limits)?;
        }
        Ok(())
    }

    /// A triangle of the object being read, with its property (its own, or the
    /// object's default).
    fn triangle(&mut self, el: &Element<'_>) -> Result<()> {
        let (_, o) = self
            .current
            .as_mut()
            .ok_or_else(|| el.at("triangle outside an object".into()))?;
        let t = [el.id("v1")?, el.id("v2")?, el.id("v3")?];
        if t.iter().any(|&v| v as usize >= o.vertices.len()) {
            return Err(el.at(format!(
                "triangle {t:?} names a vertex beyond the {} read",
                o.vertices.len()
            )));
        }
        o.triangles.push(t);
        let prop = if el.has("pid") || el.has("p1") {
            let pid = match el.get("pid") {
                Some(_) => el.id("pid")?,
                None => o.default_property.map_or(0, |d| d.0),
            };
            Some((pid, el.id("p1")?))
        } else {
            o.default_property
        };
        o.properties.push(prop);
        Ok(())
    }

    /// Reads the end of element `name`: an object or a materials group is complete.
    fn end(&mut self, name: &str) {
        match name {
            "object" => {
                if let Some((id, o)) = self.current.take() {
                    self.objects.insert(id, o);
                }
            }
            "basematerials" => {
                if let Some((id, names)) = self.current_group.take() {
                    self.base_groups.insert(id, names);
                }
            }
            _ => {}
        }
    }

    /// All base materials, numbered across groups in id order, and the number of each
    /// group's first.
    fn material_numbers(&self) -> (Vec<String>, HashMap<u32, u32>) {
        let mut group_ids: Vec<u32> = self.base_groups.keys().copied().collect();
        group_ids.sort_unstable();
        let mut material_names = Vec::new();
        let mut group_offset = HashMap::new();
        for g in group_ids {
            group_offset.insert(g, material_names.len() as u32);
            material_names.extend(self.base_groups[&g].iter().cloned());
        }
        (material_names, group_offset)
    }

    /// Refuses a build that expands (with every component instance) to more triangles
    /// than allowed, before any is copied.
    fn check_expansion(&self) -> Result<()> {
        let mut expanded = HashMap::new();
        let mut total = 0.0;
        for (object, _) in &self.items {
            total += expanded_triangles(self.path, &self.objects, *object, 0, &mut expanded)?;
        }
        self.limits.check(
            Limit::Triangles,
            total,
            &format!(
                "{} (its build items with every component instance)",
                self.path.display()
            ),
        )
    }

    /// One mesh per build item of the model part `part`, in millimetres.
    fn into_meshes(mut self, part: &str) -> Result<Vec<Mesh>> {
        let path = self.path;
        if self.items.is_empty() {
            return Err(err(path, format!("{part}: the build has no items")));
        }
        let (material_names, group_offset) = self.material_numbers();
        vertex_cap(path, self.vertices, self.limits)?;
        // Each instance copies its object's vertices: only those its triangles use are
        // kept, so that what the build expands to is bounded by its triangles.
        for o in self.objects.values_mut() {
            o.compact();
        }
        let scale = self.scale;
        let units: Transform = [scale, 0.0, 0.0, 0.0, scale, 0.0, 0.0, 0.0, scale, 0.0, 0.0, 0.0];
        self.check_expansion()?;
        let mut meshes = Vec::new();
        for (n, (object, transform)) in self.items.iter().enumerate() {
            let mut mesh = Mesh::new(format!("item {n}"), Vec::new(), Vec::new());
            let mut any_material = false;
            let mut tri_materials = Vec::new();
            collect(
                path,
                &self.objects,
                *object,
                &compose(transform, &units),
                0,
                &mut mesh,
                &mut tri_materials,
                &group_offset,
                &self.base_groups,
                &mut any_material,
            )?;
            if let Some(name) = self.objects.get(object).and_then(|o| o.name.clone()) {
                mesh.name = name;
            }
            if any_material {
                mesh.triangle_materials = tri_materials;
                mesh.material_names = material_names.clone();
            }
            meshes.push(mesh);
        }
        Ok(meshes)
    }
}

/// Refuses more vertices than three per allowed triangle: no mesh within the
/// triangle limit uses them, and each takes memory.
fn vertex_cap(path: &Path, vertices: usize, limits: &Limits) -> Result<()> {
    limits.check(
        Limit::Triangles,
        vertices as f64 / 3.0,
        &format!("{} (its vertices, three to a triangle)", path.display()),
    )
}

impl Object {
    /// Drops the vertices no triangle of the object uses, renumbering the rest in
    /// their order.
    fn compact(&mut self) {
        let mut used = vec![false; self.vertices.len()];
        for t in &self.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        if used.iter().all(|&u| u) {
            return;
        }
        let mut new_index = vec![u32::MAX; self.vertices.len()];
        let mut kept = Vec::new();
        for (i, p) in self.vertices.iter().enumerate() {
            if used[i] {
                new_index[i] = kept.len() as u32;
                kept.push(*p);
            }
        }
        for t in &mut self.triangles {
            for v in t.iter_mut() {
                *v = new_index[*v as usize];
            }
        }
        self.vertices = kept;
    }
}

/// Object `id`, met `depth` components down; refused past [`MAX_DEPTH`] (a cycle).
fn object_at<'a>(
    path: &Path,
    objects: &'a HashMap<u32, Object>,
    id: u32,
    depth: usize,
) -> Result<&'a Object> {
    if depth > MAX_DEPTH {
        return Err(err(
            path,
            format!("components nest deeper than {MAX_DEPTH} (a cycle?)"),
        ));
    }
    objects
        .get(&id)
        .ok_or_else(|| err(path, format!("the build names object {id}, which is not defined")))
}

/// Triangles object `id` expands to with its components, each object counted once
/// (memoised): a chain of objects that each instantiate the one below twice doubles
/// per level, and is refused before it is built. Floats, so the count cannot wrap.
fn expanded_triangles(
    path: &Path,
    objects: &HashMap<u32, Object>,
    id: u32,
    depth: usize,
    memo: &mut HashMap<u32, f64>,
) -> Result<f64> {
    if let Some(&n) = memo.get(&id) {
        return Ok(n);
    }
    let o = object_at(path, objects, id, depth)?;
    let mut n = o.triangles.len() as f64;
    for (child, _) in &o.components {
        n += expanded_triangles(path, objects, *child, depth + 1, memo)?;
    }
    memo.insert(id, n);
    Ok(n)
}

#[allow(clippy::too_many_arguments)]
fn collect(
    path: &Path,
    objects: &HashMap<u32, Object>,
    id: u32,
    transform: &Transform,
    depth: usize,
    mesh: &mut Mesh,
    tri_materials: &mut Vec<u32>,
    group_offset: &HashMap<u32, u32>,
    groups: &HashMap<u32, Vec<String>>,
    any_material: &mut bool,
) -> Result<()> {
    let o = object_at(path, objects, id, depth)?;
    let base = mesh.vertices.len() as u32;
    mesh.vertices
        .extend(o.vertices.iter().map(|&p| apply(transform, p)));
    for (t, prop) in o.triangles.iter().zip(&o.properties) {
        mesh.triangles.push([t[0] + base, t[1] + base, t[2] + base]);
        let material = prop
            .and_then(|(pid, p)| {
                let names = groups.get(&pid)?;
                ((p as usize) < names.len()).then(|| group_offset[&pid] + p)
            })
            .inspect(|_| *any_material = true)
            .unwrap_or(u32::MAX);
        tri_materials.push(material);
    }
    for (child, t) in &o.components {
        collect(
            path,
            objects,
            *child,
            &compose(t, transform),
            depth + 1,
            mesh,
            tri_materials,
            group_offset,
            groups,
            any_material,
        )?;
    }
    Ok(())
}

/// Writes meshes as a 3MF package (millimetres, one object and build item per mesh,
/// base materials when the mesh carries them).
pub fn write(meshes: &[Mesh]) -> std::io::Result<Vec<u8>> {
    use std::fmt::Write as _;
    use std::io::Write as _;
    let mut model = String::from(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<model unit=\"millimeter\" xml:lang=\"en-US\" \
         xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\">\n <resources>\n",
    );
    let escape = |s: &str| {
        s.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('"', "&quot;")
    };
    let mut items = Vec::new();
    for (k, mesh) in meshes.iter().enumerate() {
        // Ids 2k + 1 for the mesh's materials, 2k + 2 for its object.
        let group = (!mesh.material_names.is_empty()
            && mesh.triangle_materials.len() == mesh.triangles.len())
        .then(|| {
            let id = 2 * k + 1;
            let _ = write!(model, "  <basematerials id=\"{id}\">");
            for name in &mesh.material_names {
                let _ = write!(
                    model,
                    "<base name=\"{}\" displaycolor=\"#808080\"/>",
                    escape(name)
                );
            }
            model.push_str("</basematerials>\n");
            id
        });
        let id = 2 * k + 2;
        let _ = write!(
            model,
            "  <object id=\"{id}\" type=\"model\" name=\"{}\">\n   <mesh>\n    <vertices>\n",
            escape(&mesh.name)
        );
        for v in &mesh.vertices {
            let _ = writeln!(model, "     <vertex x=\"{}\" y=\"{}\" z=\"{}\"/>", v.x, v.y, v.z);
        }
        model.push_str("    </vertices>\n    <triangles>\n");
        for (i, t) in mesh.triangles.iter().enumerate() {
            let _ = write!(
                model,
                "     <triangle v1=\"{}\" v2=\"{}\" v3=\"{}\"",
                t[0], t[1], t[2]
            );
            if let (Some(g), Some(&m)) = (group, mesh.triangle_materials.get(i))
                && m != u32::MAX
            {
                let _ = write!(model, " pid=\"{g}\" p1=\"{m}\"");
            }
            model.push_str("/>\n");
        }
        model.push_str("    </triangles>\n   </mesh>\n  </object>\n");
        items.push(id);
    }
    model.push_str(" </resources>\n <build>\n");
    for id in items {
        let _ = writeln!(model, "  <item objectid=\"{id}\"/>");
    }
    model.push_str(" </build>\n</model>\n");

    let mut out = std::io::Cursor::new(Vec::new());
    let mut zip = zip::ZipWriter::new(&mut out);
    let options = zip::write::SimpleFileOptions::default();
    let zerr = |e: zip::result::ZipError| std::io::Error::other(e);
    zip.start_file("[Content_Types].xml", options).map_err(zerr)?;
    zip.write_all(
        b"<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Types xmlns=\"http://schemas.openxmlformats.org/package/2006/content-types\">\
<Default Extension=\"rels\" ContentType=\"application/vnd.openxmlformats-package.relationships+xml\"/>\
<Default Extension=\"model\" ContentType=\"application/vnd.ms-package.3dmanufacturing-3dmodel+xml\"/></Types>\n",
    )?;
    zip.start_file("_rels/.rels", options).map_err(zerr)?;
    zip.write_all(
        b"<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Relationships xmlns=\"http://schemas.openxmlformats.org/package/2006/relationships\">\
<Relationship Target=\"/3D/3dmodel.model\" Id=\"rel0\" Type=\"http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel\"/></Relationships>\n",
    )?;
    zip.start_file("3D/3dmodel.model", options).map_err(zerr)?;
    zip.write_all(model.as_bytes())?;
    zip.finish().map_err(zerr)?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn package(model: &str) -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut zip = zip::ZipWriter::new(&mut out);
        let options = zip::write::SimpleFileOptions::default();
        zip.start_file("3D/3dmodel.model", options).expect("entry");
        zip.write_all(model.as_bytes()).expect("write");
        zip.finish().expect("finish");
        out.into_inner()
    }

    const TETRA: &str = r##"<?xml version="1.0" encoding="UTF-8"?>
<model unit="centimeter" xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">
 <resources>
  <basematerials id="1"><base name="ceramic" displaycolor="#FFFFFF"/><base name="metal" displaycolor="#808080"/></basematerials>
  <object id="2" type="model" pid="1" pindex="0">
   <mesh>
    <vertices><vertex x="0" y="0" z="0"/><vertex x="1" y="0" z="0"/><vertex x="0" y="1" z="0"/><vertex x="0" y="0" z="1"/></vertices>
    <triangles><triangle v1="0" v2="2" v3="1"/><triangle v1="0" v2="1" v3="3" pid="1" p1="1"/><triangle v1="1" v2="2" v3="3"/><triangle v1="0" v2="3" v3="2"/></triangles>
   </mesh>
  </object>
  <object id="3" type="model"><components><component objectid="2" transform="1 0 0 0 1 0 0 0 1 5 0 0"/></components></object>
 </resources>
 <build><item objectid="2"/><item objectid="3" transform="1 0 0 0 1 0 0 0 1 0 0 2"/></build>
</model>"##;

    #[test]
    fn items_components_units_and_materials_are_read() {
        let meshes = read(Path::new("t.3mf"), &package(TETRA)).expect("reads");
        assert_eq!(meshes.len(), 2);
        let m = &meshes[0];
        assert_eq!(m.triangles.len(), 4);
        // centimetres to millimetres
        assert!((m.bbox().max.x - 10.0).abs() < 1e-12);
        assert!(m.signed_volume() > 0.0);
        assert_eq!(m.material_names, vec!["ceramic".to_string(), "metal".to_string()]);
        assert_eq!(m.triangle_materials, vec![0, 1, 0, 0]);
        // component offset 5 cm in x, then the item 2 cm up
        let b = meshes[1].bbox();
        assert!(
            (b.min.x - 50.0).abs() < 1e-12 && (b.min.z - 20.0).abs() < 1e-12,
            "{b:?}"
        );
    }

    #[test]
    fn written_packages_read_back() {
        let meshes = read(Path::new("t.3mf"), &package(TETRA)).expect("reads");
        let again = read(Path::new("w.3mf"), &write(&meshes).expect("writes")).expect("reads back");
        assert_eq!(again.len(), 2);
        assert_eq!(again[0].vertices, meshes[0].vertices);
        let names = |m: &Mesh| -> Vec<String> {
            m.triangle_materials
                .iter()
                .map(|&i| m.material_names[i as usize].clone())
                .collect()
        };
        assert_eq!(names(&again[0]), names(&meshes[0]));
        assert_eq!(names(&again[1]), names(&meshes[1]));
    }

    /// One object of many vertices and few triangles, instanced a thousand times:
    /// only the vertices its triangles use are copied, so it reads small; more
    /// vertices than the triangle limit could use are refused as they are read.
    #[test]
    fn instanced_vertices_are_bounded_by_the_triangles() {
        let mut spare = String::new();
        for i in 0..20_000 {
            spare.push_str(&format!("<vertex x=\"{i}\" y=\"0\" z=\"0\"/>"));
        }
        let components: String = (0..1000)
            .map(|i| format!("<component objectid=\"2\" transform=\"1 0 0 0 1 0 0 0 1 {i} 0 0\"/>"))
            .collect();
        let model = format!(
            "<?xml version=\"1.0\"?><model unit=\"millimeter\" xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\"><resources>\
             <object id=\"2\" type=\"model\"><mesh><vertices>\
             <vertex x=\"0\" y=\"0\" z=\"0\"/><vertex x=\"1\" y=\"0\" z=\"0\"/><vertex x=\"0\" y=\"1\" z=\"0\"/><vertex x=\"0\" y=\"0\" z=\"1\"/>{spare}\
             </vertices><triangles><triangle v1=\"0\" v2=\"2\" v3=\"1\"/><triangle v1=\"0\" v2=\"1\" v3=\"3\"/>\
             <triangle v1=\"0\" v2=\"3\" v3=\"2\"/><triangle v1=\"1\" v2=\"2\" v3=\"3\"/></triangles></mesh></object>\
             <object id=\"3\" type=\"model\"><components>{components}</components></object>\
             </resources><build><item objectid=\"3\"/></build></model>"
        );
        let meshes = read(Path::new("bomb.3mf"), &package(&model)).expect("reads");
        assert_eq!(meshes[0].triangles.len(), 4000);
        assert_eq!(meshes[0].vertices.len(), 4000, "four vertices per instance");
        // With room for 1000 triangles, 20,004 vertices are more than they could use.
        let limits = Limits {
            triangles: 1000,
            ..Limits::default()
        };
        let e = read_within(Path::new("bomb.3mf"), &package(&model), &limits).expect_err("too many vertices");
        assert!(e.to_string().contains("vertices"), "{e}");
    }

    #[test]
    fn bad_packages_are_errors() {
        assert!(read(Path::new("t.3mf"), b"not a zip").is_err());
        let bad = TETRA.replace("v3=\"1\"", "v3=\"9\"");
        let e = read(Path::new("t.3mf"), &package(&bad)).expect_err("bad index");
        assert!(e.to_string().contains("line 8"), "{e}");
        let bad = TETRA.replace("x=\"1\"", "x=\"nan\"");
        assert!(read(Path::new("t.3mf"), &package(&bad)).is_err());
        let cyclic = TETRA.replace("component objectid=\"2\"", "component objectid=\"3\"");
        assert!(read(Path::new("t.3mf"), &package(&cyclic)).is_err());
    }
}
