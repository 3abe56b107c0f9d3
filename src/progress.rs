//! Progress and summaries on the terminal: a progress bar when stderr is a terminal,
//! nothing otherwise; warnings are printed above the bar.

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};
use lamina_core::runtime::{Observer, RunReport};

pub struct Progress {
    bar: Option<ProgressBar>,
    quiet: bool,
    /// Warnings by their shape (numbers left out): how many of each, and the first
    /// one's text. A layer-by-layer warning is printed once, with its count at the end.
    seen: std::sync::Mutex<Vec<Seen>>,
}

/// One shape of warning: the shape, the first one's text and how many came.
#[derive(Clone)]
struct Seen {
    shape: String,
    first: String,
    count: usize,
}

/// A warning with its numbers left out: the same warning on another layer.
fn shape(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut digits = false;
    for c in message.chars() {
        let d = c.is_ascii_digit() || (digits && c == '.');
        if d && !digits {
            out.push('#');
        } else if !d {
            out.push(c);
        }
        digits = d;
    }
    out
}

impl Progress {
    pub fn new(quiet: bool) -> Self {
        Self {
            bar: None,
            quiet,
            seen: std::sync::Mutex::new(Vec::new()),
        }
        .with_bar()
    }

    fn with_bar(mut self) -> Self {
        if !self.quiet && std::io::stderr().is_terminal() {
            let bar = ProgressBar::hidden();
            bar.set_style(
                ProgressStyle::with_template("{spinner} layers {pos}/{len} [{bar:40}] {elapsed} (eta {eta})")
                    .unwrap_or_else(|_| ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
            self.bar = Some(bar);
        }
        self
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
        let seen = self.seen.lock().map(|s| s.clone()).unwrap_or_default();
        for w in seen.iter().filter(|w| w.count > 1) {
            eprintln!("warning: {} more like \"{}\"", w.count - 1, w.first);
        }
    }
}

impl Observer for Progress {
    fn started(&self, layers: usize) {
        if let Some(bar) = &self.bar {
            bar.set_length(layers as u64);
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
        }
    }

    fn layer_done(&self, _index: usize) {
        if let Some(bar) = &self.bar {
            bar.inc(1);
        }
    }

    /// Warnings are printed even when quiet: `-q` silences the chatter, not what a
    /// user must know about the output.
    fn warning(&self, message: &str) {
        if let Ok(mut seen) = self.seen.lock() {
            let key = shape(message);
            match seen.iter_mut().find(|w| w.shape == key) {
                Some(w) => {
                    w.count += 1;
                    return;
                }
                None => seen.push(Seen {
                    shape: key,
                    first: message.to_string(),
                    count: 1,
                }),
            }
        }
        match &self.bar {
            Some(bar) => bar.suspend(|| eprintln!("warning: {message}")),
            None => eprintln!("warning: {message}"),
        }
    }
}

pub fn summary(report: &RunReport, timings: bool) {
    eprintln!(
        "{} layers, {} regions, {} warnings in {:.2} s",
        report.layers,
        report.regions,
        report.warnings,
        report.timings.wall().as_secs_f64()
    );
    match (report.build_time, report.sequential_time) {
        (Some(t), Some(s)) if s > 0.0 => {
            eprintln!(
                "planned build time: {t:.1} s ({s:.1} s one tool at a time: ratio {:.3})",
                t / s
            )
        }
        (Some(t), _) => eprintln!("planned build time: {t:.1} s"),
        _ => {}
    }
    if let Some((deposited, volume)) = report.fill
        && volume > 0.0
    {
        eprintln!(
            "beads deposit {deposited:.1} mm³ of the sub-regions' {volume:.1} mm³ ({:.1} %)",
            100.0 * deposited / volume
        );
    }
    if let Some(o) = &report.orientation {
        let [x, y, z] = o.direction;
        eprintln!(
            "build direction [{x:.4}, {y:.4}, {z:.4}] (least {}), of {} candidates:",
            o.criterion,
            o.candidates.len()
        );
        eprintln!(
            "  {:<14} {:>26} {:>14} {:>11} {:>17}",
            "candidate", "direction", "cost", "height mm", "area x angle"
        );
        for c in o.candidates.iter().take(8) {
            let [x, y, z] = c.direction;
            eprintln!(
                "  {:<14} [{x:>7.4}, {y:>7.4}, {z:>7.4}] {:>14.4} {:>11.3} {:>17.2}",
                c.label, c.cost, c.height, c.surface_angle
            );
        }
    }
    for f in &report.files {
        eprintln!("wrote {}", f.display());
    }
    if timings {
        self::timings(report);
    }
}

/// Per-stage times (summed over threads) and the wall time, on stdout.
pub fn timings(report: &RunReport) {
    println!("stage        time (s, summed over threads)");
    for (kind, d) in report.timings.entries() {
        println!("{:<12} {:.4}", kind.name(), d.as_secs_f64());
    }
    println!("{:<12} {:.4}", "wall", report.timings.wall().as_secs_f64());
}
