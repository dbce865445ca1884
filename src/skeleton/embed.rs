//! An automatic skeleton (`pipeline skeleton`): a template skeleton scaled, turned and
//! embedded in the reference frame's closed surface, in the spirit of Pinocchio (Baran and
//! Popović 2007): bones along the surface's medial axis, lengths and offsets near the
//! template's.
//!
//! 1. The surface is voxelized (1 cm, or coarser for big subjects) and its interior depth
//!    D (the distance to the surface, positive inside) taken by an exact distance
//!    transform. The medial axis is where D is largest across a part.
//! 2. **Placement.** The template, with the world's up axis kept, is scaled so that its
//!    joints span [`JOINT_SPAN`] of the surface's height, its lowest joint just above the
//!    interior's bottom, centred on the interior, and turned so that its left-right axis
//!    (from its `_l`/`_r` bone pairs) lies along the interior's widest horizontal axis;
//!    both facings and five scales are tried, each with its limbs swung (step 3), and the
//!    placement with the most of its bones inside (depth capped) wins.
//! 3. **Limbs.** Each limb (a left/right pair's top bone with everything below it) is
//!    swung about its root joint in the frontal plane, from -60 to +60 degrees, to the
//!    angle where most of it lies inside (depth capped, so that it does not dive into the
//!    torso): an A-pose template finds the arms of a T-pose (unit test: mean 1.8 cm, worst
//!    4.1 cm).
//! 4. **Refinement.** Each limb is first lengthened to the length the energy below
//!    prefers (a straight limb has nothing along it to mark its joints). Then every joint
//!    moves by gradient descent on the negated mean depth along the bones (each point's
//!    depth capped a little above the bone's start depth,
//!    so that a bone is drawn onto its own part's axis and not into a thicker neighbour),
//!    plus priors: within each chain (an unbranched run of bones) the template's length
//!    proportions, the chain's length near the placement's scale (weakly), a head apart
//!    from its parent's tail (a shoulder, a hip) at its template offset, and each end
//!    bone's tail about its part's radius short of the part's end (a capsule's cap).
//! 5. **Checks.** A bone whose points are not inside, a hand or foot whose tail lies as
//!    deep as the torso (a limb fused to the body), left and right limbs whose lengths
//!    differ by more than [`LIMB_ASYMMETRY`], or more than [`UNCOVERED_SHARE`] of the
//!    surface far from every bone and from the web between the legs (a dress) refuse the
//!    embedding with a message; the share left unexplained is reported (a limb the
//!    template could not follow: hands on the hips, crossed forearms).

use super::{Bone, Skeleton};
use crate::error::Refusal;
use crate::geometry::grid::GridSpec;
use crate::geometry::TriMesh;
use nalgebra::{Rotation3, Vector2, Vector3};

/// The template's joints span this share of the body's height (the feet's joints lie a few
/// centimetres above the floor, the head's tail a few below its top; the built-in
/// humanoid: 1.685 of 1.815 m).
pub const JOINT_SPAN: f64 = 0.93;

/// The template's lowest joint lies this share of the body's height above its lowest point
/// (the toes' joints above the soles; the built-in humanoid: 3.5 of 181.5 cm).
pub const FOOT_MARGIN: f64 = 0.02;

/// Refusal: left and right limbs whose lengths differ by more than this share.
pub const LIMB_ASYMMETRY: f64 = 0.2;

/// Refusal: a limb shorter than this share of the length the trunk calls for (the
/// template's limb scaled as the trunk came out).
pub const LIMB_SHORTEST: f64 = 0.6;

/// Weights of the refinement's terms (step 4 of the module's notes): bone lengths within
/// their chain, each chain's length against the placement's scale, heads apart from their
/// parent's tail, and the end bones' reach.
const LENGTH_WEIGHT: f64 = 0.02;
const CHAIN_WEIGHT: f64 = 0.002;
const OFFSET_WEIGHT: f64 = 0.01;
const REACH_WEIGHT: f64 = 2.0;

/// The depth cap of the limbs' swing, metres: thinner than any limb.
const SWING_CAP: f64 = 0.015;

/// The refinement caps each bone's depth at this times its mean depth at the start (at
/// least [`SWING_CAP`]): a bone is drawn onto its own part's axis, not into a thicker
/// neighbour.
const REFINE_CAP: f64 = 1.25;

/// Gradient steps of the refinement at most.
const REFINE_ITERATIONS: usize = 2000;

/// Limb lengths tried (1 to 1.2 of the start's, in this many steps) before the descent.
const LIMB_SCALES: usize = 35;

/// Points sampled along each bone.
const SAMPLES: usize = 8;

/// The finest voxel and the most voxels along the longest side.
const FINEST_VOXEL: f64 = 0.01;
const MOST_VOXELS: f64 = 300.0;

/// The surface's interior as a depth field, in the frame where up is +z.
struct Interior {
    grid: GridSpec,
    /// Depth at voxel centres, metres: positive inside, negative outside.
    depth: Vec<f32>,
}

impl Interior {
    fn new(surface: &TriMesh) -> Result<Interior, Refusal> {
        let (mut lo, mut hi) = (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        );
        for v in &surface.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        if surface.triangles.is_empty() || !(hi - lo).iter().all(|e| e.is_finite() && *e > 0.0) {
            return Err("the reference surface is empty".into());
        }
        let voxel = FINEST_VOXEL.max((hi - lo).max() / MOST_VOXELS);
        let margin = Vector3::repeat(3.0 * voxel);
        let grid = GridSpec::covering(lo - margin, hi + margin, voxel);
        let occupied = occupancy(&grid, surface);
        if !occupied.iter().any(|&o| o) {
            return Err("the reference surface encloses no volume".into());
        }
        let depth = crate::geometry::distance::signed_distance(&grid, &occupied)
            .into_iter()
            .map(|d| -d)
            .collect();
        Ok(Interior { grid, depth })
    }

    /// D at `p`, metres (trilinear; far outside beyond the grid).
    fn at(&self, p: &Vector3<f64>) -> f64 {
        self.grid.interpolate(&self.depth, p, -1.0) as f64
    }

    /// The centres of the voxels at least one voxel deep.
    fn inside_points(&self) -> Vec<Vector3<f64>> {
        let g = &self.grid;
        (0..g.len())
            .filter(|&i| self.depth[i] as f64 >= g.voxel)
            .map(|i| {
                let [x, y, z] = g.coords(i);
                g.centre(x, y, z)
            })
            .collect()
    }
}

