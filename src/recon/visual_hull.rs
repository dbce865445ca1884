//! Stage 2, the visual hull (method.md "Stage 2"): conservative voxel carving, coarse to
//! fine, then a watertight mesh of the occupancy.
//!
//! A voxel stays when its projected footprint (a pixel rectangle surely holding the image of
//! the voxel's bounding ball) holds at least one silhouette pixel in every camera whose image
//! its centre falls in; with `all_but = k`, up to k cameras may disagree. Voxels seen by fewer than
//! `min_views` cameras are carved. Carving works on blocks of 16^3 voxels first: a block whose
//! footprint lies inside a camera's image and holds no silhouette pixel is carved whole, a
//! block whose footprint is all silhouette in every camera that sees it stays whole, and only
//! the rest is split (octree-style), so the work grows with the surface, not the volume.
//! Footprint counts come from per-mask summed-area tables.
//!
//! The occupancy's signed distance (exact Euclidean distance transform) places the surface
//! to within a voxel; near it, the distance to the silhouette cones
//! ([`crate::geometry::cone_distance`]) moves it onto the cones themselves, below the voxel
//! size ([`on_the_cones`]). That field is meshed with marching tetrahedra
//! ([`crate::geometry::isosurface`]) and optionally Taubin-smoothed. The grid, the
//! occupancy's signed distance and the shell where the meshed field differs from it
//! ([`ConeBand`]) are kept for the graph-cut stage.

use crate::camera::Camera;
use crate::error::Refusal;
use crate::geometry::cone_distance::ConeDistance;
use crate::geometry::distance::signed_distance;
use crate::geometry::grid::GridSpec;
use crate::geometry::isosurface::{self, ScalarGrid};
use crate::geometry::smooth::taubin;
use crate::geometry::TriMesh;
use image::GrayImage;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// An axis-aligned box, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoundingBox {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// Parameters of the visual hull stage (pipeline.yaml key `visual_hull`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VisualHullParams {
    /// Voxel edge length, metres. Default 0.01.
    pub voxel_size: f64,
    /// Box to carve, metres; derived per frame from the cameras and silhouettes when absent.
    pub bbox: Option<BoundingBox>,
    /// Margin added around the derived box, metres. Default 0.03.
    pub margin: f64,
    /// Number of cameras allowed to disagree (all-but-k carving for noisy masks). Default 0.
    pub all_but: usize,
    /// Voxels seen by fewer cameras are carved. Default 2.
    pub min_views: usize,
    /// Taubin smoothing iterations on the mesh (0: off). Default 10.
    pub smoothing_iterations: usize,
    /// Largest grid allowed, megabytes (about 10 bytes per voxel). Default 4096.
    pub memory_cap_mb: f64,
}

impl Default for VisualHullParams {
    fn default() -> Self {
        VisualHullParams {
            voxel_size: 0.01,
            bbox: None,
            margin: 0.03,
            all_but: 0,
            min_views: 2,
            smoothing_iterations: 10,
            memory_cap_mb: 4096.0,
        }
    }
}

/// Bytes per voxel the stage needs at its peak (occupancy, two distance fields, the signed
/// distance, and the iso-surface samples).
pub const BYTES_PER_VOXEL: f64 = 1.0 + 8.0 + 8.0 + 4.0 + 4.0;

/// A carved frame: grid, occupancy, signed distance (metres, negative inside) and mesh.
pub struct Hull {
    pub grid: GridSpec,
    pub occupied: Vec<bool>,
    pub sdf: Vec<f32>,
    /// The field the mesh was extracted from (the solid on the cones) where it differs from
    /// `sdf`: a thin shell around the surface, kept for the graph cut's mesh.
    pub on_cones: ConeBand,
    pub mesh: TriMesh,
}

/// Summed-area table of a mask: O(1) counts of silhouette pixels in rectangles.
pub struct MaskCounts {
    w: usize,
    h: usize,
    sums: Vec<u32>,
    /// Bound on the magnification of the camera's lens distortion ([`Camera::distortion_gain`]).
    gain: f64,
}

