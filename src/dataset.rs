//! Capture sequences on disk (`data/<sequence>/`, `shared/dataset-format.md`): discovery of
//! cameras and frames, consistency checks against the calibration, and loading of frames,
//! background plates, masks, the skeleton and ground truth.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::joints::JointRow;
use crate::skeleton::Skeleton;
use image::{GrayImage, RgbImage};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Image file extensions accepted for frames, in order of preference.
const FRAME_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// A capture sequence checked against its calibration.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// The sequence folder `data/<sequence>`.
    pub dir: PathBuf,
    /// The calibration, in the order of cameras.yaml.
    pub cameras: Vec<Camera>,
    /// Frame indices present for every camera, ascending.
    pub frames: Vec<u32>,
    /// Where each camera's frames come from.
    sources: Vec<FrameSource>,
    /// Whether given masks (`masks/`) are present.
    pub has_masks: bool,
    /// Whether the capture has frames (`frames/`); without, it is a masks-only capture: the
    /// masks give the silhouettes, and there is nothing photo-consistency could use.
    pub has_frames: bool,
    /// Whether every camera has a background plate.
    pub has_backgrounds: bool,
    /// Things that are odd but not fatal (extra folders, stray files).
    pub warnings: Vec<String>,
    /// Read as if it had no skeleton.yaml (`pipeline skeleton --force` replacing one).
    pub skeleton_ignored: bool,
    /// Cameras whose video frames are not decoded yet (opened without decoding).
    pub undecoded: Vec<String>,
    /// The key of the background plates learned from the frames
    /// ([`crate::artifacts::learned_background`]), once learned (`silhouette.method:
    /// learned`).
    pub learned_plates: Option<String>,
}

/// Where a camera's frames come from.
#[derive(Debug, Clone)]
pub enum FrameSource {
    /// A folder of images `frames/<camera>/NNNNNN.<ext>` (png, jpg or jpeg).
    Folder(&'static str),
    /// A video `frames/<camera>.<ext>`, decoded into the cache; the capture's frame f is
    /// the video's frame f + `offset` (`sync.offsets`).
    Video {
        decoded: crate::video::Decoded,
        offset: i64,
    },
}

/// How a capture's camera videos are read: where their decoded frames are cached, and
/// each camera's frame offset (pipeline.yaml keys `cache` and `sync.offsets`).
#[derive(Debug, Clone)]
pub struct VideoOptions {
    /// `<cache>/decoded`.
    pub decoded_root: PathBuf,
    pub offsets: std::collections::BTreeMap<String, i64>,
    /// The pipeline file, named in messages about `sync.offsets`.
    pub config_path: PathBuf,
    /// The capture frames a run reads, `first..=last` (its selected frames, pipeline.yaml's
    /// and the skeleton's reference frame): only these are decoded, and a camera may lack
    /// frames outside them. `None`: every frame.
    pub window: Option<(u32, u32)>,
    /// Whether frames missing from the cache are decoded now (false for read-only
    /// commands: [`Sequence::undecoded`] names the cameras left undecoded).
    pub decode: bool,
}

/// The video frames to decode for the capture frames `window` (`None`: all) of a camera
/// whose capture frame f is its video frame f + `offset`, in a video of `frames` frames.
fn video_window(
    window: Option<(u32, u32)>,
    offset: i64,
    frames: u32,
) -> std::ops::RangeInclusive<u32> {
    let (lo, hi) = match window {
        Some((a, b)) => (a as i64 + offset, b as i64 + offset),
        None => (offset, i64::MAX),
    };
    let (lo, hi) = (lo.max(0), hi.min(frames as i64 - 1));
    if hi < lo {
        #[allow(clippy::reversed_empty_ranges)]
        return 1..=0;
    }
    lo as u32..=hi as u32
}

/// The name of frame `index`'s files: the zero-padded six-digit index.
pub fn frame_stem(index: u32) -> String {
    format!("{index:06}")
}

/// An image reader on the regular file at `path` ([`crate::limits::open_regular`]).
fn open_image(path: &Path) -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
    let file = crate::limits::open_regular(path)?;
    Ok(image::ImageReader::new(std::io::BufReader::new(file)))
}

