//! `pipeline skeleton FILE`: the sequence's `skeleton.yaml` made from its reference frame's
//! reconstruction, by embedding a template ([`crate::skeleton::embed`]); with a PLY of the
//! bones and the skeleton drawn on the reference frame in every camera, to check it.

use crate::error::{Error, Result};
use crate::geometry::TriMesh;
use crate::runner::{Job, RunOptions};
use crate::skeleton::Skeleton;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The skeleton to embed: the built-in humanoid, or a `skeleton.yaml` used as a template.
#[derive(Debug, Clone)]
pub enum Template {
    Humanoid,
    File(PathBuf),
}

impl Template {
    /// `humanoid`, or the path of a skeleton.yaml.
    pub fn parse(s: &str) -> Template {
        match s {
            "humanoid" => Template::Humanoid,
            path => Template::File(PathBuf::from(path)),
        }
    }

    /// The template in a world whose up is `up`: the built-in humanoid (standing on +z)
    /// turned so that it stands on `up`; a file's skeleton as it is (its world's up taken
    /// to be the capture's).
    fn load(&self, up: &Vector3<f64>) -> Result<Skeleton> {
        match self {
            Template::Humanoid => {
                let mut skeleton = crate::synth::humanoid::skeleton();
                let turn =
                    nalgebra::Rotation3::rotation_between(&Vector3::z(), up).unwrap_or_else(|| {
                        nalgebra::Rotation3::from_axis_angle(
                            &Vector3::x_axis(),
                            std::f64::consts::PI,
                        )
                    });
                for b in &mut skeleton.bones {
                    (b.head, b.tail) = (turn * b.head, turn * b.tail);
                }
                Ok(skeleton)
            }
            Template::File(path) => Skeleton::read(path),
        }
    }
}

/// What `pipeline skeleton` wrote.
pub struct Written {
    pub skeleton: PathBuf,
    pub bones_ply: PathBuf,
    pub overlay: PathBuf,
    /// Seconds of the embedding alone (the reconstruction of the frame excluded).
    pub embed_seconds: f64,
    /// The frame the skeleton was embedded at.
    pub frame: u32,
    pub skeleton_value: Skeleton,
    /// Every frame examined: its score, or why it was refused; best first.
    pub candidates: Vec<Candidate>,
    /// The joint (bone name, `head` or `tail`) the fewest cameras' silhouettes hold, and
    /// how many of them do (within [`MASK_SLACK_PX`]).
    pub least_seen_joint: (String, usize),
    /// Each left limb's length against its right one's, metres: (left top bone, left,
    /// right).
    pub limb_lengths: Vec<(String, f64, f64)>,
    /// The share of the surface far from every bone
    /// ([`crate::skeleton::embed::Embedding::uncovered_share`]).
    pub uncovered_share: f64,
    /// Without `world.up` (or `export.up_axis`): the up direction found and its cues (one line).
    pub up_found: Option<String>,
}

/// A frame `pipeline skeleton` examined.
#[derive(Debug, Clone)]
pub struct Candidate {
    pub frame: u32,
    /// The embedding's score ([`Scored::score`]), or why the frame was refused.
    pub outcome: std::result::Result<f64, String>,
}

/// An embedding in one frame, scored.
#[derive(Debug, Clone)]
struct Scored {
    skeleton: Skeleton,
    /// The share of (joint, camera) pairs whose joint projects inside the camera's
    /// silhouette (dilated by [`MASK_SLACK_PX`]), less the share of the surface the bones
    /// leave unexplained and less the largest left/right limb length difference (a share
    /// of the longer): 1 for a symmetric skeleton every view agrees with.
    score: f64,
    /// The joint the fewest silhouettes hold, and how many do ([`Written::least_seen_joint`]).
    least_seen_joint: (String, usize),
    /// [`Written::uncovered_share`].
    uncovered_share: f64,
}

/// One examined frame.
struct Tried {
    frame: u32,
    outcome: std::result::Result<Scored, String>,
}

