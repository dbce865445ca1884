//! Calibration import: cameras from other tools' files, converted to the project's
//! `calib/cameras.yaml` convention (OpenCV pinhole, world-to-camera `x_c = R·X + t`, pixel
//! centres on integer coordinates).
//!
//! - **OpenCV FileStorage** (`intri.yml` / `extri.yml` as multi-view capture tools write
//!   them): `%YAML:1.0` header, `!!opencv-matrix` maps (`rows`, `cols`, `dt`, row-major
//!   `data`). `intri.yml`: `names`, `K_<name>`, `dist_<name>` (k1 k2 p1 p2 [k3]), optional
//!   `H_<name>` / `W_<name>` (image size). `extri.yml`: `R_<name>` (3x1 Rodrigues vector) or
//!   `Rot_<name>` (3x3), and `T_<name>` (3x1), world to camera. The pixel convention is
//!   already ours.
//! - **COLMAP text model** (`cameras.txt`, `images.txt`): one image per camera of the rig;
//!   `QW QX QY QZ` is the world-to-camera rotation (Hamilton, scalar first), `TX TY TZ` the
//!   translation. COLMAP puts the top-left pixel's centre at (0.5, 0.5), we put it at (0, 0):
//!   `cx_ours = cx_colmap - 0.5` (and the same for cy), so that every pixel coordinate is
//!   COLMAP's minus 0.5.
//! - **Pose2Sim / anipose TOML** ([`pose2sim`]) and **Qualisys `.qca.txt`** ([`qualisys`]).

pub mod pose2sim;
pub mod qualisys;

use crate::camera::{check_name, Camera};
use crate::error::Refusal;
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// Cameras and the notes the import made (values it had to assume).
#[derive(Debug, Clone)]
pub struct Imported {
    pub cameras: Vec<Camera>,
    pub warnings: Vec<String>,
}

/// One value of an OpenCV FileStorage map.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum CvValue {
    Matrix {
        rows: usize,
        cols: usize,
        /// Element type (`d` for the doubles calibrations hold).
        dt: String,
        data: Vec<f64>,
    },
    Number(f64),
    List(Vec<CvName>),
    /// Other entries (dates, notes) are accepted and ignored.
    #[allow(dead_code)]
    Text(String),
}

/// A camera name as FileStorage lists it (quoted text, or a bare number).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum CvName {
    Text(String),
    Integer(i64),
}

impl CvName {
    fn text(&self) -> String {
        match self {
            CvName::Text(s) => s.clone(),
            CvName::Integer(i) => i.to_string(),
        }
    }
}

/// Reads an OpenCV FileStorage YAML file into its top-level map. The `%YAML:1.0`
/// directive (not valid YAML 1.2) and the `!!opencv-matrix` tags are removed first.
fn read_file_storage(path: &Path) -> Result<BTreeMap<String, CvValue>> {
    let text = crate::fsutil::read_to_string(path)?;
    let mut cleaned = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        if i == 0 && line.trim_start().starts_with("%YAML") {
            // An empty line in its place keeps the line numbers of messages right.
            cleaned.push('\n');
            continue;
        }
        cleaned.push_str(&line.replace("!!opencv-matrix", ""));
        cleaned.push('\n');
    }
    if cleaned.trim().is_empty() || cleaned.trim() == "---" {
        return Err(Error::invalid(path, "the file is empty"));
    }
    // Each entry on its own, so that an entry of no known shape is named with its line
    // (an untagged enum's own error names neither).
    let raw: BTreeMap<String, serde_yaml_ng::Value> = crate::yaml::from_str(path, &cleaned)?;
    let mut out = BTreeMap::new();
    for (key, value) in raw {
        // Only for a message: a scan of the text.
        let line = || {
            cleaned
                .lines()
                .position(|l| l.trim_start().starts_with(&format!("{key}:")))
                .map_or(String::new(), |i| format!("line {}: ", i + 1))
        };
        let entry: CvValue = serde_yaml_ng::from_value(value).map_err(|_| {
            Error::invalid(
                path,
                format!(
                    "{}entry '{}' is neither a matrix (rows, cols, dt, data), a number, a \
                     list of names nor text",
                    line(),
                    crate::yaml::shorten(&key)
                ),
            )
        })?;
        if let CvValue::Matrix { dt, .. } = &entry {
            if !matches!(dt.as_str(), "u" | "c" | "w" | "s" | "i" | "f" | "d") {
                return Err(Error::invalid(
                    path,
                    format!(
                        "{}matrix '{}' has dt '{}'; OpenCV's element types are u, c, w, s, \
                         i, f and d",
                        line(),
                        crate::yaml::shorten(&key),
                        crate::yaml::shorten(dt)
                    ),
                ));
            }
        }
        out.insert(key, entry);
    }
    Ok(out)
}

