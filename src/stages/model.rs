//! Stage 5, the skin-bone body model (method.md "Stage 5"): from the reference frame's
//! refined surface (or a mesh the user supplies, e.g. a body scan posed as the skeleton at
//! t0) and skeleton.yaml, per-vertex skinning weights
//! ([`crate::skeleton::skinning::skin_weights`]) and part labels.
//!
//! Artifacts (filed under the reference frame): `model.hpm`, the compact model the fit
//! reads ([`BodyModel::to_bytes`]), and `model.ply`, the surface coloured by part with the
//! part label and the two strongest (bone, weight) pairs as extra vertex properties.

use super::{Context, Output};
use crate::artifacts::reconstruction::{self, Surface};
use crate::cache::KeyBuilder;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::skeleton::model::{bones_inside, build};
use crate::skeleton::Skeleton;

/// `pipeline check`'s test of skeleton.yaml against the reference frame's surface, when it
/// is at hand (`model.mesh`, or the reference frame's refined surface or hull in the
/// cache): a line saying which surface every bone lies inside, `None` when no surface is
/// at hand yet, an error naming the bone otherwise.
pub fn check_skeleton(ctx: &Context) -> Result<Option<String>> {
    let Some(skeleton) = ctx.sequence.skeleton()? else {
        return Ok(None);
    };
    let skeleton_path = ctx.sequence.dir.join("skeleton.yaml");
    let frame = skeleton.reference_frame;
    let surface = match &ctx.config.model.mesh {
        Some(path) => Some((reference_surface(ctx, frame)?, path.clone())),
        None => [Surface::Refined, Surface::Hull]
            .into_iter()
            .filter(|s| ctx.cache.manifest(s.stage(), frame).is_some())
            .find(|&s| reconstruction::mesh_path(ctx.cache, s, frame).is_file())
            .map(|s| {
                Ok::<_, Error>((
                    reconstruction::read_mesh(ctx.cache, s, frame)?,
                    reconstruction::mesh_path(ctx.cache, s, frame),
                ))
            })
            .transpose()?,
    };
    let Some((mesh, path)) = surface else {
        return Ok(None);
    };
    bones_inside(&skeleton, &mesh).map_err(|m| {
        Error::invalid(
            &skeleton_path,
            format!("{m} (tested against {})", path.display()),
        )
    })?;
    Ok(Some(format!(
        "every bone lies inside the reference frame's surface ({})",
        path.display()
    )))
}

pub(super) fn sources(ctx: &Context, _frame: u32, key: &mut KeyBuilder) -> Result<()> {
    key.add_file(&ctx.sequence.dir.join("skeleton.yaml"))?;
    if let Some(mesh) = &ctx.config.model.mesh {
        key.add_file(mesh)?;
    }
    Ok(())
}

/// Reads the reference surface: the user's mesh (OBJ or PLY) or the refined surface.
fn reference_surface(ctx: &Context, frame: u32) -> Result<TriMesh> {
    match &ctx.config.model.mesh {
        Some(path) => {
            let ext = path
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase);
            match ext.as_deref() {
                Some("obj") => crate::geometry::obj::read_obj(path),
                Some("ply") => crate::geometry::ply::read_ply(path),
                _ => Err(Error::invalid(
                    &ctx.config.path,
                    format!(
                        "model.mesh: {} must be an .obj or .ply file",
                        path.display()
                    ),
                )),
            }
        }
        None => reconstruction::read_mesh(ctx.cache, Surface::Refined, frame),
    }
}

pub(super) fn compute(ctx: &Context, frame: u32) -> Result<Output> {
    let skeleton_path = ctx.sequence.dir.join("skeleton.yaml");
    let skeleton = Skeleton::read(&skeleton_path)?;
    let mesh = reference_surface(ctx, frame)?;
    let mut warnings = Vec::new();
    if !mesh.is_watertight() {
        warnings.push(
            "model: the reference surface is not closed; inside tests and normals may be off"
                .to_string(),
        );
    }
    let model = build(&skeleton, &mesh, &ctx.config.model).map_err(|m| {
        let source = ctx
            .config
            .model
            .mesh
            .clone()
            .unwrap_or_else(|| skeleton_path.clone());
        let m = if mesh.vertices.is_empty() {
            format!("{m}: {}", super::why_hull_is_empty(ctx, frame))
        } else {
            m
        };
        Error::invalid(&source, format!("model (reference frame {frame}): {m}"))
    })?;
    let files = crate::artifacts::body_model::write(
        &ctx.cache.stage_dir(crate::artifacts::body_model::STAGE),
        &model,
    )?;
    Ok(Output { files, warnings })
}
