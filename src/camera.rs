//! Calibrated cameras: the OpenCV pinhole model with distortion `[k1, k2, p1, p2, k3]` and
//! optional skew, as `shared/dataset-format.md` states it, and `calib/cameras.yaml` I/O.
//!
//! Convention: a world point `X` (metres) maps to camera coordinates `x_c = R·X + t`; the
//! normalized coordinates `(x, y) = (x_c/z_c, y_c/z_c)` are distorted to `(x', y')` and the
//! pixel is `(u, v) = (fx·x' + s·y' + cx, fy·y' + cy)`. Pixel centres lie on integer
//! coordinates (the top-left pixel's centre is (0, 0)); the camera looks along +z, image x
//! goes right and y goes down.

use crate::error::Refusal;
use crate::error::{Error, Result};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use serde::Deserialize;
use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::Path;

/// Tolerance on `R·Rᵀ = I` and `det R = 1` when a calibration is loaded.
pub const ROTATION_TOLERANCE: f64 = 1e-6;
/// Deviation up to which an R that misses [`ROTATION_TOLERANCE`] is taken as a rotation
/// printed with too few digits (published calibrations often carry 10 significant digits,
/// about 1e-6 off): it is replaced by the nearest rotation, with a warning.
pub const ROUNDED_ROTATION_TOLERANCE: f64 = 1e-4;

/// The largest camera translation accepted, metres.
pub const MAX_TRANSLATION: f64 = 1e4;

/// One calibrated camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Camera name; also the name of its image folders.
    pub name: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Skew `K[0][1]`, pixels (0 for most cameras).
    pub skew: f64,
    /// OpenCV distortion `[k1, k2, p1, p2, k3]`.
    pub dist: [f64; 5],
    /// World-to-camera rotation.
    pub r: Matrix3<f64>,
    /// World-to-camera translation, metres.
    pub t: Vector3<f64>,
}

impl Camera {
    /// An ideal camera (no distortion, no skew) at `centre` looking at `target`, with `up`
    /// giving the world direction that appears upwards in the image.
    #[allow(clippy::too_many_arguments)]
    pub fn look_at(
        name: &str,
        width: u32,
        height: u32,
        focal_px: f64,
        centre: Vector3<f64>,
        target: Vector3<f64>,
        up: Vector3<f64>,
    ) -> Camera {
        let z = (target - centre).normalize();
        // Image y goes down, so the camera's y axis is the negated up direction.
        let x = z.cross(&up).normalize();
        let y = z.cross(&x);
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        Camera {
            name: name.to_string(),
            width,
            height,
            fx: focal_px,
            fy: focal_px,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
            skew: 0.0,
            dist: [0.0; 5],
            r,
            t: -(r * centre),
        }
    }