/// A matrix entry `key` of a FileStorage map, checked to hold `len` values.
fn cv_matrix<'a>(
    path: &Path,
    map: &'a BTreeMap<String, CvValue>,
    key: &str,
    lens: &[usize],
) -> Result<Option<&'a [f64]>> {
    match map.get(key) {
        None => Ok(None),
        Some(CvValue::Matrix {
            rows, cols, data, ..
        }) => {
            if rows * cols != data.len() {
                return Err(Error::invalid(
                    path,
                    format!(
                        "key '{key}': {rows}x{cols} matrix with {} values",
                        data.len()
                    ),
                ));
            }
            if !lens.contains(&data.len()) {
                return Err(Error::invalid(
                    path,
                    format!(
                        "key '{key}': expected {} values, found {}",
                        lens.iter()
                            .map(|l| l.to_string())
                            .collect::<Vec<_>>()
                            .join(" or "),
                        data.len()
                    ),
                ));
            }
            if data.iter().any(|v| !v.is_finite()) {
                return Err(Error::invalid(
                    path,
                    format!("key '{key}': a value is not finite"),
                ));
            }
            Ok(Some(data))
        }
        Some(_) => Err(Error::invalid(
            path,
            format!("key '{key}' must be an !!opencv-matrix (rows, cols, dt, data)"),
        )),
    }
}

/// A required matrix entry.
fn cv_required<'a>(
    path: &Path,
    map: &'a BTreeMap<String, CvValue>,
    key: &str,
    lens: &[usize],
) -> Result<&'a [f64]> {
    cv_matrix(path, map, key, lens)?
        .ok_or_else(|| Error::invalid(path, format!("key '{key}' is missing")))
}

/// The camera names a FileStorage file lists under `names`.
fn cv_names(path: &Path, map: &BTreeMap<String, CvValue>) -> Result<Vec<String>> {
    match map.get("names") {
        Some(CvValue::List(names)) if !names.is_empty() => {
            Ok(names.iter().map(CvName::text).collect())
        }
        _ => Err(Error::invalid(
            path,
            "key 'names' must list the camera names (e.g. names: [\"cam00\", \"cam01\"])",
        )),
    }
}