impl MaskCounts {
    /// The table of `mask`, seen by `cam`.
    pub fn new(mask: &GrayImage, cam: &Camera) -> MaskCounts {
        let (w, h) = (mask.width() as usize, mask.height() as usize);
        let mut sums = vec![0u32; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0u32;
            for x in 0..w {
                row += (mask.as_raw()[y * w + x] >= 128) as u32;
                sums[(y + 1) * (w + 1) + x + 1] = sums[y * (w + 1) + x + 1] + row;
            }
        }
        MaskCounts {
            w,
            h,
            sums,
            gain: cam.distortion_gain(),
        }
    }

    /// Silhouette pixels in the inclusive rectangle [x0, x1] x [y0, y1] (already clipped).
    fn count(&self, x0: usize, y0: usize, x1: usize, y1: usize) -> u32 {
        let s = |x: usize, y: usize| self.sums[y * (self.w + 1) + x];
        s(x1 + 1, y1 + 1) + s(x0, y0) - s(x0, y1 + 1) - s(x1 + 1, y0)
    }

    /// Whether the mask holds any silhouette pixel.
    pub fn any(&self) -> bool {
        self.sums[self.sums.len() - 1] > 0
    }
}

/// What one camera says about a box.
#[derive(Debug, Clone, Copy, PartialEq)]
enum View {
    /// The footprint lies in the image with no silhouette pixel.
    Empty,
    /// The footprint lies in the image and is all silhouette.
    Full,
    /// The footprint lies in the image, partly silhouette.
    Partial,
    /// The footprint lies entirely outside the image: the camera has no say.
    Unseen,
    /// Straddles the image border or the camera plane: undecided for a block.
    Unknown,
}

/// The pixel rectangle (inclusive, unclipped) that surely holds the projection of the ball
/// of `radius` metres around `centre`; `None` when the ball reaches behind the camera. One
/// projection instead of eight corners: the ball's image lies within f * R / (z - R) pixels of
/// the centre's image (pinhole bound), times the lens distortion's magnification bound
/// `gain` (plus a quarter pixel against rounding).
fn footprint(cam: &Camera, gain: f64, centre: &Vector3<f64>, radius: f64) -> Option<[f64; 4]> {
    let (px, z) = cam.project_with_depth(centre);
    if z - radius <= 1e-6 {
        return None;
    }
    let r = gain * (cam.fx.max(cam.fy) + cam.skew.abs()) * radius / (z - radius) + 0.25;
    Some([
        (px.x - r).round(),
        (px.y - r).round(),
        (px.x + r).round(),
        (px.y + r).round(),
    ])
}

/// Classifies a ball (the bounding ball of a box) in one camera.
fn view_ball(cam: &Camera, counts: &MaskCounts, centre: &Vector3<f64>, radius: f64) -> View {
    let Some([x0, y0, x1, y1]) = footprint(cam, counts.gain, centre, radius) else {
        return View::Unknown;
    };
    let (w, h) = (counts.w as f64, counts.h as f64);
    if x1 < 0.0 || y1 < 0.0 || x0 > w - 1.0 || y0 > h - 1.0 {
        return View::Unseen;
    }
    if x0 < 0.0 || y0 < 0.0 || x1 > w - 1.0 || y1 > h - 1.0 {
        return View::Unknown;
    }
    let (x0, y0, x1, y1) = (x0 as usize, y0 as usize, x1 as usize, y1 as usize);
    let n = counts.count(x0, y0, x1, y1);
    let area = ((x1 - x0 + 1) * (y1 - y0 + 1)) as u32;
    if n == 0 {
        View::Empty
    } else if n == area {
        View::Full
    } else {
        View::Partial
    }
}

/// Classifies the box [lo, hi] in one camera (through its bounding ball).
fn view_box(cam: &Camera, counts: &MaskCounts, lo: &Vector3<f64>, hi: &Vector3<f64>) -> View {
    view_ball(cam, counts, &((lo + hi) / 2.0), (hi - lo).norm() / 2.0)
}

/// Block edge of the coarse level, voxels.
const BLOCK: usize = 16;