/// Each left limb (a `_l` bone whose parent has no side, with the chain below it) against
/// its right one: (left top bone, left length, right length), metres.
pub fn limb_lengths(skeleton: &Skeleton) -> Vec<(String, f64, f64)> {
    use crate::skeleton::sides::{is_left, other_side};
    let children = skeleton.children();
    let chain_length = |top: usize| {
        let mut length = 0.0;
        let mut at = Some(top);
        while let Some(b) = at {
            length += skeleton.bones[b].length();
            at = children[b].first().copied();
        }
        length
    };
    skeleton
        .bones
        .iter()
        .enumerate()
        .filter(|(_, b)| is_left(&b.name))
        .filter(|(_, b)| {
            b.parent
                .is_none_or(|p| other_side(&skeleton.bones[p].name).is_none())
        })
        .filter_map(|(l, b)| {
            let r = other_side(&b.name).and_then(|n| skeleton.bone_index(&n))?;
            Some((b.name.clone(), chain_length(l), chain_length(r)))
        })
        .collect()
}

/// How many frames `pipeline skeleton` examines without `--frame`, at most.
pub const CANDIDATE_FRAMES: usize = 12;

/// Pixels of slack around a silhouette when testing a joint's projection.
pub const MASK_SLACK_PX: i64 = 5;

/// Frames spread evenly over `frames` (sorted), at most [`CANDIDATE_FRAMES`], the first and
/// last among them.
pub fn candidate_frames(frames: &[u32]) -> Vec<u32> {
    let n = frames.len();
    if n <= CANDIDATE_FRAMES {
        return frames.to_vec();
    }
    let mut out: Vec<u32> = (0..CANDIDATE_FRAMES)
        .map(|k| frames[k * (n - 1) / (CANDIDATE_FRAMES - 1)])
        .collect();
    out.dedup();
    out
}

/// Reconstructs `frame` up to its refined surface and embeds `template` in its largest
/// piece; a refusal is the outcome, not an error.
fn try_frame(job: &Job, template: &Skeleton, up: Vector3<f64>, frame: u32) -> Result<Tried> {
    // Only this frame is reconstructed (a job's runs compute the job's frames).
    let opts = RunOptions {
        until: Some("graphcut".into()),
        ..Default::default()
    };
    crate::runner::run(&job.with_frames(vec![frame]), &opts)?;
    use crate::artifacts::reconstruction::{self, Surface};
    let surface = reconstruction::read_mesh(&job.cache, Surface::Refined, frame)?;
    // Phantom pieces (floor blobs, cables) would distort the body's height and coverage.
    let body = surface.largest_piece();
    if body.vertices.is_empty() {
        let masks = crate::stages::load_silhouettes(&job.context(), frame)?;
        let why = crate::stages::why_hull_is_empty(&job.sequence.cameras, Ok(masks));
        return Ok(Tried {
            frame,
            outcome: Err(format!("the frame's hull is empty: {why}")),
        });
    }
    // Where the person model saw the subject, its keypoints place the template first (no
    // A- or T-pose needed) beside the template's own placement; the surface refines both and
    // the one that explains it better is kept.
    let guess = crate::artifacts::person::read(&job.cache, frame)?.and_then(|person| {
        let points = crate::person::triangulate::triangulate_frame(&job.sequence.cameras, &person);
        crate::person::skeleton::from_keypoints(template, &points)
    });
    let embedded = crate::skeleton::embed::embed_from(template, &body, up, guess.as_ref());
    let outcome = match embedded {
        Ok(e) => {
            let masks = crate::stages::load_silhouettes(&job.context(), frame)?;
            let views = joint_views(&job.sequence.cameras, &masks, &e.skeleton);
            let seen: usize = views.iter().map(|v| v.1).sum();
            let agreement = seen as f64 / (views.len() * masks.len()).max(1) as f64;
            // Left and right limbs of one length are a body's; a larger difference is a
            // limb followed into the wrong part.
            let asymmetry = limb_lengths(&e.skeleton)
                .iter()
                .map(|(_, l, r)| (l - r).abs() / l.max(*r).max(1e-9))
                .fold(0.0, f64::max);
            Ok(Scored {
                skeleton: e.skeleton,
                score: agreement - e.uncovered_share - asymmetry,
                uncovered_share: e.uncovered_share,
                least_seen_joint: views.into_iter().min_by_key(|v| v.1).unwrap_or_default(),
            })
        }
        Err(m) => Err(m.0),
    };
    Ok(Tried { frame, outcome })
}

