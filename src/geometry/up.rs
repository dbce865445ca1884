//! The world's up direction found from the capture when pipeline.yaml does not give it.
//!
//! Two cues from the cameras alone: the mean of the cameras' image-up directions (people
//! mount cameras upright, so each image's up is near the world's; tilts towards the
//! subject cancel around a ring), and the normal of the plane through the camera centres
//! (a ring at about one height), turned to the side the images call up. Where every
//! camera's image x axis lies in one plane (cameras mounted without roll, whatever their
//! tilt), that plane is level and its normal is the up: exact, where the other two cues
//! carry the cameras' tilts and heights. A third cue, where the person model saw the
//! subject, is the body's standing axis (ankles to shoulders).

use crate::camera::Camera;
use nalgebra::{Matrix3, Vector3};

/// Cues further apart than this, degrees, disagree: the estimate is not to be trusted.
pub const DISAGREEMENT_DEG: f64 = 20.0;

/// The image up and the rig's normal are averaged when within this angle, degrees: their
/// errors tend to cancel (cameras tilted down onto the subject, a ring not quite level: the
/// real dancer's lie 7 degrees to either side of her up, their mean within half a degree).
pub const AVERAGED_DEG: f64 = 30.0;

/// The cameras' image x axes lie in one plane within this, degrees RMS, for that plane to
/// be taken as level (the synthetic rings: 0; the real dancer's 8 cameras: 4.9, rolled).
pub const LEVEL_RMS_DEG: f64 = 1.0;

/// The up direction and the cues it came from (unit vectors, world frame).
#[derive(Debug, Clone, PartialEq)]
pub struct UpEstimate {
    /// The estimate: the level cameras' normal where there is one, else the mean of the
    /// image up and the rig's normal when they lie within [`AVERAGED_DEG`], else the
    /// standing axis where there is one, else the image up.
    pub up: Vector3<f64>,
    /// The normalized sum of the cameras' image-up directions.
    pub image_up: Vector3<f64>,
    /// The normal of the camera centres' plane, if they span one (3 cameras or more, not on
    /// a line), on the image-up side.
    pub rig_normal: Option<Vector3<f64>>,
    /// The subject's standing axis, if given.
    pub standing: Option<Vector3<f64>>,
    /// The normal of the plane the cameras' image x axes lie in, where they lie in one
    /// within [`LEVEL_RMS_DEG`] (3 cameras or more, not all facing one way), on the
    /// image-up side.
    pub level: Option<Vector3<f64>>,
}

impl UpEstimate {
    /// The largest angle between the estimate's cues, degrees (the standing axis counts only
    /// where the cameras' cues disagree: a subject may lean).
    pub fn spread_deg(&self) -> f64 {
        let cameras_agree = self
            .rig_normal
            .is_some_and(|n| angle_deg(&n, &self.image_up) <= AVERAGED_DEG);
        let standing = if cameras_agree { None } else { self.standing };
        let cues: Vec<Vector3<f64>> = [Some(self.image_up), self.rig_normal, standing]
            .into_iter()
            .flatten()
            .collect();
        let mut worst: f64 = 0.0;
        for (i, a) in cues.iter().enumerate() {
            for b in &cues[i + 1..] {
                worst = worst.max(angle_deg(a, b));
            }
        }
        worst
    }

    /// One line on the estimate and its cues, for `pipeline check` and `pipeline skeleton`.
    pub fn describe(&self) -> String {
        let v = |u: &Vector3<f64>| format!("({:+.3}, {:+.3}, {:+.3})", u.x, u.y, u.z);
        let mut cues = vec![format!("the cameras' image up {}", v(&self.image_up))];
        if let Some(n) = &self.rig_normal {
            cues.push(format!("the rig's plane normal {}", v(n)));
        }
        if let Some(l) = &self.level {
            cues.push(format!(
                "the level cameras' normal {} (their image x axes in one plane within {LEVEL_RMS_DEG:.0} \
                 degree, which decides)",
                v(l)
            ));
        }
        if let Some(s) = &self.standing {
            cues.push(format!("the subject's standing axis {}", v(s)));
        }
        format!(
            "up (found, no up given): {}, nearest axis {}, from {}; the cues lie within {:.1} \
             degrees{}",
            v(&self.up),
            nearest_axis(&self.up),
            cues.join(", "),
            self.spread_deg(),
            self.standing.map_or(String::new(), |s| format!(
                "; the subject stands {:.1} degrees from it",
                angle_deg(&s, &self.up)
            ))
        )
    }
}

