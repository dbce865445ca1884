//! Stage 1, silhouettes ([`crate::recon::silhouette`]): the given masks (cleaned when
//! asked), or background subtraction against the plates or one constant colour.

use super::{Inputs, PerFrame, Produced};
use crate::artifacts::learned_background::{self, CameraShares, LearnedInfo};
use crate::artifacts::person::PersonFrame;
use crate::artifacts::silhouettes::Silhouettes;
use crate::cache::KeyBuilder;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::recon::silhouette::{self, SilhouetteMethod, SilhouetteParams};
use serde::Serialize;

/// What the stage reads besides the capture's files.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    /// The method `auto` resolved for this capture.
    pub method: SilhouetteMethod,
    pub params: SilhouetteParams,
    /// Method `learned`: the key of the learned plates (which holds the content of every
    /// frame they were learned from, [`learn_plates`]).
    pub learned_plates: Option<String>,
    /// Method `person`: the person model's fingerprint (its files' content) and the carving
    /// that makes its masks consistent across cameras.
    pub person_model: Option<String>,
    pub person_hull: Option<crate::recon::visual_hull::VisualHullParams>,
}

/// The stage.
pub static STAGE: PerFrame<Settings> = PerFrame { resolve, compute };

fn resolve(config: &Config, sequence: &Sequence) -> Result<Settings> {
    let method = resolve_method(config, sequence)?;
    let person = method == SilhouetteMethod::Person;
    Ok(Settings {
        method,
        params: config.silhouette.clone(),
        learned_plates: sequence.learned_plates.clone(),
        person_model: if person {
            Some(crate::person::model::fingerprint(
                &crate::person::model::folder(),
            )?)
        } else {
            None
        },
        person_hull: person.then(|| config.visual_hull.clone()),
    })
}

/// Which silhouette source a sequence uses under `silhouette.method`.
pub fn resolve_method(config: &Config, seq: &Sequence) -> Result<SilhouetteMethod> {
    let method = match config.silhouette.method {
        SilhouetteMethod::Auto if seq.has_masks => SilhouetteMethod::Masks,
        SilhouetteMethod::Auto if seq.has_backgrounds || !seq.has_frames => {
            SilhouetteMethod::Background
        }
        // Neither masks nor plates: a person model finds the subject without either.
        SilhouetteMethod::Auto
            if crate::person::model::is_set_up(&crate::person::model::folder()) =>
        {
            SilhouetteMethod::Person
        }
        SilhouetteMethod::Auto => SilhouetteMethod::Background,
        m => m,
    };
    match method {
        SilhouetteMethod::Masks if !seq.has_masks => Err(Error::invalid(
            seq.dir.join("masks"),
            "silhouette.method is 'masks' but the sequence has no masks/ folder",
        )),
        SilhouetteMethod::Background
        | SilhouetteMethod::Constant
        | SilhouetteMethod::Learned
        | SilhouetteMethod::Person
            if !seq.has_frames =>
        {
            Err(Error::invalid(
                seq.dir.join("frames"),
                "a masks-only capture (no frames/) takes its silhouettes from masks/; \
                 set silhouette.method to 'masks' or 'auto'",
            ))
        }
        SilhouetteMethod::Background if !seq.has_backgrounds => Err(Error::invalid(
            seq.dir.join("background"),
            format!(
                "background subtraction needs a plate background/<camera>.png for every camera \
                 (or given masks in masks/<camera>/). A capture of one person without either \
                 takes its silhouettes from the person model (silhouette.method 'person', which \
                 'auto' picks once it is set up: `bash tools/setup-person-model.sh`, into {} \
                 or the folder ${})",
                crate::text::shown_path(&crate::person::model::folder()),
                crate::person::model::FOLDER_VARIABLE
            ),
        )),
        m => Ok(m),
    }
}

pub(super) fn sources(ctx: &super::Context, frame: u32, key: &mut KeyBuilder) -> Result<()> {
    let seq = ctx.sequence;
    let method = resolve_method(ctx.config, seq)?;
    for c in 0..seq.cameras.len() {
        key.add("camera", &seq.cameras[c].name);
        match method {
            SilhouetteMethod::Masks => key.add_file(&seq.mask_path(c, frame))?,
            // The learned plates' key (in the settings) holds what they were learned from.
            SilhouetteMethod::Constant | SilhouetteMethod::Learned | SilhouetteMethod::Person => {
                key.add_file(&seq.frame_path(c, frame))?
            }
            _ => key
                .add_file(&seq.frame_path(c, frame))?
                .add_file(&seq.background_path(c))?,
        };
    }
    Ok(())
}

