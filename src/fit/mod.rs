//! Robust articulated fitting (method.md "Stage 6"): the pose of the skin-bone model that
//! best explains one frame's observed surface, starting from the previous frame's pose.
//!
//! Per frame, alternate (a) posing the model and finding, both ways, each vertex's nearest
//! neighbour on the other surface and the pair's weight; (b) Levenberg-Marquardt steps on the
//! 3N+3 pose increments with the pairs held ([`solve`]); until the joints move less than
//! `tolerance` in one round or `max_iterations` rounds.
//!
//! Paper eq. 4, with each pair weighted by its own two ends (model vertex v, observed u):
//! `E(p) = sum_pairs rho_c(v)/R_c * rho_p(u)/R_p * |v - u|^2`. The five methods are this one
//! energy with different weights ([`Method`]).

mod anderson;
pub mod contact;
pub mod kept_nearest;
mod moments;
pub mod solve;

use crate::geometry::cell_grid::CellGrid;
use crate::geometry::nearest::{key, NearestTree};
use crate::geometry::TriMesh;
use crate::skeleton::model::BodyModel;
use crate::skeleton::skinning::pose_vertices;
use crate::skeleton::{Pose, PosedBones, Skeleton};
use contact::{ContactParams, ContactSearch};
use kept_nearest::{MovingPoints, MovingQueries};
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use solve::{HeldProblem, Targets};

/// The cell edge of the grids that answer the short nearest searches between rounds
/// ([`kept_nearest`]), in units of the surface's spacing (`sample_spacing` for the
/// observed surface, `model_spacing` for the model): a search within a spacing or two
/// visits a few cells of a few points each (tripod, 1 cm: 2 cm cells 1.15x faster than
/// 1 cm ones).
const SEARCH_CELLS_PER_SPACING: f64 = 2.0;

/// The grids' cell edge for a surface thinned to `spacing` metres (0: not thinned, taken as
/// the paper's 1 cm), metres.
fn search_cell(spacing: f64) -> f64 {
    SEARCH_CELLS_PER_SPACING * if spacing > 0.0 { spacing } else { 0.01 }
}

/// Which weights the energy uses: the paper's method and the baselines it compares with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Every pair weighs 1 (articulated ICP).
    Icp,
    /// Ogawara et al.: pairs whose normals differ by more than `normal_angle_deg` weigh 0,
    /// the others 1.
    Normals,
    /// rho_c(v) only.
    RhoC,
    /// rho_p(u) only.
    RhoP,
    /// rho_c(v) rho_p(u) (paper eq. 4).
    Proposed,
}

impl Method {
    pub const ALL: [Method; 5] = [
        Method::Icp,
        Method::Normals,
        Method::RhoC,
        Method::RhoP,
        Method::Proposed,
    ];

    /// The name used in pipeline.yaml and in outputs.
    pub fn name(self) -> &'static str {
        match self {
            Method::Icp => "icp",
            Method::Normals => "normals",
            Method::RhoC => "rho_c",
            Method::RhoP => "rho_p",
            Method::Proposed => "proposed",
        }
    }

    fn uses_rho_c(self) -> bool {
        matches!(self, Method::RhoC | Method::Proposed)
    }

    fn uses_rho_p(self) -> bool {
        matches!(self, Method::RhoP | Method::Proposed)
    }
}

/// Where a tracked frame's fit starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Start {
    /// The previous frame's pose (method.md's literal rule).
    Previous,
    /// The previous pose moved on by the last frame-to-frame motion (constant velocity:
    /// L_pred = (L_prev L_before⁻¹) L_prev per bone, likewise the root translation); the
    /// previous pose itself at the first tracked frame. It overshoots where the motion
    /// turns or stops (the bundled sample's frames 3-4: 8 and 11 cm off from it, 0.3 cm
    /// from the previous pose); `proposed` tries it as a second start anyway.
    Predicted,
}

/// `proposed`'s energy per round: this share of the point-to-point energy plus the rest of
/// the point-to-plane energy (each pair measured along its plane's normal). Small enough
/// that the model slides along the surface within one step, large enough to hold what the
/// planes leave free (a cylinder's axis); BENCHMARKS.md has the tries.
pub const POINT_SHARE: f64 = 0.03;

/// A model vertex's pair takes its observed partner's tangent plane when their normals'
/// dot product is above this (45 degrees), its own otherwise (BENCHMARKS.md).
const PLANE_AGREEMENT: f64 = 0.7;

/// `proposed` stops when eq. 4 has not fallen a thousandth ([`PLATEAU_GAIN`]) below its
/// lowest value in this many rounds.
const PLATEAU_ROUNDS: usize = 5;
const PLATEAU_GAIN: f64 = 1e-3;

/// The baselines' LM steps per round, with the pairs held.
const BASELINE_LM_STEPS: usize = 3;

/// Rounds remembered by the Anderson acceleration of the baselines' rounds.
const ANDERSON_DEPTH: usize = 5;

/// The name of a part of the `rho_c` step in [`Fitter::timings`]: [`STEP_PART_PREFIX`]
/// followed by `$part` (one literal, so the two cannot drift apart).
macro_rules! rho_c_part {
    ($part:literal) => {
        concat!("rho_c: ", $part)
    };
}

