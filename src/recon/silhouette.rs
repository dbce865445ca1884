//! Stage 1, silhouettes (method.md "Stage 1"): given masks pass through; otherwise
//! background subtraction against the camera's background plate.
//!
//! Per pixel, the observed colour I is compared with the plate's colour B in the
//! brightness/chromaticity model of Horprasert et al. (1999): the brightness ratio
//! `a = (I·B)/(B·B)` and the chromaticity distortion `cd = |I - a·B|` (8-bit levels). A shadow
//! or a global brightness change scales B (small `cd`, `a` below or near 1), the subject
//! changes its colour direction (large `cd`) or its brightness far beyond a shadow. The raw
//! mask is then cleaned: an opening removes specks, a closing mends one-pixel cracks,
//! background holes smaller than `max_hole_px` are filled (real gaps, such as between an arm
//! on the hip and the body, are larger), and only the subject's connected components are
//! kept (those at least `min_component_fraction` of the largest).

use image::{GrayImage, RgbImage};
use serde::{Deserialize, Serialize};

/// Where silhouettes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SilhouetteMethod {
    /// Given masks when the sequence has them, background subtraction otherwise.
    Auto,
    /// Always the given masks (an error when there are none).
    Masks,
    /// Always background subtraction (an error without background plates).
    Background,
    /// Subtraction of one constant background colour (`background_color`), for captures on
    /// a uniform backdrop without plates (e.g. objects on black).
    Constant,
    /// Subtraction of a plate learned from the frames themselves, for captures without
    /// plates where the subject moves through the view ([`super::learned_background`]).
    Learned,
    /// A learned person model's mask in each image ([`crate::person`]), made consistent
    /// across the cameras: for captures of one person without masks or plates.
    Person,
}

/// Parameters of the silhouette stage (pipeline.yaml key `silhouette`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SilhouetteParams {
    /// Source of the masks: auto, masks, background, constant, learned or person. Default
    /// auto: the given masks, else background subtraction with the plates, else the person
    /// model (when it is set up).
    pub method: SilhouetteMethod,
    /// Chromaticity distortion above which a pixel is foreground, 8-bit levels. Default 12.
    pub color_threshold: f64,
    /// Brightness ratio below which a pixel is foreground even with the background's colour
    /// (darker than any shadow). Default 0.4.
    pub min_brightness: f64,
    /// Brightness ratio above which a pixel is foreground. Default 1.25.
    pub max_brightness: f64,
    /// Radius of the speck-removing opening, pixels. Default 1.
    pub open_radius: u32,
    /// Radius of the crack-mending closing, pixels. Default 0 (a closing also seals real narrow gaps between limbs).
    pub close_radius: u32,
    /// Background regions enclosed by the subject up to this area are filled, pixels at
    /// 1024x768 (scaled with the image area). Default 60.
    pub max_hole_px: u32,
    /// Foreground components smaller than this share of the largest are dropped. Default 0.01.
    pub min_component_fraction: f64,
    /// The backdrop's colour for method `constant`, 8-bit RGB. Default [0, 0, 0].
    pub background_color: [u8; 3],
    /// Method `constant`: a pixel farther than this from `background_color` (Euclidean RGB
    /// distance, 8-bit levels) is foreground. Default 48.
    pub constant_threshold: f64,
    /// Given masks get the same clean-up as subtracted ones (opening, closing, small holes
    /// filled, small components dropped): for real masks with specks, floor blobs or a
    /// cable line. Default false: given masks are used as they are.
    pub clean_given: bool,
    /// Method `learned`: frames whose colours lie within this distance of each other show
    /// the same thing (Euclidean RGB distance, 8-bit levels). Default 20.
    pub learned_tolerance: f64,
    /// Method `learned`: a pixel whose steadiest colour fills fewer than this share of the
    /// frames never showed its background; it counts as the subject's in every frame.
    /// Default 0.2.
    pub learned_min_share: f64,
    /// Method `learned`: a camera with more than this share of its pixels never showing the
    /// background is refused (plates or masks are needed). Default 0.02.
    pub learned_max_undecided: f64,
}

