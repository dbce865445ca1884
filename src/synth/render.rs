//! Rendering a synthetic capture: the static room (ray-cast per pixel), the skinned,
//! textured subject (rasterized), a soft floor shadow, per-camera gain and offset, a slight
//! per-frame brightness flicker, and Gaussian pixel noise.

use super::texture;
use crate::camera::Camera;
use crate::geometry::raster::{self, PixelRays};
use crate::geometry::TriMesh;
use crate::rng::Rng;
use image::{GrayImage, RgbImage};
use nalgebra::Vector3;

/// Half-size of the square room around the origin, metres.
const ROOM_HALF: f64 = 7.0;
/// Ceiling height, metres.
const CEILING: f64 = 4.5;
/// Standard deviation of the pixel noise, 8-bit levels.
pub const NOISE_SIGMA: f64 = 2.0;

/// Direction towards the (distant) light.
pub fn light_dir() -> Vector3<f64> {
    Vector3::new(0.3, -0.2, 1.0).normalize()
}

/// Per-camera data that does not change over frames.
pub struct CameraView {
    pub rays: PixelRays,
    /// The room's radiance per pixel, before gain and noise (linear, [0, 1]).
    pub room: Vec<Vector3<f32>>,
    /// Floor point (x, y) seen by each pixel, if it sees the floor.
    pub floor: Vec<Option<[f32; 2]>>,
    /// Camera gain (multiplies radiance) and offset (8-bit levels).
    pub gain: f64,
    pub offset: f64,
}

impl CameraView {
    pub fn new(cam: &Camera, seed: u64, index: u64) -> CameraView {
        let rays = PixelRays::new(cam);
        let centre = cam.centre();
        let mut room = Vec::with_capacity(rays.normalized.len());
        let mut floor = Vec::with_capacity(rays.normalized.len());
        for n in &rays.normalized {
            let dir = cam.r.transpose() * Vector3::new(n.x, n.y, 1.0);
            let (p, normal) = hit_room(&centre, &dir);
            let shade = if normal.z > 0.5 { 1.0 } else { 0.85 };
            room.push((texture::room_albedo(p, normal, seed) * shade).cast::<f32>());
            floor.push((normal.z > 0.5).then_some([p.x as f32, p.y as f32]));
        }
        let mut rng = Rng::new(seed, 1_000_000 + index);
        CameraView {
            rays,
            room,
            floor,
            gain: rng.range(0.92, 1.08),
            offset: rng.range(-4.0, 4.0),
        }
    }
}

/// Where a ray from `o` along `d` meets the room (floor z = 0, walls, ceiling), and the
/// surface normal there.
fn hit_room(o: &Vector3<f64>, d: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let mut best = (f64::INFINITY, Vector3::z());
    let planes = [
        (2, 0.0, Vector3::z()),
        (2, CEILING, -Vector3::z()),
        (0, -ROOM_HALF, Vector3::x()),
        (0, ROOM_HALF, -Vector3::x()),
        (1, -ROOM_HALF, Vector3::y()),
        (1, ROOM_HALF, -Vector3::y()),
    ];
    for (axis, at, normal) in planes {
        if d[axis].abs() > 1e-12 {
            let t = (at - o[axis]) / d[axis];
            if t > 0.0 && t < best.0 {
                best = (t, normal);
            }
        }
    }
    (o + best.0 * d, best.1)
}

/// A soft shadow of the subject on the floor: the subject's vertices projected along the
/// light onto the floor, splatted on a 2 cm grid and blurred.
pub struct ShadowMap {
    cells: Vec<f32>,
    n: usize,
    half: f64,
    cell: f64,
}

impl ShadowMap {
    pub fn new(mesh: &TriMesh) -> ShadowMap {
        let (n, half) = (400usize, 4.0);
        let cell = 2.0 * half / n as f64;
        let mut cells = vec![0f32; n * n];
        let l = light_dir();
        for v in &mesh.vertices {
            let p = v - (v.z / l.z) * l;
            let (i, j) = (
                ((p.x + half) / cell) as isize,
                ((p.y + half) / cell) as isize,
            );
            if i >= 0 && j >= 0 && (i as usize) < n && (j as usize) < n {
                cells[j as usize * n + i as usize] = 1.0;
            }
        }
        // Three box blurs of radius 3 cells approximate a Gaussian penumbra of ~6 cm.
        for _ in 0..3 {
            cells = box_blur(&cells, n, 3);
        }
        ShadowMap {
            cells,
            n,
            half,
            cell,
        }
    }

    /// Light reaching floor point (x, y): 1 in full light, down to 0.55 in full shadow.
    pub fn light(&self, x: f32, y: f32) -> f32 {
        let (i, j) = (
            ((x as f64 + self.half) / self.cell) as isize,
            ((y as f64 + self.half) / self.cell) as isize,
        );
        if i < 0 || j < 0 || i as usize >= self.n || j as usize >= self.n {
            return 1.0;
        }
        let occ = (self.cells[j as usize * self.n + i as usize] * 1.5).min(1.0);
        1.0 - 0.45 * occ
    }
}