/// Imports an OpenCV FileStorage calibration (`intri`, `extri`). `size` gives the image
/// size (width, height) for cameras whose `W_<name>` / `H_<name>` are absent.
pub fn from_opencv(intri: &Path, extri: &Path, size: Option<(u32, u32)>) -> Result<Imported> {
    let im = read_file_storage(intri)?;
    let ex = read_file_storage(extri)?;
    let names = cv_names(intri, &im)?;
    let mut warnings = Vec::new();
    let mut cameras = Vec::with_capacity(names.len());
    for name in &names {
        check_name(name).map_err(|m| Error::invalid(intri, format!("camera '{name}': {m}")))?;
        let k = cv_required(intri, &im, &format!("K_{name}"), &[9])?;
        let dist = cv_matrix(intri, &im, &format!("dist_{name}"), &[4, 5, 8, 12, 14])?;
        let mut d = [0.0; 5];
        if let Some(dist) = dist {
            let n = dist.len().min(5);
            d[..n].copy_from_slice(&dist[..n]);
            if dist.iter().skip(5).any(|&x| x != 0.0) {
                return Err(Error::invalid(
                    intri,
                    format!(
                        "key 'dist_{name}': only k1 k2 p1 p2 k3 are supported; the rational or \
                         thin-prism terms (values 6 and on) must be zero"
                    ),
                ));
            }
        }
        let dim = |key: String| -> Result<Option<u32>> {
            match im.get(&key) {
                None => Ok(None),
                Some(CvValue::Number(v)) if *v >= 1.0 && v.fract() == 0.0 && *v < 1e6 => {
                    Ok(Some(*v as u32))
                }
                Some(_) => Err(Error::invalid(
                    intri,
                    format!("key '{key}' must be a positive whole number of pixels"),
                )),
            }
        };
        let (width, height) = match (dim(format!("W_{name}"))?, dim(format!("H_{name}"))?) {
            (Some(w), Some(h)) => (w, h),
            _ => size.ok_or_else(|| {
                Error::invalid(
                    intri,
                    format!(
                        "camera '{name}' has no W_{name} / H_{name} (image size); pass --size WxH"
                    ),
                )
            })?,
        };
        let rotation = match (
            cv_matrix(extri, &ex, &format!("R_{name}"), &[3])?,
            cv_matrix(extri, &ex, &format!("Rot_{name}"), &[9])?,
        ) {
            (Some(rvec), rot) => {
                let r = *Rotation3::new(Vector3::new(rvec[0], rvec[1], rvec[2])).matrix();
                if let Some(rot) = rot {
                    let given = Matrix3::from_row_slice(rot);
                    let gap = (given - r).abs().max();
                    if gap > 1e-6 {
                        warnings.push(format!(
                            "camera '{name}': Rot_{name} differs from Rodrigues(R_{name}) by {gap:.1e}; using R_{name}"
                        ));
                    }
                }
                r
            }
            (None, Some(rot)) => Matrix3::from_row_slice(rot),
            (None, None) => {
                return Err(Error::invalid(
                    extri,
                    format!(
                        "camera '{name}' has neither R_{name} (Rodrigues) nor Rot_{name} (3x3)"
                    ),
                ))
            }
        };
        let t = cv_required(extri, &ex, &format!("T_{name}"), &[3])?;
        let cam = camera_from_k(name.clone(), (width, height), k, d, rotation, t);
        if k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(Error::invalid(
                intri,
                format!("key 'K_{name}' must be [fx, s, cx; 0, fy, cy; 0, 0, 1]"),
            ));
        }
        cam.validate()
            .map_err(|m| Error::invalid(extri, format!("camera '{name}': {m}")))?;
        cameras.push(cam);
    }
    revalidate(intri, cameras, warnings)
}

/// A camera from a row-major 3x3 `k` ([fx, s, cx; 0, fy, cy; 0, 0, 1], checked by the
/// caller), its image size, distortion and world-to-camera `r`, `t`.
fn camera_from_k(
    name: String,
    (width, height): (u32, u32),
    k: &[f64],
    dist: [f64; 5],
    r: Matrix3<f64>,
    t: &[f64],
) -> Camera {
    Camera {
        name,
        width,
        height,
        fx: k[0],
        fy: k[4],
        cx: k[2],
        cy: k[5],
        skew: k[1],
        dist,
        r,
        t: Vector3::new(t[0], t[1], t[2]),
    }
}

/// A warning when the cameras stand farther apart than a capture room allows in metres
/// (median distance from their centroid over 100 m): the file's lengths are in another unit.
fn unit_warning(cameras: &[Camera]) -> Option<String> {
    let centres: Vec<Vector3<f64>> = cameras.iter().map(Camera::centre).collect();
    let mean = centres.iter().sum::<Vector3<f64>>() / centres.len() as f64;
    let mut d: Vec<f64> = centres.iter().map(|c| (c - mean).norm()).collect();
    d.sort_by(f64::total_cmp);
    let median = d[d.len() / 2];
    (median > 100.0).then(|| {
        format!(
            "the cameras stand a median {median:.0} m from their centre: the translations look \
             like millimetres or centimetres; import again with --units mm (or cm)"
        )
    })
}

