//! Evaluation against ground truth: reconstruction accuracy and completeness per frame and
//! reconstruction stage.
//!
//! - accuracy: the distance within which 90% of the reconstructed vertices lie from the true
//!   surface (metres; the true surface is sampled every 2 mm);
//! - signed offset: each reconstructed vertex's distance to the true surface, positive
//!   outside; its median and the share of vertices outside show a surface that is too fat
//!   or too thin, which accuracy alone does not;
//! - completeness: the share of points sampled on the true surface that lie within one voxel
//!   of the reconstructed surface (both surfaces sampled every 2 mm);
//! - inside completeness (the older figure): the share of true-surface samples inside the
//!   reconstructed solid or within one voxel of it (from the stage's cached signed
//!   distance), which a reconstruction too fat by any amount passes.

use crate::artifacts::reconstruction::{self, Surface};
use crate::error::{Error, Result};
use crate::geometry::cell_grid::CellGrid;
use crate::geometry::grid::GridSpec;
use crate::geometry::nearest::{key, NearestTree};
use crate::geometry::TriMesh;
use crate::runner::Job;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::fmt::Write as _;

pub mod health_table;
pub mod holdout;
pub mod pose;
pub mod pose_search;
pub mod reliability;
pub mod tracked;

/// Points on `mesh`'s surface about `spacing` metres apart (deterministic).
pub fn sample_surface(mesh: &TriMesh, spacing: f64) -> Vec<Vector3<f64>> {
    sample_oriented(mesh, spacing).0
}

/// [`sample_surface`] with each point's triangle's unit normal (the triangles' winding
/// decides which side it points to; zero for a degenerate triangle).
pub fn sample_oriented(mesh: &TriMesh, spacing: f64) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let (mut out, mut normals) = (Vec::new(), Vec::new());
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let cross = (b - a).cross(&(c - a));
        let area = 0.5 * cross.norm();
        let normal = cross.try_normalize(1e-300).unwrap_or_else(Vector3::zeros);
        // n x n barycentric grid with ~area / spacing^2 points.
        let n = ((2.0 * area).sqrt() / spacing).ceil().max(1.0) as usize;
        for i in 0..n {
            for j in 0..n - i {
                let (u, v) = (
                    (i as f64 + 1.0 / 3.0) / n as f64,
                    (j as f64 + 1.0 / 3.0) / n as f64,
                );
                out.push(a + u * (b - a) + v * (c - a));
                normals.push(normal);
            }
        }
    }
    (out, normals)
}

/// One row of the reconstruction table.
#[derive(Debug, Clone)]
pub struct ReconRow {
    pub frame: u32,
    pub stage: &'static str,
    pub vertices: usize,
    pub score: ReconScore,
    /// The stage's voxel size, metres.
    pub voxel: f64,
}

/// How one reconstruction compares with the true surface (see the module's notes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReconScore {
    /// Metres.
    pub accuracy90: f64,
    /// Median signed distance of the reconstructed vertices to the true surface, metres,
    /// positive outside.
    pub median_offset: f64,
    /// Share of the reconstructed vertices outside the true surface, in [0, 1].
    pub outside_share: f64,
    /// Share of true-surface samples within one voxel of the reconstructed surface.
    pub completeness: f64,
    /// Share of true-surface samples inside the reconstruction or within one voxel of it.
    pub inside_completeness: f64,
}

/// Spacing of the surface samples both surfaces are measured with, metres.
pub(crate) const SAMPLE_SPACING: f64 = 0.002;

/// The true surface sampled every 2 mm with its outward normals, indexed for
/// nearest-point queries.
pub struct TruthSamples {
    pub points: Vec<Vector3<f64>>,
    index: NearestTree,
    normals: Vec<Vector3<f64>>,
}

impl TruthSamples {
    pub fn new(truth: &TriMesh) -> TruthSamples {
        let (points, normals) = sample_oriented(truth, SAMPLE_SPACING);
        TruthSamples {
            index: NearestTree::new(&points),
            points,
            normals,
        }
    }

