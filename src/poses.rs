//! poses.csv: pose parameters per frame in the project's own parameterization
//! (`crate::skeleton::pose`): `frame,bone,rx,ry,rz,tx,ty,tz`, one row per frame and bone.
//! `rx ry rz` is the rotation vector (radians) of the bone's rotation relative to the
//! reference frame in its parent's posed frame; `tx ty tz` the root's translation from its
//! reference position (metres), zeros on the other bones' rows.

use crate::error::{Error, Result};
use crate::skeleton::{Pose, Skeleton};
use nalgebra::{Rotation3, Vector3};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// The CSV header line.
pub const HEADER: &str = "frame,bone,rx,ry,rz,tx,ty,tz";

/// The CSV text of `poses` (frame, pose) of `skeleton`.
pub fn to_csv(skeleton: &Skeleton, poses: &[(u32, Pose)]) -> String {
    let mut s = format!("{HEADER}\n");
    for (frame, pose) in poses {
        for (b, bone) in skeleton.bones.iter().enumerate() {
            let r = pose.rotations[b].scaled_axis();
            let t = if b == 0 {
                pose.translation
            } else {
                Vector3::zeros()
            };
            let _ = writeln!(
                s,
                "{frame},{},{:?},{:?},{:?},{:?},{:?},{:?}",
                bone.name, r.x, r.y, r.z, t.x, t.y, t.z
            );
        }
    }
    s
}

/// Writes poses.csv atomically.
pub fn write(path: &Path, skeleton: &Skeleton, poses: &[(u32, Pose)]) -> Result<()> {
    crate::fsutil::write_atomic(path, to_csv(skeleton, poses).as_bytes())
}

/// Parses poses.csv text for `skeleton`: every frame must list every bone once.
pub fn parse(path: &Path, text: &str, skeleton: &Skeleton) -> Result<Vec<(u32, Pose)>> {
    let rows = crate::joints::parse_frame_bone_rows(path, text, HEADER)?;
    let n = skeleton.bones.len();
    let mut frames: BTreeMap<u32, (Pose, Vec<bool>)> = BTreeMap::new();
    for (frame, bone, v) in rows {
        let b = skeleton.bone_index(&bone).ok_or_else(|| {
            Error::invalid(
                path,
                format!("frame {frame}: '{bone}' is not a bone of the skeleton"),
            )
        })?;
        let (pose, seen) = frames
            .entry(frame)
            .or_insert_with(|| (Pose::rest(n), vec![false; n]));
        if std::mem::replace(&mut seen[b], true) {
            return Err(Error::invalid(
                path,
                format!("frame {frame}: bone '{bone}' is listed twice"),
            ));
        }
        pose.rotations[b] = Rotation3::new(Vector3::new(v[0], v[1], v[2]));
        if b == 0 {
            pose.translation = Vector3::new(v[3], v[4], v[5]);
        }
    }
    frames
        .into_iter()
        .map(|(frame, (pose, seen))| match seen.iter().position(|s| !s) {
            Some(b) => Err(Error::invalid(
                path,
                format!(
                    "frame {frame}: bone '{}' has no row",
                    skeleton.bones[b].name
                ),
            )),
            None => Ok((frame, pose)),
        })
        .collect()
}

/// Reads poses.csv for `skeleton`.
pub fn read(path: &Path, skeleton: &Skeleton) -> Result<Vec<(u32, Pose)>> {
    parse(path, &crate::fsutil::read_to_string(path)?, skeleton)
}