/// Voxels whose centre lies inside the closed `surface`: along each vertical column of
/// centres, the surface's crossings are collected and the centres between the first and
/// second, third and fourth, ... are inside (even-odd rule).
fn occupancy(grid: &GridSpec, surface: &TriMesh) -> Vec<bool> {
    let [nx, ny, nz] = grid.dims;
    let mut crossings: Vec<Vec<f64>> = vec![Vec::new(); nx * ny];
    // Column centres nudged off the lattice, so that no column passes exactly through an
    // edge or a vertex of the (often grid-aligned) surface.
    let nudge = Vector2::new(0.5 + 1.3e-4, 0.5 + 2.9e-4);
    let column = |i: f64, j: f64| {
        Vector2::new(
            grid.origin.x + (i + nudge.x) * grid.voxel,
            grid.origin.y + (j + nudge.y) * grid.voxel,
        )
    };
    for t in &surface.triangles {
        let [a, b, c] = t.map(|i| surface.vertices[i as usize]);
        let (pa, pb, pc) = (a.xy(), b.xy(), c.xy());
        let area = (pb - pa).perp(&(pc - pa));
        if area.abs() < 1e-18 {
            continue;
        }
        let lo = pa.inf(&pb).inf(&pc);
        let hi = pa.sup(&pb).sup(&pc);
        let to_index = |v: f64, o: f64, n: f64| ((v - o) / grid.voxel - n).floor();
        let i0 = to_index(lo.x, grid.origin.x, nudge.x).max(0.0) as usize;
        let j0 = to_index(lo.y, grid.origin.y, nudge.y).max(0.0) as usize;
        let i1 = (to_index(hi.x, grid.origin.x, nudge.x) + 1.0).min(nx as f64 - 1.0);
        let j1 = (to_index(hi.y, grid.origin.y, nudge.y) + 1.0).min(ny as f64 - 1.0);
        if i1 < 0.0 || j1 < 0.0 {
            continue;
        }
        for j in j0..=j1 as usize {
            for i in i0..=i1 as usize {
                let q = column(i as f64, j as f64);
                let wa = (pb - q).perp(&(pc - q)) / area;
                let wb = (pc - q).perp(&(pa - q)) / area;
                let wc = 1.0 - wa - wb;
                if wa >= 0.0 && wb >= 0.0 && wc >= 0.0 {
                    crossings[j * nx + i].push(wa * a.z + wb * b.z + wc * c.z);
                }
            }
        }
    }
    let mut occupied = vec![false; grid.len()];
    for (col, zs) in crossings.iter_mut().enumerate() {
        zs.sort_by(f64::total_cmp);
        let (i, j) = (col % nx, col / nx);
        for pair in zs.chunks_exact(2) {
            for k in 0..nz {
                let z = grid.origin.z + (k as f64 + 0.5) * grid.voxel;
                if z > pair[0] && z < pair[1] {
                    occupied[grid.index(i, j, k)] = true;
                }
            }
        }
    }
    occupied
}

/// A skeleton as points: each bone's head and tail are indices into the points (a child
/// whose head is its parent's tail shares that point).
#[derive(Clone)]
struct Joints {
    points: Vec<Vector3<f64>>,
    /// (head, tail) per bone.
    ends: Vec<(usize, usize)>,
}

impl Joints {
    fn of(bones: &[Bone]) -> Joints {
        let mut points: Vec<Vector3<f64>> = Vec::new();
        let mut index = |p: Vector3<f64>| match points.iter().position(|q| (q - p).norm() < 1e-6) {
            Some(i) => i,
            None => {
                points.push(p);
                points.len() - 1
            }
        };
        let ends = bones
            .iter()
            .map(|b| (index(b.head), index(b.tail)))
            .collect();
        Joints { points, ends }
    }

    fn bone(&self, b: usize) -> (Vector3<f64>, Vector3<f64>) {
        (self.points[self.ends[b].0], self.points[self.ends[b].1])
    }

    /// Mean depth along bone `b`, each point's depth capped at `cap` metres (outside
    /// counts five times: bones must stay inside).
    fn bone_depth(&self, interior: &Interior, b: usize, cap: f64) -> f64 {
        let (h, t) = self.bone(b);
        (0..SAMPLES)
            .map(|k| {
                let d = interior.at(&(h + (t - h) * ((k as f64 + 0.5) / SAMPLES as f64)));
                if d < 0.0 {
                    5.0 * d
                } else {
                    d.min(cap)
                }
            })
            .sum::<f64>()
            / SAMPLES as f64
    }

    /// The sum of the bones' mean depths (bone b's capped at `caps[b]`), each weighted by
    /// its template length share.
    fn depth(&self, interior: &Interior, weights: &[f64], caps: &[f64]) -> f64 {
        (0..self.ends.len())
            .map(|b| weights[b] * self.bone_depth(interior, b, caps[b]))
            .sum()
    }
}

/// Embeds `template` in the closed `surface` (world metres) whose up direction is `up`;
/// the result keeps the template's bones, names, parents and `reference_frame`. Refuses,
/// with a message naming the problem, a surface it cannot embed the template in.
pub fn embed(
    template: &Skeleton,
    surface: &TriMesh,
    up: Vector3<f64>,
) -> Result<Skeleton, Refusal> {
    embed_scored(template, surface, up).map(|e| e.skeleton)
}

/// An embedded skeleton and how much of the surface it leaves unexplained.
#[derive(Debug, Clone)]
pub struct Embedding {
    pub skeleton: Skeleton,
    /// The share of the surface farther than [`UNCOVERED_EXCESS`] beyond every bone's part
    /// (below [`UNCOVERED_SHARE`], else the embedding is refused).
    pub uncovered_share: f64,
}

/// [`embed`], with the embedding's coverage of the surface.
pub fn embed_scored(
    template: &Skeleton,
    surface: &TriMesh,
    up: Vector3<f64>,
) -> Result<Embedding, Refusal> {
    embed_from(template, surface, up, None)
}

