//! A human figure (17 bones, 54 pose parameters, 1.8 m tall, facing -y, z up) moving from an
//! A-pose reference frame through three contact poses: hands on hips, forearms crossed on
//! the chest, and the right hand on the raised left knee. The legs wear plain trousers (a
//! nearly uniform colour, where photo-consistency has nothing to lock onto).
//!
//! Natural length 24 key frames: A-pose t0; hands on hips t4-t5; A-pose t8; forearms
//! crossed t12-t13; A-pose t16; hand on knee t20-t21; back towards A-pose by t23.

use super::body::{segment_segment, Body, Pose};
use super::scene::{self, RingSpec, Scene};
use crate::skeleton::{Bone, Skeleton};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// Number of key frames of the motion.
pub const KEY_FRAMES: usize = 24;

/// Key frames of the dance (`--motion dance`), at 25 per second.
pub const DANCE_KEY_FRAMES: usize = 39;
/// Key frames of the walk (once around its circle).
pub const WALK_KEY_FRAMES: usize = 24;
/// Radius of the walk's circle, metres.
const WALK_RADIUS: f64 = 1.0;

/// How far the dance turns the body about the vertical over its key frames, degrees.
const DANCE_TURN_DEG: f64 = 120.0;
/// Gap the contact poses aim for between touching parts (slightly pressed), metres.
const CONTACT_GAP: f64 = -0.003;

/// (name, parent, head, tail, head radius, tail radius, plain material) at the A-pose.
type BoneDef = (String, Option<String>, [f64; 3], [f64; 3], f64, f64, bool);

/// The humanoid's proportions, as factors of the standard body (1.8 m tall): `legs` scales
/// the hips' height and every leg bone, `torso` the height from the hips to the top of the
/// head, `arms` every arm bone's length, `width` the shoulders' and hips' spacing and every
/// radius. The motion (joint angles) is the same for every body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proportions {
    pub legs: f64,
    pub torso: f64,
    pub arms: f64,
    pub width: f64,
}

impl Default for Proportions {
    fn default() -> Self {
        Proportions {
            legs: 1.0,
            torso: 1.0,
            arms: 1.0,
            width: 1.0,
        }
    }
}

impl Proportions {
    /// A body drawn from `seed` (`pipeline synth --body SEED`): its height within 15% of
    /// the standard's, its arms, legs, torso and width each within a further 7%.
    pub fn from_seed(seed: u64) -> Proportions {
        let mut rng = crate::rng::Rng::new(seed, 9_000_000);
        let mut uniform = |half: f64| 1.0 + half * (2.0 * rng.uniform() - 1.0);
        let height = uniform(0.15);
        Proportions {
            legs: height * uniform(0.07),
            torso: height * uniform(0.07),
            arms: height * uniform(0.07),
            width: height * uniform(0.07),
        }
    }
}

/// The standard body's hip height, metres: below it `Proportions::legs` applies, above it
/// `Proportions::torso`.
const HIP_HEIGHT: f64 = 0.9;

