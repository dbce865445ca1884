//! Recovery of a tracked frame whose fit lost a part (README "Reading the fit's health"):
//! when the fitted pose leaves reliable observed surface unexplained, or moves a joint
//! faster than a body moves, the frame is fitted again from other hypotheses; the lowest
//! score ([`super::FitDiagnostics::score`], eq. 4 without rho_c) wins, unless the frame's
//! silhouettes clearly prefer the other fit ([`judged`]).
//!
//! The hypotheses, each a start for a full fit:
//! - **straightened**: every end bone (a hand, a foot, the head: a bone without children)
//!   back at the reference pose's joint angle. A hand folded back onto its forearm, which
//!   rho_c then hides, leaves its true surface unexplained; on the humanoid's dance the
//!   right hand so folded as the arms crossed, 30 cm off for 29 frames.
//! - **held**: every end bone back at its angle in the previous frame: a hand that folded
//!   in this frame's fit only. On the masks-only humanoid (t13) the fold fills the hull's
//!   phantom volume, so it scores better than the straightened hand and the held one; the
//!   silhouettes choose the held hand, within 3 cm of the truth.
//! - **mirrored**: the two limbs of a left/right pair (bones whose names differ only by
//!   `l`/`r` or `left`/`right`) swap their joint angles, mirrored through the body's
//!   left-right plane: the limb swaps of fast crossing motion.

use super::pairs::Prepared;
use super::{FitDiagnostics, FitResult, FitStatus, Fitter, Probe};
use crate::skeleton::sides::{is_left, is_left_token, other_side};
use crate::skeleton::{Pose, Skeleton};
use nalgebra::{Matrix3, Rotation3, Vector3};

/// A start that recovery tries.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Hypothesis {
    /// Its name in fit.csv's `recovery` column.
    pub name: String,
    pub start: Pose,
}

impl Fitter<'_> {
    /// Why `fit` (from the previous frame's `previous`) needs recovery, if it does: the
    /// unexplained observed surface above `fit.health.unexplained_cm2` (where rho_p is
    /// photo-consistency), two parts overlapping deeper than
    /// `fit.health.interpenetration_cm`, an end bone swung further than
    /// `fit.health.bend_deg`, or a joint moved
    /// farther than the fastest plausible motion allows between two frames.
    pub(super) fn needs_recovery(&self, fit: &FitResult, previous: &Pose) -> Option<&'static str> {
        let area = unexplained_cm2(&fit.diagnostics, self.params.sample_spacing);
        if self.photo_consistent && area >= self.params.health.unexplained_cm2 {
            return Some("unexplained");
        }
        let overlap = self
            .capsules
            .deepest(self.model, &fit.pose)
            .map_or(0.0, |x| x.2);
        if 100.0 * overlap >= self.params.health.interpenetration_cm {
            return Some("interpenetration");
        }
        let bend = super::health::sharpest_end_bend(&self.model.skeleton, &fit.pose);
        if bend > self.params.health.bend_deg {
            return Some("bent_joint");
        }
        let step = self.max_joint_step?;
        (super::joint_motion(self.model, previous, &fit.pose) > step).then_some("fast_joint")
    }

    /// Fits `prepared` again from the most promising recovery hypothesis of `best` and
    /// keeps the better of the two ([`judged`]); `diagnostics.recovery` names the
    /// hypothesis that won (`kept` when none did), and the rounds of every start are
    /// counted.
    ///
    /// Every hypothesis is screened with [`SCREEN_ROUNDS`] rounds; only the lowest score
    /// goes on to a full fit. On the humanoid's dance the screen's scores after 1 and 3
    /// rounds ranked the hypotheses as their full fits did; 2 rounds cut the recovered
    /// frame's time from 3.3 to 2.5 times its first fit's.
    pub(super) fn recover(
        &self,
        prepared: &Prepared,
        best: FitResult,
        previous: &Pose,
        cap: usize,
        silhouettes: Option<&dyn SilhouetteScore>,
        probe: &Probe,
    ) -> FitResult {
        let mut best = best;
        best.diagnostics.recovery = Some("kept".to_string());
        let screened = hypotheses(&self.model.skeleton, &best.pose, previous)
            .into_iter()
            .map(|h| {
                let mut r = self.fit_prepared(prepared, &h.start, SCREEN_ROUNDS, probe);
                r.diagnostics.recovery = Some(h.name);
                r
            })
            .reduce(super::tracking::better);
        let Some(screened) = screened else {
            return best;
        };
        let r = if screened.diagnostics.status == FitStatus::Converged {
            screened
        } else {
            let mut r = self.fit_prepared(prepared, &screened.pose, cap, probe);
            r.diagnostics.recovery = screened.diagnostics.recovery.clone();
            r.diagnostics.iterations += screened.diagnostics.iterations;
            r.diagnostics.lm_steps += screened.diagnostics.lm_steps;
            r
        };
        // Both count the rounds of both (the screen's already count every start's).
        match silhouettes {
            Some(s) => judged(best, r, s),
            None => super::tracking::better(best, r),
        }
    }
}

