//! Exports of the bundled sample: the .glb passes the Khronos glTF-Validator and its
//! animation reproduces joints.csv; an independent BVH reader (bvhio) puts every joint where
//! joints.csv has it, and so do OpenSim (the TRC) and ezc3d (the C3D); PLY / OBJ meshes read
//! back whole with their attributes; Blender plays the tracked surface's point caches (PC2,
//! MDD) onto its rest mesh as the per-frame PLY has it, and its morph-target glb passes the
//! validator and holds every frame; overlays and contact sheets are written; `pipeline
//! export` rewrites a format from the cache alone.
//!
//! The external checkers (tools/validate_gltf.cjs with npm's gltf-validator under
//! tools/node_modules, tools/check_bvh.py with PyPI's bvhio, tools/check_markers.py with
//! PyPI's opensim and ezc3d, tools/check_point_cache.py run by Debian's blender) are
//! installed by `.ci/run`;
//! with `HULLPOSE_EXTERNAL_CHECKS=1` (as CI sets it) a missing checker fails the test,
//! otherwise it is skipped with a note.

use crate::common;

use common::*;
use hullpose::geometry::axes::ExportFrame;
use hullpose::skeleton::Skeleton;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The bundled sample with its pipeline.yaml (up axis +z), frames 0..2, run once through
/// every stage and the exports.
fn sample_run() -> &'static Path {
    static CELL: OnceLock<tempfile::TempDir> = OnceLock::new();
    CELL.get_or_init(|| {
        let dir = process_tempdir();
        let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
        copy_sample_capture(dir.path());
        let yaml = std::fs::read_to_string(repo.join("pipeline.yaml"))
            .unwrap()
            .replace("frames: all", "frames: 0..2")
            .replace(
                "export:\n",
                "export:\n  formats: [glb, bvh, ply, obj, overlay, trc, c3d, surface]\n",
            );
        assert!(yaml.contains("up: +z"), "the sample declares its up axis");
        std::fs::write(dir.path().join("pipeline.yaml"), yaml).unwrap();
        let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], dir.path());
        assert!(ok, "{out}\n{err}");
        assert!(out.contains("export:"), "{out}");
        dir
    })
    .path()
}

/// Whether external checks are required (CI) rather than optional.
fn required() -> bool {
    std::env::var("HULLPOSE_EXTERNAL_CHECKS").is_ok_and(|v| v == "1")
}

/// How the sample's exports place the world (output/export/world.yaml): +z turned to +Y,
/// the floor (the lowest point of the posed model) at Y = 0.
fn export_frame(dir: &Path) -> ExportFrame {
    let path = dir.join("output/export/world.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    hullpose::yaml::from_str(&path, &text).unwrap()
}

/// The sample's floor, as `--floor` for the checkers.
fn floor_arg(dir: &Path) -> String {
    format!("{}", export_frame(dir).floor)
}

fn repo_tools() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tools")
}

/// Runs an external checker; `None` when it is not installed (and not required).
fn external(program: &str, args: &[&str], probe: &[&str]) -> Option<(bool, String)> {
    let available = std::process::Command::new(program)
        .args(probe)
        .output()
        .is_ok_and(|o| o.status.success());
    if !available {
        assert!(
            !required(),
            "{program} {probe:?} failed: install the checkers as .ci/run does"
        );
        eprintln!("note: {program} {probe:?} is not available; external check skipped");
        return None;
    }
    let out = std::process::Command::new(program)
        .args(args)
        .output()
        .expect("run checker");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Some((out.status.success(), text))
}

#[test]
fn glb_passes_the_khronos_validator() {
    let glb = sample_run().join("output/export/tripod.glb");
    let script = repo_tools().join("validate_gltf.cjs");
    let node_modules = repo_tools().join("node_modules/gltf-validator");
    let probe = format!(
        "require('{}')",
        node_modules.display().to_string().replace('\\', "/")
    );
    let Some((ok, report)) = external(
        "node",
        &[script.to_str().unwrap(), glb.to_str().unwrap()],
        &["-e", &probe],
    ) else {
        return;
    };
    assert!(ok, "{report}");
    assert!(
        report.starts_with("errors 0 warnings 0"),
        "validator report: {report}"
    );
}

/// The GLB's JSON and binary chunks.
fn read_glb(path: &Path) -> (Value, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[0..4], b"glTF");
    let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
    assert_eq!(u32_at(8), bytes.len(), "declared length");
    let json_len = u32_at(12);
    let json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let bin_start = 20 + json_len + 8;
    (json, bytes[bin_start..].to_vec())
}

