//! A frame's person evidence over the rig: the person model run on every camera's image,
//! then the masks made consistent across views. A mask pixel is kept only where its viewing
//! ray meets the visual hull of all the cameras' masks, which is exactly where the other
//! cameras' silhouettes support it (the ray already lies in its own camera's cone); what is
//! dropped is counted per camera.

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
/// silhouette supports (whose ray misses the visual hull of all of `masks`); returns per
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
    let Some((lo, hi)) = visual_hull::carving_box(cams, &counts, p) else {
        return out;
    };
    let size = (hi - lo).max() / CONSISTENCY_VOXELS;
    let grid = GridSpec::covering(lo, hi, size);
    let occupied = visual_hull::carve(&grid, cams, &counts, p);
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

    #[test]
    fn a_blob_no_other_camera_sees_is_dropped_and_the_body_kept() {
        let cams = crate::synth::scene::camera_ring(
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
        );
        // A vertical cylinder (a body) seen by every camera.
        let body = |p: &Vector3<f64>| p.x.hypot(p.y) < 0.2 && p.z > 0.2 && p.z < 1.6;
        let mut masks: Vec<GrayImage> = cams
            .iter()
            .map(|c| {
                let mut m = GrayImage::new(c.width, c.height);
                for z in 0..70 {
                    for a in 0..72 {
                        for r in [0.05, 0.1, 0.15, 0.19] {
                            let t = (a as f64 * 5.0).to_radians();
                            let p = Vector3::new(r * t.cos(), r * t.sin(), 0.21 + z as f64 * 0.02);
                            if let Some(px) = c.project(&p) {
                                if body(&p) && c.in_image(&px) {
                                    fill_square(&mut m, px, 1);
                                }
                            }
                        }
                    }
                }
                m
            })
            .collect();
        let body_pixels = masks[2].pixels().filter(|p| p.0[0] > 0).count();
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
}
