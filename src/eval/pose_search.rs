//! `pipeline pose-search`: is a flagged frame's pose wrong, or does the model miss shape?
//!
//! From a fitted frame's pose, a compass search looks for a pose whose posed model
//! explains the frame's silhouettes better: a higher worst-camera IoU, measured exactly as
//! the fit's health check measures it (fit.csv's `iou_worst`; README "Reading the fit's
//! health"). Each sweep tries every bone turned both ways about each of its three axes,
//! and the root moved both ways along each world axis, keeping each try that raises the
//! worst IoU; when a sweep keeps none, the step halves, from [`STEPS_DEG`]'s first to its
//! last. Deterministic: the same cache gives the same answer.
//!
//! Reading the answer: a worst IoU found well above the fitted one means that a pose near
//! the fit explains the silhouettes better, so the fit's pose is wrong there (the joints
//! that moved say where). A search that finds little says that nothing near the fit does
//! better: what the model misses is shape (a dress, hair) or lies far from the fit. The
//! search is local: it bounds from below what the silhouettes allow nearby.

use crate::error::Result;
use crate::runner::Job;
use crate::skeleton::pose::PosedBones;
use crate::skeleton::Pose;
use crate::stages::fit::FrameSilhouettes;
use nalgebra::{Rotation3, Vector3};
use std::fmt::Write as _;

/// The turns tried, degrees, largest first; the root moves [`ROOT_STEP_PER_DEGREE`] per
/// degree of turn.
const STEPS_DEG: [f64; 4] = [20.0, 10.0, 5.0, 2.5];
/// A root move per degree of the current turn, metres (4 cm at 20 degrees).
const ROOT_STEP_PER_DEGREE: f64 = 0.002;
/// A rise of the worst IoU beyond this says the fit's pose is off (twice the margin by
/// which the silhouettes overrule the fit's score in recovery).
const CLEAR_GAIN: f64 = 0.01;
/// Joints that moved less than this are not listed, metres.
const LISTED_MOTION: f64 = 0.02;

/// What the search found.
#[derive(Debug, Clone)]
pub struct SearchResult {
    /// Per camera, the fitted pose's IoU and the found pose's.
    pub fitted: Vec<f64>,
    pub found: Vec<f64>,
    /// The pose found (the fitted pose when no try did better).
    pub pose: Pose,
    /// Bones whose head or tail moved more than [`LISTED_MOTION`], with the larger of the
    /// two motions in metres, largest first.
    pub moved: Vec<(String, f64)>,
    /// Tries made (at most the budget), and how many were kept.
    pub tries: usize,
    pub kept: usize,
}

/// The worst of per-camera IoUs, and its camera's index (as the health check reports them).
pub fn worst(ious: &[f64]) -> (f64, usize) {
    let h = crate::fit::health::summarize(ious, 0.0);
    (h.iou_worst, h.iou_worst_camera)
}

/// Searches from `judge`'s fitted pose with at most `tries` posed-model IoUs; `progress` is
/// told after each try how many were made and the best worst IoU so far.
pub fn search(
    judge: &FrameSilhouettes,
    tries: usize,
    progress: &dyn Fn(usize, f64),
) -> SearchResult {
    let fitted = judge.ious(&judge.fitted);
    let bones = judge.fitted.rotations.len();
    let (mut pose, mut best) = (judge.fitted.clone(), worst(&fitted).0);
    let (mut made, mut kept) = (0, 0);
    'steps: for step_deg in STEPS_DEG {
        let (turn, shift) = (step_deg.to_radians(), step_deg * ROOT_STEP_PER_DEGREE);
        loop {
            let mut improved = false;
            // Bones 0..bones turn about their axes; index `bones` moves the root.
            for b in 0..=bones {
                for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
                    for sign in [1.0, -1.0] {
                        if made == tries {
                            break 'steps;
                        }
                        let mut candidate = pose.clone();
                        if b < bones {
                            candidate.rotations[b] *= Rotation3::new(axis * (sign * turn));
                        } else {
                            candidate.translation += axis * (sign * shift);
                        }
                        made += 1;
                        let w = worst(&judge.ious(&candidate)).0;
                        let better = w > best;
                        if better {
                            (best, pose) = (w, candidate);
                            kept += 1;
                            improved = true;
                        }
                        progress(made, best);
                        if better {
                            break; // the other sign would undo it
                        }
                    }
                }
            }
            if !improved {
                break;
            }
        }
    }
    let found = judge.ious(&pose);
    let skeleton = &judge.model.skeleton;
    let (a, b) = (
        PosedBones::new(skeleton, &judge.fitted),
        PosedBones::new(skeleton, &pose),
    );
    let mut moved: Vec<(String, f64)> = skeleton
        .bones
        .iter()
        .enumerate()
        .map(|(i, bone)| {
            let m = (a.heads[i] - b.heads[i])
                .norm()
                .max((a.tails[i] - b.tails[i]).norm());
            (bone.name.clone(), m)
        })
        .filter(|x| x.1 > LISTED_MOTION)
        .collect();
    moved.sort_by(|x, y| y.1.total_cmp(&x.1));
    SearchResult {
        fitted,
        found,
        pose,
        moved,
        tries: made,
        kept,
    }
}

/// `pipeline pose-search`: the search on `frame` of `job`, as a table.
pub fn report(job: &Job, frame: u32, tries: usize) -> Result<String> {
    // What it reads must be what `run` would reuse: a stale, damaged or hand-edited
    // artifact is refused by name, never searched from.
    job.require_cached(&[
        crate::artifacts::fitted::STAGE,
        crate::artifacts::body_model::STAGE,
        crate::artifacts::observation::STAGE,
        crate::artifacts::silhouettes::STAGE,
    ])?;
    let ctx = job.context();
    let judge = FrameSilhouettes::load(&ctx, frame)?;
    let started = std::time::Instant::now();
    // Drawn on stderr, hidden when that is not a terminal.
    let bar = indicatif::ProgressBar::new(tries as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "pose-search [{bar:30}] {pos}/{len} poses at most, worst IoU {msg} ({elapsed})",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let r = search(&judge, tries, &|made, best| {
        bar.set_position(made as u64);
        bar.set_message(format!("{best:.4}"));
    });
    bar.finish_and_clear();
    let secs = started.elapsed().as_secs_f64();
    let names = judge.camera_names();
    let mut out = format!(
        "pose search, frame {frame}: {} tries from the fitted pose, {} kept, {secs:.1} s\n  \
         camera    fitted   found\n",
        r.tries, r.kept
    );
    for (i, name) in names.iter().enumerate() {
        let _ = writeln!(out, "  {name:<8} {:>7.4} {:>7.4}", r.fitted[i], r.found[i]);
    }
    let ((wf, cf), (wn, cn)) = (worst(&r.fitted), worst(&r.found));
    let _ = writeln!(
        out,
        "  worst     {wf:.4} ({})  ->  {wn:.4} ({})",
        names[cf], names[cn]
    );
    let _ = writeln!(
        out,
        "{}",
        if wn - wf > CLEAR_GAIN {
            "  the silhouettes ask for another pose: the fit is off where joints moved"
        } else {
            "  no pose near the fit explains the silhouettes better by more than 0.01"
        }
    );
    if r.moved.is_empty() {
        let _ = writeln!(out, "  no joint moved more than 2 cm");
    } else {
        let list: Vec<String> = r
            .moved
            .iter()
            .map(|(n, m)| format!("{n} {:.1} cm", 100.0 * m))
            .collect();
        let _ = writeln!(out, "  joints moved: {}", list.join(", "));
    }
    Ok(out)
}