/// Checks imported cameras as cameras.yaml will be checked when read (unique names, also
/// ignoring case, and every camera's values), so a bad import fails here, naming `source`.
fn revalidate(source: &Path, cameras: Vec<Camera>, warnings: Vec<String>) -> Result<Imported> {
    crate::camera::parse_cameras(source, &crate::camera::cameras_to_yaml(&cameras))?;
    Ok(Imported { cameras, warnings })
}

/// A COLMAP camera model's intrinsics in our terms: fx, fy, cx, cy (COLMAP's pixel
/// convention), dist.
type ColmapIntrinsics = (f64, f64, f64, f64, [f64; 5]);

/// Converts one `cameras.txt` model and its parameters.
fn colmap_intrinsics(model: &str, p: &[f64]) -> std::result::Result<ColmapIntrinsics, Refusal> {
    let need = |n: usize| -> std::result::Result<(), Refusal> {
        if p.len() == n {
            Ok(())
        } else {
            Err(format!("model {model} takes {n} parameters, found {}", p.len()).into())
        }
    };
    Ok(match model {
        "SIMPLE_PINHOLE" => {
            need(3)?;
            (p[0], p[0], p[1], p[2], [0.0; 5])
        }
        "PINHOLE" => {
            need(4)?;
            (p[0], p[1], p[2], p[3], [0.0; 5])
        }
        "SIMPLE_RADIAL" => {
            need(4)?;
            (p[0], p[0], p[1], p[2], [p[3], 0.0, 0.0, 0.0, 0.0])
        }
        "RADIAL" => {
            need(5)?;
            (p[0], p[0], p[1], p[2], [p[3], p[4], 0.0, 0.0, 0.0])
        }
        "OPENCV" => {
            need(8)?;
            (p[0], p[1], p[2], p[3], [p[4], p[5], p[6], p[7], 0.0])
        }
        "FULL_OPENCV" => {
            need(12)?;
            if p[9..].iter().any(|&x| x != 0.0) {
                return Err(
                    "FULL_OPENCV with non-zero k4, k5, k6 (the rational model) is not supported"
                        .into(),
                );
            }
            (p[0], p[1], p[2], p[3], [p[4], p[5], p[6], p[7], p[8]])
        }
        other => {
            return Err(format!(
                "camera model {other} is not supported; use SIMPLE_PINHOLE, PINHOLE, \
                 SIMPLE_RADIAL, RADIAL, OPENCV or FULL_OPENCV"
            )
            .into())
        }
    })
}

/// The data lines of a COLMAP text file (comments removed; blank lines kept, as
/// images.txt uses them for images without 2D points), with their 1-based line numbers.
fn colmap_lines(text: &str) -> Vec<(usize, &str)> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#'))
        .map(|(i, l)| (i + 1, l.trim()))
        .collect()
}

/// The camera name of a COLMAP image: its folder when it has one (`cam00/000000.png` is
/// camera `cam00`), else its file stem.
fn colmap_camera_name(image: &str) -> String {
    let p = Path::new(image);
    match p.parent().and_then(|d| d.file_name()) {
        Some(dir) => dir.to_string_lossy().into_owned(),
        None => p
            .file_stem()
            .map_or(image.to_string(), |s| s.to_string_lossy().into_owned()),
    }
}

