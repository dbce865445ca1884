//! Synthetic captures with ground truth: `pipeline synth`.
//!
//! A scene (body, motion, camera ring) is meshed at rest, skinned, posed per frame and
//! rendered through the camera model into a complete dataset in the project's format:
//! calibration, frames, background plates, true masks, skeleton, true joints and true
//! meshes, plus a ready-to-run pipeline.yaml.

pub mod body;
pub mod dress;
pub mod humanoid;
pub mod render;
pub mod scene;
pub mod sequence;
pub mod texture;
pub mod tripod;
pub mod world;

use crate::error::{Error, Result};
use crate::geometry::ply::{self, PlyFormat, VertexAttributes};
use crate::geometry::TriMesh;
use crate::joints::JointRow;
use body::Body;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use render::{CameraView, ShadowMap, Surface};
use scene::Scene;
use std::path::PathBuf;
use std::time::Instant;

/// The export settings of a synthetic capture's pipeline.yaml: its world stands on +z, and
/// its `frame_rate` frames per second make the motion last as long as its key frames at
/// their own rate, however many frames sample it (`frames` of the scene's key frames).
/// The capture's frame rate, frames per second: the motion's key frames at their rate,
/// resampled to `frames`.
fn frame_rate(frames: usize, opts: &SynthOptions) -> f64 {
    let (key_frames, key_rate) = key_frames(opts);
    if key_frames > 1 {
        key_rate * (frames.max(2) - 1) as f64 / (key_frames - 1) as f64
    } else {
        key_rate
    }
}

fn synth_export_yaml(frames: usize, opts: &SynthOptions) -> String {
    let key_rate = key_frames(opts).1;
    let rate = frame_rate(frames, opts);
    // A tilted world says nothing of its up: the tool finds it. The tripod hangs in the air,
    // so nothing of it shows the floor: its height is given.
    let floor = match opts.scene {
        SceneKind::Tripod => {
            "  floor: 0            # the tripod hangs in the air: the floor is given, not found\n"
        }
        SceneKind::Humanoid | SceneKind::Meshes => "",
    };
    let up = if opts.world_tilt_deg == 0.0 {
        format!(
            "world:\n  up: +z              # the synthetic captures stand on +z; the exports turn it to +Y\n{floor}"
        )
    } else {
        String::new()
    };
    format!(
        "{up}# exports (glb, bvh, ply, overlay, surface; add obj to formats for OBJ copies) under output/export/\n\
         export:\n  frame_rate: {}        # the motion's key frames at {key_rate} per second\n",
        (rate * 100.0).round() / 100.0
    )
}

/// The `visual_hull:` section of a synthetic capture's pipeline.yaml: empty when the box
/// the hull derives from the first frame's silhouettes fits the default memory cap, else
/// an explicit box around the subject's true extent over every frame (`bounds`, with 10 cm
/// to spare): with few cameras the derived box stays as wide as the camera ring.
fn box_yaml(
    cams: &[crate::camera::Camera],
    seq_dir: &std::path::Path,
    frame: u32,
    bounds: Option<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)>,
) -> Result<String> {
    use crate::recon::visual_hull::{self, MaskCounts, VisualHullParams};
    let p = VisualHullParams::default();
    let counts = cams
        .iter()
        .map(|c| {
            let path = seq_dir
                .join("masks")
                .join(&c.name)
                .join(format!("{}.png", crate::dataset::frame_stem(frame)));
            let mask = crate::dataset::decode(&path, Some(c))?.into_luma8();
            Ok(MaskCounts::new(&mask, c))
        })
        .collect::<Result<Vec<_>>>()?;
    let fits = visual_hull::carving_box(cams, &counts, &p).is_none_or(|(lo, hi)| {
        visual_hull::check_memory(
            &crate::geometry::grid::GridSpec::covering(lo, hi, p.voxel_size),
            &p,
        )
        .is_ok()
    });
    let Some((lo, hi)) = bounds.filter(|_| !fits) else {
        return Ok(String::new());
    };
    let (lo, hi) = (lo.add_scalar(-0.1), hi.add_scalar(0.1));
    let r = |v: f64| (v * 100.0).round() / 100.0;
    Ok(format!(
        "# the box the silhouettes of so few cameras leave is too large: the subject's own\n\
         visual_hull:\n  bbox: {{min: [{}, {}, {}], max: [{}, {}, {}]}}\n",
        r(lo.x),
        r(lo.y),
        r(lo.z),
        r(hi.x),
        r(hi.y),
        r(hi.z)
    ))
}