/// [`embed_scored`] from a first guess `start` (the template's bones, placed in the world
/// by other evidence, as the person model's keypoints) instead of the template's own
/// placement: the guess is refined in the surface (step 4 on) and checked as any embedding.
pub fn embed_from(
    template: &Skeleton,
    surface: &TriMesh,
    up: Vector3<f64>,
    start: Option<&Skeleton>,
) -> Result<Embedding, Refusal> {
    if template.bones.is_empty() {
        return Err("the template has no bones".into());
    }
    let to_z = Rotation3::rotation_between(&up.normalize(), &Vector3::z())
        .unwrap_or_else(|| Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
    let local = TriMesh {
        vertices: surface.vertices.iter().map(|v| to_z * v).collect(),
        triangles: surface.triangles.clone(),
    };
    let interior = Interior::new(&local)?;
    let bones: Vec<Bone> = template
        .bones
        .iter()
        .map(|b| Bone {
            head: to_z * b.head,
            tail: to_z * b.tail,
            ..b.clone()
        })
        .collect();
    let tpl = Joints::of(&bones);
    let lengths: Vec<f64> = bones.iter().map(|b| b.length()).collect();
    let total: f64 = lengths.iter().sum::<f64>().max(1e-9);
    let weights: Vec<f64> = lengths.iter().map(|l| l / total).collect();

    // The starts: the first guess (the person model's keypoints: its joints, at its own
    // scale) when there is one, and the template's own placement in the interior.
    let mut starts: Vec<(Joints, f64)> = Vec::new();
    if let Some(start) = start {
        if start.bones.len() != template.bones.len() {
            return Err("the first guess does not have the template's bones".into());
        }
        let mut joints = tpl.clone();
        for (b, bone) in start.bones.iter().enumerate() {
            joints.points[tpl.ends[b].0] = to_z * bone.head;
            joints.points[tpl.ends[b].1] = to_z * bone.tail;
        }
        let guessed: f64 = start.bones.iter().map(|b| b.length()).sum();
        starts.push((joints, guessed / total));
    }
    let placed = place(&interior, template, &tpl, &weights);
    let mut refusals: Vec<String> = Vec::new();
    match placed {
        Ok(p) => starts.push(p),
        Err(e) if starts.is_empty() => return Err(e),
        Err(e) => refusals.push(format!("the template's own placement: {e}")),
    }
    // The surface's extremities, seen from the torso of the template's own placement (the
    // guess's where that failed).
    let own = &starts.last().expect("a start, or returned above").0;
    let tips = limb_extremities(&interior, template, own);
    let finish = |joints: Joints, scale: f64| -> Result<(Joints, f64, Unheld), Refusal> {
        let refined = descend_joints(&interior, template, &tpl, joints, scale, &weights);
        check(&interior, template, &refined)?;
        let uncovered = check_coverage(&interior, template, &refined, &local)?;
        let empty = unheld(template, &refined, &tips);
        Ok((refined, uncovered, empty))
    };
    // From each start two tries: its own pose, and its limbs followed through the interior
    // to the surface's extremities (a real body's limbs raised, forward or bent). The one
    // that leaves fewer limb-shaped extremities without a bone wins, then the one that
    // leaves less of the surface unexplained; the earlier on a tie.
    let mut best: Option<(Joints, f64, Unheld)> = None;
    for (placed, scale) in starts {
        let followed = follow_limbs(template, placed.clone(), &tips);
        for tried in [finish(placed, scale), finish(followed, scale)] {
            match tried {
                Ok(t) => {
                    if best
                        .as_ref()
                        .is_none_or(|b| (t.2.rank(), t.1) < (b.2.rank(), b.1))
                    {
                        best = Some(t);
                    }
                }
                Err(e) => refusals.push(e.0),
            }
        }
    }
    let Some((refined, uncovered_share, empty)) = best else {
        let last = refusals.pop().unwrap_or_default();
        return Err(if refusals.is_empty() {
            last.into()
        } else {
            format!("{last} (other tries: {})", refusals.join("; ")).into()
        });
    };
    if let (true, Some(&e)) = (empty.misplaced, empty.parts.first()) {
        let tip = tips[e].path.last().copied().unwrap_or_default();
        let tip = to_z.inverse() * tip;
        return Err(format!(
            "a limb-shaped part of the surface ({:.0} cm long, its end at ({:.2}, {:.2}, \
             {:.2})) holds no bone while '{}' lies in no limb{}: the template's limbs could \
             not be laid in this body's limbs (a hand touching the body, as hands on the \
             hips, closes a loop the template cannot follow); choose a frame where the arms \
             and legs stand clear of the torso with --frame, or check the world's up",
            100.0 * tips[e].length,
            tip.x,
            tip.y,
            tip.z,
            template.bones[empty.limbs[0]].name,
            if empty.parts.len() > 1 {
                format!(" ({} such parts)", empty.parts.len())
            } else {
                String::new()
            }
        )
        .into());
    }
    let from_z = to_z.inverse();
    let skeleton = Skeleton {
        reference_frame: template.reference_frame,
        bones: template
            .bones
            .iter()
            .enumerate()
            .map(|(b, bone)| {
                let (h, t) = refined.bone(b);
                Bone {
                    head: from_z * h,
                    tail: from_z * t,
                    ..bone.clone()
                }
            })
            .collect(),
    };
    Ok(Embedding {
        skeleton,
        uncovered_share,
    })
}

/// The template's left-right axis in its horizontal plane (left minus right heads of its
/// pairs), if it has pairs.
fn left_right_axis(template: &Skeleton, tpl: &Joints) -> Option<Vector2<f64>> {
    let mut sum = Vector2::zeros();
    for (l, bone) in template.bones.iter().enumerate() {
        let Some(r) = super::sides::other_side(&bone.name).and_then(|n| template.bone_index(&n))
        else {
            continue;
        };
        if super::sides::is_left(&bone.name) {
            sum += (tpl.bone(l).0 - tpl.bone(r).0).xy();
        }
    }
    (sum.norm() > 1e-9).then(|| sum.normalize())
}

/// The least width of a body's interior, as a share of its height.
const MIN_WIDTH_SHARE: f64 = 0.12;

/// Steps 2 and 3: the template scaled, turned and moved into the interior, its limbs
/// swung; the deepest of the tried placements, and its scale.
fn place(
    interior: &Interior,
    template: &Skeleton,
    tpl: &Joints,
    weights: &[f64],
) -> Result<(Joints, f64), Refusal> {
    let inside = interior.inside_points();
    if inside.len() < 10 {
        return Err("the reference surface is too thin to hold a skeleton".into());
    }
    let n = inside.len() as f64;
    let centre = inside.iter().sum::<Vector3<f64>>() / n;
    let (zmin, zmax) = inside
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.z), b.max(p.z))
        });
    // The widest horizontal axis of the interior.
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in &inside {
        let d = p - centre;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let widest = Vector2::new(angle.cos(), angle.sin());
    // A body is at least shoulder-wide (about a quarter of its height, arms down): a pole
    // or a stick is not a body the template fits.
    let (wmin, wmax) = inside
        .iter()
        .map(|p| (p - centre).xy().dot(&widest))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), w| {
            (a.min(w), b.max(w))
        });
    let (width, tall) = (
        wmax - wmin + interior.grid.voxel,
        zmax - zmin + interior.grid.voxel,
    );
    if width < MIN_WIDTH_SHARE * tall {
        return Err(format!(
            "the reference surface is {:.0} cm wide and {:.0} cm tall: too thin for a body (a \
             body is at least {:.0}% as wide as it is tall); is the subject in this frame, and \
             world.up right?",
            100.0 * width,
            100.0 * tall,
            100.0 * MIN_WIDTH_SHARE
        )
        .into());
    }
    let template_axis = left_right_axis(template, tpl).unwrap_or_else(Vector2::x);
    let (tzmin, tzmax) = tpl
        .points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.z), b.max(p.z))
        });
    if tzmax - tzmin < 1e-6 {
        return Err(
            "the template's joints all lie at one height: is its up axis the capture's?".into(),
        );
    }
    let template_centre = tpl.points.iter().sum::<Vector3<f64>>() / tpl.points.len() as f64;
    // Placements are compared by the depth along the bones capped at SWING_CAP (how much
    // of the skeleton lies inside), the scale nearest the height's winning ties:
    // uncapped, a scale that lifts the chest into a T-pose's wide shoulders would win.
    let caps = vec![SWING_CAP; weights.len()];
    let limbs = limbs(template);
    // The surface's interior spans about a voxel less than the body at each end.
    let height = zmax - zmin + interior.grid.voxel;
    let s0 = JOINT_SPAN * height / (tzmax - tzmin);
    let mut best: Option<(f64, Joints, f64)> = None;
    for facing in [widest, -widest] {
        let yaw = facing.y.atan2(facing.x) - template_axis.y.atan2(template_axis.x);
        let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
        for factor in [1.0, 0.96, 1.04, 0.92, 1.08] {
            let s = s0 * factor;
            // The lowest joint just above the interior's bottom.
            let floor = zmin - 0.5 * interior.grid.voxel + FOOT_MARGIN * height;
            let points = tpl
                .points
                .iter()
                .map(|p| {
                    let mut d = p - template_centre;
                    d.z = p.z - tzmin;
                    let q = turn * (d * s);
                    Vector3::new(centre.x + q.x, centre.y + q.y, floor + q.z)
                })
                .collect();
            let joints = Joints {
                points,
                ends: tpl.ends.clone(),
            };
            // Each placement's limbs swung first (step 3): limbs the template holds
            // differently would otherwise steer the choice.
            let joints = swing_limbs(interior, &limbs, joints, weights);
            let depth = joints.depth(interior, weights, &caps);
            if best
                .as_ref()
                .is_none_or(|b| depth > b.0 * (1.0 + 1e-3) + 1e-9)
            {
                best = Some((depth, joints, s));
            }
        }
    }
    let (_, joints, s) = best.expect("placements were tried");
    Ok((joints, s))
}

