//! glTF 2.0 binary (.glb): the skinned body model with the fitted motion as an animation,
//! and a mesh sequence as morph targets ([`morph_sequence_glb`]).
//!
//! One node per bone, placed at the bone's head: its rest translation is the head's offset
//! from the parent's head at t0 (the root's: its head), its rest rotation the identity, so the
//! bind pose is the reference frame t0 and each joint's inverse bind matrix is the translation
//! by minus its t0 head. The animation drives the root's translation (its posed head) and
//! every bone's rotation L_b (the pose's local rotation, [`crate::skeleton::pose`]), one key
//! per fitted frame at `(frame - first) / frame_rate` seconds, linear interpolation. The mesh
//! is the t0 surface with its four strongest skinning influences per vertex (JOINTS_0 /
//! WEIGHTS_0, renormalized), normals and part colours (COLOR_0). glTF's joint matrices
//! `world_b · IBM_b` then reproduce the model's linear blend skinning exactly.
//!
//! Axes: every position x is written as C x - floor Y and every rotation R as C R Cᵀ
//! ([`crate::geometry::axes::ExportFrame`]), so the scene stands on glTF's +Y with its floor
//! at Y = 0.

use crate::geometry::axes::ExportFrame;
use crate::skeleton::model::BodyModel;
use crate::skeleton::Pose;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use serde_json::{json, Value};

const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_BYTE: u32 = 5121;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// The binary chunk and the bufferViews / accessors describing it.
#[derive(Default)]
struct Buffer {
    data: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Buffer {
    /// Appends `bytes` as a new bufferView (4-byte aligned); returns its index.
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.data.len().is_multiple_of(4) {
            self.data.push(0);
        }
        let mut v = json!({
            "buffer": 0,
            "byteOffset": self.data.len(),
            "byteLength": bytes.len(),
        });
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.data.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// Adds an accessor over a whole bufferView; returns its index.
    fn accessor(&mut self, view: usize, component: u32, count: usize, kind: &str) -> usize {
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": component,
            "count": count,
            "type": kind,
        }));
        self.accessors.len() - 1
    }

    /// Float accessor of `values` (`width` numbers per element) with min / max.
    fn floats(&mut self, values: &[f32], width: usize, kind: &str, target: Option<u32>) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let a = self.accessor(view, FLOAT, values.len() / width, kind);
        let (mut lo, mut hi) = (vec![f32::INFINITY; width], vec![f32::NEG_INFINITY; width]);
        for chunk in values.chunks_exact(width) {
            for k in 0..width {
                lo[k] = lo[k].min(chunk[k]);
                hi[k] = hi[k].max(chunk[k]);
            }
        }
        self.accessors[a]["min"] = json!(lo);
        self.accessors[a]["max"] = json!(hi);
        a
    }

    /// The .glb of `doc` with this buffer as its one buffer (views and accessors added).
    fn into_glb(mut self, mut doc: Value) -> Vec<u8> {
        while !self.data.len().is_multiple_of(4) {
            self.data.push(0);
        }
        doc["buffers"] = json!([{ "byteLength": self.data.len() }]);
        doc["bufferViews"] = json!(self.views);
        doc["accessors"] = json!(self.accessors);
        glb_container(&doc, &self.data)
    }
}

/// The four strongest influences of a vertex, renormalized so that their f32 values sum
/// to 1 (the largest absorbs the rounding): (joints, weights); unused slots are joint 0
/// with weight 0.
fn four_influences(influences: &[(usize, f64)]) -> ([u16; 4], [f32; 4]) {
    let mut sorted: Vec<(usize, f64)> = influences
        .iter()
        .copied()
        .filter(|x| x.1 > 0.0 && x.1.is_finite())
        .collect();
    sorted.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    sorted.truncate(4);
    let total: f64 = sorted.iter().map(|x| x.1).sum();
    let mut joints = [0u16; 4];
    let mut weights = [0f32; 4];
    if sorted.is_empty() || total <= 0.0 {
        weights[0] = 1.0;
        return (joints, weights);
    }
    for (k, (b, w)) in sorted.iter().enumerate() {
        joints[k] = *b as u16;
        weights[k] = (w / total) as f32;
    }
    let rest: f64 = weights[1..].iter().map(|&w| w as f64).sum();
    weights[0] = (1.0 - rest) as f32;
    (joints, weights)
}

