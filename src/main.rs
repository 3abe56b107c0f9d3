//! `lamina`: the command line of Lamina. Parses arguments, runs pipelines through
//! lamina-core, and is the only part of Lamina that knows about the terminal.

mod catalogue;
mod generate;
mod progress;
mod report;
mod scaffold;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use lamina_core::pipeline::{Override, Pipeline};
use lamina_core::plugin::{ChildProgram, Isolation};
use lamina_core::runtime::{Engine, RunOptions};
use lamina_core::{Registry, StageKind};

// Built-in stages register themselves with `inventory`; referencing each crate keeps
// the linker from dropping those registrations.
use lamina_discretise as _;
use lamina_export as _;
use lamina_gcode as _;
use lamina_grade as _;
use lamina_model as _;
use lamina_orient as _;
use lamina_plan as _;
use lamina_preview as _;
use lamina_process as _;
use lamina_sequence as _;
use lamina_slice as _;
use lamina_sort as _;
use lamina_sources as _;

#[derive(Debug, Parser)]
#[command(
    name = "lamina",
    version = lamina_core::VERSION,
    about = "Plans the layered manufacturing of functionally graded multi-material objects",
    after_help = concat!(
        "A pipeline file (TOML) names the stages: model, slice, discretise, grade, plan and ",
        "outputs; `pipelines/` holds examples and `lamina plugins` lists every stage with its options.\n\n",
        "  lamina check pipelines/gear-z-gradient.toml    find every mistake, run nothing\n",
        "  lamina run pipelines/gear-z-gradient.toml      write the outputs into ./out\n",
        "  lamina view pipelines/gear-z-gradient.toml     the same, and open the layer viewer\n\n",
        "Exit codes: 0 done; 1 the run failed (nothing is left under an output's name); ",
        "2 the command line or the pipeline is wrong (nothing was run)."
    )
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Args)]
struct PipelineArgs {
    /// The pipeline file (TOML).
    pipeline: PathBuf,
    /// Replaces the model file of a single-part pipeline.
    #[arg(long, value_name = "PATH")]
    model: Option<PathBuf>,
    /// Overrides a pipeline value, e.g. `--set slice.thickness=0.1` (repeatable).
    #[arg(long = "set", value_name = "TABLE.KEY=VALUE")]
    set: Vec<Override>,
    /// Loads a plugin library (repeatable); a pipeline's `plugins` only says which it
    /// needs, and is refused without them.
    #[arg(long = "plugin", value_name = "PATH")]
    plugins: Vec<PathBuf>,
    /// Lets the pipeline read files (models, machine profiles, cells, scripts) under
    /// this folder, or this one file, too (repeatable). Without it a pipeline reads
    /// only in its own folder and the output folder.
    #[arg(long = "allow", value_name = "PATH")]
    allow: Vec<PathBuf>,
    /// Runs each plugin in a process of its own: a crash or hang of the plugin fails
    /// the run with its name rather than ending lamina, at the cost of serving its
    /// calls one at a time. (`lamina check` always does.)
    #[arg(long)]
    isolate_plugins: bool,
    /// With --isolate-plugins: how long a plugin may go without answering before it
    /// is stopped.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
    plugin_timeout: f64,
}

impl PipelineArgs {
    /// The pipeline, reading within its folder, `out` and what `--allow` names.
    fn load(&self, out: Option<&std::path::Path>) -> lamina_core::Result<Pipeline> {
        let allowed: Vec<PathBuf> = self.allow.iter().cloned().chain(out.map(PathBuf::from)).collect();
        Pipeline::load_allowing(&self.pipeline, &self.set, &allowed)
    }

    /// Where the plugins run: apart when asked, or when `apart` says they must.
    fn isolation(&self, apart: bool) -> lamina_core::Result<Isolation> {
        if !(self.isolate_plugins || apart) {
            return Ok(Isolation::InProcess);
        }
        isolated(self.plugin_timeout)
    }
}