/// The names of a step's parts in [`Fitter::timings`] begin with this, so that a report can
/// tell them from whole steps (whose sum already holds them).
pub const STEP_PART_PREFIX: &str = rho_c_part!("");

/// The parts of the `rho_c` step in [`Fitter::timings`] ([`contact::ContactTimes`]).
const RHO_C_STALENESS: &str = rho_c_part!("stale lists found");
const RHO_C_REBUILDING: &str = rho_c_part!("lists rebuilt");
const RHO_C_SCANNING: &str = rho_c_part!("lists scanned");

/// How far the `nearest_compatible` search looks for a vertex whose normal agrees, metres.
pub const COMPATIBLE_SEARCH_LIMIT: f64 = 0.2;

/// Parameters of the fit stage (pipeline.yaml key `fit`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FitParams {
    /// `icp`, `normals`, `rho_c`, `rho_p` or `proposed` (default).
    pub method: Method,
    /// Where a tracked frame starts: `previous` (default) or `predicted` ([`Start`]).
    /// `proposed` also fits from the other one and keeps the lower score.
    pub start: Start,
    /// rho_c and the contact partners ([`ContactParams`]).
    pub contact: ContactParams,
    /// For `normals`: pairs whose normals differ by more than this are rejected, degrees.
    /// Default 45.
    pub normal_angle_deg: f64,
    /// Spacing of the observed vertices the energy runs over, metres: each frame's surface
    /// is thinned to one vertex per cube of this size (the vertex nearest the cube's
    /// centre), about the paper's 1 cm triangles. 0 keeps every vertex. Default 0.01.
    pub sample_spacing: f64,
    /// The same for the model's vertices, metres. Default 0.01 (the paper's setting).
    pub model_spacing: f64,
    /// When a frame's rounds stop ([`StopParams`]).
    pub stop: StopParams,
    /// Frames whose observed surface has fewer vertices than this share of the model's keep
    /// the previous pose (and are flagged). Default 0.05.
    pub min_observed_share: f64,
    /// Fits again from other starts when a fit looks lost ([`RestartParams`]).
    pub restart: RestartParams,
}

/// When a frame's rounds stop (pipeline.yaml key `fit.stop`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StopParams {
    /// `proposed` (Gauss-Newton rounds): converged when no joint moved more than this in a
    /// round, metres. Default 0.0001.
    pub tolerance: f64,
    /// `proposed`: rounds per start at most. Default 60.
    pub max_rounds: usize,
    /// The baselines (point-to-point rounds, which converge linearly): the same tolerance,
    /// metres. Default 0.00001.
    pub baseline_tolerance: f64,
    /// The baselines: rounds per start at most. Default 120.
    pub baseline_max_rounds: usize,
}

impl Default for StopParams {
    fn default() -> Self {
        StopParams {
            tolerance: 0.0001,
            max_rounds: 60,
            baseline_tolerance: 0.00001,
            baseline_max_rounds: 120,
        }
    }
}

/// Restarts of a fit that looks lost (pipeline.yaml key `fit.restart`; [`Fitter::lost`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RestartParams {
    /// Whether a lost fit is fitted again from the other start and from the reference pose
    /// at the previous root position, keeping the lowest score. Default true.
    pub enabled: bool,
    /// A fit is lost when its energy rose above this times the previous frame's (or hit
    /// the round cap with its score so risen). Default 3.
    pub energy_ratio: f64,
    /// A fit is also lost when a bone's head-to-tail direction ends more than this many
    /// degrees from its direction both in the start pose and in the previous frame's pose
    /// (a limb folded back onto itself). Default 45.
    pub turn_deg: f64,
    /// Rounds per restart at most, as a multiple of the method's round cap. Default 2.
    pub rounds_factor: usize,
}

impl Default for RestartParams {
    fn default() -> Self {
        RestartParams {
            enabled: true,
            energy_ratio: 3.0,
            turn_deg: 45.0,
            rounds_factor: 2,
        }
    }
}

impl Default for FitParams {
    fn default() -> Self {
        FitParams {
            method: Method::Proposed,
            start: Start::Previous,
            contact: ContactParams::default(),
            normal_angle_deg: 45.0,
            sample_spacing: 0.01,
            model_spacing: 0.01,
            stop: StopParams::default(),
            min_observed_share: 0.05,
            restart: RestartParams::default(),
        }
    }
}

impl FitParams {
    /// The tolerance (metres) and round cap of `method`'s rounds.
    pub fn stopping(&self, method: Method) -> (f64, usize) {
        if method == Method::Proposed {
            (self.stop.tolerance, self.stop.max_rounds)
        } else {
            (self.stop.baseline_tolerance, self.stop.baseline_max_rounds)
        }
    }
}