/// Every joint of `skeleton` (each bone's `head` and `tail`, named) and how many of the
/// cameras' silhouettes hold it, within [`MASK_SLACK_PX`] pixels.
pub fn joint_views(
    cams: &[crate::camera::Camera],
    masks: &[image::GrayImage],
    skeleton: &Skeleton,
) -> Vec<(String, usize)> {
    skeleton
        .bones
        .iter()
        .flat_map(|b| {
            [
                (format!("{} head", b.name), b.head),
                (format!("{} tail", b.name), b.tail),
            ]
        })
        .map(|(name, p)| {
            let seen = cams
                .iter()
                .zip(masks)
                .filter(|(cam, mask)| joint_in_mask(cam, mask, &p))
                .count();
            (name, seen)
        })
        .collect()
}

/// Whether `p` projects within [`MASK_SLACK_PX`] of a silhouette pixel of `mask`.
pub fn joint_in_mask(
    cam: &crate::camera::Camera,
    mask: &image::GrayImage,
    p: &Vector3<f64>,
) -> bool {
    let Some(px) = cam.project(p) else {
        return false;
    };
    let (w, h) = (mask.width() as i64, mask.height() as i64);
    let (u, v) = (px.x.round() as i64, px.y.round() as i64);
    let r = MASK_SLACK_PX;
    for y in (v - r).max(0)..=(v + r).min(h - 1) {
        for x in (u - r).max(0)..=(u + r).min(w - 1) {
            if (x - u).pow(2) + (y - v).pow(2) <= r * r
                && mask.get_pixel(x as u32, y as u32).0[0] >= 128
            {
                return true;
            }
        }
    }
    false
}

/// Reconstructs `frame` (default: the first of the job's frames) up to its refined
/// surface, embeds `template` in it and writes the sequence's `skeleton.yaml` (an
/// existing one only with `force`), `output/skeleton/bones.ply` and
/// `output/skeleton/overlay.png`.
pub fn make(job: &Job, template: &Template, frame: Option<u32>, force: bool) -> Result<Written> {
    let seq = &job.sequence;
    let path = seq.dir.join("skeleton.yaml");
    if path.exists() && !force {
        return Err(Error::Usage(format!(
            "{} exists; pass --force to replace it (or move it away)",
            path.display()
        )));
    }
    // The world's up: pipeline.yaml's, else as the cameras show it.
    let (up, up_found) = match job.config.given_up() {
        Some(up) => (up, None),
        None => {
            let e = crate::geometry::up::estimate(&seq.cameras, None).ok_or_else(|| {
                Error::Usage("pipeline skeleton: the capture has no cameras".into())
            })?;
            (e.up, Some(e.describe()))
        }
    };
    let template = template.load(&up)?;
    let candidates = match frame {
        Some(f) if !job.frames.contains(&f) => {
            return Err(Error::Usage(
                match (job.frames.first(), job.frames.last()) {
                    (Some(a), Some(b)) => format!(
                    "frame {f} is not among the frames selected ({a}..{b}, from pipeline.yaml's \
                     `frames` and the capture); pick one of those, or widen `frames`"
                ),
                    _ => format!("frame {f} is not among the capture's frames"),
                },
            ))
        }
        Some(f) => vec![f],
        None => candidate_frames(&job.frames),
    };
    if candidates.is_empty() {
        return Err(Error::Usage(
            "the sequence has no frames to embed a skeleton in".into(),
        ));
    }
    let started = std::time::Instant::now();
    let mut tried = Vec::with_capacity(candidates.len());
    for &f in &candidates {
        tried.push(try_frame(job, &template, up, f)?);
    }
    let embed_seconds = started.elapsed().as_secs_f64();
    let best = tried
        .iter()
        .filter_map(|t| t.outcome.as_ref().ok().map(|e| (t.frame, e)))
        .max_by(|a, b| a.1.score.total_cmp(&b.1.score));
    let Some((frame, chosen)) = best else {
        let reasons: Vec<String> = tried
            .iter()
            .map(|t| {
                format!(
                    "frame {}: {}",
                    t.frame,
                    t.outcome.as_ref().err().unwrap_or(&String::new())
                )
            })
            .collect();
        return Err(Error::Usage(format!(
            "pipeline skeleton: no skeleton embedded in {} ({}):\n  {}",
            if tried.len() == 1 {
                "the frame"
            } else {
                "any examined frame"
            },
            job.cache
                .stage_dir(crate::artifacts::reconstruction::Surface::Refined.stage())
                .display(),
            reasons.join("\n  ")
        )));
    };
    let mut skeleton = chosen.skeleton.clone();
    let least_seen_joint = chosen.least_seen_joint.clone();
    let uncovered_share = chosen.uncovered_share;
    skeleton.reference_frame = frame;
    let out = job.config.output.join("skeleton");
    crate::fsutil::create_dir_all(&out)?;
    let bones_ply = out.join("bones.ply");
    write_bones(&bones_ply, &skeleton)?;
    let overlay = out.join("overlay.png");
    write_overlay(job, frame, &skeleton, &overlay)?;
    skeleton.write(&path)?;
    let mut candidates: Vec<Candidate> = tried
        .into_iter()
        .map(|t| Candidate {
            frame: t.frame,
            outcome: t.outcome.map(|e| e.score),
        })
        .collect();
    candidates.sort_by(|a, b| match (&a.outcome, &b.outcome) {
        (Ok(x), Ok(y)) => y.total_cmp(x),
        (Ok(_), Err(_)) => std::cmp::Ordering::Less,
        (Err(_), Ok(_)) => std::cmp::Ordering::Greater,
        _ => a.frame.cmp(&b.frame),
    });
    let limb_lengths = limb_lengths(&skeleton);
    Ok(Written {
        up_found,
        least_seen_joint,
        limb_lengths,
        uncovered_share,
        skeleton: path,
        bones_ply,
        overlay,
        embed_seconds,
        frame,
        skeleton_value: skeleton,
        candidates,
    })
}

