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

impl UpAxis {
    /// The six axes.
    pub const ALL: [UpAxis; 6] = [
        UpAxis::PlusX,
        UpAxis::MinusX,
        UpAxis::PlusY,
        UpAxis::MinusY,
        UpAxis::PlusZ,
        UpAxis::MinusZ,
    ];
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

/// The world's up as pipeline.yaml's `world.up` gives it: an axis name or a vector.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "UpSpelling", into = "UpSpelling")]
pub struct UpDirection(Vector3<f64>);

/// How `world.up` may be written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
enum UpSpelling {
    Axis(String),
    Vector([f64; 3]),
}

impl TryFrom<UpSpelling> for UpDirection {
    type Error = Refusal;
    fn try_from(s: UpSpelling) -> Result<Self, Refusal> {
        let v = match s {
            UpSpelling::Axis(a) => up_vector(UpAxis::try_from(a)?),
            UpSpelling::Vector(v) => Vector3::from(v),
        };
        if !v.iter().all(|x| x.is_finite()) || v.norm() < 1e-9 {
            return Err(format!(
                "{:?} is not a direction: give an axis (+z) or a vector such as [0, 0, 1]",
                v.as_slice()
            )
            .into());
        }
        Ok(UpDirection(v.normalize()))
    }
}

impl From<UpDirection> for UpSpelling {
    fn from(u: UpDirection) -> UpSpelling {
        UpSpelling::Vector(u.0.into())
    }
}

impl UpDirection {
    /// The direction, unit length.
    pub fn vector(&self) -> Vector3<f64> {
        self.0
    }
}

/// How the exports place the world: turned so that its up becomes +Y and moved so that its
/// floor lies at Y = 0. A world point x is written as `C x - floor Y`. Written beside the
/// exports as `world.yaml` (`rotation`: C's rows; `floor`, metres), so that a reader can take
/// an exported point y back to the world: x = Cᵀ (y + floor Y).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "FrameFile", into = "FrameFile")]
pub struct ExportFrame {
    /// The rotation C (world to export axes).
    pub rotation: Rotation3<f64>,
    /// The floor's height along the world's up, metres.
    pub floor: f64,
}

/// [`ExportFrame`] as `world.yaml` holds it.
#[derive(Serialize, Deserialize)]
struct FrameFile {
    /// The world's up (C's middle row), unit length.
    up: [f64; 3],
    /// The floor's height along `up`, metres.
    floor: f64,
    /// C, row by row: world to export axes.
    rotation: [[f64; 3]; 3],
}

impl From<ExportFrame> for FrameFile {
    fn from(f: ExportFrame) -> FrameFile {
        let m = f.rotation.matrix();
        let row = |i: usize| [m[(i, 0)], m[(i, 1)], m[(i, 2)]];
        FrameFile {
            up: row(1),
            floor: f.floor,
            rotation: [row(0), row(1), row(2)],
        }
    }
}

impl From<FrameFile> for ExportFrame {
    fn from(f: FrameFile) -> ExportFrame {
        let r = f.rotation;
        ExportFrame {
            rotation: Rotation3::from_matrix(&Matrix3::from_fn(|i, j| r[i][j])),
            floor: f.floor,
        }
    }
}

impl ExportFrame {
    /// The world as it is (no up known): axes and origin unchanged.
    pub fn identity() -> ExportFrame {
        ExportFrame {
            rotation: Rotation3::identity(),
            floor: 0.0,
        }
    }

    /// The frame for the world's `up` (unit) and floor height: C turns `up` onto +Y, as the
    /// axis table of [`to_y_up`] does for the nearest axis, after the smallest turn from
    /// `up` onto that axis (so an up found a degree off an axis exports as that axis does).
    pub fn new(up: &Vector3<f64>, floor: f64) -> ExportFrame {
        let nearest = UpAxis::ALL
            .into_iter()
            .max_by(|a, b| up_vector(*a).dot(up).total_cmp(&up_vector(*b).dot(up)))
            .expect("six axes");
        let onto_axis = Rotation3::rotation_between(up, &up_vector(nearest))
            .unwrap_or_else(Rotation3::identity);
        ExportFrame {
            rotation: to_y_up(Some(nearest)) * onto_axis,
            floor,
        }
    }

    /// A world point in the export frame.
    pub fn point(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * x - Vector3::y() * self.floor
    }

    /// A world direction (or difference of points) in the export frame.
    pub fn vector(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * v
    }

    /// A world rotation R expressed in the export axes: C R C^T.
    pub fn turn(&self, r: &Rotation3<f64>) -> Rotation3<f64> {
        self.rotation * r * self.rotation.inverse()
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
        for up in UpAxis::ALL {
            let c = to_y_up(Some(up));
            assert!((c * up_vector(up) - Vector3::y()).norm() < 1e-15, "{up:?}");
            assert!((c.matrix().determinant() - 1.0).abs() < 1e-15, "{up:?}");
            let s: String = up.into();
            assert_eq!(UpAxis::try_from(s).unwrap(), up);
        }
        assert!(UpAxis::try_from("up".to_string()).is_err());
    }

    #[test]
    fn the_world_up_is_an_axis_or_a_vector_and_the_export_frame_stands_it_on_y() {
        let parse = |t: &str| -> Result<UpDirection, String> {
            crate::yaml::from_str::<UpDirection>(std::path::Path::new("p.yaml"), t)
                .map_err(|e| e.to_string())
        };
        assert_eq!(parse("+z").unwrap().vector(), Vector3::z());
        let v = parse("[0, 3, 4]").unwrap().vector();
        assert!((v - Vector3::new(0.0, 0.6, 0.8)).norm() < 1e-12);
        for bad in ["[0, 0, 0]", "[1, nan, 0]", "up", "[1, 2]"] {
            assert!(parse(bad).is_err(), "{bad}");
        }
        // On an axis the frame is the axis table's rotation; the floor goes to Y = 0.
        let f = ExportFrame::new(&Vector3::z(), 0.25);
        assert!((f.rotation.matrix() - to_y_up(Some(UpAxis::PlusZ)).matrix()).norm() < 1e-12);
        assert!((f.point(&Vector3::new(0.3, -0.2, 0.25)).y).abs() < 1e-12);
        // Any up becomes +Y, a proper rotation, and the frame survives world.yaml.
        let up = Vector3::new(0.2, -0.5, 0.84).normalize();
        let f = ExportFrame::new(&up, -1.5);
        assert!((f.vector(&up) - Vector3::y()).norm() < 1e-12);
        assert!((f.rotation.matrix().determinant() - 1.0).abs() < 1e-12);
        assert!((f.point(&(up * -1.5 + up.cross(&Vector3::x()))).y).abs() < 1e-12);
        let text = crate::yaml::to_string(&f).unwrap();
        let back: ExportFrame =
            crate::yaml::from_str(std::path::Path::new("world.yaml"), &text).unwrap();
        assert!((back.rotation.matrix() - f.rotation.matrix()).norm() < 1e-12);
        assert_eq!(back.floor, f.floor);
    }
}
