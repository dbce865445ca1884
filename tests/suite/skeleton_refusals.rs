//! `pipeline skeleton` refuses what is not a body the humanoid template fits: a sphere, a
//! cube, a thin stick, and a frame whose silhouettes are empty. Each is a masks-only
//! capture seen by the bundled sample's 15 cameras, its masks cast exactly (ray against the
//! shape); each refusal is one clear message, and nothing is written.

use crate::common;

use common::*;
use hullpose::camera::Camera;
use image::{GrayImage, Luma};
use nalgebra::{Vector2, Vector3};
use std::path::Path;

/// A solid the masks are cast from.
enum Shape {
    Sphere {
        centre: Vector3<f64>,
        radius: f64,
    },
    Box {
        min: Vector3<f64>,
        max: Vector3<f64>,
    },
    Nothing,
}

impl Shape {
    /// Whether the ray from `o` along `d` meets the solid in front of the camera.
    fn hit(&self, o: &Vector3<f64>, d: &Vector3<f64>) -> bool {
        match self {
            Shape::Sphere { centre, radius } => {
                let oc = o - centre;
                let b = oc.dot(d);
                let c = oc.norm_squared() - radius * radius;
                b * b - c >= 0.0 && -b + (b * b - c).sqrt() > 0.0
            }
            Shape::Box { min, max } => {
                let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
                for a in 0..3 {
                    if d[a].abs() < 1e-12 {
                        if o[a] < min[a] || o[a] > max[a] {
                            return false;
                        }
                        continue;
                    }
                    let (t1, t2) = ((min[a] - o[a]) / d[a], (max[a] - o[a]) / d[a]);
                    near = near.max(t1.min(t2));
                    far = far.min(t1.max(t2));
                }
                near <= far && far > 0.0
            }
            Shape::Nothing => false,
        }
    }
}

/// A masks-only capture of `shape` (two frames) with the sample's cameras.
fn capture(dir: &Path, shape: &Shape) {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::create_dir_all(dir.join("calib")).unwrap();
    std::fs::copy(
        repo.join("calib/cameras.yaml"),
        dir.join("calib/cameras.yaml"),
    )
    .unwrap();
    let cameras: Vec<Camera> = hullpose::camera::read_cameras(&dir.join("calib/cameras.yaml"))
        .unwrap()
        .cameras;
    for cam in &cameras {
        let folder = dir.join("data/shape/masks").join(&cam.name);
        std::fs::create_dir_all(&folder).unwrap();
        let mask = GrayImage::from_fn(cam.width, cam.height, |x, y| {
            let (o, d) = cam.ray(Vector2::new(x as f64, y as f64));
            Luma([if shape.hit(&o, &d) { 255 } else { 0 }])
        });
        for f in 0..1 {
            mask.save(folder.join(format!("{f:06}.png"))).unwrap();
        }
    }
    std::fs::write(
        dir.join("pipeline.yaml"),
        "calibration: calib/cameras.yaml\nsequence: data/shape\nexport:\n  up_axis: +z\n",
    )
    .unwrap();
}

#[test]
fn a_sphere_a_cube_a_stick_and_an_empty_frame_are_refused_with_nothing_written() {
    let centre = Vector3::new(0.0, 0.0, 0.9);
    let cases = [
        (
            "sphere",
            Shape::Sphere {
                centre,
                radius: 0.45,
            },
        ),
        (
            "cube",
            Shape::Box {
                min: centre.add_scalar(-0.45),
                max: centre.add_scalar(0.45),
            },
        ),
        (
            "stick",
            Shape::Box {
                min: Vector3::new(-0.03, -0.03, 0.2),
                max: Vector3::new(0.03, 0.03, 1.6),
            },
        ),
        ("empty", Shape::Nothing),
    ];
    for (name, shape) in cases {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        capture(d, &shape);
        let (ok, out, err) = run_cli(&["skeleton", "pipeline.yaml"], d);
        assert!(!ok, "{name}: embedded a skeleton\n{out}");
        assert!(err.starts_with("error: "), "{name}: {err}");
        assert_eq!(
            err.trim().lines().count(),
            2,
            "{name}: one reason per frame\n{err}"
        );
        assert!(
            !d.join("data/shape/skeleton.yaml").exists() && !d.join("output/skeleton").exists(),
            "{name}: wrote a file"
        );
        eprintln!("{name}: {err}");
    }
}
