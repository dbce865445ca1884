//! Procedural textures defined on 3D coordinates (rest-pose coordinates for the subject, so
//! the pattern moves with the surface; world coordinates for the room).

use crate::rng::mix64;
use nalgebra::Vector3;

/// Smooth 3D value noise in [0, 1] with unit lattice spacing; `salt` picks the pattern.
pub fn value_noise(p: Vector3<f64>, salt: u64) -> f64 {
    let base = p.map(f64::floor);
    let f = p - base;
    // Quintic fade for C2-continuous interpolation.
    let fade = f.map(|t| t * t * t * (t * (t * 6.0 - 15.0) + 10.0));
    let lattice = |dx: i64, dy: i64, dz: i64| -> f64 {
        let (x, y, z) = (base.x as i64 + dx, base.y as i64 + dy, base.z as i64 + dz);
        let h = mix64(
            (x as u64).wrapping_mul(0x8DA6_B343)
                ^ (y as u64).wrapping_mul(0xD816_3841)
                ^ (z as u64).wrapping_mul(0xCB1A_B31F)
                ^ salt.wrapping_mul(0x9E37_79B9),
        );
        (h >> 11) as f64 / (1u64 << 53) as f64
    };
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(lattice(0, 0, 0), lattice(1, 0, 0), fade.x);
    let x10 = lerp(lattice(0, 1, 0), lattice(1, 1, 0), fade.x);
    let x01 = lerp(lattice(0, 0, 1), lattice(1, 0, 1), fade.x);
    let x11 = lerp(lattice(0, 1, 1), lattice(1, 1, 1), fade.x);
    lerp(lerp(x00, x10, fade.y), lerp(x01, x11, fade.y), fade.z)
}

/// Multi-scale noise: the mean of octaves at the given feature sizes (metres).
fn octaves(p: Vector3<f64>, sizes: &[f64], salt: u64) -> f64 {
    let sum: f64 = sizes
        .iter()
        .enumerate()
        .map(|(k, &s)| value_noise(p / s, salt.wrapping_add(k as u64 * 7919)))
        .sum();
    sum / sizes.len() as f64
}

/// Pushes a value in [0, 1] towards 0 and 1 (contrast), keeping it in [0, 1].
fn contrast(v: f64, gain: f64) -> f64 {
    0.5 + 0.5 * (gain * (v - 0.5)).tanh() / (gain * 0.5).tanh()
}

/// The subject's albedo (linear RGB in [0, 1]) at rest-pose point `p` (metres): a
/// high-contrast pattern of saturated colours with features at 1.5, 4 and 10 cm, so that
/// patch correlation finds a clear peak at every scale the pipeline uses. Hue, value and
/// saturation come from three independent noise fields; saturation stays high, as a
/// capture subject's costume differs in colour from a studio's grey and wooden backdrop.
pub fn subject_albedo(p: Vector3<f64>, salt: u64) -> Vector3<f64> {
    let sizes = [0.015, 0.04, 0.10];
    let hue = (octaves(p, &sizes, salt) - 0.5) * 3.0 + 0.5; // spread over ~1.5 turns
    let value = 0.25 + 0.7 * contrast(octaves(p, &sizes, salt + 101), 6.0);
    let sat = 0.7 + 0.3 * contrast(octaves(p, &sizes, salt + 202), 4.0);
    hsv_to_rgb(hue.rem_euclid(1.0), sat, value)
}

/// HSV (all in [0, 1]) to RGB.
fn hsv_to_rgb(h: f64, s: f64, v: f64) -> Vector3<f64> {
    let h6 = h * 6.0;
    let f = |n: f64| {
        let k = (n + h6) % 6.0;
        v - v * s * (k.min(4.0 - k).clamp(0.0, 1.0))
    };
    Vector3::new(f(5.0), f(3.0), f(1.0))
}

/// A nearly uniform cloth colour (dark blue trousers) with faint low-frequency variation.
pub fn plain_albedo(p: Vector3<f64>, salt: u64) -> Vector3<f64> {
    let v = 0.97 + 0.03 * octaves(p, &[0.2], salt + 303);
    Vector3::new(0.10, 0.13, 0.30) * v
}

