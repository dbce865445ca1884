//! A background plate learned from the frames themselves (`silhouette.method: learned`),
//! for captures filmed without plates where the subject moves through the view.
//!
//! Per pixel, the colours it shows over the frames are clustered around their mode: each
//! of up to [`CANDIDATES`] evenly spread frames proposes its colour, the proposal with the
//! most frames within `tolerance` (Euclidean RGB distance, 8-bit levels) wins, and the
//! plate's colour is the mean of those frames. A moving subject shows a pixel different
//! colours from frame to frame, the background always the same one (up to noise, flicker
//! and passing shadows), so the largest cluster is the background wherever the pixel shows
//! it in more frames than any one colour of the subject. Its share of the frames is kept:
//! a pixel whose largest cluster holds fewer than `min_share` of the frames never showed a
//! steady background, and cannot be decided from its own history.
//!
//! What this cannot see: a part of the subject that never moves over the whole range keeps
//! one colour like the background does, and is learned as background (README "No plates").

use image::RgbImage;
use rayon::prelude::*;

/// How many frames propose a colour per pixel (evenly spread over the frames).
pub const CANDIDATES: usize = 16;

/// A learned plate and how sure it is of each pixel.
pub struct LearnedPlate {
    /// The background colour per pixel.
    pub plate: RgbImage,
    /// The share of the frames that showed the plate's colour, per pixel (row-major), 0..1.
    pub share: Vec<f32>,
}

impl LearnedPlate {
    /// The share of the image's pixels whose background was seen in fewer than `min_share`
    /// of the frames (the pixels it cannot decide).
    pub fn never_background(&self, min_share: f64) -> f64 {
        if self.share.is_empty() {
            return 0.0;
        }
        let n = self
            .share
            .iter()
            .filter(|&&s| (s as f64) < min_share)
            .count();
        n as f64 / self.share.len() as f64
    }
}

/// Learns one camera's plate from its frames (all of one size, at least one).
pub fn learn(frames: &[&RgbImage], tolerance: f64) -> LearnedPlate {
    let (w, h) = frames[0].dimensions();
    let n = frames.len();
    let candidates: Vec<usize> = if n <= CANDIDATES {
        (0..n).collect()
    } else {
        (0..CANDIDATES)
            .map(|k| k * (n - 1) / (CANDIDATES - 1))
            .collect()
    };
    let tol2 = (tolerance * tolerance) as f32;
    let rows: Vec<(Vec<u8>, Vec<f32>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut colours = vec![[0f32; 3]; n];
            let mut plate = Vec::with_capacity(3 * w as usize);
            let mut share = Vec::with_capacity(w as usize);
            for x in 0..w {
                for (c, f) in colours.iter_mut().zip(frames) {
                    *c = f.get_pixel(x, y).0.map(|v| v as f32);
                }
                let near = |a: &[f32; 3], b: &[f32; 3]| {
                    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2) <= tol2
                };
                let (best, _) = candidates
                    .iter()
                    .map(|&k| {
                        let count = colours.iter().filter(|c| near(c, &colours[k])).count();
                        (k, count)
                    })
                    // the first of equal counts: the result does not depend on thread order
                    .fold((candidates[0], 0), |a, b| if b.1 > a.1 { b } else { a });
                // The cluster's mean, then once more around that mean (a proposal at the
                // cluster's edge would otherwise bias it).
                let mut centre = colours[best];
                let mut count = 0;
                for _ in 0..2 {
                    let mut sum = [0f32; 3];
                    count = 0;
                    for c in colours.iter().filter(|c| near(c, &centre)) {
                        for k in 0..3 {
                            sum[k] += c[k];
                        }
                        count += 1;
                    }
                    if count == 0 {
                        break;
                    }
                    centre = sum.map(|s| s / count as f32);
                }
                plate.extend(centre.map(|v| v.round().clamp(0.0, 255.0) as u8));
                share.push(count as f32 / n as f32);
            }
            (plate, share)
        })
        .collect();
    let mut plate = Vec::with_capacity(3 * (w * h) as usize);
    let mut share = Vec::with_capacity((w * h) as usize);
    for (p, s) in rows {
        plate.extend(p);
        share.extend(s);
    }
    LearnedPlate {
        plate: RgbImage::from_raw(w, h, plate).expect("w x h x 3 bytes"),
        share,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_moving_over_a_plate_leaves_the_plate_with_its_shares() {
        let bg = RgbImage::from_fn(40, 30, |x, y| {
            image::Rgb([(x * 5) as u8, (y * 7) as u8, 90])
        });
        // A 10 px square crossing the image, a new colour in every frame.
        let frames: Vec<RgbImage> = (0..10)
            .map(|i| {
                let mut f = bg.clone();
                for y in 10..20 {
                    for x in (i * 3)..(i * 3 + 10) {
                        f.put_pixel(x, y, image::Rgb([200, (i * 20) as u8, 10]));
                    }
                }
                f
            })
            .collect();
        let refs: Vec<&RgbImage> = frames.iter().collect();
        let learned = learn(&refs, 12.0);
        assert_eq!(learned.plate, bg);
        // Column 15 of row 15 is covered in frames 2..=5: 6 of 10 frames show the plate.
        assert!((learned.share[15 * 40 + 15] - 0.6).abs() < 1e-6);
        assert_eq!(learned.share[0], 1.0);
        assert_eq!(learned.never_background(0.2), 0.0);
        assert!(learned.never_background(0.7) > 0.0);
    }
}
