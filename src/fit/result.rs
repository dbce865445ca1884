//! What the fit takes and gives: one frame's observed surface, and the fitted pose with
//! its diagnostics (the rows of `fit.csv`).

use crate::skeleton::Pose;
use nalgebra::Vector3;

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
    /// Stopped at the round cap (`fit.stop.max_rounds`, or the baselines' cap).
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
    /// (`Round::score` in round.rs; equal to `energy` for methods without rho_c).
    pub score: f64,
    /// Observed vertices.
    pub observed: usize,
    /// The reliable observed surface the final pose leaves unexplained (`round.rs`).
    pub unexplained: Unexplained,
    /// Recovery (`recovery.rs`): not tried (`None`), tried and the first fit kept
    /// (`kept`), or the hypothesis that won.
    pub recovery: Option<String>,
    /// How far an equally good fit of one limb lies from this pose, metres (the largest
    /// joint motion between the two), when the frame's evidence could not choose between
    /// them (`tracking.rs`, `ambiguity`); `None` when there was no such fit.
    pub ambiguous: Option<f64>,
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
            unexplained: Default::default(),
            recovery: None,
            ambiguous: None,
        }
    }
}

/// A fitted frame.
#[derive(Debug, Clone)]
pub struct FitResult {
    pub pose: Pose,
    pub diagnostics: FitDiagnostics,
}

/// The reliable observed surface the posed model leaves unexplained: how many thinned
/// observed vertices (about one per `sample_spacing` squared of surface), and the bone
/// whose model vertices are most often their nearest (the part that should be there).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Unexplained {
    pub vertices: usize,
    pub bone: Option<usize>,
}