/// What a point of the subject wears under `pipeline synth --look person`: a person's look
/// (skin, hair, a shirt, trousers, shoes), so that a person model recognizes the figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Material {
    /// Neck, forearms and hands: skin with faint mottling.
    Skin,
    /// The head: a face (eyes, brows, mouth) in front, hair over the top and back
    /// ([`head_albedo`]).
    Head,
    /// Chest, belly and upper arms: a red shirt with a woven pattern (photo-consistency
    /// still finds a peak on it).
    Shirt,
    /// Hips and legs: the plain trousers ([`plain_albedo`]).
    Trousers,
    /// Feet: white shoes.
    Shoe,
}

/// The albedo (RGB in [0, 1]) of material `m` at rest-pose point `p`, metres.
pub fn material_albedo(m: Material, p: Vector3<f64>, salt: u64) -> Vector3<f64> {
    let mottle = |amount: f64, sizes: &[f64], s: u64| 1.0 - amount + amount * octaves(p, sizes, s);
    match m {
        Material::Skin => skin(p, salt),
        Material::Head => skin(p, salt),
        Material::Shirt => {
            let weave = contrast(octaves(p, &[0.015, 0.04, 0.10], salt + 707), 4.0);
            Vector3::new(0.78, 0.20, 0.18) * (0.55 + 0.45 * weave)
        }
        Material::Trousers => plain_albedo(p, salt),
        Material::Shoe => Vector3::new(0.88, 0.88, 0.85) * mottle(0.1, &[0.03], salt + 808),
    }
}

fn skin(p: Vector3<f64>, salt: u64) -> Vector3<f64> {
    Vector3::new(0.87, 0.66, 0.54) * (0.85 + 0.15 * octaves(p, &[0.015, 0.04], salt + 505))
}

fn hair(p: Vector3<f64>, salt: u64) -> Vector3<f64> {
    Vector3::new(0.20, 0.13, 0.08) * (0.7 + 0.3 * octaves(p, &[0.01, 0.03], salt + 606))
}

/// The head's albedo at rest point `p`, `d` being `p` from the head's centre in head radii
/// (the figure faces -y, z up): hair above the brow and over the back, and a face in front
/// with dark eyes on white, brows and a mouth, as a face detector expects.
pub fn head_albedo(p: Vector3<f64>, d: Vector3<f64>, salt: u64) -> Vector3<f64> {
    if d.z > 0.45 || (d.y > 0.1 && d.z > -0.7) {
        return hair(p, salt);
    }
    if d.y < -0.5 {
        let (x, z) = (d.x.abs(), d.z);
        let eye = ((x - 0.33).powi(2) + ((z - 0.1) / 0.7).powi(2)).sqrt();
        if eye < 0.07 {
            return Vector3::new(0.12, 0.08, 0.06);
        }
        if eye < 0.14 {
            return Vector3::new(0.92, 0.92, 0.9);
        }
        if (0.15..0.5).contains(&x) && (0.27..0.34).contains(&z) {
            return hair(p, salt);
        }
        if x < 0.22 && (-0.47..-0.39).contains(&z) {
            return Vector3::new(0.62, 0.28, 0.28);
        }
    }
    skin(p, salt)
}

/// The room's albedo at world point `p` on a surface facing `normal`: a wooden-looking floor
/// with tiles, and plastered walls with mild mottling. Deliberately less saturated than the
/// subject, as a studio would be.
pub fn room_albedo(p: Vector3<f64>, normal: Vector3<f64>, salt: u64) -> Vector3<f64> {
    let n = octaves(p, &[0.03, 0.12, 0.5], salt + 404);
    if normal.z.abs() > 0.5 {
        // Floor: 0.5 m tiles in two tones, with grain.
        let tile = ((p.x / 0.5).floor() + (p.y / 0.5).floor()) as i64 & 1;
        let base = if tile == 0 {
            Vector3::new(0.55, 0.45, 0.33)
        } else {
            Vector3::new(0.42, 0.34, 0.25)
        };
        base * (0.75 + 0.5 * n)
    } else {
        let stripe = 0.9 + 0.1 * ((p.z * 6.0).sin() * 0.5 + 0.5);
        Vector3::new(0.62, 0.62, 0.58) * stripe * (0.8 + 0.4 * n)
    }
}
