//! BlazePose's tensors in and out (MediaPipe's pose detector and pose landmark model): the
//! detector's anchors and decoding, the rotated square crop it gives the landmark model, and
//! the landmarks and mask mapped back to image pixels. Pure functions; running the models is
//! [`super::model`]'s.
//!
//! Conventions are MediaPipe's `pose_detection` and `pose_landmark` graphs (0.10.14): a
//! 224x224 letterboxed input in [-1, 1] for the detector, a 256x256 crop in [0, 1] for the
//! landmarks, both sampled bilinearly.

use image::RgbImage;

/// The detector's input side, pixels.
pub const DETECTOR_SIDE: usize = 224;
/// The landmark model's input side, pixels.
pub const LANDMARK_SIDE: usize = 256;
/// Number of detector anchors (the model's output rows).
pub const ANCHORS: usize = 2254;
/// Values per anchor: box (x, y, w, h) and 4 keypoints (x, y).
pub const DETECTION_VALUES: usize = 12;
/// Body landmarks the model names (it outputs 39; the last 6 are auxiliary).
pub const LANDMARKS: usize = 33;
/// Values per landmark in the model's output: x, y, z, visibility, presence.
pub const LANDMARK_VALUES: usize = 5;
/// Landmarks in the model's output, body and auxiliary.
pub const LANDMARK_ROWS: usize = 39;

/// Below this score a detector anchor is no person (MediaPipe's 0.5).
pub const MIN_DETECTION_SCORE: f32 = 0.5;

/// MediaPipe's names of the 33 body landmarks, in the model's order.
pub const LANDMARK_NAMES: [&str; LANDMARKS] = [
    "nose",
    "left_eye_inner",
    "left_eye",
    "left_eye_outer",
    "right_eye_inner",
    "right_eye",
    "right_eye_outer",
    "left_ear",
    "right_ear",
    "mouth_left",
    "mouth_right",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_pinky",
    "right_pinky",
    "left_index",
    "right_index",
    "left_thumb",
    "right_thumb",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_heel",
    "right_heel",
    "left_foot_index",
    "right_foot_index",
];

/// An affine map from a model input's pixel grid (u, v) to image pixels (x, y):
/// `x = a[0] u + a[1] v + a[2]`, `y = a[3] u + a[4] v + a[5]`, pixel centres at +0.5.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Affine(pub [f64; 6]);

impl Affine {
    pub fn apply(&self, u: f64, v: f64) -> (f64, f64) {
        let a = &self.0;
        (a[0] * u + a[1] * v + a[2], a[3] * u + a[4] * v + a[5])
    }

    /// The inverse map (image pixels to the input's grid).
    pub fn inverse(&self) -> Affine {
        let a = &self.0;
        let det = a[0] * a[4] - a[1] * a[3];
        let (i0, i1, i3, i4) = (a[4] / det, -a[1] / det, -a[3] / det, a[0] / det);
        Affine([
            i0,
            i1,
            -(i0 * a[2] + i1 * a[5]),
            i3,
            i4,
            -(i3 * a[2] + i4 * a[5]),
        ])
    }
}

/// The detector's letterbox: the whole image scaled into the square, centred, padded.
pub fn letterbox(width: u32, height: u32) -> Affine {
    let side = DETECTOR_SIDE as f64;
    let scale = width.max(height) as f64 / side; // image pixels per input pixel
    let pad_x = (side - width as f64 / scale) / 2.0;
    let pad_y = (side - height as f64 / scale) / 2.0;
    Affine([scale, 0.0, -pad_x * scale, 0.0, scale, -pad_y * scale])
}

/// A rotated square in the image: the landmark model's crop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crop {
    /// Centre, image pixels.
    pub center: (f64, f64),
    /// Side, image pixels.
    pub side: f64,
    /// Rotation, radians: the crop's x axis points along (cos, sin) in the image.
    pub rotation: f64,
}

