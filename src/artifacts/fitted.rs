//! The fit's state between frames, as the next frame's fit and health checks read it: the
//! pose and the diagnostics at full precision (every `f64` stored as its bit pattern), and
//! the frame's worst silhouette IoU. A resumed run reads this instead of re-parsing the
//! rounded CSV rows, so a run killed and resumed writes what a fresh run writes, byte for
//! byte. File: `NNNNNN.state.json` in the fit stage's folder.
//!
//! The other files of a fitted frame are written by [`crate::stages::fit`] under the names
//! [`files`] gives: the pose and joint rows, the diagnostics row, the posed surface.

use crate::cache::Cache;
use crate::dataset::frame_stem;
use crate::error::{Error, Result};
use crate::fit::{FitDiagnostics, FitStatus};
use crate::geometry::TriMesh;
use crate::skeleton::Pose;
use crate::skeleton::Skeleton;
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format of the state file (bumped with any change of its fields or meaning).
const FORMAT: u32 = 2;

/// The stage folder's name.
pub const STAGE: &str = "fit";

/// The per-frame file names: (pose, joints, diagnostics, mesh, state between frames).
fn files(frame: u32) -> [String; 5] {
    let s = frame_stem(frame);
    [
        format!("{s}.pose.csv"),
        format!("{s}.joints.csv"),
        format!("{s}.fit.csv"),
        format!("{s}.ply"),
        format!("{s}.state.json"),
    ]
}

/// A fitted frame: its rows of poses.csv, joints.csv and fit.csv (each with its header),
/// the posed model coloured by part, and its state.
pub struct FittedFrame {
    pub poses_csv: String,
    pub joints_csv: String,
    pub diagnostics_csv: String,
    pub mesh: TriMesh,
    pub colours: Vec<[u8; 3]>,
    pub state: FitState,
}

impl super::Artifact for FittedFrame {
    fn write(&self, dir: &Path, frame: u32) -> Result<Vec<String>> {
        use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
        let names = files(frame);
        crate::fsutil::write_atomic(&dir.join(&names[0]), self.poses_csv.as_bytes())?;
        crate::fsutil::write_atomic(&dir.join(&names[1]), self.joints_csv.as_bytes())?;
        crate::fsutil::write_atomic(&dir.join(&names[2]), self.diagnostics_csv.as_bytes())?;
        let normals = self.mesh.vertex_normals();
        write_ply(
            &dir.join(&names[3]),
            &self.mesh,
            &VertexAttributes {
                normals: Some(&normals),
                colors: Some(&self.colours),
                scalars: Vec::new(),
            },
            PlyFormat::BinaryLittleEndian,
        )?;
        // Written last: a frame whose state exists has every other file.
        write_state(&dir.join(&names[4]), frame, &self.state)?;
        Ok(names.to_vec())
    }
}

/// A cached fitted frame's CSV rows, without their headers.
pub struct Rows {
    pub poses: String,
    pub joints: String,
    pub diagnostics: String,
}

/// Reads a cached fitted frame's rows of poses.csv, joints.csv and fit.csv.
pub fn read_rows(cache: &Cache, frame: u32) -> Result<Rows> {
    let dir = cache.stage_dir(STAGE);
    let names = files(frame);
    let body = |name: &str| -> Result<String> {
        let text = crate::fsutil::read_to_string(&dir.join(name))?;
        Ok(text.split_once('\n').map_or("", |x| x.1).to_string())
    };
    Ok(Rows {
        poses: body(&names[0])?,
        joints: body(&names[1])?,
        diagnostics: body(&names[2])?,
    })
}

/// Reads a cached frame's state (its pose and diagnostics at full precision).
pub fn read_state(cache: &Cache, skeleton: &Skeleton, frame: u32) -> Result<FitState> {
    let path = cache.stage_dir(STAGE).join(&files(frame)[4]);
    read(&path, frame, skeleton.bones.len())
}

/// Reads a cached frame's posed model (world metres).
pub fn read_mesh(cache: &Cache, frame: u32) -> Result<TriMesh> {
    crate::geometry::ply::read_ply(&cache.stage_dir(STAGE).join(&files(frame)[3]))
}

/// Reads a cached frame's pose.
pub fn read_pose(cache: &Cache, skeleton: &Skeleton, frame: u32) -> Result<Pose> {
    Ok(read_state(cache, skeleton, frame)?.pose)
}

/// A fitted frame's state.
#[derive(Debug, Clone, PartialEq)]
pub struct FitState {
    pub pose: Pose,
    pub diagnostics: FitDiagnostics,
    /// The worst camera's silhouette IoU of the posed model.
    pub iou_worst: f64,
}

