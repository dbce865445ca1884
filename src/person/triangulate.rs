//! Body landmarks in 3D from their 2D positions in several calibrated views: a linear
//! triangulation (DLT on undistorted, normalized coordinates, each view weighted by the
//! landmark's visibility), with the view that disagrees most dropped while it reprojects
//! more than [`MAX_REPROJECTION_PX`] off and at least two views remain: a view that misses
//! or mislabels a joint (left for right, a guess behind the body) does not pull the point.

use super::PersonFrame;
use crate::camera::Camera;
use crate::recon::visual_hull::BoundingBox;
use nalgebra::{Matrix4, Vector2, Vector3};

/// Below this visibility a landmark's 2D position is a guess (hidden or out of view) and is
/// not used.
pub const MIN_VISIBILITY: f64 = 0.5;

/// A view reprojecting a triangulated landmark further than this from its 2D position,
/// pixels, disagrees with the others.
pub const MAX_REPROJECTION_PX: f64 = 25.0;

/// One triangulated landmark.
#[derive(Debug, Clone, PartialEq)]
pub struct Point3 {
    /// World position, metres.
    pub position: Vector3<f64>,
    /// The cameras (indices) whose views made it.
    pub views: Vec<usize>,
    /// Root mean square reprojection error over those views, pixels.
    pub rms_px: f64,
}

/// Each of the 33 landmarks of one frame triangulated, `None` where fewer than two views
/// see it (or agree on it). A view that labels a pair of landmarks the wrong way round (a
/// left knee as the right one, as a person model often does in a side view, where the two
/// nearly overlap and the swap costs few pixels) has that pair swapped first
/// ([`swapped_views`]).
pub fn triangulate_frame(cams: &[Camera], frame: &PersonFrame) -> Vec<Option<Point3>> {
    let mut views: Vec<Option<Vec<[f64; 3]>>> = frame
        .views
        .iter()
        .map(|v| v.found.then(|| v.landmarks.clone()))
        .collect();
    for (left, right) in mirrored_pairs() {
        for c in swapped_views(cams, &views, left, right) {
            if let Some(marks) = &mut views[c] {
                marks.swap(left, right);
            }
        }
    }
    (0..crate::person::LANDMARKS)
        .map(|l| robust(cams, observations(cams, &views, l)))
        .collect()
}

/// One view's judgement of a proposed pair of points: whether it agrees (within
/// [`MAX_REPROJECTION_PX`]), whether its labels are swapped, its reprojection error with the
/// nearer labelling and with the other (px).
type Verdict = (bool, bool, f64, f64);

