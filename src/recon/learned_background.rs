//! A background plate learned from the frames themselves (`silhouette.method: learned`),
//! for captures filmed without plates.
//!
//! 1. **The steady colour.** Per pixel, the colours it shows over the frames are clustered
//!    around their mode: each of up to [`CANDIDATES`] evenly spread frames proposes its
//!    colour, the proposal with the most frames within `learned_tolerance` (Euclidean RGB
//!    distance, 8-bit levels) wins, and the steady colour is the mean of those frames; the
//!    share of the frames it holds is kept. A pixel whose steady colour holds fewer than
//!    `learned_min_share` of the frames never showed one thing long enough to be decided.
//! 2. **Whose colour it is.** The steady image is the room where the subject moves, but the
//!    subject's own colours where a part of it stays in place (a torso, a standing leg).
//!    It is split by a graph cut (GrabCut-like): the subject's colours are those the frames
//!    show where they differ from the steady colour (the parts that moved), the room's are
//!    the steady colours far from every pixel that ever changed; both as histograms of
//!    chromaticity (r, g over r + g + b: shading and shadows keep it), a contrast-sensitive
//!    smoothness between neighbours.
//! 3. **A frame's mask.** Where the steady colour is the room's, a pixel is the subject's
//!    when it differs from it (the brightness/chromaticity test of background subtraction,
//!    with a plate that may hold a shadow: light coming back up to 1 / `min_brightness` is
//!    still the room). Where it is the subject's, the pixel is the subject's unless the frame
//!    shows something else whose chromaticity is more the room's than the subject's (the part
//!    moved away). Undecided pixels count as the subject's.
//!
//! What this cannot see: a part of the subject whose colours are the room's and that never
//! moves over the range.

use super::silhouette::{classify_up_to, SilhouetteParams};
use image::RgbImage;
use rayon::prelude::*;

/// How many frames propose a colour per pixel (evenly spread over the frames).
pub const CANDIDATES: usize = 16;

/// Bins per chromaticity coordinate of the colour models.
pub const CHROMA_BINS: usize = 24;

/// Steady pixels farther than this share of the image width from every pixel that ever
/// changed seed the room's colours and are held to the room (the subject stays within its
/// reach of its moving parts: 0.08 seeded the standing legs of a humanoid whose arms only
/// moved at its chest as room; at 0.25 frames 0..3 of the humanoid still give IoU 0.993).
const ROOM_SEED_DISTANCE: f64 = 0.25;

/// Weight of the graph cut's smoothness against the colour models' log-likelihoods.
const SMOOTHNESS: f64 = 4.0;

/// One camera's learned background.
pub struct Learned {
    /// The steady colour per pixel.
    pub plate: RgbImage,
    /// The share of the frames that showed the steady colour, per pixel (row-major), 0..1.
    pub share: Vec<f32>,
    /// Whether the steady colour is the subject's (a part that stays), per pixel.
    pub steady_subject: Vec<bool>,
    /// Whether a chromaticity bin (`r_bin + CHROMA_BINS * g_bin`) is more the subject's
    /// than the room's.
    pub subject_chroma: Vec<bool>,
}

impl Learned {
    /// The share of the image's pixels whose steady colour holds fewer than `min_share` of
    /// the frames (undecided).
    pub fn undecided(&self, min_share: f64) -> f64 {
        share_of(self.share.iter().map(|&s| (s as f64) < min_share))
    }

    /// The share of the image's pixels where a part of the subject stays (the background
    /// behind it never shows, or too rarely to be the steady colour).
    pub fn never_background(&self) -> f64 {
        share_of(self.steady_subject.iter().copied())
    }

