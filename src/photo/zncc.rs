//! Zero-mean normalized cross-correlation of sampled patches.

use rayon::prelude::*;

/// Zero-mean normalized cross-correlation of two equally long samples (0 for flat ones).
pub fn zncc(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (
        a.iter().map(|&v| v as f64).sum::<f64>() / n,
        b.iter().map(|&v| v as f64).sum::<f64>() / n,
    );
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (dx, dy) = (x as f64 - ma, y as f64 - mb);
        ab += dx * dy;
        aa += dx * dx;
        bb += dy * dy;
    }
    if aa < 1e-6 || bb < 1e-6 {
        return 0.0;
    }
    ab / (aa * bb).sqrt()
}

/// Zero mean and unit norm in place; all zeros for a flat patch (it correlates 0 with
/// anything).
pub fn normalize(patch: &mut [f32]) {
    let mean = sum(patch) / patch.len() as f32;
    patch.iter_mut().for_each(|v| *v -= mean);
    let norm = dot(patch, patch).sqrt();
    let scale = if norm < 1e-3 { 0.0 } else { 1.0 / norm };
    patch.iter_mut().for_each(|v| *v *= scale);
}

/// Sum of a slice in eight independent lanes (so that it vectorizes).
fn sum(a: &[f32]) -> f32 {
    let mut lanes = [0.0f32; 8];
    let chunks = a.chunks_exact(8);
    let rest: f32 = chunks.remainder().iter().sum();
    for c in chunks {
        for k in 0..8 {
            lanes[k] += c[k];
        }
    }
    lanes.iter().sum::<f32>() + rest
}

/// Dot product of two equally long slices in eight independent lanes.
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut lanes = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let rest: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            lanes[k] += x[k] * y[k];
        }
    }
    lanes.iter().sum::<f32>() + rest
}

/// The mean ZNCC of raw patch pairs laid out as `[a0, b0, a1, b1, ...]`, `len` values per
/// patch (the benchmark's kernel: normalize both, one dot product), over all cores.
pub fn zncc_of_pairs(data: &[f32], len: usize) -> f64 {
    let sum: f64 = data
        .par_chunks(2 * len)
        .map_init(
            || vec![0.0f32; 2 * len],
            |buf, pair| {
                buf.copy_from_slice(pair);
                let (a, b) = buf.split_at_mut(len);
                normalize(a);
                normalize(b);
                dot(a, b) as f64
            },
        )
        .sum();
    sum / (data.len() / (2 * len)).max(1) as f64
}
