//! The fitted joints as motion-capture markers, for biomechanics tools: TRC (OpenSim's
//! marker file) and C3D (the biomechanics lab's binary point file; Mokka, OpenSim, Visual3D).
//!
//! A marker is a joint of joints.csv, named as in the BVH export: each bone's head (named
//! as the bone) and each tail that is no child's head (`<bone>_tail`), so a chain's joints
//! appear once. Both files hold millimetres in the export axes (the world's up as +Y and its
//! floor at Y = 0, as OpenSim expects; [`crate::geometry::axes::ExportFrame`]), one
//! row per fitted frame, timed at the capture's frame rate (frame f at f / rate seconds).

use super::bvh::{joint_name, tail_is_a_head};
use crate::geometry::axes::ExportFrame;
use crate::skeleton::{Pose, Skeleton};
use nalgebra::Vector3;
use std::fmt::Write as _;

/// Where a marker sits: bone b's head, or bone b's tail.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Joint {
    Head(usize),
    Tail(usize),
}

/// The markers of `skeleton`, named, in bone order (each head, then its bone's tail when no
/// child starts there). Names are unique: a name already taken (a bone `arm_tail` beside a
/// leaf `arm`, or `a b` beside `a_b`) gets the first free suffix `_2`, `_3`...
fn markers(skeleton: &Skeleton) -> Vec<(String, Joint)> {
    let children = skeleton.children();
    let mut out = Vec::new();
    for (b, bone) in skeleton.bones.iter().enumerate() {
        let name = joint_name(&bone.name);
        out.push((name.clone(), Joint::Head(b)));
        if !tail_is_a_head(skeleton, &children[b], b) {
            out.push((format!("{name}_tail"), Joint::Tail(b)));
        }
    }
    // Heads first claim their own names, so a bone keeps its name whatever the order.
    let mut taken: std::collections::HashSet<String> = out
        .iter()
        .filter(|(_, j)| matches!(j, Joint::Head(_)))
        .map(|(n, _)| n.clone())
        .collect();
    let mut heads_seen: std::collections::HashSet<String> = std::collections::HashSet::new();
    for (name, joint) in out.iter_mut() {
        let first_head = matches!(joint, Joint::Head(_)) && heads_seen.insert(name.clone());
        if first_head {
            continue;
        }
        if taken.contains(name.as_str()) {
            let base = name.clone();
            *name = (2..)
                .map(|k| format!("{base}_{k}"))
                .find(|n| !taken.contains(n))
                .expect("a free suffix");
        }
        taken.insert(name.clone());
    }
    out
}

/// Whether a C3D of `skeleton`'s markers over capture frames `first..=last` can be
/// written: at most 255 markers and 255 bytes a label, frames numbered up to 65,535.
/// Checked before any stage runs, so a run never fails after the other exports.
pub fn check_c3d(skeleton: &Skeleton, first: u32, last: u32) -> Result<(), String> {
    let markers = markers(skeleton);
    if markers.len() > u8::MAX as usize {
        return Err(format!(
            "export.formats holds c3d, but the skeleton makes {} markers and a C3D file holds \
             at most 255; drop c3d (trc holds any number) or use fewer bones",
            markers.len()
        ));
    }
    if let Some((name, _)) = markers.iter().find(|(n, _)| n.len() > u8::MAX as usize) {
        return Err(format!(
            "export.formats holds c3d, but the marker name '{}...' is {} bytes long, over the \
             255 a C3D label holds",
            crate::text::escape_controls(&name.chars().take(20).collect::<String>()),
            name.len()
        ));
    }
    if last as u64 + 1 > u16::MAX as u64 || first > last {
        return Err(format!(
            "export.formats holds c3d, which numbers frames up to {}; frame {last} is past that",
            u16::MAX - 1
        ));
    }
    Ok(())
}

