//! Camera videos as frames: a capture may hold one video per camera, `frames/<camera>.<ext>`
//! (any container and codec the system's `ffmpeg` reads), instead of a folder of images.
//!
//! A video is first probed (`ffprobe`: size, rate, display rotation, container, and the
//! frames it holds, counted from its packets without decoding). Only the frames a run
//! selects are decoded, by `ffmpeg` run directly (never through a shell), as PPM images
//! read from a pipe (each frame's header states its size, which is checked against the
//! probe), into PNG frames under `<cache>/decoded/<camera>/<content>/<first>-<last>/`, where
//! `<content>` is the BLAKE3 hash of the video file and `<first>-<last>` the video frames
//! decoded. `info.yaml` there lists every frame's size and hash: a re-run reads the decoded
//! PNGs after checking them against it, and decodes again when one is missing or changed.
//! A decoding writes into a temporary folder that is renamed into place only when every
//! frame is written, so an interrupted or refused decoding leaves nothing behind.
//!
//! Refused by name: a container that reads other files (playlists, concat lists), a stream
//! whose decoded frames are not the probed size, any error ffmpeg reports while decoding
//! (damage it would conceal), a decoding that would not fit the cap or the free disk, two
//! videos for one camera.

use crate::camera::Camera;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;

/// Video file extensions recognised as `frames/<camera>.<ext>`.
pub const VIDEO_EXTENSIONS: [&str; 9] = [
    "mp4", "mkv", "avi", "mov", "webm", "m4v", "mpg", "mpeg", "ts",
];

/// The program that decodes videos, and its prober.
const FFMPEG: &str = "ffmpeg";
const FFPROBE: &str = "ffprobe";

/// Containers (ffprobe's format names) that read other files or streams than the one
/// given: playlists, concat lists, image sequences, session descriptions. Refused.
const INDIRECT_FORMATS: [&str; 12] = [
    "hls",
    "applehttp",
    "concat",
    "dash",
    "webm_dash_manifest",
    "image2",
    "sdp",
    "rtp",
    "rtsp",
    "tee",
    "lavfi",
    "ffmetadata",
];

/// What probing a video found, without decoding it.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Frame size as stored, pixels (before any display rotation).
    pub width: u32,
    pub height: u32,
    /// The stream's average frame rate, frames per second, when the container states one.
    pub rate: Option<f64>,
    /// Frames the stream holds (its packets, counted by demuxing).
    pub frames: u32,
    /// The display rotation the file asks players for, degrees (0: none). Frames are
    /// decoded as stored, without it.
    pub rotation: f64,
    /// What ffprobe reported while reading the file, when it reported anything: damage.
    pub damage: Option<String>,
}

/// One decoded frame file as written: its size in bytes and BLAKE3 hash (hex).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameRecord {
    pub bytes: u64,
    pub blake3: String,
}

/// What a decoded folder holds (`info.yaml` in it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VideoInfo {
    /// The first video frame decoded (its file is `NNNNNN.png` with this index).
    pub first: u32,
    /// Frames decoded, from `first` on.
    pub frames: u32,
    /// Frame size, pixels.
    pub width: u32,
    pub height: u32,
    /// The stream's average frame rate, frames per second, when the container states one.
    pub rate: Option<f64>,
    /// The video's BLAKE3 hash (hex): the decoded folder's parent's name.
    pub content: String,
    /// Each decoded frame's file, in order from `first`.
    pub files: Vec<FrameRecord>,
}

/// A camera's video: what it holds, and where its decoded frames are.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    /// The video file.
    pub video: PathBuf,
    /// What probing found (`probe.frames` is what the video holds).
    pub probe: Probe,
    /// The folder of its decoded frames, `NNNNNN.png` named by video frame index.
    pub dir: PathBuf,
    /// The video frames decoded there, `first..=last` (empty when nothing is decoded).
    pub decoded: std::ops::Range<u32>,
    /// Whether this call decoded it (false: the cache held it, or nothing was decoded).
    pub fresh: bool,
}