/// What the humanoid wears (`pipeline synth --look`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Look {
    /// A saturated noise pattern everywhere but the plain trousers: what photo-consistency
    /// locks onto best.
    #[default]
    Costume,
    /// A person's look ([`texture::Material`]): skin, hair, a shirt, trousers, shoes.
    Person,
}

/// Which motion the humanoid performs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Motion {
    /// The scene's own motion (the humanoid: hands on hips, forearms crossed, hand on knee).
    #[default]
    Default,
    /// Fast motion at 25 frames per second (humanoid only): the arms swing across the
    /// chest and back with hand steps of up to 16 cm per frame, the left leg steps across the
    /// right, and the whole body turns 120 degrees over the sequence (39 frames).
    Dance,
    /// The default motion after ten frames standing with the arms hanging at the sides
    /// against the hips (humanoid only): no frame before the tenth is an open pose. The
    /// A-pose comes at key frame 13, the reference frame of skeleton.yaml.
    ArmsDown,
    /// Walking once around a circle of 1 m radius from the volume's centre (in the A-pose
    /// at frame 0), facing the way it goes, legs and arms swinging (humanoid only, 24 frames):
    /// the subject moves through every camera's view, so each pixel shows the background in
    /// most frames (for `silhouette.method: learned`).
    Walk,
}

/// The humanoid's dress (`pipeline synth --dress`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Dress {
    /// A skirt skinned like the flesh: it swings with the legs ([`body::Skirt`]).
    Fitted,
    /// The same skirt with a hem that swings after the body as a damped pendulum
    /// ([`dress`]): a shape the pose alone does not give.
    Loose,
}

/// Which scene to make.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SceneKind {
    /// The paper's three-armed test object (phantom volume and arms pressed together).
    Tripod,
    /// A human figure moving through contact poses.
    Humanoid,
    /// A given mesh sequence (`--meshes DIR`, [`sequence`]): a 4D scan or any
    /// fixed-topology sequence, its surfaces kept as the truth.
    Meshes,
}

/// Options of `pipeline synth`.
#[derive(Debug, Clone)]
pub struct SynthOptions {
    pub scene: SceneKind,
    /// Output folder (receives calib/, data/<scene>/ and pipeline.yaml).
    pub out: PathBuf,
    /// Number of cameras on the ring.
    pub cameras: usize,
    /// Image size, pixels.
    pub width: u32,
    pub height: u32,
    /// Number of frames; `None` for the motion's own key frames.
    pub frames: Option<usize>,
    /// Seed of every random choice (camera jitter, noise); same seed, same bytes.
    pub seed: u64,
    /// Spacing of the rest-surface iso-surface grid, metres.
    pub mesh_spacing: f64,
    /// Frames before this index are not written (for quick datasets of late frames; the
    /// written frames keep their indices).
    pub first_frame: usize,
    /// The humanoid's motion.
    pub motion: Motion,
    /// The humanoid's proportions (`--body SEED`: [`humanoid::Proportions::from_seed`]).
    pub proportions: humanoid::Proportions,
    /// The humanoid's dress, if it wears one (`--dress`).
    pub dress: Option<Dress>,
    /// What the humanoid wears (`--look`).
    pub look: Look,
    /// A pose the humanoid holds in every frame instead of a motion (`--pose`).
    pub pose: Option<humanoid::HeldPose>,
    /// Degrees by which the written world is tilted (`--world-tilt`): the calibration and
    /// the truth are turned and moved together, nothing in the files says where up is
    /// (0: the world stands on +z, as pipeline.yaml's world.up says).
    pub world_tilt_deg: f64,
    /// The mesh sequence's folder (`--meshes`, scene `meshes`).
    pub meshes: Option<PathBuf>,
    /// The mesh sequence's up axis (`--mesh-up`).
    pub mesh_up: crate::geometry::axes::UpAxis,
}