/// The views whose labels of the pair (`left`, `right`) are the wrong way round. Every two
/// views that see both, with the second's labels as they are and swapped, propose the pair's
/// two points; each view takes the labelling that reprojects nearer to them, and agrees when
/// that is within [`MAX_REPROJECTION_PX`] for both. The proposal most views agree with (then
/// the nearest; three at least) wins, the labelling most of them give is taken as right, and
/// a view is swapped where its own labels lie beyond [`MAX_REPROJECTION_PX`].
fn swapped_views(
    cams: &[Camera],
    views: &[Option<Vec<[f64; 3]>>],
    left: usize,
    right: usize,
) -> Vec<usize> {
    // (camera, left pixel, right pixel) where both are seen.
    let rights = observations(cams, views, right);
    let seen: Vec<(usize, Vector2<f64>, Vector2<f64>)> = observations(cams, views, left)
        .into_iter()
        .filter_map(|(c, pa, _)| rights.iter().find(|o| o.0 == c).map(|o| (c, pa, o.1)))
        .collect();
    // For proposed points (l, r): each view's verdict.
    let judge = |l: &Vector3<f64>, r: &Vector3<f64>| -> Vec<Verdict> {
        seen.iter()
            .map(
                |(c, pa, pb)| match (cams[*c].project(l), cams[*c].project(r)) {
                    (Some(ql), Some(qr)) => {
                        let straight = (pa - ql).norm().max((pb - qr).norm());
                        let swapped = (pa - qr).norm().max((pb - ql).norm());
                        let error = straight.min(swapped);
                        let other = straight.max(swapped);
                        (
                            error <= MAX_REPROJECTION_PX,
                            swapped < straight,
                            error,
                            other,
                        )
                    }
                    _ => (false, false, f64::INFINITY, f64::INFINITY),
                },
            )
            .collect()
    };
    // (views agreeing, their summed error, every view's verdict)
    let mut best: Option<(usize, f64, Vec<Verdict>)> = None;
    for i in 0..seen.len() {
        for j in i + 1..seen.len() {
            for swap in [false, true] {
                let (ci, ai, bi) = seen[i];
                let (cj, aj, bj) = seen[j];
                let (aj, bj) = if swap { (bj, aj) } else { (aj, bj) };
                let (Some(l), Some(r)) = (
                    dlt(cams, &[(ci, ai, 1.0), (cj, aj, 1.0)]),
                    dlt(cams, &[(ci, bi, 1.0), (cj, bj, 1.0)]),
                ) else {
                    continue;
                };
                let verdict = judge(&l, &r);
                let agree = verdict.iter().filter(|v| v.0).count();
                let error: f64 = verdict.iter().filter(|v| v.0).map(|v| v.2).sum();
                if best
                    .as_ref()
                    .is_none_or(|b| agree > b.0 || (agree == b.0 && error < b.1))
                {
                    best = Some((agree, error, verdict));
                }
            }
        }
    }
    // Three views at least must agree, or there is no telling which labels are wrong.
    let Some((_, _, verdict)) = best.filter(|b| b.0 >= 3) else {
        return Vec::new();
    };
    // Most agreeing views keep their labels: the others are the swapped ones, where their
    // own labels are clearly wrong (beyond MAX_REPROJECTION_PX; near-overlapping pairs,
    // where either labelling fits, stay as they are).
    let agreeing: Vec<(usize, bool, f64)> = seen
        .iter()
        .zip(&verdict)
        .filter(|(_, v)| v.0)
        .map(|(s, v)| (s.0, v.1, v.3))
        .collect();
    let flipped = agreeing.iter().filter(|a| a.1).count();
    let majority_flipped = 2 * flipped > agreeing.len();
    agreeing
        .into_iter()
        .filter(|a| a.1 != majority_flipped && a.2 > MAX_REPROJECTION_PX)
        .map(|a| a.0)
        .collect()
}

/// The (left, right) landmark index pairs, by name (`left_*` and `right_*`).
fn mirrored_pairs() -> Vec<(usize, usize)> {
    let names = crate::person::LANDMARK_NAMES;
    names
        .iter()
        .enumerate()
        .filter_map(|(l, n)| {
            let rest = n.strip_prefix("left_")?;
            let r = names
                .iter()
                .position(|m| m.strip_prefix("right_") == Some(rest))?;
            Some((l, r))
        })
        .collect()
}

/// Landmark `l`'s usable observations: (camera, pixel, visibility) in each view that found
/// the person, sees it (visibility at least [`MIN_VISIBILITY`]) and has it inside the image.
fn observations(
    cams: &[Camera],
    views: &[Option<Vec<[f64; 3]>>],
    l: usize,
) -> Vec<(usize, Vector2<f64>, f64)> {
    views
        .iter()
        .enumerate()
        .filter_map(|(c, v)| {
            let [x, y, vis] = v.as_ref()?[l];
            (vis >= MIN_VISIBILITY && cams[c].in_image(&Vector2::new(x, y))).then_some((
                c,
                Vector2::new(x, y),
                vis,
            ))
        })
        .collect()
}

/// Triangulates `obs` (camera, pixel, weight), dropping the worst view while one is off.
fn robust(cams: &[Camera], mut obs: Vec<(usize, Vector2<f64>, f64)>) -> Option<Point3> {
    loop {
        if obs.len() < 2 {
            return None;
        }
        let x = dlt(cams, &obs)?;
        let errors: Vec<f64> = obs
            .iter()
            .map(|(c, px, _)| match cams[*c].project(&x) {
                Some(p) => (p - px).norm(),
                None => f64::INFINITY,
            })
            .collect();
        let (worst, &err) = errors
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .expect("two views or more");
        if err <= MAX_REPROJECTION_PX {
            let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
            return Some(Point3 {
                position: x,
                views: obs.iter().map(|o| o.0).collect(),
                rms_px: rms,
            });
        }
        if obs.len() == 2 {
            return None;
        }
        obs.remove(worst);
    }
}