/// Carves the grid: occupancy per voxel.
pub fn carve(
    grid: &GridSpec,
    cams: &[Camera],
    counts: &[MaskCounts],
    p: &VisualHullParams,
) -> Vec<bool> {
    let [nx, ny, nz] = grid.dims;
    let blocks: Vec<[usize; 3]> = (0..nz.div_ceil(BLOCK))
        .flat_map(|bz| {
            (0..ny.div_ceil(BLOCK))
                .flat_map(move |by| (0..nx.div_ceil(BLOCK)).map(move |bx| [bx, by, bz]))
        })
        .collect();
    let all: Vec<u16> = (0..cams.len() as u16).collect();
    let kept: Vec<Vec<usize>> = blocks
        .par_iter()
        .map(|b| {
            let mut out = Vec::new();
            let start = Votes {
                open: all.clone(),
                keep: 0,
                against: 0,
            };
            carve_block(
                grid,
                cams,
                counts,
                p,
                [b[0] * BLOCK, b[1] * BLOCK, b[2] * BLOCK],
                BLOCK,
                start,
                &mut out,
            );
            out
        })
        .collect();
    let mut occupied = vec![false; grid.len()];
    for list in kept {
        for i in list {
            occupied[i] = true;
        }
    }
    occupied
}

/// What the cameras have settled for every voxel of a block so far.
#[derive(Clone)]
struct Votes {
    /// Cameras that still have to be asked.
    open: Vec<u16>,
    /// Cameras that see every voxel of the block and keep it.
    keep: usize,
    /// Cameras that carve every voxel of the block.
    against: usize,
}

/// Decides the cube of `size` voxels at voxel `at`, splitting it while cameras disagree;
/// pushes the indices of kept voxels. A camera that keeps (footprint all silhouette) or does
/// not see (footprint outside its image) a block says the same of every voxel inside, so it
/// is not asked again below.
#[allow(clippy::too_many_arguments)]
fn carve_block(
    grid: &GridSpec,
    cams: &[Camera],
    counts: &[MaskCounts],
    p: &VisualHullParams,
    at: [usize; 3],
    size: usize,
    mut votes: Votes,
    out: &mut Vec<usize>,
) {
    if (0..3).any(|a| at[a] >= grid.dims[a]) {
        return;
    }
    let end = [0, 1, 2].map(|a| (at[a] + size).min(grid.dims[a]));
    let lo = grid.origin + grid.voxel * Vector3::new(at[0] as f64, at[1] as f64, at[2] as f64);
    let hi = grid.origin + grid.voxel * Vector3::new(end[0] as f64, end[1] as f64, end[2] as f64);
    let centre = (lo + hi) / 2.0;
    let radius = (hi - lo).norm() / 2.0;
    if size == 1 {
        // The voxel rule: every open camera whose image holds the centre votes.
        let mut seen = votes.keep;
        for &c in &votes.open {
            let (cam, cnt) = (&cams[c as usize], &counts[c as usize]);
            let (px, z) = cam.project_with_depth(&centre);
            if z <= 0.0 || !cam.in_image(&px) {
                continue;
            }
            seen += 1;
            let empty = match footprint(cam, cnt.gain, &centre, radius) {
                None => false,
                Some([x0, y0, x1, y1]) => {
                    // Count within the part of the footprint inside the image.
                    let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64 - 1.0) as usize;
                    cnt.count(
                        clamp(x0, cnt.w),
                        clamp(y0, cnt.h),
                        clamp(x1, cnt.w),
                        clamp(y1, cnt.h),
                    ) == 0
                }
            };
            votes.against += empty as usize;
            if votes.against > p.all_but {
                return;
            }
        }
        if seen >= p.min_views {
            out.push(grid.index(at[0], at[1], at[2]));
        }
        return;
    }
    let mut still_open = Vec::with_capacity(votes.open.len());
    for &c in &votes.open {
        match view_ball(&cams[c as usize], &counts[c as usize], &centre, radius) {
            View::Full => votes.keep += 1,
            View::Unseen => {}
            View::Empty => {
                votes.against += 1;
                if votes.against > p.all_but {
                    return; // every voxel inside is carved
                }
            }
            View::Partial | View::Unknown => still_open.push(c),
        }
    }
    votes.open = still_open;
    if votes.open.is_empty() {
        if votes.keep >= p.min_views {
            for z in at[2]..end[2] {
                for y in at[1]..end[1] {
                    for x in at[0]..end[0] {
                        out.push(grid.index(x, y, z));
                    }
                }
            }
        }
        return;
    }
    let half = size / 2;
    for dz in [0, half] {
        for dy in [0, half] {
            for dx in [0, half] {
                carve_block(
                    grid,
                    cams,
                    counts,
                    p,
                    [at[0] + dx, at[1] + dy, at[2] + dz],
                    half,
                    votes.clone(),
                    out,
                );
            }
        }
    }
}