impl SynthOptions {
    /// Defaults of the paper's setting: 15 cameras at 1024x768.
    pub fn new(scene: SceneKind, out: impl Into<PathBuf>) -> SynthOptions {
        SynthOptions {
            scene,
            out: out.into(),
            cameras: 15,
            width: 1024,
            height: 768,
            frames: None,
            seed: 0,
            mesh_spacing: 0.01,
            first_frame: 0,
            motion: Motion::Default,
            proportions: Default::default(),
            dress: None,
            look: Look::Costume,
            pose: None,
            world_tilt_deg: 0.0,
            meshes: None,
            mesh_up: crate::geometry::axes::UpAxis::PlusY,
        }
    }
}

/// Builds the scene the options describe (no rendering).
pub fn build_scene(opts: &SynthOptions) -> Result<Scene> {
    if opts.cameras < 2 {
        return Err(Error::Usage("--cameras must be at least 2".into()));
    }
    if opts.width < 16 || opts.height < 16 || opts.width > 8192 || opts.height > 8192 {
        return Err(Error::Usage(
            "--width and --height must be between 16 and 8192".into(),
        ));
    }
    if !(0.002..=0.1).contains(&opts.mesh_spacing) {
        return Err(Error::Usage(
            "--mesh-spacing must be between 0.002 and 0.1 m".into(),
        ));
    }
    if opts.frames == Some(0) {
        return Err(Error::Usage("--frames must be at least 1".into()));
    }
    if opts.proportions != humanoid::Proportions::default() && opts.scene != SceneKind::Humanoid {
        return Err(Error::Usage("--body needs --scene humanoid".into()));
    }
    if opts.dress.is_some() && opts.scene != SceneKind::Humanoid {
        return Err(Error::Usage("--dress needs --scene humanoid".into()));
    }
    if opts.look != Look::Costume && opts.scene != SceneKind::Humanoid {
        return Err(Error::Usage("--look needs --scene humanoid".into()));
    }
    if opts.pose.is_some() && opts.scene != SceneKind::Humanoid {
        return Err(Error::Usage("--pose needs --scene humanoid".into()));
    }
    if opts.pose.is_some() && opts.motion != Motion::Default {
        return Err(Error::Usage(
            "--pose holds one pose in every frame: leave out --motion".into(),
        ));
    }
    if !(opts.world_tilt_deg.is_finite() && (0.0..=90.0).contains(&opts.world_tilt_deg)) {
        return Err(Error::Usage(
            "--world-tilt must be between 0 and 90 degrees".into(),
        ));
    }
    if opts.motion != Motion::Default && opts.scene != SceneKind::Humanoid {
        return Err(Error::Usage(
            "--motion dance, arms-down and walk need --scene humanoid".into(),
        ));
    }
    Ok(match opts.scene {
        SceneKind::Tripod => tripod::scene(
            opts.cameras,
            opts.width,
            opts.height,
            opts.frames.unwrap_or(tripod::KEY_FRAMES),
            opts.seed,
        ),
        SceneKind::Humanoid => humanoid::scene(opts, opts.frames.unwrap_or(key_frames(opts).0)),
        SceneKind::Meshes => {
            return Err(Error::Usage(
                "--scene meshes films a given sequence, not a body: see `generate`".into(),
            ))
        }
    })
}

/// The number of key frames of a scene's motion, and their rate (frames per second) at
/// which its joints move no faster than people do: the tripod's 16 cm steps at 25, the
/// humanoid's hand sweeps of up to 60 cm at 8, the dance's steps of up to 16 cm at 25.
fn key_frames(opts: &SynthOptions) -> (usize, f64) {
    match (opts.scene, opts.motion) {
        (SceneKind::Tripod, _) => (tripod::KEY_FRAMES, 25.0),
        (SceneKind::Meshes, _) => (1, 25.0),
        (SceneKind::Humanoid, _) if opts.pose.is_some() => (1, 8.0),
        (SceneKind::Humanoid, Motion::Dance) => (humanoid::DANCE_KEY_FRAMES, 25.0),
        (SceneKind::Humanoid, Motion::Default) => (humanoid::KEY_FRAMES, 8.0),
        (SceneKind::Humanoid, Motion::ArmsDown) => (humanoid::KEY_FRAMES, 8.0),
        // 15 degrees of the circle (26 cm) a frame: a walk at 4 frames per second.
        (SceneKind::Humanoid, Motion::Walk) => (humanoid::WALK_KEY_FRAMES, 4.0),
    }
}