/// Imports a COLMAP text model from `dir` (cameras.txt and images.txt): one camera per
/// image.
pub fn from_colmap(dir: &Path) -> Result<Imported> {
    let cameras_path = dir.join("cameras.txt");
    let images_path = dir.join("images.txt");
    let mut intrinsics = BTreeMap::new();
    let text = crate::fsutil::read_to_string(&cameras_path)?;
    for (line_no, line) in colmap_lines(&text) {
        if line.is_empty() {
            continue;
        }
        let bad = |m: String| Error::invalid(&cameras_path, format!("line {line_no}: {m}"));
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 4 {
            return Err(bad("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...".into()));
        }
        let id: u64 = f[0]
            .parse()
            .map_err(|_| bad(format!("'{}' is not a camera id", f[0])))?;
        let dim = |s: &str| -> Result<u32> {
            s.parse::<u32>()
                .ok()
                .filter(|&v| v > 0)
                .ok_or_else(|| bad(format!("'{s}' is not an image size in pixels")))
        };
        let (w, h) = (dim(f[2])?, dim(f[3])?);
        let params: Vec<f64> = f[4..]
            .iter()
            .map(|s| s.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| bad("a parameter is not a finite number".into()))?;
        let k = colmap_intrinsics(f[1], &params).map_err(|m| bad(m.0))?;
        if intrinsics.insert(id, (w, h, k)).is_some() {
            return Err(bad(format!("camera id {id} is listed twice")));
        }
    }
    let text = crate::fsutil::read_to_string(&images_path)?;
    let lines = colmap_lines(&text);
    let mut cameras: Vec<Camera> = Vec::new();
    let mut names = std::collections::HashSet::new();
    let mut warnings = Vec::new();
    // Two lines per image: the pose line, then the 2D points (possibly blank).
    let mut i = 0;
    while i < lines.len() {
        let (line_no, line) = lines[i];
        if line.is_empty() {
            i += 1;
            continue;
        }
        i += 2;
        let bad = |m: String| Error::invalid(&images_path, format!("line {line_no}: {m}"));
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 10 {
            return Err(bad(
                "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME".into()
            ));
        }
        let num: Vec<f64> = f[1..8]
            .iter()
            .map(|s| s.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| bad("a pose value is not a finite number".into()))?;
        let camera_id: u64 = f[8]
            .parse()
            .map_err(|_| bad(format!("'{}' is not a camera id", f[8])))?;
        let &(width, height, (fx, fy, cx, cy, dist)) = intrinsics
            .get(&camera_id)
            .ok_or_else(|| bad(format!("camera id {camera_id} is not in cameras.txt")))?;
        let image = f[9..].join(" ");
        let name = colmap_camera_name(&image);
        check_name(&name).map_err(|m| bad(format!("image '{image}': {m}")))?;
        if !names.insert(name.clone()) {
            return Err(bad(format!(
                "two images map to camera '{name}'; give each camera's image its own folder \
                 or file name (one image per camera)"
            )));
        }
        let q = Quaternion::new(num[0], num[1], num[2], num[3]);
        let norm = q.norm();
        if norm < 1e-9 {
            return Err(bad("the rotation quaternion is zero".into()));
        }
        if (norm - 1.0).abs() > 1e-6 {
            warnings.push(format!(
                "image '{image}': quaternion norm {norm:.6}; normalized"
            ));
        }
        let r = *UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .matrix();
        let cam = Camera {
            name,
            width,
            height,
            fx,
            fy,
            cx: cx - 0.5,
            cy: cy - 0.5,
            skew: 0.0,
            dist,
            r,
            t: Vector3::new(num[4], num[5], num[6]),
        };
        cam.validate()
            .map_err(|m| bad(format!("image '{image}': {m}")))?;
        cameras.push(cam);
    }
    if cameras.is_empty() {
        return Err(Error::invalid(&images_path, "lists no image"));
    }
    revalidate(&images_path, cameras, warnings)
}

/// Parses `WxH` (e.g. `1920x1080`).
pub fn parse_size(s: &str) -> std::result::Result<(u32, u32), Refusal> {
    let err = || format!("'{s}' is not an image size; write WIDTHxHEIGHT, e.g. 1920x1080");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(err)?;
    let w: u32 = w.trim().parse().map_err(|_| err())?;
    let h: u32 = h.trim().parse().map_err(|_| err())?;
    if w == 0 || h == 0 {
        return Err(err().into());
    }
    Ok((w, h))
}