/// Fills empty voxels that the grid's outside cannot reach (6-connected): a visual hull has
/// no inner cavities, these are discretization artefacts (voxels whose small footprint fell
/// into a one-pixel gap of a silhouette).
pub fn fill_cavities(grid: &GridSpec, occupied: &mut [bool]) {
    let [nx, ny, nz] = grid.dims;
    let mut outside = vec![false; grid.len()];
    let mut stack: Vec<usize> = Vec::new();
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let border =
                    x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1;
                let i = grid.index(x, y, z);
                if border && !occupied[i] && !outside[i] {
                    outside[i] = true;
                    stack.push(i);
                }
            }
        }
    }
    while let Some(i) = stack.pop() {
        let [x, y, z] = grid.coords(i);
        let mut visit = |j: usize| {
            if !occupied[j] && !outside[j] {
                outside[j] = true;
                stack.push(j);
            }
        };
        if x > 0 {
            visit(i - 1);
        }
        if x + 1 < nx {
            visit(i + 1);
        }
        if y > 0 {
            visit(i - nx);
        }
        if y + 1 < ny {
            visit(i + nx);
        }
        if z > 0 {
            visit(i - nx * ny);
        }
        if z + 1 < nz {
            visit(i + nx * ny);
        }
    }
    for (o, out) in occupied.iter_mut().zip(&outside) {
        *o = !*out;
    }
}

/// A 3x3x3 box blur of per-voxel values (clamped at the border). On a signed distance it
/// keeps the zero level in place on smooth surfaces and removes features one voxel thin:
/// slits that single columns of pixels cut, lone voxels, and voxels joined only by an edge,
/// which would otherwise give the mesh spurious handles.
pub fn box_blur_3d(grid: &GridSpec, values: &[f32]) -> Vec<f32> {
    let [nx, ny, nz] = grid.dims;
    let mut cur = values.to_vec();
    for axis in 0..3 {
        let (n, stride) = match axis {
            0 => (nx, 1),
            1 => (ny, nx),
            _ => (nz, nx * ny),
        };
        let src = cur.clone();
        cur.par_iter_mut().enumerate().for_each(|(i, v)| {
            let c = (i / stride) % n;
            let lo = if c > 0 { i - stride } else { i };
            let hi = if c + 1 < n { i + stride } else { i };
            *v = (src[lo] + src[i] + src[hi]) / 3.0;
        });
    }
    cur
}

/// Checks the memory a grid needs against the cap.
pub fn check_memory(grid: &GridSpec, p: &VisualHullParams) -> std::result::Result<(), Refusal> {
    // In floating point: the product of absurd dimensions overflows an integer.
    let voxels: f64 = grid.dims.iter().map(|&d| d as f64).product();
    let mb = voxels * BYTES_PER_VOXEL / 1e6;
    if mb > p.memory_cap_mb {
        return Err(format!(
            "the grid of {}x{}x{} voxels of {} m needs about {mb:.0} MB, over visual_hull.memory_cap_mb = {}; \
             use a larger voxel_size, a tighter bbox, or raise the cap",
            grid.dims[0], grid.dims[1], grid.dims[2], grid.voxel, p.memory_cap_mb
        ).into());
    }
    Ok(())
}

