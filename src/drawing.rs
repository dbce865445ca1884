//! Pictures of results for people: a reconstruction rendered through a capture camera
//! beside the frame it explains.

use crate::artifacts::reconstruction::Surface;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::runner::Job;
use image::{GrayImage, Rgb, RgbImage};
use nalgebra::{Vector2, Vector3};

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
    let fg = |x: i64, y: i64| foreground(mask, x, y);
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let (xi, yi) = (x as i64, y as i64);
            let edge = silhouette_edge(mask, xi, yi);
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

/// Whether pixel (x, y) of `mask` is foreground (outside the image: no).
fn foreground(mask: &GrayImage, x: i64, y: i64) -> bool {
    x >= 0
        && y >= 0
        && x < mask.width() as i64
        && y < mask.height() as i64
        && mask.get_pixel(x as u32, y as u32).0[0] >= 128
}

/// Whether pixel (x, y) is on the silhouette's outline: foreground with a 4-neighbour that
/// is not.
pub fn silhouette_edge(mask: &GrayImage, x: i64, y: i64) -> bool {
    let fg = |x, y| foreground(mask, x, y);
    fg(x, y) && !(fg(x - 1, y) && fg(x + 1, y) && fg(x, y - 1) && fg(x, y + 1))
}

/// Paints a disc of `radius` pixels centred at `p`.
fn disc(img: &mut RgbImage, p: Vector2<f64>, radius: f64, colour: [u8; 3]) {
    let r = radius.ceil() as i64;
    let (cx, cy) = (p.x.round() as i64, p.y.round() as i64);
    for y in cy - r..=cy + r {
        for x in cx - r..=cx + r {
            let inside = ((x - cx).pow(2) + (y - cy).pow(2)) as f64 <= radius * radius;
            if inside && x >= 0 && y >= 0 && x < img.width() as i64 && y < img.height() as i64 {
                img.put_pixel(x as u32, y as u32, Rgb(colour));
            }
        }
    }
}

/// Paints a segment of half-width `radius` from a to b.
fn segment(img: &mut RgbImage, a: Vector2<f64>, b: Vector2<f64>, radius: f64, colour: [u8; 3]) {
    let steps = ((b - a).norm().ceil() as usize).clamp(1, 100_000);
    for k in 0..=steps {
        disc(img, a + (b - a) * (k as f64 / steps as f64), radius, colour);
    }
}

/// The frame seen by `cam` with the silhouette's outline in green and the skeleton's bones
/// (`joints`: posed (head, tail) per bone, world metres) projected on it, each bone in its
/// part's colour over a black rim, joints as white dots. Bones behind the camera are left
/// out.
pub fn skeleton_on_frame(
    cam: &Camera,
    frame: &RgbImage,
    mask: &GrayImage,
    joints: &[(Vector3<f64>, Vector3<f64>)],
) -> RgbImage {
    let mut out = frame.clone();
    for y in 0..out.height() {
        for x in 0..out.width() {
            if silhouette_edge(mask, x as i64, y as i64) {
                out.put_pixel(x, y, Rgb([0, 255, 0]));
            }
        }
    }
    // Line half-width: about 1/300 of the image's width, at least one pixel.
    let r = (cam.width as f64 / 300.0).max(1.0);
    let projected: Vec<Option<(Vector2<f64>, Vector2<f64>)>> = joints
        .iter()
        .map(|(h, t)| Some((cam.project(h)?, cam.project(t)?)))
        .collect();
    for (b, p) in projected.iter().enumerate() {
        if let Some((h, t)) = p {
            segment(&mut out, *h, *t, r + 1.0, [0, 0, 0]);
            segment(&mut out, *h, *t, r, crate::skeleton::model::part_colour(b));
        }
    }
    for (h, t) in projected.iter().flatten() {
        for p in [h, t] {
            disc(&mut out, *p, r + 2.0, [0, 0, 0]);
            disc(&mut out, *p, r + 1.0, [255, 255, 255]);
        }
    }
    out
}

/// Tiles `images` (with their `labels`) into one picture, `columns` per row, each shrunk to
/// about `tile_width` pixels wide by an integer factor (box-averaged: cheap, and sharp
/// enough for a sheet).
pub fn contact_sheet(images: &[RgbImage], labels: &[String], tile_width: u32) -> RgbImage {
    let n = images.len().max(1);
    let columns = (n as f64).sqrt().ceil() as u32;
    let rows = (n as u32).div_ceil(columns);
    let (w0, h0) = images.first().map_or((1, 1), |i| (i.width(), i.height()));
    let factor = ((w0 as f64 / tile_width as f64).round() as u32).max(1);
    let (tile_width, tile_height) = ((w0 / factor).max(1), (h0 / factor).max(1));
    let gap = 4;
    let mut sheet = RgbImage::from_pixel(
        columns * (tile_width + gap) + gap,
        rows * (tile_height + gap) + gap,
        Rgb([32, 32, 32]),
    );
    for (i, (img, label)) in images.iter().zip(labels).enumerate() {
        let tile = shrink(img, factor);
        let (col, row) = (i as u32 % columns, i as u32 / columns);
        let (x, y) = (
            gap + col * (tile_width + gap),
            gap + row * (tile_height + gap),
        );
        image::imageops::replace(&mut sheet, &tile, x as i64, y as i64);
        crate::plot::text(
            &mut sheet,
            x as i64 + 4,
            y as i64 + 4,
            label,
            [255, 255, 255],
        );
    }
    sheet
}

/// `img` shrunk by an integer `factor`: each pixel the mean of a `factor` x `factor` block
/// (a partial block at the right and bottom edges is dropped).
pub fn shrink(img: &RgbImage, factor: u32) -> RgbImage {
    let f = factor.max(1);
    let (w, h) = ((img.width() / f).max(1), (img.height() / f).max(1));
    let count = (f * f).min(img.width() * img.height()).max(1);
    RgbImage::from_fn(w, h, |x, y| {
        let mut sum = [0u32; 3];
        for dy in 0..f.min(img.height()) {
            for dx in 0..f.min(img.width()) {
                let p = img.get_pixel(x * f + dx, y * f + dy).0;
                for (s, v) in sum.iter_mut().zip(p) {
                    *s += v as u32;
                }
            }
        }
        Rgb(sum.map(|s| ((s + count / 2) / count) as u8))
    })
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
        Some(name) => seq.camera_index(&job.config.calibration, name)?,
    };
    let ctx = crate::stages::Context::new(&job.config, seq, &job.cache);
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    let surface = if stage == "graphcut" {
        Surface::Refined
    } else {
        Surface::Hull
    };
    let mesh = crate::artifacts::reconstruction::read_mesh(&job.cache, surface, frame)?;
    Ok(mesh_beside_frame(
        &seq.cameras[c],
        &seq.load_frame(c, frame)?,
        &masks[c],
        &mesh,
    ))
}