fn compute(s: &Settings, inputs: &Inputs, frame: u32) -> Result<Produced> {
    let (masks, person) = masks(
        s,
        inputs.sequence,
        |key, c| inputs.learned_plate(key, c),
        frame,
    )?;
    let cameras = inputs
        .sequence
        .cameras
        .iter()
        .map(|c| c.name.clone())
        .collect();
    let warnings = person.as_ref().map(person_warnings).unwrap_or_default();
    Ok(Produced::new(
        Silhouettes {
            cameras,
            masks,
            person,
        },
        warnings,
    ))
}

/// Frame `frame`'s silhouettes (and method `person`'s evidence) as the stage computes them,
/// written nowhere (for `pipeline
/// check`, which inspects the first selected frame before any stage runs).
pub fn frame_masks(
    config: &Config,
    seq: &Sequence,
    cache: &crate::cache::Cache,
    frame: u32,
) -> Result<(Vec<image::GrayImage>, Option<PersonFrame>)> {
    let s = resolve(config, seq)?;
    masks(
        &s,
        seq,
        |key, c| learned_background::read(cache, key, &seq.cameras[c]),
        frame,
    )
}

/// Above this share of a camera's person mask without support from the other cameras, the
/// mask (or the calibration) is suspect.
const MAX_UNSUPPORTED: f64 = 0.1;

/// The person model's findings a user should know of: cameras where nobody was found, and
/// masks largely unsupported by the other cameras.
pub fn person_warnings(frame: &PersonFrame) -> Vec<String> {
    let mut out = Vec::new();
    let missing: Vec<String> = frame
        .views
        .iter()
        .filter(|v| !v.found)
        .map(|v| crate::text::quoted(&v.camera))
        .collect();
    if !missing.is_empty() {
        out.push(format!(
            "the person model found nobody in camera(s) {}: their silhouettes are the whole \
             image and carve nothing",
            missing.join(", ")
        ));
    }
    let unsupported: Vec<String> = frame
        .views
        .iter()
        .filter(|v| v.found && v.unsupported > MAX_UNSUPPORTED)
        .map(|v| {
            format!(
                "{} ({:.0}%)",
                crate::text::quoted(&v.camera),
                100.0 * v.unsupported
            )
        })
        .collect();
    if !unsupported.is_empty() {
        out.push(format!(
            "the person masks of camera(s) {} lie partly where no other camera sees the \
             person (dropped): a second person, a reflection, or a calibration that does not \
             fit these videos",
            unsupported.join(", ")
        ));
    }
    out
}

/// Every camera's silhouette of `frame` under the settings `s`; `plate(key, c)` reads
/// camera c's learned plate.
fn masks(
    s: &Settings,
    seq: &Sequence,
    plate: impl Fn(&str, usize) -> Result<crate::recon::learned_background::Learned>,
    frame: u32,
) -> Result<(Vec<image::GrayImage>, Option<PersonFrame>)> {
    let p = &s.params;
    if s.method == SilhouetteMethod::Person {
        let images: Vec<image::RgbImage> = (0..seq.cameras.len())
            .map(|c| seq.load_frame(c, frame))
            .collect::<Result<_>>()?;
        let hull = s.person_hull.as_ref().ok_or_else(|| {
            Error::Usage(
                "silhouette.method 'person' without its settings (a defect of hullpose)".into(),
            )
        })?;
        let (masks, person) = crate::person::evidence::frame_evidence(&seq.cameras, &images, hull)
            .map_err(|e| match e {
                Error::Usage(m) => {
                    Error::invalid(seq.dir.join("frames"), format!("frame {frame}: {m}"))
                }
                e => e,
            })?;
        return Ok((masks, Some(person)));
    }
    let mut masks = Vec::with_capacity(seq.cameras.len());
    for c in 0..seq.cameras.len() {
        let mask = match s.method {
            SilhouetteMethod::Masks => {
                let mask = seq.load_mask(c, frame)?.ok_or_else(|| {
                    Error::invalid(seq.mask_path(c, frame), "the mask is missing")
                })?;
                if p.clean_given {
                    silhouette::clean_given(&mask, p)
                } else {
                    mask
                }
            }
            SilhouetteMethod::Constant => {
                silhouette::subtract_constant(&seq.load_frame(c, frame)?, p)
            }
            SilhouetteMethod::Learned => {
                let key = s.learned_plates.as_deref().ok_or_else(|| {
                    Error::Usage(
                        "silhouette.method is 'learned' but the plates were not learned \
                         (a defect of hullpose, please report it)"
                            .into(),
                    )
                })?;
                let learned = plate(key, c)?;
                silhouette::subtract_learned(&seq.load_frame(c, frame)?, &learned, p)
            }
            _ => {
                let img = seq.load_frame(c, frame)?;
                let bg = seq.load_background(c)?.ok_or_else(|| {
                    Error::invalid(seq.background_path(c), "the background plate is missing")
                })?;
                silhouette::subtract_background(&img, &bg, p)
            }
        };
        masks.push(mask);
    }
    Ok((masks, None))
}

