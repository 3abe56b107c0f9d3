//! Hostile input, run through the `lamina` binary as a user or an attacker would: scripts
//! that try to hang or exhaust the machine, option values that would allocate without
//! bound, huge coordinates, inputs that are large in count rather than bytes, names
//! that try to inject G-code or markup, output paths that try to escape, and faults in
//! the middle of a run.
//!
//! Every case must end in a clear error (or a warning) within [`SECONDS`] and
//! [`PEAK_BYTES`] of memory, with no panic, and nothing written outside `--out`.

use crate::support::{pipelines, skip};
use std::ffi::OsString;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Wall time one case may take.
const SECONDS: f64 = 10.0;
/// Peak resident memory one case may reach.
const PEAK_BYTES: u64 = 1 << 30;

/// How a `lamina` process ended.
#[derive(Debug)]
struct Outcome {
    code: Option<i32>,
    stderr: String,
    seconds: f64,
    peak_bytes: u64,
}

/// The high-water mark of the resident memory of process `pid` (`self` for this one)
/// as Linux tells it (`VmHWM` in `/proc/<pid>/status`), while it runs.
fn high_water(pid: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Waits for `child`, killing it after twice the budget, and reads its peak memory
/// from the kernel's accounting of the process (`wait4`).
///
/// Linux folds the high-water mark of the memory a process replaces at `execve` into
/// its `ru_maxrss`, and a child started with `vfork` replaces this test program's: a
/// child then reads at least this program's own peak, however little it used. Where
/// `ru_maxrss` is no more than that, the child's own high-water mark, sampled while it
/// runs, is its peak (a process gone within one 5 ms sample used too little to matter).
#[cfg(unix)]
fn wait_measured(child: &mut Child) -> (Option<i32>, u64) {
    use std::os::unix::process::ExitStatusExt;
    let pid = child.id() as libc::pid_t;
    let deadline = Instant::now() + Duration::from_secs_f64(2.0 * SECONDS);
    let mut sampled = 0;
    loop {
        let ours = high_water("self");
        sampled = sampled.max(high_water(&pid.to_string()).unwrap_or(0));
        let mut status = 0;
        // SAFETY: an all-zero `rusage` is a valid value of this plain C struct.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: `pid` is our own child, not yet reaped; the pointers are valid.
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if r == pid {
            let status = std::process::ExitStatus::from_raw(status);
            // ru_maxrss is in KiB on Linux.
            let reported = usage.ru_maxrss as u64 * 1024;
            let peak = match ours {
                Some(ours) if reported <= ours => sampled,
                _ => reported,
            };
            return (status.code(), peak);
        }
        assert!(r == 0, "wait4 failed: {}", std::io::Error::last_os_error());
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("lamina ran for more than {} s", 2.0 * SECONDS);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Runs `lamina` in `cwd` and measures it.
fn lamina_in(cwd: &Path, args: &[OsString]) -> Outcome {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .current_dir(cwd)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("lamina starts");
    let mut stderr = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        std::io::Read::read_to_string(&mut stderr, &mut text).ok();
        text
    });
    let (code, peak_bytes) = wait_measured(&mut child);
    Outcome {
        code,
        stderr: reader.join().unwrap_or_default(),
        seconds: started.elapsed().as_secs_f64(),
        peak_bytes,
    }
}

/// A scratch folder: lamina runs in it, writes into `out/` inside it, and nothing else
/// may appear in it.
struct Scratch {
    dir: tempfile::TempDir,
}

impl Scratch {
    fn new() -> Self {
        Self {
            dir: tempfile::tempdir().expect("tempdir"),
        }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }

    fn out(&self) -> PathBuf {
        self.path().join("out")
    }

    fn write(&self, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
        let p = self.path().join(name);
        std::fs::write(&p, bytes).expect("write fixture");
        p
    }

    /// `lamina run PIPELINE --out out -q --set ...`.
    fn run(&self, pipeline: &Path, sets: &[&str]) -> Outcome {
        let mut args: Vec<OsString> = vec![
            "run".into(),
            pipeline.into(),
            "--out".into(),
            self.out().into(),
            "-q".into(),
        ];
        for s in sets {
            args.push("--set".into());
            args.push(s.into());
        }
        lamina_in(self.path(), &args)
    }

    fn check(&self, pipeline: &Path, sets: &[&str]) -> Outcome {
        let mut args: Vec<OsString> = vec!["check".into(), pipeline.into()];
        for s in sets {
            args.push("--set".into());
            args.push(s.into());
        }
        lamina_in(self.path(), &args)
    }

    /// Names in the scratch folder other than the fixtures and `out`.
    fn strays(&self, fixtures: &[&str]) -> Vec<String> {
        std::fs::read_dir(self.path())
            .expect("list")
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != "out" && !fixtures.contains(&n.as_str()))
            .collect()
    }

    /// Files under `out/`.
    fn outputs(&self) -> Vec<PathBuf> {
        fn walk(dir: &Path, into: &mut Vec<PathBuf>) {
            for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
                let p = e.path();
                if p.is_dir() {
                    walk(&p, into);
                } else {
                    into.push(p);
                }
            }
        }
        let mut files = Vec::new();
        walk(&self.out(), &mut files);
        files
    }
}

/// The budgets every case keeps, and no panic or abort.
fn within_budget(label: &str, o: &Outcome) {
    // The margin left, in the log: a case that creeps up is seen before it fails.
    eprintln!(
        "{label}: {:.2} s of {SECONDS} s, {} MiB of {} MiB",
        o.seconds,
        o.peak_bytes >> 20,
        PEAK_BYTES >> 20
    );
    assert!(
        o.seconds <= SECONDS,
        "{label}: took {:.1} s\n{}",
        o.seconds,
        o.stderr
    );
    assert!(
        o.peak_bytes <= PEAK_BYTES,
        "{label}: peak memory {} MiB\n{}",
        o.peak_bytes >> 20,
        o.stderr
    );
    assert!(
        !o.stderr.contains("panicked") && !o.stderr.contains("stack overflow"),
        "{label}: {}",
        o.stderr
    );
    assert!(o.code.is_some(), "{label}: killed by a signal\n{}", o.stderr);
}