impl Crop {
    /// The map from the landmark input's pixel grid to image pixels.
    pub fn affine(&self) -> Affine {
        let s = self.side / LANDMARK_SIDE as f64;
        let (sin, cos) = self.rotation.sin_cos();
        // x = c + R (s (u - n/2)), with the grid's centre at n/2.
        let h = LANDMARK_SIDE as f64 / 2.0;
        Affine([
            cos * s,
            -sin * s,
            self.center.0 - (cos * s * h - sin * s * h),
            sin * s,
            cos * s,
            self.center.1 - (sin * s * h + cos * s * h),
        ])
    }
}

/// Samples `img` through `map` into an `n` x `n` x 3 tensor (row-major, RGB), values
/// `lo + (hi - lo) * level / 255`, bilinear, black outside the image.
pub fn sample(img: &RgbImage, map: &Affine, n: usize, lo: f32, hi: f32) -> Vec<f32> {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let raw = img.as_raw();
    let px = |x: i64, y: i64, ch: usize| -> f32 {
        if x < 0 || y < 0 || x >= w || y >= h {
            0.0
        } else {
            raw[((y * w + x) * 3) as usize + ch] as f32
        }
    };
    let k = (hi - lo) / 255.0;
    let mut out = vec![0f32; n * n * 3];
    for v in 0..n {
        for u in 0..n {
            let (x, y) = map.apply(u as f64 + 0.5, v as f64 + 0.5);
            let (fx, fy) = (x - 0.5, y - 0.5);
            let (x0, y0) = (fx.floor() as i64, fy.floor() as i64);
            let (tx, ty) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
            for ch in 0..3 {
                let top = px(x0, y0, ch) * (1.0 - tx) + px(x0 + 1, y0, ch) * tx;
                let bottom = px(x0, y0 + 1, ch) * (1.0 - tx) + px(x0 + 1, y0 + 1, ch) * tx;
                out[(v * n + u) * 3 + ch] = lo + k * (top * (1.0 - ty) + bottom * ty);
            }
        }
    }
    out
}

/// The detector's anchors' centres in its normalized input square (MediaPipe's SSD anchors
/// for pose detection: strides 8, 16, 32, 32, 32, two anchors per layer and cell, the
/// layers of one stride merged, fixed size 1).
pub fn anchors() -> Vec<(f32, f32)> {
    let strides = [8usize, 16, 32, 32, 32];
    let mut out = Vec::with_capacity(ANCHORS);
    let mut layer = 0;
    while layer < strides.len() {
        let mut last = layer;
        let mut per_cell = 0;
        while last < strides.len() && strides[last] == strides[layer] {
            per_cell += 2;
            last += 1;
        }
        let cells = DETECTOR_SIDE.div_ceil(strides[layer]);
        for y in 0..cells {
            for x in 0..cells {
                for _ in 0..per_cell {
                    out.push((
                        (x as f32 + 0.5) / cells as f32,
                        (y as f32 + 0.5) / cells as f32,
                    ));
                }
            }
        }
        layer = last;
    }
    out
}

/// One detected person, in image pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// Probability that the box holds a person, 0..1.
    pub score: f32,
    /// Box: min x, min y, max x, max y.
    pub bbox: [f64; 4],
    /// Keypoints: hip centre, a point above the head (the body's scale), and two more.
    pub keypoints: [(f64, f64); 4],
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x.clamp(-100.0, 100.0)).exp())
}

