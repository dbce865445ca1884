//! Stage 3, graph-cut multi-view stereo refinement of the hull (method.md "Stage 3", after
//! Vogiatzis, Torr and Cipolla, CVPR 2005).
//!
//! - **Band**: the hull voxels within `band` metres of the hull surface (from the hull's
//!   signed distance) and within the outer half of the local thickness (the largest depth
//!   within `band`), so thin parts keep a fixed core. They are the graph's nodes; every other
//!   voxel keeps its hull label.
//! - **Visibility** of a band voxel x: the cameras that see the nearest hull surface point
//!   p = x - sdf(x) * n (n the unit gradient of the signed distance): p faces the camera
//!   (n . (c - p) > 0) and the camera's depth map of the hull mesh (z-buffer, the farthest of
//!   the 2 x 2 pixels around p's projection) is not closer than p by more than 1.5 voxels.
//! - **Photo-consistency** C(x) in [-1, 1]: zero-mean normalized cross-correlation of
//!   patches of `window` x `window` points spaced `patch_spacing` voxels on the plane through x
//!   parallel to the hull's tangent plane, projected into each visible camera (affinely, from
//!   the projections of the patch centre and two tangent steps) and sampled bilinearly in
//!   grey; over pairs of visible cameras whose viewing directions differ by at most
//!   `max_pair_angle_deg`, C is the mean of the best `best_pairs` pairs. Patches sampled on
//!   the surface correspond across wide baselines and have the same metric size at every
//!   image resolution. Without such a pair, C = -1 (flat cost).
//! - **Cost** rho(x) = 1 - exp(-tan^2(pi/4 (C(x) - 1)) / sigma^2): 0 where the images agree
//!   perfectly, 1 where they disagree or nothing sees x.
//! - **Graph**: 6-neighbour edges of weight (4 pi / 3) h^2 (rho_i + rho_j) / 2 (h the voxel
//!   size; the 4 pi / 3 factor makes the cut's cost approximate the surface integral of rho,
//!   Boykov and Kolmogorov ICCV 2003). A band voxel next to an outside voxel is linked to the
//!   source (outside) with that face's weight, next to a deeper hull voxel to the sink
//!   (inside); every band voxel gets a ballooning link lambda h^3 b(x) to the sink, rewarding
//!   enclosed volume so the minimal surface does not shrink.
//! - **Evidence-weighted ballooning** (optional, `ballooning_evidence`; without it b = 1 as in
//!   method.md) b(x) in {0, 1} (after the "intelligent ballooning" of
//!   Hernandez, Vogiatzis and Cipolla, 2007, here along the hull's normal rather than along
//!   camera rays): b(x) = 0 when a band voxel deeper along the hull's inward normal from x
//!   has C >= max(C(x), `ballooning_evidence`): the images show a surface behind x, so x is
//!   likely empty; otherwise 1. A uniform ballooning caps how deep the cut can carve: a layer
//!   of voxels costs lambda h^3 each and can save at most one face's weight (4 pi / 3) h^2,
//!   about two voxels at the default lambda, far less than the hull's error in concavities.
//!   Where nothing sees the surface, C = -1 everywhere and the full ballooning stays.
//! - **Rims**: an outer band voxel whose centre projects onto a silhouette's outline lies
//!   where the hull touches the object; with `pin_rims` it is tied to the sink (kept), and
//!   after the cut, carved voxels whose carving uncovers a silhouette pixel the hull covered
//!   are put back, so the refined surface still explains the silhouettes.
//! - **Cut**: Boykov-Kolmogorov max-flow; source-side band voxels are carved. Where no camera
//!   pair sees the surface, rho is flat and the ballooning keeps the hull's shape (the
//!   phantom volume stays, for stage 4 to flag).

