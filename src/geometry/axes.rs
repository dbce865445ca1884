//! World axes and Euler rotation orders of the exports: glTF and (most readers of) BVH
//! take +Y as up, while the dataset contract leaves the up axis to the capture. When
//! pipeline.yaml names it (`export.up_axis`), exports turn the world by the proper rotation
//! that takes it to +Y.

use crate::error::Refusal;
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// The world's up direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum UpAxis {
    PlusX,
    MinusX,
    PlusY,
    MinusY,
    PlusZ,
    MinusZ,
}

impl TryFrom<String> for UpAxis {
    type Error = Refusal;
    fn try_from(s: String) -> Result<Self, Refusal> {
        Ok(match s.trim() {
            "+x" | "x" | "+X" | "X" => UpAxis::PlusX,
            "-x" | "-X" => UpAxis::MinusX,
            "+y" | "y" | "+Y" | "Y" => UpAxis::PlusY,
            "-y" | "-Y" => UpAxis::MinusY,
            "+z" | "z" | "+Z" | "Z" => UpAxis::PlusZ,
            "-z" | "-Z" => UpAxis::MinusZ,
            other => {
                return Err(
                    format!("'{other}' is not an axis; use +x, -x, +y, -y, +z or -z").into(),
                )
            }
        })
    }
}

impl From<UpAxis> for String {
    fn from(a: UpAxis) -> String {
        match a {
            UpAxis::PlusX => "+x",
            UpAxis::MinusX => "-x",
            UpAxis::PlusY => "+y",
            UpAxis::MinusY => "-y",
            UpAxis::PlusZ => "+z",
            UpAxis::MinusZ => "-z",
        }
        .into()
    }
}

/// The rotation C from world axes to export axes (+Y up, right-handed): a world point x is
/// written as C x. The identity when the up axis is unknown or already +Y.
pub fn to_y_up(up: Option<UpAxis>) -> Rotation3<f64> {
    // Rows of C: each maps the world's axes so that `up` lands on +Y with det C = +1.
    let rows: [[f64; 3]; 3] = match up {
        None | Some(UpAxis::PlusY) => return Rotation3::identity(),
        Some(UpAxis::MinusY) => [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        Some(UpAxis::PlusZ) => [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]],
        Some(UpAxis::MinusZ) => [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
        Some(UpAxis::PlusX) => [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        Some(UpAxis::MinusX) => [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
    };
    Rotation3::from_matrix_unchecked(Matrix3::from_fn(|i, j| rows[i][j]))
}

/// The world's up direction as a vector.
pub fn up_vector(up: UpAxis) -> Vector3<f64> {
    match up {
        UpAxis::PlusX => Vector3::x(),
        UpAxis::MinusX => -Vector3::x(),
        UpAxis::PlusY => Vector3::y(),
        UpAxis::MinusY => -Vector3::y(),
        UpAxis::PlusZ => Vector3::z(),
        UpAxis::MinusZ => -Vector3::z(),
    }
}

/// An Euler rotation order: the axes (0 = X, 1 = Y, 2 = Z) of the first, second and third
/// rotation, R = R_first R_second R_third.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RotationOrder(pub [usize; 3]);

impl RotationOrder {
    /// Parses `XYZ`, `ZXY`, ... (any permutation of X, Y, Z).
    pub fn parse(s: &str) -> Result<RotationOrder, Refusal> {
        let axes: Vec<usize> = s
            .trim()
            .chars()
            .map(|c| match c.to_ascii_uppercase() {
                'X' => Some(0),
                'Y' => Some(1),
                'Z' => Some(2),
                _ => None,
            })
            .collect::<Option<_>>()
            .ok_or_else(|| format!("'{s}' is not a rotation order such as ZXY"))?;
        if axes.len() != 3 || axes[0] == axes[1] || axes[1] == axes[2] || axes[0] == axes[2] {
            return Err(format!("'{s}' must name each of X, Y and Z once (e.g. ZXY, XYZ)").into());
        }
        Ok(RotationOrder([axes[0], axes[1], axes[2]]))
    }

    /// The BVH channel names, e.g. `Zrotation Xrotation Yrotation`.
    pub fn channels(&self) -> String {
        self.0
            .iter()
            .map(|&a| format!("{}rotation", ["X", "Y", "Z"][a]))
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// Whether the order is a cyclic permutation of XYZ.
    fn cyclic(&self) -> bool {
        matches!(self.0, [0, 1, 2] | [1, 2, 0] | [2, 0, 1])
    }

    /// The rotation of Euler angles (radians) in this order.
    pub fn compose(&self, angles: [f64; 3]) -> Rotation3<f64> {
        let axis = |a: usize| Vector3::ith_axis(a);
        Rotation3::from_axis_angle(&axis(self.0[0]), angles[0])
            * Rotation3::from_axis_angle(&axis(self.0[1]), angles[1])
            * Rotation3::from_axis_angle(&axis(self.0[2]), angles[2])
    }

    /// Euler angles (radians) of `r` in this order: the middle angle in [-90°, 90°]; at
    /// gimbal lock (middle angle ±90°) the third angle is set to zero.
    pub fn decompose(&self, r: &Matrix3<f64>) -> [f64; 3] {
        let [i, j, k] = self.0;
        // s = +1 for cyclic orders, -1 otherwise: the signs of the off-diagonal terms flip.
        let s = if self.cyclic() { 1.0 } else { -1.0 };
        let sin_b = (s * r[(i, k)]).clamp(-1.0, 1.0);
        let b = sin_b.asin();
        if sin_b.abs() < 1.0 - 1e-12 {
            let a = (-s * r[(j, k)]).atan2(r[(k, k)]);
            let c = (-s * r[(i, j)]).atan2(r[(i, i)]);
            [a, b, c]
        } else {
            // R = R_i(a) R_j(b): column j of R is R_i(a) e_j.
            let a = (s * r[(k, j)]).atan2(r[(j, j)]);
            [a, b, 0.0]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_up_axis_becomes_plus_y_by_a_proper_rotation() {
        for up in [
            UpAxis::PlusX,
            UpAxis::MinusX,
            UpAxis::PlusY,
            UpAxis::MinusY,
            UpAxis::PlusZ,
            UpAxis::MinusZ,
        ] {
            let c = to_y_up(Some(up));
            assert!((c * up_vector(up) - Vector3::y()).norm() < 1e-15, "{up:?}");
            assert!((c.matrix().determinant() - 1.0).abs() < 1e-15, "{up:?}");
            let s: String = up.into();
            assert_eq!(UpAxis::try_from(s).unwrap(), up);
        }
        assert!(UpAxis::try_from("up".to_string()).is_err());
    }
}