/// A run that must be refused with `expected` in its message, leaving no output.
fn refused(scratch: &Scratch, label: &str, o: &Outcome, expected: &str) {
    within_budget(label, o);
    assert!(
        matches!(o.code, Some(1 | 2)),
        "{label}: exit {:?}, expected an error\n{}",
        o.code,
        o.stderr
    );
    assert!(
        o.stderr.contains(expected),
        "{label}: the message does not say `{expected}`:\n{}",
        o.stderr
    );
    assert!(
        scratch.outputs().is_empty(),
        "{label}: a failed run left {:?}",
        scratch.outputs()
    );
}

#[test]
fn scripts_that_hang_or_hoard_are_stopped_with_their_location() {
    let p = pipelines().join("tube-gradient.toml");
    let cases = [
        ("sleep", "grade.f=sleep(1); 0.5", "not available"),
        ("sleep forever", "grade.f=sleep(1e9); 0.5", "not available"),
        ("endless loop", "grade.f=loop {}", "limit"),
        (
            "a sort comparator that loops",
            "grade.f=let a = [3, 1, 2]; a.sort(|x, y| { loop {} }); 0.5",
            "limit",
        ),
        (
            "a huge array",
            "grade.f=let a = []; a.pad(100000000, 0.5); 0.5",
            "too large",
        ),
        (
            "a string that doubles",
            "grade.f=let s = \"xx\"; loop { s += s; }",
            "too large",
        ),
        (
            "a huge map",
            "grade.f=let m = #{}; for i in 0..1000000 { m[`k${i}`] = i; } 0.5",
            "limit",
        ),
        (
            "a map of large arrays",
            "grade.f=let a = []; a.pad(99999, 1.0); let m = #{}; for i in 0..99999 { m[`${i}`] = a; } 0.5",
            "memory limit",
        ),
        ("import", "grade.f=import \"x\" as y; 0.5", "modules"),
        ("eval", "grade.f=eval(\"0.5\")", "eval"),
        ("NaN", "grade.f=0.0 / 0.0", "NaN"),
        ("a negative fraction", "grade.f=\"0.0 - 0.5\"", "outside [0, 1]"),
    ];
    for (label, set, expected) in cases {
        let s = Scratch::new();
        let o = s.run(&p, &[set]);
        refused(&s, label, &o, expected);
        // Located in the override, not in the file's text.
        assert!(o.stderr.contains("--set:1:"), "{label}: {}", o.stderr);
        assert!(
            !o.stderr.contains("tube-gradient.toml:2"),
            "{label}: {}",
            o.stderr
        );
        assert!(s.strays(&[]).is_empty(), "{label}: {:?}", s.strays(&[]));
    }
}

#[test]
fn deep_recursion_is_stopped_at_the_function_and_never_overflows_the_stack() {
    let s = Scratch::new();
    std::fs::copy(pipelines().join("tube-gradient.toml"), s.path().join("p.toml")).expect("copy");
    let nested = format!("{}r + 1.0{}", "(".repeat(25), ")".repeat(25));
    s.write(
        "deep.rhai",
        format!("fn deep(r) {{\n  if r > 1e9 {{ r }} else {{ deep({nested}) }}\n}}\n\nfn down(r) {{\n  down(r)\n}}\n"),
    );
    for function in ["deep", "down"] {
        let set = format!("grade.f=\"deep.rhai#{function}\"");
        let o = s.run(&s.path().join("p.toml"), &[&set]);
        refused(&s, function, &o, "deep.rhai:");
        assert!(
            o.stderr.contains("nested function calls"),
            "{function}: {}",
            o.stderr
        );
    }
    // Nesting deeper than the parser allows is refused when the script compiles.
    let too_deep = format!("fn f(r) {{ {}r{} }}\n", "(".repeat(200), ")".repeat(200));
    s.write("deep.rhai", too_deep);
    let o = s.check(&s.path().join("p.toml"), &["grade.f=\"deep.rhai#f\""]);
    within_budget("200 parentheses", &o);
    assert_eq!(o.code, Some(2), "{}", o.stderr);
    assert!(o.stderr.contains("deep.rhai:1:"), "{}", o.stderr);
}