/// The bones as octahedra (Blender's bone shape: widest a tenth of the way from the head,
/// a tenth of the length wide), each in its part's colour.
fn write_bones(path: &Path, skeleton: &Skeleton) -> Result<()> {
    use crate::geometry::ply::{write_ply, PlyFormat, VertexAttributes};
    let mut mesh = TriMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    let mut colours = Vec::new();
    for (b, bone) in skeleton.bones.iter().enumerate() {
        let axis = bone.tail - bone.head;
        let length = axis.norm();
        if length < 1e-9 {
            continue;
        }
        let u = axis / length;
        let helper = if u.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let v = u.cross(&helper).normalize() * (0.1 * length);
        let w = u.cross(&v);
        let ring = bone.head + 0.1 * axis;
        let base = mesh.vertices.len() as u32;
        mesh.vertices
            .extend([bone.head, ring + v, ring + w, ring - v, ring - w, bone.tail]);
        for k in 0..4u32 {
            let (a, c) = (base + 1 + k, base + 1 + (k + 1) % 4);
            mesh.triangles.push([base, c, a]);
            mesh.triangles.push([base + 5, a, c]);
        }
        colours.extend([crate::skeleton::model::part_colour(b); 6]);
    }
    write_ply(
        path,
        &mesh,
        &VertexAttributes {
            normals: None,
            colors: Some(&colours),
            scalars: Vec::new(),
        },
        PlyFormat::BinaryLittleEndian,
    )
}

/// The skeleton drawn on `frame` in every camera (with the silhouette's outline), tiled in
/// one picture.
fn write_overlay(job: &Job, frame: u32, skeleton: &Skeleton, path: &Path) -> Result<()> {
    let ctx = job.context();
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    let joints: Vec<_> = skeleton.bones.iter().map(|b| (b.head, b.tail)).collect();
    let mut tiles = Vec::new();
    let mut labels = Vec::new();
    for (c, cam) in job.sequence.cameras.iter().enumerate() {
        // A masks-only capture has no photograph: the silhouette, dimmed, stands in.
        let image = if job.sequence.has_frames {
            job.sequence.load_frame(c, frame)?
        } else {
            image::RgbImage::from_fn(masks[c].width(), masks[c].height(), |x, y| {
                let v = masks[c].get_pixel(x, y).0[0] / 3;
                image::Rgb([v, v, v])
            })
        };
        tiles.push(crate::drawing::skeleton_on_frame(
            cam, &image, &masks[c], &joints,
        ));
        labels.push(cam.name.clone());
    }
    crate::imageio::write_rgb(path, &crate::drawing::contact_sheet(&tiles, &labels, 320))
}
