//! The fit stage's parameters (pipeline.yaml key `fit`) and their checks: which method
//! (the paper's and the baselines it compares with), where a frame starts, the contact
//! weight, the sampling, when the rounds stop and when a lost fit is restarted.

use super::contact::ContactParams;
use crate::error::Refusal;
use serde::{Deserialize, Serialize};

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

    pub(super) fn uses_rho_c(self) -> bool {
        matches!(self, Method::RhoC | Method::Proposed)
    }

    pub(super) fn uses_rho_p(self) -> bool {
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

/// Parameters of the fit stage (pipeline.yaml key `fit`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FitParams {
    /// `icp`, `normals`, `rho_c`, `rho_p` or `proposed` (default).
    pub method: Method,
    /// Where a tracked frame starts: `previous` (default) or `predicted` ([`Start`]).
    /// A fit that looks lost is fitted again from the other one ([`RestartParams`]).
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
    /// When a fitted frame counts as implausible ([`crate::fit::health`]).
    pub health: HealthParams,
    /// The motion prior's acceleration, m/s^2: how fast a body part's velocity typically
    /// changes. In `proposed`'s energy (the baselines have none), every model vertex is pulled towards where the previous two frames' motion
    /// continued at constant velocity puts it, with weight (2 mm f^2 / a)^2 (f the frame
    /// rate, `export.frame_rate`; a pair's weight is rho_c rho_p, at most 1): a Gaussian
    /// prior whose spread a / f^2 is the distance such an acceleration moves a part off
    /// the prediction in one frame, against surfaces known to about 2 mm. Smaller values
    /// trust the prediction more; 0: no prior. Default 18 (a weight of 0.005 at 25 fps,
    /// 0.00005 at 8 fps, where the prediction is ten times less sure).
    pub motion_prior_acceleration: f64,
}

/// How well the surfaces place a point, metres: the motion prior's scale
/// ([`FitParams::motion_prior_acceleration`]).
pub const PRIOR_NOISE: f64 = 0.002;

/// The frame rate the motion prior's weight is computed at when the capture's is unknown,
/// frames per second: its spread then comes from the tracked motion (it is never below half
/// the last step's RMS motion, [`crate::fit::tracking`]), so the nominal rate only sets how
/// much a slow body is trusted to keep its velocity.
pub const NOMINAL_FRAME_RATE: f64 = 25.0;

/// The motion prior's weight per model vertex at `frame_rate` frames per second (0: none).
pub fn motion_prior_weight(acceleration: f64, frame_rate: f64) -> f64 {
    if acceleration <= 0.0 || frame_rate <= 0.0 {
        return 0.0;
    }
    (PRIOR_NOISE * frame_rate * frame_rate / acceleration).powi(2)
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

/// Restarts of a fit that looks lost (pipeline.yaml key `fit.restart`; `tracking.rs`).
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
    /// (a limb folded back onto itself), unless its score fell below the previous frame's
    /// (a fast turn the observation explains). Default 45.
    pub turn_deg: f64,
    /// Rounds per restart at most, as a multiple of the method's round cap. Default 2.
    pub rounds_factor: usize,
}

/// The fit's health checks (pipeline.yaml key `fit.health`): a frame is flagged in fit.csv
/// and the run summary when one of them fails.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HealthParams {
    /// The fastest plausible motion of a joint, metres per second, at the capture's frame
    /// rate (`export.frame_rate`). Default 6: a sprinter's hand; at 25 frames per second, 24
    /// cm between frames.
    pub max_joint_speed: f64,
    /// A frame is flagged when its worst-camera silhouette IoU falls below this share of
    /// the recent level (the median of the previous five tracked frames' worst IoU).
    /// Default 0.9.
    pub iou_drop: f64,
    /// A frame is flagged `iou_drift` when its worst-camera silhouette IoU falls below this
    /// share of the reference frame's (a slow drift that `iou_drop`, judged against the
    /// recent frames, never sees). Default 0.9.
    pub iou_drift: f64,
    /// A frame is flagged, and fitted again from the recovery hypotheses (`recovery.rs`),
    /// when the fitted pose leaves more than this much reliable observed surface (rho_p at
    /// least 0.5) farther than 3 cm from the model, cm^2. Default 8 (a fit from the true
    /// pose leaves 0-2 on the humanoid's dance, a hand folded back 9-18).
    pub unexplained_cm2: f64,
    /// The silhouette IoU above is measured on the posed model moved onto the frame's
    /// observed surface where that lies within this reach, metres ([`super::surface_layer`]):
    /// clothing and surface detail the rigidly skinned model cannot follow do not count
    /// against the pose, a limb farther off does. 0: the posed model as it is. Default 0.05.
    pub surface_reach: f64,
    /// A frame is flagged, and recovered, when two parts that do not meet at a joint overlap
    /// deeper than this (their flesh as capsules, beyond their overlap at the reference
    /// pose; `interpenetration.rs`), cm. Default 6 (the dance's true poses reach 3.8 where a
    /// hand presses on the other forearm).
    pub interpenetration_cm: f64,
    /// A frame is flagged `bent_joint`, and recovered, when an end bone (a hand, a foot, the
    /// head: a bone without children) swings more than this from its reference direction
    /// relative to its parent ([`super::health::sharpest_end_bend`]), degrees. Default 120:
    /// a wrist or an ankle moves within about 90 degrees; the dance's right hand folded back
    /// onto its forearm swings 146-163 (BENCHMARKS.md has the real dancer's).
    pub bend_deg: f64,
    /// A frame is flagged `twisted_trunk` when the hips turned more than this from the
    /// shoulders about the trunk since the reference pose
    /// ([`super::health::trunk_twist_deg`]), degrees. Default 90: a trunk turns about 45
    /// each way. Only flagged: recovery's hypotheses do not turn the pelvis.
    pub twist_deg: f64,
    /// A frame is flagged when its eq. 4 energy is more than this times the larger of the
    /// two previous tracked frames'. Default 10 (on a masks-only capture, where the hull's
    /// phantom volumes are observed surface, eq. 4 varies by 3x between good frames).
    pub energy_jump: f64,
}