#[test]
fn option_values_that_would_exhaust_the_machine_are_refused_before_work() {
    let p = |name: &str| pipelines().join(name);
    let cases: &[(&str, &str, &[&str], &str)] = &[
        (
            "distance-field samples",
            "blade-skin.toml",
            &["discretise.samples=8192"],
            "limits.grid_samples",
        ),
        (
            "distance-field count",
            "blade-skin.toml",
            &["discretise.count=10000"],
            "limits.regions",
        ),
        (
            "distance-field sample spacing",
            "blade-skin.toml",
            &["discretise.sample_spacing=1e-5"],
            "`sample_spacing` = 1e-5 is outside its range 0.0001 to 1000000",
        ),
        (
            "offset count",
            "gear-mixing-gcode.toml",
            &["discretise.count=10000"],
            "limits.regions",
        ),
        (
            "offset spacing",
            "gear-mixing-gcode.toml",
            &["discretise={use = \"offset\", spacing = 1e-6}"],
            "`spacing` = 1e-6 is outside its range 0.001 to 1000000",
        ),
        (
            "offset tolerance",
            "gear-mixing-gcode.toml",
            &["discretise.tolerance=1e-12"],
            "`tolerance` = 1e-12 is outside its range 0.0001 to 10",
        ),
        (
            "step-width step",
            "gear-mixing-gcode.toml",
            &["discretise={use = \"step-width\", step = 1e-4}"],
            "`step` = 0.0001 is outside its range 0.001 to 1",
        ),
        (
            "sources step",
            "grading-sources.toml",
            &["discretise.sources.0.step=1e-9"],
            "levels",
        ),
        (
            "bitmap period",
            "pipe-work-cycles.toml",
            &["output.2.period=[1, 1, 1e-300]"],
            "period",
        ),
        (
            "bitmap void radius",
            "pipe-work-cycles.toml",
            &["output.2.void_radius=1e9"],
            "void_radius",
        ),
        (
            "bitmap pixel",
            "pipe-work-cycles.toml",
            &["output.2.pixel=1e-6"],
            "`pixel` = 1e-6 is outside its range",
        ),
        (
            "layers",
            "tube-gradient.toml",
            &["slice.thickness=1e-9"],
            "`thickness` = 1e-9 is outside its range 0.001 to 100",
        ),
        (
            "iso-contours a nanometre apart",
            "blade-skin.toml",
            &["discretise={use = \"distance-field\", spacing = 1e-7}"],
            "`spacing` = 1e-7 is outside its range 0.001 to 1000000",
        ),
        (
            "cells a nanometre long",
            "blade-idw.toml",
            &["discretise.cell_length=1e-7"],
            "`cell_length` = 1e-7 is outside its range 0.001 to 1000000",
        ),
        (
            "a bead of a nanometre",
            "gear-mixing-gcode.toml",
            &["plan.width=1e-7"],
            "`width` = 1e-7 is outside its range 0.01 to 50",
        ),
        (
            "a check every nanosecond",
            "assembly-two-tools.toml",
            &["plan.step=1e-9"],
            "`step` = 1e-9 is outside its range 0.0001 to 10",
        ),
        (
            "a source far away",
            "grading-sources.toml",
            &["discretise.sources.1.at=[1e308, 0, 0]"],
            "1000000 mm",
        ),
        (
            "a source width",
            "grading-sources.toml",
            &["discretise.sources.1.width=1e300"],
            "alpha",
        ),
        (
            "a huge box",
            "grading-sources.toml",
            &["model.size=[1e300, 1, 1]"],
            "`size` = 1e300 is outside its range",
        ),
        (
            "a tiny box",
            "grading-sources.toml",
            &["model.size=[1e-6, 1e-6, 1e-6]"],
            "`size` = 1e-6 is outside its range",
        ),
        (
            "a huge scale",
            "grading-sources.toml",
            &["model.scale=1e300"],
            "kilometre",
        ),
        (
            "a deep --set path",
            "tube-gradient.toml",
            &[],
            "more than 16 parts",
        ),
        (
            "a tube of 65536 sides",
            "distance-field-power.toml",
            &["model.segments=65536"],
            "`segments` = 65536 is outside its range 3 to 4096",
        ),
        (
            "65536 directions to orient by",
            "tube-gradient.toml",
            &["orient.use=\"candidates\"", "orient.samples=65536"],
            "`samples` = 65536 is outside its range 0 to 4096",
        ),
    ];
    let deep_path = format!("{}=1", vec!["a"; 20_000].join("."));
    for &(label, pipeline, sets, expected) in cases {
        let s = Scratch::new();
        let mut sets: Vec<&str> = sets.to_vec();
        if label == "a deep --set path" {
            sets.push(&deep_path);
        }
        let o = s.run(&p(pipeline), &sets);
        refused(&s, label, &o, expected);
    }
}

#[test]
fn a_model_scaled_thinner_than_a_layer_is_planned_with_a_warning() {
    let s = Scratch::new();
    for scale in ["1e-300", "1e-3"] {
        let o = s.run(
            &pipelines().join("grading-sources.toml"),
            &[&format!("model.scale={scale}")],
        );
        within_budget(scale, &o);
        assert_eq!(o.code, Some(0), "{}", o.stderr);
        assert!(o.stderr.contains("thinner than a layer"), "{scale}: {}", o.stderr);
    }
}

#[test]
fn a_limit_is_raised_in_the_pipeline() {
    let s = Scratch::new();
    let p = pipelines().join("gear-mixing-gcode.toml");
    let o = s.check(&p, &["discretise.count=1500"]);
    within_budget("count over the limit", &o);
    assert_eq!(o.code, Some(2), "{}", o.stderr);
    assert!(o.stderr.contains("[limits]"), "{}", o.stderr);
    let o = s.check(&p, &["discretise.count=1500", "limits.regions=2000"]);
    within_budget("count within the raised limit", &o);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let o = s.check(&p, &["limits.region=2000"]);
    assert_eq!(o.code, Some(2), "{}", o.stderr);
    assert!(o.stderr.contains("unknown field `region`"), "{}", o.stderr);
}

/// A pipeline reading `model`, graded by a script, with one JSON output.
fn pipeline_for(model: &str) -> String {
    format!(
        "name = \"hostile\"\n\n[model]\nfile = \"{model}\"\nplace = \"centre\"\n\n[materials.a]\ncolour = [255, 0, 0]\n\n[slice]\nuse = \"uniform\"\nthickness = 1.0\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
    )
}

/// A 3MF package holding `model` as its model part.
fn three_mf(model: &[u8]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("3D/3dmodel.model", options).expect("zip");
    zip.write_all(model).expect("zip");
    zip.finish().expect("zip").into_inner()
}

