//! A fit from one start: rounds of (a) pairs and weights ([`super::round`]) and (b) a
//! Levenberg-Marquardt step on the pose with those pairs held ([`super::solve`]), until
//! the pose settles (method.md "Stage 6").
//!
//! `proposed` takes Gauss-Newton rounds on per-pair planes; the baselines keep the
//! paper's point-to-point alternation, so that they compare as the paper compares them.

use super::anderson::Anderson;
use super::pairs::Prepared;
use super::probe::{Probe, RoundKind};
use super::round::Round;
use super::solve::{self, HeldProblem};
use super::tracking::joint_motion;
use super::{FitDiagnostics, FitResult, FitStatus, Fitter, Method};
use crate::skeleton::Pose;

/// `proposed`'s energy per round: this share of the point-to-point energy plus the rest of
/// the point-to-plane energy (each pair measured along its plane's normal). Small enough
/// that the model slides along the surface within one step, large enough to hold what the
/// planes leave free (a cylinder's axis); BENCHMARKS.md has the tries.
pub const POINT_SHARE: f64 = 0.03;

/// `proposed` stops when eq. 4 has not fallen a thousandth ([`PLATEAU_GAIN`]) below its
/// lowest value in this many rounds.
const PLATEAU_ROUNDS: usize = 5;
const PLATEAU_GAIN: f64 = 1e-3;

/// The baselines' LM steps per round, with the pairs held.
const BASELINE_LM_STEPS: usize = 3;

/// Rounds remembered by the Anderson acceleration of the baselines' rounds.
const ANDERSON_DEPTH: usize = 5;

/// Where a fit's rounds start: the pose, its round (pairs, weights) and the diagnostics so
/// far.
struct FitStart {
    pose: Pose,
    round: Round,
    diagnostics: FitDiagnostics,
}

