//! The model stage's artifact, filed under the reference frame: `model.hpm`, the compact
//! model the fit reads, and `model.ply`, the surface coloured by part with the part label
//! and the two strongest (bone, weight) pairs as extra vertex properties.

use crate::cache::Cache;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::skeleton::model::{part_colour, BodyModel};
use crate::skeleton::{skinning, Skeleton};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The stage folder's name.
pub const STAGE: &str = "model";

/// The compact model's and the coloured PLY's names in the stage folder.
const MODEL_FILE: &str = "model.hpm";
const MODEL_PLY: &str = "model.ply";

/// Magic bytes of the model file.
const MAGIC: &[u8; 8] = b"HPMODEL1";

/// Where the coloured model is in the cache.
pub fn ply_path(cache: &Cache) -> PathBuf {
    cache.stage_dir(STAGE).join(MODEL_PLY)
}

/// Reads the cached body model.
pub fn read(cache: &Cache) -> Result<BodyModel> {
    let path = cache.stage_dir(STAGE).join(MODEL_FILE);
    let data = crate::limits::read_cache_file(&path)?;
    parse_model(&path, &data)
}

impl super::Artifact for BodyModel {
    fn write(&self, dir: &Path, _frame: u32) -> Result<Vec<String>> {
        write(dir, self)
    }
}

/// Writes `model` into `dir`; returns the files, relative to it.
fn write(dir: &Path, model: &BodyModel) -> Result<Vec<String>> {
    use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
    let colours: Vec<[u8; 3]> = model.labels.iter().map(|&l| part_colour(l)).collect();
    let normals = model.mesh.vertex_normals();
    let label: Vec<f32> = model.labels.iter().map(|&l| l as f32).collect();
    let strongest = |k: usize, bone: bool| -> Vec<f32> {
        model
            .weights
            .iter()
            .map(|w| {
                let mut w = w.clone();
                w.sort_by(|a, b| b.1.total_cmp(&a.1));
                match w.get(k) {
                    Some(&(b, _)) if bone => b as f32,
                    Some(&(_, x)) => x as f32,
                    None if bone => -1.0,
                    None => 0.0,
                }
            })
            .collect()
    };
    let (b0, w0, b1, w1) = (
        strongest(0, true),
        strongest(0, false),
        strongest(1, true),
        strongest(1, false),
    );
    let attrs = VertexAttributes {
        normals: Some(&normals),
        colors: Some(&colours),
        scalars: vec![
            ("part", &label),
            ("bone0", &b0),
            ("weight0", &w0),
            ("bone1", &b1),
            ("weight1", &w1),
        ],
    };
    write_ply(
        &dir.join(MODEL_PLY),
        &model.mesh,
        &attrs,
        PlyFormat::BinaryLittleEndian,
    )?;
    crate::fsutil::write_atomic(&dir.join(MODEL_FILE), &model_bytes(model))?;
    Ok(vec![MODEL_FILE.into(), MODEL_PLY.into()])
}

/// The compact little-endian file: magic; skeleton.yaml text (u64 length, bytes);
/// vertex count (u64), per vertex x y z (f64), influence count (u8) and (bone u16,
/// weight f32) pairs; triangle count (u64) and indices (3 x u32). Labels are the
/// dominant influences, so they are not stored.
pub fn model_bytes(model: &BodyModel) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    let yaml = model.skeleton.to_yaml();
    out.extend_from_slice(&(yaml.len() as u64).to_le_bytes());
    out.extend_from_slice(yaml.as_bytes());
    out.extend_from_slice(&(model.mesh.vertices.len() as u64).to_le_bytes());
    for (v, w) in model.mesh.vertices.iter().zip(&model.weights) {
        for x in v.iter() {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.push(w.len() as u8);
        for &(b, wb) in w {
            out.extend_from_slice(&(b as u16).to_le_bytes());
            out.extend_from_slice(&(wb as f32).to_le_bytes());
        }
    }
    out.extend_from_slice(&(model.mesh.triangles.len() as u64).to_le_bytes());
    for t in &model.mesh.triangles {
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}

/// Reads what [`model_bytes`] wrote; `path` names the file in errors. Counts
/// are checked against the remaining bytes before anything is allocated from them.
pub fn parse_model(path: &Path, data: &[u8]) -> Result<BodyModel> {
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
