//! The paper's test object: three 1.0 m arms of two bones each joined at a hub (6 bones,
//! 21 pose parameters), about 8 cm thick, filmed by a ring of cameras.
//!
//! Motion over the 19 key frames t0..t18: at t0 the arms lie flat, apart (the reference
//! frame). They then swing down and curl inward, so that the three arms enclose a narrow
//! space beneath the hub that no camera sees (a phantom volume in the visual hull, largest
//! around t6-t8 and t11-t13), until at t9-t10 the lower arms press together: their tips
//! touch and they lie within 2 cm of each other along their whole length, so the faces that
//! touch are missing from every observation (the paper's "heavy contact"); then they open again,
//! symmetrically (frame t mirrors frame 19 - t). The whole object also turns slowly about the
//! vertical axis (2 degrees per frame), so the root moves too.

use super::body::{Body, Pose};
use super::scene::{self, RingSpec, Scene};
use crate::skeleton::{Bone, Skeleton};
use nalgebra::{Rotation3, Unit, Vector3};

/// Centre of the hub where the arms meet, metres.
const HUB: Vector3<f64> = Vector3::new(0.0, 0.0, 1.45);
/// Length of each bone (half an arm), metres.
const BONE: f64 = 0.5;
/// Flesh radii: upper bone (hub, elbow) and lower bone (elbow, tip), metres.
const UPPER_R: (f64, f64) = (0.09, 0.08);
const LOWER_R: (f64, f64) = (0.08, 0.07);
/// Gap left between the arm tips at full curl, metres (they touch within 2 mm).
const TIP_GAP: f64 = 0.002;
/// Number of key frames of the motion.
pub const KEY_FRAMES: usize = 19;
/// Curl amount per key frame (0 flat, 1 lower arms pressed together).
const CURL: [f64; KEY_FRAMES] = [
    0.0, 0.12, 0.25, 0.38, 0.52, 0.65, 0.77, 0.86, 0.94, 1.0, 1.0, 0.94, 0.86, 0.77, 0.65, 0.52,
    0.38, 0.25, 0.12,
];
/// Curl knots and the bone angles below horizontal at them, degrees (the last lower-bone
/// angle is solved so that the tips touch). At full curl the elbows are 18 cm apart, so the
/// 8 cm lower arms hang nearly parallel, 2 cm apart at the elbows and touching at the tips:
/// with the tips alone touching (72 degrees upper), the contact was too light for the
/// baselines to slip as the paper's do (ICP, Ogawara's normal test and rho_c alone stayed
/// within 1.6 cm of the truth).
const CURL_KNOTS: [f64; 4] = [0.0, 0.5, 0.8, 1.0];
const UPPER_DEG: [f64; 4] = [30.0, 55.0, 72.0, 78.0];
const LOWER_DEG: [f64; 3] = [30.0, 72.0, 88.0];
/// Turn about the vertical axis per key frame, degrees.
const YAW_PER_FRAME: f64 = 2.0;

/// Angle of the arms below horizontal in the reference frame t0, degrees.
const REST_DEG: f64 = 30.0;

/// Horizontal direction of arm k.
fn arm_direction(k: usize) -> Vector3<f64> {
    let az = (90.0 + 120.0 * k as f64).to_radians();
    Vector3::new(az.cos(), az.sin(), 0.0)
}

/// Direction of arm k at `deg` degrees below horizontal.
fn arm_direction_down(k: usize, deg: f64) -> Vector3<f64> {
    let a = deg.to_radians();
    a.cos() * arm_direction(k) - a.sin() * Vector3::z()
}

fn body() -> Body {
    let mut bones = Vec::new();
    let mut radii = Vec::new();
    for k in 0..3 {
        let d = arm_direction_down(k, REST_DEG);
        let elbow = HUB + BONE * d;
        bones.push(Bone {
            name: format!("arm{k}_upper"),
            parent: if k == 0 { None } else { Some(0) },
            head: HUB,
            tail: elbow,
        });
        bones.push(Bone {
            name: format!("arm{k}_lower"),
            parent: Some(2 * k),
            head: elbow,
            tail: elbow + BONE * d,
        });
        radii.push(UPPER_R);
        radii.push(LOWER_R);
    }
    Body {
        skeleton: Skeleton {
            reference_frame: 0,
            bones,
        },
        radii,
        plain: vec![false; 6],
        blend: 0.03,
        skirt: None,
    }
}

/// The pose with upper and lower bones bent `upper_deg` and `lower_deg` below horizontal
/// and the whole object turned by `yaw_deg` about the vertical (rotations relative to the
/// rest pose, whose arms are [`REST_DEG`] below horizontal).
fn pose(upper_deg: f64, lower_deg: f64, yaw_deg: f64) -> Pose {
    let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians());
    let mut rotations = Vec::new();
    for k in 0..3 {
        // Turning about d x z by a negative angle tips the arm direction d downwards.
        let axis = Unit::new_normalize(arm_direction(k).cross(&Vector3::z()));
        rotations
            .push(yaw * Rotation3::from_axis_angle(&axis, -(upper_deg - REST_DEG).to_radians()));
        rotations
            .push(yaw * Rotation3::from_axis_angle(&axis, -(lower_deg - REST_DEG).to_radians()));
    }
    Pose {
        rotations,
        root_translation: Vector3::zeros(),
    }
}

/// The lower-bone angle at full curl that leaves [`TIP_GAP`] between the tips.
fn touching_lower_deg(body: &Body) -> f64 {
    let upper = UPPER_DEG[3];
    let (mut lo, mut hi) = (LOWER_DEG[2], 150.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        // More curl brings the tips closer (until they pass each other, beyond `hi`).
        if body.flesh_gap(&pose(upper, mid, 0.0), 1, 3) > TIP_GAP {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Builds the tripod scene with `frames` frames sampled over the motion.
pub fn scene(cameras: usize, width: u32, height: u32, frames: usize, seed: u64) -> Scene {
    let body = body();
    let lower_full = touching_lower_deg(&body);
    let lower = [LOWER_DEG[0], LOWER_DEG[1], LOWER_DEG[2], lower_full];
    let key: Vec<f64> = (0..KEY_FRAMES).map(|k| k as f64).collect();
    let mut poses = Vec::new();
    let mut contacts = Vec::new();
    for (f, t) in scene::sample_times(KEY_FRAMES, frames)
        .into_iter()
        .enumerate()
    {
        let s = scene::interp(&key, &CURL, t);
        poses.push(pose(
            scene::interp(&CURL_KNOTS, &UPPER_DEG, s),
            scene::interp(&CURL_KNOTS, &lower, s),
            YAW_PER_FRAME * t,
        ));
        if s >= 1.0 - 1e-9 {
            for (a, b) in [(1, 3), (3, 5), (1, 5)] {
                contacts.push((f as u32, a, b));
            }
        }
    }
    let cams = scene::camera_ring(
        &RingSpec {
            count: cameras,
            radius: 4.0,
            // Below, level with and above the hub (elevations about -13, +12 and +37 degrees
            // at the ring's radius), so that every surface of the open pose is seen.
            heights: vec![0.5, 2.3, 4.2],
            target: Vector3::new(0.0, 0.0, 1.0),
            focal_1024: 1150.0,
            width,
            height,
        },
        seed,
    );
    Scene {
        name: "tripod".into(),
        body,
        poses,
        cameras: cams,
        contacts,
    }
}
