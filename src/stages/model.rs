//! Stage 5, the skin-bone body model (method.md "Stage 5"): from the reference frame's
//! refined surface (or a mesh the user supplies, e.g. a body scan posed as the skeleton at
//! t0) and skeleton.yaml, per-vertex skinning weights
//! ([`crate::skeleton::skinning::skin_weights`]) and part labels.
//!
//! Artifacts (filed under the reference frame): `model.hpm`, the compact model the fit
//! reads ([`BodyModel::to_bytes`]), and `model.ply`, the surface coloured by part with the
//! part label and the two strongest (bone, weight) pairs as extra vertex properties.

use super::{hull_files, Context, Output};
use crate::cache::KeyBuilder;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::skeleton::model::BodyModel;
use crate::skeleton::{skinning, Skeleton};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Parameters of the model stage (pipeline.yaml key `model`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelParams {
    /// The subject's true shape as a mesh (OBJ or PLY, world metres, posed as the skeleton
    /// at t0), relative to pipeline.yaml; default none: the reference frame's refined
    /// surface.
    pub mesh: Option<PathBuf>,
    /// Width of the weight blend across a joint, metres. Default 0.025.
    pub blend_width: f64,
}

impl Default for ModelParams {
    fn default() -> Self {
        ModelParams {
            mesh: None,
            blend_width: 0.025,
        }
    }
}

/// Checks parameters that do not depend on the data.
pub fn validate(p: &ModelParams) -> std::result::Result<(), String> {
    if !(p.blend_width > 0.0 && p.blend_width.is_finite()) {
        return Err(format!(
            "model.blend_width must be a positive width in metres, got {}",
            p.blend_width
        ));
    }
    Ok(())
}

/// Builds the model of `skeleton` on the reference surface `mesh`. Refuses an empty
/// surface and bones that do not lie inside it (at least two of the points at a quarter,
/// half and three quarters of the bone must be inside), naming the bone.
pub fn build(
    skeleton: &Skeleton,
    mesh: &TriMesh,
    p: &ModelParams,
) -> std::result::Result<BodyModel, String> {
    bones_inside(skeleton, mesh)?;
    let weights = skinning::skin_weights(skeleton, &mesh.vertices, p.blend_width);
    let labels = skinning::labels(&weights);
    Ok(BodyModel {
        skeleton: skeleton.clone(),
        mesh: mesh.clone(),
        weights,
        labels,
    })
}

/// Checks that every bone of `skeleton` lies inside the closed surface `mesh` (at least
/// two of the points at a quarter, half and three quarters of the bone inside); the message
/// names the first bone that does not.
pub fn bones_inside(skeleton: &Skeleton, mesh: &TriMesh) -> std::result::Result<(), String> {
    if mesh.vertices.is_empty() || mesh.triangles.is_empty() {
        return Err("the reference surface is empty".into());
    }
    for bone in &skeleton.bones {
        let inside = [0.25, 0.5, 0.75]
            .iter()
            .filter(|&&t| mesh.winding_number(&(bone.head + t * (bone.tail - bone.head))) > 0.5)
            .count();
        if inside < 2 {
            return Err(format!(
                "bone '{}' lies outside the reference surface ({} of 3 points along it inside); \
                 check skeleton.yaml's coordinates and reference_frame",
                bone.name, inside
            ));
        }
    }
    Ok(())
}

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
    let (ply, _) = hull_files(frame);
    let surface = match &ctx.config.model.mesh {
        Some(path) => Some((reference_surface(ctx, frame)?, path.clone())),
        None => ["graphcut", "visual_hull"]
            .iter()
            .filter(|stage| ctx.cache.manifest(stage, frame).is_some())
            .map(|stage| ctx.cache.stage_dir(stage).join(&ply))
            .find(|path| path.is_file())
            .map(|path| Ok::<_, Error>((crate::geometry::ply::read_ply(&path)?, path)))
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

/// A distinct colour per part.
pub fn part_colour(part: usize) -> [u8; 3] {
    const PALETTE: [[u8; 3]; 12] = [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [250, 190, 212],
        [0, 128, 128],
        [170, 110, 40],
    ];
    PALETTE[part % PALETTE.len()]
}

/// The model file's and the coloured PLY's names in the stage folder.
pub const MODEL_FILE: &str = "model.hpm";
pub const MODEL_PLY: &str = "model.ply";

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
        None => {
            let (ply, _) = hull_files(frame);
            crate::geometry::ply::read_ply(&ctx.cache.stage_dir("graphcut").join(ply))
        }
    }
}

pub(super) fn compute(ctx: &Context, frame: u32) -> Result<Output> {
    use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
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
    let dir = ctx.cache.stage_dir("model");
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
    crate::fsutil::write_atomic(&dir.join(MODEL_FILE), &model.to_bytes())?;
    Ok(Output {
        files: vec![MODEL_FILE.into(), MODEL_PLY.into()],
        warnings,
    })
}

/// Reads the cached body model.
pub fn load(ctx: &Context) -> Result<BodyModel> {
    let path = ctx.cache.stage_dir("model").join(MODEL_FILE);
    let data = crate::limits::read_cache_file(&path)?;
    BodyModel::parse(&path, &data)
}
