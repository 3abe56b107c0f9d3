//! `lamina generate`: builds one model stage (a generator such as `blade`, or a reader)
//! from options given on the command line and writes its meshes to a file, STL, OBJ or
//! 3MF by the extension.
//!
//! The options go through the same path as a pipeline's `[model]` table with `--set`
//! overrides, so a generator validates them exactly as in a pipeline and its errors
//! name the bad option. Several meshes (the gear and shaft of `gear-shaft`) go into one
//! file: merged into the single solid of an STL (the runtime can still tell the parts
//! apart with `family_at`), one object each in OBJ and 3MF.

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use lamina_core::output::AtomicOutputs;
use lamina_core::pipeline::{Override, PathElem, Pipeline};
use lamina_core::stage::OutputFiles;
use lamina_core::{Error, Mesh, ModelSource, Registry, Result, SourceFile};

/// The file formats `generate` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Stl,
    Obj,
    ThreeMf,
}

impl Format {
    fn of(path: &Path) -> Result<Format> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "stl" => Ok(Format::Stl),
            "obj" => Ok(Format::Obj),
            "3mf" => Ok(Format::ThreeMf),
            _ => Err(
                Error::config(format!("output `{}`: unknown format `.{ext}`", path.display()))
                    .with_help("name the file *.stl, *.obj or *.3mf"),
            ),
        }
    }
}

/// What to generate and where to write it.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    pub model: String,
    pub options: Vec<Override>,
    pub output: PathBuf,
    /// No summary.
    pub quiet: bool,
}

/// Reads the option words after the model name: `--key value`, `--key=value`,
/// `key=value`, `--set key=value` (also `--set model.key=value`), and `-o FILE` /
/// `--output FILE` and `-q` / `--quiet` when clap left them among the options. Values are TOML (`12`,
/// `2.5`, `[50.0, 20.0]`, `"2412"`); anything that is not TOML is a string.
pub fn request(model: &str, output: Option<PathBuf>, quiet: bool, words: &[String]) -> Result<Request> {
    let (mut output, mut quiet) = (output, quiet);
    let mut options = Vec::new();
    let mut words = words.iter();
    let usage = |m: String| Error::config(m).with_help("lamina generate MODEL [--key value ...] -o FILE");
    while let Some(word) = words.next() {
        if word == "-q" || word == "--quiet" {
            quiet = true;
            continue;
        }
        if word == "-h" || word == "--help" {
            return Err(usage(format!(
                "`{model}` takes the options listed by `lamina plugins model`"
            )));
        }
        let (key, value) = if word == "-o" || word == "--output" {
            let path = words
                .next()
                .ok_or_else(|| usage(format!("{word} needs a file name")))?;
            if output.replace(PathBuf::from(path)).is_some() {
                return Err(usage("the output file is given twice".into()));
            }
            continue;
        } else if word == "--set" {
            let pair = words
                .next()
                .ok_or_else(|| usage("--set needs KEY=VALUE".into()))?;
            split_pair(pair).ok_or_else(|| usage(format!("--set {pair}: expected KEY=VALUE")))?
        } else if let Some(flag) = word.strip_prefix("--") {
            match flag.split_once('=') {
                Some((k, v)) => (k.to_string(), v.to_string()),
                None => {
                    let value = words
                        .next()
                        .ok_or_else(|| usage(format!("--{flag} needs a value")))?;
                    (flag.to_string(), value.clone())
                }
            }
        } else {
            split_pair(word).ok_or_else(|| {
                usage(format!(
                    "`{word}`: expected an option as --key value or key=value"
                ))
            })?
        };
        let key = key.strip_prefix("model.").unwrap_or(&key).trim().to_string();
        if key.is_empty()
            || !key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(usage(format!("`{key}` is not an option name")));
        }
        if key == "use" {
            return Err(usage("the model is the first argument, not an option".into()));
        }
        let mut o: Override = format!("model.{key}={value}").parse()?;
        o.path = vec![PathElem::Key("model".into()), PathElem::Key(key)];
        options.push(o);
    }
    if model.is_empty()
        || !model
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Err(
            usage(format!("`{model}` is not a model name")).with_help("`lamina plugins model` lists them")
        );
    }
    let output = output.ok_or_else(|| usage("no output file: add -o FILE.stl".into()))?;
    Format::of(&output)?;
    Ok(Request {
        model: model.to_string(),
        options,
        output,
        quiet,
    })
}

fn split_pair(s: &str) -> Option<(String, String)> {
    let (k, v) = s.split_once('=')?;
    Some((k.to_string(), v.to_string()))
}