/// Checks parameters that do not depend on the data.
pub fn validate(p: &FitParams) -> std::result::Result<(), String> {
    let positive = |v: f64| v > 0.0 && v.is_finite();
    let c = &p.contact;
    if !positive(c.alpha_c) || !positive(c.tau_c) || !positive(c.rest_distance) {
        return Err(
            "fit.contact: alpha_c, tau_c and rest_distance must be positive numbers".into(),
        );
    }
    if !(p.normal_angle_deg > 0.0 && p.normal_angle_deg <= 180.0) {
        return Err(format!(
            "fit.normal_angle_deg must be in (0, 180] degrees, got {}",
            p.normal_angle_deg
        ));
    }
    let s = &p.stop;
    if s.max_rounds == 0 || s.baseline_max_rounds == 0 || p.restart.rounds_factor == 0 {
        return Err(
            "fit: stop.max_rounds, stop.baseline_max_rounds and restart.rounds_factor must be at least 1"
                .into(),
        );
    }
    for (key, spacing) in [
        ("sample_spacing", p.sample_spacing),
        ("model_spacing", p.model_spacing),
    ] {
        if !(spacing >= 0.0 && spacing.is_finite()) {
            return Err(format!(
                "fit.{key} must be 0 (every vertex) or a spacing in metres, got {spacing}"
            ));
        }
    }
    for (key, tolerance) in [
        ("tolerance", s.tolerance),
        ("baseline_tolerance", s.baseline_tolerance),
    ] {
        if !positive(tolerance) {
            return Err(format!(
                "fit.stop.{key} must be a positive distance in metres, got {tolerance}"
            ));
        }
    }
    let r = &p.restart;
    if !(r.energy_ratio.is_finite() && r.energy_ratio >= 1.0) {
        return Err(format!(
            "fit.restart.energy_ratio must be a number >= 1, got {}",
            r.energy_ratio
        ));
    }
    if !(r.turn_deg > 0.0 && r.turn_deg <= 180.0) {
        return Err(format!(
            "fit.restart.turn_deg must be in (0, 180] degrees, got {}",
            r.turn_deg
        ));
    }
    if !(0.0..1.0).contains(&p.min_observed_share) {
        return Err(format!(
            "fit.min_observed_share must be in [0, 1), got {}",
            p.min_observed_share
        ));
    }
    Ok(())
}

/// One frame's observed surface (from the reliability stage).
#[derive(Debug, Clone, Default)]
pub struct Observation {
    /// Vertices, world metres.
    pub vertices: Vec<Vector3<f64>>,
    /// Unit outward normals.
    pub normals: Vec<Vector3<f64>>,
    /// rho_p per vertex, (0, 1).
    pub rho_p: Vec<f64>,
}

/// How a frame's fit ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitStatus {
    /// The reference frame: the embedded skeleton's pose, not fitted.
    Reference,
    /// Converged within the tolerance.
    Converged,
    /// Stopped at `max_iterations`.
    IterationCap,
    /// Too little observed surface: the previous pose was kept.
    NoObservation,
}

impl FitStatus {
    pub fn name(self) -> &'static str {
        match self {
            FitStatus::Reference => "reference",
            FitStatus::Converged => "converged",
            FitStatus::IterationCap => "iteration_cap",
            FitStatus::NoObservation => "no_observation",
        }
    }

    pub fn parse(s: &str) -> Option<FitStatus> {
        [
            FitStatus::Reference,
            FitStatus::Converged,
            FitStatus::IterationCap,
            FitStatus::NoObservation,
        ]
        .into_iter()
        .find(|f| f.name() == s)
    }
}

/// Per-frame fit diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct FitDiagnostics {
    pub status: FitStatus,
    /// Correspondence rounds.
    pub iterations: usize,
    /// Accepted LM steps over all rounds.
    pub lm_steps: usize,
    /// Paper eq. 4 at the final pose with the final pairs (weights normalized by R_c R_p,
    /// m^2).
    pub energy: f64,
    /// Weighted root-mean-square pair distance at the end, metres.
    pub rms: f64,
    /// Share of pairs (both directions) weighing less than 0.5.
    pub downweighted_share: f64,
    /// Share of model vertices with rho_c < 0.5 (0 for methods without rho_c).
    pub contact_share: f64,
    /// The fit's score at the final pose, m^2: the method's energy without rho_c
    /// ([`Round::score`]; equal to `energy` for methods without rho_c).
    pub score: f64,
    /// Observed vertices.
    pub observed: usize,
}

impl FitDiagnostics {
    /// A frame not (yet) fitted: no rounds, zero energy.
    pub fn unfitted(status: FitStatus, observed: usize) -> FitDiagnostics {
        FitDiagnostics {
            status,
            iterations: 0,
            lm_steps: 0,
            energy: 0.0,
            rms: 0.0,
            downweighted_share: 0.0,
            contact_share: 0.0,
            score: 0.0,
            observed,
        }
    }
}

/// A fitted frame.
#[derive(Debug, Clone)]
pub struct FitResult {
    pub pose: Pose,
    pub diagnostics: FitDiagnostics,
}

/// Fits frames of one sequence with one model and one set of parameters.
pub struct Fitter<'a> {
    pub model: &'a BodyModel,
    pub params: FitParams,
    /// The model's vertices the energy runs over (about one per `model_spacing`), with
    /// their reference normals; no triangles.
    sample: BodyModel,
    sample_normals: Vec<Vector3<f64>>,
    contact: ContactSearch,
    /// Seconds spent per step, summed over every fit (for benchmarks).
    timings: std::sync::Mutex<Vec<(&'static str, f64)>>,
    /// Nearest answers reused from an earlier round and answers given, both ways, over
    /// every fit (for benchmarks).
    nearest_reuse: std::sync::Mutex<[usize; 4]>,
    /// Every round since the last [`Fitter::take_rounds`], and how many fits (starts) began
    /// since then.
    rounds: std::sync::Mutex<(Vec<RoundRecord>, usize)>,
}

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

