//! Camera videos as frames: a capture may hold one video per camera, `frames/<camera>.<ext>`
//! (any container and codec the system's `ffmpeg` reads), instead of a folder of images.
//!
//! Each video is decoded once by `ffmpeg` (run directly, never through a shell, its raw
//! RGB read from a pipe) into PNG frames under `<cache>/decoded/<camera>/<content>/`, where
//! `<content>` is the BLAKE3 hash of the video file: a re-run, or any stage reading the
//! frames, reads the decoded PNGs without decoding again, and a replaced video is decoded
//! afresh. A decoding writes into a temporary folder that is renamed into place only when
//! every frame is written, so an interrupted decoding leaves nothing that looks complete.

use crate::camera::Camera;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Video file extensions recognised as `frames/<camera>.<ext>`.
pub const VIDEO_EXTENSIONS: [&str; 9] = [
    "mp4", "mkv", "avi", "mov", "webm", "m4v", "mpg", "mpeg", "ts",
];

/// The program that decodes videos, and its prober.
const FFMPEG: &str = "ffmpeg";
const FFPROBE: &str = "ffprobe";

/// What a decoded video holds (`info.yaml` in its decoded folder).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VideoInfo {
    /// Frames decoded.
    pub frames: u32,
    /// Frame size, pixels.
    pub width: u32,
    pub height: u32,
    /// The stream's average frame rate, frames per second, when the container states one.
    pub rate: Option<f64>,
    /// The video's BLAKE3 hash (hex): the decoded folder's name.
    pub content: String,
}

/// A camera's decoded video: where its PNG frames are, and what it held.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    /// The video file.
    pub video: PathBuf,
    /// The folder of its frames, `NNNNNN.png` from 000000.
    pub dir: PathBuf,
    pub info: VideoInfo,
    /// Whether this call decoded it (false: the cache held it).
    pub fresh: bool,
}

/// The camera a video file stands for: its file stem, when its extension is a video's
/// ([`VIDEO_EXTENSIONS`], in any case).
pub fn camera_of(path: &Path) -> Option<String> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    VIDEO_EXTENSIONS
        .contains(&ext.as_str())
        .then(|| path.file_stem()?.to_str().map(str::to_string))
        .flatten()
}

/// The video of `camera` in `frames_dir`, if there is one (`<camera>.<ext>`; the first by
/// name when there are several).
pub fn find(frames_dir: &Path, camera: &str) -> Option<PathBuf> {
    let entries = std::fs::read_dir(frames_dir).ok()?;
    let mut found: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| camera_of(p).as_deref() == Some(camera))
        .collect();
    found.sort();
    found.into_iter().next()
}

/// The error for a machine without ffmpeg.
fn not_installed(video: &Path) -> Error {
    Error::invalid(
        video,
        "decoding camera videos needs ffmpeg, which is not installed (or not on PATH): \
         install it (Debian/Ubuntu: apt install ffmpeg; macOS: brew install ffmpeg), or give \
         the frames as image folders frames/<camera>/NNNNNN.png",
    )
}

/// Runs `program` with `args`, mapping a missing program to [`not_installed`].
fn spawn(program: &str, args: &[&std::ffi::OsStr], video: &Path) -> Result<std::process::Child> {
    Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => not_installed(video),
            _ => Error::io(video, e),
        })
}

/// `video` as ffmpeg's `file:` input: a name holding `:` or starting with `-` is read as
/// the file it names, never as a protocol or an option.
fn file_url(video: &Path) -> std::ffi::OsString {
    let mut s = std::ffi::OsString::from("file:");
    s.push(video.as_os_str());
    s
}

/// ffmpeg's complaint, shortened to its last few lines.
fn complaint(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let tail = &lines[lines.len().saturating_sub(3)..];
    if tail.is_empty() {
        "no message".to_string()
    } else {
        tail.join(" / ")
    }
}