    /// The 3x3 intrinsic matrix K.
    pub fn k_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.fx, self.skew, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0,
        )
    }

    /// Camera centre in world coordinates, metres: `-Rᵀ t`.
    pub fn centre(&self) -> Vector3<f64> {
        -(self.r.transpose() * self.t)
    }

    /// World point to camera coordinates (metres, +z forward).
    pub fn to_camera(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.r * x + self.t
    }

    /// Whether any distortion coefficient is non-zero.
    pub fn has_distortion(&self) -> bool {
        self.dist.iter().any(|&d| d != 0.0)
    }

    /// Applies the OpenCV distortion to normalized coordinates.
    pub fn distort(&self, n: Vector2<f64>) -> Vector2<f64> {
        let [k1, k2, p1, p2, k3] = self.dist;
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        Vector2::new(
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Jacobian of [`Camera::distort`] with respect to the normalized coordinates.
    fn distort_jacobian(&self, n: Vector2<f64>) -> Matrix2<f64> {
        let [k1, k2, p1, p2, k3] = self.dist;
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        // d(radial)/d(r2)
        let dradial = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3);
        let dxdx = radial + x * dradial * 2.0 * x + 2.0 * p1 * y + 6.0 * p2 * x;
        let dxdy = x * dradial * 2.0 * y + 2.0 * p1 * x + 2.0 * p2 * y;
        let dydx = y * dradial * 2.0 * x + 2.0 * p1 * x + 2.0 * p2 * y;
        let dydy = radial + y * dradial * 2.0 * y + 6.0 * p1 * y + 2.0 * p2 * x;
        Matrix2::new(dxdx, dxdy, dydx, dydy)
    }

    /// An upper bound (with 1% slack) of how much the lens distortion magnifies small
    /// lengths anywhere in the image: the largest singular value of the distortion's Jacobian
    /// over a grid of image points; 1 without distortion.
    pub fn distortion_gain(&self) -> f64 {
        if !self.has_distortion() {
            return 1.0;
        }
        let mut gain: f64 = 1.0;
        for j in 0..=12 {
            for i in 0..=16 {
                let px = Vector2::new(
                    i as f64 / 16.0 * (self.width as f64 - 1.0),
                    j as f64 / 12.0 * (self.height as f64 - 1.0),
                );
                let jac = self.distort_jacobian(self.pixel_to_normalized(px));
                gain = gain.max(jac.singular_values().max());
            }
        }
        gain * 1.01
    }

    /// Removes the distortion from distorted normalized coordinates (inverse of
    /// [`Camera::distort`]) by Newton's method; exact to ~1e-15 for realistic lenses.
    pub fn undistort(&self, d: Vector2<f64>) -> Vector2<f64> {
        if !self.has_distortion() {
            return d;
        }
        let mut n = d;
        for _ in 0..50 {
            let residual = self.distort(n) - d;
            if residual.norm() < 1e-15 {
                break;
            }
            let step = match self.distort_jacobian(n).try_inverse() {
                Some(inv) => inv * residual,
                None => break,
            };
            n -= step;
        }
        n
    }

    /// The same camera with its image scaled by `factor` (0.5: half the width and height):
    /// pixel centres stay at integer coordinates, so a pixel x maps to (x + 0.5) factor - 0.5.
    pub fn scaled(&self, factor: f64) -> Camera {
        Camera {
            width: ((self.width as f64 * factor).ceil() as u32).max(1),
            height: ((self.height as f64 * factor).ceil() as u32).max(1),
            fx: self.fx * factor,
            fy: self.fy * factor,
            skew: self.skew * factor,
            cx: (self.cx + 0.5) * factor - 0.5,
            cy: (self.cy + 0.5) * factor - 0.5,
            ..self.clone()
        }
    }

    /// Normalized (undistorted) coordinates to a pixel.
    pub fn normalized_to_pixel(&self, n: Vector2<f64>) -> Vector2<f64> {
        let d = self.distort(n);
        Vector2::new(
            self.fx * d.x + self.skew * d.y + self.cx,
            self.fy * d.y + self.cy,
        )
    }

    /// A pixel to normalized (undistorted) coordinates.
    pub fn pixel_to_normalized(&self, px: Vector2<f64>) -> Vector2<f64> {
        let yd = (px.y - self.cy) / self.fy;
        let xd = (px.x - self.cx - self.skew * yd) / self.fx;
        self.undistort(Vector2::new(xd, yd))
    }

    /// Projects a world point; returns the pixel and the depth `z_c` (metres). The pixel is
    /// meaningless when the depth is not positive.
    pub fn project_with_depth(&self, x: &Vector3<f64>) -> (Vector2<f64>, f64) {
        let c = self.to_camera(x);
        let n = Vector2::new(c.x / c.z, c.y / c.z);
        (self.normalized_to_pixel(n), c.z)
    }

    /// Projects a world point in front of the camera; `None` behind it.
    pub fn project(&self, x: &Vector3<f64>) -> Option<Vector2<f64>> {
        let (px, z) = self.project_with_depth(x);
        (z > 0.0).then_some(px)
    }

    /// The world point seen at pixel `px` at depth `depth` (metres along the optical axis).
    pub fn backproject(&self, px: Vector2<f64>, depth: f64) -> Vector3<f64> {
        let n = self.pixel_to_normalized(px);
        let c = Vector3::new(n.x * depth, n.y * depth, depth);
        self.r.transpose() * (c - self.t)
    }

    /// The viewing ray through pixel `px`: (camera centre, unit direction), world frame.
    pub fn ray(&self, px: Vector2<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let n = self.pixel_to_normalized(px);
        let dir = self.r.transpose() * Vector3::new(n.x, n.y, 1.0);
        (self.centre(), dir.normalize())
    }

    /// Whether pixel `px` lies inside the image (pixel centres at integers, so the image
    /// spans [-0.5, width-0.5) x [-0.5, height-0.5)).
    pub fn in_image(&self, px: &Vector2<f64>) -> bool {
        px.x >= -0.5
            && px.y >= -0.5
            && px.x < self.width as f64 - 0.5
            && px.y < self.height as f64 - 0.5
    }

    /// The farthest image corner from the principal point, as a distorted normalized radius.
    fn corner_radius(&self) -> f64 {
        let (w, h) = (self.width as f64, self.height as f64);
        [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
            .iter()
            .map(|&(x, y)| {
                let ny = (y - self.cy) / self.fy;
                Vector2::new((x - self.cx - self.skew * ny) / self.fx, ny).norm()
            })
            .fold(0.0, f64::max)
    }

    /// Where the radial distortion r (1 + k1 r^2 + k2 r^4 + k3 r^6) stops increasing before
    /// it reaches the image's corners (a lens model that folds the image onto itself), as
    /// the distorted normalized radius; `None` when it is one-to-one over the image.
    fn fold_radius(&self) -> Option<f64> {
        let [k1, k2, _, _, k3] = self.dist;
        if k1 >= 0.0 && k2 >= 0.0 && k3 >= 0.0 {
            return None;
        }
        let corner = self.corner_radius();
        let radial = |r: f64| r * (1.0 + r * r * (k1 + r * r * (k2 + r * r * k3)));
        let slope = |r: f64| {
            let r2 = r * r;
            1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + 7.0 * r2 * k3))
        };
        // Walk the undistorted radius out until the image's corner is reached.
        let steps = 2000;
        let step = 4.0 * corner / steps as f64;
        for i in 1..=steps {
            let r = i as f64 * step;
            if slope(r) <= 0.0 {
                return Some(radial(r));
            }
            if radial(r) >= corner {
                return None;
            }
        }
        // The corners are never reached: the distortion shrinks the image by 4x or more.
        Some(radial(4.0 * corner))
    }

    /// The share of the image (0..1) where the whole lens model (radial and tangential)
    /// folds: sampled undistorted directions, out to where the radial part reaches the
    /// image's corners, whose pixel lies in the image and where the Jacobian of
    /// [`Camera::distort`] has a non-positive determinant (two directions meet there).
    /// 0 for a one-to-one model.
    fn folded_share(&self) -> f64 {
        if !self.has_distortion() {
            return 0.0;
        }
        let [k1, k2, _, _, k3] = self.dist;
        let corner = self.corner_radius();
        // The undistorted radius where the radial part first reaches the corners (the
        // radial fold is refused on its own, [`Camera::fold_radius`]).
        let radial = |r: f64| r * (1.0 + r * r * (k1 + r * r * (k2 + r * r * k3)));
        let steps = 2000;
        let reach = (1..=steps)
            .map(|i| i as f64 * 4.0 * corner / steps as f64)
            .find(|&r| radial(r) >= corner)
            .unwrap_or(4.0 * corner);
        let n = 96;
        let (mut inside, mut folded) = (0usize, 0usize);
        for j in 0..=n {
            for i in 0..=n {
                let u = Vector2::new(
                    (2.0 * i as f64 / n as f64 - 1.0) * reach,
                    (2.0 * j as f64 / n as f64 - 1.0) * reach,
                );
                if u.norm() > reach {
                    continue;
                }
                let d = self.distort(u);
                let px = Vector2::new(
                    self.fx * d.x + self.skew * d.y + self.cx,
                    self.fy * d.y + self.cy,
                );
                if !self.in_image(&px) {
                    continue;
                }
                inside += 1;
                if self.distort_jacobian(u).determinant() <= 0.0 {
                    folded += 1;
                }
            }
        }
        if inside == 0 {
            return 1.0;
        }
        folded as f64 / inside as f64
    }

    /// Checks the values a calibration must satisfy; the message names what is wrong.
    pub fn validate(&self) -> std::result::Result<(), Refusal> {
        if self.width == 0 || self.height == 0 {
            return Err(
                format!("image size {}x{} must be positive", self.width, self.height).into(),
            );
        }
        let numbers = [self.fx, self.fy, self.cx, self.cy, self.skew]
            .into_iter()
            .chain(self.dist)
            .chain(self.r.iter().copied())
            .chain(self.t.iter().copied());
        if numbers.into_iter().any(|v| !v.is_finite()) {
            return Err("K, dist, R and t must hold finite numbers".into());
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(format!(
                "focal lengths must be positive (fx = {}, fy = {})",
                self.fx, self.fy
            )
            .into());
        }
        // Plausible ranges: absurd numbers pass every other test and make a camera that
        // silently sees nothing.
        let side = self.width.max(self.height) as f64;
        for (what, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(f >= 0.001 * side && f <= 1000.0 * side) {
                return Err(format!(
                    "{what} = {f} pixels is outside 0.001 to 1000 times the image's longer side \
                     ({side} pixels); focal lengths are in pixels"
                )
                .into());
            }
        }
        if self.skew.abs() > self.fx.max(self.fy) {
            return Err(format!(
                "the skew K[0][1] = {} is larger than the focal length; it is 0 for most cameras",
                self.skew
            )
            .into());
        }
        let (w, h) = (self.width as f64, self.height as f64);
        if !(-w..=2.0 * w).contains(&self.cx) || !(-h..=2.0 * h).contains(&self.cy) {
            return Err(format!(
                "the principal point ({}, {}) lies far outside the {}x{} image (it is near the \
                 image centre for most cameras)",
                self.cx, self.cy, self.width, self.height
            )
            .into());
        }
        if self.t.norm() > MAX_TRANSLATION {
            return Err(format!(
                "|t| = {:.0} is over {MAX_TRANSLATION} m: t is in metres (millimetres would be \
                 1000 times too large)",
                self.t.norm()
            )
            .into());
        }
        if self.dist.iter().any(|d| d.abs() > 1e3) {
            return Err(format!(
                "dist {:?} holds a coefficient over 1000 in size; expected [k1, k2, p1, p2, k3]",
                self.dist
            )
            .into());
        }
        if let Some(r) = self.fold_radius() {
            return Err(format!(
                "dist {:?} folds the image: the radial distortion stops growing {:.0} pixels from \
                 the principal point, inside the image, so two directions would meet at one \
                 pixel; check the coefficients and their order [k1, k2, p1, p2, k3]",
                self.dist,
                r * self.fx.min(self.fy)
            )
            .into());
        }
        let folded = self.folded_share();
        if folded > 0.0 {
            return Err(format!(
                "dist {:?} folds the image: over {:.0}% of it the lens model (radial and \
                 tangential terms together) turns back on itself, so two directions would meet \
                 at one pixel; check the coefficients and their order [k1, k2, p1, p2, k3] \
                 (tangential terms p1, p2 are small, typically under 0.01)",
                self.dist,
                (100.0 * folded).max(1.0)
            )
            .into());
        }
        let ortho = (self.r * self.r.transpose() - Matrix3::identity())
            .abs()
            .max();
        let det = self.r.determinant();
        if ortho > ROTATION_TOLERANCE || (det - 1.0).abs() > ROTATION_TOLERANCE {
            return Err(format!(
                "R is not a rotation: |R·Rᵀ - I| = {ortho:.3e} and det R = {det:.9} \
                 (need R orthonormal with det +1 within {ROTATION_TOLERANCE:e}); \
                 check that R is the world-to-camera rotation matrix, row by row"
            )
            .into());
        }
        Ok(())
    }
}

