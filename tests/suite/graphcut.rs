//! The graph-cut refinement: better than the hull where cameras see the surface, the hull's
//! shape where nothing does (the phantom volume stays), closed meshes, no collapse.

use crate::common;

use common::*;
use hullpose::geometry::grid::GridSpec;
use hullpose::geometry::nearest::NearestTree;
use hullpose::geometry::TriMesh;
use std::path::Path;

/// The rows of `pipeline evaluate`.
fn evaluate(dir: &Path, frames: &str) -> Vec<ReconRow> {
    let (ok, _, err) = run_cli(
        &[
            "run",
            "pipeline.yaml",
            "--frames",
            frames,
            "--until",
            "graphcut",
        ],
        dir,
    );
    assert!(ok, "{err}");
    let (ok, out, err) = run_cli(&["evaluate", "pipeline.yaml", "--frames", frames], dir);
    assert!(ok, "{err}");
    eprintln!("{out}");
    reconstruction_rows(dir)
}

fn mesh(dir: &Path, stage: &str, frame: u32) -> TriMesh {
    hullpose::geometry::ply::read_ply(&dir.join(format!("cache/{stage}/{frame:06}.ply"))).unwrap()
}

fn grid(dir: &Path, stage: &str, frame: u32) -> (GridSpec, Vec<f32>) {
    use hullpose::artifacts::reconstruction::{read_grid, Surface};
    let surface = if stage == "graphcut" {
        Surface::Refined
    } else {
        Surface::Hull
    };
    read_grid(
        &hullpose::cache::Cache::new(dir.join("cache")),
        surface,
        frame,
    )
    .unwrap()
}

/// Over true-surface samples seen by at least two cameras where the hull lies more than two
/// voxels away: mean distance to the hull and to the refined surface (metres), and count.
fn concavity_errors(made: &Made, seq: &str, dir: &Path, frame: u32) -> (f64, f64, usize) {
    let sequence = hullpose::dataset::Sequence::open_with_calibration(
        &made.root.join("calib/cameras.yaml"),
        &made.root.join("data").join(seq),
    )
    .unwrap();
    let truth = sequence.ground_truth_mesh(frame).unwrap().unwrap();
    let normals = truth.vertex_normals();
    let truth_index = NearestTree::new(&truth.vertices);
    let depth = hullpose::photo::depth_maps(&sequence.cameras, &truth);
    let samples = hullpose::eval::sample_surface(&truth, 0.005);
    let hull = NearestTree::new(&mesh(dir, "visual_hull", frame).vertices);
    let refined = NearestTree::new(&mesh(dir, "graphcut", frame).vertices);
    let (mut dh, mut dr, mut n) = (0.0, 0.0, 0usize);
    for s in &samples {
        let normal = normals[truth_index.nearest(s).unwrap().0];
        // Seen clearly: facing the camera, and no true surface more than 1 cm in front of it
        // at its projection's pixel or the 8 around it (not on an occluding contour, where
        // a view grazes the surface).
        let seen = sequence
            .cameras
            .iter()
            .zip(&depth)
            .filter(|(cam, d)| {
                let (px, z) = cam.project_with_depth(s);
                if z <= 0.0 || !cam.in_image(&px) || normal.dot(&(cam.centre() - s)) <= 0.0 {
                    return false;
                }
                let (w, h) = (cam.width as i64, cam.height as i64);
                let (u, v) = (px.x.round() as i64, px.y.round() as i64);
                (-1..=1).all(|dy| {
                    (-1..=1).all(|dx| {
                        let (x, y) = ((u + dx).clamp(0, w - 1), (v + dy).clamp(0, h - 1));
                        (z as f32) <= d[(y * w + x) as usize] + 0.01
                    })
                })
            })
            .count();
        let h = hull.nearest(s).unwrap().1.sqrt();
        if seen >= 2 && h > 0.02 {
            dh += h;
            dr += refined.nearest(s).unwrap().1.sqrt();
            n += 1;
        }
    }
    (dh / n.max(1) as f64, dr / n.max(1) as f64, n)
}

/// Checks a scene; `max_ratio` bounds the refined surface's error over the hull's in seen
/// concavities.
fn check_scene(
    made: &Made,
    seq: &str,
    frames: &str,
    concavity_frames: &[u32],
    max_ratio: f64,
) -> tempfile::TempDir {
    // The evidence-weighted ballooning: the uniform one of method.md carves about two voxels
    // at most (-29% on the tripod, -7% on the humanoid; see the README).
    let dir = run_folder(made, seq, "graphcut:\n  ballooning_evidence: 0.3\n");
    let rows = evaluate(dir.path(), frames);
    for r in rows.iter().filter(|r| r.stage == "graphcut") {
        let (f, acc) = (r.frame, r.accuracy);
        let hull = rows
            .iter()
            .find(|h| h.frame == f && h.stage == "visual_hull")
            .unwrap();
        // The hull lies on the silhouette cones below the voxel size; the cut places the
        // surfaces it carves between voxels, so its accuracy may trail the hull's by up to
        // a voxel overall while it halves the hull's error in the concavities (below).
        assert!(
            acc <= hull.accuracy + 0.01,
            "{seq} t{f}: graphcut accuracy {acc:.4} more than a voxel worse than the hull's {:.4}",
            hull.accuracy
        );
        assert!(
            r.inside >= 0.98,
            "{seq} t{f}: inside completeness {}",
            r.inside
        );
        let m = mesh(dir.path(), "graphcut", f);
        assert!(
            m.is_watertight() && m.signed_volume() > 0.0,
            "{seq} t{f}: closed, outward"
        );
    }
    for &f in concavity_frames {
        let (hull, refined, n) = concavity_errors(made, seq, dir.path(), f);
        eprintln!("{seq} t{f}: {n} seen samples > 2 voxels from the hull: hull {:.2} cm, refined {:.2} cm", hull * 100.0, refined * 100.0);
        assert!(n > 50, "{seq} t{f}: such regions exist");
        // The refinement at least halves the hull's error there (measured: tripod -81% at
        // 512x384, humanoid -58% at 384x288, where a pixel is about a voxel).
        assert!(
            refined <= max_ratio * hull,
            "{seq} t{f}: refined {refined:.4} vs hull {hull:.4}"
        );
    }
    dir
}

