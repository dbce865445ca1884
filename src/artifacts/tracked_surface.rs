//! The surface stage's artifact per frame ([`crate::tracked_surface`]): `NNNNNN.ply`, the
//! tracked mesh (world metres, the body model's vertices and triangles, with normals and
//! each vertex's distance from the bare posed model as the float property `offset`,
//! metres), and `NNNNNN.track.yaml`, what tracking it did and how well the tracked surface
//! and the bare posed model explain the silhouettes (written last).

use crate::cache::Cache;
use crate::dataset::frame_stem;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::tracked_surface::TrackStats;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The stage folder's name.
pub const STAGE: &str = "surface";

/// Format of the files (bumped with any change of their fields or meaning).
/// 2: the silhouette IoU of the tracked surface and of the bare posed model.
pub const FORMAT: u32 = 2;

fn files(frame: u32) -> [String; 2] {
    let s = frame_stem(frame);
    [format!("{s}.ply"), format!("{s}.track.yaml")]
}

/// Where a frame's tracked mesh is in the cache.
pub fn ply_path(cache: &Cache, frame: u32) -> PathBuf {
    cache.stage_dir(STAGE).join(&files(frame)[0])
}

/// A tracked frame: the mesh (vertices already rounded to the file's 32-bit floats, so
/// that the next frame reads the same numbers from memory as from the cache), each
/// vertex's distance from the bare posed model, and the statistics.
pub struct TrackedSurface {
    pub mesh: TriMesh,
    pub offset: Vec<f32>,
    pub stats: TrackStats,
}

/// The statistics file's fields.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StatsFile {
    format: u32,
    frame: u32,
    vertices: usize,
    followed_share: f64,
    silhouette_pulls: usize,
    median_offset: f64,
    max_offset: f64,
    iterations: usize,
    iou_worst: f64,
    iou_worst_posed: f64,
}

/// Rounds every coordinate to a 32-bit float (as the PLY stores it).
pub fn rounded(vertices: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    vertices
        .iter()
        .map(|v| v.map(|x| x as f32 as f64))
        .collect()
}

impl super::Artifact for TrackedSurface {
    fn write(&self, dir: &Path, frame: u32) -> Result<Vec<String>> {
        use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
        let names = files(frame);
        let normals = self.mesh.vertex_normals();
        write_ply(
            &dir.join(&names[0]),
            &self.mesh,
            &VertexAttributes {
                normals: Some(&normals),
                colors: None,
                scalars: vec![("offset", &self.offset)],
            },
            PlyFormat::BinaryLittleEndian,
        )?;
        let s = &self.stats;
        let text = crate::yaml::to_string(&StatsFile {
            format: FORMAT,
            frame,
            vertices: self.mesh.vertices.len(),
            followed_share: s.followed_share,
            silhouette_pulls: s.silhouette_pulls,
            median_offset: s.median_offset,
            max_offset: s.max_offset,
            iterations: s.iterations,
            iou_worst: s.iou_worst,
            iou_worst_posed: s.iou_worst_posed,
        })?;
        crate::fsutil::write_atomic(&dir.join(&names[1]), text.as_bytes())?;
        Ok(names.to_vec())
    }
}

/// Reads a cached frame's tracked mesh.
pub fn read_mesh(cache: &Cache, frame: u32) -> Result<TriMesh> {
    crate::geometry::ply::read_ply(&ply_path(cache, frame))
}

/// Reads a cached frame's statistics.
pub fn read_stats(cache: &Cache, frame: u32) -> Result<TrackStats> {
    let path = cache.stage_dir(STAGE).join(&files(frame)[1]);
    let s: StatsFile = crate::yaml::read(&path)?;
    if s.format != FORMAT || s.frame != frame {
        return Err(Error::invalid(
            &path,
            format!(
                "holds format {} of frame {}, not format {FORMAT} of frame {frame}: run the \
                 surface stage again",
                s.format, s.frame
            ),
        ));
    }
    Ok(TrackStats {
        followed_share: s.followed_share,
        silhouette_pulls: s.silhouette_pulls,
        median_offset: s.median_offset,
        max_offset: s.max_offset,
        iterations: s.iterations,
        iou_worst: s.iou_worst,
        iou_worst_posed: s.iou_worst_posed,
    })
}
