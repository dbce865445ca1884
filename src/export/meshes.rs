//! Every reconstruction's meshes as binary PLY or OBJ, for MeshLab, Blender and the like.
//!
//! Per selected frame: `visual_hull/NNNNNN` and `graphcut/NNNNNN` (the surfaces, coloured
//! from the input frames: per vertex the cos-weighted mean colour over the cameras that see
//! it, facing and not hidden), and with a skeleton `fit/NNNNNN` and, where the surface
//! stage ran, `surface/NNNNNN` (the posed model and the tracked surface, coloured by
//! part) plus `model` (the t0 body model). PLY carries normals, colours and a `quality` that
//! MeshLab reads as its scalar: the number of cameras seeing the vertex (hull), rho_p
//! (refined surface, with raw `zncc`, `rho_p` and `cameras` beside it when the reliability
//! is cached) and the part index (fit, model).

use crate::artifacts::reconstruction::{self, Surface};
use crate::camera::Camera;
use crate::config::Format;
use crate::error::Result;
use crate::geometry::obj::write_obj;
use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
use crate::geometry::TriMesh;
use crate::skeleton::model::BodyModel;
use crate::stages::Context;
use image::RgbImage;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::path::Path;

/// Per vertex of `mesh` (normals `normals`): the cos-weighted mean colour over the cameras
/// that see it (facing it, and not hidden behind the mesh by more than `tolerance` metres in
/// the camera's depth map, rasterized at half resolution: a quarter of the cost, and the
/// tolerance is over a voxel), and how many cameras see it. Unseen vertices are mid grey.
pub fn image_colours(
    cams: &[Camera],
    images: &[RgbImage],
    mesh: &TriMesh,
    normals: &[Vector3<f64>],
    tolerance: f64,
) -> (Vec<[u8; 3]>, Vec<f32>) {
    let coarse: Vec<Camera> = cams.iter().map(|c| c.scaled(0.5)).collect();
    let depth = crate::photo::depth_maps(&coarse, mesh);
    let centres: Vec<Vector3<f64>> = cams.iter().map(Camera::centre).collect();
    mesh.vertices
        .par_iter()
        .zip(normals.par_iter())
        .map(|(v, n)| {
            let (mut sum, mut weight, mut seen) = ([0.0f64; 3], 0.0, 0u32);
            for (c, cam) in cams.iter().enumerate() {
                let to_cam = (centres[c] - v).normalize();
                let facing = n.dot(&to_cam);
                if facing <= 0.0 {
                    continue;
                }
                let (px, z) = cam.project_with_depth(v);
                if z <= 0.0 || !cam.in_image(&px) {
                    continue;
                }
                let (w, h) = (coarse[c].width as usize, coarse[c].height as usize);
                let (qx, qy) = ((px.x + 0.5) * 0.5 - 0.5, (px.y + 0.5) * 0.5 - 0.5);
                let front = crate::photo::farthest_around(&depth[c], w, h, qx, qy);
                if z as f32 > front + tolerance as f32 {
                    continue;
                }
                let (x, y) = (px.x.round() as u32, px.y.round() as u32);
                let p = images[c].get_pixel(x.min(cam.width - 1), y.min(cam.height - 1));
                for (s, &channel) in sum.iter_mut().zip(&p.0) {
                    *s += facing * channel as f64;
                }
                weight += facing;
                seen += 1;
            }
            let colour = if weight > 0.0 {
                sum.map(|s| (s / weight).round().clamp(0.0, 255.0) as u8)
            } else {
                [128, 128, 128]
            };
            (colour, seen as f32)
        })
        .unzip()
}

/// One mesh with its normals and attributes, written in each of `formats` (PLY, OBJ) at
/// `stem` (no extension); returns the number of files.
fn write_one(
    formats: &[Format],
    stem: &Path,
    mesh: &TriMesh,
    normals: &[Vector3<f64>],
    colours: &[[u8; 3]],
    scalars: Vec<(&str, &[f32])>,
) -> Result<usize> {
    if formats.contains(&Format::Obj) {
        write_obj(
            &stem.with_extension("obj"),
            mesh,
            Some(normals),
            Some(colours),
        )?;
    }
    if formats.contains(&Format::Ply) {
        write_ply(
            &stem.with_extension("ply"),
            mesh,
            &VertexAttributes {
                normals: Some(normals),
                colors: Some(colours),
                scalars,
            },
            PlyFormat::BinaryLittleEndian,
        )?;
    }
    Ok(formats
        .iter()
        .filter(|f| matches!(f, Format::Ply | Format::Obj))
        .count())
}