/// A frame's silhouettes, as a judge of poses: the worst camera's IoU of the model posed at
/// `pose` with the frame's masks (the health check's measure, README "Reading the fit's
/// health"); `None` when the masks cannot be read.
pub trait SilhouetteScore {
    fn worst_iou(&self, pose: &Pose) -> Option<f64>;
}

/// Two fits' worst-camera IoUs must differ by more than this for the silhouettes to decide
/// between them; closer, the lower score does. Half a percent: on the masks-only humanoid's
/// folded hand (t13) the straightened fit's IoU is 0.938 against the fold's 0.928.
pub const SILHOUETTE_MARGIN: f64 = 0.005;

/// Appended to fit.csv's `recovery` when the silhouettes chose against the score (the
/// observed surface and the masks disagree about the frame; on the masks-only humanoid's
/// t13 the masks were right).
pub const BY_SILHOUETTES: &str = " by silhouettes";

/// Of the fit kept (`kept`) and the recovered one (`recovered`), the one whose posed model
/// explains the silhouettes better by more than [`SILHOUETTE_MARGIN`], else the lower score
/// ([`super::tracking::better`]), with the rounds of both. The score measures the observed
/// surface, which on a masks-only capture is the hull with its phantom volumes: there a
/// hand folded into a phantom can score better than the straightened hand the silhouettes
/// show. When the silhouettes overrule the score, the winner's `recovery` says so
/// ([`BY_SILHOUETTES`]).
fn judged(kept: FitResult, recovered: FitResult, silhouettes: &dyn SilhouetteScore) -> FitResult {
    let Some(take_recovered) = prefers_second(silhouettes, &kept.pose, &recovered.pose) else {
        return super::tracking::better(kept, recovered);
    };
    let score_prefers_recovered = recovered.diagnostics.score < kept.diagnostics.score;
    let mut best = super::tracking::pick(kept, recovered, take_recovered);
    if take_recovered != score_prefers_recovered {
        if let Some(name) = best.diagnostics.recovery.as_mut() {
            name.push_str(BY_SILHOUETTES);
        }
    }
    best
}

/// Whether the silhouettes prefer pose `b` to pose `a` (`Some(true)`) or `a` to `b`
/// (`Some(false)`): their worst-camera IoUs differ by more than [`SILHOUETTE_MARGIN`].
/// `None` when they lie closer or cannot be read.
pub(super) fn prefers_second(
    silhouettes: &dyn SilhouetteScore,
    a: &Pose,
    b: &Pose,
) -> Option<bool> {
    match (silhouettes.worst_iou(a), silhouettes.worst_iou(b)) {
        (Some(x), Some(y)) if y > x + SILHOUETTE_MARGIN => Some(true),
        (Some(x), Some(y)) if x > y + SILHOUETTE_MARGIN => Some(false),
        _ => None,
    }
}

/// Rounds each recovery hypothesis is fitted before the most promising one goes on.
const SCREEN_ROUNDS: usize = 2;

