//! Calibration import from OpenCV FileStorage and COLMAP text files written by hand in each
//! tool's format: the imported cameras project known points where the source tool's own
//! projection formula puts them (within 1e-6 px, after COLMAP's half-pixel shift).

use hullpose::calib_import::{from_colmap, from_opencv};
use hullpose::camera::{read_cameras, write_cameras, Camera};
use nalgebra::{Matrix3, Vector2, Vector3};
use std::path::Path;

/// Points spread in front of every test camera (world metres).
fn points() -> Vec<Vector3<f64>> {
    let mut p = Vec::new();
    for i in 0..5 {
        for j in 0..5 {
            for k in 0..3 {
                p.push(Vector3::new(
                    -0.4 + 0.2 * i as f64,
                    -0.3 + 0.15 * j as f64,
                    -0.2 + 0.2 * k as f64,
                ));
            }
        }
    }
    p
}

/// Rodrigues' formula, written out: R = I + sin(a) [k]x + (1 - cos(a)) [k]x^2.
fn rodrigues(r: [f64; 3]) -> Matrix3<f64> {
    let v = Vector3::from(r);
    let a = v.norm();
    let k = v / a;
    let kx = Matrix3::new(0.0, -k.z, k.y, k.z, 0.0, -k.x, -k.y, k.x, 0.0);
    Matrix3::identity() + kx * a.sin() + kx * kx * (1.0 - a.cos())
}

/// cv::projectPoints' model (fx, fy, cx, cy, k1 k2 p1 p2 k3), written out.
#[allow(clippy::too_many_arguments)]
fn opencv_project(
    x: &Vector3<f64>,
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    k: [f64; 4],
    d: [f64; 5],
) -> Vector2<f64> {
    let c = r * x + t;
    let (x, y) = (c.x / c.z, c.y / c.z);
    let r2 = x * x + y * y;
    let radial = 1.0 + d[0] * r2 + d[1] * r2 * r2 + d[4] * r2 * r2 * r2;
    let xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x);
    let yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y;
    Vector2::new(k[0] * xd + k[2], k[1] * yd + k[3])
}

fn check_close(cam: &Camera, reference: impl Fn(&Vector3<f64>) -> Vector2<f64>) {
    for p in points() {
        let ours = cam.project(&p).expect("in front");
        let theirs = reference(&p);
        let gap = (ours - theirs).norm();
        assert!(
            gap <= 1e-6,
            "camera {}: point {p:?}: {ours:?} vs {theirs:?} ({gap:e} px)",
            cam.name
        );
    }
}

const INTRI: &str = r#"%YAML:1.0
---
names:
   - "01"
   - "cam_b"
K_01: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1.1520000000000000e+03, 0., 9.6000000000000000e+02, 0.,
       1.1480000000000000e+03, 5.4000000000000000e+02, 0., 0., 1. ]
dist_01: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -1.2e-01, 3.4e-02, 1.5e-03, -7.0e-04, 2.0e-03 ]
H_01: 1080
W_01: 1920
K_cam_b: !!opencv-matrix
   rows: 3
   cols: 3
   dt: f
   data: [ 800., 0., 320., 0., 810., 240., 0., 0., 1. ]
dist_cam_b: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ 0.05, 0., 0., 0., 0. ]
H_cam_b: 480
W_cam_b: 640
"#;

const EXTRI: &str = r#"%YAML:1.0
---
names:
   - "01"
   - "cam_b"
R_01: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0.1, -2.9, 0.05 ]
Rot_01: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]
T_01: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0.2, -0.1, 3.5 ]
Rot_cam_b: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 0., -1., 0., 1., 0., 0., 0., 0., 1. ]
T_cam_b: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0., 0., 4. ]
"#;