fn iou(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = w * h;
    let union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// The strongest person among the detector's outputs (`boxes`: [`ANCHORS`] x
/// [`DETECTION_VALUES`], `scores`: [`ANCHORS`] logits), blended with the boxes overlapping
/// it (MediaPipe's weighted suppression, overlap 0.3), mapped to image pixels through
/// `letterbox`. `None` when no anchor scores [`MIN_DETECTION_SCORE`].
pub fn strongest_person(boxes: &[f32], scores: &[f32], letterbox: &Affine) -> Option<Detection> {
    let side = DETECTOR_SIDE as f32;
    let anchors = anchors();
    let mut found: Vec<Detection> = Vec::new();
    for (i, &(ax, ay)) in anchors.iter().enumerate() {
        let score = sigmoid(scores[i]);
        if score < MIN_DETECTION_SCORE {
            continue;
        }
        let r = &boxes[i * DETECTION_VALUES..(i + 1) * DETECTION_VALUES];
        // Input pixels.
        let point = |dx: f32, dy: f32| {
            letterbox.apply(
                ((dx / side + ax) * side) as f64,
                ((dy / side + ay) * side) as f64,
            )
        };
        let (cx, cy) = point(r[0], r[1]);
        let (hw, hh) = (
            (r[2] as f64) * letterbox.0[0] / 2.0,
            (r[3] as f64) * letterbox.0[4] / 2.0,
        );
        found.push(Detection {
            score,
            bbox: [cx - hw, cy - hh, cx + hw, cy + hh],
            keypoints: std::array::from_fn(|k| point(r[4 + 2 * k], r[5 + 2 * k])),
        });
    }
    let best = found
        .iter()
        .max_by(|a, b| a.score.total_cmp(&b.score))?
        .clone();
    let mut total = 0.0;
    let mut bbox = [0.0; 4];
    let mut keypoints = [(0.0, 0.0); 4];
    for d in found.iter().filter(|d| iou(&d.bbox, &best.bbox) > 0.3) {
        let w = d.score as f64;
        total += w;
        for (b, v) in bbox.iter_mut().zip(d.bbox) {
            *b += w * v;
        }
        for (k, v) in keypoints.iter_mut().zip(d.keypoints) {
            k.0 += w * v.0;
            k.1 += w * v.1;
        }
    }
    Some(Detection {
        score: best.score,
        bbox: bbox.map(|b| b / total),
        keypoints: keypoints.map(|(x, y)| (x / total, y / total)),
    })
}

/// The landmark model's crop around a detection: centred on the hip centre, rotated so the
/// point above the head is straight up, twice the hip-to-head distance, enlarged 1.25x
/// (MediaPipe's `pose_detection_to_roi`).
pub fn crop_of(d: &Detection) -> Crop {
    let (x0, y0) = d.keypoints[0];
    let (x1, y1) = d.keypoints[1];
    let size = 2.0 * ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
    let mut rotation = std::f64::consts::FRAC_PI_2 - (-(y1 - y0)).atan2(x1 - x0);
    // Into [-pi, pi).
    rotation -= 2.0
        * std::f64::consts::PI
        * ((rotation + std::f64::consts::PI) / (2.0 * std::f64::consts::PI)).floor();
    Crop {
        center: (x0, y0),
        side: size * 1.25,
        rotation,
    }
}

/// One body landmark in an image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Landmark {
    /// Image pixels (x right, y down, pixel centres at +0.5).
    pub x: f64,
    pub y: f64,
    /// Probability that the landmark is visible (not hidden by the body or out of view), 0..1.
    pub visibility: f32,
    /// Probability that the landmark is in the image, 0..1.
    pub presence: f32,
}

/// The 33 body landmarks from the landmark model's first output (39 x 5 values, crop pixels
/// and logits), mapped through the crop.
pub fn landmarks(raw: &[f32], crop: &Crop) -> [Landmark; LANDMARKS] {
    let map = crop.affine();
    std::array::from_fn(|i| {
        let r = &raw[i * LANDMARK_VALUES..(i + 1) * LANDMARK_VALUES];
        let (x, y) = map.apply(r[0] as f64, r[1] as f64);
        Landmark {
            x,
            y,
            visibility: sigmoid(r[3]),
            presence: sigmoid(r[4]),
        }
    })
}