const THREE_MF_HEAD: &str = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<model unit=\"millimeter\" xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\"><resources>";
const TETRA: &str = "<object id=\"1\" type=\"model\"><mesh><vertices><vertex x=\"0\" y=\"0\" z=\"0\"/><vertex x=\"10\" y=\"0\" z=\"0\"/><vertex x=\"0\" y=\"10\" z=\"0\"/><vertex x=\"0\" y=\"0\" z=\"10\"/></vertices><triangles><triangle v1=\"0\" v2=\"2\" v3=\"1\"/><triangle v1=\"0\" v2=\"1\" v3=\"3\"/><triangle v1=\"1\" v2=\"2\" v3=\"3\"/><triangle v1=\"0\" v2=\"3\" v3=\"2\"/></triangles></mesh></object>";

#[test]
fn files_that_expand_without_bound_are_refused_by_a_named_limit() {
    // Components nested 30 deep, two per level: 2^30 tetrahedra from 2 KB.
    let mut model = String::from(THREE_MF_HEAD);
    model.push_str(TETRA);
    for id in 2..=31 {
        model.push_str(&format!(
            "<object id=\"{id}\" type=\"model\"><components><component objectid=\"{}\"/><component objectid=\"{}\" transform=\"1 0 0 0 1 0 0 0 1 1 0 0\"/></components></object>",
            id - 1,
            id - 1
        ));
    }
    model.push_str("</resources><build><item objectid=\"31\"/></build></model>");
    let s = Scratch::new();
    s.write("nested.3mf", three_mf(model.as_bytes()));
    let p = s.write("p.toml", pipeline_for("nested.3mf"));
    let o = s.run(&p, &[]);
    refused(&s, "nested components", &o, "limits.triangles");

    // A ZIP bomb: 1.1 GiB of spaces inside an XML comment, a few MB packed.
    let s = Scratch::new();
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .large_file(true);
    zip.start_file("3D/3dmodel.model", options).expect("zip");
    zip.write_all(THREE_MF_HEAD.as_bytes()).expect("zip");
    zip.write_all(b"<!--").expect("zip");
    let spaces = vec![b' '; 1 << 24];
    for _ in 0..70 {
        zip.write_all(&spaces).expect("zip");
    }
    zip.write_all(b"-->").expect("zip");
    zip.write_all(TETRA.as_bytes()).expect("zip");
    zip.write_all(b"</resources><build><item objectid=\"1\"/></build></model>")
        .expect("zip");
    let bomb = zip.finish().expect("zip").into_inner();
    assert!(bomb.len() < 8 << 20, "{} bytes", bomb.len());
    s.write("bomb.3mf", bomb);
    let p = s.write("p.toml", pipeline_for("bomb.3mf"));
    let o = s.run(&p, &[]);
    refused(&s, "a ZIP bomb", &o, "limits.model_bytes");

    // The same limits, lowered, refuse an ordinary file.
    let s = Scratch::new();
    let mut model = String::from(THREE_MF_HEAD);
    model.push_str(TETRA);
    model.push_str("</resources><build><item objectid=\"1\"/></build></model>");
    s.write("tetra.3mf", three_mf(model.as_bytes()));
    let p = s.write("p.toml", pipeline_for("tetra.3mf"));
    let o = s.run(&p, &[]);
    within_budget("a tetrahedron", &o);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let o = s.run(&p, &["limits.triangles=3"]);
    assert!(o.stderr.contains("needs 4 triangles"), "{}", o.stderr);
    let o = s.run(&p, &["limits.model_bytes=100"]);
    assert!(o.stderr.contains("limits.model_bytes"), "{}", o.stderr);
}

/// A device or a FIFO where a model, a machine profile or a plugin belongs is refused
/// before it is read: `/dev/zero` would fill the memory, a FIFO would never end.
#[test]
fn devices_and_fifos_are_refused_before_they_are_read() {
    let s = Scratch::new();
    // A link to a device leads out of the pipeline's folder; allowed by the command
    // line, it is still no regular file.
    for (name, model) in [
        ("zero.stl", "zero.stl"),
        ("zero.3mf", "zero.3mf"),
        ("zero.obj", "zero.obj"),
    ] {
        let link = s.path().join(name);
        std::os::unix::fs::symlink("/dev/zero", &link).expect("symlink");
        let p = s.write("p.toml", pipeline_for(model));
        let o = s.run(&p, &[]);
        refused(&s, name, &o, "outside what the pipeline may read");
        assert!(o.stderr.contains(name), "{name}: {}", o.stderr);
        let mut args: Vec<OsString> = vec!["check".into(), p.clone().into()];
        args.extend(["--allow".into(), "/dev".into()]);
        let o = lamina_in(s.path(), &args);
        refused(&s, name, &o, "not a regular file");
    }
    let fifo = s.path().join("pipe.stl");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
    assert!(made.success());
    let p = s.write("p.toml", pipeline_for("pipe.stl"));
    refused(&s, "a FIFO model", &s.run(&p, &[]), "not a regular file");
    // A machine profile.
    let fifo = s.path().join("machine.toml");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
    assert!(made.success());
    let p = s.write(
        "m.toml",
        format!("machine = \"machine.toml\"\n{}", pipeline_for("tetra.3mf")),
    );
    let o = s.run(&p, &[]);
    refused(&s, "a FIFO machine profile", &o, "not a regular file");
    assert!(o.stderr.contains("machine.toml"), "{}", o.stderr);
}

