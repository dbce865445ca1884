//! The skin-bone body model M(p) (method.md "Stage 5"): the reference surface, the skeleton
//! embedded in it, per-vertex skinning weights and part labels; and its compact file.

use super::skinning::{self, Influences};
use super::{Pose, PosedBones, Skeleton};
use crate::error::Refusal;
use crate::geometry::TriMesh;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A skinned body model at the reference frame t0.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyModel {
    pub skeleton: Skeleton,
    /// The reference surface (t0), world metres.
    pub mesh: TriMesh,
    /// Bone influences per vertex (weights sum to 1).
    pub weights: Vec<Influences>,
    /// Part label (dominant bone) per vertex.
    pub labels: Vec<usize>,
}

/// Parameters of the model stage (pipeline.yaml key `model`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelParams {
    /// The subject's true shape as a mesh (OBJ or PLY, world metres, posed as the skeleton
    /// at t0), relative to pipeline.yaml; default none: the reference frame's refined
    /// surface.
    pub mesh: Option<PathBuf>,
    /// Width of the weight blend across a joint, metres. Default 0.025.
    pub blend_width: f64,
}

impl Default for ModelParams {
    fn default() -> Self {
        ModelParams {
            mesh: None,
            blend_width: 0.025,
        }
    }
}

/// Checks parameters that do not depend on the data.
pub fn validate(p: &ModelParams) -> std::result::Result<(), Refusal> {
    if !(p.blend_width > 0.0 && p.blend_width.is_finite()) {
        return Err(format!(
            "model.blend_width must be a positive width in metres, got {}",
            p.blend_width
        )
        .into());
    }
    Ok(())
}

/// Builds the model of `skeleton` on the reference surface `mesh`. Refuses an empty
/// surface and bones that do not lie inside it (at least two of the points at a quarter,
/// half and three quarters of the bone must be inside), naming the bone.
pub fn build(
    skeleton: &Skeleton,
    mesh: &TriMesh,
    p: &ModelParams,
) -> std::result::Result<BodyModel, Refusal> {
    bones_inside(skeleton, mesh)?;
    let weights = skinning::skin_weights(skeleton, &mesh.vertices, p.blend_width);
    let labels = skinning::labels(&weights);
    Ok(BodyModel {
        skeleton: skeleton.clone(),
        mesh: mesh.clone(),
        weights,
        labels,
    })
}

/// Checks that every bone of `skeleton` lies inside the closed surface `mesh` (at least
/// two of the points at a quarter, half and three quarters of the bone inside); the message
/// names the first bone that does not.
pub fn bones_inside(skeleton: &Skeleton, mesh: &TriMesh) -> std::result::Result<(), Refusal> {
    if mesh.vertices.is_empty() || mesh.triangles.is_empty() {
        return Err("the reference surface is empty".into());
    }
    for bone in &skeleton.bones {
        let inside = [0.25, 0.5, 0.75]
            .iter()
            .filter(|&&t| mesh.winding_number(&(bone.head + t * (bone.tail - bone.head))) > 0.5)
            .count();
        if inside < 2 {
            return Err(format!(
                "bone '{}' lies outside the reference surface ({} of 3 points along it inside); \
                 check skeleton.yaml's coordinates and reference_frame",
                bone.name, inside
            )
            .into());
        }
    }
    Ok(())
}

/// A distinct colour per part.
pub fn part_colour(part: usize) -> [u8; 3] {
    const PALETTE: [[u8; 3]; 12] = [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [250, 190, 212],
        [0, 128, 128],
        [170, 110, 40],
    ];
    PALETTE[part % PALETTE.len()]
}

impl BodyModel {
    /// The model's surface posed by `pose` (linear blend skinning).
    pub fn pose(&self, pose: &Pose) -> TriMesh {
        let bones = PosedBones::new(&self.skeleton, pose);
        TriMesh {
            vertices: skinning::pose_vertices(&bones, &self.mesh.vertices, &self.weights),
            triangles: self.mesh.triangles.clone(),
        }
    }
}
