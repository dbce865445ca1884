//! Tracking over frames (method.md "Stage 6"): each frame's fit starts from its tracked
//! neighbour's pose (nearer the reference frame t0), and a fit that looks lost is fitted
//! again from other starts. [`Tracker`] is the one path that `pipeline run` and
//! `pipeline bench track` both take.

use super::pairs::prepare;
use super::probe::Probe;
use super::recovery::SilhouetteScore;
use super::{FitDiagnostics, FitResult, FitStatus, Fitter, Observation, Start};
use crate::skeleton::model::BodyModel;
use crate::skeleton::{Pose, PosedBones, Skeleton};
use nalgebra::Vector3;
use std::collections::HashMap;

/// Fits the frames of a sequence in tracking order, keeping each fitted frame's pose and
/// diagnostics in memory for the frames that start from it.
pub struct Tracker<'a> {
    fitter: Fitter<'a>,
    /// The frames fitted (or read back) so far.
    done: HashMap<u32, (Pose, FitDiagnostics)>,
}

/// Where a tracked frame's fit starts: its tracked neighbour nearer t0 (`previous`), and
/// that frame's own neighbour (`before`, for the constant-velocity prediction).
#[derive(Debug, Clone, Copy)]
pub struct Neighbours {
    pub previous: u32,
    pub before: Option<u32>,
}

impl<'a> Tracker<'a> {
    pub fn new(fitter: Fitter<'a>) -> Tracker<'a> {
        Tracker {
            fitter,
            done: HashMap::new(),
        }
    }

    /// Whether `frame`'s result is known (fitted, or given by [`Tracker::know`]).
    pub fn knows(&self, frame: u32) -> bool {
        self.done.contains_key(&frame)
    }

    /// Takes `frame`'s result as fitted earlier (read back from the cache).
    pub fn know(&mut self, frame: u32, pose: Pose, diagnostics: FitDiagnostics) {
        self.done.insert(frame, (pose, diagnostics));
    }

    /// Fits `frame` from its `neighbours` (none: the reference frame t0, not fitted); a
    /// neighbour not known starts from the reference pose.
    ///
    /// The restart test ([`Fitter::lost`]) measures the fit's energy against the larger of
    /// the two neighbours' energies: a neighbour the model fits almost exactly (a pose near
    /// the reference pose, where the model was built) is a poor yardstick. On the
    /// humanoid, t8 and t16 (near the reference pose, eq. 4 a tenth of their neighbours')
    /// made the well-fitted t9 and t17 restart, for 60 rounds.
    pub fn fit(
        &mut self,
        frame: u32,
        obs: &Observation,
        neighbours: Option<Neighbours>,
        silhouettes: Option<&dyn SilhouetteScore>,
        probe: &Probe,
    ) -> FitResult {
        let result = match neighbours {
            None => self.fitter.reference(obs.vertices.len()),
            Some(n) => {
                let rest = Pose::rest(self.fitter.model.skeleton.bones.len());
                let (start, mut previous_fit) = match self.done.get(&n.previous) {
                    Some((pose, fit)) => (pose, Some(fit.clone())),
                    None => (&rest, None),
                };
                let before = n.before.and_then(|f| self.done.get(&f));
                if let (Some(fit), Some((_, before))) = (previous_fit.as_mut(), before) {
                    fit.energy = fit.energy.max(before.energy);
                }
                let before = before.map(|x| &x.0);
                self.fitter.fit_tracked(
                    obs,
                    start,
                    before,
                    previous_fit.as_ref(),
                    silhouettes,
                    probe,
                )
            }
        };

        self.done
            .insert(frame, (result.pose.clone(), result.diagnostics.clone()));
        result
    }
}

/// The share of the last step's motion (RMS over the thinned model vertices) below which
/// the motion prior's spread is never taken: a constant-velocity prediction can be off by
/// about that much when the motion turns.
const PRIOR_STEP_SHARE: f64 = 0.5;

/// The motion prior's weight for this frame: `weight` (from the frame rate,
/// [`super::params::motion_prior_weight`]) unless the motion itself shows the prediction
/// to be less sure. Its spread, PRIOR_NOISE / sqrt(weight), is at least
/// [`PRIOR_STEP_SHARE`] of the last step's RMS motion, so a frame rate set too high (a
/// weight too large by f^4) cannot pin a fast-moving body to its prediction.
fn prior_weight(weight: f64, last: &[Vector3<f64>], earlier: &[Vector3<f64>]) -> f64 {
    if weight <= 0.0 || last.is_empty() {
        return weight;
    }
    let step = (last
        .iter()
        .zip(earlier)
        .map(|(a, b)| (a - b).norm_squared())
        .sum::<f64>()
        / last.len() as f64)
        .sqrt();
    let spread = (super::params::PRIOR_NOISE / weight.sqrt()).max(PRIOR_STEP_SHARE * step);
    (super::params::PRIOR_NOISE / spread).powi(2)
}

impl Fitter<'_> {
    /// Fits a tracked frame from the start `params.start` chooses (`previous` is the
    /// neighbour's pose, nearer t0; `before` the pose one frame further back), and when that
    /// fit looks lost ([`Fitter::lost`]) also from the other of the two and from the
    /// reference pose at the previous root position; the lowest score
    /// ([`FitDiagnostics::score`]) wins. `iterations` counts the rounds of every start. A
    /// frame without enough observation keeps `previous`. `previous_fit` is the fit of the
    /// frame `previous` belongs to (none, or zero energy and score, when unknown).
    pub fn fit_tracked(
        &self,
        obs: &Observation,
        previous: &Pose,
        before: Option<&Pose>,
        previous_fit: Option<&FitDiagnostics>,
        silhouettes: Option<&dyn SilhouetteScore>,
        probe: &Probe,
    ) -> FitResult {
        let p = &self.params;
        let Some(mut prepared) = prepare(obs, p, self.model.mesh.vertices.len()) else {
            return self.unobserved(obs, previous);
        };
        let predicted = before.map(|before| predict(previous, before));
        if let (Some(before), true) = (before, self.motion_prior > 0.0) {
            // Each thinned model vertex where constant velocity takes it: 2 x(t-1) - x(t-2).
            let (last, earlier) = (self.posed_sample(previous).0, self.posed_sample(before).0);
            let targets = last
                .iter()
                .zip(&earlier)
                .map(|(a, b)| 2.0 * a - b)
                .collect();
            prepared.prior = Some((targets, prior_weight(self.motion_prior, &last, &earlier)));
        }
        let (first, second) = match (&predicted, p.start) {
            (Some(pred), Start::Predicted) => (pred.clone(), Some(previous.clone())),
            _ => (previous.clone(), predicted.clone()),
        };
        let (_, cap) = p.stopping(p.method);
        let mut best = self.fit_prepared(&prepared, &first, cap, probe);
        if !p.restart.enabled {
            return best;
        }
        if self.lost(&best, &first, previous, previous_fit) {
            let mut rest = Pose::rest(previous.rotations.len());
            rest.translation = previous.translation;
            // A start already tried would end where it did (the fit is deterministic): at
            // the frame after t0 the previous pose is the reference pose itself.
            let mut starts: Vec<Pose> = Vec::new();
            for start in second.into_iter().chain([rest]) {
                if start != first && !starts.contains(&start) {
                    starts.push(start);
                }
            }
            for start in &starts {
                let r = self.fit_prepared(&prepared, start, cap * p.restart.rounds_factor, probe);
                best = better(best, r);
            }
        }
        let best = self.unfolded(
            &prepared,
            best,
            previous,
            predicted.as_ref(),
            cap,
            silhouettes,
            probe,
        );
        self.recovered(&prepared, best, previous, cap, silhouettes, probe)
    }