/// The weighted linear triangulation: the point minimizing the algebraic error of
/// `x × (P X) = 0` over the views, from the smallest eigenvector of the 4x4 normal matrix.
fn dlt(cams: &[Camera], obs: &[(usize, Vector2<f64>, f64)]) -> Option<Vector3<f64>> {
    let mut a = Matrix4::<f64>::zeros();
    for (c, px, w) in obs {
        let cam = &cams[*c];
        let n = cam.pixel_to_normalized(*px);
        // P = [R | t] on normalized coordinates.
        let row = |i: usize| {
            nalgebra::RowVector4::new(cam.r[(i, 0)], cam.r[(i, 1)], cam.r[(i, 2)], cam.t[i])
        };
        let (p0, p1, p2) = (row(0), row(1), row(2));
        for r in [p2 * n.x - p0, p2 * n.y - p1] {
            a += r.transpose() * r * (w * w);
        }
    }
    let eig = a.symmetric_eigen();
    let (i, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))?;
    let v = eig.eigenvectors.column(i);
    (v[3].abs() > 1e-12).then(|| Vector3::new(v[0] / v[3], v[1] / v[3], v[2] / v[3]))
}

/// How far a body reaches beyond its keypoints (the top of the head above the eyes, the
/// fingertips beyond the index knuckles, clothing), metres.
pub const BODY_REACH: f64 = 0.3;

/// The box a person fills, from a frame's triangulated keypoints: their bounding box grown
/// by [`BODY_REACH`], as the visual hull's carving box; `None` with fewer than 4 keypoints
/// (too few to bound a body).
pub fn body_box(points: &[Option<Point3>]) -> Option<BoundingBox> {
    let found: Vec<&Vector3<f64>> = points.iter().flatten().map(|p| &p.position).collect();
    if found.len() < 4 {
        return None;
    }
    let lo = found
        .iter()
        .fold(Vector3::repeat(f64::INFINITY), |a, p| a.inf(p));
    let hi = found
        .iter()
        .fold(Vector3::repeat(f64::NEG_INFINITY), |a, p| a.sup(p));
    Some(BoundingBox {
        min: (lo - Vector3::repeat(BODY_REACH)).into(),
        max: (hi + Vector3::repeat(BODY_REACH)).into(),
    })
}

/// The body's standing axis in a frame, from its feet towards its head: the mean of the
/// ankles to the mean of the shoulders, when all four are triangulated.
pub fn standing_axis(points: &[Option<Point3>]) -> Option<Vector3<f64>> {
    let at = |name: &str| {
        let i = crate::person::LANDMARK_NAMES
            .iter()
            .position(|n| *n == name)?;
        points[i].as_ref().map(|p| p.position)
    };
    let shoulders = (at("left_shoulder")? + at("right_shoulder")?) / 2.0;
    let ankles = (at("left_ankle")? + at("right_ankle")?) / 2.0;
    (shoulders - ankles).try_normalize(1e-9)
}

/// The header of `keypoints3d.csv`.
pub const CSV_HEADER: &str = "frame,landmark,x,y,z,views,rms_reprojection_px";

/// One frame's rows of `keypoints3d.csv` (landmarks no two views agree on are left out):
/// world metres, the number of views, the RMS reprojection error in pixels.
pub fn csv_rows(frame: u32, points: &[Option<Point3>]) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    for (l, p) in points.iter().enumerate() {
        if let Some(p) = p {
            let _ = writeln!(
                out,
                "{frame},{},{:.5},{:.5},{:.5},{},{:.2}",
                crate::person::LANDMARK_NAMES[l],
                p.position.x,
                p.position.y,
                p.position.z,
                p.views.len(),
                p.rms_px
            );
        }
    }
    out
}