/// The file's fields; floating-point numbers as `f64::to_bits`.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StateFile {
    format: u32,
    frame: u32,
    translation: [u64; 3],
    /// Each bone's rotation matrix, column-major.
    rotations: Vec<[u64; 9]>,
    status: String,
    iterations: usize,
    lm_steps: usize,
    energy: u64,
    rms: u64,
    downweighted_share: u64,
    contact_share: u64,
    score: u64,
    observed: usize,
    unexplained_vertices: usize,
    unexplained_bone: Option<usize>,
    recovery: Option<String>,
    ambiguous: Option<u64>,
    iou_worst: u64,
}

/// Writes `state` of `frame` to `path` (atomically).
fn write_state(path: &Path, frame: u32, state: &FitState) -> Result<()> {
    let d = &state.diagnostics;
    let file = StateFile {
        format: FORMAT,
        frame,
        translation: state.pose.translation.map(f64::to_bits).into(),
        rotations: state
            .pose
            .rotations
            .iter()
            .map(|r| {
                let m = r.matrix();
                std::array::from_fn(|i| m[i].to_bits())
            })
            .collect(),
        status: d.status.name().to_string(),
        iterations: d.iterations,
        lm_steps: d.lm_steps,
        energy: d.energy.to_bits(),
        rms: d.rms.to_bits(),
        downweighted_share: d.downweighted_share.to_bits(),
        contact_share: d.contact_share.to_bits(),
        score: d.score.to_bits(),
        observed: d.observed,
        unexplained_vertices: d.unexplained.vertices,
        unexplained_bone: d.unexplained.bone,
        recovery: d.recovery.clone(),
        ambiguous: d.ambiguous.map(f64::to_bits),
        iou_worst: state.iou_worst.to_bits(),
    };
    let text = serde_json::to_string(&file)
        .map_err(|e| Error::invalid(path, format!("cannot encode the fit state: {e}")))?;
    crate::fsutil::write_atomic(path, text.as_bytes())
}

/// Reads the state of `frame` for a skeleton of `bones` bones from `path`.
fn read(path: &Path, frame: u32, bones: usize) -> Result<FitState> {
    let text = crate::fsutil::read_to_string(path)?;
    let bad = |m: String| {
        Error::invalid(
            path,
            format!("{m}; the fit's cache is damaged: run the fit stage again (--force fit)"),
        )
    };
    let f: StateFile =
        serde_json::from_str(&text).map_err(|e| bad(format!("not a fit state file ({e})")))?;
    if f.format != FORMAT || f.frame != frame || f.rotations.len() != bones {
        return Err(bad(format!(
            "holds format {} for frame {} with {} bones, not format {FORMAT} for frame {frame} \
             with {bones}",
            f.format,
            f.frame,
            f.rotations.len()
        )));
    }
    let real = f64::from_bits;
    let status =
        FitStatus::parse(&f.status).ok_or_else(|| bad(format!("status {:?}", f.status)))?;
    let mut diagnostics = FitDiagnostics::unfitted(status, f.observed);
    diagnostics.iterations = f.iterations;
    diagnostics.lm_steps = f.lm_steps;
    diagnostics.energy = real(f.energy);
    diagnostics.rms = real(f.rms);
    diagnostics.downweighted_share = real(f.downweighted_share);
    diagnostics.contact_share = real(f.contact_share);
    diagnostics.score = real(f.score);
    diagnostics.unexplained.vertices = f.unexplained_vertices;
    diagnostics.unexplained.bone = f.unexplained_bone.filter(|&b| b < bones);
    diagnostics.recovery = f.recovery;
    diagnostics.ambiguous = f.ambiguous.map(real);
    let pose = Pose {
        translation: Vector3::from(f.translation.map(real)),
        rotations: f
            .rotations
            .iter()
            .map(|m| Rotation3::from_matrix_unchecked(Matrix3::from_column_slice(&m.map(real))))
            .collect(),
    };
    let finite = pose.translation.iter().all(|v| v.is_finite())
        && pose
            .rotations
            .iter()
            .all(|r| r.matrix().iter().all(|v| v.is_finite()));
    if !finite {
        return Err(bad("holds a pose that is not finite".into()));
    }
    Ok(FitState {
        pose,
        diagnostics,
        iou_worst: real(f.iou_worst),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_reads_back_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000003.state.json");
        let mut pose = Pose::rest(2);
        pose.translation = Vector3::new(0.1, -1.0 / 3.0, 2e-17);
        pose.rotations[1] = Rotation3::new(Vector3::new(0.3, 1.0 / 7.0, -0.2));
        let mut diagnostics = FitDiagnostics::unfitted(FitStatus::Converged, 1234);
        diagnostics.energy = std::f64::consts::PI * 1e-5;
        diagnostics.recovery = Some("kept".into());
        diagnostics.ambiguous = Some(0.1 + 0.037);
        diagnostics.unexplained.bone = Some(1);
        let state = FitState {
            pose,
            diagnostics,
            iou_worst: 0.1 + 0.2,
        };
        write_state(&path, 3, &state).unwrap();
        assert_eq!(read(&path, 3, 2).unwrap(), state);
        assert!(read(&path, 4, 2).is_err());
        assert!(read(&path, 3, 3).is_err());
    }
}