fn bone_defs(p: Proportions) -> Vec<BoneDef> {
    let a = std::f64::consts::FRAC_1_SQRT_2;
    // A standard body's point in this body: heights below the hips by the legs' factor,
    // above them by the torso's, sideways by the width.
    let place = |q: [f64; 3]| -> [f64; 3] {
        let z = if q[2] <= HIP_HEIGHT {
            q[2] * p.legs
        } else {
            HIP_HEIGHT * p.legs + (q[2] - HIP_HEIGHT) * p.torso
        };
        [q[0] * p.width, q[1] * p.width, z]
    };
    // Arm bones from the shoulder along the A-pose's 45 degrees, `from` and `len` in the
    // standard arm's metres.
    let arm = |s: f64, from: f64, len: f64| -> ([f64; 3], [f64; 3]) {
        let shoulder = place([0.19, 0.0, 1.40]);
        let (x0, z0) = (
            shoulder[0] + from * p.arms * a,
            shoulder[2] - from * p.arms * a,
        );
        let len = len * p.arms;
        ([s * x0, 0.0, z0], [s * (x0 + len * a), 0.0, z0 - len * a])
    };
    // Leg and torso points go through `place`; arm points are placed already.
    let def = |name: &str,
               parent: Option<&str>,
               h: [f64; 3],
               t: [f64; 3],
               r0: f64,
               r1: f64,
               plain: bool|
     -> BoneDef {
        let placed = name.contains("arm") || name.starts_with("hand");
        let (h, t) = if placed { (h, t) } else { (place(h), place(t)) };
        (
            name.to_string(),
            parent.map(str::to_string),
            h,
            t,
            r0 * p.width,
            r1 * p.width,
            plain,
        )
    };
    let mut defs: Vec<BoneDef> = vec![
        def(
            "pelvis",
            None,
            [0.0, 0.0, 0.92],
            [0.0, 0.0, 1.05],
            0.14,
            0.13,
            false,
        ),
        def(
            "spine",
            Some("pelvis"),
            [0.0, 0.0, 1.05],
            [0.0, 0.0, 1.25],
            0.125,
            0.13,
            false,
        ),
        def(
            "chest",
            Some("spine"),
            [0.0, 0.0, 1.25],
            [0.0, 0.0, 1.43],
            0.145,
            0.13,
            false,
        ),
        def(
            "neck",
            Some("chest"),
            [0.0, 0.0, 1.43],
            [0.0, 0.0, 1.54],
            0.05,
            0.05,
            false,
        ),
        def(
            "head",
            Some("neck"),
            [0.0, 0.0, 1.54],
            [0.0, 0.0, 1.72],
            0.085,
            0.095,
            false,
        ),
    ];
    for (s, side) in [(1.0, "l"), (-1.0, "r")] {
        let n = |base: &str| format!("{base}_{side}");
        let (h, t) = arm(s, 0.0, 0.28);
        defs.push(def(&n("upper_arm"), Some("chest"), h, t, 0.05, 0.04, false));
        let (h, t) = arm(s, 0.28, 0.26);
        defs.push(def(
            &n("forearm"),
            Some(&n("upper_arm")),
            h,
            t,
            0.04,
            0.03,
            false,
        ));
        let (h, t) = arm(s, 0.54, 0.16);
        defs.push(def(
            &n("hand"),
            Some(&n("forearm")),
            h,
            t,
            0.03,
            0.028,
            false,
        ));
        defs.push(def(
            &n("thigh"),
            Some("pelvis"),
            [s * 0.10, 0.0, 0.90],
            [s * 0.14, 0.0, 0.49],
            0.075,
            0.05,
            true,
        ));
        defs.push(def(
            &n("shin"),
            Some(&n("thigh")),
            [s * 0.14, 0.0, 0.49],
            [s * 0.16, 0.0, 0.09],
            0.05,
            0.04,
            true,
        ));
        defs.push(def(
            &n("foot"),
            Some(&n("shin")),
            [s * 0.16, 0.0, 0.09],
            [s * 0.17, -0.16, 0.035],
            0.04,
            0.035,
            false,
        ));
    }
    defs
}

/// The standard humanoid's skeleton at its reference frame (17 bones; `_l`/`_r` sides).
pub fn skeleton() -> Skeleton {
    standard_body().skeleton
}

/// The standard humanoid's body (1.8 m, A-pose at rest).
pub fn standard_body() -> Body {
    body(Proportions::default())
}

fn body(proportions: Proportions) -> Body {
    let defs = bone_defs(proportions);
    let mut bones: Vec<Bone> = Vec::new();
    for (name, parent, head, tail, ..) in &defs {
        let parent = parent.as_ref().map(|p| {
            bones
                .iter()
                .position(|b| &b.name == p)
                .expect("parent first")
        });
        bones.push(Bone {
            name: name.clone(),
            parent,
            head: Vector3::from(*head),
            tail: Vector3::from(*tail),
        });
    }
    Body {
        skeleton: Skeleton {
            reference_frame: 0,
            bones,
        },
        radii: defs.iter().map(|d| (d.4, d.5)).collect(),
        plain: defs.iter().map(|d| d.6).collect(),
        blend: 0.02,
        skirt: None,
    }
}