    /// The raw mask of `frame` (step 3 of the module's documentation), before clean-up.
    pub fn subject(&self, frame: &RgbImage, p: &SilhouetteParams) -> Vec<bool> {
        let changed = changed(frame, &self.plate, p);
        changed
            .iter()
            .zip(frame.pixels())
            .enumerate()
            .map(|(i, (&changed, colour))| {
                if (self.share[i] as f64) < p.learned_min_share {
                    true
                } else if self.steady_subject[i] {
                    !changed || self.subject_chroma[chroma_bin(colour.0)]
                } else {
                    changed
                }
            })
            .collect()
    }
}

fn share_of(flags: impl ExactSizeIterator<Item = bool>) -> f64 {
    let n = flags.len();
    if n == 0 {
        return 0.0;
    }
    flags.filter(|&f| f).count() as f64 / n as f64
}

/// Whether each pixel of `frame` differs from the learned `plate`.
fn changed(frame: &RgbImage, plate: &RgbImage, p: &SilhouetteParams) -> Vec<bool> {
    classify_up_to(frame, plate, p, 1.0 / p.min_brightness)
}

/// The chromaticity bin of an 8-bit colour.
fn chroma_bin(c: [u8; 3]) -> usize {
    let sum = c[0] as f64 + c[1] as f64 + c[2] as f64 + 3.0;
    let bin = |v: u8| (((v as f64 + 1.0) / sum * CHROMA_BINS as f64) as usize).min(CHROMA_BINS - 1);
    bin(c[0]) + CHROMA_BINS * bin(c[1])
}

/// Learns one camera's background from its frames (all of one size, at least one); also
/// the share of the image's pixels that changed in some frame (0: nothing moved, and
/// nothing tells the subject from the room).
pub fn learn(frames: &[&RgbImage], p: &SilhouetteParams) -> (Learned, f64) {
    let (plate, share) = steady_colours(frames, p.learned_tolerance);
    let (w, h) = (plate.width() as usize, plate.height() as usize);
    // Step 2: the parts that moved give the subject's colours, the steady pixels far from
    // them the room's.
    let mut subject_hist = vec![0.0f64; CHROMA_BINS * CHROMA_BINS];
    let mut ever_changed = vec![false; w * h];
    for frame in frames {
        for (i, c) in changed(frame, &plate, p).into_iter().enumerate() {
            if c {
                ever_changed[i] = true;
                subject_hist[chroma_bin(frame.as_raw()[3 * i..3 * i + 3].try_into().unwrap())] +=
                    1.0;
            }
        }
    }
    let far = chamfer_distance(&ever_changed, w, h);
    let seed_distance = ROOM_SEED_DISTANCE * w as f64;
    let room_seed: Vec<bool> = far.iter().map(|&d| d > seed_distance).collect();
    let mut room_hist = vec![0.0f64; CHROMA_BINS * CHROMA_BINS];
    for (i, c) in plate.pixels().enumerate() {
        if room_seed[i] {
            room_hist[chroma_bin(c.0)] += 1.0;
        }
    }
    let (subject_log, room_log) = (log_density(&subject_hist), log_density(&room_hist));
    let subject_chroma: Vec<bool> = subject_log
        .iter()
        .zip(&room_log)
        .map(|(s, r)| s > r)
        .collect();
    let steady_subject = if ever_changed.iter().any(|&c| c) {
        split_steady(&plate, &room_seed, &subject_log, &room_log)
    } else {
        vec![false; w * h] // nothing moved: nothing tells the subject's colours
    };
    let changed = share_of(ever_changed.into_iter());
    (
        Learned {
            plate,
            share,
            steady_subject,
            subject_chroma,
        },
        changed,
    )
}

/// Step 1: each pixel's steady colour and the share of frames showing it.
fn steady_colours(frames: &[&RgbImage], tolerance: f64) -> (RgbImage, Vec<f32>) {
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
                    .map(|&k| (k, colours.iter().filter(|c| near(c, &colours[k])).count()))
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
    (
        RgbImage::from_raw(w, h, plate).expect("w x h x 3 bytes"),
        share,
    )
}