/// The limbs: each left/right pair's top bone (a paired bone whose parent is not paired)
/// with the bones below it.
fn limbs(template: &Skeleton) -> Vec<Vec<usize>> {
    let children = template.children();
    let paired = |b: usize| {
        super::sides::other_side(&template.bones[b].name)
            .and_then(|n| template.bone_index(&n))
            .is_some()
    };
    (0..template.bones.len())
        .filter(|&b| paired(b) && template.bones[b].parent.is_none_or(|p| !paired(p)))
        .map(|top| {
            let mut limb = vec![top];
            let mut i = 0;
            while i < limb.len() {
                limb.extend(children[limb[i]].iter().copied());
                i += 1;
            }
            limb
        })
        .collect()
}

/// Step 3: each of the `limbs` ([`limbs`]) swung about its root joint in the frontal
/// plane to its deepest angle.
fn swing_limbs(
    interior: &Interior,
    limbs: &[Vec<usize>],
    mut joints: Joints,
    weights: &[f64],
) -> Joints {
    let centre = joints.points.iter().sum::<Vector3<f64>>() / joints.points.len() as f64;
    for limb in limbs {
        let root = joints.ends[limb[0]].0;
        let pivot = joints.points[root];
        // The frontal plane's normal: horizontal, across the line from the body's centre to
        // the limb's root.
        let out = pivot - centre;
        let axis = Vector3::new(-out.y, out.x, 0.0);
        if axis.norm() < 1e-9 {
            continue;
        }
        let axis = nalgebra::Unit::new_normalize(axis);
        let moved: Vec<usize> = {
            let mut m: Vec<usize> = limb
                .iter()
                .flat_map(|&b| [joints.ends[b].0, joints.ends[b].1])
                .filter(|&p| p != root)
                .collect();
            m.sort_unstable();
            m.dedup();
            m
        };
        let original = joints.clone();
        // Depth capped at SWING_CAP: a limb is as good anywhere it lies wholly inside
        // (uncapped, it would dive into the thicker torso); the smallest swing wins a tie.
        let limb_depth = |j: &Joints| {
            limb.iter()
                .map(|&b| weights[b] * j.bone_depth(interior, b, SWING_CAP))
                .sum::<f64>()
        };
        let mut best = (limb_depth(&joints), 0.0);
        for step in [1, -1, 2, -2, 3, -3, 4, -4, 5, -5, 6, -6] {
            let angle = (10.0 * step as f64).to_radians();
            let turn = Rotation3::from_axis_angle(&axis, angle);
            let mut trial = original.clone();
            for &p in &moved {
                trial.points[p] = pivot + turn * (original.points[p] - pivot);
            }
            let d = limb_depth(&trial);
            if d > best.0 * (1.0 + 1e-3) + 1e-9 {
                best = (d, angle);
            }
        }
        let turn = Rotation3::from_axis_angle(&axis, best.1);
        for &p in &moved {
            joints.points[p] = pivot + turn * (original.points[p] - pivot);
        }
    }
    joints
}

/// The chains that end in a leaf bone (a hand, a foot, the head), each from the bone
/// below its branching parent down to the leaf, in order.
fn end_chains(template: &Skeleton) -> Vec<Vec<usize>> {
    let children = template.children();
    (0..template.bones.len())
        .filter(|&b| children[b].is_empty())
        .map(|leaf| {
            let mut chain = vec![leaf];
            while let Some(p) = template.bones[*chain.last().expect("a leaf")].parent {
                if children[p].len() != 1 {
                    break;
                }
                chain.push(p);
            }
            chain.reverse();
            chain
        })
        .collect()
}

/// The interior's extremities ([`super::follow::extremities`]) from the torso of the
/// placed `joints` (the bones in no end chain).
fn limb_extremities(
    interior: &Interior,
    template: &Skeleton,
    joints: &Joints,
) -> Vec<super::follow::Extremity> {
    let chains = end_chains(template);
    let in_chain: Vec<usize> = chains.iter().flatten().copied().collect();
    let torso: Vec<usize> = (0..template.bones.len())
        .filter(|b| !in_chain.contains(b))
        .collect();
    if torso.is_empty() || chains.is_empty() {
        return Vec::new();
    }
    let near = torso
        .iter()
        .map(|&b| {
            let (h, t) = joints.bone(b);
            (h + t) / 2.0
        })
        .sum::<Vector3<f64>>()
        / torso.len() as f64;
    let field = super::follow::Field {
        grid: &interior.grid,
        depth: &interior.depth,
    };
    super::follow::extremities(&field, &near, 0.2)
}

/// An extremity is held when an end chain's last bone (a hand, a foot, the head) passes
/// within this of its tip, metres.
const TIP_HELD: f64 = 0.12;