#[test]
fn inputs_large_in_count_are_handled_in_time() {
    // Thousands of material tables: each is read from the file's one parse.
    let s = Scratch::new();
    let base = std::fs::read_to_string(pipelines().join("tube-gradient.toml")).expect("read");
    std::fs::copy(pipelines().join("gradient.rhai"), s.path().join("gradient.rhai")).expect("copy");
    let tables: String = (0..5000)
        .map(|i| format!("[materials.m{i}]\ncolour = [1, 2, 3]\n"))
        .collect();
    let p = s.write(
        "many.toml",
        base.replace("[slice]", &format!("{tables}\n[slice]")),
    );
    let o = s.check(&p, &[]);
    within_budget("5000 material tables", &o);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    assert!(o.seconds < 2.0, "5000 tables took {:.1} s", o.seconds);

    // Rhai functions by the ten thousand: refused before Rhai's parser, which slows
    // down with their square, sees them; and a script file of megabytes.
    for (count, expected) in [
        (20_000, "defines 20001 functions"),
        (200_000, "more than the 1048576"),
    ] {
        let functions: String = (0..count).map(|i| format!("fn f{i}(z) {{ z }}\n")).collect();
        s.write(
            "gradient.rhai",
            format!("{functions}fn smooth_z(z) {{ z / 10.0 }}\n"),
        );
        let o = s.check(&s.path().join("many.toml"), &[]);
        within_budget("many functions", &o);
        assert_eq!(o.code, Some(2), "{}", o.stderr);
        assert!(o.stderr.contains(expected), "{}", o.stderr);
    }

    // Disjoint triangles: open chains are joined in linear time.
    let s = Scratch::new();
    let mut stl = vec![0u8; 80];
    let n: u32 = 20_000;
    stl.extend_from_slice(&n.to_le_bytes());
    let mut seed = 1u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..n {
        let (x, y, z) = (next() * 50.0, next() * 50.0, next() * 5.0);
        let corners = [[x, y, z], [x + 0.5, y, z + 0.7], [x, y + 0.5, z + 0.9]];
        stl.extend_from_slice(&[0u8; 12]);
        for c in corners {
            for v in c {
                stl.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
        stl.extend_from_slice(&[0, 0]);
    }
    s.write("soup.stl", stl);
    let p = s.write("p.toml", pipeline_for("soup.stl"));
    let o = s.run(&p, &["slice.thickness=0.5"]);
    within_budget("20k disjoint triangles", &o);
    assert!(o.stderr.contains("open"), "{}", o.stderr);

    // Large random triangles: tens of thousands of open chains a layer, whose ends
    // meet within the gap tolerance everywhere, joined through a grid of their ends
    // (every end against every other took minutes); no area closes, and the run says
    // so in time.
    let s = Scratch::new();
    let mut stl = vec![0u8; 80];
    let n: u32 = 80_000;
    stl.extend_from_slice(&n.to_le_bytes());
    for _ in 0..n {
        stl.extend_from_slice(&[0u8; 12]);
        for _ in 0..3 {
            for scale in [100.0, 100.0, 10.0] {
                stl.extend_from_slice(&((next() * scale) as f32).to_le_bytes());
            }
        }
        stl.extend_from_slice(&[0, 0]);
    }
    s.write("soup.stl", stl);
    let p = s.write("p.toml", pipeline_for("soup.stl"));
    let o = s.run(&p, &[]);
    within_budget("80k random triangles", &o);
    assert!(
        o.code == Some(1) && o.stderr.contains("closes no area"),
        "{}",
        o.stderr
    );
}

#[test]
fn names_cannot_inject_machine_code_or_markup() {
    let s = Scratch::new();
    let evil = "x\\nG1 Z-20 F3000\\r\\nM104 S300 <script>alert(1)</script> \\\"&";
    let pipeline = format!(
        "name = \"{evil}\"\nmachine = \"marlin-mixing-2in1\"\n\n[model]\nuse = \"gear\"\nteeth = 12\nheight = 1.0\n\n[materials.\"{evil}\"]\ncolour = [255, 0, 0]\n[materials.green]\ncolour = [0, 255, 0]\n\n[[parts]]\nname = \"{evil}\"\n[parts.grade]\nuse = \"xy\"\nf = \"linear\"\nmu = -1.0\nlambda = 1.0\n\n[slice]\nuse = \"uniform\"\nthickness = 0.25\n\n[discretise]\nuse = \"offset\"\ncount = 3\n\n[plan]\nuse = \"sequential\"\nmixing = true\nwidth = 0.4\n\n[[output]]\nuse = \"gcode\"\npath = \"g.gcode\"\n\n[[output]]\nuse = \"html\"\npath = \"v.html\"\n\n[[output]]\nuse = \"svg\"\npath = \"svg/s\"\nlayers = [0]\n\n[[output]]\nuse = \"3mf\"\npath = \"m.3mf\"\n\n[[output]]\nuse = \"cli\"\npath = \"l.cli\"\nformat = \"modified\"\n\n[[output]]\nuse = \"json\"\npath = \"p.json\"\n"
    );
    let p = s.write("p.toml", pipeline);
    let o = s.run(&p, &[]);
    within_budget("names", &o);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let files = s.outputs();
    assert!(files.len() >= 6, "{files:?}");
    for file in files {
        let name = file.display().to_string();
        let bytes = std::fs::read(&file).expect("read output");
        let ext = file
            .extension()
            .map(|e| e.to_string_lossy().into_owned())
            .unwrap_or_default();
        match ext.as_str() {
            // Machine files: no line the name smuggled in is a command.
            "gcode" | "cli" => {
                let text = String::from_utf8_lossy(&bytes).into_owned();
                for line in text.split(['\n', '\r']) {
                    let t = line.trim_start();
                    assert!(
                        !t.starts_with("G1 Z-20") && !t.starts_with("M104 S300"),
                        "{name}: an injected line: {line:?}"
                    );
                }
            }
            // Markup: the tags arrive escaped.
            "html" | "svg" => {
                let text = String::from_utf8_lossy(&bytes).into_owned();
                assert!(!text.contains("<script>alert(1)"), "{name}: an unescaped tag");
            }
            "3mf" => {
                let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).expect("a ZIP");
                for i in 0..zip.len() {
                    let mut entry = zip.by_index(i).expect("entry");
                    let mut text = String::new();
                    if std::io::Read::read_to_string(&mut entry, &mut text).is_ok() {
                        assert!(!text.contains("<script>"), "{name} entry {i}: an unescaped tag");
                    }
                }
            }
            _ => {}
        }
    }
}

#[test]
fn output_paths_stay_inside_the_output_folder() {
    let p = pipelines().join("tube-gradient.toml");
    let outside = tempfile::tempdir().expect("tempdir");
    let absolute = format!("output.0.path=\"{}\"", outside.path().join("x.json").display());
    let cases: [(&str, &str, &str); 5] = [
        ("empty", "output.0.path=\"\"", "must name a file"),
        ("dot", "output.0.path=\".\"", "must name a file"),
        ("parent", "output.0.path=\"../x.json\"", "stay inside"),
        ("nested parent", "output.0.path=\"a/../../x.json\"", "stay inside"),
        ("absolute", &absolute, "stay inside"),
    ];
    for (label, set, expected) in cases {
        let s = Scratch::new();
        std::fs::copy(pipelines().join("gradient.rhai"), s.path().join("gradient.rhai")).expect("copy");
        let o = s.run(&p, &[set]);
        refused(&s, label, &o, expected);
        assert!(
            s.strays(&["gradient.rhai"]).is_empty(),
            "{label}: {:?}",
            s.strays(&["gradient.rhai"])
        );
    }
    assert_eq!(std::fs::read_dir(outside.path()).expect("list").count(), 0);

    // Two outputs of one name, and an output whose name is a folder.
    let s = Scratch::new();
    let o = s.run(
        &p,
        &["output=[{use = \"json\", path = \"a.json\"}, {use = \"json\", path = \"a.json\"}]"],
    );
    refused(&s, "duplicate", &o, "two outputs write");
    std::fs::create_dir_all(s.out().join("b.json")).expect("mkdir");
    let o = s.run(
        &p,
        &["output=[{use = \"json\", path = \"a.json\"}, {use = \"json\", path = \"b.json\"}]"],
    );
    within_budget("a folder", &o);
    assert!(matches!(o.code, Some(1 | 2)), "{}", o.stderr);
    assert!(o.stderr.contains("is a folder"), "{}", o.stderr);
    assert!(!s.out().join("a.json").exists(), "the first output was committed");

    // A link inside --out that leads out of it.
    #[cfg(unix)]
    {
        let s = Scratch::new();
        std::fs::create_dir_all(s.out()).expect("mkdir");
        std::os::unix::fs::symlink(outside.path(), s.out().join("link")).expect("symlink");
        let o = s.run(&p, &["output.0.path=\"link/x.json\""]);
        within_budget("link", &o);
        assert!(o.stderr.contains("leads out"), "{}", o.stderr);
        assert_eq!(std::fs::read_dir(outside.path()).expect("list").count(), 0);
    }
}

#[test]
fn files_a_pipeline_names_stay_in_its_folder_unless_the_command_line_allows_more() {
    let s = Scratch::new();
    let secret = s.write("secret.rhai", "root:x:0:0:the secret line\n");
    let secret_toml = s.write("secret.toml", "token = \"the secret line\"\n");
    let sub = s.path().join("sub");
    std::fs::create_dir(&sub).expect("mkdir");
    let p = sub.join("p.toml");
    std::fs::copy(pipelines().join("tube-gradient.toml"), &p).expect("copy");
    let abs = |p: &Path| p.display().to_string();
    let refused = |label: &str, o: &Outcome| {
        within_budget(label, o);
        assert_eq!(o.code, Some(2), "{label}: {}", o.stderr);
        assert!(
            o.stderr.contains("outside what the pipeline may read") && o.stderr.contains("--allow"),
            "{label}: {}",
            o.stderr
        );
        assert!(
            !o.stderr.contains("the secret line"),
            "{label}: quoted {}",
            o.stderr
        );
    };
    let sets = [
        ("script, parent", "grade.f=\"../secret.rhai#f\"".to_string()),
        ("script, absolute", format!("grade.f=\"{}#f\"", abs(&secret))),
        ("machine, parent", "machine=\"../secret.toml\"".to_string()),
        ("machine, absolute", format!("machine=\"{}\"", abs(&secret_toml))),
        (
            "machine base",
            "machine={base = \"../secret.toml\", name = \"x\"}".to_string(),
        ),
    ];
    for (label, set) in &sets {
        refused(label, &s.check(&p, &[set]));
    }
    // A model, a machining cell and a plugin library named outside.
    let head = "[materials.a]\ncolour = [255, 0, 0]\n\n[slice]\nuse = \"uniform\"\nthickness = 1.0\n\n";
    let model = sub.join("model.toml");
    std::fs::write(
        &model,
        format!("[model]\nuse = \"stl\"\nfile = \"../secret.toml\"\n\n{head}[[output]]\nuse = \"json\"\npath = \"plan.json\"\n"),
    )
    .expect("write");
    refused("model", &s.check(&model, &[]));
    let cell = sub.join("cell.toml");
    std::fs::write(
        &cell,
        format!("[model]\nuse = \"tube\"\nheight = 2.0\n\n{head}[[output]]\nuse = \"nc\"\npath = \"x.nc\"\nmachine = \"{}\"\n", abs(&secret_toml)),
    )
    .expect("write");
    refused("cell", &s.check(&cell, &[]));
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(&secret, sub.join("gradient.rhai")).expect("symlink");
        refused("a link out", &s.check(&p, &[]));
        std::fs::remove_file(sub.join("gradient.rhai")).expect("unlink");
    }
    // The pipeline cannot widen its reach, nor load code.
    let o = s.check(&p, &["script_dirs=[\"/\"]"]);
    assert_eq!(o.code, Some(2), "{}", o.stderr);
    assert!(
        o.stderr.contains("cannot widen") && o.stderr.contains("--allow"),
        "{}",
        o.stderr
    );
    let o = s.check(&p, &[&format!("plugins=[\"{}\"]", abs(&secret_toml))]);
    assert_eq!(o.code, Some(2), "{}", o.stderr);
    assert!(
        o.stderr.contains("cannot load code by itself") && o.stderr.contains("--plugin"),
        "{}",
        o.stderr
    );
    // The command line lets a folder in: the script is read (and is no Rhai).
    let mut args: Vec<OsString> = vec!["check".into(), p.clone().into(), "--set".into()];
    args.push("grade.f=\"../secret.rhai#f\"".into());
    args.extend(["--allow".into(), s.path().into()]);
    let o = lamina_in(s.path(), &args);
    assert_eq!(o.code, Some(2), "{}", o.stderr);
    assert!(o.stderr.contains("does not compile"), "{}", o.stderr);
}