    /// `best`, or its recovery ([`super::recovery`]) when it needs one.
    fn recovered(
        &self,
        prepared: &super::pairs::Prepared,
        best: FitResult,
        previous: &Pose,
        cap: usize,
        silhouettes: Option<&dyn SilhouetteScore>,
        probe: &Probe,
    ) -> FitResult {
        match self.needs_recovery(&best, previous) {
            Some(_) => self.recover(prepared, best, previous, cap, silhouettes, probe),
            None => best,
        }
    }

    /// A per-limb restart: when the best fit bent one joint by more than
    /// `restart.turn_deg` from both `previous` and the constant-velocity prediction
    /// `predicted` (a hand folded back into the chest that rho_c hides), that joint is put
    /// back as it was in `previous`, its children following, and fitted again from there;
    /// the lower score wins. On the humanoid the right hand folded
    /// back at t11-t14 as the forearms crossed the chest (2.41 cm); unfolded, 0.25 cm.
    /// When the two lie [`AMBIGUOUS_REACH`] or more apart and the evidence does not choose
    /// between them ([`ambiguity`]), the winner records how far the other lies
    /// ([`super::FitDiagnostics::ambiguous`]): the frame is flagged `ambiguous`.
    #[allow(clippy::too_many_arguments)]
    fn unfolded(
        &self,
        prepared: &super::pairs::Prepared,
        best: FitResult,
        previous: &Pose,
        predicted: Option<&Pose>,
        cap: usize,
        silhouettes: Option<&dyn SilhouetteScore>,
        probe: &Probe,
    ) -> FitResult {
        let skeleton = &self.model.skeleton;
        let Some((bone, turn)) = sharpest_joint_turn(skeleton, &best.pose, previous, predicted)
        else {
            return best;
        };
        if turn <= self.params.restart.turn_deg {
            return best;
        }
        let mut start = best.pose.clone();
        start.rotations[bone] = previous.rotations[bone];
        let r = self.fit_prepared(prepared, &start, cap, probe);
        let ambiguous = ambiguity(self.model, &best, &r, silhouettes);
        let mut chosen = better(best, r);
        chosen.diagnostics.ambiguous = ambiguous;
        chosen
    }

