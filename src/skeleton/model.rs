//! The skin-bone body model M(p) (method.md "Stage 5"): the reference surface, the skeleton
//! embedded in it, per-vertex skinning weights and part labels; and its compact file.

use super::skinning::{self, Influences};
use super::{Pose, PosedBones, Skeleton};
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

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
pub fn validate(p: &ModelParams) -> std::result::Result<(), String> {
    if !(p.blend_width > 0.0 && p.blend_width.is_finite()) {
        return Err(format!(
            "model.blend_width must be a positive width in metres, got {}",
            p.blend_width
        ));
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
) -> std::result::Result<BodyModel, String> {
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
pub fn bones_inside(skeleton: &Skeleton, mesh: &TriMesh) -> std::result::Result<(), String> {
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
            ));
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

/// Magic bytes of the model file.
const MAGIC: &[u8; 8] = b"HPMODEL1";

impl BodyModel {
    /// The model's surface posed by `pose` (linear blend skinning).
    pub fn pose(&self, pose: &Pose) -> TriMesh {
        let bones = PosedBones::new(&self.skeleton, pose);
        TriMesh {
            vertices: skinning::pose_vertices(&bones, &self.mesh.vertices, &self.weights),
            triangles: self.mesh.triangles.clone(),
        }
    }

    /// The compact little-endian file: magic; skeleton.yaml text (u64 length, bytes);
    /// vertex count (u64), per vertex x y z (f64), influence count (u8) and (bone u16,
    /// weight f32) pairs; triangle count (u64) and indices (3 x u32). Labels are the
    /// dominant influences, so they are not stored.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(MAGIC);
        let yaml = self.skeleton.to_yaml();
        out.extend_from_slice(&(yaml.len() as u64).to_le_bytes());
        out.extend_from_slice(yaml.as_bytes());
        out.extend_from_slice(&(self.mesh.vertices.len() as u64).to_le_bytes());
        for (v, w) in self.mesh.vertices.iter().zip(&self.weights) {
            for x in v.iter() {
                out.extend_from_slice(&x.to_le_bytes());
            }
            out.push(w.len() as u8);
            for &(b, wb) in w {
                out.extend_from_slice(&(b as u16).to_le_bytes());
                out.extend_from_slice(&(wb as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&(self.mesh.triangles.len() as u64).to_le_bytes());
        for t in &self.mesh.triangles {
            for i in t {
                out.extend_from_slice(&i.to_le_bytes());
            }
        }
        out
    }

    /// Reads what [`BodyModel::to_bytes`] wrote; `path` names the file in errors. Counts
    /// are checked against the remaining bytes before anything is allocated from them.
    pub fn parse(path: &Path, data: &[u8]) -> Result<BodyModel> {
        let bad = || Error::invalid(path, "not a hullpose model file (or truncated)");
        let mut r = Reader { data, at: 0 };
        if r.take(8).ok_or_else(bad)? != MAGIC {
            return Err(bad());
        }
        let len = r.count(1).ok_or_else(bad)?;
        let yaml = std::str::from_utf8(r.take(len).ok_or_else(bad)?).map_err(|_| bad())?;
        let skeleton = Skeleton::parse(path, yaml)?;
        let n = r.count(25).ok_or_else(bad)?;
        let mut mesh = TriMesh::default();
        let mut weights = Vec::with_capacity(n);
        for _ in 0..n {
            let v = r.take(24).ok_or_else(bad)?;
            let f = |k: usize| f64::from_le_bytes(v[8 * k..8 * k + 8].try_into().unwrap());
            mesh.vertices.push(Vector3::new(f(0), f(1), f(2)));
            let k = r.take(1).ok_or_else(bad)?[0] as usize;
            let mut w = Vec::with_capacity(k);
            for _ in 0..k {
                let e = r.take(6).ok_or_else(bad)?;
                let b = u16::from_le_bytes([e[0], e[1]]) as usize;
                if b >= skeleton.bones.len() {
                    return Err(bad());
                }
                w.push((b, f32::from_le_bytes(e[2..6].try_into().unwrap()) as f64));
            }
            weights.push(w);
        }
        let nt = r.count(12).ok_or_else(bad)?;
        for _ in 0..nt {
            let t = r.take(12).ok_or_else(bad)?;
            let i = |k: usize| u32::from_le_bytes(t[4 * k..4 * k + 4].try_into().unwrap());
            let tri = [i(0), i(1), i(2)];
            if tri.iter().any(|&i| i as usize >= n) {
                return Err(bad());
            }
            mesh.triangles.push(tri);
        }
        if r.at != data.len() {
            return Err(bad());
        }
        let labels = skinning::labels(&weights);
        Ok(BodyModel {
            skeleton,
            mesh,
            weights,
            labels,
        })
    }
}

/// A bounded little-endian reader.
struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.at.checked_add(n)?;
        let s = self.data.get(self.at..end)?;
        self.at = end;
        Some(s)
    }

    /// A u64 count of records at least `min_size` bytes each that fit in the rest.
    fn count(&mut self, min_size: usize) -> Option<usize> {
        let n = u64::from_le_bytes(self.take(8)?.try_into().ok()?) as usize;
        (n.checked_mul(min_size)? <= self.data.len() - self.at).then_some(n)
    }
}