/// A histogram's log density, with half a count added to every bin and smoothed over the
/// 3x3 neighbouring bins (a sample's chromaticity is known to about a bin).
fn log_density(hist: &[f64]) -> Vec<f64> {
    let n = CHROMA_BINS as isize;
    let mut out = vec![0.0; hist.len()];
    for g in 0..n {
        for r in 0..n {
            let (mut sum, mut weight) = (0.0, 0.0);
            for dg in -1..=1 {
                for dr in -1..=1 {
                    let (rr, gg) = (r + dr, g + dg);
                    if (0..n).contains(&rr) && (0..n).contains(&gg) {
                        let w = if dr == 0 && dg == 0 {
                            4.0
                        } else if dr == 0 || dg == 0 {
                            2.0
                        } else {
                            1.0
                        };
                        sum += w * hist[(rr + n * gg) as usize];
                        weight += w;
                    }
                }
            }
            out[(r + n * g) as usize] = sum / weight + 0.5;
        }
    }
    let total: f64 = out.iter().sum();
    out.iter().map(|v| (v / total).ln()).collect()
}

/// Distance of every pixel to the nearest `set` pixel, pixels (a 3-4 chamfer over 3, within
/// 8% of the Euclidean); infinite when `set` is empty.
fn chamfer_distance(set: &[bool], w: usize, h: usize) -> Vec<f64> {
    const INF: u32 = u32::MAX / 2;
    let mut d: Vec<u32> = set.iter().map(|&s| if s { 0 } else { INF }).collect();
    let at = |x: usize, y: usize| x + w * y;
    for y in 0..h {
        for x in 0..w {
            let mut v = d[at(x, y)];
            if x > 0 {
                v = v.min(d[at(x - 1, y)] + 3);
            }
            if y > 0 {
                v = v.min(d[at(x, y - 1)] + 3);
                if x > 0 {
                    v = v.min(d[at(x - 1, y - 1)] + 4);
                }
                if x + 1 < w {
                    v = v.min(d[at(x + 1, y - 1)] + 4);
                }
            }
            d[at(x, y)] = v;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let mut v = d[at(x, y)];
            if x + 1 < w {
                v = v.min(d[at(x + 1, y)] + 3);
            }
            if y + 1 < h {
                v = v.min(d[at(x, y + 1)] + 3);
                if x + 1 < w {
                    v = v.min(d[at(x + 1, y + 1)] + 4);
                }
                if x > 0 {
                    v = v.min(d[at(x - 1, y + 1)] + 4);
                }
            }
            d[at(x, y)] = v;
        }
    }
    d.into_iter()
        .map(|v| {
            if v >= INF {
                f64::INFINITY
            } else {
                v as f64 / 3.0
            }
        })
        .collect()
}