#[test]
fn opencv_file_storage_projects_like_opencv() {
    let dir = tempfile::tempdir().unwrap();
    let (intri, extri) = (dir.path().join("intri.yml"), dir.path().join("extri.yml"));
    std::fs::write(&intri, INTRI).unwrap();
    std::fs::write(&extri, EXTRI).unwrap();
    let imported = from_opencv(&intri, &extri, None).unwrap();
    // R_01 wins over the (inconsistent) Rot_01, as EasyMocap's reader does, with a warning.
    assert_eq!(imported.warnings.len(), 1, "{:?}", imported.warnings);
    let cams = &imported.cameras;
    assert_eq!(cams.len(), 2);
    assert_eq!(
        (cams[0].name.as_str(), cams[0].width, cams[0].height),
        ("01", 1920, 1080)
    );
    let r0 = rodrigues([0.1, -2.9, 0.05]);
    check_close(&cams[0], |p| {
        opencv_project(
            p,
            &r0,
            &Vector3::new(0.2, -0.1, 3.5),
            [1152.0, 1148.0, 960.0, 540.0],
            [-0.12, 0.034, 0.0015, -0.0007, 0.002],
        )
    });
    let r1 = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    check_close(&cams[1], |p| {
        opencv_project(
            p,
            &r1,
            &Vector3::new(0.0, 0.0, 4.0),
            [800.0, 810.0, 320.0, 240.0],
            [0.05, 0.0, 0.0, 0.0, 0.0],
        )
    });
    // Through cameras.yaml and back: the same cameras (names that look like numbers stay
    // names).
    let out = dir.path().join("calib/cameras.yaml");
    write_cameras(&out, cams).unwrap();
    assert_eq!(&read_cameras(&out).unwrap().cameras, cams);
}

#[test]
fn opencv_errors_name_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let (intri, extri) = (dir.path().join("intri.yml"), dir.path().join("extri.yml"));
    std::fs::write(&intri, INTRI.replace("H_cam_b: 480\nW_cam_b: 640\n", "")).unwrap();
    std::fs::write(&extri, EXTRI).unwrap();
    let err = from_opencv(&intri, &extri, None).unwrap_err().to_string();
    assert!(err.contains("W_cam_b") && err.contains("--size"), "{err}");
    assert!(from_opencv(&intri, &extri, Some((640, 480))).is_ok());
    std::fs::write(&intri, INTRI).unwrap();
    std::fs::write(&extri, EXTRI.replace("T_cam_b", "T_other")).unwrap();
    let err = from_opencv(&intri, &extri, None).unwrap_err().to_string();
    assert!(
        err.contains("extri.yml") && err.contains("'T_cam_b' is missing"),
        "{err}"
    );
    std::fs::write(
        &extri,
        EXTRI.replace("data: [ 0., 0., 4. ]", "data: [ 0., 4. ]"),
    )
    .unwrap();
    let err = from_opencv(&intri, &extri, None).unwrap_err().to_string();
    assert!(err.contains("T_cam_b"), "{err}");
}

const COLMAP_CAMERAS: &str = "# Camera list with one line of data per camera:
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]
# Number of cameras: 2
3 OPENCV 1280 720 1000.5 1002.25 640.5 360.5 -0.08 0.02 0.001 -0.0005
7 PINHOLE 640 480 600 600 320 240
";

const COLMAP_IMAGES: &str = "# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
# Number of images: 2, mean observations per image: 1
12 0.9238795325112867 0.0 0.3826834323650898 0.0 0.1 0.2 3.0 3 camA/000000.png
100.0 200.0 -1
40 0.8 0.36 0.48 0.0 -0.2 0.0 4.0 7 camB.jpg

";

