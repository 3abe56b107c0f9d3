//! Progress and summaries on the terminal: a progress bar when stderr is a terminal,
//! nothing otherwise; diagnostics grouped by their code, one line a group, once the run
//! ends (`--verbose`: each as it comes, above the bar).

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};
use lamina_core::runtime::{Observer, RunReport};
use lamina_core::{Diagnostic, Severity, StageKind};

pub struct Progress {
    bar: Option<ProgressBar>,
    quiet: bool,
    /// Every diagnostic printed as it comes, rather than grouped at the end.
    verbose: bool,
    /// Diagnostics grouped by kind: one line each at the end.
    groups: std::sync::Mutex<Vec<Group>>,
}

/// Diagnostics of one kind (same severity, stage, part and code) on different layers.
/// A diagnostic without a code (from a plugin older than ABI 7.3) is grouped with
/// those of the same words once their numbers are left out.
struct Group {
    key: (Severity, StageKind, Option<String>, Kind),
    first: Diagnostic,
    layers: Vec<usize>,
    count: usize,
    /// Whether every one said exactly the first one's words.
    identical: bool,
}

/// What a group's diagnostics have in common besides their place.
#[derive(PartialEq, Eq)]
enum Kind {
    Code(String),
    Words(String),
}

impl Kind {
    fn of(d: &Diagnostic) -> Kind {
        if d.code.is_empty() {
            Kind::Words(shape(&d.message))
        } else {
            Kind::Code(d.code.clone())
        }
    }
}

/// `warning[slice.gaps-closed]`: the severity, and the stage and code when there is one.
fn heading(d: &Diagnostic) -> String {
    if d.code.is_empty() {
        d.severity.name().to_string()
    } else {
        format!("{}[{}.{}]", d.severity.name(), d.stage.name(), d.code)
    }
}

/// A message with its numbers left out: the same message about another place.
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

impl Group {
    /// One line: the first diagnostic's words, with the layers and count of all.
    fn line(&self) -> String {
        let d = &self.first;
        if self.count == 1 {
            return format!("{}: {d}", heading(d));
        }
        let mut place = Vec::new();
        if !self.layers.is_empty() {
            let word = if self.layers.len() == 1 { "layer" } else { "layers" };
            place.push(format!(
                "{word} {}",
                lamina_core::text::layer_ranges(&self.layers, 6)
            ));
        }
        if let Some(p) = &d.part {
            place.push(format!("part `{p}`"));
        }
        // When the words differ in their numbers, the ones shown are the first's.
        let first = match (self.identical, d.layer) {
            (false, Some(l)) => format!(", as on layer {l}"),
            (false, None) => ", the first shown".to_string(),
            (true, _) => String::new(),
        };
        format!(
            "{}: {} ({} times{first}): {}",
            heading(d),
            place.join(", "),
            self.count,
            d.message
        )
    }
}