/// Checks parameters that do not depend on the data.
pub fn validate(p: &VisualHullParams) -> std::result::Result<(), Refusal> {
    if !(p.voxel_size > 0.0 && p.voxel_size.is_finite()) {
        return Err(format!(
            "visual_hull.voxel_size must be a positive length in metres, got {}",
            p.voxel_size
        )
        .into());
    }
    if let Some(b) = &p.bbox {
        if (0..3).any(|a| b.min[a] >= b.max[a] || !b.min[a].is_finite() || !b.max[a].is_finite()) {
            return Err(format!(
                "visual_hull.bbox: min {:?} must be below max {:?} on every axis",
                b.min, b.max
            )
            .into());
        }
    }
    if p.voxel_size > MAX_VOXEL_SIZE {
        return Err(format!(
            "visual_hull.voxel_size {} m is larger than {MAX_VOXEL_SIZE} m: a person 1.7 m tall \
             would be a handful of voxels; use 0.005 to 0.02 for a body",
            p.voxel_size
        )
        .into());
    }
    if !(p.margin >= 0.0 && p.margin <= 10.0) {
        return Err(format!(
            "visual_hull.margin must be a length from 0 to 10 m, got {}",
            p.margin
        )
        .into());
    }
    if !(p.memory_cap_mb > 0.0 && p.memory_cap_mb.is_finite()) {
        return Err(format!(
            "visual_hull.memory_cap_mb must be a positive number of MB, got {}",
            p.memory_cap_mb
        )
        .into());
    }
    crate::limits::check_smoothing("visual_hull.smoothing_iterations", p.smoothing_iterations)?;
    if let Some(b) = &p.bbox {
        let grid = GridSpec::covering(Vector3::from(b.min), Vector3::from(b.max), p.voxel_size);
        check_memory(&grid, p)?;
        check_resolution(&grid)?;
    }
    Ok(())
}

/// The largest voxel accepted, metres.
pub const MAX_VOXEL_SIZE: f64 = 0.25;

/// The fewest voxels a grid must span along its longest side.
pub const MIN_VOXELS_ACROSS: usize = 12;

/// Refuses a grid too coarse to hold a shape (fewer than [`MIN_VOXELS_ACROSS`] voxels
/// along its longest side).
pub fn check_resolution(grid: &GridSpec) -> std::result::Result<(), Refusal> {
    let across = grid.dims.iter().copied().max().unwrap_or(0);
    if across < MIN_VOXELS_ACROSS {
        return Err(format!(
            "the grid is {}x{}x{} voxels of {} m, fewer than {MIN_VOXELS_ACROSS} across: the hull \
             would be a few blocks; use a smaller visual_hull.voxel_size",
            grid.dims[0], grid.dims[1], grid.dims[2], grid.voxel
        )
        .into());
    }
    Ok(())
}

/// Checks the parameters against the capture's cameras (`cameras` of them).
pub fn validate_for_cameras(
    p: &VisualHullParams,
    cameras: usize,
) -> std::result::Result<(), Refusal> {
    if p.min_views > cameras {
        return Err(format!(
            "visual_hull.min_views = {} is more than the capture's {cameras} cameras: every voxel \
             would be carved; use 2 (the default) up to {cameras}",
            p.min_views
        )
        .into());
    }
    if p.all_but + 2 > cameras {
        return Err(format!(
            "visual_hull.all_but = {} lets all but {} of the capture's {cameras} cameras disagree; \
             at least two cameras must agree: use 0 (the default) up to {}",
            p.all_but,
            cameras.saturating_sub(p.all_but),
            cameras.saturating_sub(2)
        )
        .into());
    }
    Ok(())
}

