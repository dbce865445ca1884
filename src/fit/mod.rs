//! Robust articulated fitting (method.md "Stage 6"): the pose of the skin-bone model that
//! best explains one frame's observed surface, starting from the previous frame's pose.
//!
//! Per frame, rounds of (a) posing the model and finding, both ways, each vertex's nearest
//! neighbour on the other surface and the pair's weight ([`round`], [`pairs`]); (b) a
//! Levenberg-Marquardt step on the 3N+3 pose increments with the pairs held ([`solve`]);
//! until the joints settle ([`descent`]). Frames are tracked from the reference frame
//! outwards, with restarts of fits that look lost ([`tracking`]).
//!
//! Paper eq. 4, with each pair weighted by its own two ends (model vertex v, observed u):
//! `E(p) = sum_pairs rho_c(v)/R_c * rho_p(u)/R_p * |v - u|^2`. The five methods are this one
//! energy with different weights ([`Method`]).
//!
//! Files: [`params`] (pipeline.yaml's `fit` and its checks), [`result`] (what a fit takes
//! and gives), [`pairs`], [`round`], [`contact`] (rho_c), [`solve`] (the held problem and
//! LM), [`descent`] (one start's rounds), [`tracking`], [`probe`] (timings for benchmarks).

mod anderson;
pub mod contact;
mod descent;
pub mod health;
pub mod interpenetration;
pub mod kept_nearest;
mod moments;
pub mod pairs;
pub mod params;
pub mod probe;
mod recovery;
pub mod result;
mod round;
pub mod solve;
pub mod surface_layer;
pub mod tracking;

pub use crate::skeleton::sides::{is_left, other_side};
pub use descent::POINT_SHARE;
pub use pairs::{thin, COMPATIBLE_SEARCH_LIMIT};
pub use params::{validate, FitParams, HealthParams, Method, RestartParams, Start, StopParams};
pub use probe::{Probe, RoundKind, RoundRecord, STEP_PART_PREFIX};
pub use recovery::{unexplained_cm2, SilhouetteScore};
pub use result::{FitDiagnostics, FitResult, FitStatus, Observation, Unexplained};
pub use tracking::{joint_motion, Neighbours, Tracker};

use crate::geometry::TriMesh;
use crate::skeleton::model::BodyModel;
use crate::skeleton::Pose;
use contact::ContactSearch;
use nalgebra::Vector3;

/// Fits frames of one sequence with one model and one set of parameters.
pub struct Fitter<'a> {
    pub model: &'a BodyModel,
    pub params: FitParams,
    /// The model's vertices the energy runs over (about one per `model_spacing`), with
    /// their reference normals; no triangles.
    sample: BodyModel,
    sample_normals: Vec<Vector3<f64>>,
    contact: ContactSearch,
    /// The farthest a joint plausibly moves between two frames, metres
    /// (`fit.health.max_joint_speed` over the frame rate); a tracked fit that moves one
    /// farther is recovered ([`recovery`]). `None`: no such check.
    pub max_joint_step: Option<f64>,
    /// Whether rho_p measures photo-consistency (false for masks-only captures, whose
    /// observed surface is the hull with its phantom volumes): only then does unexplained
    /// observed surface send a frame to recovery.
    pub photo_consistent: bool,
    /// The parts as capsules, for the interpenetration check ([`interpenetration`]).
    pub capsules: interpenetration::Capsules,
    /// The motion prior's weight per model vertex ([`params::motion_prior_weight`]; it
    /// needs the frame rate). 0: none.
    pub motion_prior: f64,
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
        let capsules = interpenetration::Capsules::new(model);
        Fitter {
            model,
            params,
            sample,
            sample_normals,
            contact,
            max_joint_step: None,
            motion_prior: 0.0,
            photo_consistent: true,
            capsules,
        }
    }

    /// The diagnostics of the reference frame (pose p_t0 = the embedded skeleton).
    pub fn reference(&self, observed: usize) -> FitResult {
        FitResult {
            pose: Pose::rest(self.model.skeleton.bones.len()),
            diagnostics: FitDiagnostics::unfitted(FitStatus::Reference, observed),
        }
    }

    /// Fits one frame's `obs` starting from `start` (no restarts); a frame without enough
    /// observation keeps `start`.
    pub fn fit(&self, obs: &Observation, start: &Pose, probe: &Probe) -> FitResult {
        let p = &self.params;
        match pairs::prepare(obs, p, self.model.mesh.vertices.len()) {
            Some(prepared) => self.fit_prepared(&prepared, start, p.stopping(p.method).1, probe),
            None => self.unobserved(obs, start),
        }
    }
}