/// A run long enough to be interrupted: a tube sliced into a thousand layers.
fn long_run(s: &Scratch) -> Child {
    std::fs::copy(pipelines().join("gradient.rhai"), s.path().join("gradient.rhai")).expect("copy");
    let mut command = Command::new(env!("CARGO_BIN_EXE_lamina"));
    // The run takes SIGINT as a terminal delivers it, whatever this test inherited: a
    // test started in the background by a shell without job control ignores SIGINT,
    // and its children would too.
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: between fork and exec the child only resets a signal's disposition,
        // which is async-signal-safe.
        unsafe {
            command.pre_exec(|| {
                libc::signal(libc::SIGINT, libc::SIG_DFL);
                Ok(())
            });
        }
    }
    command
        .current_dir(s.path())
        .args(["run"])
        .arg(pipelines().join("tube-gradient.toml"))
        .arg("--out")
        .arg(s.out())
        .args([
            "-q",
            "--set",
            // About 3 s here: long enough that a loaded machine still signals it
            // while it runs.
            "slice.thickness=0.004",
            "--set",
            "model.segments=2048",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("lamina starts")
}

#[cfg(unix)]
#[test]
fn an_interrupted_run_leaves_no_output_and_its_leftovers_are_removed_by_the_next() {
    for signal in [libc::SIGKILL, libc::SIGINT, libc::SIGTERM] {
        let s = Scratch::new();
        let mut child = long_run(&s);
        // Until the output's temporary file exists, then a little longer.
        let started = Instant::now();
        while s.outputs().is_empty() && started.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_millis(100));
        // SAFETY: sending a signal to our own child.
        unsafe { libc::kill(child.id() as libc::pid_t, signal) };
        let status = child.wait().expect("wait");
        assert!(!status.success(), "the run finished before the signal");
        assert!(
            !s.out().join("tube-gradient.json").exists(),
            "an interrupted run committed its output"
        );
        if signal != libc::SIGKILL {
            // A signal that can be caught ends the run as it would, and nothing of the
            // run is left.
            assert_eq!(status.code(), Some(128 + signal), "{status:?}");
            assert_eq!(s.outputs(), Vec::<PathBuf>::new(), "signal {signal}");
            continue;
        }
        // What a killed run leaves deeper in the folder (a process id above Linux's
        // largest is never running).
        let deep = s.out().join("a/b");
        std::fs::create_dir_all(&deep).expect("mkdir");
        std::fs::write(deep.join(".lamina-4194399-x.partial"), "left").expect("write");
        // The next run into the same folder cleans up and commits.
        let o = s.run(&pipelines().join("tube-gradient.toml"), &[]);
        within_budget("the next run", &o);
        assert_eq!(o.code, Some(0), "{}", o.stderr);
        let files: Vec<_> = s
            .outputs()
            .into_iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        assert_eq!(files, vec!["tube-gradient.json".to_string()], "signal {signal}");
    }
}