/// The box to carve: pipeline.yaml's, or derived from the silhouettes: the cube spanned by
/// the camera centres (cameras surround the subject) is carved coarsely (64^3), then the box
/// of what remains is carved again at 64^3 to tighten it. These passes keep only voxels seen
/// by at least half of the cameras, so that space that few narrow views see (and cannot
/// carve) does not inflate the box.
pub fn carving_box(
    cams: &[Camera],
    counts: &[MaskCounts],
    p: &VisualHullParams,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if let Some(b) = &p.bbox {
        return Some((Vector3::from(b.min), Vector3::from(b.max)));
    }
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for c in cams {
        lo = lo.inf(&c.centre());
        hi = hi.sup(&c.centre());
    }
    let centre = (lo + hi) / 2.0;
    let half = (hi - lo).max() / 2.0;
    let mut bounds = (
        centre - Vector3::repeat(half),
        centre + Vector3::repeat(half),
    );
    let coarse = VisualHullParams {
        min_views: p.min_views.max(cams.len().div_ceil(2)),
        ..p.clone()
    };
    for _ in 0..2 {
        let size = (bounds.1 - bounds.0).max() / 64.0;
        let grid = GridSpec::covering(bounds.0, bounds.1, size);
        let occupied = carve(&grid, cams, counts, &coarse);
        let (mut a, mut b) = (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        );
        for (i, _) in occupied.iter().enumerate().filter(|(_, &o)| o) {
            let [x, y, z] = grid.coords(i);
            let v = grid.origin + size * Vector3::new(x as f64, y as f64, z as f64);
            a = a.inf(&v);
            b = b.sup(&(v + Vector3::repeat(size)));
        }
        if a.x > b.x {
            return None;
        }
        // The coarse voxels are conservative already; one more coarse voxel of slack.
        bounds = (a - Vector3::repeat(size), b + Vector3::repeat(size));
    }
    Some((
        bounds.0 - Vector3::repeat(p.margin),
        bounds.1 + Vector3::repeat(p.margin),
    ))
}

/// Carves one frame and meshes it. `None` when the silhouettes leave nothing (an empty
/// frame). `Err` names the problem for a camera that sees none of the box.
pub fn reconstruct(
    cams: &[Camera],
    masks: &[GrayImage],
    p: &VisualHullParams,
) -> std::result::Result<Option<Hull>, Refusal> {
    validate(p)?;
    let counts: Vec<MaskCounts> = masks
        .iter()
        .zip(cams)
        .map(|(m, c)| MaskCounts::new(m, c))
        .collect();
    if counts.iter().all(|c| !c.any()) {
        return Ok(None);
    }
    let Some((lo, hi)) = carving_box(cams, &counts, p) else {
        return Ok(None);
    };
    for (cam, cnt) in cams.iter().zip(&counts) {
        if view_box(cam, cnt, &lo, &hi) == View::Unseen {
            return Err(format!(
                "camera '{}' sees none of the reconstruction volume {:?}..{:?}; check its calibration (R, t) or visual_hull.bbox",
                cam.name,
                lo.as_slice(),
                hi.as_slice()
            ).into());
        }
    }
    let grid = GridSpec::covering(lo, hi, p.voxel_size);
    check_memory(&grid, p)?;
    check_resolution(&grid)?;
    let mut occupied = carve(&grid, cams, &counts, p);
    if !occupied.iter().any(|&o| o) {
        return Ok(None);
    }
    fill_cavities(&grid, &mut occupied);
    let mut sdf = box_blur_3d(&grid, &signed_distance(&grid, &occupied));
    let cones = cones(cams, masks, p, &grid);
    let field = on_the_cones(&grid, &sdf, &cones);
    let mut mesh = mesh_sdf(&grid, &field);
    taubin(&mut mesh, p.smoothing_iterations);
    with_occupancy_sign(&mut sdf, &occupied);
    let on_cones = ConeBand::between(&sdf, &field);
    Ok(Some(Hull {
        grid,
        occupied,
        sdf,
        on_cones,
        mesh,
    }))
}

/// How far the cones may move the occupancy's surface, voxels: the carving keeps a voxel
/// whose footprint (the image of its bounding ball, radius 0.87 voxel) touches a
/// silhouette, so its surface lies up to about a voxel outside the cones.
const CONE_REACH: f64 = 1.5;