#[test]
fn tripod_refinement_beats_the_hull_where_seen_and_keeps_the_phantom() {
    let made = tripod();
    let dir = check_scene(made, "tripod", "0..18", &[0], 0.5);
    // The phantom volume beneath the hub survives the refinement on t6-t8 (nothing sees it).
    let skel =
        hullpose::skeleton::Skeleton::read(&made.root.join("data/tripod/skeleton.yaml")).unwrap();
    let hub = skel.bones[0].head;
    for f in [6, 7, 8] {
        let (g, sdf) = grid(dir.path(), "graphcut", f);
        let truth = hullpose::geometry::ply::read_ply(
            &made
                .root
                .join(format!("data/tripod/ground_truth/meshes/{f:06}.ply")),
        )
        .unwrap();
        let tg = Grid {
            lo: g.origin,
            size: g.voxel,
            dims: g.dims,
        };
        let near_truth = dilate(&tg, &voxelize(&tg, &truth));
        let phantom: Vec<bool> = (0..g.len())
            .map(|i| {
                let [x, y, z] = g.coords(i);
                let c = g.centre(x, y, z);
                sdf[i] < 0.0
                    && !near_truth[i]
                    && (c.xy() - hub.xy()).norm() < 0.25
                    && c.z < hub.z - 0.10
            })
            .collect();
        let largest = components(&tg, &phantom)
            .into_iter()
            .map(|c| c.len())
            .max()
            .unwrap_or(0);
        let volume_cm3 = largest as f64 * 1e6 * g.voxel.powi(3);
        eprintln!("t{f}: phantom after refinement {volume_cm3:.0} cm^3");
        assert!(
            volume_cm3 > 100.0,
            "t{f}: the phantom volume stays ({volume_cm3:.0} cm^3)"
        );
    }
}

#[test]
fn humanoid_refinement_beats_the_hull_where_seen() {
    check_scene(humanoid(), "humanoid", "0..0", &[0], 0.5);
}

/// Per-camera silhouette coverage of the hull and of the refined surface, and the accuracy of
/// both, for frame 0 of a run with `extra` configuration.
fn coverage_and_accuracy(made: &Made, seq: &str, extra: &str) -> (Vec<(f64, f64)>, f64, f64) {
    let dir = run_folder(made, seq, extra);
    let rows = evaluate(dir.path(), "0..0");
    let config = hullpose::config::Config::load(&dir.path().join("pipeline.yaml")).unwrap();
    let job = hullpose::runner::Job::load(config, None).unwrap();
    let hull = hullpose::eval::reprojection_agreement(
        &job,
        hullpose::artifacts::reconstruction::Surface::Hull,
        0,
    )
    .unwrap();
    let cut = hullpose::eval::reprojection_agreement(
        &job,
        hullpose::artifacts::reconstruction::Surface::Refined,
        0,
    )
    .unwrap();
    let acc = |stage: &str| rows.iter().find(|r| r.stage == stage).unwrap().accuracy;
    (
        hull.iter()
            .zip(&cut)
            .map(|(h, c)| (h.coverage, c.coverage))
            .collect(),
        acc("visual_hull"),
        acc("graphcut"),
    )
}

/// A low ballooning weight carves into the silhouettes; with `pin_rims` the refined surface
/// explains every silhouette as well as the hull (reprojected coverage per camera, within
/// 0.05%) and its accuracy stays within a voxel of the hull's (which lies on the cones).
#[test]
fn pinned_rims_keep_the_silhouettes_explained() {
    let made = humanoid();
    let (free, _, _) = coverage_and_accuracy(made, "humanoid", "graphcut:\n  ballooning: 100\n");
    let lost = free.iter().map(|(h, c)| h - c).fold(0.0, f64::max);
    eprintln!("without pinned rims: largest coverage loss {lost:.5}");
    assert!(lost > 0.002, "the unpinned cut uncovers silhouette pixels");
    let (pinned, hull_acc, cut_acc) = coverage_and_accuracy(
        made,
        "humanoid",
        "graphcut:\n  ballooning: 100\n  pin_rims: true\n",
    );
    for (k, (h, c)) in pinned.iter().enumerate() {
        eprintln!("camera {k}: hull {h:.5}, refined {c:.5}");
        assert!(
            *c >= h - 0.0005,
            "camera {k}: refined coverage {c} below the hull's {h}"
        );
    }
    assert!(
        cut_acc < hull_acc + 0.01,
        "refined accuracy {cut_acc} vs the hull's {hull_acc}: more than a voxel worse"
    );
}
