//! The fit's health per frame, with or without ground truth: how well the posed model
//! explains every camera's silhouette, and how far the skeleton moved since the previous
//! frame. A limb swap, a drift or a fit stuck at the round cap shows here first.
//!
//! The silhouette agreement is the intersection over union of the posed model's projection
//! (its depth map, rasterized at a reduced resolution) with the silhouette sampled at the
//! same pixels, per camera; the row keeps the worst camera, the median over cameras and the
//! worst camera's name.

use crate::camera::Camera;
use crate::geometry::TriMesh;
use crate::skeleton::sides::{is_left, other_side};
use crate::skeleton::{Pose, PosedBones, Skeleton};
use image::GrayImage;
use nalgebra::Vector3;
use rayon::prelude::*;

/// Width of the reduced images the agreement is measured on, pixels (at most).
const HEALTH_WIDTH: u32 = 256;

/// One frame's health figures.
#[derive(Debug, Clone, PartialEq)]
pub struct Health {
    /// The lowest silhouette IoU over the cameras, [0, 1].
    pub iou_worst: f64,
    /// Which camera it is (its index in the calibration).
    pub iou_worst_camera: usize,
    /// The median silhouette IoU over the cameras.
    pub iou_median: f64,
    /// The largest motion of any joint since the previous tracked frame, metres (0 at the
    /// reference frame).
    pub joint_motion: f64,
    /// The reliable observed surface the fit left unexplained, cm^2
    /// ([`crate::fit::unexplained_cm2`]); `None` where rho_p carries no photo-consistency
    /// (masks-only captures: the hull's phantom volumes are observed surface there).
    pub unexplained_cm2: Option<f64>,
    /// The deepest overlap of two parts that do not meet, beyond the reference pose's,
    /// metres (0: none; [`crate::fit::interpenetration`]).
    pub interpenetration: f64,
    /// The sharpest swing of an end bone from its reference direction relative to its
    /// parent, degrees ([`sharpest_end_bend`]).
    pub end_bend_deg: f64,
    /// How far the hips turned from the shoulders about the trunk since the reference
    /// pose, degrees ([`trunk_twist_deg`]).
    pub trunk_twist_deg: f64,
    /// Eq. 4 against the previous tracked frame's (0: unknown).
    pub energy_ratio: f64,
    /// How far an equally good fit of one limb lies, metres
    /// ([`crate::fit::FitDiagnostics::ambiguous`]).
    pub ambiguous: Option<f64>,
}

/// The body model's mesh coarsened for the silhouette check (vertex clustering on a grid of
/// `cell` metres at the rest pose: one vertex per occupied cell, triangles whose corners
/// fall in three different cells): a sixth of the triangles at 2 cm, and a projection that
/// differs from the full mesh's by under a cell at its outline.
pub struct CoarseModel {
    /// The model vertex standing for each cell.
    keep: Vec<usize>,
    /// Triangles over `keep`'s indices.
    triangles: Vec<[u32; 3]>,
}

impl CoarseModel {
    pub fn new(rest: &TriMesh, cell: f64) -> CoarseModel {
        let mut cells: std::collections::HashMap<[i64; 3], u32> = Default::default();
        let mut keep = Vec::new();
        let cluster: Vec<u32> = rest
            .vertices
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let key = [v.x, v.y, v.z].map(|c| (c / cell).floor() as i64);
                *cells.entry(key).or_insert_with(|| {
                    keep.push(i);
                    (keep.len() - 1) as u32
                })
            })
            .collect();
        let triangles = rest
            .triangles
            .iter()
            .map(|t| t.map(|i| cluster[i as usize]))
            .filter(|[a, b, c]| a != b && b != c && a != c)
            .collect();
        CoarseModel { keep, triangles }
    }

    /// The model vertex standing for each coarse vertex.
    pub fn kept(&self) -> &[usize] {
        &self.keep
    }

    /// The coarse mesh's triangles, over [`CoarseModel::kept`]'s indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The coarse mesh at the pose of `posed` (the full model mesh posed).
    pub fn posed(&self, posed: &TriMesh) -> TriMesh {
        self.at(&posed.vertices)
    }

    /// The coarse mesh over `vertices`, the full model's vertices wherever they are (a
    /// posed model, or a surface of the model's topology moved from it).
    pub fn at(&self, vertices: &[Vector3<f64>]) -> TriMesh {
        TriMesh {
            vertices: self.keep.iter().map(|&i| vertices[i]).collect(),
            triangles: self.triangles.clone(),
        }
    }
}

