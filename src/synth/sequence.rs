//! A capture of a given mesh sequence (`pipeline synth --meshes DIR`): any fixed-topology
//! sequence of meshes (a 4D scan, a simulation; OBJ or PLY, one file per frame) filmed by
//! the synthetic rig in the synthetic room, with its surfaces kept as the truth.
//!
//! The frames are the files of DIR whose names hold a number (`1.obj`, `frame_0042.ply`),
//! in that number's order; every one must have the first one's vertices and triangles (the
//! same topology). The meshes are in metres; `--mesh-up` names their up axis (+y, as OBJ
//! files usually have it), which becomes +z; the first frame's footprint is centred on the
//! rig's axis and its lowest point put on the floor (z = 0), the same shift for every frame.
//! The texture is the synthetic noise pattern keyed to each vertex's first-frame position,
//! so it moves with the surface. No skeleton comes with it: `pipeline skeleton` makes one.

use crate::error::{Error, Result};
use crate::geometry::axes::UpAxis;
use crate::geometry::TriMesh;
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// At most this many frames are read.
pub const MAX_FRAMES: usize = 10_000;

/// The frame files of `dir`, in the order of the numbers in their names.
pub fn frame_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut files: Vec<(u64, PathBuf)> = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        if !matches!(ext.as_deref(), Some("obj" | "ply")) || !path.is_file() {
            continue;
        }
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        let digits: String = stem
            .chars()
            .rev()
            .skip_while(|c| !c.is_ascii_digit())
            .take_while(|c| c.is_ascii_digit())
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        if let Ok(n) = digits.parse::<u64>() {
            files.push((n, path));
        }
    }
    files.sort();
    if let Some(w) = files.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(Error::invalid(
            &w[1].1,
            format!(
                "has the same frame number as {}: keep one file per frame",
                w[0].1.display()
            ),
        ));
    }
    if files.is_empty() {
        return Err(Error::invalid(
            dir,
            "holds no mesh files with a frame number in their names (1.obj, frame_0042.ply)",
        ));
    }
    Ok(files.into_iter().map(|x| x.1).collect())
}

/// Reads `frames` (all when `None`) of the sequence in `dir`, turned so that `up` becomes
/// +z and placed on the floor at the rig's centre.
pub fn read(dir: &Path, up: UpAxis, frames: Option<usize>) -> Result<Vec<TriMesh>> {
    let mut files = frame_files(dir)?;
    files.truncate(frames.unwrap_or(MAX_FRAMES).min(MAX_FRAMES));
    let meshes: Vec<TriMesh> = files
        .par_iter()
        .map(|path| {
            let is_obj = path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
            if is_obj {
                crate::geometry::obj::read_obj(path)
            } else {
                crate::geometry::ply::read_ply(path)
            }
        })
        .collect::<Result<_>>()?;
    let first = &meshes[0];
    if first.triangles.is_empty() {
        return Err(Error::invalid(&files[0], "has no triangles"));
    }
    for (mesh, path) in meshes.iter().zip(&files).skip(1) {
        if mesh.vertices.len() != first.vertices.len() || mesh.triangles != first.triangles {
            return Err(Error::invalid(
                path,
                format!(
                    "has {} vertices and {} triangles where {} has {} and {}: the sequence \
                     must keep one topology (the same vertices and triangles in every frame)",
                    mesh.vertices.len(),
                    mesh.triangles.len(),
                    files[0].display(),
                    first.vertices.len(),
                    first.triangles.len()
                ),
            ));
        }
    }
    // The smallest turn taking `up` to +z (a half turn about x for -z).
    let from = crate::geometry::axes::up_vector(up);
    let turn = Rotation3::rotation_between(&from, &Vector3::z())
        .unwrap_or_else(|| Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
    let turned: Vec<TriMesh> = meshes
        .into_iter()
        .map(|m| TriMesh {
            vertices: m.vertices.iter().map(|v| turn * v).collect(),
            triangles: m.triangles,
        })
        .collect();
    let (lo, hi) = turned[0]
        .bounds()
        .expect("a mesh with triangles has vertices");
    let extent = hi - lo;
    if !(0.2..=4.0).contains(&extent.z) {
        return Err(Error::invalid(
            &files[0],
            format!(
                "stands {:.2} m tall along --mesh-up: the meshes must be in metres (a person: \
                 1-2 m), with --mesh-up naming their up axis",
                extent.z
            ),
        ));
    }
    let shift = Vector3::new(-(lo.x + hi.x) / 2.0, -(lo.y + hi.y) / 2.0, -lo.z);
    Ok(turned
        .into_iter()
        .map(|m| TriMesh {
            vertices: m.vertices.iter().map(|v| v + shift).collect(),
            triangles: m.triangles,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frame files are ordered by their numbers (not as text), other files are left out,
    /// and a y-up sequence lands standing on the floor at the origin.
    #[test]
    fn a_sequence_is_read_in_frame_order_and_stood_on_the_floor() {
        let dir = tempfile::tempdir().unwrap();
        let tri = |dy: f64| {
            format!(
                "v 1 {} 5\nv 2 {} 5\nv 1 {} 6\nf 1 2 3\n",
                1.0 + dy,
                1.0 + dy,
                2.7 + dy
            )
        };
        std::fs::write(dir.path().join("10.obj"), tri(0.5)).unwrap();
        std::fs::write(dir.path().join("2.obj"), tri(0.0)).unwrap();
        std::fs::write(dir.path().join("notes.txt"), "x").unwrap();
        let files = frame_files(dir.path()).unwrap();
        assert!(files[0].ends_with("2.obj") && files[1].ends_with("10.obj"));
        let meshes = read(dir.path(), UpAxis::PlusY, None).unwrap();
        assert_eq!(meshes.len(), 2);
        let (lo, hi) = meshes[0].bounds().unwrap();
        assert!(lo.z.abs() < 1e-12 && (hi.z - 1.7).abs() < 1e-6, "{lo} {hi}");
        assert!((lo.x + hi.x).abs() < 1e-12 && (lo.y + hi.y).abs() < 1e-12);
        // The second frame keeps its own motion: 0.5 m higher.
        let (lo2, _) = meshes[1].bounds().unwrap();
        assert!((lo2.z - 0.5).abs() < 1e-6);
        // A frame with another topology is refused by name.
        std::fs::write(
            dir.path().join("11.obj"),
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n",
        )
        .unwrap();
        let err = read(dir.path(), UpAxis::PlusY, None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("11.obj") && err.contains("one topology"),
            "{err}"
        );
    }
}