use crate::camera::Camera;
use crate::error::Refusal;
use crate::geometry::grid::{GridSpec, FACE_OFFSETS};
use crate::geometry::TriMesh;
use crate::maxflow::GridGraph;
use crate::photo::{depth_maps, dot, normalize, patch_grid, GreyImage, Visibility};
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Parameters of the graph-cut stage (pipeline.yaml key `graphcut`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GraphcutParams {
    /// Band thickness inside the hull surface, metres. Default 0.05.
    pub band: f64,
    /// Patch edge, samples (odd). Default 7.
    pub window: usize,
    /// Distance between patch samples on the tangent plane, voxels. Default 0.5.
    pub patch_spacing: f64,
    /// Largest angle between two cameras' viewing directions for their patches to be
    /// compared, degrees. Default 50.
    pub max_pair_angle_deg: f64,
    /// Number of best camera pairs averaged into C(x). Default 3.
    pub best_pairs: usize,
    /// Sharpness sigma of the cost mapping. Default 0.5.
    pub sigma: f64,
    /// Ballooning weight lambda, per metre (times h^3 per voxel). Default 200. A voxel is
    /// kept outside the photo-consistent surface when the cost of the faces it adds differs
    /// from that of the faces it hides by less than lambda h / (4 pi / 3) (0.48 at 1 cm
    /// voxels), so the cut leans outward by up to a voxel where it carves; lower values
    /// shrink surfaces nothing sees (see docs/decisions.md).
    pub ballooning: f64,
    /// Evidence-weighted ballooning: the photo-consistency C from which a surface seen behind
    /// a band voxel (deeper along the hull's inward normal, within the band, and at least as
    /// consistent as the voxel) removes the voxel's ballooning link (0.3 suits the synthetic
    /// scenes). Default none: the uniform ballooning of method.md.
    pub ballooning_evidence: Option<f64>,
    /// Taubin smoothing iterations of the mesh. Default 10.
    pub smoothing_iterations: usize,
    /// Keep the hull's rim voxels (outer band voxels whose centre projects onto a silhouette's
    /// outline, where the hull touches the object) inside. Default false: with many cameras
    /// the rims cover much of the surface and little is refined (tripod t0: accuracy 1.63 cm
    /// with, 1.31 cm without); on real captures it keeps the silhouettes explained.
    pub pin_rims: bool,
    /// Optional last step: each mesh vertex seen by two or more cameras moves along its
    /// normal to the shift of best multi-view ZNCC, searched up to this many voxels either
    /// way, regularised over its neighbours ([`crate::photo::refine`]). Default 0: off.
    pub photo_refine: f64,
}

impl Default for GraphcutParams {
    fn default() -> Self {
        GraphcutParams {
            band: 0.05,
            window: 7,
            patch_spacing: 0.5,
            max_pair_angle_deg: 50.0,
            best_pairs: 3,
            sigma: 0.5,
            ballooning: 200.0,
            ballooning_evidence: None,
            smoothing_iterations: 10,
            pin_rims: false,
            photo_refine: 0.0,
        }
    }
}

/// Checks parameters that do not depend on the data.
pub fn validate(p: &GraphcutParams) -> std::result::Result<(), Refusal> {
    if !(p.band > 0.0 && p.band.is_finite()) {
        return Err(format!(
            "graphcut.band must be a positive thickness in metres, got {}",
            p.band
        )
        .into());
    }
    if p.window < 3 || p.window.is_multiple_of(2) || p.window > 31 {
        return Err(format!(
            "graphcut.window must be an odd number of pixels from 3 to 31, got {}",
            p.window
        )
        .into());
    }
    if !(0.0..=3.0).contains(&p.photo_refine) {
        return Err(format!(
            "graphcut.photo_refine must lie in [0, 3] voxels (0: off), got {}",
            p.photo_refine
        )
        .into());
    }
    if p.sigma.is_nan()
        || p.sigma <= 0.0
        || p.ballooning.is_nan()
        || p.ballooning < 0.0
        || p.ballooning_evidence.is_some_and(f64::is_nan)
        || p.best_pairs == 0
        || !(p.patch_spacing > 0.0 && p.patch_spacing <= 10.0)
        || !(p.max_pair_angle_deg > 0.0 && p.max_pair_angle_deg <= 180.0)
    {
        return Err(
            "graphcut: sigma must be positive, ballooning not negative, ballooning_evidence a \
             number, best_pairs at least 1, patch_spacing in (0, 10] voxels and \
             max_pair_angle_deg in (0, 180]"
                .into(),
        );
    }
    crate::limits::check_smoothing("graphcut.smoothing_iterations", p.smoothing_iterations)?;
    Ok(())
}

/// The refined occupancy of one frame.
#[allow(clippy::too_many_arguments)]
pub fn min_cut_occupancy(
    grid: &GridSpec,
    occupied: &[bool],
    sdf: &[f32],
    cams: &[Camera],
    images: &[GreyImage],
    depth: &[Vec<f32>],
    silhouettes: &[image::GrayImage],
    p: &GraphcutParams,
    progress: &mut dyn FnMut(f64, u64),
) -> Vec<bool> {
    min_cut_occupancy_timed(
        grid,
        occupied,
        sdf,
        cams,
        images,
        depth,
        silhouettes,
        p,
        progress,
        &mut Timings::default(),
    )
}

/// Where [`min_cut_occupancy`]'s time went (seconds), for benchmarks.
#[derive(Debug, Default)]
pub struct Timings {
    pub band_voxels: usize,
    pub photo: f64,
    pub cut: f64,
}

/// [`min_cut_occupancy`], recording [`Timings`].
#[allow(clippy::too_many_arguments)]
pub fn min_cut_occupancy_timed(
    grid: &GridSpec,
    occupied: &[bool],
    sdf: &[f32],
    cams: &[Camera],
    images: &[GreyImage],
    depth: &[Vec<f32>],
    silhouettes: &[image::GrayImage],
    p: &GraphcutParams,
    progress: &mut dyn FnMut(f64, u64),
    timings: &mut Timings,
) -> Vec<bool> {
    let outlines: Vec<Vec<bool>> = if p.pin_rims {
        silhouettes.par_iter().map(outline).collect()
    } else {
        Vec::new()
    };
    let start = std::time::Instant::now();
    let h = grid.voxel;
    // Band nodes: hull voxels within `band` of the surface, and within the outer half of the
    // local thickness, so that thin parts (arms, fingers) keep a fixed core and cannot be cut
    // away whole.
    let radius = (p.band / h).ceil() as usize;
    let inner: Vec<f32> = sdf.iter().map(|&v| (-v).max(0.0)).collect();
    let thickness = max_filter(grid, &inner, radius);
    let band: Vec<usize> = (0..grid.len())
        .filter(|&i| {
            occupied[i]
                && (inner[i] as f64) <= p.band
                && inner[i] <= 0.5 * thickness[i] + 0.5 * h as f32
        })
        .collect();
    let mut node_of = vec![u32::MAX; grid.len()];
    for (k, &i) in band.iter().enumerate() {
        node_of[i] = k as u32;
    }
    // Photo-consistency and hull normal (none where the distance field is flat) per band voxel.
    let visibility = hull_visibility(cams, depth, h);
    let photo: Vec<(f64, Option<Vector3<f64>>)> = band
        .par_iter()
        .map(|&i| {
            let [x, y, z] = grid.coords(i);
            photo_consistency(
                grid,
                sdf,
                cams,
                images,
                &visibility,
                p,
                &grid.centre(x, y, z),
            )
        })
        .collect();
    let rho: Vec<f64> = photo
        .iter()
        .map(|&(c, _)| {
            let t = (std::f64::consts::FRAC_PI_4 * (c - 1.0)).tan();
            1.0 - (-(t * t) / (p.sigma * p.sigma)).exp()
        })
        .collect();
    let balloon = match p.ballooning_evidence {
        Some(evidence) => ballooning_weights(grid, &band, &node_of, &photo, p.band, evidence),
        None => vec![1.0; band.len()],
    };
    timings.band_voxels = band.len();
    timings.photo = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    let face = 4.0 * std::f64::consts::PI / 3.0 * h * h;
    // The cut runs on the grid of the band's bounding box; voxels of the box outside the band
    // stay isolated nodes.
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    for &i in &band {
        let c = grid.coords(i);
        for a in 0..3 {
            lo[a] = lo[a].min(c[a]);
            hi[a] = hi[a].max(c[a]);
        }
    }
    let box_dims: [usize; 3] = std::array::from_fn(|a| (hi[a] + 1).saturating_sub(lo[a]));
    let node = |c: [usize; 3]| {
        (c[0] - lo[0]) + box_dims[0] * ((c[1] - lo[1]) + box_dims[1] * (c[2] - lo[2]))
    };
    let mut g = GridGraph::new(box_dims);
    for (k, &i) in band.iter().enumerate() {
        let [x, y, z] = grid.coords(i);
        let mut source = 0.0;
        let mut sink = p.ballooning * h * h * h * balloon[k];
        for offset in FACE_OFFSETS {
            match grid.face_neighbour(i, offset) {
                Some(j) if occupied[j] && node_of[j] == u32::MAX => sink += face * rho[k],
                Some(j) if occupied[j] => {
                    // Each edge once, from the voxel on its negative side.
                    if offset > [0, 0, 0] {
                        let w = (face * (rho[k] + rho[node_of[j] as usize]) / 2.0) as f32;
                        let axis = offset.iter().position(|&o| o != 0).expect("a face");
                        g.set_edge(node([x, y, z]), axis, w, w);
                    }
                }
                // Outside the grid or the hull.
                _ => source += face * rho[k],
            }
        }
        if p.pin_rims && source > 0.0 && on_rim(cams, &outlines, &grid.centre(x, y, z)) {
            sink += 1e12; // the hull touches the object here: keep it
        }
        g.add_terminal_weights(node([x, y, z]), source, sink);
    }
    g.maxflow_with_progress(progress);
    timings.cut = start.elapsed().as_secs_f64();
    let mut out = occupied.to_vec();
    for &i in &band {
        if g.is_source_side(node(grid.coords(i))) {
            out[i] = false;
        }
    }
    if p.pin_rims {
        keep_silhouettes(grid, occupied, &mut out, cams, silhouettes, 0);
    } else if !silhouettes.is_empty() {
        // Never carve away what every silhouette confirms: a thin limb the photo-consistency
        // cannot hold (few cameras, no texture) is put back where its carving uncovers more
        // than a sliver of a silhouette.
        keep_silhouettes(
            grid,
            occupied,
            &mut out,
            cams,
            silhouettes,
            LIMB_CORE_RADIUS_PX,
        );
    }
    out
}

/// Silhouette pixels uncovered by the cut count for [`keep_silhouettes`]'s limb guarantee
/// only where the whole square of this radius around them is uncovered, pixels: a band
/// under 5 px wide along an outline (the cut moving a rim inward by a voxel or two, which
/// the refinement is for) is left carved; a limb carved away is not.
pub const LIMB_CORE_RADIUS_PX: usize = 2;

/// Per band voxel, the factor (0 or 1) of its ballooning link: 0 where the images show a
/// surface behind the voxel, i.e. a band voxel deeper along the hull's inward normal (within
/// `band` metres) has a photo-consistency C at least `evidence` and at least the voxel's own;
/// 1 elsewhere, including wherever nothing sees the surface (C = -1).
fn ballooning_weights(
    grid: &GridSpec,
    band: &[usize],
    node_of: &[u32],
    photo: &[(f64, Option<Vector3<f64>>)],
    band_thickness: f64,
    evidence: f64,
) -> Vec<f64> {
    let h = grid.voxel;
    let steps = (band_thickness / h).ceil() as usize;
    band.par_iter()
        .zip(photo)
        .map(|(&i, &(c, n))| {
            let Some(n) = n else {
                return 1.0;
            };
            let [x, y, z] = grid.coords(i);
            let centre = grid.centre(x, y, z);
            // Voxels met at whole-voxel steps along the inward normal, while in the band.
            let behind = (1..=steps)
                .map(|s| (centre - n * (s as f64 * h) - grid.origin) / h)
                .take_while(|q| (0..3).all(|a| q[a] >= 0.0 && q[a] < grid.dims[a] as f64))
                .map(|q| node_of[grid.index(q.x as usize, q.y as usize, q.z as usize)])
                .take_while(|&node| node != u32::MAX);
            let seen_behind = behind
                .map(|node| photo[node as usize].0)
                .any(|cb| cb >= evidence && cb >= c);
            if seen_behind {
                0.0
            } else {
                1.0
            }
        })
        .collect()
}

/// Silhouette outline, one pixel wide on each side: pixels whose 3x3 neighbourhood holds both
/// silhouette and background.
fn outline(mask: &image::GrayImage) -> Vec<bool> {
    let (w, h) = (mask.width() as i64, mask.height() as i64);
    let fg = |x: i64, y: i64| {
        x >= 0 && y >= 0 && x < w && y < h && mask.as_raw()[(y * w + x) as usize] >= 128
    };
    let mut out = vec![false; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let (mut any_fg, mut any_bg) = (false, false);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if fg(x + dx, y + dy) {
                        any_fg = true;
                    } else {
                        any_bg = true;
                    }
                }
            }
            out[(y * w + x) as usize] = any_fg && any_bg;
        }
    }
    out
}