impl Default for SilhouetteParams {
    fn default() -> Self {
        SilhouetteParams {
            method: SilhouetteMethod::Auto,
            color_threshold: 12.0,
            min_brightness: 0.4,
            max_brightness: 1.25,
            open_radius: 1,
            close_radius: 0,
            max_hole_px: 60,
            min_component_fraction: 0.01,
            background_color: [0, 0, 0],
            constant_threshold: 48.0,
            clean_given: false,
            learned_tolerance: 20.0,
            learned_min_share: 0.2,
            learned_max_undecided: 0.02,
        }
    }
}

/// The raw foreground decision per pixel (true = subject).
pub fn classify(frame: &RgbImage, background: &RgbImage, p: &SilhouetteParams) -> Vec<bool> {
    classify_up_to(frame, background, p, p.max_brightness)
}

/// [`classify`] with brightness ratios up to `max_brightness` taken as the background's.
pub fn classify_up_to(
    frame: &RgbImage,
    background: &RgbImage,
    p: &SilhouetteParams,
    max_brightness: f64,
) -> Vec<bool> {
    frame
        .pixels()
        .zip(background.pixels())
        .map(|(i, b)| {
            let i = i.0.map(|v| v as f64);
            let b = b.0.map(|v| v as f64 + 1.0); // +1 keeps black plates well defined
            let bb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
            let a = (i[0] * b[0] + i[1] * b[1] + i[2] * b[2]) / bb;
            let cd =
                ((i[0] - a * b[0]).powi(2) + (i[1] - a * b[1]).powi(2) + (i[2] - a * b[2]).powi(2))
                    .sqrt();
            cd > p.color_threshold || a < p.min_brightness || a > max_brightness
        })
        .collect()
}

/// Binary dilation (or erosion) of a w x h mask with a square element of radius r; the
/// window is clamped at the image border.
fn morph(mask: &[bool], w: usize, h: usize, r: usize, dilate: bool) -> Vec<bool> {
    if r == 0 {
        return mask.to_vec();
    }
    // Separable: a pass along rows, then one along columns.
    let pass = |src: &[bool], horizontal: bool| -> Vec<bool> {
        let mut out = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let (at, len) = if horizontal { (x, w) } else { (y, h) };
                let window = at.saturating_sub(r)..=(at + r).min(len - 1);
                let mut values = window.map(|k| {
                    if horizontal {
                        src[y * w + k]
                    } else {
                        src[k * w + x]
                    }
                });
                out[y * w + x] = if dilate {
                    values.any(|v| v)
                } else {
                    values.all(|v| v)
                };
            }
        }
        out
    };
    pass(&pass(mask, true), false)
}

/// Connected components (8-connected when `diagonal`) of pixels equal to `value`:
/// component id per pixel (u32::MAX for other pixels) and the size of each component.
fn components(
    mask: &[bool],
    w: usize,
    h: usize,
    value: bool,
    diagonal: bool,
) -> (Vec<u32>, Vec<usize>) {
    let mut id = vec![u32::MAX; w * h];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for s in 0..w * h {
        if mask[s] != value || id[s] != u32::MAX {
            continue;
        }
        let c = sizes.len() as u32;
        let mut size = 0;
        id[s] = c;
        stack.push(s);
        while let Some(p) = stack.pop() {
            size += 1;
            let (x, y) = ((p % w) as i64, (p / w) as i64);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    if (dx == 0 && dy == 0) || (!diagonal && dx != 0 && dy != 0) {
                        continue;
                    }
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let q = ny as usize * w + nx as usize;
                    if mask[q] == value && id[q] == u32::MAX {
                        id[q] = c;
                        stack.push(q);
                    }
                }
            }
        }
        sizes.push(size);
    }
    (id, sizes)
}