    /// Whether a tracked frame's fit from `start` looks lost, so that other starts are
    /// tried (`params.restart`):
    /// - its eq. 4 energy is above `restart_energy_ratio` times the previous frame's;
    /// - some bone turned more than `restart_turn_deg` from both `start` and `previous`,
    ///   and the score did not fall below the previous frame's (on the humanoid, the turns
    ///   with a falling score were fast motion: skipping their restarts saved 118 of 744
    ///   rounds and left the mean and worst joint errors as they were);
    /// - it hit the iteration cap and its score is above `restart_energy_ratio` times the
    ///   previous frame's (or that is unknown). A capped fit whose score stayed level is
    ///   sliding or circling near its answer: restarting the tripod's t11 from two farther
    ///   starts took 617 more rounds and kept the first fit. A capped fit whose score rose
    ///   has pressed parts into each other where rho_c hides them (the humanoid's t23: eq.
    ///   4 level with t22, the score 39 times t22's; the reference pose wins there).
    fn lost(
        &self,
        fit: &FitResult,
        start: &Pose,
        previous: &Pose,
        previous_fit: Option<&FitDiagnostics>,
    ) -> bool {
        let p = &self.params;
        let d = &fit.diagnostics;
        let rose = |now: f64, before: Option<f64>| {
            before.is_some_and(|b| b > 0.0 && now > p.restart.energy_ratio * b)
        };
        let score_known = previous_fit.is_some_and(|f| f.score > 0.0);
        // A fast turn that the observation explains better than the previous frame's fit
        // explained its own is motion, not a fold.
        let score_fell = previous_fit.is_some_and(|f| f.score > 0.0 && d.score <= f.score);
        rose(d.energy, previous_fit.map(|f| f.energy))
            || (!score_fell
                && largest_turn_deg(&self.model.skeleton, &fit.pose, start, previous)
                    > p.restart.turn_deg)
            || (d.status == FitStatus::IterationCap
                && (!score_known || rose(d.score, previous_fit.map(|f| f.score))))
    }

    /// The result for a frame with too little usable observation: `pose` kept, flagged.
    pub(super) fn unobserved(&self, obs: &Observation, pose: &Pose) -> FitResult {
        FitResult {
            pose: pose.clone(),
            diagnostics: FitDiagnostics::unfitted(FitStatus::NoObservation, obs.vertices.len()),
        }
    }
}

/// The last frame-to-frame motion applied once more (constant velocity):
/// L_pred = (L L_before⁻¹) L per bone, likewise the root translation.
fn predict(previous: &Pose, before: &Pose) -> Pose {
    Pose {
        translation: previous.translation * 2.0 - before.translation,
        rotations: previous
            .rotations
            .iter()
            .zip(&before.rotations)
            .map(|(l, lb)| (l * lb.inverse()) * l)
            .collect(),
    }
}

/// The largest displacement of any joint (head or tail) between two poses, metres.
pub fn joint_motion(model: &BodyModel, a: &Pose, b: &Pose) -> f64 {
    largest_distance(&joints_of(model, a), &joints_of(model, b))
}

/// Every joint (head, tail) of the model at `pose`, metres.
fn joints_of(model: &BodyModel, pose: &Pose) -> Vec<Vector3<f64>> {
    crate::skeleton::pose::joints(&model.skeleton, pose)
        .into_iter()
        .flat_map(|(head, tail)| [head, tail])
        .collect()
}

/// The largest distance between corresponding points, metres.
fn largest_distance(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).norm())
        .fold(0.0, f64::max)
}

/// The fit with the lower score ([`FitDiagnostics::score`]), with the rounds and steps of
/// both.
pub(super) fn better(a: FitResult, b: FitResult) -> FitResult {
    let take_b = b.diagnostics.score < a.diagnostics.score;
    pick(a, b, take_b)
}

/// `b` when `take_b`, else `a`, with the rounds and steps of both.
pub(super) fn pick(a: FitResult, b: FitResult, take_b: bool) -> FitResult {
    let (rounds, steps) = (
        a.diagnostics.iterations + b.diagnostics.iterations,
        a.diagnostics.lm_steps + b.diagnostics.lm_steps,
    );
    let mut best = if take_b { b } else { a };
    best.diagnostics.iterations = rounds;
    best.diagnostics.lm_steps = steps;
    best
}