/// A skirt for `body`: from 5 cm above the hips to 70% of the way down the thighs, wide
/// enough at the top to hold both thighs' flesh and flaring by 6 cm to the hem.
fn skirt(body: &Body) -> super::body::Skirt {
    let bone = |n: &str| body.skeleton.bone_index(n).expect("known bone");
    let (l, r) = (bone("thigh_l"), bone("thigh_r"));
    let (hl, hr) = (&body.skeleton.bones[l], &body.skeleton.bones[r]);
    let centre = 0.5 * (hl.head + hr.head);
    let half_width = 0.5 * (hl.head - hr.head).norm();
    let thigh = body.radii[l].0.max(body.radii[r].0);
    let knee = 0.5 * (hl.tail.z + hr.tail.z);
    let top = centre + Vector3::z() * 0.05;
    let length = 0.05 + 0.7 * (centre.z - knee);
    let radius = half_width + thigh + 0.01;
    super::body::Skirt {
        top,
        length,
        radii: (radius, radius + 0.06),
    }
}

/// Poses are built bone by bone from world directions.
struct PoseBuilder<'a> {
    body: &'a Body,
    pose: Pose,
}

impl<'a> PoseBuilder<'a> {
    fn new(body: &'a Body) -> Self {
        PoseBuilder {
            body,
            pose: Pose::rest(body.skeleton.bones.len()),
        }
    }

    fn bone(&self, name: &str) -> usize {
        self.body.skeleton.bone_index(name).expect("known bone")
    }

    /// Sets bone `name`'s world rotation.
    fn rotate(&mut self, name: &str, r: Rotation3<f64>) {
        let b = self.bone(name);
        self.pose.rotations[b] = r;
    }

    /// Turns bone `name` (minimal rotation from its rest direction) to point along `dir`.
    fn point(&mut self, name: &str, dir: Vector3<f64>) {
        let b = self.bone(name);
        let bone = &self.body.skeleton.bones[b];
        let rest = (bone.tail - bone.head).normalize();
        self.pose.rotations[b] = Rotation3::rotation_between(&rest, &dir.normalize())
            .unwrap_or_else(Rotation3::identity);
    }

    fn joints(&self) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        self.body.joints(&self.pose)
    }

    /// Two-bone IK: places the wrist of side `side`'s arm at `wrist`, the elbow towards
    /// `pole`, and the hand along `hand_dir`.
    fn reach(
        &mut self,
        side: &str,
        wrist: Vector3<f64>,
        pole: Vector3<f64>,
        hand_dir: Vector3<f64>,
    ) {
        let upper = self.bone(&format!("upper_arm_{side}"));
        let fore = self.bone(&format!("forearm_{side}"));
        let l1 = self.body.skeleton.bones[upper].length();
        let l2 = self.body.skeleton.bones[fore].length();
        let shoulder = self.joints()[upper].0;
        let to = wrist - shoulder;
        let d = to.norm().clamp(1e-6, (l1 + l2) * 0.9999);
        let u = to.normalize();
        let v = (pole - pole.dot(&u) * u).normalize();
        let cos_a = ((l1 * l1 + d * d - l2 * l2) / (2.0 * l1 * d)).clamp(-1.0, 1.0);
        let elbow = shoulder + l1 * (cos_a * u + (1.0 - cos_a * cos_a).sqrt() * v);
        let wrist = shoulder + d * u;
        self.point(&format!("upper_arm_{side}"), elbow - shoulder);
        self.point(&format!("forearm_{side}"), wrist - elbow);
        self.point(&format!("hand_{side}"), hand_dir);
    }

    /// Moves the wrist target until the flesh of `part` and `other` is [`CONTACT_GAP`]
    /// apart, re-solving the arm each time.
    fn touch(
        &mut self,
        side: &str,
        mut wrist: Vector3<f64>,
        pole: Vector3<f64>,
        hand_dir: Vector3<f64>,
        part: &str,
        other: &str,
    ) {
        let (a, b) = (self.bone(part), self.bone(other));
        for _ in 0..40 {
            self.reach(side, wrist, pole, hand_dir);
            let j = self.joints();
            let (s, t, _) = segment_segment(&j[a].0, &j[a].1, &j[b].0, &j[b].1);
            let pa = j[a].0 + s * (j[a].1 - j[a].0);
            let pb = j[b].0 + t * (j[b].1 - j[b].0);
            let gap = self.body.flesh_gap(&self.pose, a, b);
            if (gap - CONTACT_GAP).abs() < 2e-4 {
                break;
            }
            // Move along the line joining the closest axis points.
            wrist -= (gap - CONTACT_GAP) * (pa - pb).normalize();
        }
    }
}

