//! The reliability stage's artifact: the observed surface with its per-vertex ZNCC, rho_p
//! and camera count, as a compact file the fit reads (`NNNNNN.obs`) and as a PLY coloured
//! by reliability for viewers (`NNNNNN.ply`).

use crate::cache::Cache;
use crate::dataset::frame_stem;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::recon::reliability::Observed;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The stage folder's name.
pub const STAGE: &str = "reliability";

/// A frame's coloured PLY and compact observation, relative to the stage folder.
fn files(frame: u32) -> (String, String) {
    let stem = frame_stem(frame);
    (format!("{stem}.ply"), format!("{stem}.obs"))
}

/// Where a frame's coloured PLY is in the cache.
pub fn ply_path(cache: &Cache, frame: u32) -> PathBuf {
    cache.stage_dir(STAGE).join(files(frame).0)
}

/// Reads a frame's observed surface with its reliability.
pub fn read(cache: &Cache, frame: u32) -> Result<Observed> {
    let path = cache.stage_dir(STAGE).join(files(frame).1);
    let data = crate::limits::read_cache_file(&path)?;
    parse_observation(&path, &data)
}

/// A frame's observed surface: the refined mesh, its vertices' reliability, and the colour
/// each vertex gets in the PLY.
pub struct Observation {
    pub mesh: TriMesh,
    pub observed: Observed,
    pub colours: Vec<[u8; 3]>,
}

impl super::Artifact for Observation {
    fn write(&self, dir: &Path, frame: u32) -> Result<Vec<String>> {
        write(dir, frame, &self.mesh, &self.observed, &self.colours)
    }
}

/// Writes a frame's observation of `mesh` into `dir`; returns the files, relative to it.
fn write(
    dir: &Path,
    frame: u32,
    mesh: &TriMesh,
    observed: &Observed,
    colours: &[[u8; 3]],
) -> Result<Vec<String>> {
    use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
    let (ply, obs) = files(frame);
    let normals: Vec<Vector3<f64>> = observed.normals.iter().map(|n| n.cast()).collect();
    let cameras: Vec<f32> = observed.cameras.iter().map(|&c| c as f32).collect();
    let attrs = VertexAttributes {
        normals: Some(&normals),
        colors: Some(colours),
        scalars: vec![
            ("quality", &observed.zncc),
            ("zncc", &observed.zncc),
            ("rho_p", &observed.rho_p),
            ("cameras", &cameras),
        ],
    };
    write_ply(&dir.join(&ply), mesh, &attrs, PlyFormat::BinaryLittleEndian)?;
    crate::fsutil::write_atomic(&dir.join(&obs), &observation_bytes(observed))?;
    Ok(vec![ply, obs])
}

/// Magic bytes of the compact observation file.
const OBS_MAGIC: &[u8; 8] = b"HPOBS001";

/// The compact little-endian form: magic, vertex count (u64), then per vertex
/// x y z nx ny nz zncc rho_p (f32) and the camera count (u8).
pub fn observation_bytes(o: &Observed) -> Vec<u8> {
    let n = o.vertices.len();
    let mut out = Vec::with_capacity(16 + 33 * n);
    out.extend_from_slice(OBS_MAGIC);
    out.extend_from_slice(&(n as u64).to_le_bytes());
    for i in 0..n {
        let v = &o.vertices[i];
        let m = &o.normals[i];
        for x in [v.x, v.y, v.z, m.x, m.y, m.z, o.zncc[i], o.rho_p[i]] {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.push(o.cameras[i]);
    }
    out
}

/// Reads what [`observation_bytes`] wrote; `path` names the file in errors.
pub fn parse_observation(path: &Path, data: &[u8]) -> Result<Observed> {
    let bad = || Error::invalid(path, "not a hullpose observation file (or truncated)");
    if data.len() < 16 || &data[..8] != OBS_MAGIC {
        return Err(bad());
    }
    let n = u64::from_le_bytes(data[8..16].try_into().unwrap());
    if n.checked_mul(33).and_then(|b| b.checked_add(16)) != Some(data.len() as u64) {
        return Err(bad());
    }
    let n = n as usize;
    let mut o = Observed {
        vertices: Vec::with_capacity(n),
        normals: Vec::with_capacity(n),
        zncc: Vec::with_capacity(n),
        rho_p: Vec::with_capacity(n),
        cameras: Vec::with_capacity(n),
    };
    for rec in data[16..].chunks_exact(33) {
        let f = |k: usize| f32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().unwrap());
        o.vertices.push(Vector3::new(f(0), f(1), f(2)));
        o.normals.push(Vector3::new(f(3), f(4), f(5)));
        o.zncc.push(f(6));
        o.rho_p.push(f(7));
        o.cameras.push(rec[32]);
    }
    Ok(o)
}
