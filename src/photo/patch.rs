//! Patches on a surface's tangent plane, as a camera sees them.

use super::GreyImage;
use crate::camera::Camera;
use nalgebra::{Vector2, Vector3};

/// The pixel grid of a patch of points spaced `step` metres on the plane through `x` with
/// normal `n`, as `cam` sees it: the projection of x and the pixel steps of the two tangent
/// axes (the projection is linearized at x). `None` when x is behind the camera.
pub fn patch_grid(
    cam: &Camera,
    x: &Vector3<f64>,
    n: &Vector3<f64>,
    step: f64,
) -> Option<(Vector2<f64>, Vector2<f64>, Vector2<f64>)> {
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = n.cross(&helper).normalize() * step;
    let t2 = n.cross(&t1);
    let (xp, a, b) = (
        cam.project(x)?,
        cam.project(&(x + t1))?,
        cam.project(&(x + t2))?,
    );
    Some((xp, a - xp, b - xp))
}

/// The grey values of a `window` x `window` patch of points spaced `step` metres on the
/// plane through `x` with normal `n`, as camera `cam` sees it; `None` when it leaves the
/// image.
pub fn sample_patch(
    cam: &Camera,
    image: &GreyImage,
    x: &Vector3<f64>,
    n: &Vector3<f64>,
    window: usize,
    step: f64,
) -> Option<Vec<f32>> {
    let (origin, du, dv) = patch_grid(cam, x, n, step)?;
    let mut patch = vec![0.0; window * window];
    image
        .sample_grid(origin, du, dv, window, &mut patch)
        .then_some(patch)
}

/// The mean ZNCC over all pairs of the cameras `seen` of patches of `window` x `window`
/// points spaced `step` metres on the plane through `x` with normal `n` (a patch leaving an
/// image correlates 0). `patches` is scratch space. At least two cameras are expected.
#[allow(clippy::too_many_arguments)]
pub fn mean_pair_zncc(
    cams: &[Camera],
    images: &[GreyImage],
    seen: &[usize],
    x: &Vector3<f64>,
    n: &Vector3<f64>,
    window: usize,
    step: f64,
    patches: &mut Vec<f32>,
) -> f32 {
    let (k, len) = (seen.len(), window * window);
    patches.resize(k * len, 0.0);
    for (slot, &c) in seen.iter().enumerate() {
        let out = &mut patches[slot * len..(slot + 1) * len];
        let ok = patch_grid(&cams[c], x, n, step)
            .is_some_and(|(o, du, dv)| images[c].sample_grid(o, du, dv, window, out));
        if ok {
            super::normalize(out);
        } else {
            out.fill(0.0);
        }
    }
    let mut sum = 0.0f32;
    for a in 0..k {
        let pa = &patches[a * len..(a + 1) * len];
        for b in a + 1..k {
            sum += super::dot(pa, &patches[b * len..(b + 1) * len]);
        }
    }
    sum / (k * (k - 1) / 2).max(1) as f32
}
