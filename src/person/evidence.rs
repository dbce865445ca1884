//! A frame's person evidence over the rig: the person model run on every camera's image,
//! then the masks made consistent across views. A mask pixel is kept only where its viewing
//! ray meets the visual hull of the cameras' masks, which is where the other cameras'
//! silhouettes support it (the ray already lies in its own camera's cone). With four or more
//! cameras that hull lets one camera disagree, so a limb one view's mask misses is kept in
//! the views that show it; what is dropped is counted per camera.

use super::model::{folder, PersonModel};
use super::{PersonFrame, PersonView};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::geometry::grid::GridSpec;
use crate::recon::visual_hull::{self, MaskCounts, VisualHullParams};
use image::{GrayImage, RgbImage};
use nalgebra::{Vector2, Vector3};
use std::cell::RefCell;

thread_local! {
    /// Each worker thread's loaded model (sessions are not shared between threads).
    static MODEL: RefCell<Option<PersonModel>> = const { RefCell::new(None) };
}

/// Runs `f` with this thread's model, loading it on first use.
fn with_model<T>(f: impl FnOnce(&mut PersonModel) -> Result<T>) -> Result<T> {
    MODEL.with(|m| {
        let mut m = m.borrow_mut();
        if m.is_none() {
            *m = Some(PersonModel::load(&folder())?);
        }
        f(m.as_mut().expect("loaded above"))
    })
}

/// Edge of the voxels of the consistency hull, as a share of the carving box's longest side.
const CONSISTENCY_VOXELS: f64 = 128.0;

/// The person's masks and evidence of one frame: `images` one per camera of `cams`.
/// A camera where nobody is found gets a full mask (it carves nothing) and `found: false`.
/// Fewer than two cameras with a person is an error naming them.
pub fn frame_evidence(
    cams: &[Camera],
    images: &[RgbImage],
    hull: &VisualHullParams,
) -> Result<(Vec<GrayImage>, PersonFrame)> {
    let mut masks = Vec::with_capacity(cams.len());
    let mut views = Vec::with_capacity(cams.len());
    for (cam, img) in cams.iter().zip(images) {
        let person = with_model(|m| m.find(img))?;
        match person {
            Some(p) => {
                masks.push(p.mask);
                views.push(PersonView {
                    camera: cam.name.clone(),
                    found: true,
                    score: p.score,
                    unsupported: 0.0,
                    // The project's pixel centres are at integers.
                    landmarks: p
                        .landmarks
                        .iter()
                        .map(|l| [l.x - 0.5, l.y - 0.5, l.visibility as f64])
                        .collect(),
                });
            }
            None => {
                masks.push(GrayImage::from_pixel(
                    img.width(),
                    img.height(),
                    image::Luma([255]),
                ));
                views.push(PersonView {
                    camera: cam.name.clone(),
                    found: false,
                    score: 0.0,
                    unsupported: 0.0,
                    landmarks: Vec::new(),
                });
            }
        }
    }
    let missing: Vec<&str> = views
        .iter()
        .filter(|v| !v.found)
        .map(|v| v.camera.as_str())
        .collect();
    if views.len() - missing.len() < 2 {
        return Err(Error::Usage(format!(
            "the person model finds nobody in camera(s) {} (a person must be seen by at least \
             two cameras): is the subject in view? Synthetic textures and very small people \
             are not recognised; give masks (masks/<camera>/) or background plates instead",
            missing.join(", ")
        )));
    }
    // The keypoints bound the person (few cameras' cones bound little of the room).
    let mut frame = PersonFrame { views };
    let mut hull = hull.clone();
    if hull.bbox.is_none() {
        hull.bbox =
            super::triangulate::body_box(&super::triangulate::triangulate_frame(cams, &frame));
    }
    let found: Vec<bool> = frame.views.iter().map(|v| v.found).collect();
    let dropped = drop_unsupported(cams, &mut masks, &found, &hull);
    for (view, share) in frame.views.iter_mut().zip(dropped) {
        view.unsupported = share;
    }
    Ok((masks, frame))
}