/// How the limbs of `joints` sit in the surface's extremities `tips`: the limb-shaped
/// extremities ([`super::follow::Extremity::limb_shaped`]) that no end chain's last bone
/// holds, and the arms and legs (end chains of a left/right pair) whose last bone holds
/// none; each last bone holds at most one extremity, the nearest pairs first.
fn unheld(template: &Skeleton, joints: &Joints, tips: &[super::follow::Extremity]) -> Unheld {
    let leaves: Vec<usize> = end_chains(template)
        .iter()
        .filter_map(|c| c.last().copied())
        .collect();
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (e, tip) in tips.iter().enumerate() {
        let Some(end) = tip.path.last().filter(|_| tip.limb_shaped()) else {
            continue;
        };
        for (l, &b) in leaves.iter().enumerate() {
            let (h, t) = joints.bone(b);
            let d = t - h;
            let s = ((end - h).dot(&d) / d.norm_squared().max(1e-18)).clamp(0.0, 1.0);
            let gap = (end - (h + d * s)).norm();
            if gap <= TIP_HELD {
                pairs.push((gap, e, l));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut tip_held, mut leaf_used) = (vec![false; tips.len()], vec![false; leaves.len()]);
    for (_, e, l) in pairs {
        if !tip_held[e] && !leaf_used[l] {
            (tip_held[e], leaf_used[l]) = (true, true);
        }
    }
    let parts: Vec<usize> = (0..tips.len())
        .filter(|&e| !tip_held[e] && tips[e].limb_shaped())
        .collect();
    let chains = end_chains(template);
    let limbs: Vec<usize> = (0..leaves.len())
        .filter(|&l| !leaf_used[l])
        .map(|l| leaves[l])
        .filter(|&b| super::sides::other_side(&template.bones[b].name).is_some())
        .collect();
    // An arm in no part is misplaced when an empty part could be its own: the part's path
    // passes the arm's root and offers about its length beyond it. (Legs are not judged
    // so: a dress hides the legs' extremities, and a real hull's phantom sheets along the
    // floor look like legs.)
    let shoulders = shoulder_line(joints);
    let misplaced = limbs.iter().any(|&leaf| {
        let Some(chain) = chains.iter().find(|c| c.last() == Some(&leaf)) else {
            return false;
        };
        let root = joints.bone(chain[0]).0;
        if root.z < shoulders {
            return false;
        }
        let length: f64 = chain
            .iter()
            .map(|&b| {
                let (h, t) = joints.bone(b);
                (t - h).norm()
            })
            .sum();
        parts
            .iter()
            .any(|&e| limb_path_cost(&tips[e].path, &root, length) < 1.0)
    });
    Unheld {
        parts,
        limbs,
        misplaced,
    }
}

/// How badly a limb of `length` metres from joint `root` fits along an extremity's `path`:
/// 0 when the path passes through the root and offers exactly the length beyond it; 1 or
/// more is no fit.
fn limb_path_cost(path: &[Vector3<f64>], root: &Vector3<f64>, length: f64) -> f64 {
    use super::follow;
    let start = follow::nearest_on(path, root);
    let available = follow::remaining(path, start);
    (available - length).abs() / length + 2.0 * (path[start] - root).norm() / length
}

/// What [`unheld`] finds.
#[derive(Debug, Clone, Default)]
struct Unheld {
    /// Limb-shaped extremities (indices into the tips) that hold no bone.
    parts: Vec<usize>,
    /// Arms' and legs' last bones that hold no extremity.
    limbs: Vec<usize>,
    /// Whether one of `parts` could be the arm of one of `limbs` ([`limb_path_cost`]): an
    /// arm laid where the surface has no arm while its own part stays empty, a wrong
    /// embedding. (A part no idle limb could fill is phantom volume or clothing; a limb in
    /// no part with no such part empty lies against the body, as arms at the sides.)
    misplaced: bool,
}

impl Unheld {
    /// Orders embeddings, the fewest problems first.
    fn rank(&self) -> (bool, usize) {
        (self.misplaced, self.parts.len() + self.limbs.len())
    }
}

/// Step 3c ([`super::follow`]): each end chain laid along the interior's path to the
/// extremity matched to it; chains with no extremity keep their pose.
fn follow_limbs(
    template: &Skeleton,
    mut joints: Joints,
    tips: &[super::follow::Extremity],
) -> Joints {
    use super::follow;
    let chains = end_chains(template);
    if tips.is_empty() || chains.is_empty() {
        return joints;
    }
    // What each chain is: its root joint and its placed length.
    let facts: Vec<(Vector3<f64>, f64)> = chains
        .iter()
        .map(|c| {
            let root = joints.bone(c[0]).0;
            let length = c
                .iter()
                .map(|&b| {
                    let (h, t) = joints.bone(b);
                    (t - h).norm()
                })
                .sum::<f64>();
            (root, length)
        })
        .collect();
    // The path must pass the chain's root (a hand's path runs through its shoulder) and
    // offer about the chain's length beyond it; where the template's end lies says nothing
    // (a real body's limbs are anywhere).
    let cost = |c: usize, e: &follow::Extremity| -> f64 {
        let (root, length) = facts[c];
        limb_path_cost(&e.path, &root, length)
    };
    // Brute force over the assignments (a chain may stay unmatched at cost 1).
    const UNMATCHED: f64 = 1.0;
    let mut best: (f64, Vec<Option<usize>>) = (f64::INFINITY, Vec::new());
    let mut current = vec![None; chains.len()];
    fn search(
        c: usize,
        used: &mut Vec<bool>,
        current: &mut Vec<Option<usize>>,
        total: f64,
        best: &mut (f64, Vec<Option<usize>>),
        costs: &[Vec<f64>],
    ) {
        if total >= best.0 {
            return;
        }
        if c == costs.len() {
            *best = (total, current.clone());
            return;
        }
        current[c] = None;
        search(c + 1, used, current, total + UNMATCHED, best, costs);
        for e in 0..used.len() {
            if !used[e] && costs[c][e] < UNMATCHED {
                used[e] = true;
                current[c] = Some(e);
                search(c + 1, used, current, total + costs[c][e], best, costs);
                used[e] = false;
            }
        }
        current[c] = None;
    }
    let costs: Vec<Vec<f64>> = (0..chains.len())
        .map(|c| tips.iter().map(|e| cost(c, e)).collect())
        .collect();
    search(
        0,
        &mut vec![false; tips.len()],
        &mut current,
        0.0,
        &mut best,
        &costs,
    );
    for (c, matched) in best.1.iter().enumerate() {
        let Some(e) = matched else { continue };
        let path = &tips[*e].path;
        let (root, length) = facts[c];
        let start = follow::nearest_on(path, &root);
        let shrink = (follow::remaining(path, start) / length).min(1.0);
        let lengths: Vec<f64> = chains[c]
            .iter()
            .map(|&b| {
                let (h, t) = joints.bone(b);
                (t - h).norm()
            })
            .collect();
        let mut along = 0.0;
        for (&b, l) in chains[c].iter().zip(lengths) {
            along += l * shrink;
            let tail = joints.ends[b].1;
            joints.points[tail] = follow::along(path, start, along);
        }
    }
    joints
}

/// Step 4: gradient descent on the joints' positions.
fn descend_joints(
    interior: &Interior,
    template: &Skeleton,
    tpl: &Joints,
    start: Joints,
    scale: f64,
    weights: &[f64],
) -> Joints {
    // Template offsets of each head from its parent's head, scaled and turned as the
    // placement turned the body (the yaw between the template's left-right axis and the
    // start's).
    let yaw = {
        let a = left_right_axis(template, tpl).unwrap_or_else(Vector2::x);
        let b = left_right_axis(template, &start).unwrap_or(a);
        b.y.atan2(b.x) - a.y.atan2(a.x)
    };
    let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
    let offsets: Vec<Option<Vector3<f64>>> = template
        .bones
        .iter()
        .enumerate()
        .map(|(b, bone)| {
            // Only a head apart from its parent's tail (a shoulder, a hip) gets the prior:
            // a connected head follows its parent's bone.
            bone.parent
                .filter(|&p| tpl.ends[b].0 != tpl.ends[p].1)
                .map(|p| turn * ((tpl.bone(b).0 - tpl.bone(p).0) * scale))
        })
        .collect();
    let lengths: Vec<f64> = (0..tpl.ends.len())
        .map(|b| {
            let (h, t) = tpl.bone(b);
            ((t - h).norm() * scale).max(1e-6)
        })
        .collect();
    let chains = chains(template);
    let children = template.children();
    let caps: Vec<f64> = (0..start.ends.len())
        .map(|b| (REFINE_CAP * start.bone_depth(interior, b, f64::INFINITY)).max(SWING_CAP))
        .collect();
    let energy = |j: &Joints| -> f64 {
        let mut e = -j.depth(interior, weights, &caps);
        let length = |b: usize| {
            let (h, t) = j.bone(b);
            (t - h).norm()
        };
        // Within a chain, the bones keep the template's proportions; the chain's own
        // length is free but for a weak pull to the placement's scale.
        for chain in &chains {
            let ratio = chain.iter().map(|&b| length(b)).sum::<f64>()
                / chain.iter().map(|&b| lengths[b]).sum::<f64>();
            e += CHAIN_WEIGHT * (ratio - 1.0).powi(2);
            for &b in chain {
                e += LENGTH_WEIGHT * (length(b) / (ratio * lengths[b]) - 1.0).powi(2);
            }
        }
        for b in 0..j.ends.len() {
            let (h, t) = j.bone(b);
            if children[b].is_empty() {
                e += REACH_WEIGHT * reach_error(interior, &h, &t).powi(2);
            }
            if let (Some(o), Some(p)) = (offsets[b], template.bones[b].parent) {
                let d = (h - j.bone(p).0) - o;
                e += OFFSET_WEIGHT * d.norm_squared() / (o.norm() + 0.05).powi(2);
            }
        }
        e
    };
    let mut joints = start;
    // Each limb first lengthened about its root joint to the length the energy prefers
    // (1 to 1.2 times the start's). A straight limb has nothing along it to mark its
    // joints, and the descent cannot lengthen a limb whose end bone has bent onto its
    // part's surface: a body whose arms are 7% longer than the template's kept its hand
    // tails 5-6 cm short. The descent shortens limbs well, and a shorter start misleads:
    // before the descent has turned a T-pose's arms, 0.85 looks best.
    for limb in limbs(template) {
        let root = joints.points[joints.ends[limb[0]].0];
        let scaled = |f: f64| {
            let mut j = joints.clone();
            for &b in &limb {
                let i = j.ends[b].1;
                j.points[i] = root + (joints.points[i] - root) * f;
            }
            j
        };
        let (_, f) = (1..=LIMB_SCALES)
            .map(|k| 1.0 + 0.2 * k as f64 / LIMB_SCALES as f64)
            .fold((energy(&joints), 1.0), |best, f| {
                let e = energy(&scaled(f));
                if e < best.0 {
                    (e, f)
                } else {
                    best
                }
            });
        joints = scaled(f);
    }
    let mut e = energy(&joints);
    let mut step = 0.005;
    let h = 1e-3;
    for _ in 0..REFINE_ITERATIONS {
        // Numerical gradient, point by point.
        let mut grad = vec![Vector3::zeros(); joints.points.len()];
        for (i, g) in grad.iter_mut().enumerate() {
            for a in 0..3 {
                let mut j = joints.clone();
                j.points[i][a] += h;
                let up = energy(&j);
                j.points[i][a] -= 2.0 * h;
                let down = energy(&j);
                g[a] = (up - down) / (2.0 * h);
            }
        }
        let norm = grad.iter().map(|g| g.norm_squared()).sum::<f64>().sqrt();
        if norm < 1e-12 {
            break;
        }
        // A step of at most `step` metres for the fastest point; halved until it helps.
        let largest = grad.iter().map(|g| g.norm()).fold(0.0, f64::max);
        let mut improved = false;
        while step > 1e-5 {
            let mut trial = joints.clone();
            for (p, g) in trial.points.iter_mut().zip(&grad) {
                *p -= g * (step / largest);
            }
            let et = energy(&trial);
            if et < e {
                (joints, e) = (trial, et);
                step *= 1.5;
                improved = true;
                break;
            }
            step *= 0.5;
        }
        if !improved {
            break;
        }
        step = step.min(0.02);
    }
    joints
}

/// The chains: maximal runs of bones each the only child of the one before (a bone whose
/// parent has several children, or none, starts a chain).
fn chains(template: &Skeleton) -> Vec<Vec<usize>> {
    let children = template.children();
    let starts = (0..template.bones.len()).filter(|&b| {
        template.bones[b]
            .parent
            .is_none_or(|p| children[p].len() != 1)
    });
    starts
        .map(|start| {
            let mut chain = vec![start];
            while let [only] = children[*chain.last().expect("not empty")][..] {
                chain.push(only);
            }
            chain
        })
        .collect()
}

/// How far an end bone's tail `t` (head `h`) misses the end of its part, metres: a part
/// ends about its radius beyond the tail, along the bone (a capsule's cap), the radius
/// taken as the depth three quarters along the bone (the tail's own depth would let a tail
/// sitting on the surface pass). The surface beyond the tail is found by marching in
/// half-voxel steps, then interpolated, so that the measure moves smoothly with the tail.
fn reach_error(interior: &Interior, h: &Vector3<f64>, t: &Vector3<f64>) -> f64 {
    let u = (t - h).normalize();
    if !u.iter().all(|x| x.is_finite()) {
        return 0.0;
    }
    let radius = interior.at(&(h + (t - h) * 0.75)).max(0.0);
    let depth = interior.at(t);
    if depth <= 0.0 {
        return depth - radius;
    }
    let step = 0.5 * interior.grid.voxel;
    let (mut s, mut before) = (0.0, depth);
    while s < 0.5 {
        let d = interior.at(&(t + u * (s + step)));
        if d <= 0.0 {
            let beyond = s + step * before / (before - d);
            return beyond - radius;
        }
        (s, before) = (s + step, d);
    }
    s - radius
}

/// Refusal: the share of the surface's vertices farther than [`UNCOVERED_EXCESS`] beyond
/// the part their nearest bone stands for may not exceed [`UNCOVERED_SHARE`]. A real
/// capture's surface holds what no bone explains: the phantom volume 8 cameras leave, a
/// dress (the real dancer's best frame: 30%); so the refusal is kept for surfaces a
/// template does not fit at all, and above [`UNCOVERED_WARN`] the user is warned.
pub const UNCOVERED_SHARE: f64 = 0.35;

/// Above this share of the surface far from every bone, `pipeline skeleton` warns (a
/// limb the template could not follow, as hands on the hips, or phantom volume): the
/// synthetic humanoid in an open pose leaves 4-8%.
pub const UNCOVERED_WARN: f64 = 0.08;

/// How far a surface vertex may lie beyond its nearest bone's part (the distance to the
/// bone less the depth there, the part's radius), metres.
pub const UNCOVERED_EXCESS: f64 = 0.05;

/// Step 5, the surface's side: every part of the surface has a bone inside it. A limb the
/// template could not follow (bent onto the body, crossed) leaves its surface far from
/// every bone.
fn check_coverage(
    interior: &Interior,
    template: &Skeleton,
    joints: &Joints,
    surface: &TriMesh,
) -> Result<f64, Refusal> {
    let mut uncovered = vec![0usize; template.bones.len()];
    let mut total = 0usize;
    // How far `v` lies beyond the part around segment h-t.
    let excess = |v: &Vector3<f64>, h: Vector3<f64>, t: Vector3<f64>| {
        let d = t - h;
        let s = ((v - h).dot(&d) / d.norm_squared().max(1e-18)).clamp(0.0, 1.0);
        let p = h + d * s;
        (v - p).norm() - interior.at(&p).max(0.0)
    };
    // Every bone, then the web between the legs, each with the bone it counts for.
    let segments: Vec<(Vector3<f64>, Vector3<f64>, usize)> = (0..template.bones.len())
        .map(|b| {
            let (h, t) = joints.bone(b);
            (h, t, b)
        })
        .chain(leg_webs(template, joints))
        .collect();
    for v in surface.vertices.iter().step_by(7) {
        total += 1;
        let (mut best, mut best_bone) = (f64::INFINITY, 0);
        for &(h, t, bone) in &segments {
            let e = excess(v, h, t);
            if e < best {
                (best, best_bone) = (e, bone);
            }
        }
        if best > UNCOVERED_EXCESS {
            uncovered[best_bone] += 1;
        }
    }
    let n: usize = uncovered.iter().sum();
    if total > 0 && n as f64 > UNCOVERED_SHARE * total as f64 {
        let worst = (0..uncovered.len())
            .max_by_key(|&b| uncovered[b])
            .unwrap_or(0);
        return Err(format!(
            "{:.0}% of the surface lies far from every bone (most of it nearest '{}'): the body \
             is not in a pose the template can be embedded in (limbs bent onto the body or \
             crossed); choose a reference frame where the arms and legs stand clear of the \
             torso (an A-pose or T-pose) with --frame",
            100.0 * n as f64 / total as f64,
            template.bones[worst].name
        )
        .into());
    }
    Ok(n as f64 / total.max(1) as f64)
}

/// Across-the-legs segments for the coverage check: between matching points of the left
/// and right leg (a limb pair whose tops lie in the lower half of the skeleton), at
/// [`SAMPLES`] + 1 shares of each leg's length, each with the left bone it starts on. A
/// dress fuses the thighs into one volume whose surface lies far from both legs' bones
/// but near the web between them; where the legs stand apart the web lies outside the
/// body (depth 0) and explains no more than the legs do.
fn leg_webs(template: &Skeleton, joints: &Joints) -> Vec<(Vector3<f64>, Vector3<f64>, usize)> {
    let limbs = limbs(template);
    let (low, high) = joints
        .points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.z), b.max(p.z))
        });
    let middle = 0.5 * (low + high);
    // A point at share `s` of the limb's length (its bones in order down the chain).
    let along = |limb: &[usize], s: f64| -> (Vector3<f64>, usize) {
        let lengths: Vec<f64> = limb
            .iter()
            .map(|&b| {
                let (h, t) = joints.bone(b);
                (t - h).norm()
            })
            .collect();
        let mut left = s * lengths.iter().sum::<f64>();
        for (k, &b) in limb.iter().enumerate() {
            let (h, t) = joints.bone(b);
            if left <= lengths[k] || k + 1 == limb.len() {
                return (h + (t - h) * (left / lengths[k].max(1e-12)).min(1.0), b);
            }
            left -= lengths[k];
        }
        (joints.bone(limb[0]).0, limb[0])
    };
    let mut webs = Vec::new();
    for limb in &limbs {
        let name = &template.bones[limb[0]].name;
        if !super::sides::is_left(name) || joints.bone(limb[0]).0.z > middle {
            continue;
        }
        let Some(other) = super::sides::other_side(name).and_then(|n| template.bone_index(&n))
        else {
            continue;
        };
        let Some(right) = limbs.iter().find(|l| l[0] == other) else {
            continue;
        };
        for k in 0..=SAMPLES {
            let s = k as f64 / SAMPLES as f64;
            let (l, bone) = along(limb, s);
            webs.push((l, along(right, s).0, bone));
        }
    }
    webs
}