/// Plugins each in a child process running this program's `plugin-host`.
fn isolated(timeout: f64) -> lamina_core::Result<Isolation> {
    if !(timeout.is_finite() && timeout > 0.0 && timeout <= 1e6) {
        return Err(lamina_core::Error::config(format!(
            "--plugin-timeout is {timeout}: it must be a number of seconds above 0 and at most 1000000"
        )));
    }
    let mut program =
        ChildProgram::this(&["plugin-host"]).map_err(|e| lamina_core::Error::io("this program's path", e))?;
    program.timeout = std::time::Duration::from_secs_f64(timeout);
    Ok(Isolation::Child(program))
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Runs a pipeline and writes its outputs.
    ///
    /// Loads the model, slices it into layers, discretises and grades each layer, plans
    /// the toolpaths and writes every `[[output]]` of the pipeline into the output
    /// folder, layers running in parallel. The files appear under their names only
    /// when the whole run succeeds: a failed or interrupted run leaves none behind.
    /// Warnings are gathered and printed once per kind at the end, with the layers
    /// they hit.
    Run {
        #[command(flatten)]
        args: PipelineArgs,
        /// Output folder, created if missing; outputs' paths are relative to it.
        #[arg(long, value_name = "DIR", default_value = "out")]
        out: PathBuf,
        /// Worker threads (default: all cores); the outputs are the same whatever the
        /// count.
        #[arg(long, value_name = "N")]
        threads: Option<usize>,
        /// No progress bar and no summary; warnings and errors are still printed.
        #[arg(long, short)]
        quiet: bool,
        /// Prints every warning and note as it comes, each with its layer, rather than
        /// one line for each kind of warning (with the layers it hit) at the end.
        #[arg(long, short)]
        verbose: bool,
        /// Prints the time spent in each stage.
        #[arg(long)]
        timings: bool,
    },
    /// Runs a pipeline and opens its layers in the HTML viewer (an `html` output is added
    /// when the pipeline has none).
    ///
    /// The viewer is one self-contained page (it needs no network): each layer's
    /// sub-regions in their colours with their compositions on hover, the planned
    /// toolpaths, the machine's moves read back from the G-code the run wrote (with a
    /// player), and a 3D view of the layer stack. It is opened with the desktop's
    /// default browser (`xdg-open`); its path is printed either way.
    View {
        #[command(flatten)]
        args: PipelineArgs,
        /// Output folder, created if missing.
        #[arg(long, value_name = "DIR", default_value = "out")]
        out: PathBuf,
        /// Only write the viewer and print its path.
        #[arg(long)]
        no_open: bool,
    },
    /// Validates a pipeline (stages, options, scripts, plugins) without running it; every wrong stage is reported, in file order, and the exit code is 2.
    Check {
        #[command(flatten)]
        args: PipelineArgs,
    },
    /// Generates a model (gear, gear-shaft, tube, blade, cube, box) and writes it as STL,
    /// OBJ or 3MF; the meshes of an assembly go into one file.
    Generate {
        /// The model stage; `lamina plugins model` lists them with their options.
        model: String,
        /// Output file; its extension chooses the format (.stl, .obj, .3mf).
        #[arg(short, long, value_name = "FILE")]
        output: Option<PathBuf>,
        /// No summary.
        #[arg(long, short)]
        quiet: bool,
        /// The model's options: `--key value`, `--key=value`, `key=value` or
        /// `--set key=value`; values are TOML (`12`, `2.5`, `[50.0, 20.0]`), anything else
        /// a string.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, value_name = "OPTIONS")]
        options: Vec<String>,
    },
    /// Writes a plugin crate with one stage, its tests and a pipeline that uses it.
    NewPlugin {
        /// The stage's name, also the crate's (lower case, digits, `-`, `_`).
        name: String,
        /// The stage kind: grade, discretise, export, model, plan, process, orient, sort, slice or sequence.
        #[arg(long, default_value = "grade")]
        kind: String,
        /// The crate's folder (default: the name, in the current directory).
        #[arg(long, value_name = "DIR")]
        dir: Option<PathBuf>,
        /// A checkout of Lamina's source to take lamina-api and lamina-test-support
        /// from (a `[patch]` table in the crate's manifest); without it, the crate
        /// depends on their published releases.
        #[arg(long, value_name = "PATH")]
        lamina: Option<PathBuf>,
    },
    /// Lists the available stages with their documentation and options.
    Plugins {
        /// Only stages of this kind (model, slice, sort, discretise, grade, sequence, plan, export).
        kind: Option<String>,
        /// Machine-readable output.
        #[arg(long, conflicts_with = "markdown")]
        json: bool,
        /// The pipeline reference in Markdown (docs/pipeline-reference.md).
        #[arg(long)]
        markdown: bool,
        /// Loads a plugin library first (repeatable), in a process of its own: listing
        /// stages runs none of a plugin's code in lamina.
        #[arg(long = "plugin", value_name = "PATH")]
        plugins: Vec<PathBuf>,
    },
    /// Loads a plugin library and serves its calls over standard input and output,
    /// for a lamina that runs its plugins apart (`--isolate-plugins`).
    #[command(hide = true)]
    PluginHost { library: PathBuf },
}