impl Default for HealthParams {
    fn default() -> Self {
        HealthParams {
            max_joint_speed: 6.0,
            iou_drop: 0.9,
            iou_drift: 0.9,
            unexplained_cm2: 8.0,
            surface_reach: 0.05,
            interpenetration_cm: 6.0,
            bend_deg: 120.0,
            twist_deg: 90.0,
            energy_jump: 10.0,
        }
    }
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
            health: HealthParams::default(),
            motion_prior_acceleration: 18.0,
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
pub fn validate(p: &FitParams) -> std::result::Result<(), Refusal> {
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
        )
        .into());
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
            )
            .into());
        }
    }
    for (key, tolerance) in [
        ("tolerance", s.tolerance),
        ("baseline_tolerance", s.baseline_tolerance),
    ] {
        if !positive(tolerance) {
            return Err(format!(
                "fit.stop.{key} must be a positive distance in metres, got {tolerance}"
            )
            .into());
        }
    }
    let h = &p.health;
    if !(p.motion_prior_acceleration >= 0.0 && p.motion_prior_acceleration.is_finite()) {
        return Err(format!(
            "fit.motion_prior_acceleration must be a number of m/s^2, 0 or more (0: no motion prior), got {}",
            p.motion_prior_acceleration
        ).into());
    }
    if !(h.iou_drift > 0.0 && h.iou_drift <= 1.0) {
        return Err(format!(
            "fit.health.iou_drift must be a share in (0, 1], got {}",
            h.iou_drift
        )
        .into());
    }
    if !(positive(h.max_joint_speed) && h.iou_drop > 0.0 && h.iou_drop <= 1.0) {
        return Err(format!(
            "fit.health: max_joint_speed must be a positive number of metres per second and \
             iou_drop a share in (0, 1], got {} and {}",
            h.max_joint_speed, h.iou_drop
        )
        .into());
    }
    let energy_jump_ok = h.energy_jump.is_finite() && h.energy_jump >= 1.0;
    if !(positive(h.unexplained_cm2) && positive(h.interpenetration_cm) && energy_jump_ok) {
        return Err(format!(
            "fit.health: unexplained_cm2 must be a positive area in cm^2, interpenetration_cm a \
             positive depth in cm and energy_jump a ratio >= 1, got {}, {} and {}",
            h.unexplained_cm2, h.interpenetration_cm, h.energy_jump
        )
        .into());
    }
    if !(h.bend_deg > 0.0 && h.bend_deg <= 180.0) {
        return Err(format!(
            "fit.health.bend_deg must be an angle in (0, 180] degrees (default 120), got {}",
            h.bend_deg
        )
        .into());
    }
    if !(h.twist_deg > 0.0 && h.twist_deg <= 180.0) {
        return Err(format!(
            "fit.health.twist_deg must be an angle in (0, 180] degrees (default 90), got {}",
            h.twist_deg
        )
        .into());
    }
    if !(h.surface_reach.is_finite() && (0.0..=0.5).contains(&h.surface_reach)) {
        return Err(format!(
            "fit.health.surface_reach must be a distance between 0 and 0.5 m (default 0.05), \
             got {}",
            h.surface_reach
        )
        .into());
    }
    let r = &p.restart;
    if !(r.energy_ratio.is_finite() && r.energy_ratio >= 1.0) {
        return Err(format!(
            "fit.restart.energy_ratio must be a number >= 1, got {}",
            r.energy_ratio
        )
        .into());
    }
    if !(r.turn_deg > 0.0 && r.turn_deg <= 180.0) {
        return Err(format!(
            "fit.restart.turn_deg must be in (0, 180] degrees, got {}",
            r.turn_deg
        )
        .into());
    }
    if !(0.0..1.0).contains(&p.min_observed_share) {
        return Err(format!(
            "fit.min_observed_share must be in [0, 1), got {}",
            p.min_observed_share
        )
        .into());
    }
    Ok(())
}