/// An arm's bones after its first lie at most this share of the torso's depth inside the
/// body: 0.16-0.28 on the synthetic poses of `pipeline synth --pose` (bodies 1-4, tilted or
/// not), 0.70-0.81 where an arm was laid through the torso (hands on the hips).
const ARM_DEPTH_SHARE: f64 = 0.5;

/// The head's chain (neck to head's tip) leans at most this far from up, degrees.
const HEAD_TILT_DEG: f64 = 60.0;

/// The height above which a joint of `joints` is at the shoulders (the hips lie below it):
/// 65% of the way from the lowest joint to the highest.
fn shoulder_line(joints: &Joints) -> f64 {
    let zs = joints.points.iter().map(|p| p.z);
    let (lo, hi) = zs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), z| {
        (a.min(z), b.max(z))
    });
    lo + 0.65 * (hi - lo)
}

/// The torso's depth: the deepest point along the bones in none of `limbs`, metres.
fn torso_depth(
    interior: &Interior,
    template: &Skeleton,
    joints: &Joints,
    limbs: &[Vec<usize>],
) -> f64 {
    let in_limb: Vec<usize> = limbs.iter().flatten().copied().collect();
    (0..template.bones.len())
        .filter(|b| !in_limb.contains(b))
        .map(|b| {
            let (h, t) = joints.bone(b);
            (0..=SAMPLES)
                .map(|k| interior.at(&(h + (t - h) * (k as f64 / SAMPLES as f64))))
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// Per arm (one of `limbs` whose root lies above `shoulders`, metres), the deepest point
/// along its bones after the first, as a share of `torso_depth` (metres).
fn arm_depths(
    interior: &Interior,
    template: &Skeleton,
    joints: &Joints,
    limbs: &[Vec<usize>],
    torso_depth: f64,
    shoulders: f64,
) -> Vec<(String, f64)> {
    limbs
        .iter()
        .filter(|limb| joints.bone(limb[0]).0.z >= shoulders)
        .map(|limb| {
            let worst = limb[1..]
                .iter()
                .flat_map(|&b| {
                    let (h, t) = joints.bone(b);
                    (1..=SAMPLES).map(move |k| h + (t - h) * (k as f64 / SAMPLES as f64))
                })
                .map(|p| interior.at(&p))
                .fold(0.0, f64::max);
            (
                template.bones[limb[0]].name.clone(),
                worst / torso_depth.max(1e-9),
            )
        })
        .collect()
}

/// Step 5: the refusals.
fn check(interior: &Interior, template: &Skeleton, joints: &Joints) -> Result<(), Refusal> {
    for (b, bone) in template.bones.iter().enumerate() {
        let (h, t) = joints.bone(b);
        let inside = [0.25, 0.5, 0.75]
            .iter()
            .filter(|&&s| interior.at(&(h + (t - h) * s)) > 0.0)
            .count();
        if inside < 2 {
            return Err(format!(
                "bone '{}' could not be placed inside the surface: is the reference frame's \
                 surface complete, and the template a skeleton of this kind of body?",
                bone.name
            )
            .into());
        }
    }
    let limbs = limbs(template);
    let in_limb: Vec<usize> = limbs.iter().flatten().copied().collect();
    let torso_depth = torso_depth(interior, template, joints, &limbs);
    let children = template.children();
    for &b in &in_limb {
        if !children[b].is_empty() {
            continue;
        }
        let tail = joints.points[joints.ends[b].1];
        if torso_depth > 0.0 && interior.at(&tail) > 0.6 * torso_depth {
            return Err(format!(
                "the end of '{}' lies as deep inside the body as the torso ({:.0} against {:.0} \
                 cm): the limb seems fused to the body at the reference frame; choose a \
                 reference frame where the arms and legs stand clear of the torso (an A-pose \
                 or T-pose)",
                template.bones[b].name,
                100.0 * interior.at(&tail),
                100.0 * torso_depth
            )
            .into());
        }
    }
    // An arm laid through the torso (its forearm or hand as deep inside the body as the
    // torso's middle, where an arm's own part is about its radius deep) is in no limb.
    let shoulders = shoulder_line(joints);
    for (name, share) in arm_depths(interior, template, joints, &limbs, torso_depth, shoulders) {
        if share > ARM_DEPTH_SHARE {
            return Err(format!(
                "the arm from '{name}' runs through the torso (its lower bones reach {:.0}% of \
                 the torso's depth): it lies in no arm of the surface (hands on the hips or \
                 arms folded against the body close loops the template cannot follow); choose \
                 a frame where the arms stand clear of the torso with --frame",
                100.0 * share
            )
            .into());
        }
    }
    // The head stands up from the shoulders: an unpaired end chain above them (neck and
    // head) tipped further than [`HEAD_TILT_DEG`] from up has been laid in an arm.
    for chain in end_chains(template) {
        let unpaired = chain
            .iter()
            .all(|&b| super::sides::other_side(&template.bones[b].name).is_none());
        let (root, end) = (
            joints.bone(chain[0]).0,
            joints.bone(*chain.last().expect("a chain has a bone")).1,
        );
        let d = end - root;
        if !unpaired || root.z < shoulders || d.norm() < 1e-9 {
            continue;
        }
        let tilt = (d.z / d.norm()).clamp(-1.0, 1.0).acos().to_degrees();
        if tilt > HEAD_TILT_DEG {
            return Err(format!(
                "'{}' points {tilt:.0} degrees from up (a standing body's head is within \
                 {HEAD_TILT_DEG:.0}): it was laid in another part of the surface; check the \
                 world's up, or choose another frame with --frame",
                template.bones[*chain.last().expect("a chain has a bone")].name
            )
            .into());
        }
    }
    // Left and right limbs of about one length.
    let limb_length = |limb: &[usize]| -> f64 {
        limb.iter()
            .map(|&b| {
                let (h, t) = joints.bone(b);
                (t - h).norm()
            })
            .sum()
    };
    // Every limb about as long as the trunk says (the template's proportions): a limb laid
    // short, folded into its own root, has not been followed.
    let template_length =
        |bones: &[usize]| -> f64 { bones.iter().map(|&b| template.bones[b].length()).sum() };
    let trunk: Vec<usize> = (0..template.bones.len())
        .filter(|b| !in_limb.contains(b))
        .collect();
    let trunk_scale = limb_length(&trunk) / template_length(&trunk).max(1e-9);
    for limb in &limbs {
        let expected = trunk_scale * template_length(limb);
        let got = limb_length(limb);
        if !trunk.is_empty() && got < LIMB_SHORTEST * expected {
            return Err(format!(
                "the limb '{}' came out {:.0} cm long where the trunk calls for about {:.0}: \
                 it could not be followed (a hand touching the body, as hands on the hips, \
                 closes a loop the template cannot follow); choose a frame where the arms and \
                 legs stand clear of the torso with --frame",
                template.bones[limb[0]].name,
                100.0 * got,
                100.0 * expected
            )
            .into());
        }
    }
    for limb in &limbs {
        let name = &template.bones[limb[0]].name;
        let Some(other) = super::sides::other_side(name).and_then(|n| template.bone_index(&n))
        else {
            continue;
        };
        let Some(other_limb) = limbs.iter().find(|l| l[0] == other) else {
            continue;
        };
        let (a, b) = (limb_length(limb), limb_length(other_limb));
        if (a - b).abs() > LIMB_ASYMMETRY * a.max(b) {
            return Err(format!(
                "the limbs '{name}' and '{}' came out {:.0} and {:.0} cm long: one of them \
                 could not be followed (touching another part, or cut off in the surface)",
                template.bones[other].name,
                100.0 * a,
                100.0 * b
            )
            .into());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::body;

    /// The synthetic humanoid posed with its arms raised to a T-pose: the A-pose template
    /// swings its arms up to them (step 3) and lands within 3 cm on average, 6 cm at worst.
    #[test]
    fn an_a_pose_template_finds_the_arms_of_a_t_pose() {
        let body = crate::synth::humanoid::standard_body();
        let b = &body;
        let rest = b.rest_mesh(0.01);
        let weights = b.skin_weights(&rest, 0.025);
        let mut pose = body::Pose::rest(b.skeleton.bones.len());
        for (side, degrees) in [("l", -45.0f64), ("r", 45.0)] {
            let raise = Rotation3::from_axis_angle(&Vector3::y_axis(), degrees.to_radians());
            for part in ["upper_arm", "forearm", "hand"] {
                let i = b.skeleton.bone_index(&format!("{part}_{side}")).unwrap();
                pose.rotations[i] = raise;
            }
        }
        let mesh = b.pose_mesh(&rest, &weights, &pose);
        let truth = b.joints(&pose);
        // The arms do stand out sideways: the left hand's tail at the shoulder's height.
        let hand = b.skeleton.bone_index("hand_l").unwrap();
        assert!((truth[hand].1.z - 1.4).abs() < 0.01, "{:?}", truth[hand].1);
        let made = embed(&b.skeleton, &mesh, Vector3::z()).unwrap();
        let errors: Vec<f64> = made
            .bones
            .iter()
            .zip(&truth)
            .flat_map(|(m, t)| [(m.head - t.0).norm(), (m.tail - t.1).norm()])
            .collect();
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let worst = errors.iter().fold(0.0f64, |a, &e| a.max(e));
        eprintln!("T-pose: mean {mean:.3} m, worst {worst:.3} m");
        assert!(
            mean < 0.03 && worst < 0.06,
            "mean {mean:.3} m, worst {worst:.3} m"
        );
    }

    /// A closed box of `size` metres standing on the origin, outward triangles.
    fn upright_box(size: [f64; 3]) -> TriMesh {
        let [sx, sy, sz] = size;
        let vertices = (0..8)
            .map(|i| {
                Vector3::new(
                    if i & 1 == 1 { sx / 2.0 } else { -sx / 2.0 },
                    if i & 2 == 2 { sy / 2.0 } else { -sy / 2.0 },
                    if i & 4 == 4 { sz } else { 0.0 },
                )
            })
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    /// A 6 cm x 6 cm x 1.4 m stick gets no skeleton: the message says it is too thin for
    /// a body. A person-sized box (45 cm wide) passes that test.
    #[test]
    fn a_thin_stick_is_refused_as_a_body() {
        let body = crate::synth::humanoid::standard_body();
        let stick = upright_box([0.06, 0.06, 1.4]);
        let err = embed(&body.skeleton, &stick, Vector3::z()).unwrap_err();
        assert!(err.0.contains("too thin for a body"), "{err}");
        if let Err(e) = embed(&body.skeleton, &upright_box([0.45, 0.3, 1.7]), Vector3::z()) {
            assert!(!e.0.contains("too thin for a body"), "{e}");
        }
    }
}