/// Removes from the masks of the cameras marked in `cleaned` every pixel no other camera's
/// silhouette supports (whose ray misses the visual hull of `masks`, one camera allowed to
/// disagree with four or more); returns per
/// camera the share of its mask's pixels removed (0 for the others).
pub fn drop_unsupported(
    cams: &[Camera],
    masks: &mut [GrayImage],
    cleaned: &[bool],
    hull: &VisualHullParams,
) -> Vec<f64> {
    let supported = supported_by_hull(cams, masks, hull);
    masks
        .iter_mut()
        .zip(&supported)
        .zip(cleaned)
        .map(|((mask, support), &clean)| {
            if !clean {
                return 0.0;
            }
            let (mut before, mut dropped) = (0usize, 0usize);
            for (m, s) in mask.iter_mut().zip(support.as_raw()) {
                if *m > 0 {
                    before += 1;
                    if *s == 0 {
                        *m = 0;
                        dropped += 1;
                    }
                }
            }
            if before > 0 {
                dropped as f64 / before as f64
            } else {
                0.0
            }
        })
        .collect()
}

/// Per camera, the pixels whose ray meets the visual hull of `masks` (255), at a coarse
/// resolution ([`CONSISTENCY_VOXELS`] along the box's longest side): every occupied voxel's
/// footprint (its bounding ball's projection) is marked.
fn supported_by_hull(cams: &[Camera], masks: &[GrayImage], p: &VisualHullParams) -> Vec<GrayImage> {
    let counts: Vec<MaskCounts> = masks
        .iter()
        .zip(cams)
        .map(|(m, c)| MaskCounts::new(m, c))
        .collect();
    let mut out: Vec<GrayImage> = cams
        .iter()
        .map(|c| GrayImage::new(c.width, c.height))
        .collect();
    // One camera may disagree (with four or more): a limb the person model misses in one
    // view stays in the others instead of being dropped from all of them. Such a voxel must
    // then be seen by three cameras, so that two disagreeing views support nothing.
    let mut lenient = p.clone();
    if cams.len() >= 4 {
        lenient.all_but = lenient.all_but.max(1);
        lenient.min_views = lenient.min_views.max(3);
    }
    let Some((lo, hi)) = visual_hull::carving_box(cams, &counts, p) else {
        return out;
    };
    let size = (hi - lo).max() / CONSISTENCY_VOXELS;
    let grid = GridSpec::covering(lo, hi, size);
    let occupied = visual_hull::carve(&grid, cams, &counts, &lenient);
    let centres: Vec<Vector3<f64>> = occupied
        .iter()
        .enumerate()
        .filter(|(_, o)| **o)
        .map(|(i, _)| {
            let [x, y, z] = grid.coords(i);
            grid.origin + size * Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5)
        })
        .collect();
    let radius = size * 3f64.sqrt() / 2.0;
    for (cam, img) in cams.iter().zip(&mut out) {
        let focal = cam.fx.max(cam.fy) * cam.distortion_gain();
        for c in &centres {
            let (px, depth) = cam.project_with_depth(c);
            if depth <= radius {
                continue;
            }
            let r = (focal * radius / (depth - radius)).ceil() as i64 + 1;
            fill_square(img, px, r);
        }
    }
    out
}