    /// Distance from `v` to the true surface, metres, positive outside: along the nearest
    /// sample's normal when `v` lies within two sample spacings of it (where the surface is
    /// as good as its tangent plane), else the distance to that sample with the side the
    /// normal gives. Infinite for an empty truth.
    pub fn signed_distance(&self, v: &Vector3<f64>) -> f64 {
        let Some((i, d2)) = self.index.nearest(v) else {
            return f64::INFINITY;
        };
        let d = d2.sqrt();
        let along = (v - self.points[i]).dot(&self.normals[i]);
        if d <= 2.0 * SAMPLE_SPACING {
            along
        } else if along < 0.0 {
            -d
        } else {
            d
        }
    }
}

/// The value below which a share `q` of the sorted `values` lie (infinite for none).
pub(crate) fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::INFINITY;
    }
    sorted[((sorted.len() as f64 * q).ceil() as usize).clamp(1, sorted.len()) - 1]
}

/// Scores the reconstruction `recon` (with its stage's grid and signed distance) against
/// the true surface.
pub fn score(recon: &TriMesh, grid: &GridSpec, sdf: &[f32], truth: &TruthSamples) -> ReconScore {
    let mut signed: Vec<f64> = recon
        .vertices
        .par_iter()
        .map(|v| truth.signed_distance(v))
        .collect();
    let mut d: Vec<f64> = signed.iter().map(|x| x.abs()).collect();
    d.sort_by(f64::total_cmp);
    signed.sort_by(f64::total_cmp);
    let outside = signed.iter().filter(|&&x| x > 0.0).count();
    let points = &truth.points;
    let share = |n: usize| n as f64 / points.len().max(1) as f64;
    // Completeness asks only whether some sample lies within a voxel: a grid of
    // voxel-sized cells answers from the few cells that ball touches, at the first sample
    // found.
    let recon_keys: Vec<[f32; 3]> = sample_surface(recon, SAMPLE_SPACING)
        .iter()
        .map(key)
        .collect();
    let recon_cells = CellGrid::new(&recon_keys, grid.voxel);
    let near = points
        .par_iter()
        .filter(|p| recon_cells.any_within(&key(p), grid.voxel))
        .count();
    let inside = points
        .par_iter()
        .filter(|p| grid.interpolate(sdf, p, f32::INFINITY) as f64 <= grid.voxel)
        .count();
    ReconScore {
        accuracy90: quantile(&d, 0.9),
        median_offset: quantile(&signed, 0.5),
        outside_share: outside as f64 / signed.len().max(1) as f64,
        completeness: share(near),
        inside_completeness: share(inside),
    }
}

/// Reconstruction stages the evaluation knows: (stage, mesh file, grid file) per frame.
const RECON_STAGES: [Surface; 2] = [Surface::Hull, Surface::Refined];

/// Evaluates every cached reconstruction of the job's frames against the true meshes.
pub fn reconstruction(job: &Job) -> Result<Vec<ReconRow>> {
    let mut rows = Vec::new();
    let mut any_truth = false;
    for &frame in &job.frames {
        let Some(truth) = job.sequence.ground_truth_mesh(frame)? else {
            continue;
        };
        any_truth = true;
        // Sampled once per frame (when a stage is cached), scored against every stage.
        let mut index = None;
        for surface in RECON_STAGES {
            let stage = surface.stage();
            if job.cache.manifest(stage, frame).is_none() {
                continue;
            }
            let mesh = reconstruction::read_mesh(&job.cache, surface, frame)?;
            let (grid, sdf) = reconstruction::read_grid(&job.cache, surface, frame)?;
            let score = score(
                &mesh,
                &grid,
                &sdf,
                index.get_or_insert_with(|| TruthSamples::new(&truth)),
            );
            rows.push(ReconRow {
                frame,
                stage,
                vertices: mesh.vertices.len(),
                score,
                voxel: grid.voxel,
            });
        }
    }
    if !any_truth {
        return Err(Error::invalid(
            job.sequence.dir.join("ground_truth/meshes"),
            "no ground-truth meshes (NNNNNN.ply) for the selected frames; evaluation needs them",
        ));
    }
    if rows.is_empty() {
        return Err(Error::Usage(
            "no reconstruction in the cache yet: run `pipeline run` first".into(),
        ));
    }
    Ok(rows)
}

/// How well a reconstruction's mesh, projected through one camera, explains that view's
/// silhouette.
#[derive(Debug, Clone, PartialEq)]
pub struct SilhouetteAgreement {
    pub camera: String,
    /// Share of the silhouette's pixels the projected mesh covers (1 when the mesh explains
    /// every silhouette pixel; a conservative hull scores about 1 with a correct
    /// calibration).
    pub coverage: f64,
    /// Intersection over union of the silhouette and the projected mesh: coverage that also
    /// counts the pixels the mesh covers outside the silhouette (1 for perfect agreement).
    pub iou: f64,
}