/// How far `r` is from a rotation: the larger of max |R·Rᵀ - I| and |det R - 1|.
pub fn rotation_deviation(r: &Matrix3<f64>) -> f64 {
    let ortho = (r * r.transpose() - Matrix3::identity()).abs().max();
    ortho.max((r.determinant() - 1.0).abs())
}

/// The rotation nearest to `r` (Frobenius norm), from its SVD.
pub fn nearest_rotation(r: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = r.svd(true, true);
    let (u, v_t) = (svd.u.expect("u"), svd.v_t.expect("v_t"));
    let mut fix = Matrix3::identity();
    fix[(2, 2)] = (u * v_t).determinant().signum();
    u * fix * v_t
}

/// A calibration as read from cameras.yaml.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub cameras: Vec<Camera>,
    /// Repairs made on load (rotations printed with too few digits).
    pub warnings: Vec<String>,
}

/// The longest camera or bone name, bytes.
pub const MAX_NAME_BYTES: usize = 100;

/// Characters that render as nothing or reorder text: Unicode's default-ignorable code
/// points (bidirectional overrides and isolates, zero-width characters, the byte-order
/// mark, soft hyphen, variation selectors, the combining grapheme joiner, Hangul and
/// Khmer fillers, tags) and the interlinear annotation marks.
fn invisible(c: char) -> bool {
    matches!(c,
        '\u{00AD}' | '\u{034F}' | '\u{061C}' | '\u{115F}'..='\u{1160}' | '\u{17B4}'..='\u{17B5}'
        | '\u{180B}'..='\u{180F}' | '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}'
        | '\u{2060}'..='\u{206F}' | '\u{3164}' | '\u{FE00}'..='\u{FE0F}' | '\u{FEFF}'
        | '\u{FFA0}' | '\u{FFF0}'..='\u{FFFB}' | '\u{1BCA0}'..='\u{1BCA3}'
        | '\u{1D173}'..='\u{1D17A}' | '\u{E0000}'..='\u{E0FFF}')
}

