//! Exports for other tools: the skinned model and its motion as glTF 2.0 binary (.glb), the
//! motion as BVH, the joints as markers (TRC, C3D), every reconstruction's meshes as PLY
//! and OBJ, and overlay pictures of the fitted skeleton on the input frames. All are written from the cache, nothing is
//! recomputed: `pipeline run` writes them after the fit (stage `export`), and
//! `pipeline export FILE --format F` rewrites one format from what the cache holds.
//!
//! Layout under `<output>/export/`: `<sequence>.glb`, `<sequence>.bvh`, `<sequence>.trc`,
//! `<sequence>.c3d` and `world.yaml` (how they place the world: [`export_frame`]),
//! `meshes/<stage>/NNNNNN.{ply,obj}` (stages visual_hull, graphcut, fit, surface) and
//! `meshes/model.{ply,obj}`, `overlays/<camera>/NNNNNN.png`, `contact_sheets/NNNNNN.png`
//! and `surface/<sequence>.{obj,pc2,mdd,glb}` (the tracked surface as one animated mesh:
//! [`surface_sequence`]).

pub mod bvh;
pub mod gltf;
pub mod markers;
pub mod meshes;
pub mod overlays;
pub mod point_cache;
pub mod surface_sequence;

use crate::config::Format;
use crate::error::{Error, Result};
use crate::skeleton::model::BodyModel;
use crate::skeleton::Pose;
use crate::stages::{Context, Finished};
use rayon::prelude::*;
use std::path::PathBuf;

/// The export folder of a job.
pub fn folder(job_output: &std::path::Path) -> PathBuf {
    job_output.join("export")
}