/// The occupancy's signed distance `sdf` (metres) with the cones' distance where that lies
/// within [`CONE_REACH`] voxels of it: min(max(cones, sdf - r), sdf + r). Its zero level
/// is the cones' surface where the two agree within r, and never strays farther than r
/// from the occupancy's, so that a one-pixel slit in one silhouette cannot cut the surface
/// deeper than the carving did.
pub fn on_the_cones(grid: &GridSpec, sdf: &[f32], cones: &ConeDistance) -> Vec<f32> {
    let r = CONE_REACH * grid.voxel;
    sdf.par_iter()
        .enumerate()
        .map(|(i, &v)| {
            let v = v as f64;
            // Beyond r from the occupancy's surface the result keeps the sign of `sdf`.
            if v.abs() >= r {
                return v as f32;
            }
            let [x, y, z] = grid.coords(i);
            let cone = cones.at(&grid.centre(x, y, z)).unwrap_or(v);
            cone.max(v - r).min(v + r) as f32
        })
        .collect()
}

/// The distance to the silhouette cones with the carving's rules (`all_but`, `min_views`),
/// for the voxels of `grid`, exact as far as [`on_the_cones`] reads it.
pub fn cones<'a>(
    cams: &'a [Camera],
    masks: &[GrayImage],
    p: &VisualHullParams,
    grid: &GridSpec,
) -> ConeDistance<'a> {
    // on_the_cones clamps the cones to within r of an occupancy distance below r.
    let reach = 2.0 * CONE_REACH * grid.voxel;
    ConeDistance::new(cams, masks, p.all_but, p.min_views, grid, reach)
}

/// Gives the stored signed distance the sign of the occupancy it was computed from (-1 um
/// or less inside, 0 or more outside), so that `sdf < 0` reads back exactly the occupied
/// voxels: the smoothing blur alone turns some corner and edge voxels positive, and a stage
/// starting from them would lose those voxels and mesh a surface shrunk against the
/// silhouettes. Meshes are extracted before, from the blurred field itself.
pub fn with_occupancy_sign(sdf: &mut [f32], occupied: &[bool]) {
    for (v, &inside) in sdf.iter_mut().zip(occupied) {
        *v = if inside { v.min(-1e-6) } else { v.max(0.0) };
    }
}

/// Meshes the zero level of a signed distance sampled at voxel centres, padded with one
/// layer of outside samples so the surface is always closed.
pub fn mesh_sdf(grid: &GridSpec, sdf: &[f32]) -> TriMesh {
    let [nx, ny, nz] = grid.dims;
    let dims = [nx + 2, ny + 2, nz + 2];
    let mut values = vec![grid.voxel as f32; dims[0] * dims[1] * dims[2]];
    for z in 0..nz {
        for y in 0..ny {
            let src = grid.index(0, y, z);
            let dst = 1 + dims[0] * (y + 1 + dims[1] * (z + 1));
            values[dst..dst + nx].copy_from_slice(&sdf[src..src + nx]);
        }
    }
    let field = ScalarGrid {
        dims,
        origin: grid.origin + Vector3::repeat(-0.5 * grid.voxel),
        spacing: grid.voxel,
        values,
    };
    isosurface::extract(&field)
}

/// A field given as a base field (the stored signed distance) with some voxels changed:
/// the hull's solid on the cones, which differs from the occupancy's distance only within
/// [`CONE_REACH`] voxels of the surface.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConeBand {
    /// (voxel index, value in metres), by increasing index.
    pub changed: Vec<(u32, f32)>,
}

impl ConeBand {
    /// The voxels where `field` differs from `base`.
    pub fn between(base: &[f32], field: &[f32]) -> ConeBand {
        ConeBand {
            changed: (0..base.len())
                .filter(|&i| base[i].to_bits() != field[i].to_bits())
                .map(|i| (i as u32, field[i]))
                .collect(),
        }
    }

    /// `base` with the band's values.
    pub fn applied_to(&self, base: &[f32]) -> Vec<f32> {
        let mut out = base.to_vec();
        for &(i, v) in &self.changed {
            out[i as usize] = v;
        }
        out
    }
}