/// The reliable observed surface a fit left unexplained, cm^2: one thinned observed vertex
/// per `sample_spacing` squared (metres; taken as 1 cm when the observation is not
/// thinned).
pub fn unexplained_cm2(diagnostics: &FitDiagnostics, sample_spacing: f64) -> f64 {
    let spacing_cm = 100.0 * sample_spacing.max(0.01);
    diagnostics.unexplained.vertices as f64 * spacing_cm * spacing_cm
}

/// The recovery hypotheses of `pose`, fitted from the `previous` frame's pose
/// ([`Hypothesis`]); none that equals `pose`, nor two alike.
pub(super) fn hypotheses(skeleton: &Skeleton, pose: &Pose, previous: &Pose) -> Vec<Hypothesis> {
    let children = skeleton.children();
    let (mut straightened, mut held) = (pose.clone(), pose.clone());
    for (b, c) in children.iter().enumerate() {
        if c.is_empty() {
            straightened.rotations[b] = Rotation3::identity();
            held.rotations[b] = previous.rotations[b];
        }
    }
    let mut out = Vec::new();
    if straightened != *pose {
        out.push(Hypothesis {
            name: "straightened".to_string(),
            start: straightened.clone(),
        });
    }
    if held != *pose && held != straightened {
        out.push(Hypothesis {
            name: "held".to_string(),
            start: held,
        });
    }
    for limb in mirrored_limbs(skeleton) {
        let mut start = pose.clone();
        for &(l, r) in &limb.pairs {
            start.rotations[l] = mirror(&limb.reflection, &pose.rotations[r]);
            start.rotations[r] = mirror(&limb.reflection, &pose.rotations[l]);
        }
        out.push(Hypothesis {
            name: format!("mirrored {}", limb.name),
            start,
        });
    }
    out
}

/// A left/right pair of limbs: the bone pairs of the two subtrees, and the reflection
/// through the plane between them at the reference frame.
#[derive(Debug, Clone)]
struct MirroredLimb {
    /// The limb's name: its top bone's name without the side.
    name: String,
    /// (left bone, right bone), the top pair first.
    pairs: Vec<(usize, usize)>,
    /// I - 2 n n^T, n the unit vector between the two top bones' heads.
    reflection: Matrix3<f64>,
}

/// The rotation `r` seen in a mirror: `M r M` (a rotation again, as M M = I).
fn mirror(reflection: &Matrix3<f64>, r: &Rotation3<f64>) -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(reflection * r.matrix() * reflection)
}

