//! `3mf`: the plan as a 3MF package with the materials extension. Every sub-region of
//! every layer becomes a closed prism (its polygon extruded over the layer's
//! thickness), coloured by a composite material that mixes the primary materials in
//! the region's fractions; slicers and viewers that read 3MF materials see the graded
//! object. Each layer of each part is one object; each layer declares the composites
//! its regions use just before its objects, so the package streams layer by layer.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{Contour, Error, LayerPlan, Polygon, Result, RunInfo, StageFactory};
use zip::ZipWriter;
use zip::write::{SimpleFileOptions, StreamWriter};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// output file, relative to the output folder
        path: PathBuf = r#""plan.3mf""#,
    }
}

struct ThreeMf {
    options: Options,
}

type Package = ZipWriter<StreamWriter<Box<dyn Write + Send>>>;

struct Sink {
    zip: Package,
    path: PathBuf,
    /// Next free resource id (1 is the base materials).
    next_id: usize,
    /// Objects to place in the build.
    objects: Vec<usize>,
    text: String,
}

fn xml_escape(s: &str) -> String {
    // XML 1.0 allows no control character but tab and line breaks, not even as a
    // reference, and a name is one line: each becomes a space.
    lamina_api::text::one_line(s)
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn zip_error(path: &std::path::Path) -> impl Fn(zip::result::ZipError) -> Error + '_ {
    move |e| Error::io(path, std::io::Error::other(e))
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

/// The XML of one object's mesh, built prism by prism.
#[derive(Default)]
struct MeshText {
    vertices: String,
    triangles: String,
    /// Vertices written so far.
    base: usize,
}

impl MeshText {
    /// Appends the prism of `polygon` between `z0` and `z1`, all triangles carrying
    /// property `p1` of group `pid`. Every prism is a closed shell of its own, wound
    /// outward.
    fn prism(&mut self, polygon: &Polygon, z0: f64, z1: f64, pid: usize, p1: usize) {
        let (vertices, triangles) = (&mut self.vertices, &mut self.triangles);
        let rings: Vec<Contour> = std::iter::once(polygon.outer.clone().oriented(true))
            .chain(polygon.holes.iter().map(|h| h.clone().oriented(false)))
            .filter(|r| r.len() >= 3)
            .collect();
        if rings.is_empty() || rings[0].area() <= 0.0 {
            return;
        }
        let mut flat: Vec<[f64; 2]> = Vec::new();
        let mut hole_starts: Vec<u32> = Vec::new();
        for (i, r) in rings.iter().enumerate() {
            if i > 0 {
                hole_starts.push(flat.len() as u32);
            }
            flat.extend(r.points.iter().map(|p| [p.x, p.y]));
        }
        let mut cap: Vec<u32> = Vec::new();
        earcut::Earcut::new().earcut(flat.iter().copied(), &hole_starts, &mut cap);
        let n = flat.len();
        for z in [z0, z1] {
            for p in &flat {
                let _ = writeln!(vertices, "<vertex x=\"{}\" y=\"{}\" z=\"{z}\"/>", p[0], p[1]);
            }
        }
        let b = self.base;
        let mut tri = |a: usize, c: usize, d: usize| {
            let _ = writeln!(
                triangles,
                "<triangle v1=\"{}\" v2=\"{}\" v3=\"{}\" pid=\"{pid}\" p1=\"{p1}\"/>",
                b + a,
                b + c,
                b + d
            );
        };
        for t in cap.chunks_exact(3) {
            let (i, j, k) = (t[0] as usize, t[1] as usize, t[2] as usize);
            let (a, c, d) = (flat[i], flat[j], flat[k]);
            let ccw = (c[0] - a[0]) * (d[1] - a[1]) - (c[1] - a[1]) * (d[0] - a[0]) > 0.0;
            let (j, k) = if ccw { (j, k) } else { (k, j) };
            tri(i + n, j + n, k + n); // top faces up
            tri(i, k, j); // bottom faces down
        }
        let mut start = 0;
        for r in &rings {
            let len = r.len();
            for e in 0..len {
                let a = start + e;
                let c = start + (e + 1) % len;
                tri(a, c, c + n);
                tri(a, c + n, a + n);
            }
            start += len;
        }
        self.base += 2 * n;
    }
}

impl Exporter for ThreeMf {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let out = ctx.files.create(&self.options.path)?;
        let path = self.options.path.clone();
        let mut zip = ZipWriter::new_stream(out);
        let options = SimpleFileOptions::default();
        let ze = zip_error(&path);
        zip.start_file("[Content_Types].xml", options).map_err(&ze)?;
        zip.write_all(
            b"<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Types xmlns=\"http://schemas.openxmlformats.org/package/2006/content-types\">\
<Default Extension=\"rels\" ContentType=\"application/vnd.openxmlformats-package.relationships+xml\"/>\
<Default Extension=\"model\" ContentType=\"application/vnd.ms-package.3dmanufacturing-3dmodel+xml\"/></Types>\n",
        )
        .map_err(io(&path))?;
        zip.start_file("_rels/.rels", options).map_err(&ze)?;
        zip.write_all(
            b"<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Relationships xmlns=\"http://schemas.openxmlformats.org/package/2006/relationships\">\
<Relationship Target=\"/3D/3dmodel.model\" Id=\"rel0\" Type=\"http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel\"/></Relationships>\n",
        )
        .map_err(io(&path))?;
        zip.start_file("3D/3dmodel.model", options.large_file(true))
            .map_err(&ze)?;
        let mut head = String::from(
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<model unit=\"millimeter\" xml:lang=\"en-US\" \
             xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\" \
             xmlns:m=\"http://schemas.microsoft.com/3dmanufacturing/material/2015/02\" requiredextensions=\"m\">\n",
        );
        let _ = writeln!(
            head,
            "<metadata name=\"Title\">{}</metadata>\n<metadata name=\"Application\">Lamina {}</metadata>\n<resources>\n<basematerials id=\"1\">",
            xml_escape(ctx.pipeline_name),
            lamina_api::VERSION
        );
        for m in &ctx.info.materials {
            let [r, g, b] = m.colour;
            let _ = writeln!(
                head,
                "<base name=\"{}\" displaycolor=\"#{r:02X}{g:02X}{b:02X}FF\"/>",
                xml_escape(&m.name)
            );
        }
        head.push_str("</basematerials>\n");
        zip.write_all(head.as_bytes()).map_err(io(&path))?;
        drop(ze);
        Ok(Box::new(Sink {
            zip,
            path,
            next_id: 2,
            objects: Vec::new(),
            text: String::new(),
        }))
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        let n_materials = info.materials.len();
        // The layer's compositions over all pipeline materials, each once.
        let mut composites: Vec<Vec<f64>> = Vec::new();
        let mut index: HashMap<Vec<u64>, usize> = HashMap::new();
        let mut region_composite: Vec<Vec<usize>> = Vec::new();
        for pl in &plan.parts {
            let part = &info.parts[pl.part];
            let mut ids = Vec::new();
            for r in &pl.regions {
                let mut values = vec![0.0; n_materials];
                if let Some(c) = &r.composition {
                    for (&m, &f) in part.materials.iter().zip(&c.fractions) {
                        values[m] += f;
                    }
                }
                let key: Vec<u64> = values.iter().map(|v| v.to_bits()).collect();
                let id = *index.entry(key).or_insert_with(|| {
                    composites.push(values);
                    composites.len() - 1
                });
                ids.push(id);
            }
            region_composite.push(ids);
        }
        if composites.is_empty() {
            return Ok(());
        }
        let group = self.next_id;
        self.next_id += 1;
        self.text.clear();
        let indices: Vec<String> = (0..n_materials).map(|i| i.to_string()).collect();
        let _ = writeln!(
            self.text,
            "<m:compositematerials id=\"{group}\" matid=\"1\" matindices=\"{}\">",
            indices.join(" ")
        );
        for values in &composites {
            let v: Vec<String> = values.iter().map(|f| f.to_string()).collect();
            let _ = writeln!(self.text, "<m:composite values=\"{}\"/>", v.join(" "));
        }
        self.text.push_str("</m:compositematerials>\n");
        let z1 = plan.z;
        let z0 = plan.z - plan.thickness;
        for (pl, ids) in plan.parts.iter().zip(&region_composite) {
            if pl.regions.is_empty() {
                continue;
            }
            let id = self.next_id;
            self.next_id += 1;
            let mut mesh = MeshText::default();
            for (r, &c) in pl.regions.iter().zip(ids) {
                mesh.prism(&r.polygon, z0, z1, group, c);
            }
            if mesh.base == 0 {
                continue;
            }
            let MeshText {
                vertices, triangles, ..
            } = mesh;
            let _ = write!(
                self.text,
                "<object id=\"{id}\" type=\"model\" name=\"{} layer {}\" pid=\"{group}\" pindex=\"{}\">\n<mesh>\n<vertices>\n{vertices}</vertices>\n<triangles>\n{triangles}</triangles>\n</mesh>\n</object>\n",
                xml_escape(&info.parts[pl.part].name),
                plan.index,
                ids[0]
            );
            self.objects.push(id);
        }
        let path = self.path.clone();
        self.zip.write_all(self.text.as_bytes()).map_err(io(&path))
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, _files: &mut dyn OutputFiles) -> Result<()> {
        let path = self.path.clone();
        let mut tail = String::from("</resources>\n<build>\n");
        for id in &self.objects {
            let _ = writeln!(tail, "<item objectid=\"{id}\"/>");
        }
        tail.push_str("</build>\n</model>\n");
        self.zip.write_all(tail.as_bytes()).map_err(io(&path))?;
        let mut out = self.zip.finish().map_err(zip_error(&path))?.into_inner();
        out.flush().map_err(io(&path))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    Ok(AnyStage::Export(Box::new(ThreeMf { options })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "3mf",
        doc: "3MF with the materials extension: every sub-region a prism over its layer, coloured by a composite of the primary materials in its fractions.",
        options: Options::SPECS,
        example: "use = \"3mf\"\npath = \"plan.3mf\"",
    },
    build,
});