/// Builds the model and loads its meshes, placed (`scale`, `place`) as a pipeline
/// would place them. Relative file names resolve against the current directory.
pub fn meshes(registry: &Registry, req: &Request) -> Result<Vec<Mesh>> {
    // A minimal pipeline whose model table is made of overrides only: errors then name
    // the option (`[model] teeth: ...`) without pointing into text the user never saw.
    let text = "[model]\n\n[materials.generated]\ncolour = [128, 128, 128]\n";
    let file = SourceFile::new("<lamina generate>", text);
    let mut overrides = vec![format!("model.use=\"{}\"", req.model).parse::<Override>()?];
    overrides.extend(req.options.iter().cloned());
    let base_dir = PathBuf::from(".");
    let pipeline = Pipeline::parse(file, base_dir.clone(), &overrides)?;
    let spec = pipeline
        .model
        .ok_or_else(|| Error::config("no model to generate"))?;
    let scripts = lamina_core::script::local(&base_dir, Default::default());
    let source = registry.build::<dyn ModelSource>(&spec.table, &scripts, &base_dir)?;
    let mut meshes = source.load(&base_dir)?;
    if meshes.iter().all(|m| m.triangles.is_empty()) {
        return Err(Error::stage(&req.model, "the model has no triangles"));
    }
    lamina_core::runtime::place(&mut meshes, spec.factor(), spec.place);
    Ok(meshes)
}

/// Writes `meshes` to `path` in the format its extension names. The file appears under
/// its name only when complete: it is written beside it and renamed.
pub fn write(meshes: &[Mesh], path: &Path) -> Result<()> {
    let format = Format::of(path)?;
    let name = path
        .file_name()
        .ok_or_else(|| Error::config(format!("output `{}` names no file", path.display())))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if path.is_dir() {
        return Err(Error::config(format!("output `{}` is a folder", path.display())));
    }
    let bytes = encode(meshes, format).map_err(|e| Error::io(path, e))?;
    let mut outputs = AtomicOutputs::new(dir);
    let mut w = outputs.create(Path::new(name))?;
    w.write_all(&bytes).map_err(|e| Error::io(path, e))?;
    w.flush().map_err(|e| Error::io(path, e))?;
    drop(w);
    outputs.commit()?;
    Ok(())
}

fn encode(meshes: &[Mesh], format: Format) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::new();
    match format {
        Format::Stl => lamina_model::stl::write_binary(&merged(meshes), &mut out)?,
        Format::ThreeMf => out = lamina_model::threemf::write(meshes)?,
        Format::Obj => out = obj(meshes).into_bytes(),
    }
    Ok(out)
}

/// All meshes as one (binary STL holds a single solid).
fn merged(meshes: &[Mesh]) -> Mesh {
    let names: Vec<&str> = meshes.iter().map(|m| m.name.as_str()).collect();
    let mut all = Mesh::new(names.join("+"), Vec::new(), Vec::new());
    for m in meshes {
        let base = all.vertices.len() as u32;
        all.vertices.extend_from_slice(&m.vertices);
        all.triangles
            .extend(m.triangles.iter().map(|t| t.map(|i| i + base)));
    }
    all
}

/// Wavefront OBJ, one `o` object per mesh, full precision.
fn obj(meshes: &[Mesh]) -> String {
    let mut s = String::from("# lamina generate\n");
    let mut base = 1usize;
    for m in meshes {
        let _ = writeln!(s, "o {}", m.name.replace(char::is_whitespace, "_"));
        for v in &m.vertices {
            let _ = writeln!(s, "v {} {} {}", v.x, v.y, v.z);
        }
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| i as usize + base);
            let _ = writeln!(s, "f {a} {b} {c}");
        }
        base += m.vertices.len();
    }
    s
}

/// One line per mesh for the user: triangles, volume, size, and whether it is closed.
pub fn describe(meshes: &[Mesh]) -> Vec<String> {
    meshes
        .iter()
        .map(|m| {
            let size = m.bbox().size();
            let closed = match lamina_model::edge_defect(m) {
                None => "closed".to_string(),
                Some(d) => format!("NOT closed: {d}"),
            };
            format!(
                "{}: {} triangles, volume {:.3} mm3, {:.3} x {:.3} x {:.3} mm, {closed}",
                m.name,
                m.triangles.len(),
                m.signed_volume(),
                size.x,
                size.y,
                size.z
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn options_in_every_spelling() {
        let r = request(
            "blade",
            None,
            false,
            &words("--cavities 2 --twist=30 naca=0012 --set root_size=[50.0,20.0] -o b.stl -q"),
        )
        .expect("parses");
        assert_eq!(r.output, PathBuf::from("b.stl"));
        assert!(r.quiet);
        let keys: Vec<String> = r
            .options
            .iter()
            .map(|o| format!("{}={}", o.path[1], o.value))
            .collect();
        assert_eq!(
            keys,
            [
                "cavities=2",
                "twist=30",
                "naca=\"0012\"",
                "root_size=[50.0, 20.0]"
            ]
        );
    }

    #[test]
    fn bad_words_are_usage_errors() {
        for bad in [
            "--cavities",
            "cavities",
            "-o",
            "--a.b 2 -o x.stl",
            "--use gear -o x.stl",
            "-o x.step",
            "--cavities 1 --help -o x.stl",
        ] {
            let e = request("blade", None, false, &words(bad)).expect_err(bad);
            assert!(e.is_usage(), "{bad}: {e}");
        }
        assert!(request("blade", Some("a.stl".into()), false, &words("-o b.stl")).is_err());
    }

    #[test]
    fn obj_has_one_object_per_mesh() {
        let a = Mesh::new("a", vec![lamina_core::Point3::origin(); 3], vec![[0, 1, 2]]);
        let text = obj(&[a.clone(), a]);
        assert_eq!(text.matches("\no ").count(), 2);
        assert!(text.contains("f 4 5 6"));
    }
}