/// The angle between two directions, degrees.
pub fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.normalize()
        .dot(&b.normalize())
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// The world axis nearest `u`, as pipeline.yaml spells it (`+z`).
pub fn nearest_axis(u: &Vector3<f64>) -> &'static str {
    let (i, _) = u
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .expect("three components");
    match (i, u[i] >= 0.0) {
        (0, true) => "+x",
        (0, false) => "-x",
        (1, true) => "+y",
        (1, false) => "-y",
        (2, true) => "+z",
        _ => "-z",
    }
}

/// Estimates the world's up from `cams` and, if known, the subject's `standing` axis (from
/// the feet towards the head). `None` without cameras.
pub fn estimate(cams: &[Camera], standing: Option<Vector3<f64>>) -> Option<UpEstimate> {
    // A camera's image y axis points down; in the world that is R^T e_y.
    let sum: Vector3<f64> = cams.iter().map(|c| -c.r.transpose() * Vector3::y()).sum();
    let image_up = sum.try_normalize(1e-9)?;
    // The normal's side: the one the images call up, or where the images do not say (rolled
    // cameras), the one the cameras look down from (rigs stand above or at the subject).
    let looking: Vector3<f64> = cams.iter().map(|c| c.r.transpose() * Vector3::z()).sum();
    let rig_normal = plane_normal(cams).map(|n| {
        let side = if n.dot(&image_up).abs() > 0.3 {
            n.dot(&image_up)
        } else {
            -n.dot(&looking)
        };
        if side < 0.0 {
            -n
        } else {
            n
        }
    });
    let standing = standing.and_then(|s| s.try_normalize(1e-9));
    // The cameras' cues first: a subject leans, bends and dances; where they disagree (a
    // rig on one side of the subject), the subject's standing axis decides.
    let level = level_normal(cams).map(|l| if l.dot(&image_up) < 0.0 { -l } else { l });
    let level = level.filter(|l| angle_deg(l, &image_up) <= AVERAGED_DEG);
    let up = match (rig_normal, standing) {
        _ if level.is_some() => level.expect("checked"),
        (Some(n), _) if angle_deg(&n, &image_up) <= AVERAGED_DEG => (n + image_up).normalize(),
        (_, Some(s)) => s,
        // Rolled cameras (a gantry, a camera on its side): a ring's plane is the better cue.
        (Some(n), None) => n,
        _ => image_up,
    };
    Some(UpEstimate {
        up,
        image_up,
        rig_normal,
        standing,
        level,
    })
}

/// The normal of the plane the cameras' image x axes (R^T e_x, world) lie in, if they lie
/// in one within [`LEVEL_RMS_DEG`] and span it (a camera without roll has a level x axis,
/// so the normal is the up whatever the cameras' tilts; cameras all facing one way leave
/// it undetermined).
fn level_normal(cams: &[Camera]) -> Option<Vector3<f64>> {
    if cams.len() < 3 {
        return None;
    }
    let mut m = Matrix3::zeros();
    for c in cams {
        let x = c.r.transpose() * Vector3::x();
        m += x * x.transpose();
    }
    let eig = m.symmetric_eigen();
    let mut order: Vec<usize> = (0..3).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let n = cams.len() as f64;
    // The x axes' RMS angle out of the plane: sin^2 summed is the least eigenvalue.
    let rms = (eig.eigenvalues[order[0]].max(0.0) / n)
        .sqrt()
        .asin()
        .to_degrees();
    // Spanning the plane: the second direction holds a fair share of the axes.
    let spans = eig.eigenvalues[order[1]] >= 0.2 * n;
    (rms <= LEVEL_RMS_DEG && spans).then(|| eig.eigenvectors.column(order[0]).into_owned())
}