/// Reads an image's dimensions from its header without decoding it.
pub fn image_dimensions(path: &Path) -> Result<(u32, u32)> {
    open_image(path)?
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?
        .into_dimensions()
        .map_err(|e| {
            Error::invalid(
                path,
                format!("cannot read the image (damaged, or not a PNG/JPEG): {e}"),
            )
        })
}

/// Decodes an image after checking its header: the dimensions must be `expected` (the
/// camera's calibration, when given) and within the image cap ([`crate::limits`]), so a
/// header claiming a huge image is refused before anything is allocated for it.
pub fn decode(path: &Path, expected: Option<&Camera>) -> Result<image::DynamicImage> {
    let open = || -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
        open_image(path)?
            .with_guessed_format()
            .map_err(|e| Error::io(path, e))
    };
    let (w, h) = image_dimensions(path)?;
    if let Some(cam) = expected {
        check_size(path, cam, w, h)?;
    }
    crate::limits::check_image(path, w, h)?;
    let mut reader = open()?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    limits.max_alloc = Some(crate::limits::image_alloc_bytes()?);
    reader.limits(limits);
    reader
        .decode()
        .map_err(|e| Error::invalid(path, format!("cannot decode the image: {e}")))
}

fn check_size(path: &Path, cam: &Camera, w: u32, h: u32) -> Result<()> {
    if (w, h) != (cam.width, cam.height) {
        return Err(Error::invalid(
            path,
            format!(
                "image is {w}x{h} but camera '{}' is calibrated for {}x{}; \
                 resize the images or fix width/height in the calibration{}",
                cam.name,
                cam.width,
                cam.height,
                crate::camera::crop_hint(cam, (w, h))
            ),
        ));
    }
    Ok(())
}

/// Frame indices found in `dir` (files named NNNNNN.<ext>), with their extension; other
/// files are reported in `warnings`.
fn list_frames(dir: &Path, warnings: &mut Vec<String>) -> Result<Vec<(u32, &'static str)>> {
    let mut found = Vec::new();
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue; // hidden files, e.g. temporary files of an interrupted writer
        }
        let parsed = path.extension().and_then(|e| e.to_str()).and_then(|ext| {
            let ext = ext.to_ascii_lowercase();
            let known = FRAME_EXTENSIONS.iter().find(|&&k| k == ext)?;
            let stem = path.file_stem()?.to_str()?;
            (stem.len() == 6 && stem.bytes().all(|b| b.is_ascii_digit()))
                .then(|| (stem.parse().ok(), *known))
        });
        match parsed {
            Some((Some(i), ext)) => found.push((i, ext)),
            _ => warnings.push(format!(
                "{}: not a frame file (NNNNNN.png), ignored",
                crate::text::shown_path(&path)
            )),
        }
    }
    found.sort();
    Ok(found)
}

impl Sequence {
    /// The index of the camera named `name` in the sequence's calibration (read from
    /// `calibration`, named in the error).
    pub fn camera_index(&self, calibration: &Path, name: &str) -> Result<usize> {
        self.cameras
            .iter()
            .position(|c| c.name == name)
            .ok_or_else(|| {
                Error::Usage(format!(
                    "no camera named '{name}' in {}",
                    calibration.display()
                ))
            })
    }