/// Whether `x` projects onto some camera's silhouette outline.
fn on_rim(cams: &[Camera], outlines: &[Vec<bool>], x: &Vector3<f64>) -> bool {
    cams.iter()
        .zip(outlines)
        .any(|(cam, o)| match cam.project(x) {
            Some(px) if cam.in_image(&px) => {
                o[px.y.round() as usize * cam.width as usize + px.x.round() as usize]
            }
            _ => false,
        })
}

/// Puts back the carved voxels whose carving uncovers a silhouette pixel: a pixel inside
/// a camera's silhouette that some hull voxel covers and no refined voxel does. A voxel covers
/// the square of pixels around its centre's projection, one pixel narrower on each side than
/// the voxel appears (so pixels at the edge of a projection count as uncovered: the meshed
/// surface's outline lies between voxel centres). Where the hull explained a silhouette, the
/// refined volume still does.
///
/// With `core_radius` r > 0 only pixels whose (2r+1)-square is wholly uncovered count (the
/// cores of what the cut uncovered), so slivers along outlines stay carved.
fn keep_silhouettes(
    grid: &GridSpec,
    hull: &[bool],
    refined: &mut [bool],
    cams: &[Camera],
    silhouettes: &[image::GrayImage],
    core_radius: usize,
) {
    let hull_voxels: Vec<usize> = (0..grid.len()).filter(|&i| hull[i]).collect();
    // The square of pixels a voxel covers in a camera, clipped to the image.
    let width = |depth: f64, cam: &Camera| grid.voxel * cam.fx.max(cam.fy) / depth;
    let footprint = |cam: &Camera, i: usize| {
        let [x, y, z] = grid.coords(i);
        let (px, depth) = cam.project_with_depth(&grid.centre(x, y, z));
        if depth <= 0.0 {
            return None;
        }
        let r = ((0.5 * width(depth, cam)).floor() as i64 - 1).max(0);
        let (cx, cy) = (px.x.round() as i64, px.y.round() as i64);
        let (w, h) = (cam.width as i64, cam.height as i64);
        let (x0, x1) = ((cx - r).max(0), (cx + r).min(w - 1));
        let (y0, y1) = ((cy - r).max(0), (cy + r).min(h - 1));
        (x0 <= x1 && y0 <= y1).then_some((x0, x1, y0, y1, w))
    };
    let restore: Vec<Vec<usize>> = cams
        .par_iter()
        .zip(silhouettes)
        .map(|(cam, mask)| {
            // Each hull voxel's footprint, projected once. Bit 1 of a pixel: covered by the
            // hull, bit 2: by the refined volume.
            let prints: Vec<_> = hull_voxels.iter().map(|&i| footprint(cam, i)).collect();
            let mut covered = vec![0u8; (cam.width * cam.height) as usize];
            for (&i, print) in hull_voxels.iter().zip(&prints) {
                if let Some((x0, x1, y0, y1, w)) = *print {
                    let bits = if refined[i] { 3 } else { 1 };
                    for y in y0..=y1 {
                        for x in x0..=x1 {
                            covered[(y * w + x) as usize] |= bits;
                        }
                    }
                }
            }
            let uncovered: Vec<bool> = covered
                .iter()
                .zip(mask.as_raw())
                .map(|(&c, &m)| c == 1 && m >= 128)
                .collect();
            let uncovered = erode(
                &uncovered,
                cam.width as usize,
                cam.height as usize,
                core_radius,
            );
            if !uncovered.iter().any(|&u| u) {
                return Vec::new();
            }
            let uncovered = |k: usize| uncovered[k];
            hull_voxels
                .iter()
                .zip(&prints)
                .filter(|(&i, _)| !refined[i])
                .filter(|(_, print)| {
                    print.is_some_and(|(x0, x1, y0, y1, w)| {
                        (y0..=y1).any(|y| (x0..=x1).any(|x| uncovered((y * w + x) as usize)))
                    })
                })
                .map(|(&i, _)| i)
                .collect()
        })
        .collect();
    // With their carved neighbours within 2 voxels too: meshing blurs and smooths the surface
    // over a voxel or two, so a lone restored voxel would still leave the outline's pixels a
    // little short (with 1 voxel the temple kept 98.6343% of the silhouettes against the
    // hull's 98.6348%; with 2, every view's coverage equals the hull's).
    let mut restored = vec![0.0f32; grid.len()];
    for i in restore.into_iter().flatten() {
        restored[i] = 1.0;
    }
    let near_restored = max_filter(grid, &restored, 2);
    for (i, r) in refined.iter_mut().enumerate() {
        *r |= hull[i] && near_restored[i] > 0.0;
    }
}