/// The fitted motion of the selected frames, from the fit's cache: the model and
/// (frame, pose) in frame order.
pub fn load_motion(ctx: &Context, frames: &[u32]) -> Result<(BodyModel, Vec<(u32, Pose)>)> {
    let model = crate::artifacts::body_model::read(ctx.cache)?;
    let mut frames = frames.to_vec();
    frames.sort_unstable();
    let poses = frames
        .iter()
        .map(|&f| {
            Ok((
                f,
                crate::artifacts::fitted::read_pose(ctx.cache, &model.skeleton, f)?,
            ))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((model, poses))
}

/// How the exports place the world (up to +Y, the floor at 0) for `model` moved by `poses`:
/// the up from pipeline.yaml or found from the cameras, the floor from `world.floor` or the
/// lowest point of the posed model over the frames. The second value says which, for the
/// summary.
pub fn export_frame(
    ctx: &Context,
    model: &BodyModel,
    poses: &[(u32, Pose)],
) -> (crate::geometry::axes::ExportFrame, String) {
    use crate::geometry::axes::ExportFrame;
    let (up, whose) = match ctx.config.given_up() {
        Some(up) => (up, "given"),
        None => match crate::geometry::up::estimate(&ctx.sequence.cameras, None) {
            Some(e) => (e.up, "found from the cameras"),
            None => return (ExportFrame::identity(), "axes unchanged".into()),
        },
    };
    let (floor, how) = match ctx.config.world.floor {
        Some(f) => (f, "given"),
        None => (
            poses
                .par_iter()
                .map(|(_, pose)| {
                    model
                        .pose(pose)
                        .vertices
                        .iter()
                        .map(|v| up.dot(v))
                        .fold(f64::INFINITY, f64::min)
                })
                .reduce(|| f64::INFINITY, f64::min),
            "the lowest point of the posed model",
        ),
    };
    let floor = if floor.is_finite() { floor } else { 0.0 };
    let about = format!(
        "up ({:+.3}, {:+.3}, {:+.3}) {whose} -> +Y; floor {floor:.3} m along it ({how}) -> Y = 0",
        up.x, up.y, up.z
    );
    (ExportFrame::new(&up, floor), about)
}

/// `pipeline export`: checks that the cache holds what the exports read, up to date for the
/// job's frames (else an error says what to run), then writes `formats`.
pub fn from_cache(job: &crate::runner::Job, formats: &[Format]) -> Result<Finished> {
    let mut stages = vec!["visual_hull", "graphcut"];
    if job.sequence.skeleton()?.is_some() {
        stages.extend(["model", "fit"]);
        if formats.contains(&Format::Surface) {
            stages.push(crate::artifacts::tracked_surface::STAGE);
        }
    }
    job.require_cached(&stages)?;
    run(&job.context(), &job.frames, formats)
}

/// Writes `formats` for `frames` from the cache (which must hold them: `pipeline run` exports
/// after the stages it reads, and [`from_cache`] checks first).
pub fn run(ctx: &Context, frames: &[u32], formats: &[Format]) -> Result<Finished> {
    let mut written = Finished::default();
    let has_skeleton = ctx.sequence.skeleton()?.is_some();
    let out = folder(&ctx.config.output);
    let p = &ctx.config.export;
    let mut formats = formats.to_vec();
    formats.sort_by_key(|f| Format::ALL.iter().position(|g| g == f));
    formats.dedup();
    if !has_skeleton && formats.iter().any(|f| f.needs_motion()) {
        written.warnings.push(format!(
            "export: {} has no skeleton.yaml, so there is no motion to export as glb, bvh or overlays",
            ctx.sequence.dir.display()
        ));
        formats.retain(|f| !f.needs_motion());
    }
    let motion = if formats.iter().any(|f| f.needs_motion()) {
        Some(load_motion(ctx, frames)?)
    } else {
        None
    };
    let name = ctx.sequence.name();
    // Meshes (PLY, OBJ) and overlays are written frame by frame, decoding each frame's
    // images once for both.
    let mesh_formats: Vec<Format> = formats
        .iter()
        .copied()
        .filter(|f| matches!(f, Format::Ply | Format::Obj))
        .collect();
    let meshes_dir = out.join("meshes");
    let overlays_dir = out.join("overlays");
    let meshes = if mesh_formats.is_empty() {
        None
    } else {
        let (export, files) =
            meshes::MeshExport::start(ctx, &mesh_formats, &meshes_dir, has_skeleton)?;
        written.files += files;
        written.outputs.push(meshes_dir.clone());
        Some(export)
    };
    let overlays = match (&motion, formats.contains(&Format::Overlay)) {
        (Some((model, poses)), true) => {
            written.outputs.push(overlays_dir.clone());
            Some((model, poses, overlays::chosen_cameras(ctx)?))
        }
        _ => None,
    };
    if meshes.is_some() || overlays.is_some() {
        let per_frame = frames.par_iter().map(|&frame| -> Result<usize> {
            let images: Vec<image::RgbImage> = (0..ctx.sequence.cameras.len())
                .into_par_iter()
                .map(|c| ctx.sequence.load_frame(c, frame))
                .collect::<Result<_>>()?;
            let mut files = 0;
            if let Some(export) = &meshes {
                files += export.frame(ctx, frame, &images)?;
            }
            if let Some((model, poses, chosen)) = &overlays {
                if let Some((_, pose)) = poses.iter().find(|(f, _)| *f == frame) {
                    let item = (frame, pose);
                    files += overlays::frame(ctx, model, item, &images, chosen, &overlays_dir)?;
                }
            }
            Ok(files)
        });
        written.files += per_frame
            .collect::<Result<Vec<usize>>>()?
            .iter()
            .sum::<usize>();
    }
    let animation_rate = p.frame_rate.unwrap_or(crate::config::ANIMATION_RATE);
    if p.frame_rate.is_none() && formats.iter().any(|f| f.is_timed()) {
        written.warnings.push(format!(
            "export.frame_rate is unset: glb, bvh, trc and c3d are timed at {} frames per \
             second (set it to the capture's rate)",
            crate::config::ANIMATION_RATE
        ));
    }
    // The one-file formats of the motion: each file's name and bytes, in the export frame.
    let frame = match motion.as_ref() {
        Some((model, poses)) if formats.iter().any(|f| f.is_timed()) => {
            let (frame, about) = export_frame(ctx, model, poses);
            println!("export: {about}");
            let path = out.join("world.yaml");
            crate::fsutil::write_atomic(&path, crate::yaml::to_string(&frame)?.as_bytes())?;
            written.outputs.push(path);
            written.files += 1;
            Some(frame)
        }
        _ => None,
    };
    for &format in &formats {
        let (Some((model, poses)), Some(frame)) = (motion.as_ref(), frame.as_ref()) else {
            continue;
        };
        if format == Format::Surface {
            let frames: Vec<u32> = poses.iter().map(|(f, _)| *f).collect();
            let (files, warnings) =
                surface_sequence::write(ctx, &frames, frame, animation_rate, &out)?;
            written.files += files.len();
            if !files.is_empty() {
                written.outputs.push(out.join(surface_sequence::FOLDER));
            }
            written.warnings.extend(warnings);
            continue;
        }
        let (path, bytes) = match format {
            Format::Glb => {
                let path = out.join(format!("{name}.glb"));
                let bytes = gltf::to_glb(model, poses, animation_rate, frame, &name);
                (path, bytes)
            }
            Format::Bvh => {
                let order = crate::geometry::axes::RotationOrder::parse(&p.bvh_rotation_order)
                    .map_err(|m| Error::invalid(&ctx.config.path, m))?;
                let text = bvh::to_bvh(&model.skeleton, poses, animation_rate, frame, order);
                (out.join(format!("{name}.bvh")), text.into_bytes())
            }
            Format::Trc => {
                let file = format!("{name}.trc");
                let text = markers::to_trc(&file, &model.skeleton, poses, animation_rate, frame);
                (out.join(file), text.into_bytes())
            }
            Format::C3d => {
                let path = out.join(format!("{name}.c3d"));
                let bytes = markers::to_c3d(&model.skeleton, poses, animation_rate, frame)
                    .map_err(|m| Error::invalid(&path, m))?;
                (path, bytes)
            }
            Format::Ply | Format::Obj | Format::Overlay | Format::Surface => continue,
        };
        crate::fsutil::write_atomic(&path, &bytes)?;
        written.outputs.push(path);
        written.files += 1;
    }
    written.outputs.dedup();
    Ok(written)
}

/// Refuses, before any stage runs, an export `export.formats` asks for that could not be
/// written for `job` (a C3D past its marker or frame limits), so that a run never fails
/// after the other exports are written.
pub fn check_formats(job: &crate::runner::Job) -> Result<()> {
    if job.config.export.formats.contains(&Format::C3d) {
        if let (Some(skeleton), Some(&first), Some(&last)) = (
            job.sequence.skeleton()?,
            job.frames.first(),
            job.frames.last(),
        ) {
            markers::check_c3d(&skeleton, first, last)
                .map_err(|m| Error::invalid(&job.config.path, m))?;
        }
    }
    Ok(())
}