/// The first video stream's size and average frame rate (`ffprobe`).
fn probe(video: &Path) -> Result<(u32, u32, Option<f64>)> {
    let input = file_url(video);
    let args: Vec<&std::ffi::OsStr> = [
        "-v",
        "error",
        "-select_streams",
        "v:0",
        "-show_entries",
        "stream=width,height,avg_frame_rate",
        "-of",
        "csv=p=0",
        "-i",
    ]
    .iter()
    .map(std::ffi::OsStr::new)
    .chain([input.as_os_str()])
    .collect();
    let out = spawn(FFPROBE, &args, video)?
        .wait_with_output()
        .map_err(|e| Error::io(video, e))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let fields: Vec<&str> = text.trim().split(',').map(str::trim).collect();
    let size = match fields.as_slice() {
        [w, h, ..] => w.parse::<u32>().ok().zip(h.parse::<u32>().ok()),
        _ => None,
    };
    let Some((w, h)) = size.filter(|_| out.status.success()) else {
        return Err(Error::invalid(
            video,
            format!(
                "not a video ffmpeg can read (damaged, or no video stream): {}",
                complaint(&out.stderr)
            ),
        ));
    };
    let rate = fields.get(2).and_then(|r| {
        let (n, d) = r.split_once('/')?;
        let (n, d) = (n.parse::<f64>().ok()?, d.parse::<f64>().ok()?);
        (d > 0.0 && n > 0.0).then_some(n / d)
    });
    Ok((w, h, rate))
}

/// The BLAKE3 hash of `video`'s bytes, hex.
fn content_hash(video: &Path) -> Result<String> {
    let file = crate::limits::open_regular(video)?;
    let mut hasher = blake3::Hasher::new();
    hasher
        .update_reader(file)
        .map_err(|e| Error::io(video, e))?;
    Ok(hasher.finalize().to_hex().to_string())
}

/// A spinner counting the frames decoded (on stderr, hidden when that is not a terminal).
pub fn progress() -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg:>12} {pos} frames ({per_sec})")
            .expect("valid template"),
    );
    bar.set_message("decoding");
    bar
}

/// The decoded frames of `video` for camera `cam`, from the cache under `root`
/// (`<cache>/decoded`) or decoded now (counted on `progress`). The video's frame size
/// must be the camera's.
pub fn decoded(
    video: &Path,
    cam: &Camera,
    root: &Path,
    progress: &indicatif::ProgressBar,
) -> Result<Decoded> {
    let content = content_hash(video)?;
    let dir = root.join(&cam.name).join(&content);
    let info_path = dir.join("info.yaml");
    if info_path.is_file() {
        let info: VideoInfo = crate::yaml::read(&info_path)?;
        return Ok(Decoded {
            video: video.to_path_buf(),
            dir,
            info,
            fresh: false,
        });
    }
    let (width, height, rate) = probe(video)?;
    if (width, height) != (cam.width, cam.height) {
        return Err(Error::invalid(
            video,
            format!(
                "the video is {width}x{height} but camera '{}' is calibrated for {}x{}; \
                 this is another camera's video, or the calibration's width/height is wrong",
                cam.name, cam.width, cam.height
            ),
        ));
    }
    crate::limits::check_image(video, width, height)?;
    let parent = root.join(&cam.name);
    crate::fsutil::create_dir_all(&parent)?;
    remove_dead_scratch(&parent);
    // A scratch folder of this process, removed whatever happens unless renamed into place
    // (named as the cache's temporary files: `.<name>.tmp-<host>-<pid>-<n>`).
    let scratch = Scratch(parent.join(format!(
        ".decoding-{content}.tmp-{}-{}-0",
        crate::fsutil::host_name(),
        std::process::id()
    )));
    let _ = std::fs::remove_dir_all(&scratch.0);
    crate::fsutil::create_dir_all(&scratch.0)?;
    let frames = decode_into(video, width, height, &scratch.0, progress)?;
    if frames == 0 {
        return Err(Error::invalid(
            video,
            "ffmpeg decoded no frame from this video",
        ));
    }
    let info = VideoInfo {
        frames,
        width,
        height,
        rate,
        content,
    };
    crate::fsutil::write_atomic(
        &scratch.0.join("info.yaml"),
        crate::yaml::to_string(&info)?.as_bytes(),
    )?;
    if let Err(e) = std::fs::rename(&scratch.0, &dir) {
        // Another process decoded the same video first: its frames are the same.
        if !info_path.is_file() {
            return Err(Error::io(&dir, e));
        }
    }
    Ok(Decoded {
        video: video.to_path_buf(),
        dir,
        info,
        fresh: true,
    })
}