/// `set` eroded by the (2r+1)-square (separable): true where the whole square is.
fn erode(set: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    if r == 0 {
        return set.to_vec();
    }
    let run = |line: &[bool]| -> Vec<bool> {
        // Length of the run of trues ending at each index, then whether the window fits.
        let n = line.len();
        let mut out = vec![false; n];
        let mut ones = 0usize;
        let mut runs = vec![0usize; n];
        for (i, &v) in line.iter().enumerate() {
            ones = if v { ones + 1 } else { 0 };
            runs[i] = ones;
        }
        for (i, o) in out.iter_mut().enumerate() {
            let end = i + r;
            *o = end < n && runs[end] > 2 * r;
        }
        out
    };
    let mut rows = vec![false; w * h];
    for y in 0..h {
        rows[y * w..(y + 1) * w].copy_from_slice(&run(&set[y * w..(y + 1) * w]));
    }
    let mut out = vec![false; w * h];
    let mut column = vec![false; h];
    for x in 0..w {
        for y in 0..h {
            column[y] = rows[y * w + x];
        }
        for (y, v) in run(&column).into_iter().enumerate() {
            out[y * w + x] = v;
        }
    }
    out
}

/// Maximum of `values` over the (2r+1)^3 box around every voxel (separable).
fn max_filter(grid: &GridSpec, values: &[f32], r: usize) -> Vec<f32> {
    let [nx, ny, _] = grid.dims;
    let mut cur = values.to_vec();
    for (axis, stride) in [(0usize, 1usize), (1, nx), (2, nx * ny)] {
        let n = grid.dims[axis];
        let src = cur.clone();
        cur.par_iter_mut().enumerate().for_each(|(i, v)| {
            let c = (i / stride) % n;
            let lo = c.saturating_sub(r);
            let hi = (c + r).min(n - 1);
            let base = i - c * stride;
            *v = (lo..=hi)
                .map(|k| src[base + k * stride])
                .fold(f32::MIN, f32::max);
        });
    }
    cur
}

