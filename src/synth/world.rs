//! A tilted world (`pipeline synth --world-tilt DEG`): the capture is rendered standing on
//! +z, then its calibration and every truth file are written through one rigid transform,
//! as when a calibration's world is camera 0's frame or a board on a wall. The images do
//! not change; nothing in the files says where up is (except `ground_truth/world.yaml`).

use crate::camera::Camera;
use crate::error::Result;
use crate::geometry::TriMesh;
use nalgebra::{Rotation3, Unit, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Azimuth of the horizontal axis the world tilts about, degrees (away from x and y, so
/// that no axis of the written world is the up or lies in the floor).
const TILT_AXIS_AZIMUTH_DEG: f64 = 30.0;
/// Turn about the vertical before the tilt, degrees.
const SPIN_DEG: f64 = 25.0;
/// Where the rendered world's origin (on the floor, under the subject) lands, metres.
const SHIFT: [f64; 3] = [0.35, -0.25, 0.6];

/// The rigid transform from the rendered world (z up, floor at z = 0) to the written one:
/// `x -> rotation x + translation`. The identity for a tilt of zero.
#[derive(Debug, Clone, Copy)]
pub struct WorldTilt {
    pub rotation: Rotation3<f64>,
    pub translation: Vector3<f64>,
}

/// The written world's up and floor (`ground_truth/world.yaml`): the floor is the plane
/// of points `x` with `up . x = floor_height` (metres).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldTruth {
    pub up: [f64; 3],
    pub floor_height: f64,
}

impl WorldTilt {
    /// A tilt of `deg` degrees (0: the identity).
    pub fn new(deg: f64) -> WorldTilt {
        if deg == 0.0 {
            return WorldTilt {
                rotation: Rotation3::identity(),
                translation: Vector3::zeros(),
            };
        }
        let az = TILT_AXIS_AZIMUTH_DEG.to_radians();
        let axis = Unit::new_normalize(Vector3::new(az.cos(), az.sin(), 0.0));
        WorldTilt {
            rotation: Rotation3::from_axis_angle(&axis, deg.to_radians())
                * Rotation3::from_axis_angle(&Vector3::z_axis(), SPIN_DEG.to_radians()),
            translation: Vector3::from(SHIFT),
        }
    }

    pub fn point(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * x + self.translation
    }

    /// The mesh moved into the written world.
    pub fn mesh(&self, m: &TriMesh) -> TriMesh {
        TriMesh {
            vertices: m.vertices.iter().map(|v| self.point(v)).collect(),
            triangles: m.triangles.clone(),
        }
    }

    /// The camera seeing the same images in the written world: `x_c = R_c x + t_c` with
    /// `x = R^T (x' - t)`.
    pub fn camera(&self, c: &Camera) -> Camera {
        let back = self.rotation.inverse();
        let r = c.r * back.matrix();
        Camera {
            r,
            t: c.t - r * self.translation,
            ..c.clone()
        }
    }

    /// The written world's up and floor (the rendered floor is z = 0).
    pub fn truth(&self) -> WorldTruth {
        let up = self.rotation * Vector3::z();
        WorldTruth {
            up: [up.x, up.y, up.z],
            floor_height: up.dot(&self.translation),
        }
    }

    /// Writes [`WorldTilt::truth`] to `path` (YAML).
    pub fn write_truth(&self, path: &Path) -> Result<()> {
        crate::fsutil::write_atomic(path, crate::yaml::to_string(&self.truth())?.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tilted_camera_projects_the_tilted_point_where_the_original_projected_the_original() {
        let tilt = WorldTilt::new(25.0);
        let cam = Camera::look_at(
            "c",
            640,
            480,
            700.0,
            Vector3::new(3.0, 1.0, 1.7),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::z(),
        );
        let moved = tilt.camera(&cam);
        for x in [Vector3::new(0.1, 0.2, 1.3), Vector3::new(-0.3, 0.0, 0.2)] {
            let a = cam.project(&x).unwrap();
            let b = moved.project(&tilt.point(&x)).unwrap();
            assert!((a - b).norm() < 1e-9, "{a} {b}");
        }
        let up = Vector3::from(tilt.truth().up);
        assert!((up.z.acos().to_degrees() - 25.0).abs() < 1e-9);
        // The floor's origin lies on the written floor plane.
        assert!((up.dot(&tilt.point(&Vector3::zeros())) - tilt.truth().floor_height).abs() < 1e-12);
    }
}
