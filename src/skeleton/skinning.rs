//! Linear blend skinning (method.md "Stage 5"): per-vertex bone weights from the reference
//! surface and skeleton, posing, and the posed vertices' Jacobians.

use super::{PosedBones, Skeleton};
use nalgebra::Vector3;
use rayon::prelude::*;

/// A vertex's bone influences: (bone index, weight), weights summing to 1.
pub type Influences = Vec<(usize, f64)>;

/// Closest point parameter of `p` on the segment `a`-`b` (0 at a, 1 at b) and its distance,
/// metres.
pub fn segment_distance(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> (f64, f64) {
    let ab = b - a;
    let h = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
    (h, (p - a - h * ab).norm())
}

/// Closest points of segments p0-p1 and q0-q1: parameters (s, t) in [0, 1] and distance.
pub fn segment_segment(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> (f64, f64, f64) {
    // Dense sampling of one parameter, exact projection for the other, then refinement:
    // robust for parallel segments and plenty fast for scene setup.
    let dist = |s: f64| {
        let p = p0 + s * (p1 - p0);
        let (t, d) = segment_distance(&p, q0, q1);
        (t, d)
    };
    let mut best = (0.0, 0.0, f64::INFINITY);
    for i in 0..=200 {
        let s = i as f64 / 200.0;
        let (t, d) = dist(s);
        if d < best.2 {
            best = (s, t, d);
        }
    }
    let (mut lo, mut hi) = ((best.0 - 0.005f64).max(0.0), (best.0 + 0.005f64).min(1.0));
    for _ in 0..60 {
        let m1 = lo + (hi - lo) / 3.0;
        let m2 = hi - (hi - lo) / 3.0;
        if dist(m1).1 < dist(m2).1 {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    let s = 0.5 * (lo + hi);
    let (t, d) = dist(s);
    if d < best.2 {
        (s, t, d)
    } else {
        best
    }
}

/// Bones that meet bone `b` at a joint: its parent and its children, and the bones whose
/// head lies at b's head (siblings rooted at the same joint, or a child rooted at its
/// parent's head, as the tripod's arms are at the hub), within 1 mm. Siblings hung from
/// different points of their parent (a thigh and an arm under a torso) do not meet.
pub fn joint_neighbours(skeleton: &Skeleton, b: usize) -> Vec<usize> {
    let bones = &skeleton.bones;
    (0..bones.len())
        .filter(|&o| {
            o != b
                && (bones[b].parent == Some(o)
                    || bones[o].parent == Some(b)
                    || (bones[o].head - bones[b].head).norm() < 1e-3)
        })
        .collect()
}

/// Skinning weights of the reference surface's `vertices` (t0, metres).
///
/// The paper assigns each vertex to its nearest bone and blends across the borders of
/// adjacent bones. Plain distance to the bone segments mislabels skin that lies closer to a
/// thin neighbour's axis than to its own thick bone's (a thigh near a hand), so the distance
/// is taken to each bone's flesh instead: the segment distance minus the bone's radius, the
/// median segment distance of the vertices nearest to it. A vertex belongs to the bone of
/// least flesh distance e_best, blended with that bone's joint neighbours b by the weight
/// exp(-((e_b - e_best) / blend_width)^2) (dropped below 0.01), then normalized: weights
/// fall off smoothly over about `blend_width` metres on either side of a joint, as they do
/// along a real limb, and stay exactly one bone's away from the joints.
pub fn skin_weights(
    skeleton: &Skeleton,
    vertices: &[Vector3<f64>],
    blend_width: f64,
) -> Vec<Influences> {
    let nb = skeleton.bones.len();
    let distances: Vec<Vec<f64>> = vertices
        .par_iter()
        .map(|v| {
            skeleton
                .bones
                .iter()
                .map(|b| segment_distance(v, &b.head, &b.tail).1)
                .collect()
        })
        .collect();
    let argmin = |d: &[f64]| {
        (0..d.len())
            .min_by(|&i, &j| d[i].total_cmp(&d[j]))
            .unwrap_or(0)
    };
    let mut per_bone: Vec<Vec<f64>> = vec![Vec::new(); nb];
    for d in &distances {
        let b = argmin(d);
        per_bone[b].push(d[b]);
    }
    let radii: Vec<f64> = per_bone
        .iter_mut()
        .map(|d| {
            if d.is_empty() {
                return 0.0;
            }
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        })
        .collect();
    let neighbours: Vec<Vec<usize>> = (0..nb).map(|b| joint_neighbours(skeleton, b)).collect();
    distances
        .par_iter()
        .map(|d| {
            let e: Vec<f64> = d.iter().zip(&radii).map(|(d, r)| d - r).collect();
            let best = argmin(&e);
            let mut w: Influences = std::iter::once(best)
                .chain(neighbours[best].iter().copied())
                .map(|b| (b, (-((e[b] - e[best]) / blend_width).powi(2)).exp()))
                .filter(|&(_, w)| w > 0.01)
                .collect();
            let sum: f64 = w.iter().map(|x| x.1).sum();
            w.iter_mut().for_each(|x| x.1 /= sum);
            w
        })
        .collect()
}

/// The dominant bone (part label) of every vertex.
pub fn labels(weights: &[Influences]) -> Vec<usize> {
    weights
        .iter()
        .map(|w| {
            w.iter()
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(0, |x| x.0)
        })
        .collect()
}

/// The t0 `vertices` posed by linear blend skinning: `sum_b w_b F_b(x)`.
pub fn pose_vertices(
    bones: &PosedBones,
    vertices: &[Vector3<f64>],
    weights: &[Influences],
) -> Vec<Vector3<f64>> {
    vertices
        .par_iter()
        .zip(weights.par_iter())
        .map(|(v, w)| pose_vertex(bones, v, w))
        .collect()
}

/// One t0 vertex posed by linear blend skinning.
pub fn pose_vertex(bones: &PosedBones, v: &Vector3<f64>, w: &Influences) -> Vector3<f64> {
    w.iter().map(|&(b, wb)| wb * bones.transform(b, v)).sum()
}

/// The Jacobian of the posed t0 vertex `v` with respect to the pose increments, keeping
/// only what is not zero: the translation block is the identity (the weights sum to 1), and
/// `blocks` is overwritten with (bone, its three columns) for every bone on the chains of
/// `v`'s influences (see [`PosedBones::add_point_jacobian`]). Returns the posed vertex,
/// the same value as [`pose_vertex`] (the same operations in the same order), so that a
/// caller needing both transforms each influence once.
pub fn sparse_vertex_jacobian(
    bones: &PosedBones,
    v: &Vector3<f64>,
    w: &Influences,
    blocks: &mut Vec<(usize, [Vector3<f64>; 3])>,
) -> Vector3<f64> {
    blocks.clear();
    let mut posed = Vector3::zeros();
    for &(b, wb) in w {
        let y = bones.transform(b, v);
        posed += wb * y;
        for &a in &bones.chains[b] {
            let at = match blocks.iter().position(|x| x.0 == a) {
                Some(i) => i,
                None => {
                    blocks.push((a, [Vector3::zeros(); 3]));
                    blocks.len() - 1
                }
            };
            let arm = y - bones.heads[a];
            let axes = &bones.increment_axes[a];
            for k in 0..3 {
                blocks[at].1[k] += wb * axes.column(k).cross(&arm);
            }
        }
    }
    posed
}

/// The Jacobian of the posed t0 vertex `v` with respect to the pose increments: `columns`
/// (one 3-vector per parameter, 3 N + 3) is overwritten. Linear blend skinning is a weighted
/// sum of rigid motions, so the Jacobian is the weighted sum of theirs.
pub fn vertex_jacobian(
    bones: &PosedBones,
    v: &Vector3<f64>,
    w: &Influences,
    columns: &mut [Vector3<f64>],
) {
    columns.fill(Vector3::zeros());
    for &(b, wb) in w {
        bones.add_point_jacobian(b, &bones.transform(b, v), wb, columns);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::skeleton::{Bone, Pose};
    use nalgebra::Rotation3;

    /// Repeatable numbers uniform in [-1, 1) for tests, from `seed`.
    pub(crate) fn signed_uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut uniform = crate::rng::chained_uniform(seed);
        move || uniform() * 2.0 - 1.0
    }

    /// A small branching skeleton (root, a two-bone arm and a one-bone arm) for tests.
    pub(crate) fn chain() -> Skeleton {
        let p = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let bone = |name: &str, parent, head, tail| Bone {
            name: name.into(),
            parent,
            head,
            tail,
        };
        Skeleton {
            reference_frame: 0,
            bones: vec![
                bone("root", None, p(0.0, 0.0, 1.0), p(0.0, 0.0, 1.3)),
                bone("a", Some(0), p(0.0, 0.0, 1.3), p(0.4, 0.0, 1.3)),
                bone("b", Some(1), p(0.4, 0.0, 1.3), p(0.8, 0.1, 1.3)),
                bone("c", Some(0), p(0.0, 0.0, 1.3), p(-0.4, 0.0, 1.3)),
            ],
        }
    }

    /// Analytic Jacobians agree with central differences of the posing for random poses.
    #[test]
    fn jacobians_match_finite_differences() {
        let skel = chain();
        let mut rnd = signed_uniform(12345);
        let vertices: Vec<Vector3<f64>> = (0..40)
            .map(|_| Vector3::new(0.5 * rnd(), 0.1 * rnd(), 1.0 + 0.4 * rnd().abs()))
            .collect();
        let weights = skin_weights(&skel, &vertices, 0.1);
        assert!(weights.iter().any(|w| w.len() > 1), "some blending");
        let mut worst: f64 = 0.0;
        for _ in 0..10 {
            let mut pose = Pose::rest(skel.bones.len());
            pose.translation = Vector3::new(rnd(), rnd(), rnd()) * 0.3;
            for r in &mut pose.rotations {
                *r = Rotation3::new(Vector3::new(rnd(), rnd(), rnd()) * 1.5);
            }
            let bones = PosedBones::new(&skel, &pose);
            let n = pose.parameter_count();
            let mut columns = vec![Vector3::zeros(); n];
            for (v, w) in vertices.iter().zip(&weights) {
                vertex_jacobian(&bones, v, w, &mut columns);
                let h = 1e-6;
                for (k, col) in columns.iter().enumerate() {
                    let mut d = vec![0.0; n];
                    d[k] = h;
                    let plus =
                        pose_vertex(&PosedBones::new(&skel, &pose.apply_increment(&d)), v, w);
                    d[k] = -h;
                    let minus =
                        pose_vertex(&PosedBones::new(&skel, &pose.apply_increment(&d)), v, w);
                    let fd = (plus - minus) / (2.0 * h);
                    let err = (fd - col).norm() / col.norm().max(1e-3);
                    worst = worst.max(err);
                }
            }
        }
        assert!(worst <= 1e-5, "worst relative Jacobian error {worst:e}");
        // The sparse form holds the same numbers.
        let pose = Pose::rest(skel.bones.len()).apply_increment(&[0.1; 15]);
        let bones = PosedBones::new(&skel, &pose);
        let mut dense = vec![Vector3::zeros(); 15];
        let mut blocks = Vec::new();
        for (v, w) in vertices.iter().zip(&weights) {
            vertex_jacobian(&bones, v, w, &mut dense);
            sparse_vertex_jacobian(&bones, v, w, &mut blocks);
            let mut rebuilt = vec![Vector3::zeros(); 15];
            for (k, col) in rebuilt.iter_mut().take(3).enumerate() {
                col[k] = 1.0;
            }
            for (b, cols) in &blocks {
                for k in 0..3 {
                    rebuilt[3 + 3 * b + k] = cols[k];
                }
            }
            for (a, b) in dense.iter().zip(&rebuilt) {
                assert!((a - b).norm() < 1e-12);
            }
        }
    }

    #[test]
    fn parameter_vectors_round_trip() {
        let mut pose = Pose::rest(3);
        pose.translation = Vector3::new(0.1, -0.2, 0.3);
        pose.rotations[1] = Rotation3::new(Vector3::new(0.3, -1.0, 0.2));
        let back = Pose::from_vector(&pose.to_vector());
        assert!((back.rotations[1].matrix() - pose.rotations[1].matrix()).norm() < 1e-12);
        assert_eq!(back.translation, pose.translation);
        assert_eq!(pose.parameter_count(), 12);
    }
}