/// A frame's observation prepared for the rounds ([`Fitter::prepare`]).
struct Prepared {
    /// Finite observed vertices thinned to `sample_spacing`.
    obs: Observation,
    tree: NearestTree,
    /// The same points in cells ([`search_cell`]), for the short searches.
    grid: CellGrid,
    /// Nearest answers kept between this frame's rounds, both ways (every start's rounds
    /// may share them: they hold for any pose).
    kept: std::sync::Mutex<(MovingQueries, MovingPoints)>,
    /// Observed vertices before thinning (for the diagnostics).
    observed: usize,
}

/// Everything one round's pairs give: the held targets and the energy's bookkeeping.
struct Round {
    targets: Targets,
    /// Sum of w |v - u|^2 over pairs (m^2) and of w.
    weighted_sq: f64,
    weight_sum: f64,
    pairs: usize,
    downweighted: usize,
    /// R_c R_p.
    normalizer: f64,
    contact_share: f64,
    /// `weighted_sq` and `normalizer` with rho_c taken as 1 (see [`Round::score`]).
    scored_sq: f64,
    score_normalizer: f64,
}

impl Round {
    /// Paper eq. 4 with these pairs and weights.
    fn energy(&self) -> f64 {
        self.weighted_sq / self.normalizer
    }

    /// The round's score, comparable between starts and frames, m^2: the method's own
    /// energy with these pairs but without rho_c. The observed surface's weights do not
    /// depend on the pose, so a fit cannot lower the score by pressing parts together, as it
    /// can lower eq. 4 through rho_c (on the humanoid, choosing starts by eq. 4 picked a
    /// pose 5 cm off at t23). A baseline is scored with its own weights only, never with
    /// rho_p it does not use. (The `proposed` and `rho_p` methods pair alike, so this is
    /// the `rho_p` method's energy at the same pose.)
    fn score(&self) -> f64 {
        self.scored_sq / self.score_normalizer
    }
}

impl<'a> Fitter<'a> {
    pub fn new(model: &'a BodyModel, params: FitParams) -> Fitter<'a> {
        let normals = model.mesh.vertex_normals();
        let keep = thin(&model.mesh.vertices, params.model_spacing);
        let sample = BodyModel {
            skeleton: model.skeleton.clone(),
            mesh: TriMesh {
                vertices: keep.iter().map(|&i| model.mesh.vertices[i]).collect(),
                triangles: Vec::new(),
            },
            weights: keep.iter().map(|&i| model.weights[i].clone()).collect(),
            labels: keep.iter().map(|&i| model.labels[i]).collect(),
        };
        let sample_normals = keep.iter().map(|&i| normals[i]).collect();
        let contact = ContactSearch::new(&sample, params.contact);
        Fitter {
            model,
            params,
            sample,
            sample_normals,
            contact,
            timings: Default::default(),
            nearest_reuse: Default::default(),
            rounds: Default::default(),
        }
    }

    /// The rounds of every fit since the last call, in order (restarts' rounds follow the
    /// first fit's, numbered by [`RoundRecord::start`]).
    pub fn take_rounds(&self) -> Vec<RoundRecord> {
        let mut r = self.rounds.lock().unwrap_or_else(|e| e.into_inner());
        r.1 = 0;
        std::mem::take(&mut r.0)
    }

    /// Records a round of the current fit.
    fn record(&self, round: usize, kind: RoundKind, moved: f64, energy: f64, pose: &Pose) {
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

    /// The shares of nearest-neighbour answers reused from an earlier round
    /// ([`kept_nearest`]), model->observed and observed->model, over every fit so far.
    pub fn nearest_reused_share(&self) -> [f64; 2] {
        let r = self.nearest_reuse.lock().map(|r| *r).unwrap_or_default();
        [
            r[0] as f64 / r[1].max(1) as f64,
            r[2] as f64 / r[3].max(1) as f64,
        ]
    }

    fn time<T>(&self, step: &'static str, f: impl FnOnce() -> T) -> T {
        let start = std::time::Instant::now();
        let out = f();
        self.add_time(step, start.elapsed().as_secs_f64());
        out
    }

    /// Adds `dt` seconds to `step`'s time.
    fn add_time(&self, step: &'static str, dt: f64) {
        if let Ok(mut t) = self.timings.lock() {
            match t.iter_mut().find(|x| x.0 == step) {
                Some(x) => x.1 += dt,
                None => t.push((step, dt)),
            }
        }
    }

    /// The diagnostics of the reference frame (pose p_t0 = the embedded skeleton).
    pub fn reference(&self, observed: usize) -> FitResult {
        FitResult {
            pose: Pose::rest(self.model.skeleton.bones.len()),
            diagnostics: FitDiagnostics::unfitted(FitStatus::Reference, observed),
        }
    }

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
    ) -> FitResult {
        let p = &self.params;
        let Some(prepared) = self.prepare(obs) else {
            return self.unobserved(obs, previous);
        };
        // Apply the last frame-to-frame motion once more: L_pred = (L L_before⁻¹) L.
        let predicted = before.map(|before| Pose {
            translation: previous.translation * 2.0 - before.translation,
            rotations: previous
                .rotations
                .iter()
                .zip(&before.rotations)
                .map(|(l, lb)| (l * lb.inverse()) * l)
                .collect(),
        });
        let (first, second) = match (&predicted, p.start) {
            (Some(pred), Start::Predicted) => (pred.clone(), Some(previous.clone())),
            _ => (previous.clone(), predicted.clone()),
        };
        let (_, cap) = p.stopping(p.method);
        let mut best = self.fit_prepared(&prepared, &first, cap);
        if !p.restart.enabled || !self.lost(&best, &first, previous, previous_fit) {
            return best;
        }
        let mut rest = Pose::rest(previous.rotations.len());
        rest.translation = previous.translation;
        // A start already tried would end where it did (the fit is deterministic): at the
        // frame after t0 the previous pose is the reference pose itself.
        let mut starts: Vec<Pose> = Vec::new();
        for start in second.into_iter().chain([rest]) {
            if start != first && !starts.contains(&start) {
                starts.push(start);
            }
        }
        for start in &starts {
            let r = self.fit_prepared(&prepared, start, cap * p.restart.rounds_factor);
            best = better(best, r);
        }
        best
    }

    /// Whether a tracked frame's fit from `start` looks lost, so that other starts are
    /// tried (`params.restart`):
    /// - its eq. 4 energy is above `restart_energy_ratio` times the previous frame's;
    /// - some bone turned more than `restart_turn_deg` from both `start` and `previous`;
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
        rose(d.energy, previous_fit.map(|f| f.energy))
            || largest_turn_deg(&self.model.skeleton, &fit.pose, start, previous)
                > p.restart.turn_deg
            || (d.status == FitStatus::IterationCap
                && (!score_known || rose(d.score, previous_fit.map(|f| f.score))))
    }