/// Cleans a raw mask: opening, closing, small-hole filling, subject components only.
pub fn clean(raw: &[bool], w: usize, h: usize, p: &SilhouetteParams) -> Vec<bool> {
    let (o, c) = (p.open_radius as usize, p.close_radius as usize);
    let opened = morph(&morph(raw, w, h, o, false), w, h, o, true);
    let mut mask = morph(&morph(&opened, w, h, c, true), w, h, c, false);
    // Fill enclosed background regions that are small (holes in the subject's texture).
    let max_hole = (p.max_hole_px as f64 * (w * h) as f64 / (1024.0 * 768.0)).round() as usize;
    let (bg_id, bg_sizes) = components(&mask, w, h, false, false);
    let mut touches_border = vec![false; bg_sizes.len()];
    for x in 0..w {
        for y in [0, h - 1] {
            if let Some(t) = touches_border.get_mut(bg_id[y * w + x] as usize) {
                *t = true;
            }
        }
    }
    for y in 0..h {
        for x in [0, w - 1] {
            if let Some(t) = touches_border.get_mut(bg_id[y * w + x] as usize) {
                *t = true;
            }
        }
    }
    for (i, m) in mask.iter_mut().enumerate() {
        let c = bg_id[i] as usize;
        if !*m && !touches_border[c] && bg_sizes[c] <= max_hole {
            *m = true;
        }
    }
    // Keep the subject's components.
    let (fg_id, fg_sizes) = components(&mask, w, h, true, true);
    let largest = fg_sizes.iter().copied().max().unwrap_or(0) as f64;
    for (i, m) in mask.iter_mut().enumerate() {
        if *m && (fg_sizes[fg_id[i] as usize] as f64) < p.min_component_fraction * largest {
            *m = false;
        }
    }
    mask
}

/// Constant-colour subtraction: the cleaned silhouette of the pixels farther than
/// `constant_threshold` from `background_color`.
pub fn subtract_constant(frame: &RgbImage, p: &SilhouetteParams) -> GrayImage {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let c = p.background_color.map(|v| v as f64);
    let raw: Vec<bool> = frame
        .pixels()
        .map(|px| {
            let d2: f64 = (0..3).map(|k| (px.0[k] as f64 - c[k]).powi(2)).sum();
            d2.sqrt() > p.constant_threshold
        })
        .collect();
    to_image(&clean(&raw, w, h, p), w, h)
}

/// A given mask (pixels of 128 and above are the subject) after [`clean`].
pub fn clean_given(mask: &GrayImage, p: &SilhouetteParams) -> GrayImage {
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let raw: Vec<bool> = mask.as_raw().iter().map(|&v| v >= 128).collect();
    to_image(&clean(&raw, w, h, p), w, h)
}

fn to_image(mask: &[bool], w: usize, h: usize) -> GrayImage {
    GrayImage::from_raw(
        w as u32,
        h as u32,
        mask.iter().map(|&m| if m { 255 } else { 0 }).collect(),
    )
    .expect("sizes match")
}

/// Background subtraction: the cleaned silhouette of `frame` against `background`.
pub fn subtract_background(
    frame: &RgbImage,
    background: &RgbImage,
    p: &SilhouetteParams,
) -> GrayImage {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    to_image(&clean(&classify(frame, background, p), w, h, p), w, h)
}

/// Checks the method `learned` keys; the message names the key.
pub fn validate(p: &SilhouetteParams) -> std::result::Result<(), crate::error::Refusal> {
    if !(p.learned_tolerance.is_finite() && p.learned_tolerance > 0.0) {
        return Err(format!(
            "key 'silhouette.learned_tolerance': {} is not a positive RGB distance (8-bit levels; default 20)",
            p.learned_tolerance
        )
        .into());
    }
    for (key, v) in [
        ("learned_min_share", p.learned_min_share),
        ("learned_max_undecided", p.learned_max_undecided),
    ] {
        if !(0.0..=1.0).contains(&v) {
            return Err(
                format!("key 'silhouette.{key}': {v} is not a share between 0 and 1").into(),
            );
        }
    }
    Ok(())
}