/// Characters that draw nothing though they are not invisible by class: white space and
/// blank letters such as the braille blank U+2800.
fn blank(c: char) -> bool {
    c.is_whitespace() || matches!(c, '\u{2800}' | '\u{3000}')
}

/// The form in which two names are compared: NFC (so that "café" composed and decomposed
/// are one name, as they are one folder on macOS), lower case (one folder on a
/// case-insensitive filesystem).
pub fn comparable_name(name: &str) -> String {
    use unicode_normalization::UnicodeNormalization;
    name.nfc().collect::<String>().to_lowercase()
}

/// Camera names become folder names: refuse anything that is not a plain file name.
pub fn check_name(name: &str) -> std::result::Result<(), Refusal> {
    if name.is_empty() {
        return Err("the name is empty".into());
    }
    // Shown escaped: a name may hold terminal escape sequences.
    let shown = name.escape_debug();
    if name == "." || name == ".." || name.contains(['/', '\\']) {
        return Err(format!(
            "the name '{shown}' is used as a folder name and must not contain '/', '\\' or be '.' or '..'"
        ).into());
    }
    if name.chars().any(|c| c.is_control()) {
        return Err(format!("the name {name:?} contains control characters").into());
    }
    // Invisible or reordering characters make two names look alike, or a name look like
    // another (U+202E shows the rest of a line backwards).
    if let Some(c) = name.chars().find(|&c| invisible(c)) {
        return Err(format!(
            "the name {:?} contains the invisible character U+{:04X}; use letters, digits, '_' \
             and '-'",
            name, c as u32
        )
        .into());
    }
    if name.chars().all(blank) {
        return Err(format!(
            "the name {:?} has no visible character; use letters, digits, '_' and '-'",
            name
        )
        .into());
    }
    if name.trim() != name || name.trim().is_empty() {
        return Err(
            format!("the name {name:?} is blank or starts or ends with white space").into(),
        );
    }
    // Names become file names (`<name>.png`, `<name>.tmp-...`): well under the usual
    // 255-byte limit.
    if name.len() > MAX_NAME_BYTES {
        return Err(format!(
            "the name '{}...' is {} bytes long; names become file names, keep them to {MAX_NAME_BYTES} bytes",
            shown.to_string().chars().take(20).collect::<String>(),
            name.len()
        ).into());
    }
    Ok(())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CamerasFile {
    cameras: Vec<CameraEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(non_snake_case)]
struct CameraEntry {
    name: String,
    width: u32,
    height: u32,
    K: [[f64; 3]; 3],
    #[serde(default)]
    dist: Option<Vec<f64>>,
    R: [[f64; 3]; 3],
    t: [f64; 3],
    #[serde(default)]
    crop: Option<CropEntry>,
}

/// The images are a window of the calibrated image (a crop, or a pad where `left`/`top`
/// are negative): image pixel (0, 0) is calibrated pixel (`left`, `top`), pixels.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CropEntry {
    left: i32,
    top: i32,
    width: u32,
    height: u32,
}