/// Step 2's graph cut on the steady image: which pixels hold the subject's colour. The
/// room's seeds are held to the room; elsewhere a pixel pays the negative log-density of its
/// chromaticity under the label it gets, and neighbours of similar colour pay
/// `SMOOTHNESS * exp(-beta |difference|^2)` to differ (beta: one over twice the image's
/// mean squared neighbour difference).
fn split_steady(
    plate: &RgbImage,
    room_seed: &[bool],
    subject_log: &[f64],
    room_log: &[f64],
) -> Vec<bool> {
    let (w, h) = (plate.width() as usize, plate.height() as usize);
    let colour = |x: usize, y: usize| plate.get_pixel(x as u32, y as u32).0.map(|v| v as f64);
    let diff2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>();
    let (mut sum, mut pairs) = (0.0, 0usize);
    for y in 0..h {
        for x in 0..w {
            if x + 1 < w {
                sum += diff2(colour(x, y), colour(x + 1, y));
                pairs += 1;
            }
            if y + 1 < h {
                sum += diff2(colour(x, y), colour(x, y + 1));
                pairs += 1;
            }
        }
    }
    let beta = if sum > 0.0 {
        pairs as f64 / (2.0 * sum)
    } else {
        0.0
    };
    let mut graph = crate::maxflow::GridGraph::new([w, h, 1]);
    // Held to the room: more than every other pixel's costs together could outweigh.
    let held = 1e9;
    for y in 0..h {
        for x in 0..w {
            let i = x + w * y;
            let c = colour(x, y);
            // Source side: the subject. A pixel on the sink side (the room) cuts its source
            // link, so that link carries the cost of the room's label, and the other way.
            let bin = chroma_bin(plate.get_pixel(x as u32, y as u32).0);
            if room_seed[i] {
                graph.add_terminal_weights(i, 0.0, held);
            } else {
                graph.add_terminal_weights(i, -room_log[bin], -subject_log[bin]);
            }
            if x + 1 < w {
                let cap = (SMOOTHNESS * (-beta * diff2(c, colour(x + 1, y))).exp()) as f32;
                graph.set_edge(i, 0, cap, cap);
            }
            if y + 1 < h {
                let cap = (SMOOTHNESS * (-beta * diff2(c, colour(x, y + 1))).exp()) as f32;
                graph.set_edge(i, 1, cap, cap);
            }
        }
    }
    graph.maxflow();
    (0..w * h).map(|i| graph.is_source_side(i)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A room with a static grey-green "torso" and a red "arm" sweeping across it.
    fn scene() -> (RgbImage, Vec<RgbImage>, Vec<Vec<bool>>) {
        let (w, h) = (80u32, 60u32);
        let room = RgbImage::from_fn(w, h, |x, y| {
            image::Rgb([120 + (x % 7) as u8, 110 + (y % 5) as u8, 100])
        });
        let mut frames = Vec::new();
        let mut truth = Vec::new();
        for i in 0..12u32 {
            let mut f = room.clone();
            let mut t = vec![false; (w * h) as usize];
            for y in 26..40 {
                for x in 35..45 {
                    f.put_pixel(x, y, image::Rgb([40 + (x * 3 % 20) as u8, 150, 60]));
                    t[(x + w * y) as usize] = true;
                }
            }
            for y in 30..35 {
                for x in (5 + 5 * i)..(15 + 5 * i) {
                    f.put_pixel(x, y, image::Rgb([200, 30 + (x % 9) as u8, 40]));
                    t[(x + w * y) as usize] = true;
                }
            }
            frames.push(f);
            truth.push(t);
        }
        (room, frames, truth)
    }

    #[test]
    fn a_part_that_stays_is_told_from_the_room_and_the_part_that_moves_is_found() {
        let (room, frames, truth) = scene();
        let refs: Vec<&RgbImage> = frames.iter().collect();
        let p = SilhouetteParams::default();
        let (learned, _) = learn(&refs, &p);
        // The room is learned where it shows; the torso is the subject's.
        let (w, _) = room.dimensions();
        assert_eq!(learned.plate.get_pixel(3, 3), room.get_pixel(3, 3));
        assert!(learned.steady_subject[(40 + w * 35) as usize]);
        assert!(!learned.steady_subject[(20 + w * 45) as usize]);
        assert_eq!(learned.undecided(0.2), 0.0);
        for (f, t) in frames.iter().zip(&truth) {
            let raw = learned.subject(f, &p);
            let wrong = raw.iter().zip(t).filter(|(a, b)| a != b).count();
            assert!(wrong <= 10, "{wrong} pixels wrong");
        }
    }

    #[test]
    fn chamfer_distances_are_within_eight_percent() {
        let (w, h) = (50, 40);
        let mut set = vec![false; w * h];
        set[10 + w * 10] = true;
        let d = chamfer_distance(&set, w, h);
        for (x, y) in [(40usize, 30usize), (10, 35), (45, 10), (10, 10)] {
            let e = ((x as f64 - 10.0).powi(2) + (y as f64 - 10.0).powi(2)).sqrt();
            assert!(
                (d[x + w * y] - e).abs() <= 0.08 * e + 1e-9,
                "{x},{y}: {} vs {e}",
                d[x + w * y]
            );
        }
    }
}
