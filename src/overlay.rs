//! Pictures of results for people: a reconstruction rendered through a capture camera
//! beside the frame it explains.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::runner::Job;
use image::{GrayImage, Rgb, RgbImage};

/// The frame with the silhouette's outline in green (left) beside `mesh` rendered through
/// `cam` with grey Lambert shading lit from the camera, silhouette pixels the mesh misses
/// in red (right).
pub fn mesh_beside_frame(
    cam: &Camera,
    frame: &RgbImage,
    mask: &GrayImage,
    mesh: &TriMesh,
) -> RgbImage {
    let (w, h) = (cam.width, cam.height);
    let rays = crate::geometry::raster::PixelRays::new(cam);
    let frags = crate::geometry::raster::rasterize(cam, &rays, &mesh.vertices, &mesh.triangles);
    let normals = mesh.vertex_normals();
    let centre = cam.centre();
    let mut out = RgbImage::new(2 * w, h);
    let fg = |x: i64, y: i64| {
        x >= 0
            && y >= 0
            && x < w as i64
            && y < h as i64
            && mask.get_pixel(x as u32, y as u32).0[0] >= 128
    };
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let (xi, yi) = (x as i64, y as i64);
            let edge = fg(xi, yi)
                && !(fg(xi - 1, yi) && fg(xi + 1, yi) && fg(xi, yi - 1) && fg(xi, yi + 1));
            out.put_pixel(
                x,
                y,
                if edge {
                    Rgb([0, 255, 0])
                } else {
                    *frame.get_pixel(x, y)
                },
            );
            let right = match &frags[i] {
                Some(f) => {
                    let t = mesh.triangles[f.triangle as usize].map(|k| k as usize);
                    let n = (normals[t[0]] * f.bary[0]
                        + normals[t[1]] * f.bary[1]
                        + normals[t[2]] * f.bary[2])
                        .normalize();
                    let p = mesh.vertices[t[0]] * f.bary[0]
                        + mesh.vertices[t[1]] * f.bary[1]
                        + mesh.vertices[t[2]] * f.bary[2];
                    let shade = 40.0 + 200.0 * n.dot(&(centre - p).normalize()).abs();
                    Rgb([shade as u8; 3])
                }
                None if fg(xi, yi) => Rgb([220, 40, 40]),
                None => Rgb([0, 0, 0]),
            };
            out.put_pixel(w + x, y, right);
        }
    }
    out
}

/// [`mesh_beside_frame`] for a job's cached reconstruction (`stage`: visual_hull or graphcut)
/// of `frame`, through the camera named `camera` (the first camera when `None`).
pub fn hull_beside_frame(
    job: &Job,
    stage: &str,
    frame: u32,
    camera: Option<&str>,
) -> Result<RgbImage> {
    if !["visual_hull", "graphcut"].contains(&stage) {
        return Err(Error::Usage(format!(
            "--stage must be visual_hull or graphcut, not '{stage}'"
        )));
    }
    let seq = &job.sequence;
    let c = match camera {
        None => 0,
        Some(name) => seq
            .cameras
            .iter()
            .position(|c| c.name == name)
            .ok_or_else(|| {
                Error::Usage(format!(
                    "no camera named '{name}' in {}",
                    job.config.calibration.display()
                ))
            })?,
    };
    let ctx = crate::stages::Context::new(&job.config, seq, &job.cache);
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    let (ply, _) = crate::stages::hull_files(frame);
    let mesh = crate::geometry::ply::read_ply(&job.cache.stage_dir(stage).join(ply))?;
    Ok(mesh_beside_frame(
        &seq.cameras[c],
        &seq.load_frame(c, frame)?,
        &masks[c],
        &mesh,
    ))
}