/// C(x): the mean of the best pairs' patch correlations around x's projections in the
/// cameras that see x's nearest hull surface point (-1 without a usable pair), and the hull's
/// unit outward normal at x (none where the signed distance is flat).
fn photo_consistency(
    grid: &GridSpec,
    sdf: &[f32],
    cams: &[Camera],
    images: &[GreyImage],
    visibility: &Visibility,
    p: &GraphcutParams,
    x: &Vector3<f64>,
) -> (f64, Option<Vector3<f64>>) {
    let h = grid.voxel;
    // Unit outward normal from the signed distance's gradient (central differences).
    let d = |o: Vector3<f64>| grid.interpolate(sdf, &(x + o), f32::MAX) as f64;
    let grad = Vector3::new(
        d(Vector3::x() * h) - d(-Vector3::x() * h),
        d(Vector3::y() * h) - d(-Vector3::y() * h),
        d(Vector3::z() * h) - d(-Vector3::z() * h),
    );
    if grad.norm().is_nan() || grad.norm() <= 1e-12 || grad.iter().any(|v| v.abs() > 1e6) {
        return (-1.0, None);
    }
    let n = grad.normalize();
    let surface = x - d(Vector3::zeros()) * n;
    (
        patch_consistency(cams, images, visibility, p, h, x, &n, &surface),
        Some(n),
    )
}