fn a_pose(body: &Body) -> Pose {
    Pose::rest(body.skeleton.bones.len())
}

/// Standing with the arms hanging straight at the sides, against the hips.
fn arms_down(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    for (s, side) in [(1.0, "l"), (-1.0, "r")] {
        for part in ["upper_arm", "forearm", "hand"] {
            p.point(&format!("{part}_{side}"), Vector3::new(s * 0.1, 0.0, -1.0));
        }
    }
    p.pose
}

fn hands_on_hips(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    for (s, side) in [(1.0, "l"), (-1.0, "r")] {
        p.touch(
            side,
            Vector3::new(s * 0.18, -0.01, 1.06),
            Vector3::new(s, 0.6, 0.0),
            Vector3::new(0.0, -0.25, -1.0),
            &format!("hand_{side}"),
            "pelvis",
        );
    }
    p.pose
}

fn forearms_crossed(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    // The right forearm lies across the chest; the left crosses over it.
    p.touch(
        "r",
        Vector3::new(0.10, -0.19, 1.26),
        Vector3::new(-1.0, -0.3, -1.0),
        Vector3::new(1.0, -0.1, 0.1),
        "forearm_r",
        "chest",
    );
    let j = p.joints();
    let fr = p.bone("forearm_r");
    let over = 0.5 * (j[fr].0 + j[fr].1);
    p.touch(
        "l",
        over + Vector3::new(-0.12, -0.06, 0.05),
        Vector3::new(1.0, -0.3, -1.0),
        Vector3::new(-1.0, -0.1, 0.1),
        "forearm_l",
        "forearm_r",
    );
    p.pose
}

fn hand_on_knee(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    let lean = |deg: f64| Rotation3::from_axis_angle(&Vector3::x_axis(), deg.to_radians());
    let twist = Rotation3::from_axis_angle(&Vector3::z_axis(), 25f64.to_radians());
    p.rotate("spine", lean(12.0));
    for b in ["chest", "neck", "head"] {
        p.rotate(b, twist * lean(28.0));
    }
    p.point("thigh_l", Vector3::new(0.05, -1.0, 0.05));
    p.point("shin_l", Vector3::new(0.0, -0.15, -1.0));
    p.point("foot_l", Vector3::new(0.0, -1.0, -0.3));
    let j = p.joints();
    let knee = j[p.bone("shin_l")].0;
    p.touch(
        "r",
        knee + Vector3::new(-0.02, 0.10, 0.09),
        Vector3::new(-1.0, 0.3, 0.2),
        Vector3::new(0.05, -1.0, -0.25),
        "hand_r",
        "thigh_l",
    );
    // The left arm rests on the raised thigh's side.
    p.point("upper_arm_l", Vector3::new(0.35, -0.2, -1.0));
    p.point("forearm_l", Vector3::new(0.25, -0.5, -1.0));
    p.point("hand_l", Vector3::new(0.2, -0.4, -1.0));
    p.pose
}

/// Arms straight out to the sides, level with the shoulders.
fn t_pose(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    for (s, side) in [(1.0, "l"), (-1.0, "r")] {
        for part in ["upper_arm", "forearm", "hand"] {
            p.point(&format!("{part}_{side}"), Vector3::new(s, 0.0, 0.0));
        }
    }
    p.pose
}

