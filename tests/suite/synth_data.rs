//! The synthetic data agrees with the camera model and reads back cleanly: masks are the
//! true mesh's silhouette through the camera model, projection is OpenCV's formula, and
//! calibration, skeleton and the whole dataset round-trip.

use crate::common;

use common::*;
use hullpose::camera::{self, Camera};
use hullpose::dataset::Sequence;
use hullpose::geometry::TriMesh;
use hullpose::skeleton::Skeleton;
use hullpose::synth::{SceneKind, SynthOptions};
use nalgebra::{Vector2, Vector3};
use std::path::Path;

fn open(root: &Path, seq: &str) -> Sequence {
    Sequence::open_with_calibration(
        &root.join("calib/cameras.yaml"),
        &root.join("data").join(seq),
    )
    .unwrap()
}

/// The silhouette of `mesh` in `cam`, by casting each pixel centre's viewing ray (the
/// camera's back-projection) at every triangle whose projection could cover it
/// (Moller-Trumbore in world space; independent of the rasterizer's normalized-plane test).
fn raycast_silhouette(cam: &Camera, mesh: &TriMesh) -> Vec<bool> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut hit = vec![false; w * h];
    let rays: Vec<(Vector3<f64>, Vector3<f64>)> = (0..w * h)
        .map(|i| cam.ray(Vector2::new((i % w) as f64, (i / w) as f64)))
        .collect();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let px: Vec<Vector2<f64>> = [a, b, c].iter().map(|p| cam.project(p).unwrap()).collect();
        let x0 = (px.iter().map(|p| p.x).fold(f64::INFINITY, f64::min) - 2.0)
            .max(0.0)
            .ceil() as usize;
        let x1 =
            (px.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max) + 2.0).min((w - 1) as f64);
        let y0 = (px.iter().map(|p| p.y).fold(f64::INFINITY, f64::min) - 2.0)
            .max(0.0)
            .ceil() as usize;
        let y1 =
            (px.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max) + 2.0).min((h - 1) as f64);
        if x1 < 0.0 || y1 < 0.0 {
            continue;
        }
        let (e1, e2) = (b - a, c - a);
        for y in y0..=y1 as usize {
            for x in x0..=x1 as usize {
                let i = y * w + x;
                if hit[i] {
                    continue;
                }
                let (o, d) = rays[i];
                let p = d.cross(&e2);
                let det = e1.dot(&p);
                if det.abs() < 1e-15 {
                    continue;
                }
                let s = o - a;
                let u = s.dot(&p) / det;
                let q = s.cross(&e1);
                let v = d.dot(&q) / det;
                let t = e2.dot(&q) / det;
                if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0 {
                    hit[i] = true;
                }
            }
        }
    }
    hit
}

fn check_masks(seq: &Sequence, frames: &[u32], cams: &[usize]) {
    for &f in frames {
        let mesh = seq.ground_truth_mesh(f).unwrap().unwrap();
        for &c in cams {
            let cam = &seq.cameras[c];
            let truth = raycast_silhouette(cam, &mesh);
            let mask = seq.load_mask(c, f).unwrap().unwrap();
            let (mut inter, mut union) = (0usize, 0usize);
            for (t, m) in truth.iter().zip(mask.as_raw()) {
                let m = *m >= 128;
                inter += (*t && m) as usize;
                union += (*t || m) as usize;
            }
            let iou = inter as f64 / union as f64;
            assert!(
                union > 500,
                "camera {} frame {f} sees the subject",
                cam.name
            );
            assert!(
                iou >= 0.999,
                "camera {} frame {f}: IoU {iou:.5} < 0.999",
                cam.name
            );
        }
    }
}

#[test]
fn tripod_masks_are_the_true_silhouettes() {
    let seq = open(&tripod().root, "tripod");
    let all: Vec<usize> = (0..seq.cameras.len()).collect();
    check_masks(&seq, &[0, 9], &all);
}

#[test]
fn humanoid_masks_are_the_true_silhouettes() {
    let seq = open(&humanoid().root, "humanoid");
    check_masks(&seq, &[0, 12, 20], &[0, 4, 8, 12]);
}

/// OpenCV's projection written out independently (cv::projectPoints with k1 k2 p1 p2 k3
/// and skew), as shared/dataset-format.md states it.
fn opencv_project(c: &Camera, x: &Vector3<f64>) -> Vector2<f64> {
    let xc = c.r * x + c.t;
    let (x, y) = (xc.x / xc.z, xc.y / xc.z);
    let [k1, k2, p1, p2, k3] = c.dist;
    let r2 = x * x + y * y;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
    let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
    let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
    Vector2::new(c.fx * xd + c.skew * yd + c.cx, c.fy * yd + c.cy)
}