/// C at point `x` with patch normal `n`, seen by the cameras that see `surface`
/// ([`hull_visibility`]); -1 without a usable camera pair.
#[allow(clippy::too_many_arguments)]
pub fn patch_consistency(
    cams: &[Camera],
    images: &[GreyImage],
    visibility: &Visibility,
    p: &GraphcutParams,
    h: f64,
    x: &Vector3<f64>,
    n: &Vector3<f64>,
    surface: &Vector3<f64>,
) -> f64 {
    // Patches normalized once (zero mean, unit norm), so each pair's ZNCC is a dot product.
    let len = p.window * p.window;
    let mut dirs: Vec<Vector3<f64>> = Vec::with_capacity(cams.len());
    let mut patches: Vec<f32> = Vec::with_capacity(cams.len() * len);
    let mut seen = Vec::with_capacity(cams.len());
    visibility.seeing(surface, n, &mut seen);
    for &c in &seen {
        let cam = &cams[c];
        let centre = cam.centre();
        let step = p.patch_spacing * h;
        let start = patches.len();
        patches.resize(start + len, 0.0);
        let out = &mut patches[start..];
        let sampled = patch_grid(cam, x, n, step)
            .is_some_and(|(o, du, dv)| images[c].sample_grid(o, du, dv, p.window, out));
        if sampled {
            normalize(out);
            dirs.push((centre - x).normalize());
        } else {
            patches.truncate(start);
        }
    }
    let cos_max = p.max_pair_angle_deg.to_radians().cos();
    let mut scores: Vec<f64> = Vec::new();
    for a in 0..dirs.len() {
        let pa = &patches[a * len..(a + 1) * len];
        for b in a + 1..dirs.len() {
            if dirs[a].dot(&dirs[b]) >= cos_max {
                scores.push(dot(pa, &patches[b * len..(b + 1) * len]) as f64);
            }
        }
    }
    if scores.is_empty() {
        return -1.0;
    }
    scores.sort_by(|a, b| b.total_cmp(a));
    let k = p.best_pairs.min(scores.len());
    scores[..k].iter().sum::<f64>() / k as f64
}