/// The skinned subject of a scene: rest mesh, weights, per-vertex labels and material.
pub struct Subject {
    pub rest: TriMesh,
    pub weights: Vec<Vec<(usize, f64)>>,
    /// Dominant bone of every vertex.
    pub labels: Vec<usize>,
    /// 1 where the vertex wears the plain material.
    pub plain: Vec<f64>,
    /// Under [`Look::Person`], what each vertex wears.
    pub materials: Option<Vec<texture::Material>>,
    /// The head's centre (rest pose, metres) and radius, metres.
    pub head: Option<(nalgebra::Vector3<f64>, f64)>,
}

impl Subject {
    pub fn new(body: &Body, spacing: f64, look: Look) -> Subject {
        let rest = body.rest_mesh(spacing);
        let weights = body.skin_weights(&rest, 0.025);
        let labels = crate::skeleton::skinning::labels(&weights);
        let plain = weights
            .iter()
            .map(|w| {
                w.iter()
                    .filter(|(b, _)| body.plain[*b])
                    .map(|(_, x)| x)
                    .sum()
            })
            .collect();
        let materials = (look == Look::Person).then(|| person_materials(body, &labels));
        // The head's centre and radius at rest, where the face is drawn.
        let head = (look == Look::Person)
            .then(|| body.skeleton.bone_index("head"))
            .flatten()
            .map(|b| {
                let bone = &body.skeleton.bones[b];
                let (r0, r1) = body.radii[b];
                ((bone.head + bone.tail) / 2.0, r0.max(r1).max(1e-3))
            });
        Subject {
            rest,
            weights,
            labels,
            plain,
            materials,
            head,
        }
    }
}

/// What each rest vertex wears under [`Look::Person`], by its dominant bone: skin on the
/// neck, forearms and hands; a face and hair on the head ([`texture::head_albedo`]); a shirt on the trunk and upper arms; trousers from the hips down; shoes.
fn person_materials(body: &Body, labels: &[usize]) -> Vec<texture::Material> {
    use texture::Material;
    labels
        .iter()
        .map(|&b| {
            let bone = &body.skeleton.bones[b];
            let name = bone.name.as_str();
            match name {
                "head" => Material::Head,
                "neck" => Material::Skin,
                n if n.starts_with("forearm") || n.starts_with("hand") => Material::Skin,
                n if n.starts_with("upper_arm") || n == "chest" || n == "spine" => Material::Shirt,
                n if n.starts_with("foot") => Material::Shoe,
                _ => Material::Trousers,
            }
        })
        .collect()
}

/// What `generate` wrote.
pub struct SynthSummary {
    pub sequence_dir: PathBuf,
    pub pipeline_yaml: PathBuf,
    pub cameras: usize,
    pub frames: usize,
    pub vertices: usize,
    pub seconds: f64,
}

