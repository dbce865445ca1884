//! The skin-bone body model M(p) (method.md "Stage 5"): the reference surface, the skeleton
//! embedded in it, per-vertex skinning weights and part labels; and its compact file.

use super::skinning::{self, Influences};
use super::{Pose, PosedBones, Skeleton};
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use nalgebra::Vector3;
use std::path::Path;

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