/// Parses cameras.yaml text (`path` only names the file in errors) and validates it.
pub fn parse_cameras(path: &Path, text: &str) -> Result<Calibration> {
    let file: CamerasFile = crate::yaml::from_str(path, text)?;
    if file.cameras.is_empty() {
        return Err(Error::invalid(path, "the calibration lists no camera"));
    }
    let mut seen = HashSet::new();
    let mut poses = std::collections::HashMap::new();
    let mut warnings = Vec::new();
    let mut cameras = Vec::with_capacity(file.cameras.len());
    for e in file.cameras {
        let bad = |msg: String| {
            Error::invalid(path, format!("camera '{}': {msg}", e.name.escape_debug()))
        };
        check_name(&e.name).map_err(|m| bad(m.0))?;
        // Names become folder names: on a case-insensitive filesystem "Cam0" and "cam0"
        // would be one folder.
        if !seen.insert(comparable_name(&e.name)) {
            return Err(bad(
                "the name is used twice (or differs from another only by case or by Unicode \
                 composition, as 'café' written two ways); camera names must be unique, also \
                 on case-insensitive and normalizing filesystems"
                    .into(),
            ));
        }
        let k = e.K;
        if k[1][0] != 0.0 || k[2][0] != 0.0 || k[2][1] != 0.0 || k[2][2] != 1.0 {
            return Err(bad(format!(
                "K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {k:?}"
            )));
        }
        let dist = match e.dist.as_deref() {
            None => [0.0; 5],
            Some(d) if d.len() <= 5 => {
                let mut full = [0.0; 5];
                full[..d.len()].copy_from_slice(d);
                full
            }
            Some(d) => {
                return Err(bad(format!(
                    "dist has {} values; expected [k1, k2, p1, p2, k3]",
                    d.len()
                )))
            }
        };
        let mut cam = Camera {
            name: e.name.clone(),
            width: e.width,
            height: e.height,
            fx: k[0][0],
            fy: k[1][1],
            cx: k[0][2],
            cy: k[1][2],
            skew: k[0][1],
            dist,
            r: Matrix3::from_fn(|i, j| e.R[i][j]),
            t: Vector3::new(e.t[0], e.t[1], e.t[2]),
        };
        let deviation = rotation_deviation(&cam.r);
        if deviation > ROTATION_TOLERANCE && deviation <= ROUNDED_ROTATION_TOLERANCE {
            cam.r = nearest_rotation(&cam.r);
            warnings.push(format!(
                "{}: camera '{}': R is {deviation:.1e} from a rotation (too few printed digits?); \
                 using the nearest rotation",
                path.display(),
                e.name
            ));
        }
        if let Some(c) = &e.crop {
            // The camera of the images: the principal point moves with the window.
            let far = |start: i32, len: u32, of: u32| start as i64 + len as i64 > of as i64 + 64;
            if c.left.abs() > 64
                || c.top.abs() > 64
                || far(c.left, c.width, e.width)
                || far(c.top, c.height, e.height)
            {
                return Err(bad(format!(
                    "crop {}x{} at ({}, {}) reaches more than 64 pixels outside the calibrated \
                     {}x{} image: a crop or pad describes images that differ from the \
                     calibrated ones by a few pixels; for another resolution, calibrate at it",
                    c.width, c.height, c.left, c.top, e.width, e.height
                )));
            }
            cam.cx -= c.left as f64;
            cam.cy -= c.top as f64;
            cam.width = c.width;
            cam.height = c.height;
        }
        cam.validate().map_err(|m| bad(m.0))?;
        // A copied entry adds nothing and may hide a missing camera; a warning, not an
        // error: real rings hold such pairs (the Middlebury temple ring's 1st and 11th).
        let pose: Vec<u64> = cam
            .r
            .iter()
            .chain(cam.t.iter())
            .map(|v| v.to_bits())
            .collect();
        if let Some(twin) = poses.insert(pose, cameras.len()) {
            let twin: &Camera = &cameras[twin];
            warnings.push(format!(
                "{}: camera '{}' has the same position and orientation as camera '{}' (a copied \
                 entry?): it adds no view; if both are meant, check their R and t",
                path.display(),
                e.name.escape_debug(),
                twin.name.escape_debug()
            ));
        }
        cameras.push(cam);
    }
    Ok(Calibration { cameras, warnings })
}