/// A failure and whether it lies in what the user asked for (exit code 2) rather than
/// in running it (exit code 1).
struct Failure {
    error: lamina_core::Error,
    usage: bool,
}

impl From<lamina_core::Error> for Failure {
    fn from(error: lamina_core::Error) -> Self {
        let usage = error.is_usage();
        Self { error, usage }
    }
}

/// Counts what each thread holds, so that a script call holding more than its budget
/// is stopped (`ScriptLimits::max_memory`). The memory comes from jemalloc: a run makes
/// millions of small, short-lived allocations on every worker (the overlays' graphs,
/// the beads), which it serves in about a twentieth less CPU time than the system
/// allocator (for some 10 MiB more peak memory on the graded two-tool 3DBenchy).
#[global_allocator]
static ALLOCATOR: lamina_core::script::CountingAllocator<tikv_jemallocator::Jemalloc> =
    lamina_core::script::CountingAllocator::new(tikv_jemallocator::Jemalloc);

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A plugin's process has no outputs of its own to remove.
    if !matches!(cli.command, Command::PluginHost { .. }) {
        remove_outputs_on_signals();
    }
    match execute(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            report::print(&f.error);
            ExitCode::from(if f.usage { 2 } else { 1 })
        }
    }
}

/// SIGINT, SIGTERM and SIGHUP end the process as they would, with their exit status
/// (128 + the signal), after the run's temporary outputs and the folders made for them
/// are removed: an interrupted run leaves nothing behind. (SIGKILL cannot be caught:
/// the next run into the folder removes what a killed one left.)
fn remove_outputs_on_signals() {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
            return;
        };
        std::thread::spawn(move || {
            if let Some(signal) = signals.forever().next() {
                lamina_core::output::abandon();
                eprintln!("lamina: interrupted");
                std::process::exit(128 + signal);
            }
        });
    }
}

/// Parses and builds the pipeline. Everything that fails here (options, scripts that do
/// not compile, plugins) is a usage error.
fn engine(
    args: &PipelineArgs,
    out: Option<&std::path::Path>,
    threads: Option<usize>,
    apart: bool,
) -> Result<Engine, Failure> {
    let build = || {
        let pipeline = args.load(out)?;
        let options = RunOptions {
            threads,
            model: args.model.clone(),
            plugins: args.plugins.clone(),
            isolation: args.isolation(apart)?,
            ..RunOptions::default()
        };
        Engine::build(pipeline, Registry::linked()?, &options)
    };
    build().map_err(|error| Failure { error, usage: true })
}

fn execute(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Run {
            args,
            out,
            threads,
            quiet,
            verbose,
            timings,
        } => {
            if threads == Some(0) {
                return Err(lamina_core::Error::config("--threads must be at least 1").into());
            }
            let engine = engine(&args, Some(&out), threads, false)?;
            let observer = progress::Progress::new(quiet, verbose);
            let report = engine.run(&out, &observer);
            observer.finish();
            let report = report?;
            if !quiet {
                progress::summary(&report, timings);
            } else if timings {
                progress::timings(&report);
            }
            Ok(())
        }
        Command::View { args, out, no_open } => view(&args, &out, no_open),
        Command::Check { args } => {
            // Checking runs none of a plugin's code in lamina.
            let engine = engine(&args, None, None, true)?;
            // The model is read as a run reads it: a file that does not parse, a part
            // off the bed or in the wrong units fails here, not in the run.
            let parts = engine
                .check_models()
                .map_err(|error| Failure { error, usage: true })?;
            println!("{}: ok", args.pipeline.display());
            for line in engine.summary().into_iter().chain(parts) {
                println!("  {line}");
            }
            Ok(())
        }
        Command::Generate {
            model,
            output,
            quiet,
            options,
        } => {
            // Everything before writing is about what the user asked for (exit code 2).
            let usage = |error| Failure { error, usage: true };
            let request = generate::request(&model, output, quiet, &options).map_err(usage)?;
            let meshes = generate::meshes(&Registry::linked()?, &request).map_err(usage)?;
            generate::write(&meshes, &request.output)?;
            if !request.quiet {
                println!("{}", request.output.display());
                for line in generate::describe(&meshes) {
                    println!("  {line}");
                }
            }
            Ok(())
        }
        Command::NewPlugin {
            name,
            kind,
            dir,
            lamina,
        } => new_plugin(&name, &kind, dir, lamina),
        Command::Plugins {
            kind,
            json,
            markdown,
            plugins,
        } => list_plugins(kind.as_deref(), json, markdown, &plugins),
        Command::PluginHost { library } => {
            std::process::exit(lamina_core::plugin::serve_child(&library));
        }
    }
}