fn fill_square(img: &mut GrayImage, px: Vector2<f64>, r: i64) {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (x, y) = (px.x.round() as i64, px.y.round() as i64);
    if x + r < 0 || y + r < 0 || x - r >= w || y - r >= h {
        return;
    }
    for yy in (y - r).max(0)..(y + r + 1).min(h) {
        for xx in (x - r).max(0)..(x + r + 1).min(w) {
            img.put_pixel(xx as u32, yy as u32, image::Luma([255]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring() -> Vec<Camera> {
        crate::synth::scene::camera_ring(
            &crate::synth::scene::RingSpec {
                count: 6,
                radius: 3.0,
                heights: vec![1.2],
                target: Vector3::new(0.0, 0.0, 0.9),
                focal_1024: 1100.0,
                width: 320,
                height: 240,
            },
            3,
        )
    }

    /// Each camera's mask of the points `points`.
    fn masks_of(cams: &[Camera], points: &[Vector3<f64>]) -> Vec<GrayImage> {
        cams.iter()
            .map(|c| {
                let mut m = GrayImage::new(c.width, c.height);
                for p in points {
                    if let Some(px) = c.project(p) {
                        if c.in_image(&px) {
                            fill_square(&mut m, px, 1);
                        }
                    }
                }
                m
            })
            .collect()
    }

    /// A vertical cylinder 0.2 m in radius from 0.21 to 1.6 m (a body), sampled densely.
    fn body_points() -> Vec<Vector3<f64>> {
        let mut points = Vec::new();
        for z in 0..70 {
            for a in 0..72 {
                for r in [0.05, 0.1, 0.15, 0.19] {
                    let t = (a as f64 * 5.0).to_radians();
                    points.push(Vector3::new(
                        r * t.cos(),
                        r * t.sin(),
                        0.21 + z as f64 * 0.02,
                    ));
                }
            }
        }
        points
    }

    fn count(m: &GrayImage) -> usize {
        m.pixels().filter(|p| p.0[0] > 0).count()
    }

    #[test]
    fn a_blob_no_other_camera_sees_is_dropped_and_the_body_kept() {
        let cams = ring();
        let mut masks = masks_of(&cams, &body_points());
        let body_pixels = count(&masks[2]);
        // Camera 2 also marks a blob in the image's corner (the room, a bystander).
        for y in 0..40 {
            for x in 0..40 {
                masks[2].put_pixel(x, y, image::Luma([255]));
            }
        }
        let hull = VisualHullParams::default();
        let dropped = drop_unsupported(&cams, &mut masks, &[true; 6], &hull);
        let blob_left = (0..40)
            .flat_map(|y| (0..40).map(move |x| (x, y)))
            .filter(|&(x, y)| masks[2].get_pixel(x, y).0[0] > 0)
            .count();
        assert_eq!(blob_left, 0, "the unsupported blob stays");
        let expected = 1600.0 / (1600 + body_pixels) as f64;
        assert!(
            (dropped[2] - expected).abs() < 0.02,
            "{dropped:?} vs {expected}"
        );
        for (c, d) in dropped.iter().enumerate().filter(|(c, _)| *c != 2) {
            assert!(*d < 0.02, "camera {c} lost {d} of the body");
        }
    }

    /// An arm (a bar held out from the body) that one camera's mask misses, as the person
    /// model does with a forearm seen from behind: the other cameras keep it.
    #[test]
    fn a_limb_one_camera_misses_stays_in_the_others() {
        let cams = ring();
        let body = body_points();
        let mut with_arm = body.clone();
        for i in 0..40 {
            for j in -3..=3 {
                for k in -3..=3 {
                    let (dy, dz) = (j as f64 * 0.01, k as f64 * 0.01);
                    with_arm.push(Vector3::new(0.2 + i as f64 * 0.01, dy, 1.3 + dz));
                }
            }
        }
        let mut masks = masks_of(&cams, &with_arm);
        masks[4] = masks_of(&cams[4..5], &body).remove(0);
        let arm_pixels: Vec<usize> = masks.iter().map(count).collect();
        let body_pixels: Vec<usize> = masks_of(&cams, &body).iter().map(count).collect();
        // The box the keypoints give (the body's reach grown by 0.3 m).
        let hull = VisualHullParams {
            bbox: Some(crate::recon::visual_hull::BoundingBox {
                min: [-0.5, -0.5, -0.1],
                max: [0.9, 0.5, 1.9],
            }),
            ..Default::default()
        };
        drop_unsupported(&cams, &mut masks, &[true; 6], &hull);
        for c in (0..6).filter(|&c| c != 4) {
            let arm = arm_pixels[c] - body_pixels[c];
            let kept = count(&masks[c]) as f64 - body_pixels[c] as f64;
            assert!(
                kept >= 0.9 * arm as f64,
                "camera {c} kept {kept} of the arm's {arm} pixels"
            );
        }
    }
}
