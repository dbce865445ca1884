//! The reconstruction stages' artifact: a surface mesh (binary PLY with normals) and the
//! grid with its signed distance (`NNNNNN.ply`, `NNNNNN.grid`), for the visual hull and for
//! the graph cut's refined surface; the hull adds its solid on the cones as a band of
//! changed voxels (`NNNNNN.band`).

use crate::cache::Cache;
use crate::dataset::frame_stem;
use crate::error::{Error, Result};
use crate::geometry::grid::GridSpec;
use crate::geometry::TriMesh;
use crate::recon::visual_hull::ConeBand;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// Which reconstruction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Surface {
    /// The visual hull (stage `visual_hull`).
    Hull,
    /// The graph cut's refined surface (stage `graphcut`).
    Refined,
}

impl Surface {
    /// The stage (and its folder) that makes it.
    pub const fn stage(self) -> &'static str {
        match self {
            Surface::Hull => "visual_hull",
            Surface::Refined => "graphcut",
        }
    }
}

/// A frame's mesh, relative to the stage folder.
fn mesh_file(frame: u32) -> String {
    format!("{}.ply", frame_stem(frame))
}

/// A frame's grid, relative to the stage folder.
fn grid_file(frame: u32) -> String {
    format!("{}.grid", frame_stem(frame))
}

/// A frame's band, relative to the hull's stage folder.
fn band_file(frame: u32) -> String {
    format!("{}.band", frame_stem(frame))
}

/// Where a frame's mesh is in the cache (for messages and the tools that open it).
pub fn mesh_path(cache: &Cache, surface: Surface, frame: u32) -> PathBuf {
    cache.stage_dir(surface.stage()).join(mesh_file(frame))
}

/// Reads a frame's mesh.
pub fn read_mesh(cache: &Cache, surface: Surface, frame: u32) -> Result<TriMesh> {
    crate::geometry::ply::read_ply(&mesh_path(cache, surface, frame))
}

/// Reads a frame's grid and signed distance.
pub fn read_grid(cache: &Cache, surface: Surface, frame: u32) -> Result<(GridSpec, Vec<f32>)> {
    let path = cache.stage_dir(surface.stage()).join(grid_file(frame));
    let data = crate::limits::read_cache_file(&path)?;
    parse_grid(&path, &data)
}

/// Reads a frame's grid from its header only (no signed distance).
pub fn read_grid_spec(cache: &Cache, surface: Surface, frame: u32) -> Result<GridSpec> {
    use std::io::Read;
    let path = cache.stage_dir(surface.stage()).join(grid_file(frame));
    let mut file = crate::limits::open_regular(&path)?;
    let len = file.metadata().map_err(|e| Error::io(&path, e))?.len();
    let mut header = Vec::with_capacity(64);
    (&mut file)
        .take(64)
        .read_to_end(&mut header)
        .map_err(|e| Error::io(&path, e))?;
    parse_grid_header(&path, &header, len)
}

/// Reads the hull's solid on the cones of a frame: its stored signed distance `sdf` with
/// the band's values.
pub fn read_hull_on_cones(cache: &Cache, frame: u32, sdf: &[f32]) -> Result<Vec<f32>> {
    let path = cache
        .stage_dir(Surface::Hull.stage())
        .join(band_file(frame));
    let data = crate::limits::read_cache_file(&path)?;
    Ok(parse_band(&path, &data, sdf.len())?.applied_to(sdf))
}

/// A frame's reconstruction: its surface, its grid and signed distance, and for the hull
/// its solid on the cones.
pub struct Reconstruction {
    pub mesh: TriMesh,
    pub grid: GridSpec,
    /// Signed distance per voxel, metres (negative inside).
    pub sdf: Vec<f32>,
    /// The hull's band; `None` for the refined surface.
    pub band: Option<ConeBand>,
}

impl super::Artifact for Reconstruction {
    fn write(&self, dir: &Path, frame: u32) -> Result<Vec<String>> {
        let mut files = write(dir, frame, &self.mesh, &self.grid, &self.sdf)?;
        if let Some(band) = &self.band {
            files.push(write_band(dir, frame, band)?);
        }
        Ok(files)
    }
}