/// The most frames a plate is learned from (evenly spread over the selected range): enough
/// for the mode of a pixel's colours, and a bound on the memory the learning takes.
pub const MAX_LEARNING_FRAMES: usize = 60;

/// What [`learn_plates`] did.
pub struct Learning {
    /// The plates' key (for [`Sequence::learned_plates`]).
    pub key: String,
    pub info: LearnedInfo,
    /// Whether they were learned now (false: found in the cache).
    pub computed: bool,
}

/// Method `learned`: learns every camera's plate from the frames pipeline.yaml selects
/// (`frames`, at most [`MAX_LEARNING_FRAMES`] of them, evenly spread), or finds them in the
/// cache. `None` for the other methods. A camera with more than
/// `silhouette.learned_max_undecided` of its pixels never showing a steady background is
/// refused by name: it needs plates or masks. Without `compute`, plates not in the cache
/// are left unlearned (`None`).
pub fn learn_plates(
    config: &Config,
    seq: &Sequence,
    cache: &crate::cache::Cache,
    compute: bool,
) -> Result<Option<Learning>> {
    if resolve_method(config, seq)? != SilhouetteMethod::Learned {
        return Ok(None);
    }
    let p = &config.silhouette;
    let selected: Vec<u32> = seq
        .frames
        .iter()
        .copied()
        .filter(|&f| config.frames.is_none_or(|r| r.contains(f)))
        .collect();
    let frames: Vec<u32> = if selected.len() <= MAX_LEARNING_FRAMES {
        selected
    } else {
        (0..MAX_LEARNING_FRAMES)
            .map(|k| selected[k * (selected.len() - 1) / (MAX_LEARNING_FRAMES - 1)])
            .collect()
    };
    let files: Vec<Vec<std::path::PathBuf>> = (0..seq.cameras.len())
        .map(|c| frames.iter().map(|&f| seq.frame_path(c, f)).collect())
        .collect();
    let key = learned_background::key(p, &seq.cameras, &files)?;
    if let Some(info) = learned_background::existing(cache, &key) {
        refuse_undecided(config, &info)?;
        return Ok(Some(Learning {
            key,
            info,
            computed: false,
        }));
    }
    if !compute {
        return Ok(None);
    }
    // On stderr, hidden when that is not a terminal.
    let bar = indicatif::ProgressBar::new(seq.cameras.len() as u64);
    bar.set_message("background");
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} cameras")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let mut plates = Vec::with_capacity(seq.cameras.len());
    let mut shares = Vec::with_capacity(seq.cameras.len());
    for c in 0..seq.cameras.len() {
        // One camera's frames at a time: 60 frames of 1920x1080 are 370 MB.
        let images: Vec<image::RgbImage> = frames
            .iter()
            .map(|&f| seq.load_frame(c, f))
            .collect::<Result<_>>()?;
        let refs: Vec<&image::RgbImage> = images.iter().collect();
        let (learned, moved) = crate::recon::learned_background::learn(&refs, p);
        shares.push(CameraShares {
            camera: seq.cameras[c].name.clone(),
            undecided: learned.undecided(p.learned_min_share),
            never_background: learned.never_background(),
            changed: moved,
        });
        plates.push(learned);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let info = LearnedInfo {
        frames,
        cameras: shares,
        files: Vec::new(),
    };
    // Refused before anything is written: a rerun refuses again, by name.
    refuse_undecided(config, &info)?;
    learned_background::write(cache, &key, &seq.cameras, &plates, &info)?;
    Ok(Some(Learning {
        key,
        info,
        computed: true,
    }))
}

/// Above this share of its pixels marked as where the subject stays, a camera's learning
/// has taken the room for the subject: one person fills far less of a view.
const MAX_SUBJECT_SHARE: f64 = 0.6;

/// Below this share of its pixels changing over the frames, a camera saw nothing move.
const MIN_CHANGED: f64 = 1e-4;

/// The cameras (with their share) whose learning marks more than [`MAX_SUBJECT_SHARE`] of
/// the image as where the subject stays.
fn room_taken_for_subject(info: &LearnedInfo) -> Vec<String> {
    info.cameras
        .iter()
        .filter(|c| c.never_background > MAX_SUBJECT_SHARE)
        .map(|c| format!("{} ({:.0}%)", c.camera, 100.0 * c.never_background))
        .collect()
}