#[test]
fn projection_is_opencvs_formula_and_backprojection_inverts_it() {
    let seq = open(&tripod().root, "tripod");
    let mut rng = hullpose::rng::Rng::new(3, 3);
    for cam in &seq.cameras {
        let mut skewed = cam.clone();
        skewed.skew = 1.5;
        for c in [cam, &skewed] {
            for _ in 0..200 {
                let p = Vector3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(0.3, 1.8),
                );
                let (px, depth) = c.project_with_depth(&p);
                let reference = opencv_project(c, &p);
                assert!(
                    (px - reference).norm() < 1e-9,
                    "{}: {px:?} vs {reference:?}",
                    c.name
                );
                let back = c.backproject(px, depth);
                assert!(
                    (back - p).norm() < 1e-9,
                    "{}: back-projection {back:?} vs {p:?}",
                    c.name
                );
            }
        }
    }
}

#[test]
fn calibration_and_skeleton_round_trip_exactly() {
    let root = &tripod().root;
    let cams = camera::read_cameras(&root.join("calib/cameras.yaml"))
        .unwrap()
        .cameras;
    let text = camera::cameras_to_yaml(&cams);
    assert_eq!(
        camera::parse_cameras(Path::new("x.yaml"), &text)
            .unwrap()
            .cameras,
        cams
    );
    let skel = Skeleton::read(&root.join("data/tripod/skeleton.yaml")).unwrap();
    assert_eq!(
        Skeleton::parse(Path::new("s.yaml"), &skel.to_yaml()).unwrap(),
        skel
    );
    assert_eq!(skel.bones.len(), 6);
    assert_eq!(skel.parameter_count(), 21);
}

#[test]
fn generated_datasets_read_back_without_warnings() {
    for (made, name, bones, frames) in [
        (tripod(), "tripod", 6, 19),
        (humanoid(), "humanoid", 17, 24),
    ] {
        let seq = open(&made.root, name);
        assert!(seq.warnings.is_empty(), "{name}: {:?}", seq.warnings);
        assert_eq!(seq.cameras.len(), 15);
        assert_eq!(seq.frames, (0..frames).collect::<Vec<u32>>());
        assert!(seq.has_masks && seq.has_backgrounds);
        let skel = seq.skeleton().unwrap().unwrap();
        assert_eq!(skel.bones.len(), bones);
        let joints = seq.ground_truth_joints().unwrap().unwrap();
        assert_eq!(joints.len(), bones * frames as usize);
        // Frame 0's true joints are the skeleton's.
        for b in &skel.bones {
            let row = joints
                .iter()
                .find(|r| r.frame == 0 && r.bone == b.name)
                .unwrap();
            assert!((row.head - b.head).norm() < 1e-12 && (row.tail - b.tail).norm() < 1e-12);
        }
        // Bone lengths are preserved in every frame (rigid bones).
        for r in &joints {
            let b = &skel.bones[skel.bone_index(&r.bone).unwrap()];
            assert!(((r.tail - r.head).norm() - b.length()).abs() < 1e-9);
        }
        let img = seq.load_frame(0, 0).unwrap();
        assert_eq!(
            (img.width(), img.height()),
            (seq.cameras[0].width, seq.cameras[0].height)
        );
        let bg = seq.load_background(0).unwrap().unwrap();
        assert_eq!(bg.dimensions(), img.dimensions());
        let mesh = seq.ground_truth_mesh(0).unwrap().unwrap();
        assert!(mesh.is_watertight(), "{name}: the true surface is closed");
        assert!(mesh.signed_volume() > 0.0, "{name}: outward oriented");
    }
}

fn all_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn same_seed_gives_same_bytes_and_another_seed_differs() {
    let dirs: Vec<tempfile::TempDir> = (0..3).map(|_| tempfile::tempdir().unwrap()).collect();
    for (dir, seed) in dirs.iter().zip([5, 5, 6]) {
        let mut o = SynthOptions::new(SceneKind::Tripod, dir.path());
        (o.cameras, o.width, o.height, o.frames, o.seed) = (3, 96, 72, Some(2), seed);
        o.mesh_spacing = 0.03;
        hullpose::synth::generate(&o).unwrap();
    }
    let [a, b, c] = [0, 1, 2].map(|i| all_files(dirs[i].path()));
    assert!(a.len() > 10);
    assert!(a == b, "same seed, same bytes");
    assert!(a != c, "another seed, other noise");
}