/// Upper arms out to the sides just below the shoulders, elbows bent so the forearms hang
/// down and a little forward, fists down (an ordinary pose of people told to stand still
/// with their arms away from the body).
fn arms_out_bent(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    for (s, side) in [(1.0, "l"), (-1.0, "r")] {
        p.point(&format!("upper_arm_{side}"), Vector3::new(s, 0.0, -0.35));
        p.point(
            &format!("forearm_{side}"),
            Vector3::new(s * 0.15, -0.2, -1.0),
        );
        p.point(&format!("hand_{side}"), Vector3::new(s * 0.1, -0.1, -1.0));
    }
    p.pose
}

/// Both arms raised over the head, a little apart.
fn arms_overhead(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    for (s, side) in [(1.0, "l"), (-1.0, "r")] {
        p.point(
            &format!("upper_arm_{side}"),
            Vector3::new(s * 0.35, 0.0, 1.0),
        );
        p.point(&format!("forearm_{side}"), Vector3::new(s * 0.2, 0.0, 1.0));
        p.point(&format!("hand_{side}"), Vector3::new(s * 0.15, 0.0, 1.0));
    }
    p.pose
}

/// The right arm held straight forward at shoulder height (the body faces -y), the left
/// hanging at the side.
fn one_arm_forward(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    for part in ["upper_arm", "forearm", "hand"] {
        p.point(&format!("{part}_r"), Vector3::new(-0.1, -1.0, 0.0));
        p.point(&format!("{part}_l"), Vector3::new(0.15, 0.0, -1.0));
    }
    p.pose
}

/// A pose held still over every frame (`pipeline synth --pose`), for testing the skeleton
/// tools on the poses people stand in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum HeldPose {
    /// The arms 45 degrees down from the shoulders (the rest pose).
    APose,
    /// The arms level out to the sides.
    TPose,
    /// The arms hanging at the sides against the hips.
    ArmsDown,
    /// Upper arms out to the sides, elbows bent, forearms and fists down.
    ArmsOutBent,
    /// Both arms raised over the head.
    ArmsOverhead,
    /// The right arm straight forward, the left down.
    OneArmForward,
    /// Both hands on the hips (hands touching the pelvis).
    HandsOnHips,
}

impl HeldPose {
    /// The pose on `body`.
    pub fn build(self, body: &Body) -> Pose {
        match self {
            HeldPose::APose => a_pose(body),
            HeldPose::TPose => t_pose(body),
            HeldPose::ArmsDown => arms_down(body),
            HeldPose::ArmsOutBent => arms_out_bent(body),
            HeldPose::ArmsOverhead => arms_overhead(body),
            HeldPose::OneArmForward => one_arm_forward(body),
            HeldPose::HandsOnHips => hands_on_hips(body),
        }
    }
}

/// The left leg stepping across the right: the thigh forward and inward, the shin down past
/// the right shin, the foot flat.
fn leg_across(body: &Body) -> Pose {
    let mut p = PoseBuilder::new(body);
    p.point("thigh_l", Vector3::new(-0.45, -0.3, -1.0));
    p.point("shin_l", Vector3::new(-0.35, 0.0, -1.0));
    p.point("foot_l", Vector3::new(0.0, -1.0, -0.3));
    // The arms open for balance.
    p.point("upper_arm_l", Vector3::new(1.0, 0.0, -0.6));
    p.point("upper_arm_r", Vector3::new(-1.0, 0.0, -0.6));
    p.pose
}