/// Silhouette agreement per camera of a reconstruction stage's mesh for one frame.
pub fn reprojection_agreement(
    job: &Job,
    surface: Surface,
    frame: u32,
) -> Result<Vec<SilhouetteAgreement>> {
    let mesh = reconstruction::read_mesh(&job.cache, surface, frame)?;
    coverage_of(job, &pixel_tables(job), &mesh, frame)
}

/// Per-camera pixel tables (one undistortion per pixel: made once per evaluation).
pub(crate) fn pixel_tables(job: &Job) -> Vec<crate::geometry::raster::PixelRays> {
    job.sequence
        .cameras
        .par_iter()
        .map(crate::geometry::raster::PixelRays::new)
        .collect()
}

/// Evaluation without ground truth (real captures), per frame and reconstruction stage in
/// the cache: silhouette coverage per camera and the mean photo-consistency over seen
/// vertices. Returns the printed report and the CSV.
pub fn without_ground_truth(job: &Job) -> Result<(String, String)> {
    use crate::recon::graphcut;
    let mut report = String::new();
    let mut csv = String::from(
        "frame,stage,camera,silhouette_coverage,mean_vertex_zncc,seen_vertices,silhouette_iou\n",
    );
    let rays = pixel_tables(job);
    for &f in &job.frames {
        let frames: Vec<image::RgbImage> = (0..job.sequence.cameras.len())
            .map(|c| job.sequence.load_frame(c, f))
            .collect::<Result<_>>()?;
        let images = crate::photo::grey(&frames);
        for surface in RECON_STAGES {
            let stage = surface.stage();
            if job.cache.manifest(stage, f).is_none() {
                continue;
            }
            let mesh = reconstruction::read_mesh(&job.cache, surface, f)?;
            let grid = reconstruction::read_grid_spec(&job.cache, surface, f)?;
            let (zncc, seen) = graphcut::mean_vertex_consistency(
                &job.sequence.cameras,
                &images,
                &mesh,
                &job.config.graphcut,
                grid.voxel,
            );
            let agreement = coverage_of(job, &rays, &mesh, f)?;
            let mean = |x: &dyn Fn(&SilhouetteAgreement) -> f64| {
                agreement.iter().map(x).sum::<f64>() / agreement.len().max(1) as f64
            };
            let _ = writeln!(
                report,
                "frame {f:>4}  {stage:>12}: {} vertices, mean silhouette coverage {:.3}%, IoU {:.3}%, mean ZNCC {zncc:.3} over {seen} seen vertices",
                mesh.vertices.len(),
                mean(&|a| a.coverage) * 100.0,
                mean(&|a| a.iou) * 100.0,
            );
            for a in &agreement {
                let (cam, c, iou) = (&a.camera, a.coverage, a.iou);
                let _ = writeln!(
                    report,
                    "      {cam:>16}  coverage {:>7.3}%  IoU {:>7.3}%",
                    c * 100.0,
                    iou * 100.0
                );
                let _ = writeln!(csv, "{f},{stage},{cam},{c:.6},{zncc:.6},{seen},{iou:.6}");
            }
        }
    }
    Ok((report, csv))
}

/// Silhouette agreement per camera of `mesh` reprojected ([`SilhouetteAgreement`]).
pub(crate) fn coverage_of(
    job: &Job,
    rays: &[crate::geometry::raster::PixelRays],
    mesh: &TriMesh,
    frame: u32,
) -> Result<Vec<SilhouetteAgreement>> {
    let ctx = crate::stages::Context::new(&job.config, &job.sequence, &job.cache);
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    Ok(job
        .sequence
        .cameras
        .par_iter()
        .zip(masks.par_iter().zip(rays.par_iter()))
        .map(|(cam, (mask, rays))| agreement(cam, rays, mask, mesh))
        .collect())
}