/// The silhouette IoU of `mesh` (the posed model) in every camera against `masks`.
pub fn silhouette_iou(cams: &[Camera], masks: &[GrayImage], mesh: &TriMesh) -> Vec<f64> {
    cams.par_iter()
        .zip(masks)
        .map(|(cam, mask)| {
            let factor = (HEALTH_WIDTH as f64 / cam.width as f64).min(1.0);
            let small = cam.scaled(factor);
            let depth = crate::geometry::raster::depth_map(&small, &mesh.vertices, &mesh.triangles);
            let (w, h) = (small.width as usize, small.height as usize);
            let (mut both, mut either) = (0usize, 0usize);
            for y in 0..h {
                // The full-resolution pixel under this one's centre.
                let my = (((y as f64 + 0.5) / factor) as u32).min(mask.height() - 1);
                for x in 0..w {
                    let mx = (((x as f64 + 0.5) / factor) as u32).min(mask.width() - 1);
                    let model = depth[y * w + x].is_finite();
                    let seen = mask.get_pixel(mx, my).0[0] >= 128;
                    both += (model && seen) as usize;
                    either += (model || seen) as usize;
                }
            }
            if either == 0 {
                1.0 // neither shows anything: they agree
            } else {
                both as f64 / either as f64
            }
        })
        .collect()
}

/// The health of a frame from its per-camera IoUs and its joint motion.
pub fn summarize(iou: &[f64], joint_motion: f64) -> Health {
    let (iou_worst_camera, iou_worst) = iou
        .iter()
        .copied()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 1.0));
    let mut sorted = iou.to_vec();
    sorted.sort_by(f64::total_cmp);
    let iou_median = if sorted.is_empty() {
        1.0
    } else if sorted.len() % 2 == 1 {
        sorted[sorted.len() / 2]
    } else {
        (sorted[sorted.len() / 2 - 1] + sorted[sorted.len() / 2]) / 2.0
    };
    Health {
        iou_worst,
        iou_worst_camera,
        iou_median,
        joint_motion,
        unexplained_cm2: None,
        interpenetration: 0.0,
        end_bend_deg: 0.0,
        trunk_twist_deg: 0.0,
        energy_ratio: 0.0,
        ambiguous: None,
    }
}

/// How far `pose` swings its end bones (bones without children: the hands, the feet, the
/// head) from their reference directions relative to their parents, at most, degrees: for
/// each, the angle between its reference direction d and R d, R its rotation relative to t0
/// in its parent's posed frame (a turn about the bone's own axis does not count). A hand
/// folded back onto its forearm swings further than a wrist moves. 0 without end bones.
pub fn sharpest_end_bend(skeleton: &Skeleton, pose: &Pose) -> f64 {
    skeleton
        .children()
        .iter()
        .enumerate()
        .filter(|(b, c)| c.is_empty() && skeleton.bones[*b].parent.is_some())
        .map(|(b, _)| {
            let bone = &skeleton.bones[b];
            let d = bone.tail - bone.head;
            (pose.rotations[b] * d).angle(&d).to_degrees()
        })
        .fold(0.0, f64::max)
}

/// How far the hips' axis (left hip minus right: the heads of the root's left/right pair
/// of children) turned against the shoulders' (the heads of another bone's left/right
/// pair) about the trunk (from the hips' middle to the shoulders') between the reference
/// pose and `pose`, degrees in [0, 180]; 0 for a skeleton without both pairs. A trunk
/// turns about 45 degrees each way: far beyond that, the pelvis the fit holds faces another
/// way than the body (a dress leaves the hips free to turn).
pub fn trunk_twist_deg(skeleton: &Skeleton, pose: &Pose) -> f64 {
    let names = &skeleton.bones;
    let children = skeleton.children();
    let pair = |bones: &[usize]| {
        let left = bones.iter().copied().find(|&b| is_left(&names[b].name))?;
        let mirror = other_side(&names[left].name)?;
        let right = bones.iter().copied().find(|&b| names[b].name == mirror)?;
        Some((left, right))
    };
    let Some(root) = names.iter().position(|b| b.parent.is_none()) else {
        return 0.0;
    };
    let Some(hips) = pair(&children[root]) else {
        return 0.0;
    };
    let Some(shoulders) = (0..names.len())
        .filter(|&b| b != root && !is_left(&names[b].name))
        .find_map(|b| pair(&children[b]))
    else {
        return 0.0;
    };
    let twist = |pose: &Pose| -> Option<f64> {
        let bones = PosedBones::new(skeleton, pose);
        let (hl, hr) = (bones.heads[hips.0], bones.heads[hips.1]);
        let (sl, sr) = (bones.heads[shoulders.0], bones.heads[shoulders.1]);
        let axis = (0.5 * (sl + sr) - 0.5 * (hl + hr)).try_normalize(1e-9)?;
        let across = |v: Vector3<f64>| v - axis * v.dot(&axis);
        let (h, s) = (across(hl - hr), across(sl - sr));
        Some(h.cross(&s).dot(&axis).atan2(h.dot(&s)))
    };
    let rest = Pose::rest(names.len());
    match (twist(pose), twist(&rest)) {
        (Some(now), Some(then)) => {
            let d = (now - then).rem_euclid(std::f64::consts::TAU);
            d.min(std::f64::consts::TAU - d).to_degrees()
        }
        _ => 0.0,
    }
}