/// When images differ from their calibration by a few pixels (a sensor window of 1088
/// against a video of 1080, say), how to say where they were cut or padded.
pub fn crop_hint(cam: &Camera, (w, h): (u32, u32)) -> String {
    let near = |a: u32, b: u32| a.abs_diff(b) <= 64;
    if !near(w, cam.width) || !near(h, cam.height) {
        return String::new();
    }
    let centred = |of: u32, is: u32| (of as i64 - is as i64) / 2;
    format!(
        ". If the images are the calibrated ones cut (or padded) by a few pixels, say where \
         in calib/cameras.yaml: `crop: {{left: L, top: T, width: {w}, height: {h}}}` on each \
         such camera, with (L, T) the calibrated pixel that is the images' top-left (centred: \
         left {}, top {}; at the origin: 0, 0), as docs/dataset-format.md describes",
        centred(cam.width, w),
        centred(cam.height, h)
    )
}

/// Reads and validates `calib/cameras.yaml`.
pub fn read_cameras(path: &Path) -> Result<Calibration> {
    let text = crate::fsutil::read_to_string(path)?;
    parse_cameras(path, &text)
}

/// The cameras.yaml text for `cameras` (flow-style rows as in the dataset contract; numbers
/// printed in Rust's shortest round-trip form, so reading it back gives identical values).
pub fn cameras_to_yaml(cameras: &[Camera]) -> String {
    let row = |v: [f64; 3]| format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2]);
    let mut s = String::from("cameras:\n");
    for c in cameras {
        let r = |i: usize| row([c.r[(i, 0)], c.r[(i, 1)], c.r[(i, 2)]]);
        let _ = writeln!(s, "  - name: {}", crate::yaml::scalar(&c.name));
        let _ = writeln!(s, "    width: {}", c.width);
        let _ = writeln!(s, "    height: {}", c.height);
        let _ = writeln!(
            s,
            "    K: [{}, {}, [0.0, 0.0, 1.0]]",
            row([c.fx, c.skew, c.cx]),
            row([0.0, c.fy, c.cy])
        );
        let d = c.dist;
        let _ = writeln!(
            s,
            "    dist: [{:?}, {:?}, {:?}, {:?}, {:?}]",
            d[0], d[1], d[2], d[3], d[4]
        );
        let _ = writeln!(s, "    R: [{}, {}, {}]", r(0), r(1), r(2));
        let _ = writeln!(s, "    t: {}", row([c.t.x, c.t.y, c.t.z]));
    }
    s
}