/// The person mask at image resolution from the landmark model's mask logits
/// ([`LANDMARK_SIDE`]² values over the crop): 255 where the bilinearly sampled logit is
/// positive (probability over one half), 0 elsewhere and outside the crop.
pub fn mask(logits: &[f32], crop: &Crop, width: u32, height: u32) -> image::GrayImage {
    let n = LANDMARK_SIDE as i64;
    let to_crop = crop.affine().inverse();
    let at = |u: i64, v: i64| -> f32 {
        if u < 0 || v < 0 || u >= n || v >= n {
            -100.0
        } else {
            logits[(v * n + u) as usize]
        }
    };
    // Only the crop's bounding box can hold the person.
    let map = crop.affine();
    let corners = [
        (0.0, 0.0),
        (n as f64, 0.0),
        (0.0, n as f64),
        (n as f64, n as f64),
    ]
    .map(|(u, v)| map.apply(u, v));
    let lo_x = corners
        .iter()
        .map(|c| c.0)
        .fold(f64::MAX, f64::min)
        .floor()
        .max(0.0) as u32;
    let hi_x = corners
        .iter()
        .map(|c| c.0)
        .fold(f64::MIN, f64::max)
        .ceil()
        .min(width as f64) as u32;
    let lo_y = corners
        .iter()
        .map(|c| c.1)
        .fold(f64::MAX, f64::min)
        .floor()
        .max(0.0) as u32;
    let hi_y = corners
        .iter()
        .map(|c| c.1)
        .fold(f64::MIN, f64::max)
        .ceil()
        .min(height as f64) as u32;
    let mut out = image::GrayImage::new(width, height);
    for y in lo_y..hi_y {
        for x in lo_x..hi_x {
            let (u, v) = to_crop.apply(x as f64 + 0.5, y as f64 + 0.5);
            let (fu, fv) = (u - 0.5, v - 0.5);
            let (u0, v0) = (fu.floor() as i64, fv.floor() as i64);
            let (tu, tv) = ((fu - u0 as f64) as f32, (fv - v0 as f64) as f32);
            let top = at(u0, v0) * (1.0 - tu) + at(u0 + 1, v0) * tu;
            let bottom = at(u0, v0 + 1) * (1.0 - tu) + at(u0 + 1, v0 + 1) * tu;
            if top * (1.0 - tv) + bottom * tv > 0.0 {
                out.put_pixel(x, y, image::Luma([255]));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_anchors_are_the_models_rows() {
        let a = anchors();
        assert_eq!(a.len(), ANCHORS);
        // First cell of the stride-8 grid (28 cells), twice; last of the stride-32 grid.
        assert_eq!(a[0], (0.5 / 28.0, 0.5 / 28.0));
        assert_eq!(a[1], a[0]);
        assert_eq!(a[ANCHORS - 1], (6.5 / 7.0, 6.5 / 7.0));
    }

    #[test]
    fn an_affine_and_its_inverse_cancel() {
        let crop = Crop {
            center: (300.0, 500.0),
            side: 420.0,
            rotation: 0.7,
        };
        let a = crop.affine();
        let (x, y) = a.apply(10.0, 200.0);
        let (u, v) = a.inverse().apply(x, y);
        assert!((u - 10.0).abs() < 1e-9 && (v - 200.0).abs() < 1e-9);
        // The grid's centre is the crop's centre; its up is the image's up when unrotated.
        let (cx, cy) = a.apply(128.0, 128.0);
        assert!((cx - 300.0).abs() < 1e-9 && (cy - 500.0).abs() < 1e-9);
    }

    #[test]
    fn an_upright_person_gets_an_unrotated_crop() {
        let d = Detection {
            score: 0.9,
            bbox: [0.0; 4],
            keypoints: [(100.0, 400.0), (100.0, 200.0), (0.0, 0.0), (0.0, 0.0)],
        };
        let c = crop_of(&d);
        assert!(c.rotation.abs() < 1e-12);
        assert!((c.side - 500.0).abs() < 1e-9);
        // Head to the right: the crop's up is the image's +x.
        let d = Detection {
            keypoints: [(100.0, 400.0), (300.0, 400.0), (0.0, 0.0), (0.0, 0.0)],
            ..d
        };
        let a = crop_of(&d).affine();
        let (x0, y0) = a.apply(128.0, 128.0);
        let (x1, y1) = a.apply(128.0, 0.0);
        assert!(x1 > x0 + 100.0 && (y1 - y0).abs() < 1e-9);
    }

    #[test]
    fn the_letterbox_fills_the_long_side() {
        let a = letterbox(1080, 1920);
        let (x, y) = a.apply(0.0, 0.0);
        assert!((y - 0.0).abs() < 1e-9 && x < 0.0);
        let (x, y) = a.apply(224.0, 224.0);
        assert!((y - 1920.0).abs() < 1e-9 && x > 1080.0);
    }
}