/// The skeleton's left/right limb pairs: a left bone whose other side exists and whose
/// parent has no side (or is not paired), with every paired bone below them.
fn mirrored_limbs(skeleton: &Skeleton) -> Vec<MirroredLimb> {
    let bones = &skeleton.bones;
    let partner = |b: usize| other_side(&bones[b].name).and_then(|n| skeleton.bone_index(&n));
    let children = skeleton.children();
    let mut limbs = Vec::new();
    for (l, bone) in bones.iter().enumerate() {
        let Some(r) = partner(l) else { continue };
        let parent_paired = bone.parent.is_some_and(|p| partner(p).is_some());
        if !is_left(&bone.name) || parent_paired {
            continue;
        }
        let across = bones[l].head - bones[r].head;
        if across.norm() < 1e-9 {
            continue;
        }
        let n: Vector3<f64> = across.normalize();
        // The two subtrees walked side by side, matching children by their other side.
        let mut pairs = vec![(l, r)];
        let mut i = 0;
        while i < pairs.len() {
            let (a, b) = pairs[i];
            for &c in &children[a] {
                if let Some(d) = partner(c).filter(|d| children[b].contains(d)) {
                    pairs.push((c, d));
                }
            }
            i += 1;
        }
        let name = bone
            .name
            .split(['_', '.', '-', ' '])
            .filter(|t| !is_left_token(t))
            .collect::<Vec<_>>()
            .join("_");
        limbs.push(MirroredLimb {
            name,
            pairs,
            reflection: Matrix3::identity() - 2.0 * n * n.transpose(),
        });
    }
    limbs
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::PosedBones;

    /// A judge that knows each pose's IoU by its root's x.
    struct ByRootX;
    impl SilhouetteScore for ByRootX {
        fn worst_iou(&self, pose: &Pose) -> Option<f64> {
            Some(pose.translation.x)
        }
    }

    fn fit_with(iou: f64, score: f64, recovery: &str) -> FitResult {
        let mut pose = Pose::rest(2);
        pose.translation.x = iou;
        let mut diagnostics = FitDiagnostics::unfitted(FitStatus::Converged, 10);
        (diagnostics.score, diagnostics.iterations) = (score, 3);
        diagnostics.recovery = Some(recovery.to_string());
        FitResult { pose, diagnostics }
    }

    /// The silhouettes decide beyond their margin, and say so when they overrule the
    /// score; within it the score decides. Either way the rounds of both count.
    #[test]
    fn silhouettes_overrule_the_score_beyond_their_margin() {
        let won = |kept, recovered| {
            let r = judged(kept, recovered, &ByRootX);
            (r.diagnostics.recovery.unwrap(), r.diagnostics.iterations)
        };
        let overruled = won(
            fit_with(0.90, 1.0, "kept"),
            fit_with(0.92, 2.0, "straightened"),
        );
        assert_eq!(overruled, ("straightened by silhouettes".to_string(), 6));
        let agreed = won(
            fit_with(0.90, 2.0, "kept"),
            fit_with(0.92, 1.0, "straightened"),
        );
        assert_eq!(agreed.0, "straightened");
        let close = won(
            fit_with(0.90, 1.0, "kept"),
            fit_with(0.904, 2.0, "straightened"),
        );
        assert_eq!(close.0, "kept");
        let kept = won(
            fit_with(0.93, 2.0, "kept"),
            fit_with(0.90, 1.0, "mirrored thigh"),
        );
        assert_eq!(kept.0, "kept by silhouettes");
    }

    #[test]
    fn sides_are_swapped_token_by_token() {
        assert_eq!(other_side("upper_arm_l").as_deref(), Some("upper_arm_r"));
        assert_eq!(other_side("hand.R").as_deref(), Some("hand.L"));
        assert_eq!(other_side("LeftFoot"), None);
        assert_eq!(other_side("left_foot").as_deref(), Some("right_foot"));
        assert_eq!(other_side("spine"), None);
        assert_eq!(other_side("pelvis_low"), None);
    }

    /// On a symmetric humanoid, the mirrored arms' hypothesis puts each arm where the
    /// other was, mirrored: its joints are the mirror images of the other arm's.
    #[test]
    fn mirrored_arms_trade_places() {
        let skeleton = crate::synth::humanoid::skeleton();
        let mut pose = Pose::rest(skeleton.bones.len());
        let l = skeleton.bone_index("upper_arm_l").unwrap();
        let r = skeleton.bone_index("forearm_r").unwrap();
        pose.rotations[l] = Rotation3::new(Vector3::new(0.3, -0.8, 0.2));
        pose.rotations[r] = Rotation3::new(Vector3::new(-0.5, 0.1, 0.9));
        let hypotheses = hypotheses(&skeleton, &pose, &Pose::rest(skeleton.bones.len()));
        let names: Vec<&str> = hypotheses.iter().map(|h| h.name.as_str()).collect();
        assert_eq!(names, ["mirrored upper_arm", "mirrored thigh"]);
        let before = PosedBones::new(&skeleton, &pose);
        let after = PosedBones::new(&skeleton, &hypotheses[0].start);
        let flip = |v: Vector3<f64>| Vector3::new(-v.x, v.y, v.z);
        for side in ["upper_arm", "forearm", "hand"] {
            let a = skeleton.bone_index(&format!("{side}_l")).unwrap();
            let b = skeleton.bone_index(&format!("{side}_r")).unwrap();
            assert!((after.tails[a] - flip(before.tails[b])).norm() < 1e-12);
            assert!((after.tails[b] - flip(before.tails[a])).norm() < 1e-12);
        }
    }
}