impl Progress {
    pub fn new(quiet: bool, verbose: bool) -> Self {
        Self {
            bar: None,
            quiet,
            verbose,
            groups: std::sync::Mutex::new(Vec::new()),
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

    /// Clears the bar and prints the grouped diagnostics, one line a group. Called
    /// whether the run succeeded or not: what was said before a failure still counts.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
        if self.verbose {
            return;
        }
        let Ok(groups) = self.groups.lock() else { return };
        for g in groups.iter() {
            eprintln!("{}", crate::report::visible(&g.line()));
        }
    }

    fn print(&self, line: &str) {
        match &self.bar {
            Some(bar) => bar.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
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

    /// Diagnostics are printed even when quiet: `-q` silences the chatter, not what a
    /// user must know about the output. `--verbose` prints each as it comes; otherwise
    /// they are grouped and printed at the end.
    fn diagnostic(&self, d: &Diagnostic) {
        if self.verbose {
            self.print(&crate::report::visible(&format!("{}: {d}", heading(d))));
            return;
        }
        let Ok(mut groups) = self.groups.lock() else {
            return;
        };
        let key = (d.severity, d.stage, d.part.clone(), Kind::of(d));
        match groups.iter_mut().find(|g| g.key == key) {
            Some(g) => {
                g.count += 1;
                g.layers.extend(d.layer);
                g.identical &= g.first.message == d.message;
            }
            None => groups.push(Group {
                key,
                first: d.clone(),
                layers: d.layer.into_iter().collect(),
                count: 1,
                identical: true,
            }),
        }
    }
}

pub fn summary(report: &RunReport, timings: bool) {
    eprintln!(
        "{} layers, {} regions, {} warnings in {:.2} s",
        report.layers,
        report.regions,
        report.warnings(),
        report.timings.wall().as_secs_f64()
    );
    // The plan's time moves at the plan's constant speeds, without acceleration,
    // heating or tool changes: a machine file's own estimate is what the machine takes.
    // The comparison with one tool at a time says something only where the tools
    // worked at once: with one busy tool the two times are the same.
    match (report.build_time, report.sequential_time) {
        (Some(t), Some(s)) if s > 0.0 && (t / s - 1.0).abs() >= 5e-4 => {
            eprintln!(
                "the plan's build time (its toolpaths at constant speeds): {t:.1} s ({s:.1} s one tool at a time: ratio {:.3})",
                t / s
            )
        }
        (Some(t), _) => eprintln!("the plan's build time (its toolpaths at constant speeds): {t:.1} s"),
        _ => {}
    }
    if let Some(p) = report.pauses {
        // Of two tools heading for a collision, the paper's rule pauses the one slower
        // along X; a pause decided otherwise breaks it.
        eprintln!(
            "pauses of the concurrent schedule: {} ({} by speed along X, {} forced: only that tool's pause cleared the way, {} by another rule)",
            p.total(),
            p.by_x_speed,
            p.forced,
            p.other
        );
    }
    for m in &report.machine_files {
        if !m.shares.is_empty() && m.part == 0.0 && m.waste.is_empty() {
            // A machining program: its time and what it goes to.
            let total: f64 = m.shares.iter().map(|(_, s)| s).sum();
            let shares: Vec<String> = m
                .shares
                .iter()
                .filter(|(_, s)| *s > 0.0)
                .map(|(k, s)| format!("{k} {:.0} %", 100.0 * s / total.max(1e-9)))
                .collect();
            eprintln!(
                "{}: {} by the file's own estimate: {}",
                m.file.display(),
                duration(m.time),
                shares.join(", ")
            );
            continue;
        }
        let waste: Vec<String> = m
            .waste
            .iter()
            .filter(|(_, v)| *v > 0.0)
            .map(|(k, v)| format!("{k} {v:.1}"))
            .collect();
        let waste = if waste.is_empty() {
            "nothing else".to_string()
        } else {
            waste.join(", ")
        };
        eprintln!(
            "{}: {} by the file's own estimate; deposits part {:.1} mm³ ({:.1} of them transitions), {waste} mm³: waste {:.1} % of all deposition",
            m.file.display(),
            duration(m.time),
            m.part,
            m.transition,
            100.0 * m.waste_share()
        );
    }
    if let Some((deposited, volume)) = report.fill
        && volume > 0.0
    {
        eprintln!(
            "beads deposit {deposited:.1} mm³ of the sub-regions' {volume:.1} mm³ ({:.1} %)",
            100.0 * deposited / volume
        );
    }
    if !report.operations.is_empty() {
        let ops: Vec<String> = report
            .operations
            .iter()
            .map(|(k, n)| format!("{n} {k}"))
            .collect();
        eprintln!("process operations: {}", ops.join(", "));
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

/// Seconds as `1 h 02 min 05 s (3725.0 s)`, the way a user reads a print's time.
fn duration(seconds: f64) -> String {
    let whole = seconds.max(0.0).round() as u64;
    let (h, m, s) = (whole / 3600, whole / 60 % 60, whole % 60);
    let hms = if h > 0 {
        format!("{h} h {m:02} min {s:02} s")
    } else {
        format!("{m} min {s:02} s")
    };
    format!("{hms} ({seconds:.1} s)")
}

/// Per-stage times (summed over threads) and the wall time, on stdout.
pub fn timings(report: &RunReport) {
    println!("stage        time (s, summed over threads)");
    for (kind, d) in report.timings.entries() {
        println!("{:<12} {:.4}", kind.name(), d.as_secs_f64());
    }
    println!("{:<12} {:.4}", "wall", report.timings.wall().as_secs_f64());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(said: &[Diagnostic]) -> Vec<String> {
        let p = Progress::new(true, false);
        for d in said {
            p.diagnostic(d);
        }
        let groups = p.groups.lock().expect("groups");
        groups.iter().map(Group::line).collect()
    }

    #[test]
    fn diagnostics_are_grouped_by_their_code_whatever_their_words() {
        let d = |code: &str, layer: usize, message: &str| {
            Diagnostic::warning(StageKind::Slice, code, message).at_layer(layer, 0.2 * layer as f64)
        };
        let got = lines(&[
            d("open-chains-dropped", 3, "dropped an open chain of 4 points"),
            d(
                "open-chains-dropped",
                4,
                "dropped 120 open chains of 900 points in all",
            ),
            d("gaps-closed", 4, "dropped an open chain of 4 points"),
            d("open-chains-dropped", 5, "dropped an open chain of 7 points"),
        ]);
        assert_eq!(got.len(), 2, "{got:?}");
        assert_eq!(
            got[0],
            "warning[slice.open-chains-dropped]: layers 3-5 (3 times, as on layer 3): dropped an open chain of 4 points"
        );
        assert!(
            got[1].starts_with("warning[slice.gaps-closed]: layer 4 (z = 0.8000 mm): "),
            "{}",
            got[1]
        );
    }

    #[test]
    fn diagnostics_without_a_code_are_grouped_by_their_words_less_their_numbers() {
        let d = |layer: usize, message: &str| {
            Diagnostic::warning(StageKind::Plan, "", message).at_layer(layer, 1.0)
        };
        let got = lines(&[
            d(1, "2 sub-regions left out"),
            d(2, "5 sub-regions left out"),
            d(2, "the schedule gave up"),
        ]);
        assert_eq!(got.len(), 2, "{got:?}");
        assert_eq!(
            got[0],
            "warning: layers 1-2 (2 times, as on layer 1): 2 sub-regions left out"
        );
        assert!(got[1].starts_with("warning: layer 2"), "{}", got[1]);
    }
}