/// A frame's mask against a learned plate ([`super::learned_background::Learned::subject`]).
pub fn subtract_learned(
    frame: &RgbImage,
    learned: &super::learned_background::Learned,
    p: &SilhouetteParams,
) -> GrayImage {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let raw = learned.subject(frame, p);
    to_image(&clean(&raw, w, h, p), w, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shadows_and_brightness_changes_stay_background_colour_changes_do_not() {
        let bg = RgbImage::from_pixel(40, 30, image::Rgb([120, 100, 80]));
        let mut frame = bg.clone();
        for y in 0..30 {
            for x in 0..40 {
                let p = frame.get_pixel_mut(x, y);
                if x < 10 {
                    p.0 = [66, 55, 44]; // shadow: 0.55 of the plate
                } else if (20..30).contains(&x) && (10..20).contains(&y) {
                    p.0 = [40, 160, 60]; // subject
                } else {
                    p.0 = [126, 105, 84]; // 5% brighter
                }
            }
        }
        let m = subtract_background(&frame, &bg, &SilhouetteParams::default());
        let count = m.pixels().filter(|p| p.0[0] == 255).count();
        assert_eq!(count, 100);
        assert_eq!(m.get_pixel(25, 15).0[0], 255);
    }

    /// A given mask with specks, a small floor blob, a one-pixel cable line and a small hole
    /// comes back as the subject alone with `clean_given`.
    #[test]
    fn given_masks_are_cleaned_on_request() {
        let (w, h) = (160u32, 120u32);
        let disc = |x: u32, y: u32| (x as f64 - 80.0).powi(2) + (y as f64 - 60.0).powi(2) <= 900.0;
        let truth =
            GrayImage::from_fn(w, h, |x, y| image::Luma([if disc(x, y) { 255 } else { 0 }]));
        let mut given = truth.clone();
        for k in 0..25u32 {
            given.put_pixel((k * 37) % w, (k * 53 + 7) % 20, image::Luma([255]));
            // specks
        }
        for x in 0..6 {
            for y in 110..114 {
                given.put_pixel(10 + x, y, image::Luma([255])); // a floor blob of 24 pixels
            }
        }
        for x in 110..160 {
            given.put_pixel(x, 60, image::Luma([255])); // a cable from the subject
        }
        given.put_pixel(80, 60, image::Luma([0])); // a hole in the subject
        let iou = |m: &GrayImage| {
            let (mut both, mut either) = (0, 0);
            for (a, b) in m.pixels().zip(truth.pixels()) {
                let (a, b) = (a.0[0] >= 128, b.0[0] >= 128);
                both += (a && b) as usize;
                either += (a || b) as usize;
            }
            both as f64 / either as f64
        };
        let cleaned = clean_given(&given, &SilhouetteParams::default());
        assert!(iou(&given) < 0.97, "the damage shows: {}", iou(&given));
        assert!(iou(&cleaned) > 0.99, "cleaned: {}", iou(&cleaned));
        assert_eq!(cleaned.get_pixel(80, 60).0[0], 255, "the hole is filled");
        assert_eq!(cleaned.get_pixel(140, 60).0[0], 0, "the cable is gone");
        assert_eq!(cleaned.get_pixel(12, 112).0[0], 0, "the floor blob is gone");
    }
}

/// Which cameras' silhouettes of a frame are empty or cover (nearly) the whole image.
#[derive(Debug, Default)]
pub struct Coverage {
    /// Cameras without a single subject pixel.
    pub empty: Vec<String>,
    /// Cameras whose silhouette covers at least [`FULL_SHARE`] of the image.
    pub full: Vec<String>,
    /// Every camera's name and the share of its image its silhouette covers (0..1).
    pub shares: Vec<(String, f64)>,
}

/// A box wider than this on some axis, metres, holds more than one person.
pub const PERSON_BOX_M: f64 = 3.0;

/// A silhouette covering more than this share of its image is more than one person at the
/// distances a capture rig films from.
const LARGE_SHARE: f64 = 0.4;

/// The share of an image a silhouette covers from which it is taken as "everything" (a
/// blank white or inverted mask): it carves nothing.
pub const FULL_SHARE: f64 = 0.995;

impl Coverage {
    /// The coverage of `masks` (binary, one per camera of `cams`).
    pub fn of(cams: &[crate::camera::Camera], masks: &[GrayImage]) -> Coverage {
        let mut out = Coverage::default();
        for (cam, m) in cams.iter().zip(masks) {
            let on = m.as_raw().iter().filter(|&&v| v >= 128).count();
            let all = m.as_raw().len().max(1);
            out.shares.push((cam.name.clone(), on as f64 / all as f64));
            if on == 0 {
                out.empty.push(cam.name.clone());
            } else if on as f64 >= FULL_SHARE * all as f64 {
                out.full.push(cam.name.clone());
            }
        }
        out
    }

    /// The warning for frame `frame` whose carving box spans `size` (metres, per axis)
    /// when it is wider than [`PERSON_BOX_M`]: the box, and the cameras whose silhouettes
    /// cover most of their image (largest first), which cause it.
    pub fn box_problem(&self, frame: u32, size: [f64; 3]) -> Option<String> {
        if size.iter().all(|&s| s <= PERSON_BOX_M) {
            return None;
        }
        let mut large: Vec<&(String, f64)> = self
            .shares
            .iter()
            .filter(|(_, s)| *s > LARGE_SHARE)
            .collect();
        large.sort_by(|a, b| b.1.total_cmp(&a.1));
        let cameras = if large.is_empty() {
            "no camera's silhouette covers much of its image: check the calibration, or set \
             visual_hull.bbox"
                .to_string()
        } else {
            format!(
                "the silhouettes of camera(s) {} cover most of their image (the room marked as \
                 the subject?): check them (`pipeline view`), or set visual_hull.bbox",
                large
                    .iter()
                    .map(|(c, s)| format!("{} ({:.0}%)", crate::text::quoted(c), 100.0 * s))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        Some(format!(
            "frame {frame}: the box the silhouettes leave to carve is {:.1} x {:.1} x {:.1} m, \
             far larger than a person (over {PERSON_BOX_M} m): {cameras}",
            size[0], size[1], size[2]
        ))
    }

    /// The cameras whose silhouette of `frame` covers the whole image: `Ok(None)` when
    /// none does, a warning naming them, or an error when they leave no more than
    /// `all_but` of the `cameras` to carve (the hull would fill the whole box).
    pub fn full_problem(
        &self,
        frame: u32,
        all_but: usize,
        cameras: usize,
    ) -> std::result::Result<Option<String>, String> {
        if self.full.is_empty() {
            return Ok(None);
        }
        let message = format!(
            "masks of frame {frame}: camera(s) {} cover the whole image, so they carve nothing \
             (inverted, or all white? the subject is 255, the background 0)",
            self.full.join(", ")
        );
        if self.full.len() + all_but >= cameras {
            return Err(format!("{message}; the hull would fill the whole box"));
        }
        Ok(Some(message))
    }

    /// Why a hull carved from these silhouettes is empty, in the user's terms.
    pub fn why_empty(&self) -> String {
        if self.empty.is_empty() {
            "every camera's silhouette holds the subject, but their cones do not meet: check the \
             calibration against the masks (a camera's R or t, or two cameras swapped)"
                .into()
        } else {
            format!(
                "the silhouette of camera(s) {} is empty (no subject pixel: masks must be 255 or \
                 1 on the subject, 0 elsewhere); every camera must see the subject, or allow \
                 cameras to disagree with visual_hull.all_but",
                self.empty.join(", ")
            )
        }
    }
}