impl Fitter<'_> {
    /// Fits from `start` in at most `cap` rounds.
    pub(super) fn fit_prepared(
        &self,
        prepared: &Prepared,
        start: &Pose,
        cap: usize,
        probe: &Probe,
    ) -> FitResult {
        probe.begin_fit();
        let from = FitStart {
            pose: start.clone(),
            round: self.round(prepared, start, probe),
            diagnostics: FitDiagnostics::unfitted(FitStatus::IterationCap, prepared.observed),
        };
        let (tolerance, _) = self.params.stopping(self.params.method);
        if self.params.method == Method::Proposed {
            self.fit_gauss_newton(prepared, from, tolerance, cap, probe)
        } else {
            self.fit_alternating(prepared, from, tolerance, cap, probe)
        }
    }

    /// The baselines' rounds (the paper's alternation): (a) pairs and weights, (b)
    /// [`BASELINE_LM_STEPS`] LM steps on the held point-to-point pairs, with Anderson
    /// acceleration of the rounds, until no joint moves more than `tolerance`.
    fn fit_alternating(
        &self,
        prepared: &Prepared,
        from: FitStart,
        tolerance: f64,
        cap: usize,
        probe: &Probe,
    ) -> FitResult {
        let FitStart {
            mut pose,
            mut round,
            mut diagnostics,
        } = from;
        let mut lambda = 1e-3;
        let mut accel = Anderson::new(ANDERSON_DEPTH);
        while diagnostics.iterations < cap {
            let (stepped, report) = probe.time("lm steps", || {
                let problem = self.held(&round);
                solve::levenberg_marquardt(&problem, &pose, BASELINE_LM_STEPS, &mut lambda)
            });
            diagnostics.iterations += 1;
            diagnostics.lm_steps += report.steps;
            // Point-to-point ICP converges slowly (linearly) where surfaces slide along each
            // other; Anderson acceleration extrapolates the sequence of rounds, and is kept
            // only when it lowers the energy (paper eq. 4) below the round it started from.
            let mut next = stepped.clone();
            let mut next_round = None;
            if let Some(extrapolated) = accel.next(&pose.to_vector(), &stepped.to_vector()) {
                let candidate = Pose::from_vector(&extrapolated);
                if candidate.is_finite() {
                    let r = self.round(prepared, &candidate, probe);
                    if r.energy() < round.energy() {
                        next = candidate;
                        next_round = Some(r);
                    } else {
                        accel.reset();
                    }
                }
            }
            let kind = if next_round.is_some() {
                RoundKind::Extrapolated
            } else {
                RoundKind::Step
            };
            let next_round = next_round.unwrap_or_else(|| self.round(prepared, &next, probe));
            let moved = joint_motion(self.model, &pose, &next);
            let n = diagnostics.iterations;
            probe.record(n, kind, moved, next_round.energy(), &next);
            pose = next;
            round = next_round;
            if moved < tolerance {
                diagnostics.status = FitStatus::Converged;
                break;
            }
        }
        // The energy and shares at the final pose, with its own pairs.
        finish(pose, &round, diagnostics)
    }

    /// `proposed`'s rounds: (a) pairs, weights and each pair's plane at the current pose,
    /// (b) one Levenberg-Marquardt step on the point-to-plane energy of those pairs
    /// ([`POINT_SHARE`], [`HeldProblem::with_planes`]): Gauss-Newton on a linearisation
    /// that lets the model slide along the observed surface, so a frame settles in about
    /// ten rounds where point-to-point rounds take hundreds. Stops when no joint moved
    /// more than `tolerance`, or when eq. 4 has not fallen below its lowest value by a
    /// thousandth for [`PLATEAU_ROUNDS`] rounds (the pairs and rho_c change with the pose,
    /// so the rounds may circle within a millimetre instead of converging); ends at the
    /// round with the lowest eq. 4.
    fn fit_gauss_newton(
        &self,
        prepared: &Prepared,
        from: FitStart,
        tolerance: f64,
        cap: usize,
        probe: &Probe,
    ) -> FitResult {
        let FitStart {
            mut pose,
            mut round,
            mut diagnostics,
        } = from;
        let mut lambda = 1e-3;
        let (mut best_pose, mut best_energy) = (pose.clone(), round.energy());
        let mut since_best = 0;
        while diagnostics.iterations < cap {
            let (stepped, report) = probe.time("lm steps", || {
                let problem = self.held(&round).with_planes(POINT_SHARE);
                solve::levenberg_marquardt(&problem, &pose, 1, &mut lambda)
            });
            diagnostics.iterations += 1;
            diagnostics.lm_steps += report.steps;
            let next_round = self.round(prepared, &stepped, probe);
            let moved = joint_motion(self.model, &pose, &stepped);
            let n = diagnostics.iterations;
            probe.record(n, RoundKind::Step, moved, next_round.energy(), &stepped);
            pose = stepped;
            round = next_round;
            let energy = round.energy();
            since_best += 1;
            if energy < best_energy * (1.0 - PLATEAU_GAIN) {
                since_best = 0;
            }
            if energy < best_energy {
                (best_pose, best_energy) = (pose.clone(), energy);
            }
            if moved < tolerance || since_best >= PLATEAU_ROUNDS {
                diagnostics.status = FitStatus::Converged;
                break;
            }
        }
        if best_pose != pose {
            round = self.round(prepared, &best_pose, probe);
            pose = best_pose;
        }
        finish(pose, &round, diagnostics)
    }

    /// Eq. 4 with `round`'s pairs held, over the thinned model.
    fn held<'b>(&'b self, round: &'b Round) -> HeldProblem<'b> {
        HeldProblem::new(
            &self.sample.skeleton,
            &self.sample.mesh.vertices,
            &self.sample.weights,
            &round.targets,
        )
    }
}

/// The fit's result at `pose`, whose pairs and weights `round` holds.
fn finish(pose: Pose, round: &Round, mut diagnostics: FitDiagnostics) -> FitResult {
    diagnostics.energy = round.energy();
    diagnostics.rms = (round.weighted_sq / round.weight_sum.max(1e-300)).sqrt();
    diagnostics.downweighted_share = round.downweighted as f64 / round.pairs.max(1) as f64;
    diagnostics.contact_share = round.contact_share;
    diagnostics.score = round.score();
    diagnostics.unexplained = round.unexplained.clone();
    FitResult { pose, diagnostics }
}
