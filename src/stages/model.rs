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
use crate::skeleton::model::{bones_inside, build, part_colour, BodyModel};
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
