//! Stage 5, the skin-bone body model (method.md "Stage 5"): from the reference frame's
//! refined surface (or a mesh the user supplies, e.g. a body scan posed as the skeleton at
//! t0) and skeleton.yaml, per-vertex skinning weights
//! ([`crate::skeleton::skinning::skin_weights`]) and part labels.
//!
//! Artifacts (filed under the reference frame): `model.hpm`, the compact model the fit
//! reads ([`crate::artifacts::body_model`]), and `model.ply`, the surface coloured by part with the
//! part label and the two strongest (bone, weight) pairs as extra vertex properties.

use super::{Context, Inputs, PerFrame, Produced};
use crate::artifacts::reconstruction::{self, Surface};
use crate::cache::KeyBuilder;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::skeleton::model::{bones_inside, build, ModelParams};
use crate::skeleton::Skeleton;
use serde::Serialize;
use std::path::{Path, PathBuf};

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
        Some(path) => Some((read_given_mesh(path, &ctx.config.path)?, path.clone())),
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

/// Reads the user's mesh (OBJ or PLY); `config_path` names pipeline.yaml in errors.
fn read_given_mesh(path: &Path, config_path: &Path) -> Result<TriMesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("obj") => crate::geometry::obj::read_obj(path),
        Some("ply") => crate::geometry::ply::read_ply(path),
        _ => Err(Error::invalid(
            config_path,
            format!(
                "model.mesh: {} must be an .obj or .ply file",
                path.display()
            ),
        )),
    }
}

/// What the stage reads besides skeleton.yaml and the reference surface.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    /// Width of the weight blend across a joint, metres.
    pub blend_width: f64,
    /// The user's mesh, when given: its content is in the key (the stage's sources), its
    /// path is not.
    #[serde(serialize_with = "given")]
    pub mesh: Option<PathBuf>,
}

/// Serializes a path as whether it is given.
fn given<S: serde::Serializer>(
    mesh: &Option<PathBuf>,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_bool(mesh.is_some())
}

/// The stage.
pub static STAGE: PerFrame<Settings> = PerFrame { resolve, compute };

fn resolve(config: &Config, _sequence: &Sequence) -> Result<Settings> {
    Ok(Settings {
        blend_width: config.model.blend_width,
        mesh: config.model.mesh.clone(),
    })
}

fn compute(s: &Settings, inputs: &Inputs, frame: u32) -> Result<Produced> {
    let skeleton_path = inputs.sequence.dir.join("skeleton.yaml");
    let skeleton = Skeleton::read(&skeleton_path)?;
    let mesh = match &s.mesh {
        Some(path) => read_given_mesh(path, inputs.config_path)?,
        None => inputs.mesh(Surface::Refined, frame)?,
    };
    let mut warnings = Vec::new();
    if !mesh.is_watertight() {
        warnings.push(
            "model: the reference surface is not closed; inside tests and normals may be off"
                .to_string(),
        );
    }
    let params = ModelParams {
        mesh: s.mesh.clone(),
        blend_width: s.blend_width,
    };
    let model = build(&skeleton, &mesh, &params).map_err(|m| {
        let source = s.mesh.clone().unwrap_or_else(|| skeleton_path.clone());
        let m = if mesh.vertices.is_empty() {
            format!(
                "{m}: {}",
                super::why_hull_is_empty(&inputs.sequence.cameras, inputs.silhouettes(frame))
            )
        } else {
            m.0
        };
        Error::invalid(&source, format!("model (reference frame {frame}): {m}"))
    })?;
    Ok(Produced::new(model, warnings))
}