/// How `mesh`, drawn in `cam` at full resolution, agrees with the silhouette `mask` there.
pub(crate) fn agreement(
    cam: &crate::camera::Camera,
    rays: &crate::geometry::raster::PixelRays,
    mask: &image::GrayImage,
    mesh: &TriMesh,
) -> SilhouetteAgreement {
    let frags = crate::geometry::raster::rasterize(cam, rays, &mesh.vertices, &mesh.triangles);
    let (mut sil, mut both, mut either) = (0usize, 0usize, 0usize);
    for (m, f) in mask.as_raw().iter().zip(&frags) {
        let (inside, drawn) = (*m >= 128, f.is_some());
        sil += inside as usize;
        both += (inside && drawn) as usize;
        either += (inside || drawn) as usize;
    }
    SilhouetteAgreement {
        camera: cam.name.clone(),
        coverage: both as f64 / sil.max(1) as f64,
        iou: both as f64 / either.max(1) as f64,
    }
}

/// The CSV text of reconstruction rows.
pub fn reconstruction_csv(rows: &[ReconRow]) -> String {
    let mut s = String::from(
        "frame,stage,vertices,accuracy90_m,completeness,voxel_m,median_offset_m,outside_share,inside_completeness\n",
    );
    for r in rows {
        let c = &r.score;
        let _ = writeln!(
            s,
            "{},{},{},{:.6},{:.6},{},{:.6},{:.6},{:.6}",
            r.frame,
            r.stage,
            r.vertices,
            c.accuracy90,
            c.completeness,
            r.voxel,
            c.median_offset,
            c.outside_share,
            c.inside_completeness
        );
    }
    s
}

/// A printed table of reconstruction rows.
pub fn reconstruction_table(rows: &[ReconRow]) -> String {
    let mut s = format!(
        "{:>6}  {:>12}  {:>9}  {:>13}  {:>10}  {:>8}  {:>12}  {:>7}\n",
        "frame",
        "stage",
        "vertices",
        "accuracy90 cm",
        "offset mm",
        "outside",
        "completeness",
        "inside"
    );
    for r in rows {
        let c = &r.score;
        let _ = writeln!(
            s,
            "{:>6}  {:>12}  {:>9}  {:>13.2}  {:>+10.1}  {:>7.1}%  {:>11.2}%  {:>6.1}%",
            r.frame,
            r.stage,
            r.vertices,
            c.accuracy90 * 100.0,
            c.median_offset * 1e3,
            c.outside_share * 100.0,
            c.completeness * 100.0,
            c.inside_completeness * 100.0
        );
    }
    s.push_str(
        "offset: median signed distance of the vertices to the truth (+ outside); outside: share \
         of vertices outside; completeness: true surface within a voxel of the reconstruction; \
         inside: true surface inside it or within a voxel\n",
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere of `radius` about the origin, meshed from its distance field (2 mm samples).
    fn sphere(radius: f64) -> TriMesh {
        crate::geometry::isosurface::sphere(radius, Vector3::zeros(), 0.002)
    }

    /// A reconstruction 5 mm too fat is 5 mm outside with every vertex outside, and
    /// complete within a 1 cm voxel; one 15 mm too fat is not complete, though the older
    /// inside figure still scores it 100%; one 5 mm too thin is 5 mm inside. (A vertex in
    /// ten thousand may land on the wrong side of a sample's tangent plane.)
    #[test]
    fn signed_offsets_show_a_fat_surface() {
        let truth = TruthSamples::new(&sphere(0.1));
        let grid = GridSpec::covering(Vector3::repeat(-0.15), Vector3::repeat(0.15), 0.01);
        for (radius, offset, outside, complete) in [
            (0.105, 0.005, 1.0, 1.0),
            (0.115, 0.015, 1.0, 0.0),
            (0.095, -0.005, 0.0, 1.0),
        ] {
            let recon = sphere(radius);
            // The reconstruction's own signed distance, as a stage caches it.
            let sdf: Vec<f32> = (0..grid.len())
                .map(|i| {
                    let [x, y, z] = grid.coords(i);
                    (grid.centre(x, y, z).norm() - radius) as f32
                })
                .collect();
            let s = score(&recon, &grid, &sdf, &truth);
            assert!((s.median_offset - offset).abs() < 3e-4, "{radius}: {s:?}");
            assert!((s.outside_share - outside).abs() < 1e-3, "{radius}: {s:?}");
            assert!((s.completeness - complete).abs() < 1e-9, "{radius}: {s:?}");
            assert!(
                (s.accuracy90 - offset.abs()).abs() < 1e-3,
                "{radius}: {s:?}"
            );
            assert_eq!(s.inside_completeness, 1.0, "{radius}: {s:?}");
        }
    }
}
