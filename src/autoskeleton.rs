//! `pipeline skeleton FILE`: the sequence's `skeleton.yaml` made from its reference frame's
//! reconstruction, by embedding a template ([`crate::skeleton::embed`]); with a PLY of the
//! bones and the skeleton drawn on the reference frame in every camera, to check it.

use crate::config::FrameRange;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::runner::{Job, RunOptions};
use crate::skeleton::Skeleton;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The skeleton to embed: the built-in humanoid, or a `skeleton.yaml` used as a template.
#[derive(Debug, Clone)]
pub enum Template {
    Humanoid,
    File(PathBuf),
}

impl Template {
    /// `humanoid`, or the path of a skeleton.yaml.
    pub fn parse(s: &str) -> Template {
        match s {
            "humanoid" => Template::Humanoid,
            path => Template::File(PathBuf::from(path)),
        }
    }

    fn load(&self) -> Result<Skeleton> {
        match self {
            Template::Humanoid => Ok(crate::synth::humanoid::skeleton()),
            Template::File(path) => Skeleton::read(path),
        }
    }
}

/// What `pipeline skeleton` wrote.
pub struct Written {
    pub skeleton: PathBuf,
    pub bones_ply: PathBuf,
    pub overlay: PathBuf,
    /// Seconds of the embedding alone (the reconstruction of the frame excluded).
    pub embed_seconds: f64,
    /// The frame the skeleton was embedded at.
    pub frame: u32,
    pub skeleton_value: Skeleton,
}

/// Reconstructs `frame` (default: the first of the job's frames) up to its refined
/// surface, embeds `template` in it and writes the sequence's `skeleton.yaml` (an
/// existing one only with `force`), `output/skeleton/bones.ply` and
/// `output/skeleton/overlay.png`.
pub fn make(job: &Job, template: &Template, frame: Option<u32>, force: bool) -> Result<Written> {
    let seq = &job.sequence;
    let path = seq.dir.join("skeleton.yaml");
    if path.exists() && !force {
        return Err(Error::Usage(format!(
            "{} exists; pass --force to replace it (or move it away)",
            path.display()
        )));
    }
    let up = job.config.export.up_axis.ok_or_else(|| {
        Error::Usage(
            "pipeline skeleton needs the world's up direction: set export.up_axis in \
             pipeline.yaml (for example +z or -y), so that the skeleton stands upright"
                .into(),
        )
    })?;
    let frame = frame
        .or_else(|| job.frames.first().copied())
        .ok_or_else(|| Error::Usage("the sequence has no frames to embed a skeleton in".into()))?;
    if !job.frames.contains(&frame) {
        return Err(Error::Usage(format!(
            "frame {frame} is not among the sequence's frames"
        )));
    }
    let template = template.load()?;
    let opts = RunOptions {
        only: None,
        from: None,
        until: Some("graphcut".into()),
        frames: Some(FrameRange {
            first: frame,
            last: frame,
        }),
        force: false,
    };
    crate::runner::run(job, &opts)?;
    let (ply, _) = crate::stages::hull_files(frame);
    let surface_path = job.cache.stage_dir("graphcut").join(ply);
    let surface = crate::geometry::ply::read_ply(&surface_path)?;
    let started = std::time::Instant::now();
    let mut skeleton =
        crate::skeleton::embed::embed(&template, &surface, crate::export::axes::up_vector(up))
            .map_err(|m| {
                Error::Usage(format!(
                    "pipeline skeleton: no skeleton embedded in frame {frame} ({}): {m}",
                    surface_path.display()
                ))
            })?;
    let embed_seconds = started.elapsed().as_secs_f64();
    skeleton.reference_frame = frame;
    let out = job.config.output.join("skeleton");
    crate::fsutil::create_dir_all(&out)?;
    let bones_ply = out.join("bones.ply");
    write_bones(&bones_ply, &skeleton)?;
    let overlay = out.join("overlay.png");
    write_overlay(job, frame, &skeleton, &overlay)?;
    skeleton.write(&path)?;
    Ok(Written {
        skeleton: path,
        bones_ply,
        overlay,
        embed_seconds,
        frame,
        skeleton_value: skeleton,
    })
}

/// The bones as octahedra (Blender's bone shape: widest a tenth of the way from the head,
/// a tenth of the length wide), each in its part's colour.
fn write_bones(path: &Path, skeleton: &Skeleton) -> Result<()> {
    use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
    let mut mesh = TriMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    let mut colours = Vec::new();
    for (b, bone) in skeleton.bones.iter().enumerate() {
        let axis = bone.tail - bone.head;
        let length = axis.norm();
        if length < 1e-9 {
            continue;
        }
        let u = axis / length;
        let helper = if u.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let v = u.cross(&helper).normalize() * (0.1 * length);
        let w = u.cross(&v);
        let ring = bone.head + 0.1 * axis;
        let base = mesh.vertices.len() as u32;
        mesh.vertices
            .extend([bone.head, ring + v, ring + w, ring - v, ring - w, bone.tail]);
        for k in 0..4u32 {
            let (a, c) = (base + 1 + k, base + 1 + (k + 1) % 4);
            mesh.triangles.push([base, c, a]);
            mesh.triangles.push([base + 5, a, c]);
        }
        colours.extend([crate::stages::model::part_colour(b); 6]);
    }
    write_ply(
        path,
        &mesh,
        &VertexAttributes {
            normals: None,
            colors: Some(&colours),
            scalars: Vec::new(),
        },
        PlyFormat::BinaryLittleEndian,
    )
}

/// The skeleton drawn on `frame` in every camera (with the silhouette's outline), tiled in
/// one picture.
fn write_overlay(job: &Job, frame: u32, skeleton: &Skeleton, path: &Path) -> Result<()> {
    let ctx = job.context();
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    let joints: Vec<_> = skeleton.bones.iter().map(|b| (b.head, b.tail)).collect();
    let mut tiles = Vec::new();
    let mut labels = Vec::new();
    for (c, cam) in job.sequence.cameras.iter().enumerate() {
        let image = job.sequence.load_frame(c, frame)?;
        tiles.push(crate::overlay::skeleton_on_frame(
            cam, &image, &masks[c], &joints,
        ));
        labels.push(cam.name.clone());
    }
    crate::imageio::write_rgb(path, &crate::overlay::contact_sheet(&tiles, &labels, 320))
}