/// Mid-stride: leg `front` (`l` or `r`) forward, the other back, the arms swinging the
/// other way (the body faces -y).
fn stride(body: &Body, front: &str) -> Pose {
    let mut p = PoseBuilder::new(body);
    let back = if front == "l" { "r" } else { "l" };
    p.point(&format!("thigh_{front}"), Vector3::new(0.0, -0.45, -1.0));
    p.point(&format!("shin_{front}"), Vector3::new(0.0, -0.2, -1.0));
    p.point(&format!("thigh_{back}"), Vector3::new(0.0, 0.35, -1.0));
    p.point(&format!("shin_{back}"), Vector3::new(0.0, 0.6, -1.0));
    for (s, side) in [(1.0, "l"), (-1.0, "r")] {
        let swing = if side == front { 0.4 } else { -0.4 };
        for part in ["upper_arm", "forearm", "hand"] {
            p.point(
                &format!("{part}_{side}"),
                Vector3::new(s * 0.25, swing, -1.0),
            );
        }
    }
    p.pose
}

/// The walk's poses at `frames` evenly spaced times: once around a circle of
/// [`WALK_RADIUS`] counter-clockwise, facing the way it goes, a step every two key frames.
/// The circle starts at the origin in the rest A-pose (the reference frame of the
/// skeleton, facing -y) and its centre lies at +x.
fn walk(body: &Body, frames: usize) -> Vec<Pose> {
    let (rest, left, right) = (a_pose(body), stride(body, "l"), stride(body, "r"));
    scene::sample_times(WALK_KEY_FRAMES, frames)
        .into_iter()
        .map(|t| {
            let angle = std::f64::consts::TAU * t / WALK_KEY_FRAMES as f64;
            let step = 0.5 + 0.5 * (std::f64::consts::PI * t / 2.0).sin();
            // Out of the A-pose over the first key frame.
            let mut pose = blend(&rest, &blend(&left, &right, step), t.min(1.0));
            // Turned by the angle walked: the tangent of the circle stays the body's front.
            let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), angle);
            for r in &mut pose.rotations {
                *r = turn * *r;
            }
            pose.root_translation = Vector3::new(
                WALK_RADIUS * (1.0 - angle.cos()),
                -WALK_RADIUS * angle.sin(),
                0.0,
            );
            pose
        })
        .collect()
}

/// Interpolates two poses (per-bone world rotations by slerp, root translation linearly).
fn blend(a: &Pose, b: &Pose, t: f64) -> Pose {
    Pose {
        rotations: a
            .rotations
            .iter()
            .zip(&b.rotations)
            .map(|(ra, rb)| {
                let qa = UnitQuaternion::from_rotation_matrix(ra);
                let qb = UnitQuaternion::from_rotation_matrix(rb);
                qa.slerp(&qb, t).to_rotation_matrix()
            })
            .collect(),
        root_translation: a.root_translation.lerp(&b.root_translation, t),
    }
}

/// A key pose: its time (key frames), the pose, and the bone pairs meant to touch.
type Key<'a> = (f64, &'a Pose, Vec<(usize, usize)>);