#[test]
fn two_runs_into_one_folder_leave_each_file_whole() {
    let s = Scratch::new();
    let first = long_run(&s);
    let second = long_run(&s);
    for mut child in [first, second] {
        assert!(child.wait().expect("wait").success());
    }
    let plan = std::fs::read(s.out().join("tube-gradient.json")).expect("the plan");
    let value: serde_json::Value = serde_json::from_slice(&plan).expect("whole JSON");
    assert!(value.get("layers").is_some());
    assert_eq!(s.outputs().len(), 1, "{:?}", s.outputs());
}

/// A small tmpfs mounted for the test (as root), unmounted when dropped.
#[cfg(target_os = "linux")]
struct Mount(PathBuf);

#[cfg(target_os = "linux")]
impl Mount {
    fn tmpfs(at: &Path, options: &str) -> Option<Self> {
        std::fs::create_dir_all(at).ok()?;
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", options, "lamina-test"])
            .arg(at)
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| Mount(at.to_path_buf()))
    }
}

#[cfg(target_os = "linux")]
impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_or_a_read_only_folder_gives_a_clear_error_and_no_file() {
    let s = Scratch::new();
    let Some(full) = Mount::tmpfs(&s.out(), "size=64k") else {
        skip("a tmpfs cannot be mounted here (not root?) for the full-disk and read-only cases");
        return;
    };
    let o = s.run(&pipelines().join("tube-gradient.toml"), &["slice.thickness=0.05"]);
    within_budget("a full disk", &o);
    assert_eq!(o.code, Some(1), "{}", o.stderr);
    assert!(o.stderr.contains("No space left"), "{}", o.stderr);
    assert!(s.outputs().is_empty(), "{:?}", s.outputs());
    drop(full);

    let s = Scratch::new();
    let Some(_read_only) = Mount::tmpfs(&s.out(), "ro,size=64k") else {
        panic!("a read-only tmpfs could not be mounted where a writable one could");
    };
    let o = s.run(&pipelines().join("tube-gradient.toml"), &[]);
    within_budget("a read-only folder", &o);
    assert_eq!(o.code, Some(1), "{}", o.stderr);
    assert!(o.stderr.contains("Read-only file system"), "{}", o.stderr);
}