fn refuse_undecided(config: &Config, info: &LearnedInfo) -> Result<()> {
    let p = &config.silhouette;
    let still: Vec<&str> = info
        .cameras
        .iter()
        .filter(|c| c.changed < MIN_CHANGED)
        .map(|c| c.camera.as_str())
        .collect();
    if !still.is_empty() {
        return Err(Error::invalid(
            &config.path,
            format!(
                "silhouette.method 'learned': nothing moved in camera(s) {} over the {} frames \
                 learned from, so nothing tells the subject from the room: learning needs \
                 frames where the subject moves. Select more frames (`frames`), or give \
                 background plates (background/<camera>.png) or masks (masks/<camera>/)",
                still.join(", "),
                info.frames.len()
            ),
        ));
    }
    let room = room_taken_for_subject(info);
    if !room.is_empty() {
        return Err(Error::invalid(
            &config.path,
            format!(
                "silhouette.method 'learned': in camera(s) {} the learning marks over {:.0}% of \
                 the image as where the subject stays, which is not one person: the subject \
                 (or the whole scene) hardly moves over the {} frames learned from, so the room \
                 cannot be told from the subject. Give background plates \
                 (background/<camera>.png) or masks (masks/<camera>/), or select frames where \
                 the subject moves through the view",
                room.join(", "),
                100.0 * MAX_SUBJECT_SHARE,
                info.frames.len()
            ),
        ));
    }
    let bad: Vec<String> = info
        .cameras
        .iter()
        .filter(|c| c.undecided > p.learned_max_undecided)
        .map(|c| format!("{} ({:.1}%)", c.camera, 100.0 * c.undecided))
        .collect();
    if bad.is_empty() {
        return Ok(());
    }
    Err(Error::invalid(
        &config.path,
        format!(
            "silhouette.method 'learned': camera(s) {} never show a steady background at more \
             than {:.1}% of their pixels (no colour fills {:.0}% of the {} frames learned \
             from): the subject covers them too often for the background to be learned from \
             the frames. Give background plates (background/<camera>.png) or masks \
             (masks/<camera>/), or select frames where the subject moves through the view",
            bad.join(", "),
            100.0 * p.learned_max_undecided,
            100.0 * p.learned_min_share,
            info.frames.len()
        ),
    ))
}

/// The file of the triangulated body keypoints in the output folder.
pub const KEYPOINTS_FILE: &str = "keypoints3d.csv";

/// Method `person`: the body keypoints of every frame, triangulated, into
/// `output/keypoints3d.csv`, with a summary of their reprojection errors.
pub(super) fn finish(ctx: &super::Context, frames: &[u32]) -> Result<super::Finished> {
    if resolve_method(ctx.config, ctx.sequence)? != SilhouetteMethod::Person {
        return Ok(super::Finished::default());
    }
    let mut frames = frames.to_vec();
    frames.sort_unstable();
    let mut text = format!("{}\n", crate::person::triangulate::CSV_HEADER);
    let mut all = Vec::with_capacity(frames.len());
    for &f in &frames {
        let Some(person) = crate::artifacts::person::read(ctx.cache, f)? else {
            continue;
        };
        let points = crate::person::triangulate::triangulate_frame(&ctx.sequence.cameras, &person);
        text += &crate::person::triangulate::csv_rows(f, &points);
        all.push(points);
    }
    let path = ctx.config.output.join(KEYPOINTS_FILE);
    crate::fsutil::write_atomic(&path, text.as_bytes())?;
    Ok(super::Finished {
        outputs: vec![path],
        files: 1,
        warnings: vec![crate::person::triangulate::summary(&all)],
    })
}

/// One line on the learned plates, for `pipeline check` and the run's summary.
pub fn learning_report(learning: &Learning) -> String {
    let cameras: Vec<String> = learning
        .info
        .cameras
        .iter()
        .map(|c| {
            format!(
                "{} {:.1}% / {:.1}%",
                c.camera,
                100.0 * c.never_background,
                100.0 * c.undecided
            )
        })
        .collect();
    format!(
        "learned background: {} from {} frames; per camera, the image's share where a part of \
         the subject stays (never background) / with no steady colour (taken as the subject): {}",
        if learning.computed {
            "learned"
        } else {
            "reused"
        },
        learning.info.frames.len(),
        cameras.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_camera_whose_subject_fills_most_of_the_image_is_named() {
        let camera = |name: &str, never_background: f64| CameraShares {
            camera: name.into(),
            undecided: 0.0,
            never_background,
            changed: 0.1,
        };
        let info = LearnedInfo {
            frames: vec![0, 1],
            cameras: vec![camera("a", 0.05), camera("b", 0.85), camera("c", 0.61)],
            files: Vec::new(),
        };
        assert_eq!(room_taken_for_subject(&info), ["b (85%)", "c (61%)"]);
    }
}
