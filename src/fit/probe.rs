//! What a fit measured about itself, for benchmarks (`pipeline bench track`, `pipeline
//! bench fit`): the seconds of each step, the nearest answers reused, and every round.
//! A [`Probe`] is passed to the fit by its caller; the fit only adds to it.

use crate::skeleton::Pose;
use std::sync::Mutex;

/// The name of a part of the `rho_c` step in [`Probe::timings`]: [`STEP_PART_PREFIX`]
/// followed by `$part` (one literal, so the two cannot drift apart).
macro_rules! rho_c_part {
    ($part:literal) => {
        concat!("rho_c: ", $part)
    };
}

/// The names of a step's parts in [`Probe::timings`] begin with this, so that a report can
/// tell them from whole steps (whose sum already holds them).
pub const STEP_PART_PREFIX: &str = rho_c_part!("");

/// The parts of the `rho_c` step in [`Probe::timings`] ([`super::contact::ContactTimes`]).
pub(super) const RHO_C_STALENESS: &str = rho_c_part!("stale lists found");
pub(super) const RHO_C_REBUILDING: &str = rho_c_part!("lists rebuilt");
pub(super) const RHO_C_SCANNING: &str = rho_c_part!("lists scanned");

/// What one round of a fit did (`pipeline bench track --rounds`): one record per round the
/// fit's `iterations` count.
#[derive(Debug, Clone)]
pub struct RoundRecord {
    /// Which fit of the frame the round belongs to: 0 the first, 1 and on the restarts.
    pub start: usize,
    /// The round's number within its fit, from 1.
    pub round: usize,
    pub kind: RoundKind,
    /// The largest joint motion from the pose before the round, metres.
    pub moved: f64,
    /// Paper eq. 4 at the round's pose with its own pairs (for a rejected step: at the
    /// candidate).
    pub energy: f64,
    /// The pose after the round (for a rejected step: the candidate).
    pub pose: Pose,
}

/// How a round moved the pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RoundKind {
    /// LM steps on the held pairs.
    Step,
    /// The baselines: the Anderson extrapolation was kept instead of the step.
    Extrapolated,
}

impl RoundKind {
    pub fn name(self) -> &'static str {
        match self {
            RoundKind::Step => "step",
            RoundKind::Extrapolated => "extrapolated",
        }
    }
}
/// The measurements of every fit it was passed to (the steps run side by side, so each
/// field is behind a lock).
#[derive(Default)]
pub struct Probe {
    /// Seconds spent per step, summed over every fit.
    timings: Mutex<Vec<(&'static str, f64)>>,
    /// Answers reused from an earlier round and answers given, over every fit: nearest
    /// model->observed, nearest observed->model, then rho_c's partner lists.
    reuse: Mutex<[usize; 6]>,
    /// Every round since the last [`Probe::take_rounds`], and how many fits (starts) began
    /// since then.
    rounds: Mutex<(Vec<RoundRecord>, usize)>,
}

impl Probe {
    /// The rounds of every fit since the last call, in order (restarts' rounds follow the
    /// first fit's, numbered by [`RoundRecord::start`]).
    pub fn take_rounds(&self) -> Vec<RoundRecord> {
        let mut r = self.rounds.lock().unwrap_or_else(|e| e.into_inner());
        r.1 = 0;
        std::mem::take(&mut r.0)
    }

    /// Marks the start of a fit (the rounds recorded next belong to it).
    pub(super) fn begin_fit(&self) {
        self.rounds.lock().unwrap_or_else(|e| e.into_inner()).1 += 1;
    }

    /// Records a round of the current fit.
    pub(super) fn record(
        &self,
        round: usize,
        kind: RoundKind,
        moved: f64,
        energy: f64,
        pose: &Pose,
    ) {
        let mut r = self.rounds.lock().unwrap_or_else(|e| e.into_inner());
        let start = r.1.saturating_sub(1);
        r.0.push(RoundRecord {
            start,
            round,
            kind,
            moved,
            energy,
            pose: pose.clone(),
        });
    }

    /// Seconds spent in each step so far, summed over every fit.
    pub fn timings(&self) -> Vec<(&'static str, f64)> {
        self.timings.lock().map(|t| t.clone()).unwrap_or_default()
    }

    /// The shares of answers reused from an earlier round over every fit so far: nearest
    /// neighbours model->observed and observed->model (`kept_nearest`), and rho_c's partner
    /// lists (`contact`).
    pub fn reused_shares(&self) -> [f64; 3] {
        let r = self.reuse.lock().map(|r| *r).unwrap_or_default();
        [0, 2, 4].map(|i| r[i] as f64 / r[i + 1].max(1) as f64)
    }

    /// Adds one round's nearest answers: reused and given model->observed, then
    /// observed->model.
    pub(super) fn add_nearest(&self, counts: [usize; 4]) {
        self.add_reuse(0, &counts);
    }

    /// Adds one round's rho_c partner lists: `kept` of `used`.
    pub(super) fn add_contact_lists(&self, kept: usize, used: usize) {
        self.add_reuse(4, &[kept, used]);
    }

    fn add_reuse(&self, from: usize, counts: &[usize]) {
        if let Ok(mut r) = self.reuse.lock() {
            for (total, n) in r[from..].iter_mut().zip(counts) {
                *total += n;
            }
        }
    }

    /// Runs `f`, adding its seconds to `step`'s time.
    pub(super) fn time<T>(&self, step: &'static str, f: impl FnOnce() -> T) -> T {
        let start = std::time::Instant::now();
        let out = f();
        self.add_time(step, start.elapsed().as_secs_f64());
        out
    }

    /// Adds `dt` seconds to `step`'s time.
    pub(super) fn add_time(&self, step: &'static str, dt: f64) {
        if let Ok(mut t) = self.timings.lock() {
            match t.iter_mut().find(|x| x.0 == step) {
                Some(x) => x.1 += dt,
                None => t.push((step, dt)),
            }
        }
    }
}