fn box_blur(src: &[f32], n: usize, r: usize) -> Vec<f32> {
    let mut tmp = vec![0f32; n * n];
    let mut out = vec![0f32; n * n];
    let norm = 1.0 / (2 * r + 1) as f32;
    for j in 0..n {
        for i in 0..n {
            let (a, b) = (i.saturating_sub(r), (i + r).min(n - 1));
            tmp[j * n + i] = src[j * n + a..=j * n + b].iter().sum::<f32>() * norm;
        }
    }
    for j in 0..n {
        for i in 0..n {
            let (a, b) = (j.saturating_sub(r), (j + r).min(n - 1));
            out[j * n + i] = (a..=b).map(|k| tmp[k * n + i]).sum::<f32>() * norm;
        }
    }
    out
}

/// Per-vertex data the subject's shading needs.
pub struct Surface<'a> {
    /// Posed mesh (world metres).
    pub mesh: &'a TriMesh,
    /// Posed unit vertex normals.
    pub normals: &'a [Vector3<f64>],
    /// Rest-pose vertex positions: the texture coordinates.
    pub rest: &'a [Vector3<f64>],
    /// 1 where a vertex wears the plain material, 0 where textured.
    pub plain: &'a [f64],
    /// What each vertex wears, under `--look person` (else the costume and `plain`).
    pub materials: Option<&'a [texture::Material]>,
    /// The head's centre (rest pose, metres) and radius (metres), where a face is drawn.
    pub head: Option<(Vector3<f64>, f64)>,
}

/// Converts radiance to 8-bit with gain, offset, flicker and noise.
fn to_u8(v: f32, gain: f64, offset: f64, rng: &mut Rng) -> u8 {
    (v as f64 * gain * 255.0 + offset + NOISE_SIGMA * rng.normal())
        .round()
        .clamp(0.0, 255.0) as u8
}

/// Renders one frame: the RGB image and the subject's mask (255 where the subject is seen).
pub fn render_frame(
    cam: &Camera,
    view: &CameraView,
    surface: &Surface,
    shadow: &ShadowMap,
    flicker: f64,
    seed: u64,
    stream: u64,
) -> (RgbImage, GrayImage) {
    let frags = raster::rasterize(
        cam,
        &view.rays,
        &surface.mesh.vertices,
        &surface.mesh.triangles,
    );
    let (w, h) = (cam.width, cam.height);
    let mut img = RgbImage::new(w, h);
    let mut mask = GrayImage::new(w, h);
    let mut rng = Rng::new(seed, stream);
    let l = light_dir();
    let gain = view.gain * flicker;
    for (i, frag) in frags.iter().enumerate() {
        let radiance: Vector3<f32> = match frag {
            Some(f) => {
                mask.as_mut()[i] = 255;
                let t = surface.mesh.triangles[f.triangle as usize].map(|k| k as usize);
                let interp = |a: &[Vector3<f64>]| -> Vector3<f64> {
                    a[t[0]] * f.bary[0] + a[t[1]] * f.bary[1] + a[t[2]] * f.bary[2]
                };
                let rest = interp(surface.rest);
                let normal = interp(surface.normals).normalize();
                let plain = surface.plain[t[0]] * f.bary[0]
                    + surface.plain[t[1]] * f.bary[1]
                    + surface.plain[t[2]] * f.bary[2];
                // A person's look: the material of the fragment's nearest vertex.
                let nearest = (0..3).max_by(|&a, &b| f.bary[a].total_cmp(&f.bary[b]));
                let albedo = if let (Some(m), Some(k)) = (surface.materials, nearest) {
                    match (m[t[k]], surface.head) {
                        (texture::Material::Head, Some((centre, r))) => {
                            texture::head_albedo(rest, (rest - centre) / r, seed)
                        }
                        (material, _) => texture::material_albedo(material, rest, seed),
                    }
                } else if plain >= 0.5 {
                    texture::plain_albedo(rest, seed)
                } else {
                    texture::subject_albedo(rest, seed)
                };
                let shade = 0.45 + 0.55 * normal.dot(&l).max(0.0);
                (albedo * shade).cast::<f32>()
            }
            None => {
                let light = view.floor[i].map_or(1.0, |[x, y]| shadow.light(x, y));
                view.room[i] * light
            }
        };
        let px = &mut img.as_mut()[3 * i..3 * i + 3];
        for k in 0..3 {
            px[k] = to_u8(radiance[k], gain, view.offset, &mut rng);
        }
    }
    (img, mask)
}

/// Renders the empty room (the background plate) with its own noise.
pub fn render_background(view: &CameraView, w: u32, h: u32, seed: u64, stream: u64) -> RgbImage {
    let mut img = RgbImage::new(w, h);
    let mut rng = Rng::new(seed, stream);
    for (px, room) in img.as_mut().chunks_exact_mut(3).zip(&view.room) {
        for (out, &v) in px.iter_mut().zip(room.iter()) {
            *out = to_u8(v, view.gain, view.offset, &mut rng);
        }
    }
    img
}