/// Writes a frame's mesh (binary PLY with normals) and grid into `dir`; returns the files,
/// relative to it.
fn write(
    dir: &Path,
    frame: u32,
    mesh: &TriMesh,
    grid: &GridSpec,
    sdf: &[f32],
) -> Result<Vec<String>> {
    use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
    let (ply, grid_name) = (mesh_file(frame), grid_file(frame));
    let normals = mesh.vertex_normals();
    let attrs = VertexAttributes {
        normals: Some(&normals),
        ..Default::default()
    };
    write_ply(&dir.join(&ply), mesh, &attrs, PlyFormat::BinaryLittleEndian)?;
    crate::fsutil::write_atomic(&dir.join(&grid_name), &grid_bytes(grid, sdf))?;
    Ok(vec![ply, grid_name])
}

/// Writes the hull's band of a frame into `dir`; returns the file, relative to it.
fn write_band(dir: &Path, frame: u32, band: &ConeBand) -> Result<String> {
    let name = band_file(frame);
    crate::fsutil::write_atomic(&dir.join(&name), &band_bytes(band))?;
    Ok(name)
}

/// Magic bytes of the band file: then the entry count (u64) and per entry the voxel index
/// (u32) and the value (f32), little-endian.
const BAND_MAGIC: &[u8; 8] = b"HPBAND01";

pub fn band_bytes(band: &ConeBand) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 + 8 * band.changed.len());
    out.extend_from_slice(BAND_MAGIC);
    out.extend_from_slice(&(band.changed.len() as u64).to_le_bytes());
    for &(i, v) in &band.changed {
        out.extend_from_slice(&i.to_le_bytes());
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Reads what [`band_bytes`] wrote, for a grid of `voxels` voxels; `path` names
/// the file in errors.
pub fn parse_band(path: &Path, data: &[u8], voxels: usize) -> Result<ConeBand> {
    let bad = |what: &str| Error::invalid(path, format!("not a hullpose band file: {what}"));
    if data.len() < 16 || &data[..8] != BAND_MAGIC {
        return Err(bad("no header (or truncated)"));
    }
    let n = u64::from_le_bytes(data[8..16].try_into().unwrap());
    if n.checked_mul(8).and_then(|b| b.checked_add(16)) != Some(data.len() as u64) {
        return Err(bad("its length does not match its entry count"));
    }
    let mut changed = Vec::with_capacity(n as usize);
    for rec in data[16..].chunks_exact(8) {
        let i = u32::from_le_bytes(rec[..4].try_into().unwrap());
        let v = f32::from_le_bytes(rec[4..].try_into().unwrap());
        if i as usize >= voxels || !v.is_finite() {
            return Err(bad("an entry outside the grid or not finite"));
        }
        changed.push((i, v));
    }
    Ok(ConeBand { changed })
}

/// Binary grid file: magic, dims, origin, voxel size, then the signed distance per voxel.
const GRID_MAGIC: &[u8; 8] = b"HPGRID01";

/// Serializes a grid and its signed distance (little-endian).
pub fn grid_bytes(grid: &GridSpec, sdf: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(64 + 4 * sdf.len());
    out.extend_from_slice(GRID_MAGIC);
    for d in grid.dims {
        out.extend_from_slice(&(d as u64).to_le_bytes());
    }
    for v in [grid.origin.x, grid.origin.y, grid.origin.z, grid.voxel] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in sdf {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// The grid of a [`grid_bytes`] file from its first 64 bytes, checked against the file's
/// length `len` in bytes.
pub fn parse_grid_header(path: &Path, header: &[u8], len: u64) -> Result<GridSpec> {
    let bad = || Error::invalid(path, "not a hullpose grid file (or truncated)");
    if header.len() < 64 || &header[..8] != GRID_MAGIC {
        return Err(bad());
    }
    let u = |o: usize| u64::from_le_bytes(header[o..o + 8].try_into().unwrap()) as usize;
    let f = |o: usize| f64::from_le_bytes(header[o..o + 8].try_into().unwrap());
    let dims = [u(8), u(16), u(24)];
    let n = dims
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(bad)?;
    if (len as u128) != 64 + 4 * n as u128 {
        return Err(bad());
    }
    Ok(GridSpec {
        dims,
        origin: Vector3::new(f(32), f(40), f(48)),
        voxel: f(56),
    })
}

/// Reads what [`grid_bytes`] wrote.
pub fn parse_grid(path: &Path, data: &[u8]) -> Result<(GridSpec, Vec<f32>)> {
    let grid = parse_grid_header(path, data, data.len() as u64)?;
    let sdf = data[64..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    Ok((grid, sdf))
}