/// How many previous frames make a frame's recent silhouette level.
pub const RECENT_FRAMES: usize = 5;

/// Why a frame is implausible (empty when it is not): `fast_joint` when a joint moved
/// faster than `p.max_joint_speed` at `frame_rate` (not judged when the rate is unknown),
/// `iou_drop` when the worst IoU fell below
/// `p.iou_drop` times the median of `recent` (the previous frames' worst IoU, oldest first;
/// only its last [`RECENT_FRAMES`] count), `iou_drift` when it fell below `p.iou_drift` times
/// `reference` (the reference frame's worst IoU; none at the reference frame), `unexplained` when the fit left at least
/// `p.unexplained_cm2` of reliable observed surface unexplained, `interpenetration` when two
/// parts overlap deeper than `p.interpenetration_cm`, `bent_joint` when an end bone swung
/// more than `p.bend_deg` from its reference direction, `twisted_trunk` when the hips
/// turned more than `p.twist_deg` from the shoulders, `energy_jump` when eq. 4 rose more
/// than `p.energy_jump` times the previous frame's, `ambiguous` when an equally good fit
/// of one limb lies a hand's length away.
pub fn flags(
    h: &Health,
    recent: &[f64],
    reference: Option<f64>,
    p: &super::params::HealthParams,
    frame_rate: Option<f64>,
) -> Vec<&'static str> {
    let mut out = Vec::new();
    if frame_rate.is_some_and(|f| h.joint_motion * f > p.max_joint_speed) {
        out.push("fast_joint");
    }
    let last = &recent[recent.len().saturating_sub(RECENT_FRAMES)..];
    if !last.is_empty() && h.iou_worst < p.iou_drop * summarize(last, 0.0).iou_median {
        out.push("iou_drop");
    }
    if reference.is_some_and(|r| h.iou_worst < p.iou_drift * r) {
        out.push("iou_drift");
    }
    if h.unexplained_cm2.is_some_and(|a| a >= p.unexplained_cm2) {
        out.push("unexplained");
    }
    if 100.0 * h.interpenetration >= p.interpenetration_cm {
        out.push("interpenetration");
    }
    if h.end_bend_deg > p.bend_deg {
        out.push("bent_joint");
    }
    if h.trunk_twist_deg > p.twist_deg {
        out.push("twisted_trunk");
    }
    if h.energy_ratio > p.energy_jump {
        out.push("energy_jump");
    }
    if h.ambiguous.is_some() {
        out.push("ambiguous");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A cube seen by a camera agrees with its own silhouette, and not with a shifted one.
    #[test]
    fn iou_of_a_cube_with_its_own_and_a_shifted_silhouette() {
        let cam = Camera::look_at(
            "c",
            640,
            480,
            600.0,
            Vector3::new(0.0, -3.0, 0.0),
            Vector3::zeros(),
            Vector3::z(),
        );
        // A 0.5 m cube, meshed as the pipeline meshes (outward, counter-clockwise).
        let grid = crate::geometry::grid::GridSpec {
            origin: Vector3::repeat(-0.4),
            voxel: 0.02,
            dims: [41, 41, 41],
        };
        let sdf: Vec<f32> = (0..grid.len())
            .map(|i| {
                let [x, y, z] = grid.coords(i);
                let c = grid.centre(x, y, z);
                (c.x.abs().max(c.y.abs()).max(c.z.abs()) - 0.25) as f32
            })
            .collect();
        let cube = crate::recon::visual_hull::mesh_sdf(&grid, &sdf);
        let silhouette = |dx: f64| {
            GrayImage::from_fn(640, 480, |x, y| {
                let p = nalgebra::Vector2::new(x as f64, y as f64);
                let (ray_origin, dir) = cam.ray(p);
                let hit = (0..200).any(|k| {
                    let q = ray_origin + dir * (2.0 + k as f64 * 0.01) - Vector3::x() * dx;
                    q.iter().all(|v| v.abs() <= 0.25)
                });
                image::Luma([if hit { 255 } else { 0 }])
            })
        };
        let own = silhouette_iou(std::slice::from_ref(&cam), &[silhouette(0.0)], &cube);
        assert!(own[0] > 0.95, "{own:?}");
        let coarse = CoarseModel::new(&cube, 0.06).posed(&cube);
        assert!(coarse.triangles.len() * 4 < cube.triangles.len());
        let own_coarse = silhouette_iou(std::slice::from_ref(&cam), &[silhouette(0.0)], &coarse);
        assert!(own_coarse[0] > 0.9, "{own_coarse:?}");
        let shifted = silhouette_iou(std::slice::from_ref(&cam), &[silhouette(0.25)], &cube);
        // Shifted by half its width: overlap 1/2 of a width, union 3/2.
        assert!((shifted[0] - 1.0 / 3.0).abs() < 0.05, "{shifted:?}");
        let p = crate::fit::params::HealthParams::default();
        let good = summarize(&[0.95, 0.96], 0.1);
        assert!(flags(&good, &[0.96, 0.95, 0.97], Some(0.97), &p, Some(25.0)).is_empty());
        let mut lost = summarize(&[0.7, 0.96], 0.3);
        lost.unexplained_cm2 = Some(12.0);
        lost.interpenetration = 0.08;
        lost.end_bend_deg = 150.0;
        lost.trunk_twist_deg = 100.0;
        lost.energy_ratio = 12.0;
        lost.ambiguous = Some(0.137);
        assert_eq!(
            flags(&lost, &[0.96], Some(0.96), &p, Some(25.0)),
            [
                "fast_joint",
                "iou_drop",
                "iou_drift",
                "unexplained",
                "interpenetration",
                "bent_joint",
                "twisted_trunk",
                "energy_jump",
                "ambiguous"
            ]
        );
        assert_eq!(
            flags(&lost, &[], None, &p, Some(10.0)),
            [
                "unexplained",
                "interpenetration",
                "bent_joint",
                "twisted_trunk",
                "energy_jump",
                "ambiguous"
            ]
        );
        // An unknown frame rate judges no speed.
        assert_eq!(
            flags(&lost, &[], None, &p, None),
            [
                "unexplained",
                "interpenetration",
                "bent_joint",
                "twisted_trunk",
                "energy_jump",
                "ambiguous"
            ]
        );
        // A slow drift: level with the recent frames, far below the reference.
        let drifted = summarize(&[0.8, 0.9], 0.0);
        assert_eq!(
            flags(&drifted, &[0.81, 0.8, 0.8], Some(0.95), &p, Some(25.0)),
            ["iou_drift"]
        );
        let h = summarize(&[0.9, 0.5, 0.8, 0.95], 0.02);
        assert_eq!((h.iou_worst, h.iou_worst_camera), (0.5, 1));
        assert!((h.iou_median - 0.85).abs() < 1e-12);
    }

    /// The humanoid's hips turned against its shoulders by the pelvis (the root, which
    /// carries the whole body) measure nothing; turned by the spine (the upper body alone)
    /// they measure the turn, whichever way, up to 180 degrees.
    #[test]
    fn trunk_twist_is_the_hips_turn_against_the_shoulders() {
        let skeleton = crate::synth::humanoid::skeleton();
        let bone = |name: &str| skeleton.bone_index(name).expect("humanoid bone");
        let turned = |b: usize, deg: f64| {
            let mut pose = Pose::rest(skeleton.bones.len());
            pose.rotations[b] =
                nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), deg.to_radians());
            pose
        };
        assert!(trunk_twist_deg(&skeleton, &Pose::rest(skeleton.bones.len())) < 1e-9);
        assert!(trunk_twist_deg(&skeleton, &turned(bone("pelvis"), 150.0)) < 1e-6);
        for (deg, expect) in [
            (30.0, 30.0),
            (-100.0, 100.0),
            (170.0, 170.0),
            (200.0, 160.0),
        ] {
            let twist = trunk_twist_deg(&skeleton, &turned(bone("spine"), deg));
            assert!((twist - expect).abs() < 1e-6, "{deg}: {twist}");
        }
    }
}