fn progress(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg:>10} [{bar:30}] {pos}/{len} ({eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

/// Renders `meshes` (one per frame, the subject's surface posed) through `cameras` into
/// `seq_dir` (frames, true masks, backgrounds) and writes the true meshes turned by `tilt`
/// (`ground_truth/meshes`); returns the true meshes with their normals, all frames.
fn render_capture(
    opts: &SynthOptions,
    cameras: &[crate::camera::Camera],
    subject: &Subject,
    meshes: Vec<TriMesh>,
    seq_dir: &std::path::Path,
    tilt: &world::WorldTilt,
) -> Result<Vec<(TriMesh, Vec<nalgebra::Vector3<f64>>)>> {
    let stem = crate::dataset::frame_stem;
    let meshes_len = meshes.len();
    let posed: Vec<(TriMesh, Vec<nalgebra::Vector3<f64>>, ShadowMap)> = meshes
        .into_par_iter()
        .map(|mesh| {
            let normals = mesh.vertex_normals();
            let shadow = ShadowMap::new(&mesh);
            (mesh, normals, shadow)
        })
        .collect();
    let views: Vec<CameraView> = cameras
        .par_iter()
        .enumerate()
        .map(|(i, c)| CameraView::new(c, opts.seed, i as u64))
        .collect();

    let nf = meshes_len;
    let nc = cameras.len();
    let first = opts.first_frame.min(nf);
    let bar = progress(((nf - first) * nc) as u64, "rendering");
    let jobs: Vec<(usize, usize)> = (first..nf)
        .flat_map(|f| (0..nc).map(move |c| (c, f)))
        .collect();
    jobs.par_iter().try_for_each(|&(c, f)| -> Result<()> {
        let cam = &cameras[c];
        let (mesh, normals, shadow) = &posed[f];
        let surface = Surface {
            mesh,
            normals,
            rest: &subject.rest.vertices,
            plain: &subject.plain,
            materials: subject.materials.as_deref(),
            head: subject.head,
        };
        // A slight frame-to-frame brightness flicker, as real lighting has.
        let flicker = 1.0 + 0.01 * crate::rng::Rng::new(opts.seed, 500_000 + f as u64).normal();
        let stream = (f * nc + c) as u64;
        let (img, mask) =
            render::render_frame(cam, &views[c], &surface, shadow, flicker, opts.seed, stream);
        let name = format!("{}.png", stem(f as u32));
        crate::imageio::write_rgb(&seq_dir.join("frames").join(&cam.name).join(&name), &img)?;
        crate::imageio::write_gray(&seq_dir.join("masks").join(&cam.name).join(&name), &mask)?;
        bar.inc(1);
        Ok(())
    })?;
    bar.finish_and_clear();

    views.par_iter().enumerate().try_for_each(|(c, view)| {
        let cam = &cameras[c];
        let img =
            render::render_background(view, cam.width, cam.height, opts.seed, 2_000_000 + c as u64);
        crate::imageio::write_rgb(
            &seq_dir.join("background").join(format!("{}.png", cam.name)),
            &img,
        )
    })?;

    // The truth in the written world (the rendered one, untilted).
    let truth: Vec<(TriMesh, Vec<nalgebra::Vector3<f64>>)> = posed
        .par_iter()
        .map(|(mesh, normals, _)| {
            let normals = normals.iter().map(|n| tilt.rotation * n).collect();
            (tilt.mesh(mesh), normals)
        })
        .collect();
    truth
        .par_iter()
        .enumerate()
        .skip(first)
        .try_for_each(|(f, (mesh, normals))| {
            let path = seq_dir
                .join("ground_truth")
                .join("meshes")
                .join(format!("{}.ply", stem(f as u32)));
            let attrs = VertexAttributes {
                normals: Some(normals),
                ..Default::default()
            };
            ply::write_ply(&path, mesh, &attrs, PlyFormat::BinaryLittleEndian)
        })?;
    Ok(truth)
}

/// Renders and writes the dataset. Every file is written atomically.
pub fn generate(opts: &SynthOptions) -> Result<SynthSummary> {
    let start = Instant::now();
    if opts.scene == SceneKind::Meshes || opts.meshes.is_some() {
        return generate_sequence(opts, start);
    }
    let scene = build_scene(opts)?;
    let subject = Subject::new(&scene.body, opts.mesh_spacing, opts.look);
    let seq_dir = opts.out.join("data").join(&scene.name);

    // Posed surfaces and shadows, one per frame.
    let mut meshes: Vec<TriMesh> = (scene.poses.par_iter())
        .map(|p| scene.body.pose_mesh(&subject.rest, &subject.weights, p))
        .collect();
    if let (Some(Dress::Loose), Some(skirt)) = (opts.dress, &scene.body.skirt) {
        let depth: Vec<f64> = (subject.rest.vertices.par_iter())
            .map(|v| scene.body.skirt_depth(v))
            .collect();
        let rate = frame_rate(scene.poses.len(), opts);
        dress::swing(&mut meshes, &depth, skirt.length, rate);
    }
    let tilt = world::WorldTilt::new(opts.world_tilt_deg);
    let truth = render_capture(opts, &scene.cameras, &subject, meshes, &seq_dir, &tilt)?;
    let (nf, nc) = (scene.poses.len(), scene.cameras.len());
    let first = opts.first_frame.min(nf);

    let joints: Vec<Vec<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)>> = (scene.poses.iter())
        .map(|p| {
            (scene.body.joints(p).iter())
                .map(|(h, t)| (tilt.point(h), tilt.point(t)))
                .collect()
        })
        .collect();
    let mut rows = Vec::new();
    for (f, frame_joints) in joints.iter().enumerate().skip(first) {
        for (b, &(head, tail)) in frame_joints.iter().enumerate() {
            rows.push(JointRow {
                frame: f as u32,
                bone: scene.body.skeleton.bones[b].name.clone(),
                head,
                tail,
            });
        }
    }
    crate::joints::write(&seq_dir.join("ground_truth").join("joints.csv"), &rows)?;
    // skeleton.yaml: the reference frame's joints; the poses relative to them.
    let reference = scene.body.skeleton.reference_frame as usize;
    let mut skeleton = scene.body.skeleton.clone();
    for (bone, &(head, tail)) in skeleton.bones.iter_mut().zip(&joints[reference]) {
        (bone.head, bone.tail) = (head, tail);
    }
    let root = (skeleton.bones.iter().position(|b| b.parent.is_none())).unwrap_or(0);
    let local: Vec<(u32, crate::skeleton::Pose)> = (scene.poses.iter().enumerate().skip(first))
        .map(|(f, p)| {
            let from = &scene.poses[reference];
            let relative = body::Pose {
                rotations: (p.rotations.iter().zip(&from.rotations))
                    .map(|(g, g0)| tilt.rotation * g * g0.inverse() * tilt.rotation.inverse())
                    .collect(),
                root_translation: joints[f][root].0 - joints[reference][root].0,
            };
            (f as u32, relative.to_local(&skeleton))
        })
        .collect();
    crate::poses::write(
        &seq_dir.join("ground_truth").join("poses.csv"),
        &skeleton,
        &local,
    )?;
    tilt.write_truth(&seq_dir.join("ground_truth").join("world.yaml"))?;
    skeleton.write(&seq_dir.join("skeleton.yaml"))?;
    let cameras: Vec<crate::camera::Camera> =
        scene.cameras.iter().map(|c| tilt.camera(c)).collect();
    crate::camera::write_cameras(&opts.out.join("calib").join("cameras.yaml"), &cameras)?;
    let pipeline_yaml = opts.out.join("pipeline.yaml");
    let bounds = truth
        .iter()
        .skip(first)
        .filter_map(|(mesh, _)| mesh.bounds())
        .reduce(|(a, b), (c, d)| (a.inf(&c), b.sup(&d)));
    crate::fsutil::write_atomic(
        &pipeline_yaml,
        format!(
            "{}{}{}",
            crate::config::default_yaml("calib/cameras.yaml", &format!("data/{}", scene.name)),
            box_yaml(&cameras, &seq_dir, first as u32, bounds)?,
            synth_export_yaml(nf, opts)
        )
        .as_bytes(),
    )?;
    Ok(SynthSummary {
        sequence_dir: seq_dir,
        pipeline_yaml,
        cameras: nc,
        frames: nf - first,
        vertices: subject.rest.vertices.len(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// `generate` for a given mesh sequence ([`sequence`]): the rig around it, its frames,
/// masks and plates rendered, its surfaces written as the truth, and a pipeline.yaml
/// (without skeleton.yaml: `pipeline skeleton` makes one).
fn generate_sequence(opts: &SynthOptions, start: Instant) -> Result<SynthSummary> {
    let humanoid_only = opts.motion != Motion::Default
        || opts.dress.is_some()
        || opts.look != Look::Costume
        || opts.pose.is_some()
        || opts.proportions != humanoid::Proportions::default();
    if humanoid_only {
        return Err(Error::Usage(
            "--motion, --dress, --look, --pose and --body are the humanoid's: leave them out \
             with --meshes"
                .into(),
        ));
    }
    let (Some(dir), SceneKind::Meshes) = (&opts.meshes, opts.scene) else {
        return Err(Error::Usage(
            "a mesh sequence is filmed with --scene meshes --meshes DIR".into(),
        ));
    };
    if opts.cameras < 2 || !(16..=8192).contains(&opts.width) || !(16..=8192).contains(&opts.height)
    {
        return Err(Error::Usage(
            "--cameras must be at least 2, --width and --height between 16 and 8192".into(),
        ));
    }
    if opts.frames == Some(0) {
        return Err(Error::Usage("--frames must be at least 1".into()));
    }
    let meshes = sequence::read(dir, opts.mesh_up, opts.frames)?;
    let name = dir
        .file_name()
        .and_then(|n| n.to_str())
        .filter(|n| crate::camera::check_name(n).is_ok() && !n.starts_with('.'))
        .unwrap_or("meshes")
        .to_string();
    // The rig's ring around the whole motion: aimed at the middle of its height, far
    // enough that the tallest frame fits the image's height with 30 cm to spare.
    let (lo, hi) = meshes
        .iter()
        .filter_map(|m| m.bounds())
        .reduce(|(a, b), (c, d)| (a.inf(&c), b.sup(&d)))
        .expect("the sequence has vertices");
    let focal = 1100.0 * opts.width as f64 / 1024.0;
    let half_view = (opts.height as f64 / 2.0 / focal).atan();
    let reach = (lo.xy().norm()).max(hi.xy().norm());
    let radius = ((hi.z - lo.z) / 2.0 + 0.3) / half_view.tan() + reach;
    let cameras = scene::camera_ring(
        &scene::RingSpec {
            count: opts.cameras,
            radius: radius.max(4.0),
            heights: vec![1.2, 1.7, 2.4],
            target: nalgebra::Vector3::new(0.0, 0.0, (lo.z + hi.z) / 2.0),
            focal_1024: 1100.0,
            width: opts.width,
            height: opts.height,
        },
        opts.seed,
    );
    let n = meshes[0].vertices.len();
    let subject = Subject {
        rest: meshes[0].clone(),
        weights: Vec::new(),
        labels: Vec::new(),
        plain: vec![0.0; n],
        materials: None,
        head: None,
    };
    let seq_dir = opts.out.join("data").join(&name);
    let tilt = world::WorldTilt::new(opts.world_tilt_deg);
    let nf = meshes.len();
    let truth = render_capture(opts, &cameras, &subject, meshes, &seq_dir, &tilt)?;
    let first = opts.first_frame.min(nf);
    tilt.write_truth(&seq_dir.join("ground_truth").join("world.yaml"))?;
    let cameras: Vec<crate::camera::Camera> = cameras.iter().map(|c| tilt.camera(c)).collect();
    crate::camera::write_cameras(&opts.out.join("calib").join("cameras.yaml"), &cameras)?;
    let pipeline_yaml = opts.out.join("pipeline.yaml");
    let bounds = (truth.iter().skip(first))
        .filter_map(|(mesh, _)| mesh.bounds())
        .reduce(|(a, b), (c, d)| (a.inf(&c), b.sup(&d)));
    let up = if opts.world_tilt_deg == 0.0 {
        "world:\n  up: +z              # the sequence stands on +z here; the exports turn it to +Y\n"
    } else {
        ""
    };
    crate::fsutil::write_atomic(
        &pipeline_yaml,
        format!(
            "{}{}{up}# the sequence's frame rate is not known here: set export.frame_rate\n",
            crate::config::default_yaml("calib/cameras.yaml", &format!("data/{name}")),
            box_yaml(&cameras, &seq_dir, first as u32, bounds)?,
        )
        .as_bytes(),
    )?;
    Ok(SynthSummary {
        sequence_dir: seq_dir,
        pipeline_yaml,
        cameras: cameras.len(),
        frames: nf - first,
        vertices: n,
        seconds: start.elapsed().as_secs_f64(),
    })
}