    /// The result for a frame with too little usable observation: `pose` kept, flagged.
    fn unobserved(&self, obs: &Observation, pose: &Pose) -> FitResult {
        FitResult {
            pose: pose.clone(),
            diagnostics: FitDiagnostics::unfitted(FitStatus::NoObservation, obs.vertices.len()),
        }
    }

    /// The frame's observation as the rounds use it: finite vertices only, thinned to
    /// `sample_spacing`, with its k-d tree; `None` when too little of it is left.
    fn prepare(&self, obs: &Observation) -> Option<Prepared> {
        let p = &self.params;
        let model_vertices = self.model.mesh.vertices.len();
        if obs.vertices.is_empty()
            || (obs.vertices.len() as f64) < p.min_observed_share * model_vertices as f64
        {
            return None;
        }
        // Non-finite observations (a damaged cache, a hostile file) are dropped, never
        // fitted: NaN must not reach a pose.
        let finite: Vec<usize> = (0..obs.vertices.len())
            .filter(|&i| {
                obs.vertices[i]
                    .iter()
                    .chain(obs.normals[i].iter())
                    .all(|v| v.is_finite())
                    && obs.rho_p[i].is_finite()
            })
            .collect();
        let points: Vec<Vector3<f64>> = finite.iter().map(|&i| obs.vertices[i]).collect();
        let keep: Vec<usize> = thin(&points, p.sample_spacing)
            .into_iter()
            .map(|k| finite[k])
            .collect();
        if keep.is_empty() {
            return None;
        }
        let input_count = obs.vertices.len();
        let obs = Observation {
            vertices: keep.iter().map(|&i| obs.vertices[i]).collect(),
            normals: keep.iter().map(|&i| obs.normals[i]).collect(),
            rho_p: keep.iter().map(|&i| obs.rho_p[i]).collect(),
        };
        let tree = NearestTree::new(&obs.vertices);
        let grid = CellGrid::new(tree.keys(), search_cell(p.sample_spacing));
        Some(Prepared {
            grid,
            observed: input_count,
            obs,
            tree,
            kept: Default::default(),
        })
    }

    /// Fits one frame's `obs` starting from `start`; a frame without enough observation
    /// keeps `start`.
    pub fn fit(&self, obs: &Observation, start: &Pose) -> FitResult {
        match self.prepare(obs) {
            Some(prepared) => {
                self.fit_prepared(&prepared, start, self.params.stopping(self.params.method).1)
            }
            None => self.unobserved(obs, start),
        }
    }