/// Removes the scratch folders that decodings killed on this host left in `dir` (their
/// process is gone).
fn remove_dead_scratch(dir: &Path) {
    let host = crate::fsutil::host_name();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !name.starts_with(".decoding-") || !e.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        if let Some((writer, pid)) = crate::fsutil::temp_writer(&name) {
            if writer == host && !Path::new(&format!("/proc/{pid}")).exists() {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    }
}

/// A folder removed when dropped (a no-op once it was renamed away).
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Decodes every frame of `video` (`width` x `height`) into `dir` as NNNNNN.png; returns
/// how many.
fn decode_into(
    video: &Path,
    width: u32,
    height: u32,
    dir: &Path,
    progress: &indicatif::ProgressBar,
) -> Result<u32> {
    let input = file_url(video);
    let args: Vec<&std::ffi::OsStr> = ["-nostdin", "-v", "error", "-i"]
        .iter()
        .map(std::ffi::OsStr::new)
        .chain([input.as_os_str()])
        .chain(
            [
                "-map", "0:v:0", "-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1",
            ]
            .iter()
            .map(std::ffi::OsStr::new),
        )
        .collect();
    let mut child = spawn(FFMPEG, &args, video)?;
    let mut stdout = child.stdout.take().expect("piped");
    // ffmpeg's messages are read on their own thread so that a full stderr pipe never
    // stalls it.
    let mut stderr = child.stderr.take().expect("piped");
    let errors = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = stderr.read_to_end(&mut buf);
        buf
    });
    let size = width as usize * height as usize * 3;
    let mut buf = vec![0u8; size];
    let mut count = 0u32;
    let outcome = loop {
        match read_full(&mut stdout, &mut buf) {
            Ok(0) => break Ok(()),
            Ok(n) if n < size => {
                break Err(format!(
                    "the stream ended inside frame {count} ({n} of {size} bytes)"
                ))
            }
            Ok(_) => {}
            Err(e) => break Err(e.to_string()),
        }
        let img = image::RgbImage::from_raw(width, height, buf.clone()).expect("sized buffer");
        let path = dir.join(format!("{count:06}.png"));
        if let Err(e) = write_png(&path, &img) {
            let _ = child.kill();
            let _ = child.wait();
            return Err(e);
        }
        count += 1;
        progress.inc(1);
    };
    let status = child.wait().map_err(|e| Error::io(video, e))?;
    let stderr = errors.join().unwrap_or_default();
    match outcome {
        Ok(()) if status.success() => Ok(count),
        Ok(()) => Err(Error::invalid(
            video,
            format!(
                "ffmpeg could not decode the video (damaged?) after {count} frames: {}",
                complaint(&stderr)
            ),
        )),
        Err(m) => Err(Error::invalid(
            video,
            format!("decoding failed: {m}: {}", complaint(&stderr)),
        )),
    }
}

/// Reads until `buf` is full or the stream ends; returns the bytes read.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Writes a decoded frame as a fast-compressed PNG.
fn write_png(path: &Path, img: &image::RgbImage) -> Result<()> {
    use image::ImageEncoder;
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        std::io::BufWriter::new(file),
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    );
    encoder
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| Error::invalid(path, format!("cannot write the decoded frame: {e}")))
}