/// Writes cameras.yaml atomically.
pub fn write_cameras(path: &Path, cameras: &[Camera]) -> Result<()> {
    crate::fsutil::write_atomic(path, cameras_to_yaml(cameras).as_bytes())
}

/// The point the cameras look at: the least-squares nearest point to their optical axes
/// (lines through each centre along its viewing direction); `None` when the axes are
/// (nearly) parallel, as for a stereo pair.
pub fn common_target(cams: &[Camera]) -> Option<Vector3<f64>> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for c in cams {
        let d = c.r.row(2).transpose();
        let p = Matrix3::identity() - d * d.transpose();
        a += p;
        b += p * c.centre();
    }
    let eig = a.symmetric_eigen();
    if eig.eigenvalues.min() < 0.05 * cams.len() as f64 {
        return None;
    }
    a.try_inverse().map(|inv| inv * b)
}

/// Refuses a camera that does not look at the point the cameras look at together
/// ([`common_target`]): it faces away from it, or it projects more than an image's size
/// outside its image (a camera turned around, or with R and t of another convention). The
/// message names the camera.
pub fn check_cameras_look_at_the_scene(cams: &[Camera]) -> std::result::Result<(), Refusal> {
    if cams.len() < 3 {
        return Ok(());
    }
    let Some(target) = common_target(cams) else {
        return Ok(());
    };
    for c in cams {
        let x = c.to_camera(&target);
        let shown = format!("({:.2}, {:.2}, {:.2})", target.x, target.y, target.z);
        if x.z <= 0.0 {
            return Err(format!(
                "camera '{}' faces away from the point the cameras look at, {shown}: it sees \
                 none of the subject; check its R and t (world-to-camera), or remove it",
                c.name
            )
            .into());
        }
        // Without the lens distortion: the point may lie far outside the image.
        let (w, h) = (c.width as f64, c.height as f64);
        let px = c.k_matrix() * (x / x.z);
        let (u, v) = (px.x, px.y);
        if !(-w..=2.0 * w).contains(&u) || !(-h..=2.0 * h).contains(&v) {
            return Err(format!(
                "camera '{}' does not see the point the cameras look at, {shown} (it would be at \
                 pixel ({u:.0}, {v:.0}) of a {}x{} image); check its K, R and t, or remove it",
                c.name, c.width, c.height
            )
            .into());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_camera() -> Camera {
        let mut c = Camera::look_at(
            "c",
            640,
            480,
            800.0,
            Vector3::new(3.0, 1.0, 1.5),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::z(),
        );
        c.dist = [-0.12, 0.05, 0.001, -0.0015, -0.01];
        c.skew = 0.7;
        c
    }

    #[test]
    fn undistort_inverts_distort() {
        let c = test_camera();
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.4, 0.35), (0.1, 0.45)] {
            let n = Vector2::new(x, y);
            let back = c.undistort(c.distort(n));
            assert!((back - n).norm() < 1e-13, "{n:?} -> {back:?}");
        }
    }

    #[test]
    fn backproject_inverts_project() {
        let c = test_camera();
        let p = Vector3::new(0.2, -0.3, 1.1);
        let (px, depth) = c.project_with_depth(&p);
        let q = c.backproject(px, depth);
        assert!((p - q).norm() < 1e-12);
        let (o, d) = c.ray(px);
        let along = (p - o).normalize();
        assert!((along - d).norm() < 1e-12);
    }

    #[test]
    fn look_at_puts_target_at_principal_point() {
        let c = Camera::look_at(
            "c",
            101,
            81,
            500.0,
            Vector3::new(0.0, -4.0, 2.0),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::z(),
        );
        let px = c.project(&Vector3::new(0.0, 0.0, 1.0)).unwrap();
        assert!((px - Vector2::new(50.0, 40.0)).norm() < 1e-9);
        // A point above the target appears above (smaller v).
        let up = c.project(&Vector3::new(0.0, 0.0, 1.2)).unwrap();
        assert!(up.y < px.y);
        assert!(c.validate().is_ok());
    }

    fn yaml_with_r(r: [[f64; 3]; 3]) -> String {
        format!(
            "cameras:\n  - name: a\n    width: 4\n    height: 3\n    K: [[2.0, 0.0, 1.5], [0.0, 2.0, 1.0], [0.0, 0.0, 1.0]]\n    R: {r:?}\n    t: [0.0, 0.0, 1.0]\n"
        )
    }

    #[test]
    fn rotations_printed_with_few_digits_are_repaired_and_wrong_ones_refused() {
        let c = 0.6;
        let s = 0.8000021; // 2.1e-6 off
        let calib = parse_cameras(
            Path::new("c.yaml"),
            &yaml_with_r([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]),
        )
        .unwrap();
        assert_eq!(calib.warnings.len(), 1);
        assert!(rotation_deviation(&calib.cameras[0].r) < 1e-12);
        let err = parse_cameras(
            Path::new("c.yaml"),
            &yaml_with_r([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("c.yaml") && err.contains("camera 'a'") && err.contains("not a rotation"),
            "{err}"
        );
    }

    #[test]
    fn a_crop_moves_the_principal_point_and_a_far_one_is_refused() {
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let base = yaml_with_r(identity);
        let cropped = format!("{base}    crop: {{left: 1, top: -1, width: 3, height: 4}}\n");
        let calib = parse_cameras(Path::new("c.yaml"), &cropped).unwrap();
        let cam = &calib.cameras[0];
        assert_eq!((cam.width, cam.height), (3, 4));
        assert_eq!((cam.cx, cam.cy), (0.5, 2.0));
        // The same world point lands one pixel left and one down of where the calibrated
        // image has it.
        let whole = &parse_cameras(Path::new("c.yaml"), &base).unwrap().cameras[0];
        let p = Vector3::new(0.1, 0.2, 1.0);
        let d = cam.project(&p).unwrap() - whole.project(&p).unwrap();
        assert!((d.x + 1.0).abs() < 1e-12 && (d.y - 1.0).abs() < 1e-12);
        let far = format!("{base}    crop: {{left: 100, top: 0, width: 3, height: 3}}\n");
        let err = parse_cameras(Path::new("c.yaml"), &far)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("camera 'a'") && err.contains("more than 64 pixels"),
            "{err}"
        );
    }
}