/// ground_truth/poses.csv holds each frame's true pose in the project's parameters: forward
/// kinematics of the skeleton under it gives joints.csv.
#[test]
fn true_poses_reproduce_the_true_joints() {
    for (made, name) in [(tripod(), "tripod"), (humanoid(), "humanoid")] {
        let dir = made.root.join("data").join(name);
        let skel = Skeleton::read(&dir.join("skeleton.yaml")).unwrap();
        let poses = hullpose::poses::read(&dir.join("ground_truth/poses.csv"), &skel).unwrap();
        let joints = hullpose::joints::read(&dir.join("ground_truth/joints.csv")).unwrap();
        assert_eq!(poses.len() * skel.bones.len(), joints.len());
        let mut worst: f64 = 0.0;
        for (frame, pose) in &poses {
            let posed = hullpose::skeleton::pose::joints(&skel, pose);
            for r in joints.iter().filter(|r| r.frame == *frame) {
                let (h, t) = posed[skel.bone_index(&r.bone).unwrap()];
                worst = worst.max((h - r.head).norm()).max((t - r.tail).norm());
            }
        }
        assert!(worst < 1e-9, "{name}: joints differ by {worst:e} m");
    }
}

/// `pipeline synth --scene meshes`: the humanoid's own true surfaces (z up), filmed again as
/// a given mesh sequence, give a capture whose true meshes are the input placed on the
/// floor (same vertices, the same shift for every frame), whose masks cover the subject in
/// every view, and whose visual hull lies within 2.5 cm (d90) of that truth.
#[test]
fn a_given_mesh_sequence_is_filmed_with_its_surfaces_as_the_truth() {
    let dir = process_tempdir();
    let d = dir.path();
    let mut options = SynthOptions::new(SceneKind::Humanoid, d.join("source"));
    (options.cameras, options.width, options.height) = (4, 160, 120);
    options.frames = Some(3);
    hullpose::synth::generate(&options).unwrap();
    let source = d.join("source/data/humanoid/ground_truth/meshes");
    let mut options = SynthOptions::new(SceneKind::Meshes, d.join("film"));
    (options.cameras, options.width, options.height) = (8, 320, 240);
    options.meshes = Some(source.clone());
    options.mesh_up = hullpose::geometry::axes::UpAxis::PlusZ;
    let summary = hullpose::synth::generate(&options).unwrap();
    assert_eq!(summary.frames, 3);
    let seq = d.join("film/data/meshes");
    let mut shift = None;
    for f in 0..3u32 {
        let given = hullpose::geometry::ply::read_ply(&source.join(format!("{f:06}.ply"))).unwrap();
        let truth =
            hullpose::geometry::ply::read_ply(&seq.join(format!("ground_truth/meshes/{f:06}.ply")))
                .unwrap();
        assert_eq!(truth.triangles, given.triangles);
        let s = truth.vertices[0] - given.vertices[0];
        let shift = *shift.get_or_insert(s);
        assert!(
            (truth.vertices.iter().zip(&given.vertices))
                .all(|(t, g)| (t - g - shift).norm() < 1e-5),
            "frame {f} is not the given surface shifted as frame 0"
        );
        for c in 0..8 {
            let mask = image::open(seq.join(format!("masks/cam{c:02}/{f:06}.png")))
                .unwrap()
                .into_luma8();
            let share = mask.pixels().filter(|p| p[0] > 127).count() as f64
                / (mask.width() * mask.height()) as f64;
            assert!(
                (0.01..0.5).contains(&share),
                "frame {f}, cam{c:02}: {share}"
            );
        }
    }
    let (lo, _) = hullpose::geometry::ply::read_ply(&seq.join("ground_truth/meshes/000000.ply"))
        .unwrap()
        .bounds()
        .unwrap();
    assert!(lo.z.abs() < 1e-5, "frame 0 stands on the floor: {lo}");
    let (ok, _, err) = run_cli(
        &["run", "pipeline.yaml", "--until", "visual_hull"],
        &d.join("film"),
    );
    assert!(ok, "{err}");
    let (ok, out, err) = run_cli(&["evaluate", "pipeline.yaml"], &d.join("film"));
    assert!(ok, "{err}");
    let csv = std::fs::read_to_string(d.join("film/output/evaluation/reconstruction.csv")).unwrap();
    for line in csv.lines().skip(1) {
        let accuracy: f64 = line.split(',').nth(3).unwrap().parse().unwrap();
        assert!(accuracy <= 0.025, "{line}\n{out}");
    }
}