/// Per landmark over many frames: how often it was triangulated and its median RMS
/// reprojection error, for the run's summary.
pub fn summary(frames: &[Vec<Option<Point3>>]) -> String {
    let mut rows = Vec::new();
    for l in [0usize, 11, 12, 13, 14, 15, 16, 23, 24, 25, 26, 27, 28] {
        let mut errors: Vec<f64> = frames
            .iter()
            .filter_map(|f| f[l].as_ref().map(|p| p.rms_px))
            .collect();
        errors.sort_by(f64::total_cmp);
        let median = errors.get(errors.len() / 2).copied();
        rows.push(match median {
            Some(m) => format!(
                "{} {:.1} px ({}/{})",
                crate::person::LANDMARK_NAMES[l],
                m,
                errors.len(),
                frames.len()
            ),
            None => format!("{} never", crate::person::LANDMARK_NAMES[l]),
        });
    }
    format!(
        "body keypoints triangulated (median RMS reprojection error, frames): {}",
        rows.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::person::PersonView;

    fn ring() -> Vec<Camera> {
        // Distorted, jittered cameras: the triangulation must undistort.
        crate::synth::scene::camera_ring(
            &crate::synth::scene::RingSpec {
                count: 6,
                radius: 3.0,
                heights: vec![1.0, 2.0],
                target: Vector3::new(0.0, 0.0, 0.9),
                focal_1024: 1100.0,
                width: 640,
                height: 480,
            },
            5,
        )
    }

    fn frame_of(cams: &[Camera], truth: &[Vector3<f64>]) -> PersonFrame {
        PersonFrame {
            views: cams
                .iter()
                .map(|c| PersonView {
                    camera: c.name.clone(),
                    found: true,
                    score: 0.9,
                    unsupported: 0.0,
                    landmarks: (0..crate::person::LANDMARKS)
                        .map(|l| {
                            let p = c.project(&truth[l % truth.len()]).unwrap();
                            [p.x, p.y, 0.9]
                        })
                        .collect(),
                })
                .collect(),
        }
    }

    #[test]
    fn exact_views_give_the_point_and_a_mislabelled_view_is_dropped() {
        let cams = ring();
        let truth = [Vector3::new(0.1, -0.2, 1.0), Vector3::new(-0.15, 0.1, 0.5)];
        let mut frame = frame_of(&cams, &truth);
        let points = triangulate_frame(&cams, &frame);
        let p = points[0].as_ref().unwrap();
        assert!((p.position - truth[0]).norm() < 1e-6 && p.rms_px < 1e-4);
        assert_eq!(p.views.len(), cams.len());
        // Camera 2 labels landmark 0 where landmark 1 is (left for right).
        frame.views[2].landmarks[0] = frame.views[2].landmarks[1];
        // Camera 4 has it hidden.
        frame.views[4].landmarks[0][2] = 0.1;
        let p = triangulate_frame(&cams, &frame)[0].clone().unwrap();
        assert!((p.position - truth[0]).norm() < 1e-6, "{:?}", p.position);
        assert_eq!(p.views, [0, 1, 3, 5]);
    }

    #[test]
    fn views_that_swap_a_left_and_right_pair_are_put_right() {
        let cams = ring();
        // 33 distinct points on a body-sized helix.
        let truth: Vec<Vector3<f64>> = (0..crate::person::LANDMARKS)
            .map(|l| {
                let a = l as f64 * 0.7;
                Vector3::new(0.25 * a.cos(), 0.2 * a.sin(), 0.1 + 0.05 * l as f64)
            })
            .collect();
        let names = crate::person::LANDMARK_NAMES;
        let at = |n: &str| names.iter().position(|m| *m == n).unwrap();
        let (knee_l, knee_r) = (at("left_knee"), at("right_knee"));
        // The knees a body's width apart.
        let mut truth = truth;
        truth[knee_l] = Vector3::new(0.15, 0.0, 0.5);
        truth[knee_r] = Vector3::new(-0.15, 0.0, 0.5);
        let mut frame = frame_of(&cams, &truth);
        // Two of six views take the left knee for the right (dropping them would leave four).
        for c in [1, 4] {
            frame.views[c].landmarks.swap(knee_l, knee_r);
        }
        let points = triangulate_frame(&cams, &frame);
        for k in [knee_l, knee_r] {
            let p = points[k].as_ref().expect("triangulated");
            assert!((p.position - truth[k]).norm() < 1e-6, "{}", names[k]);
            assert_eq!(p.views.len(), cams.len(), "{}", names[k]);
        }
    }
}