/// Each frame's marker positions in the export axes, millimetres.
fn positions(
    skeleton: &Skeleton,
    poses: &[(u32, Pose)],
    frame: &ExportFrame,
    markers: &[(String, Joint)],
) -> Vec<Vec<Vector3<f64>>> {
    poses
        .iter()
        .map(|(_, pose)| {
            let joints = crate::skeleton::pose::joints(skeleton, pose);
            markers
                .iter()
                .map(|(_, j)| {
                    let p = match *j {
                        Joint::Head(b) => joints[b].0,
                        Joint::Tail(b) => joints[b].1,
                    };
                    frame.point(&p) * 1000.0
                })
                .collect()
        })
        .collect()
}

/// A TRC file (OpenSim's marker format, version 4 of `PathFileType`): tab-separated, a
/// header naming the rate, frame and marker counts and the units (mm), then one row per
/// frame (`Frame#` from 1, `Time` in seconds) with X, Y, Z per marker.
pub fn to_trc(
    file_name: &str,
    skeleton: &Skeleton,
    poses: &[(u32, Pose)],
    rate: f64,
    frame: &ExportFrame,
) -> String {
    let markers = markers(skeleton);
    let rows = positions(skeleton, poses, frame, &markers);
    let mut t = String::new();
    let _ = writeln!(t, "PathFileType\t4\t(X/Y/Z)\t{file_name}");
    let _ = writeln!(
        t,
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames"
    );
    let first = poses.first().map_or(0, |p| p.0);
    let _ = writeln!(
        t,
        "{rate}\t{rate}\t{}\t{}\tmm\t{rate}\t{}\t{}",
        poses.len(),
        markers.len(),
        first + 1,
        poses.len()
    );
    let mut names = String::from("Frame#\tTime");
    let mut axes = String::from("\t");
    for (k, (name, _)) in markers.iter().enumerate() {
        let _ = write!(names, "\t{name}\t\t");
        let _ = write!(axes, "\tX{0}\tY{0}\tZ{0}", k + 1);
    }
    let _ = writeln!(t, "{}", names.trim_end_matches('\t'));
    let _ = writeln!(t, "{axes}");
    let _ = writeln!(t);
    for (i, ((frame, _), row)) in poses.iter().zip(&rows).enumerate() {
        let _ = write!(t, "{}\t{:.6}", i + 1, *frame as f64 / rate);
        for p in row {
            let _ = write!(t, "\t{:.6}\t{:.6}\t{:.6}", p.x, p.y, p.z);
        }
        let _ = writeln!(t);
    }
    t
}

/// Bytes of one C3D block.
const BLOCK: usize = 512;

