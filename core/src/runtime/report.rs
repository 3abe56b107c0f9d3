//! What a run tells its observer while it goes, and what it returns.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crate::diagnostic::{Diagnostic, Severity};
use crate::model::Orientation;
use crate::stage::StageKind;

/// Receives progress from a run. Only the CLI knows the terminal: the runtime reports
/// here and never prints.
pub trait Observer: Send + Sync {
    /// The run is about to process `layers` layers.
    fn started(&self, _layers: usize) {}
    /// Layer `index` was handed to the exporters.
    fn layer_done(&self, _index: usize) {}
    /// A stage repaired, dropped or noted something; the run goes on. Said as it
    /// happens, in build order; the report holds them all at the end.
    fn diagnostic(&self, _diagnostic: &Diagnostic) {}
}

/// An observer that ignores everything.
#[derive(Debug, Default, Clone, Copy)]
pub struct Silent;

impl Observer for Silent {}

/// Time spent in each stage kind, summed over all threads.
#[derive(Debug, Default)]
pub struct Timings {
    nanos: [AtomicU64; StageKind::ALL.len()],
    pub(super) wall: AtomicU64,
}

impl Timings {
    pub(super) fn add(&self, kind: StageKind, d: Duration) {
        let i = StageKind::ALL.iter().position(|k| *k == kind).unwrap_or(0);
        self.nanos[i].fetch_add(d.as_nanos() as u64, Ordering::Relaxed);
    }

    pub(super) fn time<T>(&self, kind: StageKind, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.add(kind, start.elapsed());
        out
    }

    /// Time spent in `kind`, summed over threads.
    pub fn get(&self, kind: StageKind) -> Duration {
        let i = StageKind::ALL.iter().position(|k| *k == kind).unwrap_or(0);
        Duration::from_nanos(self.nanos[i].load(Ordering::Relaxed))
    }

    /// Wall-clock time of the whole run.
    pub fn wall(&self) -> Duration {
        Duration::from_nanos(self.wall.load(Ordering::Relaxed))
    }

    /// `(stage, time)` for every stage kind that took any time.
    pub fn entries(&self) -> Vec<(StageKind, Duration)> {
        StageKind::ALL
            .into_iter()
            .map(|k| (k, self.get(k)))
            .filter(|(_, d)| !d.is_zero())
            .collect()
    }
}

/// What a finished run produced.
#[derive(Debug)]
pub struct RunReport {
    pub layers: usize,
    pub regions: usize,
    /// Files written, under their final names.
    pub files: Vec<PathBuf>,
    /// Everything the stages said, in build order (the run's own first, then layer by
    /// layer).
    pub diagnostics: Vec<Diagnostic>,
    pub timings: Timings,
    /// Sum of the planned layer build times (s), when a planner ran.
    pub build_time: Option<f64>,
    /// Sum of the layers' one-tool-at-a-time build times (s), when the planner timed
    /// that baseline (a concurrent planner).
    pub sequential_time: Option<f64>,
    /// The concurrent schedules' pauses by what decided them, when any was kept.
    pub pauses: Option<crate::Pauses>,
    /// Volume the planned beads deposit and volume of the sub-regions they fill (mm³),
    /// when a planner reported its fill.
    pub fill: Option<(f64, f64)>,
    /// The build direction chosen by an `[orient]` stage and the alternatives weighed.
    pub orientation: Option<Orientation>,
    /// How many operations of each kind the `[[process]]` stages planned.
    pub operations: std::collections::BTreeMap<String, usize>,
    /// What each machine file says of itself: its own time, what it deposits.
    pub machine_files: Vec<crate::stage::MachineFileReport>,
}

impl RunReport {
    /// How many of the diagnostics are warnings.
    pub fn warnings(&self) -> usize {
        self.diagnostics
            .iter()
            .filter(|d| d.severity == Severity::Warning)
            .count()
    }
}