/// Meshes a refined occupancy as the hull stage does, intersected with the hull's solid on
/// the silhouette cones (`hull_on_cones`, the field the hull stage meshed,
/// [`crate::recon::visual_hull::on_the_cones`]): where the cut kept the hull, its surface
/// is the hull's, below the voxel size; where it carved, it lies between the kept and
/// carved voxels; it never lies outside the hull.
pub fn mesh(
    grid: &GridSpec,
    occupied: &[bool],
    hull_on_cones: &[f32],
    smoothing: usize,
) -> (Vec<f32>, TriMesh) {
    use crate::recon::visual_hull::box_blur_3d;
    let mut sdf = box_blur_3d(
        grid,
        &crate::geometry::distance::signed_distance(grid, occupied),
    );
    let field: Vec<f32> = sdf
        .iter()
        .zip(hull_on_cones)
        .map(|(&cut, &hull)| cut.max(hull))
        .collect();
    let mut m = crate::recon::visual_hull::mesh_sdf(grid, &field);
    crate::geometry::smooth::taubin(&mut m, smoothing);
    crate::recon::visual_hull::with_occupancy_sign(&mut sdf, occupied);
    (sdf, m)
}

/// Which cameras see a point of a surface whose depth maps are `depth` (voxel size `h`):
/// the point faces the camera and no surface lies more than 1.5 voxels in front of it.
pub fn hull_visibility<'a>(cams: &'a [Camera], depth: &'a [Vec<f32>], h: f64) -> Visibility<'a> {
    Visibility::new(cams, depth, 90.0, 1.5 * h)
}

/// Mean photo-consistency C over a mesh's vertices seen by a usable camera pair (patches on
/// the vertex's tangent plane, spaced as the stage's, `h` the voxel size), and how many
/// vertices that is. Visibility from the mesh's own depth maps.
pub fn mean_vertex_consistency(
    cams: &[Camera],
    images: &[GreyImage],
    mesh: &TriMesh,
    p: &GraphcutParams,
    h: f64,
) -> (f64, usize) {
    let depth = depth_maps(cams, mesh);
    let visibility = hull_visibility(cams, &depth, h);
    let normals = mesh.vertex_normals();
    let scores: Vec<f64> = mesh
        .vertices
        .par_iter()
        .zip(normals.par_iter())
        .map(|(v, n)| patch_consistency(cams, images, &visibility, p, h, v, n, v))
        .filter(|&c| c > -1.0)
        .collect();
    (
        scores.iter().sum::<f64>() / scores.len().max(1) as f64,
        scores.len(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erosion_keeps_only_wide_cores() {
        // A 7-wide band (x 0..7) and a 3-wide sliver (x 9..12) in a 12x12 image.
        let (w, h) = (12, 12);
        let set: Vec<bool> = (0..w * h).map(|k| k % w < 7 || k % w >= 9).collect();
        let e = erode(&set, w, h, 2);
        for y in 0..h {
            for x in 0..w {
                // The band's core, away from the image's border by the radius.
                let core = (2..h - 2).contains(&y) && (2..5).contains(&x);
                assert_eq!(e[y * w + x], core, "({x}, {y})");
            }
        }
        assert_eq!(erode(&set, w, h, 0), set);
    }
}