/// A UV sphere of radius `r` standing on the bed, `n` rings of `n` segments: about
/// 2 n² triangles, written as binary STL.
fn sphere_stl(path: &Path, n: usize, r: f64) -> usize {
    let vertex = |i: usize, j: usize| {
        let (th, ph) = (
            std::f64::consts::PI * i as f64 / n as f64,
            std::f64::consts::TAU * (j % n) as f64 / n as f64,
        );
        [r * th.sin() * ph.cos(), r * th.sin() * ph.sin(), r + r * th.cos()]
    };
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (
                vertex(i, j),
                vertex(i + 1, j),
                vertex(i + 1, j + 1),
                vertex(i, j + 1),
            );
            // The pole rows have one degenerate triangle each: left out.
            if i > 0 {
                triangles.push([a, b, c]);
            }
            if i + 1 < n {
                triangles.push([a, c, d]);
            }
        }
    }
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).expect("create"));
    out.write_all(&[0u8; 80]).expect("write");
    out.write_all(&(triangles.len() as u32).to_le_bytes())
        .expect("write");
    for t in &triangles {
        out.write_all(&[0u8; 12]).expect("write");
        for v in t {
            for c in v {
                out.write_all(&(*c as f32).to_le_bytes()).expect("write");
            }
        }
        out.write_all(&[0, 0]).expect("write");
    }
    out.flush().expect("flush");
    triangles.len()
}

#[test]
fn a_five_million_triangle_mesh_runs_within_budget() {
    let s = Scratch::new();
    let count = sphere_stl(&s.path().join("sphere.stl"), 1582, 20.0);
    assert!(count >= 5_000_000, "{count}");
    let pipeline = pipeline_for("sphere.stl").replace("place = \"centre\"\n", "")
        + "\n[discretise]\nuse = \"offset\"\ncount = 4\n";
    let p = s.write("p.toml", pipeline);
    let o = s.run(&p, &["slice.thickness=0.2"]);
    within_budget("5 M triangles", &o);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(s.out().join("plan.json")).expect("the plan")).expect("JSON");
    assert_eq!(plan["layers"].as_array().map(Vec::len), Some(200));
}

/// A graded box named `name` (TOML basic-string escapes allowed), written as 3MF and
/// SVG, graded by the script `f`.
fn named_box(name: &str, f: &str) -> String {
    format!(
        r#"name = "names"

[[parts]]
name = "{name}"
materials = ["red", "blue\u0007"]
[parts.model]
use = "box"
size = [10.0, 10.0, 1.0]
[parts.grade]
use = "script"
f = "{f}"

[materials.red]
colour = [255, 0, 0]
[materials."blue\u0007"]
colour = [0, 0, 255]

[slice]
use = "uniform"
thickness = 0.5

[[output]]
use = "3mf"
path = "names.3mf"

[[output]]
use = "svg"
path = "svg/names"
"#
    )
}

#[test]
fn control_characters_in_names_make_valid_xml_and_reach_no_terminal_raw() {
    let probe = std::process::Command::new("python3")
        .args(["-c", "import zipfile, xml.etree.ElementTree"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        crate::support::skip("python3 is not installed");
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let o = crate::support::try_run_text(dir.path(), &named_box("box\\u001b[2J\\u0007", "0.5"));
    assert!(o.status.success(), "{}", crate::support::text(&o.stderr));
    // An XML parser of Python's own reads both files.
    let check = std::process::Command::new("python3")
        .arg("-c")
        .arg(
            "import sys, zipfile, glob, xml.etree.ElementTree as ET\n\
             z = zipfile.ZipFile(sys.argv[1])\n\
             ET.fromstring(z.read('3D/3dmodel.model'))\n\
             for f in glob.glob(sys.argv[2] + '/*.svg'):\n    ET.parse(f)\n\
             print('ok')",
        )
        .arg(dir.path().join("out/names.3mf"))
        .arg(dir.path().join("out/svg"))
        .output()
        .expect("python3 runs");
    assert_eq!(
        crate::support::text(&check.stdout).trim(),
        "ok",
        "{}",
        crate::support::text(&check.stderr)
    );
    // A script's message with an escape sequence is shown, not obeyed.
    let dir = tempfile::tempdir().expect("tempdir");
    let o = crate::support::try_run_text(
        dir.path(),
        &named_box("box", "throw \\\"\\u001b[2J\\u001b[32mall checks passed\\\""),
    );
    let err = crate::support::text(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(!err.contains('\u{1b}'), "{err:?}");
    assert!(err.contains("\\x1b[2J"), "{err}");
    // The failed run leaves no folder behind: not `out`, which it made.
    assert!(
        !dir.path().join("out").exists(),
        "a failed run leaves its folders"
    );
}

#[test]
fn an_output_name_no_file_system_takes_is_refused_by_check_and_run_before_anything_is_written() {
    let long = "a".repeat(300);
    for (bad, want) in [
        (format!("{long}.json"), "a name of 305 bytes, longer than the 255"),
        ("x\\u0000y.json".to_string(), "holds a NUL character"),
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let text = format!(
            "{}\n[[output]]\nuse = \"json\"\npath = \"{bad}\"\n",
            named_box("box", "0.5")
        );
        let p = crate::support::write(dir.path(), "p.toml", &text);
        let check = crate::support::lamina(&["check", p.to_str().expect("utf-8")]);
        let err = crate::support::text(&check.stderr);
        assert_eq!(check.status.code(), Some(2), "{err}");
        assert!(err.contains(want) && err.contains("[output.2] path"), "{err}");
        let run = crate::support::try_run(&p, &dir.path().join("out"), &[]);
        assert!(!run.status.success());
        assert!(
            !dir.path().join("out/names.3mf").exists(),
            "the first output is not committed when a later one cannot be"
        );
    }
}