/// Two fits of a frame this far apart (their largest joint motion, metres) that the
/// evidence does not choose between make the frame `ambiguous`: a hand's length. On the
/// humanoid in a dress (t15), the right hand held straight in front of the skirt (the
/// truth) and folded against the belly (15.8 cm off) end 13.7 cm apart.
const AMBIGUOUS_REACH: f64 = 0.1;

/// How far apart fits `a` and `b` of one frame lie (metres) when the evidence does not
/// choose between them: they lie [`AMBIGUOUS_REACH`] or more apart, eq. 4 (with rho_c) and
/// the score (without it) prefer different ones, and the silhouettes' worst IoUs lie
/// within [`super::recovery::SILHOUETTE_MARGIN`] of each other (or cannot be read). A
/// hand against the body is such a case: rho_c discounts the contact wherever it is, so
/// eq. 4 may prefer one fit while the score, which counts the contact in full, prefers the
/// other, and in every camera the hand lies inside the body's outline.
fn ambiguity(
    model: &BodyModel,
    a: &FitResult,
    b: &FitResult,
    silhouettes: Option<&dyn SilhouetteScore>,
) -> Option<f64> {
    let apart = joint_motion(model, &a.pose, &b.pose);
    let (da, db) = (&a.diagnostics, &b.diagnostics);
    if apart < AMBIGUOUS_REACH || (da.energy < db.energy) == (da.score < db.score) {
        return None;
    }
    let decided = silhouettes
        .and_then(|s| super::recovery::prefers_second(s, &a.pose, &b.pose))
        .is_some();
    (!decided).then_some(apart)
}

/// The bone whose direction in its parent's frame (its joint's bend; the twist about the
/// bone, which the surface hardly shows, left out) differs most between `pose` and the
/// nearer of `previous` and `predicted`, and by how much, degrees.
fn sharpest_joint_turn(
    skeleton: &Skeleton,
    pose: &Pose,
    previous: &Pose,
    predicted: Option<&Pose>,
) -> Option<(usize, f64)> {
    let bend = |b: usize, other: &Pose| {
        let d = skeleton.bones[b].tail - skeleton.bones[b].head;
        (pose.rotations[b] * d).angle(&(other.rotations[b] * d))
    };
    (0..skeleton.bones.len())
        .map(|b| {
            let from_previous = bend(b, previous);
            predicted
                .map_or(from_previous, |q| from_previous.min(bend(b, q)))
                .to_degrees()
        })
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// The largest angle, degrees, by which a bone's head-to-tail direction in `pose` differs
/// from its direction in whichever of `a` and `b` is nearer to it.
fn largest_turn_deg(skeleton: &Skeleton, pose: &Pose, a: &Pose, b: &Pose) -> f64 {
    let [fit, a, b] = [pose, a, b].map(|q| PosedBones::new(skeleton, q));
    let direction = |bones: &PosedBones, i: usize| bones.tails[i] - bones.heads[i];
    (0..skeleton.bones.len())
        .map(|i| {
            let d = direction(&fit, i);
            d.angle(&direction(&a, i)).min(d.angle(&direction(&b, i)))
        })
        .fold(0.0, f64::max)
        .to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::skinning::tests::chain;
    use nalgebra::Rotation3;

    /// A bone folded back is measured from the nearer of the two reference poses; turning a
    /// parent turns its child's direction too, and a root translation turns nothing.
    #[test]
    fn largest_turn_is_measured_from_the_nearer_pose() {
        let skeleton = chain();
        let rest = Pose::rest(skeleton.bones.len());
        let mut folded = rest.clone();
        // Bone "b" (index 2) turned 150 degrees about the vertical axis.
        folded.rotations[2] = Rotation3::new(Vector3::z() * 150f64.to_radians());
        let mut moved = rest.clone();
        moved.translation = Vector3::new(0.3, -0.2, 0.1);
        let turn = |p: &Pose, a: &Pose, b: &Pose| largest_turn_deg(&skeleton, p, a, b);
        assert!((turn(&folded, &rest, &moved) - 150.0).abs() < 1e-6);
        assert!(turn(&folded, &rest, &folded).abs() < 1e-6);
        assert!(turn(&moved, &rest, &rest).abs() < 1e-6);
        let mut arm = rest.clone();
        arm.rotations[1] = Rotation3::new(Vector3::y() * 70f64.to_radians());
        assert!((turn(&arm, &rest, &rest) - 70.0).abs() < 1e-6);
    }
}
