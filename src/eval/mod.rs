//! Evaluation against ground truth: reconstruction accuracy and completeness per frame and
//! reconstruction stage.
//!
//! - accuracy: the distance within which 90% of the reconstructed vertices lie from the true
//!   surface (metres; the true surface is sampled every 2 mm);
//! - completeness: the share of points sampled on the true surface that lie inside the
//!   reconstructed solid or within one voxel of it (from the stage's cached signed distance),
//!   so a reconstruction that never cuts into the object scores 1.

use crate::error::{Error, Result};
use crate::geometry::grid::GridSpec;
use crate::geometry::spatial::PointIndex;
use crate::geometry::TriMesh;
use crate::runner::Job;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::fmt::Write as _;

pub mod pose;
pub mod reliability;

/// Points on `mesh`'s surface about `spacing` metres apart (deterministic).
pub fn sample_surface(mesh: &TriMesh, spacing: f64) -> Vec<Vector3<f64>> {
    let mut out = Vec::new();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let area = 0.5 * (b - a).cross(&(c - a)).norm();
        // n x n barycentric grid with ~area / spacing^2 points.
        let n = ((2.0 * area).sqrt() / spacing).ceil().max(1.0) as usize;
        for i in 0..n {
            for j in 0..n - i {
                let (u, v) = (
                    (i as f64 + 1.0 / 3.0) / n as f64,
                    (j as f64 + 1.0 / 3.0) / n as f64,
                );
                out.push(a + u * (b - a) + v * (c - a));
            }
        }
    }
    out
}

/// One row of the reconstruction table.
#[derive(Debug, Clone)]
pub struct ReconRow {
    pub frame: u32,
    pub stage: &'static str,
    pub vertices: usize,
    /// Metres.
    pub accuracy90: f64,
    /// Share in [0, 1].
    pub completeness: f64,
    /// The stage's voxel size, metres.
    pub voxel: f64,
}

/// Accuracy and completeness of one reconstruction.
pub fn score(recon: &TriMesh, grid: &GridSpec, sdf: &[f32], truth: &TriMesh) -> (f64, f64) {
    score_against(recon, grid, sdf, &truth_index(truth))
}

/// The true surface sampled every 2 mm, indexed for nearest-point queries.
pub fn truth_index(truth: &TriMesh) -> PointIndex {
    PointIndex::new(sample_surface(truth, 0.002), 0.01)
}

/// [`score`] against an already sampled true surface.
fn score_against(recon: &TriMesh, grid: &GridSpec, sdf: &[f32], index: &PointIndex) -> (f64, f64) {
    let mut d: Vec<f64> = recon
        .vertices
        .par_iter()
        .map(|v| index.nearest(v).map_or(f64::INFINITY, |x| x.1))
        .collect();
    d.sort_by(f64::total_cmp);
    let accuracy90 = if d.is_empty() {
        f64::INFINITY
    } else {
        d[((d.len() as f64 * 0.9).ceil() as usize).clamp(1, d.len()) - 1]
    };
    let covered = index
        .points()
        .par_iter()
        .filter(|p| grid.interpolate(sdf, p, f32::INFINITY) as f64 <= grid.voxel)
        .count();
    (
        accuracy90,
        covered as f64 / index.points().len().max(1) as f64,
    )
}

/// Reconstruction stages the evaluation knows: (stage, mesh file, grid file) per frame.
const RECON_STAGES: &[&str] = &["visual_hull", "graphcut"];

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
        for &stage in RECON_STAGES {
            if job.cache.manifest(stage, frame).is_none() {
                continue;
            }
            let dir = job.cache.stage_dir(stage);
            let (ply, grid_file) = crate::stages::hull_files(frame);
            let mesh = crate::geometry::ply::read_ply(&dir.join(&ply))?;
            let path = dir.join(&grid_file);
            let data = crate::limits::read_cache_file(&path)?;
            let (grid, sdf) = crate::stages::visual_hull::parse_grid(&path, &data)?;
            let (accuracy90, completeness) = score_against(
                &mesh,
                &grid,
                &sdf,
                index.get_or_insert_with(|| truth_index(&truth)),
            );
            rows.push(ReconRow {
                frame,
                stage,
                vertices: mesh.vertices.len(),
                accuracy90,
                completeness,
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
    stage: &str,
    frame: u32,
) -> Result<Vec<SilhouetteAgreement>> {
    let (ply, _) = crate::stages::hull_files(frame);
    let mesh = crate::geometry::ply::read_ply(&job.cache.stage_dir(stage).join(ply))?;
    coverage_of(job, &pixel_tables(job), &mesh, frame)
}

/// Per-camera pixel tables (one undistortion per pixel: made once per evaluation).
fn pixel_tables(job: &Job) -> Vec<crate::geometry::raster::PixelRays> {
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
    use crate::stages::graphcut;
    let mut report = String::new();
    let mut csv = String::from(
        "frame,stage,camera,silhouette_coverage,mean_vertex_zncc,seen_vertices,silhouette_iou\n",
    );
    let rays = pixel_tables(job);
    for &f in &job.frames {
        let frames: Vec<image::RgbImage> = (0..job.sequence.cameras.len())
            .map(|c| job.sequence.load_frame(c, f))
            .collect::<Result<_>>()?;
        let images = graphcut::grey(&frames);
        for &stage in RECON_STAGES {
            if job.cache.manifest(stage, f).is_none() {
                continue;
            }
            let (ply, grid_file) = crate::stages::hull_files(f);
            let dir = job.cache.stage_dir(stage);
            let mesh = crate::geometry::ply::read_ply(&dir.join(ply))?;
            let path = dir.join(grid_file);
            let data = crate::limits::read_cache_file(&path)?;
            let (grid, _) = crate::stages::visual_hull::parse_grid(&path, &data)?;
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
fn coverage_of(
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
        .map(|(cam, (mask, rays))| {
            let frags =
                crate::geometry::raster::rasterize(cam, rays, &mesh.vertices, &mesh.triangles);
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
        })
        .collect())
}

/// The CSV text of reconstruction rows.
pub fn reconstruction_csv(rows: &[ReconRow]) -> String {
    let mut s = String::from("frame,stage,vertices,accuracy90_m,completeness,voxel_m\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{:.6},{:.6},{}",
            r.frame, r.stage, r.vertices, r.accuracy90, r.completeness, r.voxel
        );
    }
    s
}

/// A printed table of reconstruction rows.
pub fn reconstruction_table(rows: &[ReconRow]) -> String {
    let mut s = format!(
        "{:>6}  {:>12}  {:>9}  {:>13}  {:>12}\n",
        "frame", "stage", "vertices", "accuracy90 cm", "completeness"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:>6}  {:>12}  {:>9}  {:>13.2}  {:>11.2}%",
            r.frame,
            r.stage,
            r.vertices,
            r.accuracy90 * 100.0,
            r.completeness * 100.0
        );
    }
    s
}
