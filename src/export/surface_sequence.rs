//! The tracked surface as one animated mesh (export format `surface`): under
//! `<output>/export/surface/`, `<sequence>.obj` (the first frame's surface: the rest mesh),
//! `<sequence>.pc2` and `<sequence>.mdd` (every frame's vertex positions,
//! [`super::point_cache`]) and `<sequence>.glb` (the same sequence as morph targets,
//! [`super::gltf::morph_sequence_glb`]). All four hold the model's vertices in the same order
//! in the export frame (up +Y, the floor at Y = 0, metres), like the other animated exports.

use super::{gltf, point_cache};
use crate::artifacts::tracked_surface;
use crate::error::{Error, Result};
use crate::geometry::axes::ExportFrame;
use crate::geometry::mesh::TriMesh;
use crate::stages::Context;
use std::path::PathBuf;

/// The folder of the sequence's files under the export folder.
pub const FOLDER: &str = "surface";

/// Writes the tracked surface of `frames` (sorted) as one animated mesh under `out`, turned
/// by `frame`, timed at `frame_rate`; returns the files written and any warnings. Frames the
/// surface stage has not cached make it a warning naming the first, and nothing is written.
pub fn write(
    ctx: &Context,
    frames: &[u32],
    frame: &ExportFrame,
    frame_rate: f64,
    out: &std::path::Path,
) -> Result<(Vec<PathBuf>, Vec<String>)> {
    let stage = tracked_surface::STAGE;
    if let Some(&missing) = frames
        .iter()
        .find(|&&f| ctx.cache.manifest(stage, f).is_none())
    {
        return Ok((
            Vec::new(),
            vec![format!(
                "export: no tracked surface is cached for frame {missing}, so the surface \
                 sequence (pc2, mdd, glb) is not written: run the `{stage}` stage"
            )],
        ));
    }
    let mut rest: Option<TriMesh> = None;
    let mut positions = Vec::with_capacity(frames.len());
    for &f in frames {
        let mesh = tracked_surface::read_mesh(ctx.cache, f)?;
        let turned: Vec<[f32; 3]> = mesh
            .vertices
            .iter()
            .map(|v| {
                let p = frame.point(v);
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        match &rest {
            None => rest = Some(mesh),
            Some(r) if r.triangles != mesh.triangles => {
                return Err(Error::invalid(
                    tracked_surface::ply_path(ctx.cache, f),
                    format!(
                        "has {} vertices and {} triangles, unlike frame {}'s {} and {}: the \
                         tracked surface keeps one topology; run the `{stage}` stage again",
                        mesh.vertices.len(),
                        mesh.triangles.len(),
                        frames[0],
                        r.vertices.len(),
                        r.triangles.len()
                    ),
                ))
            }
            Some(_) => {}
        }
        positions.push(turned);
    }
    let Some(mut rest) = rest else {
        return Ok((Vec::new(), Vec::new()));
    };
    rest.vertices = positions[0]
        .iter()
        .map(|p| nalgebra::Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect();
    let dir = out.join(FOLDER);
    let name = ctx.sequence.name();
    let mut written = Vec::new();
    let mut warnings = Vec::new();
    let obj = dir.join(format!("{name}.obj"));
    crate::geometry::obj::write_obj(&obj, &rest, None, None)?;
    written.push(obj);
    let cache_bytes = positions.len() * rest.vertices.len() * 12;
    if cache_bytes > point_cache::MAX_BYTES {
        warnings.push(format!(
            "export: the surface's point caches would take {:.1} GB, over the formats' 2 GB: \
             export fewer frames (`frames:`)",
            cache_bytes as f64 / 1e9
        ));
    } else {
        let pc2 = dir.join(format!("{name}.pc2"));
        crate::fsutil::write_atomic(&pc2, &point_cache::to_pc2(&positions))?;
        let mdd = dir.join(format!("{name}.mdd"));
        crate::fsutil::write_atomic(&mdd, &point_cache::to_mdd(&positions, frame_rate))?;
        written.extend([pc2, mdd]);
    }
    let names: Vec<String> = frames.iter().map(|f| format!("frame {f:06}")).collect();
    match gltf::morph_sequence_glb(&rest.triangles, &positions, &names, frame_rate, &name) {
        Some(bytes) => {
            let glb = dir.join(format!("{name}.glb"));
            crate::fsutil::write_atomic(&glb, &bytes)?;
            written.push(glb);
        }
        None => warnings.push(
            "export: the surface sequence's glb would pass glb's 4 GiB limit and is not \
             written: export fewer frames (`frames:`), or use the point caches"
                .into(),
        ),
    }
    Ok((written, warnings))
}