/// Builds the humanoid scene with `frames` frames sampled over the motion.
pub fn scene(opts: &super::SynthOptions, frames: usize) -> Scene {
    let (cameras, width, height, seed, motion) = (
        opts.cameras,
        opts.width,
        opts.height,
        opts.seed,
        opts.motion,
    );
    let mut body = body(opts.proportions);
    if opts.dress.is_some() {
        body.skirt = Some(skirt(&body));
    }
    let bone = |n: &str| body.skeleton.bone_index(n).expect("known bone");
    let down = arms_down(&body);
    let (a, hips, cross, knee, step) = (
        a_pose(&body),
        hands_on_hips(&body),
        forearms_crossed(&body),
        hand_on_knee(&body),
        leg_across(&body),
    );
    // The bone pairs meant to touch in each contact pose.
    let crossed = || {
        vec![
            (bone("forearm_r"), bone("chest")),
            (bone("forearm_l"), bone("forearm_r")),
        ]
    };
    let on_hips = || {
        vec![
            (bone("hand_l"), bone("pelvis")),
            (bone("hand_r"), bone("pelvis")),
        ]
    };
    let on_knee = || vec![(bone("hand_r"), bone("thigh_l"))];
    let held = opts.pose.map(|h| h.build(&body));
    let (keys, key_frames, turn_deg): (Vec<Key>, usize, f64) = match (&held, motion) {
        (Some(pose), _) => {
            let touching = if opts.pose == Some(HeldPose::HandsOnHips) {
                on_hips()
            } else {
                vec![]
            };
            (vec![(0.0, pose, touching)], 1, 0.0)
        }
        (None, super::Motion::Dance) => (
            vec![
                (0.0, &a, vec![]),
                (13.0, &cross, crossed()),
                (26.0, &a, vec![]),
                (32.0, &step, vec![]),
                (38.0, &a, vec![]),
            ],
            DANCE_KEY_FRAMES,
            DANCE_TURN_DEG,
        ),
        (None, super::Motion::ArmsDown) => (
            vec![
                (0.0, &down, vec![]),
                (9.0, &down, vec![]),
                (13.0, &a, vec![]),
                (17.0, &cross, crossed()),
                (18.0, &cross, crossed()),
                (21.0, &a, vec![]),
                (23.0, &a, vec![]),
            ],
            KEY_FRAMES,
            0.0,
        ),
        // Replaced by the walk's own poses below.
        (None, super::Motion::Walk) => (vec![(0.0, &a, vec![])], WALK_KEY_FRAMES, 0.0),
        (None, super::Motion::Default) => (
            vec![
                (0.0, &a, vec![]),
                (4.0, &hips, on_hips()),
                (5.0, &hips, on_hips()),
                (8.0, &a, vec![]),
                (12.0, &cross, crossed()),
                (13.0, &cross, crossed()),
                (16.0, &a, vec![]),
                (20.0, &knee, on_knee()),
                (21.0, &knee, on_knee()),
                (23.0, &a, vec![]),
            ],
            KEY_FRAMES,
            0.0,
        ),
    };
    let mut poses = Vec::new();
    let mut contacts = Vec::new();
    for (f, t) in scene::sample_times(key_frames, frames)
        .into_iter()
        .enumerate()
    {
        let k = keys.iter().rposition(|k| k.0 <= t).unwrap_or(0);
        if (keys[k].0 - t).abs() < 1e-9 || k + 1 == keys.len() {
            poses.push(keys[k].1.clone());
            if (keys[k].0 - t).abs() < 1e-9 {
                contacts.extend(keys[k].2.iter().map(|&(x, y)| (f as u32, x, y)));
            }
        } else {
            let u = (t - keys[k].0) / (keys[k + 1].0 - keys[k].0);
            // Ease in and out between key poses.
            let u = u * u * (3.0 - 2.0 * u);
            poses.push(blend(keys[k].1, keys[k + 1].1, u));
        }
        // The dance turns the whole body about the vertical through the pelvis.
        let last = (key_frames.max(2) - 1) as f64;
        let turn =
            Rotation3::from_axis_angle(&Vector3::z_axis(), (turn_deg * t / last).to_radians());
        let pose = poses.last_mut().expect("pushed");
        for r in &mut pose.rotations {
            *r = turn * *r;
        }
    }
    if motion == super::Motion::Walk && held.is_none() {
        poses = walk(&body, frames);
    }
    let cams = scene::camera_ring(
        &RingSpec {
            count: cameras,
            radius: 4.0,
            heights: vec![1.2, 1.7, 2.4],
            target: Vector3::new(0.0, 0.0, 0.95),
            focal_1024: 1100.0,
            width,
            height,
        },
        seed,
    );
    if motion == super::Motion::ArmsDown && held.is_none() {
        // The reference frame is the A-pose's (key frame 13; the nearest frame, snapped to
        // it, when the frames sampled miss it).
        let times = scene::sample_times(key_frames, frames);
        let reference = (0..times.len())
            .min_by(|&x, &y| (times[x] - 13.0).abs().total_cmp(&(times[y] - 13.0).abs()))
            .unwrap_or(0);
        poses[reference] = a_pose(&body);
        body.skeleton.reference_frame = reference as u32;
    }
    Scene {
        name: "humanoid".into(),
        body,
        poses,
        cameras: cams,
        contacts,
    }
}