/// COLMAP's projection: rotate by the quaternion (q v q*), divide by depth, OpenCV
/// distortion, then fx * x + cx with COLMAP's principal point (top-left centre at 0.5).
fn colmap_project(
    x: &Vector3<f64>,
    q: [f64; 4],
    t: [f64; 3],
    k: [f64; 4],
    d: [f64; 4],
) -> Vector2<f64> {
    let (w, u) = (q[0], Vector3::new(q[1], q[2], q[3]));
    let rotated = 2.0 * u.dot(x) * u + (w * w - u.dot(&u)) * x + 2.0 * w * u.cross(x);
    let c = rotated + Vector3::from(t);
    let (x, y) = (c.x / c.z, c.y / c.z);
    let (x2, y2, xy, r2) = (x * x, y * y, x * y, x * x + y * y);
    let radial = d[0] * r2 + d[1] * r2 * r2;
    let dx = x * radial + 2.0 * d[2] * xy + d[3] * (r2 + 2.0 * x2);
    let dy = y * radial + 2.0 * d[3] * xy + d[2] * (r2 + 2.0 * y2);
    Vector2::new(k[0] * (x + dx) + k[2], k[1] * (y + dy) + k[3])
}

#[test]
fn colmap_text_model_projects_like_colmap_minus_half_a_pixel() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cameras.txt"), COLMAP_CAMERAS).unwrap();
    std::fs::write(dir.path().join("images.txt"), COLMAP_IMAGES).unwrap();
    let imported = from_colmap(dir.path()).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let cams = &imported.cameras;
    assert_eq!(cams.len(), 2);
    assert_eq!((cams[0].name.as_str(), cams[0].width), ("camA", 1280));
    assert_eq!((cams[1].name.as_str(), cams[1].height), ("camB", 480));
    let half = Vector2::new(0.5, 0.5);
    check_close(&cams[0], |p| {
        colmap_project(
            p,
            [0.9238795325112867, 0.0, 0.3826834323650898, 0.0],
            [0.1, 0.2, 3.0],
            [1000.5, 1002.25, 640.5, 360.5],
            [-0.08, 0.02, 0.001, -0.0005],
        ) - half
    });
    check_close(&cams[1], |p| {
        colmap_project(
            p,
            [0.8, 0.36, 0.48, 0.0],
            [-0.2, 0.0, 4.0],
            [600.0, 600.0, 320.0, 240.0],
            [0.0; 4],
        ) - half
    });
}

#[test]
fn colmap_errors_name_the_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("cameras.txt"),
        COLMAP_CAMERAS.replace("PINHOLE 640", "OPENCV_FISHEYE 640"),
    )
    .unwrap();
    std::fs::write(dir.path().join("images.txt"), COLMAP_IMAGES).unwrap();
    let err = from_colmap(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("cameras.txt") && err.contains("line 5") && err.contains("OPENCV_FISHEYE"),
        "{err}"
    );
    std::fs::write(dir.path().join("cameras.txt"), COLMAP_CAMERAS).unwrap();
    std::fs::write(
        dir.path().join("images.txt"),
        COLMAP_IMAGES.replace(" 7 camB.jpg", " 9 camB.jpg"),
    )
    .unwrap();
    let err = from_colmap(dir.path()).unwrap_err().to_string();
    assert!(err.contains("camera id 9"), "{err}");
    let missing = from_colmap(Path::new("/nonexistent/colmap")).unwrap_err();
    assert!(missing.to_string().contains("cameras.txt"));
}

/// A Pose2Sim Calib.toml as Pose2Sim's `toml_write` lays it out: two cameras, Rodrigues
/// rotations, translations in metres, four distortion terms, a metadata table.
const POSE2SIM_TOML: &str = r#"[cam_01]
name = "cam_01"
size = [ 1088.0, 1920.0]
matrix = [ [ 1677.3, 0.0, 543.8], [ 0.0, 1679.9, 962.1], [ 0.0, 0.0, 1.0]]
distortions = [ -0.0431, 0.0712, 0.0011, -0.0006]
rotation = [ 1.2214, -1.1834, 1.1721]
translation = [ 0.2013, 0.4821, 3.8514]
fisheye = false