/// A rotation as glTF's unit quaternion (x, y, z, w), normalized in f32.
fn quaternion(r: &Rotation3<f64>) -> [f32; 4] {
    let q = UnitQuaternion::from_rotation_matrix(r);
    let v = [q.i as f32, q.j as f32, q.k as f32, q.w as f32];
    let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    v.map(|x| x / n)
}

fn push3(out: &mut Vec<f32>, v: &Vector3<f64>) {
    out.extend([v.x as f32, v.y as f32, v.z as f32]);
}

/// The .glb bytes of `model` animated by `poses` ((frame, pose) in frame order) at
/// `frame_rate` frames per second; `name` names the scene and the animation.
pub fn to_glb(
    model: &BodyModel,
    poses: &[(u32, Pose)],
    frame_rate: f64,
    frame: &ExportFrame,
    name: &str,
) -> Vec<u8> {
    let skeleton = &model.skeleton;
    let n_bones = skeleton.bones.len();
    let mut buf = Buffer::default();

    // The mesh: t0 surface, normals, part colours, skinning.
    let mesh = &model.mesh;
    let mut positions = Vec::with_capacity(3 * mesh.vertices.len());
    let mut normals = Vec::with_capacity(3 * mesh.vertices.len());
    for (v, n) in mesh.vertices.iter().zip(mesh.vertex_normals()) {
        push3(&mut positions, &frame.point(v));
        let n = frame.vector(&n);
        let n = if n.norm() > 1e-12 {
            n.normalize()
        } else {
            Vector3::y()
        };
        let n32 = Vector3::new(n.x as f32, n.y as f32, n.z as f32).normalize();
        normals.extend([n32.x, n32.y, n32.z]);
    }
    let position_acc = buf.floats(&positions, 3, "VEC3", Some(ARRAY_BUFFER));
    let normal_acc = buf.floats(&normals, 3, "VEC3", Some(ARRAY_BUFFER));
    let colours: Vec<u8> = model
        .labels
        .iter()
        .flat_map(|&l| {
            let [r, g, b] = crate::skeleton::model::part_colour(l);
            [r, g, b, 255]
        })
        .collect();
    let colour_view = buf.view(&colours, Some(ARRAY_BUFFER));
    let colour_acc = buf.accessor(colour_view, UNSIGNED_BYTE, mesh.vertices.len(), "VEC4");
    buf.accessors[colour_acc]["normalized"] = json!(true);
    let (mut joint_bytes, mut weights) = (Vec::new(), Vec::new());
    for w in &model.weights {
        let (j, wt) = four_influences(w);
        joint_bytes.extend(j.iter().flat_map(|x| x.to_le_bytes()));
        weights.extend(wt);
    }
    let joints_view = buf.view(&joint_bytes, Some(ARRAY_BUFFER));
    let joints_acc = buf.accessor(joints_view, UNSIGNED_SHORT, mesh.vertices.len(), "VEC4");
    let weights_acc = buf.floats(&weights, 4, "VEC4", Some(ARRAY_BUFFER));
    let indices: Vec<u8> = mesh
        .triangles
        .iter()
        .flat_map(|t| t.iter().flat_map(|i| i.to_le_bytes()))
        .collect();
    let index_view = buf.view(&indices, Some(ELEMENT_ARRAY_BUFFER));
    let index_acc = buf.accessor(index_view, UNSIGNED_INT, 3 * mesh.triangles.len(), "SCALAR");

    // Inverse bind matrices (column-major): translation by minus each t0 head.
    let heads: Vec<Vector3<f64>> = skeleton
        .bones
        .iter()
        .map(|b| frame.point(&b.head))
        .collect();
    let mut ibm = Vec::with_capacity(16 * n_bones);
    for h in &heads {
        ibm.extend([1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        ibm.extend([-h.x as f32, -h.y as f32, -h.z as f32, 1.0]);
    }
    let ibm_bytes: Vec<u8> = ibm.iter().flat_map(|v: &f32| v.to_le_bytes()).collect();
    let ibm_view = buf.view(&ibm_bytes, None);
    let ibm_acc = buf.accessor(ibm_view, FLOAT, n_bones, "MAT4");

    // Nodes: bones first (node b = bone b), then the skinned mesh's node.
    let children = skeleton.children();
    let mut nodes: Vec<Value> = skeleton
        .bones
        .iter()
        .enumerate()
        .map(|(b, bone)| {
            let offset = match bone.parent {
                Some(p) => heads[b] - heads[p],
                None => heads[b],
            };
            let mut node = json!({
                "name": bone.name,
                "translation": [offset.x as f32, offset.y as f32, offset.z as f32],
            });
            if !children[b].is_empty() {
                node["children"] = json!(children[b]);
            }
            node
        })
        .collect();
    nodes.push(json!({ "name": format!("{name}_surface"), "mesh": 0, "skin": 0 }));
    let roots: Vec<usize> = (0..n_bones)
        .filter(|&b| skeleton.bones[b].parent.is_none())
        .chain([n_bones])
        .collect();

    // The animation: one key per fitted frame.
    let mut animation = json!({ "name": name, "channels": [], "samplers": [] });
    if !poses.is_empty() {
        let first = poses[0].0;
        let times: Vec<f32> = poses
            .iter()
            .map(|(f, _)| ((f - first) as f64 / frame_rate) as f32)
            .collect();
        let time_acc = buf.floats(&times, 1, "SCALAR", None);
        let mut add_channel = |node: usize, path: &str, values: Vec<f32>, kind: &str| {
            let width = if kind == "VEC4" { 4 } else { 3 };
            let out = buf.floats(&values, width, kind, None);
            let samplers = animation["samplers"].as_array_mut().expect("array");
            samplers.push(json!({ "input": time_acc, "output": out, "interpolation": "LINEAR" }));
            let sampler = samplers.len() - 1;
            animation["channels"]
                .as_array_mut()
                .expect("array")
                .push(json!({ "sampler": sampler, "target": { "node": node, "path": path } }));
        };
        for (b, bone) in skeleton.bones.iter().enumerate() {
            if bone.parent.is_none() {
                let mut t = Vec::with_capacity(3 * poses.len());
                for (_, pose) in poses {
                    push3(&mut t, &frame.point(&(bone.head + pose.translation)));
                }
                add_channel(b, "translation", t, "VEC3");
            }
            let r: Vec<f32> = poses
                .iter()
                .flat_map(|(_, pose)| quaternion(&frame.turn(&pose.rotations[b])))
                .collect();
            add_channel(b, "rotation", r, "VEC4");
        }
    }

    let mut doc = json!({
        "asset": { "version": "2.0", "generator": "hullpose" },
        "scene": 0,
        "scenes": [{ "name": name, "nodes": roots }],
        "nodes": nodes,
        "meshes": [{
            "name": format!("{name}_surface"),
            "primitives": [{
                "attributes": {
                    "POSITION": position_acc,
                    "NORMAL": normal_acc,
                    "COLOR_0": colour_acc,
                    "JOINTS_0": joints_acc,
                    "WEIGHTS_0": weights_acc,
                },
                "indices": index_acc,
                "mode": 4,
            }],
        }],
        "skins": [{
            "name": format!("{name}_skeleton"),
            "inverseBindMatrices": ibm_acc,
            "joints": (0..n_bones).collect::<Vec<_>>(),
            "skeleton": roots[0],
        }],
    });
    if !poses.is_empty() {
        doc["animations"] = json!([animation]);
    }
    buf.into_glb(doc)
}

/// The .glb bytes of one mesh moving through `frames` (each one position per vertex, the
/// same count in all, already in glTF's axes) at `frame_rate` frames per second, as morph
/// targets: the base is the first frame, target k-1 holds frame k's offsets from it, and the
/// animation's key k sets target k-1's weight to 1 and the others to 0 (linear in between).
/// Morph targets, not one node per frame: one mesh that viewers and Blender (shape keys)
/// treat as one object, and the same size (the vertex positions of every frame). No normals
/// are written, so viewers shade each frame's own triangles. `names` name the targets
/// (`mesh.extras.targetNames`). `None` when the file would pass glb's 4 GiB limit.
pub fn morph_sequence_glb(
    triangles: &[[u32; 3]],
    frames: &[Vec<[f32; 3]>],
    names: &[String],
    frame_rate: f64,
    name: &str,
) -> Option<Vec<u8>> {
    let vertices = frames.first().map_or(0, Vec::len);
    let estimate = frames.len() * vertices * 12 + triangles.len() * 12 + frames.len().pow(2) * 4;
    if estimate >= u32::MAX as usize - (1 << 20) {
        return None;
    }
    let mut buf = Buffer::default();
    let flat = |f: &Vec<[f32; 3]>| -> Vec<f32> { f.iter().flatten().copied().collect() };
    let base = &frames[0];
    let position_acc = buf.floats(&flat(base), 3, "VEC3", Some(ARRAY_BUFFER));
    let indices: Vec<u8> = triangles
        .iter()
        .flatten()
        .flat_map(|i| i.to_le_bytes())
        .collect();
    let index_view = buf.view(&indices, Some(ELEMENT_ARRAY_BUFFER));
    let index_acc = buf.accessor(index_view, UNSIGNED_INT, triangles.len() * 3, "SCALAR");
    let targets: Vec<Value> = frames[1..]
        .iter()
        .map(|f| {
            let delta: Vec<f32> = f
                .iter()
                .zip(base)
                .flat_map(|(p, b)| [p[0] - b[0], p[1] - b[1], p[2] - b[2]])
                .collect();
            json!({ "POSITION": buf.floats(&delta, 3, "VEC3", Some(ARRAY_BUFFER)) })
        })
        .collect();
    let n_targets = targets.len();
    let mut primitive = json!({
        "attributes": { "POSITION": position_acc },
        "indices": index_acc,
        "mode": 4,
    });
    let mut mesh = json!({ "name": format!("{name}_surface"), "primitives": [] });
    let mut doc = json!({
        "asset": { "version": "2.0", "generator": "hullpose" },
        "scene": 0,
        "scenes": [{ "name": name, "nodes": [0] }],
        "nodes": [{ "name": format!("{name}_surface"), "mesh": 0 }],
    });
    if n_targets > 0 {
        primitive["targets"] = json!(targets);
        mesh["weights"] = json!(vec![0.0; n_targets]);
        mesh["extras"] = json!({ "targetNames": names.get(1..).unwrap_or_default() });
        let times: Vec<f32> = (0..frames.len())
            .map(|k| (k as f64 / frame_rate) as f32)
            .collect();
        let time_acc = buf.floats(&times, 1, "SCALAR", None);
        let mut weights = vec![0f32; frames.len() * n_targets];
        for k in 1..frames.len() {
            weights[k * n_targets + k - 1] = 1.0;
        }
        let bytes: Vec<u8> = weights.iter().flat_map(|w| w.to_le_bytes()).collect();
        let view = buf.view(&bytes, None);
        let weight_acc = buf.accessor(view, FLOAT, weights.len(), "SCALAR");
        doc["animations"] = json!([{
            "name": name,
            "samplers": [{ "input": time_acc, "output": weight_acc, "interpolation": "LINEAR" }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }],
        }]);
    }
    mesh["primitives"] = json!([primitive]);
    doc["meshes"] = json!([mesh]);
    Some(buf.into_glb(doc))
}

/// The GLB container: 12-byte header, the JSON chunk (space-padded) and the BIN chunk
/// (zero-padded), each 4-byte aligned.
fn glb_container(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).expect("JSON of plain values");
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_strongest_influences_sum_to_one_in_f32() {
        let (j, w) = four_influences(&[(3, 0.1), (1, 0.5), (7, 0.05), (2, 0.3), (9, 0.05)]);
        assert_eq!(j[..3], [1, 2, 3]);
        let sum: f64 = w.iter().map(|&x| x as f64).sum();
        assert!((sum - 1.0).abs() < 1e-7, "{sum}");
        let (j, w) = four_influences(&[(4, 1.0)]);
        assert_eq!((j, w), ([4, 0, 0, 0], [1.0, 0.0, 0.0, 0.0]));
    }
}