/// A C3D file: little-endian (Intel), 3D points as 32-bit floats in millimetres (scale
/// -1), no analog channels. Block 1 is the header, block 2 on the parameters (groups
/// POINT, ANALOG and TRIAL), then the frames, each marker as X, Y, Z and a residual word
/// of 0 (a valid point).
pub fn to_c3d(
    skeleton: &Skeleton,
    poses: &[(u32, Pose)],
    rate: f64,
    frame: &ExportFrame,
) -> Result<Vec<u8>, String> {
    let markers = markers(skeleton);
    let first = poses.first().map_or(0, |p| p.0) as usize + 1;
    let last = first + poses.len().saturating_sub(1);
    if last > u16::MAX as usize {
        return Err(format!(
            "C3D numbers frames up to {}; the last frame would be {last}",
            u16::MAX
        ));
    }
    // At most 255 markers (the labels' count is one byte), checked with the parameters.
    let params = parameters(&markers, poses.len(), rate, first, last)?;
    let param_blocks = params.len().div_ceil(BLOCK);
    let data_start = 2 + param_blocks;

    let mut header = vec![0u8; BLOCK];
    let word =
        |h: &mut [u8], w: usize, v: u16| h[2 * w..2 * w + 2].copy_from_slice(&v.to_le_bytes());
    header[0] = 2; // the parameters' first block
    header[1] = 0x50;
    word(&mut header, 1, markers.len() as u16);
    word(&mut header, 2, 0); // analog samples per frame, all channels
    word(&mut header, 3, first as u16);
    word(&mut header, 4, last as u16);
    word(&mut header, 5, 10); // the largest gap filled by interpolation
    header[12..16].copy_from_slice(&(-1.0f32).to_le_bytes());
    word(&mut header, 8, data_start as u16);
    word(&mut header, 9, 0); // analog samples per frame and channel
    header[20..24].copy_from_slice(&(rate as f32).to_le_bytes());

    let rows = positions(skeleton, poses, frame, &markers);
    let mut out = header;
    let mut p = params;
    p.resize(param_blocks * BLOCK, 0);
    out.extend_from_slice(&p);
    for row in &rows {
        for m in row {
            for v in [m.x as f32, m.y as f32, m.z as f32, 0.0] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    out.resize(out.len().div_ceil(BLOCK) * BLOCK, 0);
    Ok(out)
}

/// A parameter group: its name, its id (positive) and its parameters.
type Group<'a> = (&'a str, i8, Vec<(&'a str, Value<'a>)>);

/// A parameter's value.
enum Value<'a> {
    Int(i16),
    Float(f32),
    /// Text, padded with spaces to the longest of them.
    Text(&'a [String]),
    Word(&'a str),
}

/// The parameter section: its 4-byte head, the groups and their parameters.
fn parameters(
    markers: &[(String, Joint)],
    frames: usize,
    rate: f64,
    first: usize,
    last: usize,
) -> Result<Vec<u8>, String> {
    let labels: Vec<String> = markers.iter().map(|m| m.0.clone()).collect();
    let descriptions: Vec<String> = markers
        .iter()
        .map(|(_, j)| match j {
            Joint::Head(_) => "joint (bone head)".to_string(),
            Joint::Tail(_) => "joint (bone tail)".to_string(),
        })
        .collect();
    let groups: [Group; 3] = [
        (
            "POINT",
            1,
            vec![
                ("USED", Value::Int(markers.len() as i16)),
                ("SCALE", Value::Float(-1.0)),
                ("RATE", Value::Float(rate as f32)),
                ("DATA_START", Value::Int(0)), // filled below
                ("FRAMES", Value::Int(frames as u16 as i16)),
                ("UNITS", Value::Word("mm")),
                ("LABELS", Value::Text(&labels)),
                ("DESCRIPTIONS", Value::Text(&descriptions)),
            ],
        ),
        (
            "ANALOG",
            2,
            vec![("USED", Value::Int(0)), ("RATE", Value::Float(rate as f32))],
        ),
        (
            "TRIAL",
            3,
            vec![
                ("ACTUAL_START_FIELD", Value::Int(first as u16 as i16)),
                ("ACTUAL_END_FIELD", Value::Int(last as u16 as i16)),
            ],
        ),
    ];
    let mut s = vec![0x01, 0x50, 0, 84]; // 84: Intel byte order
    let mut data_start_at = None;
    let mut last_offset_at = 0;
    for (name, id, params) in &groups {
        last_offset_at = group(&mut s, name, -id);
        for (pname, value) in params {
            last_offset_at = parameter(&mut s, pname, *id, value)?;
            if *name == "POINT" && *pname == "DATA_START" {
                // An int16 value right after the offset, type and dimension count.
                data_start_at = Some(last_offset_at + 4);
            }
        }
    }
    // The last record's offset is 0: the section ends there.
    s[last_offset_at..last_offset_at + 2].copy_from_slice(&0i16.to_le_bytes());
    let blocks = s.len().div_ceil(BLOCK);
    if blocks > 200 {
        return Err(format!(
            "the C3D parameters would take {blocks} blocks (at most 200)"
        ));
    }
    s[2] = blocks as u8;
    let at = data_start_at.expect("POINT:DATA_START is written");
    s[at..at + 2].copy_from_slice(&((2 + blocks) as i16).to_le_bytes());
    Ok(s)
}

/// A group record: name length, negative id, name, offset to the next record, an empty
/// description; returns where the offset lies.
fn group(s: &mut Vec<u8>, name: &str, id: i8) -> usize {
    s.push(name.len() as u8);
    s.push(id as u8);
    s.extend_from_slice(name.as_bytes());
    let at = s.len();
    s.extend_from_slice(&3i16.to_le_bytes()); // the offset field, the length byte, no text
    s.push(0);
    at
}

/// A parameter record of group `id`; returns where its offset to the next record lies.
fn parameter(s: &mut Vec<u8>, name: &str, id: i8, value: &Value) -> Result<usize, String> {
    let mut body: Vec<u8> = Vec::new();
    match value {
        Value::Int(v) => {
            body.push(2);
            body.push(0);
            body.extend_from_slice(&v.to_le_bytes());
        }
        Value::Float(v) => {
            body.push(4);
            body.push(0);
            body.extend_from_slice(&v.to_le_bytes());
        }
        Value::Word(w) => {
            body.push(0xff); // -1: characters
            body.push(1);
            body.push(w.len() as u8);
            body.extend_from_slice(w.as_bytes());
        }
        Value::Text(items) => {
            let width = items.iter().map(|t| t.len()).max().unwrap_or(0).max(1);
            if width > u8::MAX as usize || items.len() > u8::MAX as usize {
                return Err(format!(
                    "C3D text parameter {name}: {} entries of up to {width} characters (at most 255 each)",
                    items.len()
                ));
            }
            body.push(0xff);
            body.push(2);
            body.push(width as u8);
            body.push(items.len() as u8);
            for t in *items {
                let mut b = t.as_bytes().to_vec();
                b.resize(width, b' ');
                body.extend_from_slice(&b);
            }
        }
    }
    body.push(0); // no description
    s.push(name.len() as u8);
    s.push(id as u8);
    s.extend_from_slice(name.as_bytes());
    let at = s.len();
    s.extend_from_slice(&((body.len() + 2) as i16).to_le_bytes());
    s.extend_from_slice(&body);
    Ok(at)
}

#[cfg(test)]
mod unique_tests {
    use super::*;

    #[test]
    fn marker_names_are_unique() {
        let bone = |name: &str, parent: Option<usize>, z: f64| crate::skeleton::Bone {
            name: name.into(),
            parent,
            head: Vector3::new(0.0, 0.0, z),
            tail: Vector3::new(0.0, 0.1, z),
        };
        let skeleton = Skeleton {
            reference_frame: 0,
            bones: vec![
                bone("root", None, 0.0),
                bone("arm0_lower", Some(0), 1.0),
                bone("arm0_lower_tail", Some(0), 2.0),
                bone("a b", Some(0), 3.0),
                bone("a_b", Some(0), 4.0),
            ],
        };
        let names: Vec<String> = markers(&skeleton).into_iter().map(|(n, _)| n).collect();
        let set: std::collections::HashSet<&String> = names.iter().collect();
        assert_eq!(set.len(), names.len(), "{names:?}");
        assert!(names.contains(&"arm0_lower_tail".to_string()));
        assert!(
            names.contains(&"arm0_lower_tail_2".to_string()),
            "{names:?}"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain's shared joints are one marker; an unshared tail gets its own.
    #[test]
    fn markers_name_each_joint_once() {
        let skeleton = crate::synth::humanoid::skeleton();
        let m = markers(&skeleton);
        let names: Vec<&str> = m.iter().map(|x| x.0.as_str()).collect();
        let mut unique = names.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), names.len());
        assert!(names.contains(&"head_tail") && names.contains(&"hand_l_tail"));
        assert!(!names.contains(&"forearm_l_tail"));
    }
}