[cam_02]
name = "cam_02"
size = [ 1088.0, 1920.0]
matrix = [ [ 1690.0, 0.0, 540.0], [ 0.0, 1690.0, 960.0], [ 0.0, 0.0, 1.0]]
distortions = [ 0.012, -0.03, 0.0, 0.0]
rotation = [ 1.9, 0.4, -0.35]
translation = [ -0.31, 0.52, 4.2]
fisheye = false

[metadata]
adjusted = false
error = 0.0
"#;

#[test]
fn pose2sim_toml_projects_like_opencv() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("Calib.toml");
    std::fs::write(&path, POSE2SIM_TOML).unwrap();
    let imported = hullpose::calib_import::pose2sim::from_toml(&path, 1.0).unwrap();
    assert_eq!(imported.cameras.len(), 2);
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let truth = [
        (
            [1.2214, -1.1834, 1.1721],
            [0.2013, 0.4821, 3.8514],
            [1677.3, 1679.9, 543.8, 962.1],
            [-0.0431, 0.0712, 0.0011, -0.0006, 0.0],
        ),
        (
            [1.9, 0.4, -0.35],
            [-0.31, 0.52, 4.2],
            [1690.0, 1690.0, 540.0, 960.0],
            [0.012, -0.03, 0.0, 0.0, 0.0],
        ),
    ];
    for (cam, (r, t, k, d)) in imported.cameras.iter().zip(truth) {
        assert_eq!((cam.width, cam.height), (1088, 1920));
        check_close(cam, |x| {
            opencv_project(x, &rodrigues(r), &Vector3::from(t), k, d)
        });
    }
    // The same file in millimetres (anipose with a board in mm): --units mm.
    let mm = POSE2SIM_TOML
        .replace("[ 0.2013, 0.4821, 3.8514]", "[ 201.3, 482.1, 3851.4]")
        .replace("[ -0.31, 0.52, 4.2]", "[ -310.0, 520.0, 4200.0]");
    std::fs::write(&path, &mm).unwrap();
    let wrong = hullpose::calib_import::pose2sim::from_toml(&path, 1.0).unwrap();
    assert!(
        wrong.warnings.iter().any(|w| w.contains("--units mm")),
        "{:?}",
        wrong.warnings
    );
    let scaled = hullpose::calib_import::pose2sim::from_toml(&path, 0.001).unwrap();
    for (a, b) in scaled.cameras.iter().zip(&imported.cameras) {
        assert!((a.t - b.t).norm() < 1e-9);
    }
    // Through the command line, and refusals that name the table and key.
    let out = dir.path().join("cameras.yaml");
    std::fs::write(&path, POSE2SIM_TOML).unwrap();
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_pipeline"))
        .args(["import-calib", "--from", "pose2sim"])
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    assert_eq!(read_cameras(&out).unwrap().cameras, imported.cameras);
    for (from, to, what) in [
        (
            "fisheye = false\n\n[cam_02]",
            "fisheye = true\n\n[cam_02]",
            "fisheye",
        ),
        (
            "rotation = [ 1.9, 0.4, -0.35]",
            "rotation = [ 1.9, 0.4]",
            "'rotation'",
        ),
        (
            "size = [ 1088.0, 1920.0]\nmatrix = [ [ 1690.0",
            "size = [ 10.5, 1920.0]\nmatrix = [ [ 1690.0",
            "'size'",
        ),
    ] {
        std::fs::write(&path, POSE2SIM_TOML.replacen(from, to, 1)).unwrap();
        let err = hullpose::calib_import::pose2sim::from_toml(&path, 1.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains(what) && err.contains("cam_0"), "{err}");
    }
}