/// `lamina view`: a run with the HTML viewer among its outputs, opened in a browser.
fn view(args: &PipelineArgs, out: &Path, no_open: bool) -> Result<(), Failure> {
    let build = || {
        let mut pipeline = args.load(Some(out))?;
        if !pipeline.outputs.iter().any(|o| o.use_name() == Some("html")) {
            let mut table = toml::Table::new();
            table.insert("use".into(), "html".into());
            table.insert("path".into(), format!("{}.html", pipeline.name).into());
            pipeline
                .outputs
                .push(lamina_core::pipeline::TableRef::detached("output", table));
        }
        let options = RunOptions {
            plugins: args.plugins.clone(),
            model: args.model.clone(),
            isolation: args.isolation(false)?,
            ..RunOptions::default()
        };
        Engine::build(pipeline, Registry::linked()?, &options)
    };
    let engine = build().map_err(|error| Failure { error, usage: true })?;
    let observer = progress::Progress::new(false, false);
    let report = engine.run(out, &observer);
    observer.finish();
    let report = report?;
    let page = report
        .files
        .iter()
        .find(|f| f.extension().is_some_and(|e| e == "html"))
        .cloned()
        .ok_or_else(|| lamina_core::Error::config("the run wrote no HTML viewer"))?;
    println!("{}", page.display());
    if !no_open {
        // Absolute, so that an output folder named `-x` is not read as an option.
        let page = std::path::absolute(&page).unwrap_or(page);
        let opened = std::process::Command::new("xdg-open")
            .arg(&page)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !opened {
            eprintln!("open {} in a browser (it needs no network)", page.display());
        }
    }
    Ok(())
}

/// `lamina new-plugin`: a plugin crate written from the template of its kind, and how
/// to build and load it.
fn new_plugin(name: &str, kind: &str, dir: Option<PathBuf>, lamina: Option<PathBuf>) -> Result<(), Failure> {
    let request =
        scaffold::Request::new(name, kind, dir, lamina).map_err(|error| Failure { error, usage: true })?;
    let files = request.write()?;
    println!("{}", request.dir.display());
    for f in files {
        println!("  {}", f.display());
    }
    if request.lamina.is_none() {
        println!(
            "note: it depends on lamina-api {v} from the registry; to take it from a checkout of Lamina, write the crate with --lamina PATH",
            v = lamina_core::VERSION
        );
    }
    println!(
        "build it with `cargo build` in {}, test it with `cargo test`, and load it with `lamina run pipeline.toml --plugin target/debug/{}{}{}`",
        request.dir.display(),
        std::env::consts::DLL_PREFIX,
        name.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    );
    Ok(())
}

/// `lamina plugins`: the stages the program and the given libraries (loaded apart)
/// provide, as text, JSON or Markdown.
fn list_plugins(kind: Option<&str>, json: bool, markdown: bool, plugins: &[PathBuf]) -> Result<(), Failure> {
    let mut registry = Registry::linked()?;
    if !plugins.is_empty() {
        let apart = isolated(ChildProgram::DEFAULT_TIMEOUT.as_secs_f64())?;
        for p in plugins {
            lamina_core::plugin::load_with(&mut registry, p, &apart)?;
        }
    }
    let kind = match kind {
        Some(k) => Some(StageKind::parse(k).ok_or_else(|| {
            lamina_core::Error::config(format!("no stage kind `{k}`"))
                .with_help(format!("kinds: {}", StageKind::ALL.map(|k| k.name()).join(", ")))
        })?),
        None => None,
    };
    let text = if json {
        catalogue::json(&registry, kind)
    } else if markdown {
        catalogue::markdown(&registry, kind)
    } else {
        catalogue::text(&registry, kind)
    };
    print!("{text}");
    Ok(())
}
