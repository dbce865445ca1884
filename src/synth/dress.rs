//! A loose dress (`pipeline synth --dress loose`): the skirt's hem swings after the body as
//! a damped pendulum would, so that its shape is not a function of the pose and linear
//! blend skinning cannot produce it.
//!
//! The skirt is first skinned like the flesh. Its hem ring's centre H(t) (world metres)
//! then drives a damped oscillator, d'' = ω² (H − d) − 2 ζ ω d' (ω = √(g / ℓ), ℓ the skirt's
//! length, ζ = [`DAMPING`]), started at rest at the first frame; each skirt vertex moves
//! horizontally by depth² · (d − H), depth 0 at the waist and 1 at the hem, scaled by
//! [`SWING`] and capped at [`MAX_LAG`]. The hem lags when the legs or hips move and swings
//! on after they stop.

use crate::geometry::TriMesh;
use nalgebra::Vector3;

/// Damping ratio of the swing (light: it swings on for a few periods).
pub const DAMPING: f64 = 0.25;
/// Gain of the lag (a loose skirt swings farther than a rigid pendulum of its length).
pub const SWING: f64 = 2.0;
/// The largest horizontal lag of the hem, metres.
pub const MAX_LAG: f64 = 0.12;
/// Integration steps per frame.
const SUBSTEPS: usize = 50;

/// Moves the skirt vertices of `posed` (one mesh per frame, `rate` frames per second) by
/// the swing; `depth` is each vertex's [`super::body::Body::skirt_depth`], `length` the
/// skirt's length in metres.
pub fn swing(posed: &mut [TriMesh], depth: &[f64], length: f64, rate: f64) {
    let hem: Vec<usize> = (0..depth.len()).filter(|&i| depth[i] > 0.9).collect();
    if hem.is_empty() || posed.is_empty() {
        return;
    }
    let centre = |m: &TriMesh| -> Vector3<f64> {
        hem.iter().map(|&i| m.vertices[i]).sum::<Vector3<f64>>() / hem.len() as f64
    };
    let driver: Vec<Vector3<f64>> = posed.iter().map(centre).collect();
    let omega = (9.81 / length.max(0.05)).sqrt();
    let dt = 1.0 / rate / SUBSTEPS as f64;
    let (mut d, mut v) = (driver[0], Vector3::zeros());
    for f in 0..posed.len() {
        if f > 0 {
            for k in 0..SUBSTEPS {
                let u = (k + 1) as f64 / SUBSTEPS as f64;
                let h = driver[f - 1] * (1.0 - u) + driver[f] * u;
                let a = omega * omega * (h - d) - 2.0 * DAMPING * omega * v;
                v += a * dt;
                d += v * dt;
            }
        }
        let mut lag = (d - driver[f]) * SWING;
        lag.z = 0.0;
        let lag = lag.cap_magnitude(MAX_LAG);
        for (x, &s) in posed[f].vertices.iter_mut().zip(depth) {
            if s > 0.0 {
                *x += s * s * lag;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hem driven one way then held still: it lags while driven and swings on after the
    /// driver stops, so the same position of the body gives different skirts.
    #[test]
    fn the_hem_lags_and_swings_on() {
        let hem_ring = |x: f64| TriMesh {
            vertices: vec![Vector3::new(x, 0.0, 0.5), Vector3::new(x, 0.0, 1.0)],
            triangles: vec![],
        };
        let mut frames: Vec<TriMesh> = (0..20)
            .map(|f| hem_ring(0.05 * (f.min(8) as f64)))
            .collect();
        let rest = frames.clone();
        swing(&mut frames, &[1.0, 0.0], 0.5, 25.0);
        // The waist vertex never moves.
        assert!(frames
            .iter()
            .zip(&rest)
            .all(|(a, b)| a.vertices[1] == b.vertices[1]));
        let lag = |f: usize| frames[f].vertices[0].x - rest[f].vertices[0].x;
        assert!(lag(5) < -0.01, "lags while driven: {}", lag(5));
        // Frames 8.. have the same body: the skirt differs between them.
        let after: Vec<f64> = (8..20).map(lag).collect();
        let spread = after.iter().cloned().fold(f64::MIN, f64::max)
            - after.iter().cloned().fold(f64::MAX, f64::min);
        assert!(spread > 0.01, "swings on: {after:?}");
        assert!(after.iter().all(|l| l.abs() <= MAX_LAG + 1e-12));
    }
}
