//! 3MF component graphs built from structured input: objects holding small meshes or
//! components that name other objects (themselves, each other in cycles, missing ones)
//! with arbitrary transforms, instanced from the build. Read within small limits,
//! every graph ends in meshes within the limits or a clean error (a cycle, a missing
//! object, too many triangles or vertices), never a panic, an abort, or memory the
//! limits do not allow.
#![no_main]

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use arbitrary::Arbitrary;
use lamina_core::Limits;
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
struct Package {
    objects: Vec<Object>,
    build: Vec<Component>,
    /// Index into the units 3MF names.
    unit: u8,
}

#[derive(Arbitrary, Debug)]
struct Object {
    vertices: Vec<[i8; 3]>,
    triangles: Vec<[u8; 3]>,
    /// An object with components has no mesh of its own.
    components: Vec<Component>,
}

#[derive(Arbitrary, Debug)]
struct Component {
    /// An object id: objects are numbered from 1, so some name nothing.
    object: u8,
    /// Twelve matrix entries, in sixteenths.
    transform: Option<[i8; 12]>,
}

const UNITS: [&str; 6] = ["micron", "millimeter", "centimeter", "inch", "foot", "meter"];

fn transform(c: &Component) -> String {
    match &c.transform {
        Some(m) => {
            let values: Vec<String> = m.iter().map(|v| format!("{}", f64::from(*v) / 16.0)).collect();
            format!(" transform=\"{}\"", values.join(" "))
        }
        None => String::new(),
    }
}

fn model(p: &Package) -> String {
    let unit = UNITS[usize::from(p.unit) % UNITS.len()];
    let mut x = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<model unit=\"{unit}\" \
         xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\"><resources>"
    );
    for (i, o) in p.objects.iter().enumerate() {
        let _ = write!(x, "<object id=\"{}\" type=\"model\">", i + 1);
        if o.components.is_empty() {
            x.push_str("<mesh><vertices>");
            for v in &o.vertices {
                let _ = write!(x, "<vertex x=\"{}\" y=\"{}\" z=\"{}\"/>", v[0], v[1], v[2]);
            }
            x.push_str("</vertices><triangles>");
            for t in &o.triangles {
                let _ = write!(x, "<triangle v1=\"{}\" v2=\"{}\" v3=\"{}\"/>", t[0], t[1], t[2]);
            }
            x.push_str("</triangles></mesh>");
        } else {
            x.push_str("<components>");
            for c in &o.components {
                let _ = write!(x, "<component objectid=\"{}\"{}/>", c.object, transform(c));
            }
            x.push_str("</components>");
        }
        x.push_str("</object>");
    }
    x.push_str("</resources><build>");
    for c in &p.build {
        let _ = write!(x, "<item objectid=\"{}\"{}/>", c.object, transform(c));
    }
    x.push_str("</build></model>");
    x
}

fn package(model: &str) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    zip.start_file("3D/3dmodel.model", options).expect("zip");
    zip.write_all(model.as_bytes()).expect("zip");
    zip.finish().expect("zip").into_inner()
}

fuzz_target!(|p: Package| {
    let limits = Limits {
        triangles: 100_000,
        model_bytes: 1 << 20,
        ..Limits::default()
    };
    let bytes = package(&model(&p));
    if let Ok(meshes) = lamina_model::threemf::read_within(Path::new("fuzz.3mf"), &bytes, &limits) {
        let triangles: usize = meshes.iter().map(|m| m.triangles.len()).sum();
        assert!(triangles as u64 <= limits.triangles, "{triangles} triangles read");
    }
});