/// What every frame's meshes share: the formats, the folder, the visibility tolerance and,
/// with a skeleton, the body model with its part colours and indices.
pub struct MeshExport<'a> {
    formats: Vec<Format>,
    dir: &'a Path,
    tolerance: f64,
    model: Option<BodyModel>,
    part_colours: Vec<[u8; 3]>,
    parts: Vec<f32>,
}

impl<'a> MeshExport<'a> {
    /// Prepares the export of meshes in `formats` (PLY and / or OBJ) under `dir` and writes
    /// the body model's (with a skeleton); returns it with the number of files written.
    pub fn start(
        ctx: &Context,
        formats: &[Format],
        dir: &'a Path,
        has_skeleton: bool,
    ) -> Result<(MeshExport<'a>, usize)> {
        let tolerance = ctx.config.reliability.depth_tolerance * ctx.config.visual_hull.voxel_size;
        let model = if has_skeleton {
            Some(crate::artifacts::body_model::read(ctx.cache)?)
        } else {
            None
        };
        // The model's part colours and part indices (its PLY quality), the same every frame.
        let (part_colours, parts): (Vec<[u8; 3]>, Vec<f32>) = model
            .iter()
            .flat_map(|m| &m.labels)
            .map(|&l| (crate::skeleton::model::part_colour(l), l as f32))
            .unzip();
        let mut files = 0;
        if let Some(m) = &model {
            files += write_one(
                formats,
                &dir.join("model"),
                &m.mesh,
                &m.mesh.vertex_normals(),
                &part_colours,
                vec![("quality", &parts)],
            )?;
        }
        let export = MeshExport {
            formats: formats.to_vec(),
            dir,
            tolerance,
            model,
            part_colours,
            parts,
        };
        Ok((export, files))
    }

    /// Writes one frame's meshes (`images`: its input frames, for the colours); returns the
    /// number of files.
    pub fn frame(&self, ctx: &Context, frame: u32, images: &[RgbImage]) -> Result<usize> {
        let (formats, dir, tolerance) = (&self.formats, self.dir, self.tolerance);
        let cams = &ctx.sequence.cameras;
        let mut files = 0;
        let stem = crate::dataset::frame_stem(frame);
        let hull = reconstruction::read_mesh(ctx.cache, Surface::Hull, frame)?;
        let normals = hull.vertex_normals();
        let (colours, seen) = image_colours(cams, images, &hull, &normals, tolerance);
        files += write_one(
            formats,
            &dir.join("visual_hull").join(&stem),
            &hull,
            &normals,
            &colours,
            vec![("quality", &seen)],
        )?;
        let refined = reconstruction::read_mesh(ctx.cache, Surface::Refined, frame)?;
        let normals = refined.vertex_normals();
        let (colours, seen) = image_colours(cams, images, &refined, &normals, tolerance);
        let observed = crate::artifacts::observation::read(ctx.cache, frame)
            .ok()
            .filter(|o| o.vertices.len() == refined.vertices.len());
        let scalars: Vec<(&str, &[f32])> = match &observed {
            Some(o) => vec![
                ("quality", &o.rho_p),
                ("zncc", &o.zncc),
                ("rho_p", &o.rho_p),
                ("cameras", &seen),
            ],
            None => vec![("quality", &seen)],
        };
        files += write_one(
            formats,
            &dir.join("graphcut").join(&stem),
            &refined,
            &normals,
            &colours,
            scalars,
        )?;
        if let Some(m) = &self.model {
            let pose = crate::artifacts::fitted::read_pose(ctx.cache, &m.skeleton, frame)?;
            let posed = m.pose(&pose);
            files += write_one(
                formats,
                &dir.join("fit").join(&stem),
                &posed,
                &posed.vertex_normals(),
                &self.part_colours,
                vec![("quality", &self.parts)],
            )?;
            let tracked = crate::artifacts::tracked_surface::STAGE;
            if ctx.cache.manifest(tracked, frame).is_some() {
                let surface = crate::artifacts::tracked_surface::read_mesh(ctx.cache, frame)?;
                if surface.vertices.len() == posed.vertices.len() {
                    files += write_one(
                        formats,
                        &dir.join(tracked).join(&stem),
                        &surface,
                        &surface.vertex_normals(),
                        &self.part_colours,
                        vec![("quality", &self.parts)],
                    )?;
                }
            }
        }
        Ok(files)
    }
}