    /// Opens the sequence in `dir` for the cameras of `cameras`; `calib_path` names the
    /// calibration in messages. Checks that every calibrated camera has a frame folder
    /// holding every frame, that image sizes match the calibration (from the headers), and
    /// the same for masks when present.
    pub fn open(
        dir: &Path,
        cameras: Vec<Camera>,
        calib_path: &Path,
        videos: Option<&VideoOptions>,
    ) -> Result<Sequence> {
        let masks_dir = dir.join("masks");
        let has_masks = masks_dir.is_dir();
        let has_frames = dir.join("frames").is_dir();
        if let Some(v) = videos {
            for name in v.offsets.keys() {
                if !cameras.iter().any(|c| &c.name == name) {
                    return Err(Error::invalid(
                        &v.config_path,
                        format!(
                            "key 'sync.offsets': no camera of {} is named '{name}'",
                            calib_path.display()
                        ),
                    ));
                }
            }
        }
        // A masks-only capture lists its frames from the masks.
        let frames_dir = if has_frames || !has_masks {
            dir.join("frames")
        } else {
            masks_dir.clone()
        };
        if !frames_dir.is_dir() {
            return Err(Error::invalid(
                dir,
                "the sequence has neither a frames/ folder (frames/<camera>/NNNNNN.png) nor a \
                 masks/ folder (masks/<camera>/NNNNNN.png, for a capture of silhouettes only)",
            ));
        }
        let mut warnings = Vec::new();
        // Folders that no calibrated camera claims.
        let mut folders: BTreeSet<String> = BTreeSet::new();
        for entry in std::fs::read_dir(&frames_dir).map_err(|e| Error::io(&frames_dir, e))? {
            let entry = entry.map_err(|e| Error::io(&frames_dir, e))?;
            let path = entry.path();
            if path.is_dir() {
                folders.insert(entry.file_name().to_string_lossy().into_owned());
            } else if let Some(camera) = crate::video::camera_of(&path).filter(|_| has_frames) {
                folders.insert(camera);
            }
        }
        for name in &folders {
            if !cameras.iter().any(|c| &c.name == name) {
                warnings.push(format!(
                    "{}: no camera of {} has this name; folder ignored",
                    frames_dir.join(name).display(),
                    calib_path.display()
                ));
            }
        }
        let mut per_camera = Vec::with_capacity(cameras.len());
        let mut decoded: Vec<Option<(crate::video::Decoded, i64)>> = vec![None; cameras.len()];
        // Cameras recorded as videos (a camera's frame folder wins over its video), decoded
        // (or found decoded) in parallel below.
        let mut video_cams: Vec<(usize, PathBuf)> = Vec::new();
        for (i, cam) in cameras.iter().enumerate().filter(|_| has_frames) {
            let Some(video) = crate::video::find(&frames_dir, &cam.name)? else {
                continue;
            };
            let folder = frames_dir.join(&cam.name);
            if folder.is_dir() {
                warnings.push(format!(
                    "{}: ignored, camera '{}' has a frame folder {}",
                    video.display(),
                    cam.name,
                    folder.display()
                ));
            } else {
                video_cams.push((i, video));
            }
        }
        if !video_cams.is_empty() {
            let Some(v) = videos else {
                return Err(Error::invalid(
                    &video_cams[0].1,
                    "camera videos are decoded into the pipeline's cache: open this capture \
                     through a pipeline.yaml",
                ));
            };
            use rayon::prelude::*;
            // Every video is probed (and refused by name) before any is decoded.
            let probes = crate::video::probe_all(&video_cams, &cameras)?;
            for ((i, path), probe) in video_cams.iter().zip(&probes) {
                if probe.rotation != 0.0 {
                    warnings.push(format!(
                        "{}: the video asks players to turn it by {} degrees; camera {}'s \
                         frames are used as stored ({}x{}, as calibrated), not turned",
                        crate::text::shown_path(path),
                        probe.rotation,
                        crate::text::quoted(&cameras[*i].name),
                        probe.width,
                        probe.height
                    ));
                }
            }
            let progress = crate::video::progress();
            let done: Vec<Result<(usize, crate::video::Decoded)>> = video_cams
                .par_iter()
                .zip(probes)
                .map(|((i, path), probe)| {
                    let offset = v.offsets.get(&cameras[*i].name).copied().unwrap_or(0);
                    let window = video_window(v.window, offset, probe.frames);
                    crate::video::decoded(
                        path,
                        probe,
                        &cameras[*i],
                        &v.decoded_root,
                        window,
                        v.decode,
                        &progress,
                    )
                    .map(|d| (*i, d))
                })
                .collect();
            progress.finish_and_clear();
            for r in done {
                let (i, d) = r?;
                let offset = v.offsets.get(&cameras[i].name).copied().unwrap_or(0);
                decoded[i] = Some((d, offset));
            }
        }
        let window = videos
            .and_then(|v| v.window)
            .filter(|_| !video_cams.is_empty());
        let mut undecoded = Vec::new();
        if let Some(v) = videos {
            for (name, _) in v.offsets.iter().filter(|(_, &o)| o != 0) {
                let i = cameras
                    .iter()
                    .position(|c| &c.name == name)
                    .expect("checked");
                if decoded[i].is_none() {
                    return Err(Error::invalid(
                        &v.config_path,
                        format!(
                            "key 'sync.offsets': camera '{name}' is not recorded as a video \
                             (frames/{name}.<ext>); offsets apply to videos only"
                        ),
                    ));
                }
            }
        }
        for (ci, cam) in cameras.iter().enumerate() {
            if let Some((d, offset)) = &decoded[ci] {
                // The capture's frames f with 0 <= f + offset < the video's frame count.
                let first = (-offset).max(0);
                let end = d.probe.frames as i64 - offset;
                let list: Vec<(u32, &'static str)> = (first..end.max(first))
                    .filter_map(|f| u32::try_from(f).ok().map(|f| (f, "png")))
                    .filter(|&(f, _)| window.is_none_or(|(a, b)| (a..=b).contains(&f)))
                    .collect();
                let held = |&(f, _): &(u32, &str)| {
                    let v = u32::try_from(f as i64 + offset).unwrap_or(u32::MAX);
                    d.decoded.contains(&v)
                };
                if !list.iter().all(held) {
                    undecoded.push(cam.name.clone());
                }
                per_camera.push(list);
                continue;
            }
            let cam_dir = frames_dir.join(&cam.name);
            if !cam_dir.is_dir() {
                return Err(Error::invalid(
                    &cam_dir,
                    format!(
                        "missing frame folder for camera '{}' of {}; every calibrated camera needs frames/<camera>/",
                        cam.name,
                        calib_path.display()
                    ),
                ));
            }
            let mut list = list_frames(&cam_dir, &mut warnings)?;
            list.retain(|&(f, _)| window.is_none_or(|(a, b)| (a..=b).contains(&f)));
            per_camera.push(list);
        }
        let all: BTreeSet<u32> = per_camera.iter().flatten().map(|&(i, _)| i).collect();
        if all.is_empty() {
            return Err(Error::invalid(
                &frames_dir,
                "no frame files (NNNNNN.png) found",
            ));
        }
        let mut sources = Vec::with_capacity(cameras.len());
        for ((cam, list), dec) in cameras.iter().zip(&per_camera).zip(&decoded) {
            let have: BTreeSet<u32> = list.iter().map(|&(i, _)| i).collect();
            if let Some(&missing) = all.difference(&have).next() {
                if let Some((d, offset)) = dec {
                    let frames = |set: &BTreeSet<u32>| {
                        format!(
                            "{}..{}",
                            set.first().unwrap_or(&0),
                            set.last().unwrap_or(&0)
                        )
                    };
                    return Err(Error::invalid(
                        &d.video,
                        format!(
                            "camera {}: the video holds {} frames (capture frames {}, with \
                             offset {offset}) but other cameras have frames {}: frame \
                             {missing} is missing. A camera that started late or stopped \
                             early needs sync.offsets in pipeline.yaml, or trim the other \
                             videos",
                            crate::text::quoted(&cam.name),
                            d.probe.frames,
                            if have.is_empty() {
                                "none".to_string()
                            } else {
                                frames(&have)
                            },
                            frames(&all)
                        ),
                    ));
                }
                return Err(Error::invalid(
                    frames_dir.join(&cam.name).join(format!("{}.png", frame_stem(missing))),
                    format!(
                        "camera '{}' lacks frame {missing}, which other cameras have; every camera needs every frame",
                        cam.name
                    ),
                ));
            }
            sources.push(match dec {
                Some((d, offset)) => FrameSource::Video {
                    decoded: d.clone(),
                    offset: *offset,
                },
                None => FrameSource::Folder(list.first().map(|&(_, e)| e).unwrap_or("png")),
            });
        }
        let bg_dir = dir.join("background");
        let has_backgrounds = bg_dir.is_dir()
            && cameras
                .iter()
                .all(|c| bg_dir.join(format!("{}.png", c.name)).is_file());
        if bg_dir.is_dir() && !has_backgrounds {
            let odd: Vec<String> = cameras
                .iter()
                .map(|c| bg_dir.join(format!("{}.png", c.name)))
                .filter(|p| std::fs::symlink_metadata(p).is_ok() && !p.is_file())
                .map(|p| p.display().to_string())
                .collect();
            warnings.push(if odd.is_empty() {
                format!(
                    "{}: not every camera has a background plate <camera>.png; background subtraction is unavailable",
                    bg_dir.display()
                )
            } else {
                format!(
                    "{}: not a regular file (a device, FIFO, folder or broken link); background subtraction is unavailable",
                    odd.join(", ")
                )
            });
        }
        let seq = Sequence {
            dir: dir.to_path_buf(),
            cameras,
            frames: all.into_iter().collect(),
            sources,
            has_masks,
            has_frames,
            has_backgrounds,
            warnings,
            skeleton_ignored: false,
            undecoded,
            learned_plates: None,
        };
        seq.check_image_sizes()?;
        Ok(seq)
    }

    /// Opens the sequence `dir` with the calibration file `calib_path` (a capture of
    /// image folders; camera videos need [`Sequence::open_with_videos`]).
    pub fn open_with_calibration(calib_path: &Path, dir: &Path) -> Result<Sequence> {
        Self::open_calibrated(calib_path, dir, None)
    }

    /// Opens the sequence `dir` with the calibration file `calib_path`, decoding camera
    /// videos as `videos` says ([`crate::video`]).
    pub fn open_with_videos(
        calib_path: &Path,
        dir: &Path,
        videos: &VideoOptions,
    ) -> Result<Sequence> {
        Self::open_calibrated(calib_path, dir, Some(videos))
    }

    fn open_calibrated(
        calib_path: &Path,
        dir: &Path,
        videos: Option<&VideoOptions>,
    ) -> Result<Sequence> {
        let calib = crate::camera::read_cameras(calib_path)?;
        let mut seq = Sequence::open(dir, calib.cameras, calib_path, videos)?;
        seq.warnings.splice(0..0, calib.warnings);
        Ok(seq)
    }

    /// Checks every frame's, mask's and plate's header against the calibration.
    fn check_image_sizes(&self) -> Result<()> {
        use rayon::prelude::*;
        // Every camera whose first frame's size is not its calibration's, named at once
        // (a calibration made at another resolution usually differs for all of them).
        if let (true, Some(&first)) = (self.has_frames, self.frames.first()) {
            let mut wrong = Vec::new();
            let mut wrong_sizes = Vec::new();
            for (c, cam) in self.cameras.iter().enumerate() {
                if self.undecoded.contains(&cam.name) {
                    continue;
                }
                let path = self.frame_path(c, first);
                if let Ok((w, h)) = image_dimensions(&path) {
                    if (w, h) != (cam.width, cam.height) {
                        wrong_sizes.push((c, (w, h)));
                        wrong.push(format!(
                            "{} ({w}x{h}, calibrated {}x{})",
                            crate::text::quoted(&cam.name),
                            cam.width,
                            cam.height
                        ));
                    }
                }
            }
            if wrong.len() > 1 {
                return Err(Error::invalid(
                    self.dir.join("frames"),
                    format!(
                        "{} cameras' images are not the size their calibration states: {}; \
                         resize the images, or fix width/height (and K) in the calibration{}",
                        wrong.len(),
                        wrong.join(", "),
                        crate::camera::crop_hint(&self.cameras[wrong_sizes[0].0], wrong_sizes[0].1)
                    ),
                ));
            }
        }
        let mut jobs: Vec<(usize, PathBuf)> = Vec::new();
        for (c, cam) in self.cameras.iter().enumerate() {
            let undecoded = self.undecoded.contains(&cam.name);
            for &f in &self.frames {
                if self.has_frames && !undecoded {
                    jobs.push((c, self.frame_path(c, f)));
                }
                if self.has_masks {
                    jobs.push((c, self.mask_path(c, f)));
                }
            }
            if self.has_backgrounds {
                jobs.push((c, self.background_path(c)));
            }
            let _ = cam;
        }
        jobs.par_iter().try_for_each(|(c, path)| {
            // A path that exists but is not a regular file is refused by the reading below.
            if !path.exists() {
                return Err(Error::invalid(
                    path,
                    format!(
                        "missing file for camera '{}'; every camera needs every frame (and every frame's mask when masks/ exists)",
                        self.cameras[*c].name
                    ),
                ));
            }
            let (w, h) = image_dimensions(path)?;
            check_size(path, &self.cameras[*c], w, h)
        })
    }

    /// The sequence name (its folder name).
    pub fn name(&self) -> String {
        // The folder's own name (outputs are named after it): a plain file name, or
        // `sequence` when the path ends in `..` or has no usable name.
        self.dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .filter(|n| crate::camera::check_name(n).is_ok())
            .unwrap_or_else(|| "sequence".into())
    }

    /// This capture without camera `name` (its frames, masks and plates left out): for
    /// scoring reconstructions in a view they never saw.
    pub fn without_camera(&self, name: &str) -> Result<Sequence> {
        let Some(c) = self.cameras.iter().position(|cam| cam.name == name) else {
            return Err(Error::Usage(format!(
                "camera {} is not in the calibration (cameras: {})",
                crate::text::quoted(name),
                self.cameras
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        };
        let mut out = self.clone();
        out.cameras.remove(c);
        out.sources.remove(c);
        out.undecoded.retain(|u| u != name);
        Ok(out)
    }

    /// The frame a tracked frame `f` starts from: its neighbour nearer to t0 (none for t0
    /// or a frame outside the sequence).
    pub fn tracked_previous(&self, f: u32, t0: u32) -> Option<u32> {
        let i = self.frames.iter().position(|&x| x == f)?;
        match f.cmp(&t0) {
            std::cmp::Ordering::Equal => None,
            std::cmp::Ordering::Greater => i.checked_sub(1).map(|j| self.frames[j]),
            std::cmp::Ordering::Less => self.frames.get(i + 1).copied(),
        }
    }

    /// Path of camera `cam`'s frame `frame` (for a video, its decoded PNG in the cache).
    pub fn frame_path(&self, cam: usize, frame: u32) -> PathBuf {
        match &self.sources[cam] {
            FrameSource::Folder(ext) => self
                .dir
                .join("frames")
                .join(&self.cameras[cam].name)
                .join(format!("{}.{ext}", frame_stem(frame))),
            FrameSource::Video { decoded, offset } => {
                let index = u32::try_from(frame as i64 + offset).unwrap_or(u32::MAX);
                decoded.dir.join(format!("{}.png", frame_stem(index)))
            }
        }
    }

    /// One line per camera recorded as a video: its file, frames, size against the
    /// calibration, rate, offset, and whether it was decoded now or found decoded.
    pub fn video_report(&self) -> Vec<String> {
        self.sources
            .iter()
            .zip(&self.cameras)
            .filter_map(|(s, cam)| match s {
                FrameSource::Folder(_) => None,
                FrameSource::Video { decoded, offset } => Some(format!(
                    "{}: {} holds {} frames, {}x{} (calibrated {}x{}), {}, offset {offset}; {}",
                    crate::text::escape_controls(&cam.name),
                    crate::text::shown_path(&decoded.video),
                    decoded.probe.frames,
                    decoded.probe.width,
                    decoded.probe.height,
                    cam.width,
                    cam.height,
                    decoded
                        .probe
                        .rate
                        .map_or("rate not stated".to_string(), |r| format!("{r:.3} fps")),
                    if decoded.decoded.is_empty() {
                        "not decoded yet (decoded by `pipeline run`)".to_string()
                    } else {
                        format!(
                            "video frames {}..{} {} {}",
                            decoded.decoded.start,
                            decoded.decoded.end - 1,
                            if decoded.fresh {
                                "decoded into"
                            } else {
                                "decoded earlier, reused from"
                            },
                            crate::text::shown_path(&decoded.dir)
                        )
                    }
                )),
            })
            .collect()
    }

    /// The cameras whose video ends before capture frame `last`, each with the video and
    /// its last capture frame (for a frame range past the end).
    pub fn videos_ending_before(&self, last: u32) -> Vec<String> {
        self.sources
            .iter()
            .zip(&self.cameras)
            .filter_map(|(s, cam)| match s {
                FrameSource::Video { decoded, offset } => {
                    let end = decoded.probe.frames as i64 - 1 - offset;
                    (end < last as i64).then(|| {
                        format!(
                            "camera {}: {} ends at capture frame {end}",
                            crate::text::quoted(&cam.name),
                            crate::text::shown_path(&decoded.video)
                        )
                    })
                }
                FrameSource::Folder(_) => None,
            })
            .collect()
    }

    /// Path of camera `cam`'s given mask of frame `frame`.
    pub fn mask_path(&self, cam: usize, frame: u32) -> PathBuf {
        self.dir
            .join("masks")
            .join(&self.cameras[cam].name)
            .join(format!("{}.png", frame_stem(frame)))
    }

    /// Path of camera `cam`'s background plate.
    pub fn background_path(&self, cam: usize) -> PathBuf {
        self.dir
            .join("background")
            .join(format!("{}.png", self.cameras[cam].name))
    }

    fn load_rgb(&self, cam: usize, path: &Path) -> Result<RgbImage> {
        let img = decode(path, Some(&self.cameras[cam]))?.into_rgb8();
        Ok(img)
    }

    /// Loads camera `cam`'s frame `frame` as 8-bit RGB. A masks-only capture has no frames:
    /// its mask stands in (white silhouette on black), for overlays and pictures.
    pub fn load_frame(&self, cam: usize, frame: u32) -> Result<RgbImage> {
        if !self.has_frames {
            let mask = self.load_mask(cam, frame)?.ok_or_else(|| {
                Error::invalid(
                    self.mask_path(cam, frame),
                    "missing: a capture without frames/ needs a mask for every camera and frame",
                )
            })?;
            return Ok(image::DynamicImage::ImageLuma8(mask).into_rgb8());
        }
        self.load_rgb(cam, &self.frame_path(cam, frame))
    }

    /// Loads camera `cam`'s background plate, if the sequence has plates.
    pub fn load_background(&self, cam: usize) -> Result<Option<RgbImage>> {
        if !self.has_backgrounds {
            return Ok(None);
        }
        self.load_rgb(cam, &self.background_path(cam)).map(Some)
    }

    /// Loads camera `cam`'s given mask of frame `frame` as 0/255 (>= 128 is foreground), if
    /// the sequence has masks.
    pub fn load_mask(&self, cam: usize, frame: u32) -> Result<Option<GrayImage>> {
        if !self.has_masks {
            return Ok(None);
        }
        let path = self.mask_path(cam, frame);
        Ok(Some(binary_mask(&decode(&path, Some(&self.cameras[cam]))?)))
    }

    /// The skeleton (`skeleton.yaml`), if present.
    pub fn skeleton(&self) -> Result<Option<Skeleton>> {
        let path = self.dir.join("skeleton.yaml");
        if self.skeleton_ignored || std::fs::symlink_metadata(&path).is_err() {
            return Ok(None);
        }
        Skeleton::read(&path).map(Some)
    }

    /// Ground-truth joints (`ground_truth/joints.csv`), if present.
    pub fn ground_truth_joints(&self) -> Result<Option<Vec<JointRow>>> {
        let path = self.dir.join("ground_truth").join("joints.csv");
        if !path.exists() {
            return Ok(None);
        }
        crate::joints::read(&path).map(Some)
    }

    /// Path of the ground-truth mesh of frame `frame`.
    pub fn ground_truth_mesh_path(&self, frame: u32) -> PathBuf {
        self.dir
            .join("ground_truth")
            .join("meshes")
            .join(format!("{}.ply", frame_stem(frame)))
    }

    /// The ground-truth surface of frame `frame`, if present.
    pub fn ground_truth_mesh(&self, frame: u32) -> Result<Option<TriMesh>> {
        let path = self.ground_truth_mesh_path(frame);
        if !path.exists() {
            return Ok(None);
        }
        crate::geometry::ply::read_ply(&path).map(Some)
    }
}

/// A mask image as the pipeline's binary silhouette (255 subject, 0 background):
/// - an image with an alpha channel that is not opaque everywhere holds its silhouette in
///   the alpha (cut-outs saved as RGBA, whose colour channels are the photograph or white);
/// - otherwise its grey level, 128 and above being the subject, or any non-zero value when
///   the image holds only the values 0 and 1 (label images written as 0/1).
pub fn binary_mask(img: &image::DynamicImage) -> image::GrayImage {
    let (w, h) = (img.width(), img.height());
    let level: image::GrayImage = if img.color().has_alpha() {
        let rgba = img.to_rgba8();
        if rgba.pixels().any(|p| p.0[3] != 255) {
            image::GrayImage::from_fn(w, h, |x, y| image::Luma([rgba.get_pixel(x, y).0[3]]))
        } else {
            img.to_luma8()
        }
    } else {
        img.to_luma8()
    };
    let zero_one = level.pixels().all(|p| p.0[0] <= 1);
    let threshold = if zero_one { 1 } else { 128 };
    let mut out = level;
    for p in out.pixels_mut() {
        p.0[0] = if p.0[0] >= threshold { 255 } else { 0 };
    }
    out
}
