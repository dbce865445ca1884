//! Photo-consistency refinement of a mesh along its vertex normals (the graph cut's optional
//! last step; after OpenMVS's mesh refinement, here a per-vertex search rather than a
//! gradient flow).
//!
//! Each vertex seen by at least two cameras (the reliability stage's visibility rule,
//! [`Visibility`]) is scored by the mean pair ZNCC of tangent-plane patches at shifts along
//! its normal, a quarter voxel apart, up to `search` voxels either way. The best shift is
//! placed between samples by the parabola through it and its two neighbours. It counts when
//! its score reaches `min_zncc` and it is a peak inside the range (not at its end, where the
//! true peak may lie beyond). The shifts are then regularised: `smoothing` rounds in which
//! every measured vertex takes the score-weighted mean of its own shift and its measured
//! neighbours'. Vertices without a measurement (fewer than two cameras, flat texture, no
//! peak) do not move.

use super::{depth_maps, mean_pair_zncc, GreyImage, Visibility};
use crate::camera::Camera;
use crate::geometry::TriMesh;
use rayon::prelude::*;

/// How the refinement searches and what it trusts.
#[derive(Debug, Clone, PartialEq)]
pub struct RefineSettings {
    /// Largest shift along the normal, voxels.
    pub search: f64,
    /// Lowest mean pair ZNCC of a shift that counts.
    pub min_zncc: f32,
    /// Rounds of neighbour averaging of the shifts.
    pub smoothing: usize,
    /// Patch edge, samples (odd).
    pub window: usize,
    /// Distance between patch samples on the tangent plane, voxels.
    pub patch_spacing: f64,
    /// Largest angle between the normal and the direction to a camera that sees the
    /// vertex, degrees.
    pub max_view_angle_deg: f64,
    /// How much closer than the vertex a depth map may be before it counts as hidden,
    /// voxels.
    pub depth_tolerance: f64,
    /// Gaussian smoothing of the grey images the patches are sampled in, pixels (the
    /// caller smooths them).
    pub image_sigma: f64,
}

impl RefineSettings {
    /// The reliability stage's patches and visibility, searching `search` voxels.
    pub fn with_search(search: f64) -> RefineSettings {
        RefineSettings {
            search,
            min_zncc: 0.5,
            smoothing: 3,
            window: 7,
            patch_spacing: 0.5,
            max_view_angle_deg: 60.0,
            depth_tolerance: 1.5,
            image_sigma: 0.6,
        }
    }
}

/// What a refinement did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RefineReport {
    /// Vertices seen by two or more cameras.
    pub seen: usize,
    /// Vertices moved (a shift counted).
    pub moved: usize,
    /// Mean absolute shift of the moved vertices, metres.
    pub mean_shift: f64,
}

/// Moves the vertices of `mesh` (voxel size `h` metres) along their normals to the shift of
/// best multi-view ZNCC in the smoothed grey images `images`, regularised (module doc).
pub fn refine_along_normals(
    cams: &[Camera],
    images: &[GreyImage],
    mesh: &mut TriMesh,
    h: f64,
    s: &RefineSettings,
) -> RefineReport {
    let normals = mesh.vertex_normals();
    let depth = depth_maps(cams, mesh);
    let visibility = Visibility::new(cams, &depth, s.max_view_angle_deg, s.depth_tolerance * h);
    let steps = (s.search / 0.25).floor() as i64;
    let quarter = 0.25 * h;
    let neighbours = mesh.vertex_neighbours();
    // A planar patch fits a curved surface best a little inside it, by the surface's mean
    // sag over the patch: H E[x^2] for mean curvature H (positive where convex) and
    // E[x^2] = step^2 (window^2 - 1) / 12 over the patch's sample offsets.
    let step = s.patch_spacing * h;
    let mean_square = step * step * ((s.window * s.window) as f64 - 1.0) / 12.0;
    let sag: Vec<f64> = mean_curvature(mesh, &normals, &neighbours)
        .iter()
        .map(|k| k * mean_square)
        .collect();
    // Per vertex: (shift in metres, score) when measured, and whether two cameras see it.
    let measured: Vec<(Option<(f64, f32)>, bool)> = mesh
        .vertices
        .par_iter()
        .zip(normals.par_iter())
        .map_init(
            || (Vec::new(), Vec::<f32>::new(), Vec::<f32>::new()),
            |(seen, patches, scores), (v, n)| {
                visibility.seeing(v, n, seen);
                if seen.len() < 2 || steps < 1 {
                    return (None, seen.len() >= 2);
                }
                scores.clear();
                for k in -steps..=steps {
                    let x = v + n * (k as f64 * quarter);
                    scores.push(mean_pair_zncc(
                        cams, images, seen, &x, n, s.window, step, patches,
                    ));
                }
                let (at, &best) = scores
                    .iter()
                    .enumerate()
                    .max_by(|a, b| a.1.total_cmp(b.1))
                    .expect("at least three shifts");
                if best < s.min_zncc || at == 0 || at + 1 == scores.len() {
                    return (None, true);
                }
                let (a, b, c) = (scores[at - 1], best, scores[at + 1]);
                let curvature = a - 2.0 * b + c;
                let offset = if curvature < 0.0 {
                    (0.5 * (a - c) / curvature).clamp(-0.5, 0.5)
                } else {
                    0.0
                };
                let shift = (at as f64 - steps as f64 + offset as f64) * quarter;
                (Some((shift, best)), true)
            },
        )
        .collect();
    let mut shift: Vec<Option<(f64, f32)>> = measured
        .iter()
        .zip(&sag)
        .map(|(m, sag)| m.0.map(|(d, w)| (d + sag, w)))
        .collect();
    for _ in 0..s.smoothing {
        shift = (0..shift.len())
            .into_par_iter()
            .map(|i| {
                let (own, w) = shift[i]?;
                let (mut sum, mut weight) = (own * w as f64, w as f64);
                for &j in &neighbours[i] {
                    if let Some((d, wj)) = shift[j as usize] {
                        sum += d * wj as f64;
                        weight += wj as f64;
                    }
                }
                Some((sum / weight, w))
            })
            .collect();
    }
    let mut report = RefineReport {
        seen: measured.iter().filter(|m| m.1).count(),
        ..Default::default()
    };
    let mut total = 0.0;
    for ((v, n), d) in mesh.vertices.iter_mut().zip(&normals).zip(&shift) {
        if let Some((d, _)) = d {
            *v += n * *d;
            report.moved += 1;
            total += d.abs();
        }
    }
    report.mean_shift = total / report.moved.max(1) as f64;
    report
}