    /// Fits from `start` in at most `cap` rounds.
    fn fit_prepared(&self, prepared: &Prepared, start: &Pose, cap: usize) -> FitResult {
        self.rounds.lock().unwrap_or_else(|e| e.into_inner()).1 += 1;
        let round = self.round(self.params.method, prepared, start);
        let diagnostics = FitDiagnostics::unfitted(FitStatus::IterationCap, prepared.observed);
        let pose = start.clone();
        let (tolerance, _) = self.params.stopping(self.params.method);
        if self.params.method == Method::Proposed {
            self.fit_gauss_newton(prepared, (pose, round, diagnostics), tolerance, cap)
        } else {
            self.fit_alternating(prepared, (pose, round, diagnostics), tolerance, cap)
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
    ) -> FitResult {
        let (mut pose, mut round, mut diagnostics) = from;
        let method = self.params.method;
        let mut lambda = 1e-3;
        let mut accel = anderson::Anderson::new(ANDERSON_DEPTH);
        while diagnostics.iterations < cap {
            let (stepped, report) = self.time("lm steps", || {
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
                    let r = self.round(method, prepared, &candidate);
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
            let next_round = next_round.unwrap_or_else(|| self.round(method, prepared, &next));
            let moved = joint_motion(self.model, &pose, &next);
            let n = diagnostics.iterations;
            self.record(n, kind, moved, next_round.energy(), &next);
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
    /// ([`POINT_SHARE`], [`solve::HeldProblem::with_planes`]): Gauss-Newton on a
    /// linearisation that lets the model slide along the observed surface, so a frame
    /// settles in about ten rounds where point-to-point rounds take hundreds. Stops when no
    /// joint moved more than `tolerance`, or when eq. 4 has not fallen below its lowest
    /// value by a thousandth for [`PLATEAU_ROUNDS`] rounds (the pairs and rho_c change
    /// with the pose, so the rounds may circle within a millimetre instead of converging);
    /// ends at the round with the lowest eq. 4.
    fn fit_gauss_newton(
        &self,
        prepared: &Prepared,
        from: FitStart,
        tolerance: f64,
        cap: usize,
    ) -> FitResult {
        let (mut pose, mut round, mut diagnostics) = from;
        let method = self.params.method;
        let mut lambda = 1e-3;
        let (mut best_pose, mut best_energy) = (pose.clone(), round.energy());
        let mut since_best = 0;
        while diagnostics.iterations < cap {
            let (stepped, report) = self.time("lm steps", || {
                let problem = self.held(&round).with_planes(POINT_SHARE);
                solve::levenberg_marquardt(&problem, &pose, 1, &mut lambda)
            });
            diagnostics.iterations += 1;
            diagnostics.lm_steps += report.steps;
            let next_round = self.round(method, prepared, &stepped);
            let moved = joint_motion(self.model, &pose, &stepped);
            let n = diagnostics.iterations;
            self.record(n, RoundKind::Step, moved, next_round.energy(), &stepped);
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
            round = self.round(method, prepared, &best_pose);
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

    /// Step (a): pose the model, its normals and rho_c, pairs both ways and their weights.
    fn round(&self, method: Method, prepared: &Prepared, pose: &Pose) -> Round {
        let p = &self.params;
        let (obs, obs_tree) = (&prepared.obs, &prepared.tree);
        let m = &self.sample;
        let (posed, normals) = self.time("pose, normals", || {
            let bones = PosedBones::new(&m.skeleton, pose);
            let posed = pose_vertices(&bones, &m.mesh.vertices, &m.weights);
            // A normal turns with its vertex's dominant bone.
            let normals: Vec<Vector3<f64>> = self
                .sample_normals
                .iter()
                .zip(&m.labels)
                .map(|(n, &l)| bones.rotations[l] * n)
                .collect();
            (posed, normals)
        });
        let find_rho_c = || {
            if method.uses_rho_c() {
                let (weights, parts) =
                    self.time("rho_c", || self.contact.weights(&posed, &normals));
                self.add_time(RHO_C_STALENESS, parts.staleness);
                self.add_time(RHO_C_REBUILDING, parts.rebuilding);
                self.add_time(RHO_C_SCANNING, parts.scanning);
                weights
            } else {
                vec![1.0; posed.len()]
            }
        };
        let cos_limit = p.normal_angle_deg.to_radians().cos();
        // `normals` (Ogawara et al.'s correspondence search, as the paper's Fig. 12 describes
        // it): the nearest vertex whose normal agrees, searched up to
        // [`COMPATIBLE_SEARCH_LIMIT`]; a model vertex may so pair with a phantom surface or,
        // where the touching surfaces are missing, with the far side of the other part.
        let compatible = method == Method::Normals;
        let agree = |v: usize, u: usize| normals[v].dot(&obs.normals[u]) >= cos_limit;
        // With `compatible`, each query point's nearest partner in `tree` whose normal agrees
        // (`agrees(query, partner)`); (0, inf) for none.
        let partners = |queries: &[Vector3<f64>],
                        tree: &NearestTree,
                        agrees: &(dyn Fn(usize, usize) -> bool + Sync)|
         -> Vec<(usize, f64)> {
            queries
                .par_iter()
                .enumerate()
                .map(|(i, q)| {
                    tree.nearest_where(q, COMPATIBLE_SEARCH_LIMIT, |j| agrees(i, j))
                        .map_or((0, f64::INFINITY), |x| x)
                })
                .collect()
        };
        let find_pairs = || {
            if compatible {
                // Model -> observed: each model vertex's nearest observed vertex whose normal
                // agrees; the model's tree for the way back is built meanwhile.
                let (forward, model_tree) = rayon::join(
                    || {
                        self.time("nearest model->observed", || {
                            partners(&posed, obs_tree, &|v, u| agree(v, u))
                        })
                    },
                    || self.time("model tree", || NearestTree::new(&posed)),
                );
                // Observed -> model.
                let backward = self.time("nearest observed->model", || {
                    partners(&obs.vertices, &model_tree, &|u, v| agree(v, u))
                });
                (forward, backward)
            } else {
                // The nearest partners both ways, reusing the earlier rounds' answers that still
                // hold ([`kept_nearest`]; the same answers as fresh searches).
                let keys: Vec<[f32; 3]> = posed.iter().map(key).collect();
                let mut guard = prepared.kept.lock().unwrap_or_else(|e| e.into_inner());
                let (to_observed, to_model) = &mut *guard;
                let reused_before = [to_observed.reused, to_model.reused];
                let (forward, backward) = rayon::join(
                    || {
                        self.time("nearest model->observed", || {
                            to_observed.partners(&keys, obs_tree, &prepared.grid)
                        })
                    },
                    || {
                        let answers = self.time("nearest observed->model", || {
                            to_model.kept(obs_tree.keys(), &keys)
                        });
                        if answers.iter().all(|a| a.is_ok()) {
                            answers.into_iter().flatten().collect()
                        } else {
                            self.time("model grid", || {
                                to_model.grid.rebuild(&keys, search_cell(p.model_spacing))
                            });
                            self.time("nearest observed->model", || {
                                to_model.search(obs_tree.keys(), &keys, answers)
                            })
                        }
                    },
                );
                if let Ok(mut r) = self.nearest_reuse.lock() {
                    r[0] += to_observed.reused - reused_before[0];
                    r[1] += forward.len();
                    r[2] += to_model.reused - reused_before[1];
                    r[3] += backward.len();
                }
                (forward, backward)
            }
        };
        // rho_c and the pairs depend only on the posed model: found side by side, so that
        // one's sequential parts (tree builds) overlap the other's parallel searches.
        let (rho_c, (forward, backward)) = rayon::join(find_rho_c, find_pairs);
        let weight = |v: usize, u: usize| -> f64 {
            match method {
                Method::Icp => 1.0,
                Method::Normals => {
                    if agree(v, u) {
                        1.0
                    } else {
                        0.0
                    }
                }
                Method::RhoC => rho_c[v],
                Method::RhoP => obs.rho_p[u],
                Method::Proposed => rho_c[v] * obs.rho_p[u],
            }
        };
        // The weight without rho_c ([`Round::score`]).
        let score_weight = |v: usize, u: usize| -> f64 {
            match method {
                Method::RhoC => 1.0,
                Method::Proposed => obs.rho_p[u],
                Method::Icp | Method::Normals | Method::RhoP => weight(v, u),
            }
        };
        self.time("pairs, weights", || {
            let n = posed.len();
            // Each pair's weight and weight without rho_c, in parallel (0 for a pair
            // without a partner).
            let weigh = |v: usize, u: usize, d2: f64| {
                if d2.is_finite() {
                    (weight(v, u), score_weight(v, u))
                } else {
                    (0.0, 0.0)
                }
            };
            let forward_weights: Vec<(f64, f64)> = forward
                .par_iter()
                .enumerate()
                .map(|(v, &(u, d2))| weigh(v, u, d2))
                .collect();
            let backward_weights: Vec<(f64, f64)> = backward
                .par_iter()
                .enumerate()
                .map(|(u, &(v, d2))| weigh(v, u, d2))
                .collect();
            // Whether a pair pulls its model vertex (a pair without a partner weighs 0).
            let pulls_on = |w: f64| w > 0.0;
            // The sums over all pairs, serially in the pairs' order (forward, then
            // backward): the same bits on every run.
            let (mut weighted_sq, mut weight_sum, mut downweighted) = (0.0, 0.0, 0usize);
            let mut scored_sq = 0.0;
            let pairs = forward
                .iter()
                .zip(&forward_weights)
                .chain(backward.iter().zip(&backward_weights));
            for (&(_, d2), &(w, ws)) in pairs {
                if w < 0.5 {
                    downweighted += 1;
                }
                if pulls_on(w) {
                    weighted_sq += w * d2;
                    weight_sum += w;
                }
                if ws > 0.0 {
                    scored_sq += ws * d2;
                }
            }
            // Each model vertex's pulls: its own pair, then the observed vertices whose
            // nearest it is, in their order (a counting sort), summed vertex by vertex in
            // parallel; each vertex's sum runs in the same order as one pass over the pairs.
            let mut starts = vec![0u32; n + 1];
            for (&(v, _), &(w, _)) in backward.iter().zip(&backward_weights) {
                if pulls_on(w) {
                    starts[v + 1] += 1;
                }
            }
            for v in 0..n {
                starts[v + 1] += starts[v];
            }
            let mut next = starts.clone();
            let mut pullers = vec![0u32; starts[n] as usize];
            for (u, (&(v, _), &(w, _))) in backward.iter().zip(&backward_weights).enumerate() {
                if pulls_on(w) {
                    pullers[next[v] as usize] = u as u32;
                    next[v] += 1;
                }
            }
            let (w_sum, target): (Vec<f64>, Vec<Vector3<f64>>) = (0..n)
                .into_par_iter()
                .map(|v| {
                    let (mut total, mut sum) = (0.0, Vector3::zeros());
                    let (u, _) = forward[v];
                    let (w, _) = forward_weights[v];
                    if pulls_on(w) {
                        total += w;
                        sum += w * obs.vertices[u];
                    }
                    for &u in &pullers[starts[v] as usize..starts[v + 1] as usize] {
                        let w = backward_weights[u as usize].0;
                        total += w;
                        sum += w * obs.vertices[u as usize];
                    }
                    (total, sum)
                })
                .unzip();
            let pulled: Vec<usize> = (0..n).filter(|&v| w_sum[v] > 0.0).collect();
            let pulls = pulled
                .iter()
                .map(|&v| (v as u32, w_sum[v], target[v] / w_sum[v]))
                .collect();
            // Each pair as a plane: a model vertex's own pair through its observed partner's
            // tangent plane, an observed vertex's pair through its model partner's.
            let planes = if method == Method::Proposed {
                // A model vertex's own pair: its partner's tangent plane where the two
                // normals agree, its own where they do not (a phantom surface, or the far
                // side of another part); an observed vertex's pair: its partner's.
                let observed_normal = |v: usize, u: usize| {
                    if normals[v].dot(&obs.normals[u]) > PLANE_AGREEMENT {
                        obs.normals[u]
                    } else {
                        normals[v]
                    }
                };
                let plane = |v: usize, u: usize, weight: f64, normal: Vector3<f64>| solve::Plane {
                    vertex: v as u32,
                    weight,
                    point: obs.vertices[u],
                    normal,
                };
                let own = forward.iter().zip(&forward_weights).enumerate();
                let theirs = backward.iter().zip(&backward_weights).enumerate();
                own.filter(|(_, (_, &(w, _)))| pulls_on(w))
                    .map(|(v, (&(u, _), &(w, _)))| plane(v, u, w, observed_normal(v, u)))
                    .chain(
                        theirs
                            .filter(|(_, (_, &(w, _)))| pulls_on(w))
                            .map(|(u, (&(v, _), &(w, _)))| plane(v, u, w, normals[v])),
                    )
                    .collect()
            } else {
                Vec::new()
            };
            let r_c: f64 = rho_c.iter().sum();
            let r_p: f64 = if method.uses_rho_p() {
                obs.rho_p.iter().sum()
            } else {
                obs.vertices.len() as f64
            };
            let n_obs = obs.vertices.len() as f64;
            let score_normalizer = n as f64
                * match method {
                    Method::Proposed | Method::RhoP => obs.rho_p.iter().sum(),
                    _ => n_obs,
                };
            Round {
                targets: Targets { pulls, planes },
                weighted_sq,
                weight_sum,
                pairs: forward.len() + backward.len(),
                downweighted,
                normalizer: (r_c * r_p).max(1e-300),
                contact_share: rho_c.iter().filter(|&&r| r < 0.5).count() as f64 / n.max(1) as f64,
                scored_sq,
                score_normalizer: score_normalizer.max(1e-300),
            }
        })
    }
}

/// Indices of `points` thinned to one per cube of side `spacing` (the point nearest the
/// cube's centre; ties to the lower index), in increasing order; all of them for spacing 0.
pub fn thin(points: &[Vector3<f64>], spacing: f64) -> Vec<usize> {
    if spacing <= 0.0 {
        return (0..points.len()).collect();
    }
    let mut best: std::collections::HashMap<[i64; 3], (usize, f64)> =
        std::collections::HashMap::new();
    for (i, p) in points.iter().enumerate() {
        let c = p / spacing;
        let cell = [c.x.floor() as i64, c.y.floor() as i64, c.z.floor() as i64];
        let centre = Vector3::new(cell[0] as f64, cell[1] as f64, cell[2] as f64).add_scalar(0.5);
        let d = (c - centre).norm_squared();
        let e = best.entry(cell).or_insert((i, d));
        if d < e.1 {
            *e = (i, d);
        }
    }
    let mut keep: Vec<usize> = best.into_values().map(|x| x.0).collect();
    keep.sort_unstable();
    keep
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
fn better(a: FitResult, b: FitResult) -> FitResult {
    let (rounds, steps) = (
        a.diagnostics.iterations + b.diagnostics.iterations,
        a.diagnostics.lm_steps + b.diagnostics.lm_steps,
    );
    let mut best = if b.diagnostics.score < a.diagnostics.score {
        b
    } else {
        a
    };
    best.diagnostics.iterations = rounds;
    best.diagnostics.lm_steps = steps;
    best
}

/// Where a solver starts: the pose, its round (pairs, weights) and the diagnostics so far.
type FitStart = (Pose, Round, FitDiagnostics);

/// The fit's result at `pose`, whose pairs and weights `round` holds.
fn finish(pose: Pose, round: &Round, mut diagnostics: FitDiagnostics) -> FitResult {
    diagnostics.energy = round.energy();
    diagnostics.rms = (round.weighted_sq / round.weight_sum.max(1e-300)).sqrt();
    diagnostics.downweighted_share = round.downweighted as f64 / round.pairs.max(1) as f64;
    diagnostics.contact_share = round.contact_share;
    diagnostics.score = round.score();
    FitResult { pose, diagnostics }
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
