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