/// The mean curvature at each vertex (1/m, positive where the surface is convex along its
/// outward normal), from the umbrella operator: the neighbours' mean lies H mean(e^2) / 2
/// inside a vertex whose edges have squared lengths e^2.
fn mean_curvature(
    mesh: &TriMesh,
    normals: &[nalgebra::Vector3<f64>],
    neighbours: &[Vec<u32>],
) -> Vec<f64> {
    (0..mesh.vertices.len())
        .into_par_iter()
        .map(|i| {
            let list = &neighbours[i];
            if list.is_empty() {
                return 0.0;
            }
            let v = mesh.vertices[i];
            let (mut mean, mut e2) = (nalgebra::Vector3::zeros(), 0.0);
            for &j in list {
                let d = mesh.vertices[j as usize] - v;
                mean += d;
                e2 += d.norm_squared();
            }
            let k = list.len() as f64;
            let inward = -(mean / k).dot(&normals[i]);
            2.0 * inward / (e2 / k)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Vector2, Vector3};

    /// Grey texture of the plane z = 0: a few sine waves, wavelengths 2-5 cm.
    fn texture(x: f64, y: f64) -> f64 {
        let waves = [
            (0.021, 0.3, 0.0),
            (0.033, 1.9, 1.0),
            (0.047, 0.9, 2.0),
            (0.027, 2.6, 0.5),
        ];
        let v: f64 = waves
            .iter()
            .map(|&(l, a, p): &(f64, f64, f64)| {
                (std::f64::consts::TAU / l * (x * a.cos() + y * a.sin()) + p).sin()
            })
            .sum();
        128.0 + 25.0 * v
    }

    fn render(cam: &Camera) -> GreyImage {
        let img = image::RgbImage::from_fn(cam.width, cam.height, |u, v| {
            let (c, d) = cam.ray(Vector2::new(u as f64, v as f64));
            let p = c + d * (-c.z / d.z);
            let g = texture(p.x, p.y).clamp(0.0, 255.0) as u8;
            image::Rgb([g, g, g])
        });
        GreyImage::from_rgb(&img).blurred(0.6)
    }

    /// A 20 cm square of the plane meshed at height `z`, vertices every centimetre.
    fn plane_mesh(z: f64) -> TriMesh {
        let n = 21;
        let mut m = TriMesh::default();
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (i as f64 * 0.01 - 0.1, j as f64 * 0.01 - 0.1);
                m.vertices.push(Vector3::new(x, y, z));
            }
        }
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = (j * n + i) as u32;
                let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
                m.triangles.push([a, b, d]);
                m.triangles.push([a, d, c]);
            }
        }
        m
    }

    /// A textured plane seen by four cameras, meshed 6 mm above itself (0.6 voxel): the
    /// refinement moves it back onto the plane; a vertex only one camera sees stays.
    #[test]
    fn a_plane_meshed_off_its_depth_moves_back_onto_it() {
        let cams: Vec<Camera> = (0..4)
            .map(|k| {
                let a = k as f64 * std::f64::consts::FRAC_PI_2;
                let centre = Vector3::new(0.5 * a.cos(), 0.5 * a.sin(), 0.9);
                Camera::look_at("c", 240, 240, 420.0, centre, Vector3::zeros(), Vector3::z())
            })
            .collect();
        let images: Vec<GreyImage> = cams.iter().map(render).collect();
        let mut mesh = plane_mesh(0.006);
        let report = refine_along_normals(
            &cams,
            &images,
            &mut mesh,
            0.01,
            &RefineSettings::with_search(1.0),
        );
        assert_eq!(report.seen, mesh.vertices.len());
        assert!(report.moved as f64 > 0.9 * report.seen as f64, "{report:?}");
        let mut heights: Vec<f64> = mesh.vertices.iter().map(|v| v.z).collect();
        heights.sort_by(f64::total_cmp);
        let median = heights[heights.len() / 2];
        assert!(median.abs() < 0.001, "median height {median} m");
        let p90 = heights
            .iter()
            .map(|z| z.abs())
            .filter(|&z| z > 0.002)
            .count();
        assert!(
            p90 < heights.len() / 10,
            "{p90} vertices more than 2 mm off"
        );

        // Seen by one camera only: not measured, not moved.
        let one = [cams[0].clone()];
        let mut mesh = plane_mesh(0.006);
        let report = refine_along_normals(
            &one,
            &images[..1],
            &mut mesh,
            0.01,
            &RefineSettings::with_search(1.0),
        );
        assert_eq!((report.seen, report.moved), (0, 0));
        assert!(mesh.vertices.iter().all(|v| v.z == 0.006));
    }
}