/// The f32 values of accessor `a`.
fn floats(doc: &Value, bin: &[u8], a: usize) -> Vec<f32> {
    let acc = &doc["accessors"][a];
    let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let start = view["byteOffset"].as_u64().unwrap() as usize;
    let len = view["byteLength"].as_u64().unwrap() as usize;
    bin[start..start + len]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

#[test]
fn glb_animation_reproduces_the_joints() {
    let dir = sample_run();
    let (doc, bin) = read_glb(&dir.join("output/export/tripod.glb"));
    let skeleton = Skeleton::read(&dir.join("data/tripod/skeleton.yaml")).unwrap();
    let joints = hullpose::joints::read(&dir.join("output/joints.csv")).unwrap();
    let placed = export_frame(dir);
    // The sample stands on +z with its floor (given: the tripod hangs in the air) at z = 0.
    assert_eq!(placed.floor, 0.0);
    assert!((placed.rotation.inverse() * Vector3::y() - Vector3::z()).norm() < 1e-9);
    let n = skeleton.bones.len();
    // Per node: rest translation, and per key the animated translation / rotation.
    let nodes = doc["nodes"].as_array().unwrap();
    let rest: Vec<Vector3<f64>> = (0..n)
        .map(|b| {
            let t = nodes[b]["translation"].as_array().unwrap();
            Vector3::new(
                t[0].as_f64().unwrap(),
                t[1].as_f64().unwrap(),
                t[2].as_f64().unwrap(),
            )
        })
        .collect();
    let anim = &doc["animations"][0];
    let mut translations = vec![None; n];
    let mut rotations = vec![None; n];
    for ch in anim["channels"].as_array().unwrap() {
        let node = ch["target"]["node"].as_u64().unwrap() as usize;
        let sampler = &anim["samplers"][ch["sampler"].as_u64().unwrap() as usize];
        let values = floats(&doc, &bin, sampler["output"].as_u64().unwrap() as usize);
        match ch["target"]["path"].as_str().unwrap() {
            "translation" => translations[node] = Some(values),
            "rotation" => rotations[node] = Some(values),
            other => panic!("unexpected path {other}"),
        }
    }
    let times_acc = anim["samplers"][0]["input"].as_u64().unwrap() as usize;
    let times = floats(&doc, &bin, times_acc);
    assert_eq!(times.len(), 3);
    // The sample's export.frame_rate.
    assert!((times[1] - 1.0 / 8.33).abs() < 1e-6, "8.33 fps: {times:?}");
    let mut worst = 0.0f64;
    for (k, frame) in [0u32, 1, 2].into_iter().enumerate() {
        let mut world: Vec<(UnitQuaternion<f64>, Vector3<f64>)> = Vec::with_capacity(n);
        for (b, bone) in skeleton.bones.iter().enumerate() {
            let t = match &translations[b] {
                Some(v) => Vector3::new(v[3 * k] as f64, v[3 * k + 1] as f64, v[3 * k + 2] as f64),
                None => rest[b],
            };
            let q = rotations[b].as_ref().expect("every bone rotates");
            let r = UnitQuaternion::from_quaternion(Quaternion::new(
                q[4 * k + 3] as f64,
                q[4 * k] as f64,
                q[4 * k + 1] as f64,
                q[4 * k + 2] as f64,
            ));
            world.push(match bone.parent {
                None => (r, t),
                Some(p) => (world[p].0 * r, world[p].0 * t + world[p].1),
            });
        }
        for (b, bone) in skeleton.bones.iter().enumerate() {
            let row = joints
                .iter()
                .find(|j| j.frame == frame && j.bone == bone.name)
                .unwrap();
            let head = world[b].1;
            let tail = world[b].0 * placed.vector(&(bone.tail - bone.head)) + head;
            worst = worst
                .max((head - placed.point(&row.head)).norm())
                .max((tail - placed.point(&row.tail)).norm());
        }
    }
    assert!(worst < 1e-4, "glb joints vs joints.csv: {worst} m");
}

#[test]
fn bvh_read_by_bvhio_matches_the_joints() {
    let dir = sample_run();
    let bvh = dir.join("output/export/tripod.bvh");
    let joints = dir.join("output/joints.csv");
    let script = repo_tools().join("check_bvh.py");
    let Some((ok, report)) = external(
        "python3",
        &[
            script.to_str().unwrap(),
            bvh.to_str().unwrap(),
            joints.to_str().unwrap(),
            "--up",
            "+z",
            "--floor",
            &floor_arg(dir),
            "--tolerance",
            "0.001",
        ],
        &["-c", "import bvhio"],
    ) else {
        return;
    };
    assert!(ok && report.contains("frames 3 bones 6"), "{report}");
    // The check can fail: read with the wrong up axis, the joints are far off.
    let (wrong, report) = external(
        "python3",
        &[
            script.to_str().unwrap(),
            bvh.to_str().unwrap(),
            joints.to_str().unwrap(),
            "--up",
            "+y",
        ],
        &["-c", "import bvhio"],
    )
    .unwrap();
    assert!(!wrong, "{report}");
}

#[test]
fn trc_read_by_opensim_and_c3d_read_by_ezc3d_match_the_joints() {
    let dir = sample_run();
    let joints = dir.join("output/joints.csv");
    let script = repo_tools().join("check_markers.py");
    let floor = floor_arg(dir);
    for (file, reader) in [("tripod.trc", "opensim"), ("tripod.c3d", "ezc3d")] {
        let path = dir.join("output/export").join(file);
        let check = |up: &str| {
            external(
                "python3",
                &[
                    script.to_str().unwrap(),
                    path.to_str().unwrap(),
                    joints.to_str().unwrap(),
                    "--up",
                    up,
                    "--floor",
                    &floor,
                    "--tolerance",
                    "0.0001",
                ],
                &["-c", &format!("import {reader}")],
            )
        };
        let Some((ok, report)) = check("+z") else {
            continue;
        };
        // Every joint of every frame within 0.1 mm, in millimetres as declared.
        assert!(
            ok && report.contains("frames 3 markers 9 units mm"),
            "{file}: {report}"
        );
        // The check can fail: read with the wrong up axis, the joints are far off.
        let (wrong, report) = check("+y").unwrap();
        assert!(!wrong, "{file}: {report}");
    }
}

#[test]
fn meshes_read_back_with_their_attributes() {
    let dir = sample_run();
    let meshes = dir.join("output/export/meshes");
    for stage in ["visual_hull", "graphcut", "fit"] {
        let cached =
            hullpose::geometry::ply::read_ply(&dir.join(format!("cache/{}/000001.ply", stage)))
                .unwrap();
        let ply_path = meshes.join(stage).join("000001.ply");
        let ply = hullpose::geometry::ply::read_ply(&ply_path).unwrap();
        let obj =
            hullpose::geometry::obj::read_obj(&meshes.join(stage).join("000001.obj")).unwrap();
        assert_eq!(ply.vertices.len(), cached.vertices.len(), "{stage}");
        assert_eq!(ply.triangles, cached.triangles, "{stage}");
        assert_eq!(obj.triangles.len(), cached.triangles.len(), "{stage}");
        assert!(ply.is_watertight(), "{stage}: closed");
        let bytes = std::fs::read(&ply_path).unwrap();
        let header = String::from_utf8_lossy(&bytes[..600.min(bytes.len())]).to_string();
        for property in [
            "binary_little_endian",
            "property float nx",
            "property uchar red",
            "property float quality",
        ] {
            assert!(
                header.contains(property),
                "{stage}: {property} in\n{header}"
            );
        }
        // The OBJ reader may reorder vertices: compare the enclosed volumes.
        let (v_ply, v_obj) = (ply.signed_volume(), obj.signed_volume());
        assert!(
            v_ply > 0.0 && (v_ply - v_obj).abs() < 1e-6 * v_ply.abs(),
            "{stage}: volumes {v_ply} (PLY) and {v_obj} (OBJ)"
        );
    }
    let header = std::fs::read(meshes.join("graphcut/000001.ply")).unwrap();
    assert!(String::from_utf8_lossy(&header[..800]).contains("property float rho_p"));
    // The surface colours come from the frames: not all grey.
    let text = std::fs::read_to_string(meshes.join("graphcut/000001.obj")).unwrap();
    let grey = text
        .lines()
        .filter(|l| l.ends_with(" 0.5020 0.5020 0.5020"))
        .count();
    let total = text.lines().filter(|l| l.starts_with("v ")).count();
    assert!(grey * 10 < total, "{grey} of {total} vertices unseen");
}

/// The tracked surface as one animated mesh (export format `surface`): Blender, opening the
/// rest OBJ with its default axes and adding a Mesh Cache modifier with its defaults, shows
/// at scene frame 2 the vertices of `meshes/surface/000002.ply` turned into the export
/// frame (within f32 rounding), from the PC2 and from the MDD alike. The glb of morph
/// targets passes the Khronos validator, and its base plus target k is frame k.
#[test]
fn the_tracked_surface_plays_in_blender_and_the_glb() {
    let dir = sample_run();
    let folder = dir.join("output/export/surface");
    let frame = export_frame(dir);
    let expected: Vec<Vector3<f64>> = (0..3)
        .map(|f| {
            let ply = dir.join(format!("output/export/meshes/surface/{f:06}.ply"));
            hullpose::geometry::ply::read_ply(&ply).unwrap().vertices
        })
        .map(|vs| vs.iter().map(|v| frame.point(v)).collect::<Vec<_>>())
        .collect::<Vec<_>>()
        .concat();
    let per_frame = expected.len() / 3;
    let near = |got: &[f32], want: &[Vector3<f64>], what: &str| {
        assert_eq!(got.len(), want.len() * 3, "{what}: vertex count");
        let worst = want
            .iter()
            .zip(got.chunks_exact(3))
            .map(|(w, g)| (w - Vector3::new(g[0] as f64, g[1] as f64, g[2] as f64)).norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{what}: {worst} m from the PLY");
    };

    let (doc, bin) = read_glb(&folder.join("tripod.glb"));
    let primitive = &doc["meshes"][0]["primitives"][0];
    let base = floats(
        &doc,
        &bin,
        primitive["attributes"]["POSITION"].as_u64().unwrap() as usize,
    );
    near(&base, &expected[..per_frame], "glb base");
    for k in 1..3 {
        let target = primitive["targets"][k - 1]["POSITION"].as_u64().unwrap() as usize;
        let moved: Vec<f32> = base
            .iter()
            .zip(floats(&doc, &bin, target))
            .map(|(b, d)| b + d)
            .collect();
        near(
            &moved,
            &expected[k * per_frame..(k + 1) * per_frame],
            "glb target",
        );
    }
    let script = repo_tools().join("validate_gltf.cjs");
    let probe = format!(
        "require('{}')",
        repo_tools().join("node_modules/gltf-validator").display()
    );
    let glb = folder.join("tripod.glb");
    if let Some((ok, report)) = external(
        "node",
        &[script.to_str().unwrap(), glb.to_str().unwrap()],
        &["-e", &probe],
    ) {
        assert!(ok && report.starts_with("errors 0 warnings 0"), "{report}");
    }

    let script = repo_tools().join("check_point_cache.py");
    let rest = folder.join("tripod.obj");
    for cache in ["tripod.pc2", "tripod.mdd"] {
        let out = tempfile::NamedTempFile::new().unwrap();
        let cache = folder.join(cache);
        let args = [
            "-b",
            "--factory-startup",
            "--python",
            script.to_str().unwrap(),
            "--",
            rest.to_str().unwrap(),
            cache.to_str().unwrap(),
            "2",
            out.path().to_str().unwrap(),
        ];
        let Some((ok, report)) = external("blender", &args, &["-b", "--version"]) else {
            return;
        };
        assert!(ok, "{report}");
        let got: Vec<f32> = std::fs::read(out.path())
            .unwrap()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        near(
            &got,
            &expected[2 * per_frame..],
            &format!("blender with {}", cache.display()),
        );
    }
}

#[test]
fn overlays_and_contact_sheets_are_written() {
    let dir = sample_run();
    let overlay = image::open(dir.join("output/export/overlays/cam00/000002.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(overlay.dimensions(), (256, 192));
    let frame = image::open(dir.join("data/tripod/frames/cam00/000002.png"))
        .unwrap()
        .to_rgb8();
    let changed = overlay
        .pixels()
        .zip(frame.pixels())
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        changed > 200,
        "skeleton and outline drawn: {changed} pixels"
    );
    let sheet = image::open(dir.join("output/export/contact_sheets/000002.png")).unwrap();
    // Frames narrower than a tile keep their size.
    assert!(sheet.width() > 4 * 256 && sheet.height() > 3 * 192);
}

#[test]
fn export_rewrites_from_the_cache_alone() {
    let dir = sample_run();
    let bvh = dir.join("output/export/tripod.bvh");
    let before = std::fs::read(&bvh).unwrap();
    // A copy of the run, without the BVH.
    let copy = tempfile::tempdir().unwrap();
    copy_tree(dir, copy.path());
    std::fs::remove_file(copy.path().join("output/export/tripod.bvh")).unwrap();
    let (ok, out, err) = run_cli(
        &["export", "pipeline.yaml", "--format", "bvh,glb"],
        copy.path(),
    );
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("from the cache"), "{out}");
    assert_eq!(
        std::fs::read(copy.path().join("output/export/tripod.bvh")).unwrap(),
        before
    );
    // A changed fit parameter makes the cache stale: export refuses and says what to run.
    let yaml = std::fs::read_to_string(copy.path().join("pipeline.yaml")).unwrap();
    std::fs::write(
        copy.path().join("pipeline.yaml"),
        format!("{yaml}fit:\n  stop:\n    tolerance: 0.001\n"),
    )
    .unwrap();
    let (ok, _, err) = run_cli(&["export", "pipeline.yaml", "--format", "bvh"], copy.path());
    assert!(!ok);
    assert!(
        err.contains("fit") && err.contains("stale") && err.contains("pipeline run"),
        "{err}"
    );
}