/// One video camera of a Qualisys .qca.txt, from the world-to-camera pose in OpenCV's
/// terms that it must import as: the camera's pose in the world (camera to world, Qualisys's
/// camera axes: -z forward, y up) in mm, the matrix written by column, intrinsics in 1/64
/// pixel on the sensor, the image a crop at (`left`, `top`).
fn qca_camera(serial: &str, model: &str, cam: &Camera, left: f64, top: f64) -> String {
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    let camera_to_world = cam.r.transpose() * flip;
    let c = -cam.r.transpose() * cam.t * 1000.0;
    let m = |i: usize, j: usize| camera_to_world[(i, j)];
    format!(
        r#"    <camera active="1" avg-residual="0.31" serial="{serial}" model="{model}" viewrotation="0">
      <fov_marker left="0" top="0" right="1919" bottom="1087"/>
      <fov_video left="{left}" top="{top}" right="{}" bottom="{}"/>
      <transform x="{}" y="{}" z="{}" r11="{}" r12="{}" r13="{}" r21="{}" r22="{}" r23="{}" r31="{}" r32="{}" r33="{}"/>
      <intrinsic focallength="4.5" sensorMinU="0" sensorMaxU="1919" sensorMinV="0" sensorMaxV="1087" focalLengthU="{}" focalLengthV="{}" centerPointU="{}" centerPointV="{}" skew="0" radialDistortion1="{}" radialDistortion2="{}" radialDistortion3="0" tangentalDistortion1="{}" tangentalDistortion2="{}"/>
    </camera>
"#,
        left + cam.width as f64 - 1.0,
        top + cam.height as f64 - 1.0,
        c.x,
        c.y,
        c.z,
        m(0, 0),
        m(1, 0),
        m(2, 0),
        m(0, 1),
        m(1, 1),
        m(2, 1),
        m(0, 2),
        m(1, 2),
        m(2, 2),
        cam.fx * 64.0,
        cam.fy * 64.0,
        (cam.cx + left) * 64.0,
        (cam.cy + top) * 64.0,
        cam.dist[0] * 64.0,
        cam.dist[1] * 64.0,
        cam.dist[2] * 64.0,
        cam.dist[3] * 64.0,
    )
}

#[test]
fn qualisys_qca_imports_the_video_cameras_as_pose2sim_reads_them() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let sample = read_cameras(&repo.join("calib/cameras.yaml"))
        .unwrap()
        .cameras;
    let mut cams: Vec<Camera> = sample[..3].to_vec();
    for c in &mut cams {
        c.dist[4] = 0.0;
    }
    // Serials 10, 9, 100: natural order puts 9 first; a marker camera is left out.
    let serials = ["10", "9", "100"];
    let mut xml = String::from(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<calibration source=\"test\">\n  <cameras>\n",
    );
    for (k, (cam, serial)) in cams.iter().zip(serials).enumerate() {
        xml += &qca_camera(serial, "Miqus Video", cam, 8.0 * k as f64, 4.0 * k as f64);
    }
    xml += &qca_camera("555", "Miqus M3", &cams[0], 0.0, 0.0);
    xml += "  </cameras>\n</calibration>\n";
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("calib.qca.txt");
    std::fs::write(&path, &xml).unwrap();
    let imported = hullpose::calib_import::qualisys::from_qca(&path).unwrap();
    let names: Vec<&str> = imported.cameras.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["9", "10", "100"]);
    assert!(
        imported.warnings.iter().any(|w| w.contains("555")),
        "{:?}",
        imported.warnings
    );
    for (cam, serial) in cams.iter().zip(serials) {
        let got = imported.cameras.iter().find(|c| c.name == serial).unwrap();
        assert_eq!((got.width, got.height), (cam.width, cam.height));
        // The sample's points lie around the world origin, in front of every camera.
        for p in points() {
            let want = cam.project(&p).expect("in front");
            let have = got.project(&p).expect("in front after the import");
            assert!(
                (want - have).norm() < 0.01,
                "{serial}: {want:?} vs {have:?}"
            );
        }
    }
    let err = {
        std::fs::write(&path, xml.replace("Miqus Video", "Oqus 7+")).unwrap();
        hullpose::calib_import::qualisys::from_qca(&path)
            .unwrap_err()
            .to_string()
    };
    assert!(err.contains("no video camera"), "{err}");
}