impl Decoded {
    /// Whether the frames `window` (video frame indices) are decoded.
    pub fn holds(&self, window: &std::ops::RangeInclusive<u32>) -> bool {
        window.is_empty()
            || (self.decoded.start <= *window.start() && *window.end() < self.decoded.end)
    }
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

/// The video of `camera` in `frames_dir`, if there is one (`<camera>.<ext>`); two videos
/// for one camera are refused, naming both.
pub fn find(frames_dir: &Path, camera: &str) -> Result<Option<PathBuf>> {
    let Ok(entries) = std::fs::read_dir(frames_dir) else {
        return Ok(None);
    };
    let mut found: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| camera_of(p).as_deref() == Some(camera))
        .collect();
    found.sort();
    if found.len() > 1 {
        let names: Vec<String> = found.iter().map(|p| crate::text::quoted_path(p)).collect();
        return Err(Error::invalid(
            frames_dir,
            format!(
                "camera {} has {} videos ({}); keep one of them (move the others out of frames/)",
                crate::text::quoted(camera),
                found.len(),
                names.join(", ")
            ),
        ));
    }
    Ok(found.pop())
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

/// ffmpeg's complaint, shortened to its last few lines (control characters escaped).
fn complaint(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let tail = &lines[lines.len().saturating_sub(3)..];
    if tail.is_empty() {
        "no message".to_string()
    } else {
        crate::text::escape_controls(&tail.join(" / "))
    }
}

/// The options every ffprobe and ffmpeg run puts before its input: only local files are
/// read (no network protocol, whatever a playlist inside says).
const INPUT_GUARD: [&str; 2] = ["-protocol_whitelist", "file"];

/// Probes `video`'s first video stream (`ffprobe`, demuxing only): size, rate, rotation,
/// frames held, and the container, which must be a plain media file.
pub fn probe(video: &Path) -> Result<Probe> {
    let input = file_url(video);
    let args: Vec<&std::ffi::OsStr> = [
        "-v",
        "error",
        "-count_packets",
        "-select_streams",
        "v:0",
        "-show_entries",
        "stream=width,height,avg_frame_rate,nb_read_packets:stream_side_data=rotation:format=format_name",
        "-of",
        "json",
    ]
    .iter()
    .chain(&INPUT_GUARD)
    .chain(&["-i"])
    .map(std::ffi::OsStr::new)
    .chain([input.as_os_str()])
    .collect();
    let out = spawn(FFPROBE, &args, video)?
        .wait_with_output()
        .map_err(|e| Error::io(video, e))?;
    let unreadable = |why: String| {
        Error::invalid(
            video,
            format!("not a video ffmpeg can read (damaged, or no video stream): {why}"),
        )
    };
    if !out.status.success() {
        return Err(unreadable(complaint(&out.stderr)));
    }
    // ffprobe succeeded but reported errors while reading every packet (and decoding the
    // first frames): the file is damaged or cut short ("File ended prematurely"). Kept for
    // the decoding, which names the frame where it can.
    let damage = (!out.stderr.trim_ascii().is_empty()).then(|| complaint(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| unreadable(format!("ffprobe's answer is not JSON: {e}")))?;
    let format = json["format"]["format_name"].as_str().unwrap_or("");
    if let Some(bad) = format
        .split(',')
        .find(|f| INDIRECT_FORMATS.contains(&f.trim()))
    {
        return Err(Error::invalid(
            video,
            format!(
                "is a '{bad}' file (a playlist or list that makes ffmpeg read other files), \
                 not a video; give the video file itself"
            ),
        ));
    }
    let stream = &json["streams"][0];
    let number = |key: &str| -> Option<u64> {
        let v = &stream[key];
        v.as_u64().or_else(|| v.as_str()?.trim().parse().ok())
    };
    let (Some(width), Some(height)) = (number("width"), number("height")) else {
        return Err(unreadable(complaint(&out.stderr)));
    };
    let (width, height) = (
        u32::try_from(width).unwrap_or(u32::MAX),
        u32::try_from(height).unwrap_or(u32::MAX),
    );
    let frames = number("nb_read_packets")
        .map(|n| u32::try_from(n).unwrap_or(u32::MAX))
        .unwrap_or(0);
    let rate = stream["avg_frame_rate"].as_str().and_then(|r| {
        let (n, d) = r.split_once('/')?;
        let (n, d) = (n.parse::<f64>().ok()?, d.parse::<f64>().ok()?);
        (d > 0.0 && n > 0.0).then_some(n / d)
    });
    let rotation = stream["side_data_list"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|s| s["rotation"].as_f64())
        .find(|r| *r != 0.0)
        .unwrap_or(0.0);
    Ok(Probe {
        width,
        height,
        rate,
        frames,
        rotation,
        damage,
    })
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

/// The probes of `videos`, one per camera of `cameras` (in parallel), each video's stored
/// frame size checked against its camera's: every camera whose video has another size is
/// named at once.
pub fn probe_all(videos: &[(usize, PathBuf)], cameras: &[Camera]) -> Result<Vec<Probe>> {
    use rayon::prelude::*;
    let probes: Vec<Probe> = videos
        .par_iter()
        .map(|(_, path)| probe(path))
        .collect::<Result<_>>()?;
    let wrong: Vec<(&(usize, PathBuf), &Probe)> = videos
        .iter()
        .zip(&probes)
        .filter(|((i, _), p)| (p.width, p.height) != (cameras[*i].width, cameras[*i].height))
        .collect();
    if let Some(&((i, path), p)) = wrong.first() {
        let named: Vec<String> = wrong
            .iter()
            .map(|((i, path), p)| {
                format!(
                    "{} is {}x{} but camera {} is calibrated for {}x{}",
                    crate::text::shown_path(path),
                    p.width,
                    p.height,
                    crate::text::quoted(&cameras[*i].name),
                    cameras[*i].width,
                    cameras[*i].height
                )
            })
            .collect();
        return Err(Error::invalid(
            path,
            format!(
                "{} video(s) are not the size their camera is calibrated for: {}; these are \
                 other cameras' videos, or the calibration's width/height is wrong{}",
                wrong.len(),
                named.join("; "),
                crate::camera::crop_hint(&cameras[*i], (p.width, p.height))
            ),
        ));
    }
    for ((_, path), p) in videos.iter().zip(&probes) {
        crate::limits::check_image(path, p.width, p.height)?;
    }
    Ok(probes)
}

/// Camera `cam`'s video with the video frames `window` decoded under `root`
/// (`<cache>/decoded`), from the cache when it holds them intact, else decoded now (counted
/// on `progress`) when `decode` is set; without `decode` (read-only commands) nothing is
/// written and a window not in the cache is left undecoded ([`Decoded::holds`]).
pub fn decoded(
    video: &Path,
    probe: Probe,
    cam: &Camera,
    root: &Path,
    window: std::ops::RangeInclusive<u32>,
    decode: bool,
    progress: &indicatif::ProgressBar,
) -> Result<Decoded> {
    let content = content_hash(video)?;
    let content_dir = root.join(&cam.name).join(&content);
    if let Some((dir, info)) = find_intact(&content_dir, &window, decode) {
        return Ok(Decoded {
            video: video.to_path_buf(),
            probe,
            dir,
            decoded: info.first..info.first + info.frames,
            fresh: false,
        });
    }
    let (first, last) = (*window.start(), *window.end());
    let dir = content_dir.join(format!("{first}-{last}"));
    if let (Some(damage), false) = (&probe.damage, decode) {
        return Err(damaged(video, damage, None));
    }
    if !decode || window.is_empty() {
        return Ok(Decoded {
            video: video.to_path_buf(),
            probe,
            dir,
            decoded: 0..0,
            fresh: false,
        });
    }
    let count = last - first + 1;
    check_space(video, root, &probe, count)?;
    crate::fsutil::create_dir_all(&content_dir)?;
    remove_dead_scratch(&content_dir);
    // A scratch folder of this process, removed whatever happens unless renamed into place
    // (named as the cache's temporary files: `.<name>.tmp-<host>-<pid>-<n>`); the folders
    // made for it go too when the decoding is refused.
    let scratch = Scratch {
        dir: content_dir.join(format!(
            ".decoding-{first}-{last}.tmp-{}-{}-0",
            crate::fsutil::host_name(),
            std::process::id()
        )),
        root: root.to_path_buf(),
    };
    let _ = std::fs::remove_dir_all(&scratch.dir);
    crate::fsutil::create_dir_all(&scratch.dir)?;
    let files = decode_into(video, &probe, first, count, &scratch.dir, progress)?;
    if let Some(damage) = &probe.damage {
        // Damage the decoding of the selected frames did not meet (elsewhere in the file).
        return Err(damaged(video, damage, None));
    }
    let info = VideoInfo {
        first,
        frames: files.len() as u32,
        width: probe.width,
        height: probe.height,
        rate: probe.rate,
        content,
        files,
    };
    crate::fsutil::write_atomic(
        &scratch.dir.join("info.yaml"),
        crate::yaml::to_string(&info)?.as_bytes(),
    )?;
    let _ = std::fs::remove_dir_all(&dir); // a damaged earlier decoding of the same window
    if let Err(e) = std::fs::rename(&scratch.dir, &dir) {
        // Another process decoded the same window first: its frames are the same.
        if !dir.join("info.yaml").is_file() {
            return Err(Error::io(&dir, e));
        }
    }
    Ok(Decoded {
        video: video.to_path_buf(),
        probe,
        dir,
        decoded: first..first + info.frames,
        fresh: true,
    })
}

/// A decoded folder under `content_dir` that holds `window` with every frame as its
/// `info.yaml` recorded it. Folders found damaged are removed when `repair` is set.
fn find_intact(
    content_dir: &Path,
    window: &std::ops::RangeInclusive<u32>,
    repair: bool,
) -> Option<(PathBuf, VideoInfo)> {
    let mut candidates: Vec<PathBuf> = std::fs::read_dir(content_dir)
        .ok()?
        .flatten()
        .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
        .map(|e| e.path())
        .collect();
    candidates.sort();
    for dir in candidates {
        let Ok(info) = crate::yaml::read::<VideoInfo>(&dir.join("info.yaml")) else {
            if repair {
                let _ = std::fs::remove_dir_all(&dir);
            }
            continue;
        };
        let held = info.first..info.first.saturating_add(info.frames);
        if window.is_empty() || !(held.start <= *window.start() && *window.end() < held.end) {
            continue;
        }
        let intact = info.files.len() == info.frames as usize
            && window.clone().all(|f| {
                let record = &info.files[(f - info.first) as usize];
                frame_intact(&dir.join(format!("{f:06}.png")), record)
            });
        if intact {
            return Some((dir, info));
        }
        if repair {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
    None
}

/// Whether the file at `path` is the one `record` describes (size, then hash).
fn frame_intact(path: &Path, record: &FrameRecord) -> bool {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return false;
    };
    if !meta.is_file() || meta.len() != record.bytes {
        return false;
    }
    let Ok(bytes) = std::fs::read(path) else {
        return false;
    };
    blake3::hash(&bytes).to_hex().as_str() == record.blake3
}

/// Refuses a decoding of `count` frames that could take more than the cap
/// ([`crate::limits::check_decoded`]), or more than the free space of the disk holding
/// `root`. Its size is bounded by the uncompressed frames (PNG never grows them by more
/// than a little).
fn check_space(video: &Path, root: &Path, probe: &Probe, count: u32) -> Result<()> {
    let frame = probe.width as u64 * probe.height as u64 * 3 + 4096;
    let need = frame.saturating_mul(count as u64);
    let mb = |b: u64| b as f64 / (1u64 << 20) as f64;
    crate::limits::check_decoded(
        video,
        &format!(
            "decoding its {count} selected frames at {}x{} (select fewer with `frames: A..B` \
             in pipeline.yaml)",
            probe.width, probe.height
        ),
        need,
    )?;
    if let Some(free) = free_bytes(root) {
        if need > free {
            return Err(Error::invalid(
                video,
                format!(
                    "decoding its {count} selected frames at {}x{} could take {:.0} MB, but \
                     the disk holding {} has {:.0} MB free; free space, put `cache` on a \
                     larger disk, or select fewer frames",
                    probe.width,
                    probe.height,
                    mb(need),
                    crate::text::quoted_path(root),
                    mb(free)
                ),
            ));
        }
    }
    Ok(())
}

/// Free bytes on the disk holding `path` (or its nearest existing ancestor), for an
/// unprivileged writer.
fn free_bytes(path: &Path) -> Option<u64> {
    let mut at = path;
    while !at.exists() {
        at = at.parent()?;
    }
    let c = std::ffi::CString::new(at.as_os_str().as_encoded_bytes()).ok()?;
    // SAFETY: `c` is a valid NUL-terminated path and `stat` a plain-data out parameter.
    let mut stat: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut stat) } != 0 {
        return None;
    }
    Some((stat.f_bavail as u64).saturating_mul(stat.f_frsize as u64))
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

/// A scratch folder removed when dropped (a no-op once it was renamed away), with the
/// folders between it and `root` that are left empty.
struct Scratch {
    dir: PathBuf,
    root: PathBuf,
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
        let mut at = self.dir.parent();
        while let Some(d) = at.filter(|d| d.starts_with(&self.root)) {
            // Fails, and stops, at the first folder that is not empty.
            if std::fs::remove_dir(d).is_err() {
                break;
            }
            at = d.parent();
        }
    }
}

/// Decodes `count` frames of `video` from video frame `first` into `dir` as NNNNNN.png
/// (named by video frame index); returns each file's record. Every frame must come out of
/// ffmpeg at the probed size, and ffmpeg must report no error while decoding.
fn decode_into(
    video: &Path,
    probe: &Probe,
    first: u32,
    count: u32,
    dir: &Path,
    progress: &indicatif::ProgressBar,
) -> Result<Vec<FrameRecord>> {
    let mut args: Vec<std::ffi::OsString> = ["-nostdin", "-v", "error", "-noautorotate"]
        .iter()
        .chain(&INPUT_GUARD)
        .chain(&["-i"])
        .map(std::ffi::OsString::from)
        .collect();
    args.push(file_url(video));
    args.extend(["-map".into(), "0:v:0".into()]);
    if first > 0 {
        // Frames before the window are decoded (a stream is decoded from its start) but
        // never written.
        args.push("-vf".into());
        args.push(format!("select=between(n\\,{first}\\,{})", first + count - 1).into());
    }
    args.push("-frames:v".into());
    args.push(count.to_string().into());
    args.extend(
        ["-f", "image2pipe", "-c:v", "ppm", "pipe:1"]
            .iter()
            .map(std::ffi::OsString::from),
    );
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let mut child = spawn(FFMPEG, &args, video)?;
    let stdout = child.stdout.take().expect("piped");
    let mut stdout = std::io::BufReader::with_capacity(1 << 20, stdout);
    // ffmpeg's messages are read on their own thread so that a full stderr pipe never
    // stalls it; each is stamped with the frames delivered when it came.
    let delivered = Arc::new(AtomicU32::new(0));
    let mut stderr = std::io::BufReader::new(child.stderr.take().expect("piped"));
    let seen = Arc::clone(&delivered);
    let errors = std::thread::spawn(move || {
        let mut all = Vec::new();
        let mut first_at = None;
        let mut line = Vec::new();
        while stderr.read_until(b'\n', &mut line).is_ok_and(|n| n > 0) {
            if first_at.is_none() && !line.trim_ascii().is_empty() {
                first_at = Some(seen.load(Ordering::SeqCst));
            }
            all.extend_from_slice(&line);
            line.clear();
        }
        (all, first_at)
    });
    let size = probe.width as usize * probe.height as usize * 3;
    let mut buf = vec![0u8; size];
    let mut files = Vec::with_capacity(count as usize);
    let outcome: std::result::Result<(), String> = loop {
        if files.len() as u32 == count {
            break Ok(());
        }
        let index = first + files.len() as u32;
        match read_ppm_header(&mut stdout) {
            Ok(None) => break Ok(()),
            Ok(Some((w, h))) if (w, h) != (probe.width, probe.height) => {
                break Err(format!(
                    "ffmpeg delivered frame {index} as {w}x{h}, but the stream was probed as \
                     {}x{} (a rotated or resized stream?)",
                    probe.width, probe.height
                ))
            }
            Ok(Some(_)) => {}
            Err(m) => break Err(format!("frame {index}: {m}")),
        }
        match read_full(&mut stdout, &mut buf) {
            Ok(n) if n < size => {
                break Err(format!(
                    "the stream ended inside frame {index} ({n} of {size} bytes)"
                ))
            }
            Ok(_) => {}
            Err(e) => break Err(e.to_string()),
        }
        let img = image::RgbImage::from_raw(probe.width, probe.height, buf.clone())
            .expect("sized buffer");
        let path = dir.join(format!("{index:06}.png"));
        match write_png(&path, &img) {
            Ok(record) => files.push(record),
            Err(e) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(e);
            }
        }
        delivered.store(files.len() as u32, Ordering::SeqCst);
        progress.inc(1);
    };
    if outcome.is_err() {
        let _ = child.kill();
    }
    let status = child.wait().map_err(|e| Error::io(video, e))?;
    let (stderr, first_error_at) = errors.join().unwrap_or_default();
    let got = files.len() as u32;
    if let Err(m) = outcome {
        return Err(Error::invalid(
            video,
            format!("decoding failed: {m}: {}", complaint(&stderr)),
        ));
    }
    if let Some(at) = first_error_at {
        return Err(damaged(video, &complaint(&stderr), Some(first + at)));
    }
    if !status.success() {
        return Err(Error::invalid(
            video,
            format!(
                "ffmpeg could not decode the video (damaged?) after {got} frames: {}",
                complaint(&stderr)
            ),
        ));
    }
    if got < count {
        return Err(Error::invalid(
            video,
            format!(
                "the container lists {} frames, but ffmpeg decoded only video frames \
                 {first}..{} of the {count} selected from {first}: the file is damaged or \
                 cut short; re-copy it from its source",
                probe.frames,
                (first + got).saturating_sub(1),
            ),
        ));
    }
    Ok(files)
}

/// The refusal of a video ffmpeg reports damage in (`complaint`), near video frame `frame`
/// when the decoding could tell.
fn damaged(video: &Path, complaint: &str, frame: Option<u32>) -> Error {
    Error::invalid(
        video,
        format!(
            "ffmpeg reports damage in the file{} (it is damaged or cut short; frames decoded \
             from it would hold concealed garbage): {complaint}; re-copy the file from its \
             source, or trim the damaged part away (ffmpeg -ss/-to) and re-encode it",
            frame.map_or(String::new(), |f| format!(", near video frame {f}"))
        ),
    )
}

/// Reads one PPM header (`P6 <w> <h> <maxval>` and one whitespace byte) from ffmpeg's
/// pipe: `None` at the end of the stream, the frame's size otherwise.
fn read_ppm_header(r: &mut impl BufRead) -> std::result::Result<Option<(u32, u32)>, String> {
    let mut fields: Vec<String> = Vec::with_capacity(4);
    let mut token = String::new();
    while fields.len() < 4 {
        let mut byte = [0u8; 1];
        match r.read(&mut byte) {
            Ok(0) if fields.is_empty() && token.is_empty() => return Ok(None),
            Ok(0) => return Err("the stream ended inside a frame header".into()),
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e.to_string()),
        }
        if byte[0].is_ascii_whitespace() {
            if !token.is_empty() {
                fields.push(std::mem::take(&mut token));
            }
        } else if token.len() < 16 {
            token.push(byte[0] as char);
        } else {
            return Err("not a PPM frame header".into());
        }
    }
    let number = |s: &str| s.parse::<u32>().ok();
    match (
        fields[0].as_str(),
        number(&fields[1]),
        number(&fields[2]),
        fields[3].as_str(),
    ) {
        ("P6", Some(w), Some(h), "255") => Ok(Some((w, h))),
        _ => Err(format!(
            "not an 8-bit PPM frame header: {}",
            fields.join(" ")
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

/// Writes a decoded frame as a fast-compressed PNG; returns its record.
fn write_png(path: &Path, img: &image::RgbImage) -> Result<FrameRecord> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
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
        .map_err(|e| Error::invalid(path, format!("cannot write the decoded frame: {e}")))?;
    std::fs::write(path, &bytes).map_err(|e| Error::io(path, e))?;
    Ok(FrameRecord {
        bytes: bytes.len() as u64,
        blake3: blake3::hash(&bytes).to_hex().to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ppm_headers_are_read_and_checked() {
        let mut r = std::io::Cursor::new(b"P6\n128 96\n255\nrest".to_vec());
        assert_eq!(read_ppm_header(&mut r).unwrap(), Some((128, 96)));
        let mut rest = String::new();
        r.read_to_string(&mut rest).unwrap();
        assert_eq!(rest, "rest");
        assert_eq!(
            read_ppm_header(&mut std::io::Cursor::new(b"")).unwrap(),
            None
        );
        assert!(read_ppm_header(&mut std::io::Cursor::new(b"P5\n1 1\n255\n")).is_err());
        assert!(read_ppm_header(&mut std::io::Cursor::new(b"P6\n1 1")).is_err());
    }
}