/// The normal of the least-squares plane through the camera centres, if they span one
/// (its smallest spread well below the next).
fn plane_normal(cams: &[Camera]) -> Option<Vector3<f64>> {
    if cams.len() < 3 {
        return None;
    }
    let centres: Vec<Vector3<f64>> = cams.iter().map(|c| c.centre()).collect();
    let mean = centres.iter().sum::<Vector3<f64>>() / centres.len() as f64;
    let mut cov = Matrix3::zeros();
    for c in &centres {
        let d = c - mean;
        cov += d * d.transpose();
    }
    let eig = cov.symmetric_eigen();
    let mut order: Vec<usize> = (0..3).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let (least, middle) = (eig.eigenvalues[order[0]], eig.eigenvalues[order[1]]);
    // On a line (the middle spread as small as the least) there is no plane.
    if middle <= 1e-9 || least > 0.25 * middle {
        return None;
    }
    Some(eig.eigenvectors.column(order[0]).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn ring(tilt: Rotation3<f64>, count: usize, heights: Vec<f64>) -> Vec<Camera> {
        crate::synth::scene::camera_ring(
            &crate::synth::scene::RingSpec {
                count,
                radius: 3.0,
                heights,
                target: Vector3::new(0.0, 0.0, 0.9),
                focal_1024: 1100.0,
                width: 640,
                height: 480,
            },
            2,
        )
        .into_iter()
        .map(|mut c| {
            // The world turned by `tilt`: x_new = tilt x, so R_new = R tilt^T and t stays.
            c.r *= tilt.inverse().matrix();
            c
        })
        .collect()
    }

    #[test]
    fn level_cameras_give_the_up_exactly_and_rolled_ones_do_not_decide() {
        let tilt = Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, 0.5)),
            25f64.to_radians(),
        );
        let truth = tilt * Vector3::z();
        let cams = ring(tilt, 8, vec![1.0, 2.0]);
        let e = estimate(&cams, None).unwrap();
        assert!(e.level.is_some(), "{e:?}");
        assert!(angle_deg(&e.up, &truth) < 0.01, "{e:?}");
        // Each camera rolled 4 degrees about its optical axis, alternately: no level plane.
        let rolled: Vec<Camera> = cams
            .into_iter()
            .enumerate()
            .map(|(i, mut c)| {
                let deg: f64 = if i % 2 == 0 { 4.0 } else { -4.0 };
                let roll = Rotation3::from_axis_angle(&Vector3::z_axis(), deg.to_radians());
                c.r = roll.matrix() * c.r;
                c
            })
            .collect();
        let e = estimate(&rolled, None).unwrap();
        assert!(e.level.is_none(), "{e:?}");
        assert!(angle_deg(&e.up, &truth) < 2.0, "{e:?}");
    }

    #[test]
    fn up_is_found_within_a_degree_on_rings_in_any_world() {
        for (axis, angle) in [
            (Vector3::x(), 0.0f64),
            (Vector3::new(1.0, 2.0, 0.5), 25.0),
            (Vector3::y(), 120.0),
        ] {
            let tilt = Rotation3::from_axis_angle(
                &nalgebra::Unit::new_normalize(axis),
                angle.to_radians(),
            );
            let truth = tilt * Vector3::z();
            for (n, heights) in [
                (8, vec![1.0, 2.0]),
                (12, vec![0.8, 1.6, 2.4]),
                (4, vec![1.5]),
            ] {
                let e = estimate(&ring(tilt, n, heights), None).unwrap();
                let err = angle_deg(&e.up, &truth);
                assert!(
                    err < 1.0,
                    "{n} cameras, tilt {angle}: {err} degrees ({e:?})"
                );
                assert!(e.spread_deg() < DISAGREEMENT_DEG, "{e:?}");
            }
        }
        // A leaning subject does not move it; where the cameras disagree, it decides.
        let cams = ring(Rotation3::identity(), 8, vec![1.0, 2.0]);
        let standing = Vector3::new(0.4, 0.0, 1.0);
        let e = estimate(&cams, Some(standing)).unwrap();
        assert!(angle_deg(&e.up, &Vector3::z()) < 1.0, "{e:?}");
        let two = &cams[..2];
        let e = estimate(two, Some(standing)).unwrap();
        assert!(e.rig_normal.is_none());
        assert!(angle_deg(&e.up, &standing) < 1e-6);
        assert_eq!(nearest_axis(&e.up), "+z");
    }
}
