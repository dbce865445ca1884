//! Limbs followed through the body's interior, for bodies the template's own pose does not
//! reach (a real dancer's raised, forward or bent arms, a leg bent back): the interior's
//! extremities (hands, feet, head) are found as the farthest points of geodesic paths from
//! the torso, each is matched to one of the template's limb ends, and that limb's joints
//! are laid along the path at the template's bone lengths. Pinocchio (Baran and Popović
//! 2007) embeds along the medial axis in the same spirit.
//!
//! 1. Paths over the inside voxels (26-neighbour Dijkstra) from the deepest voxel near the
//!    placed torso, each step costing its length over the depth there: the paths run along
//!    the middle of the parts.
//! 2. Extremities: the farthest voxel not yet claimed, then the tube around its path (the
//!    local depth plus [`TUBE_MARGIN`]) and the geodesic ball around it are claimed, and
//!    again, while the farthest unclaimed voxel lies at least [`MIN_REACH`] from the torso.
//! 3. Matching (`embed.rs`): each end chain (down to a hand, a foot, the head) takes the
//!    extremity whose path passes nearest its root joint and offers about its length beyond
//!    it (brute force over the assignments); a chain with no extremity keeps its pose.
//! 4. Each matched chain is laid along its path from the path point nearest its root joint,
//!    the bones at their placed lengths, shortened together when the path is shorter.

use nalgebra::Vector3;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The interior as the follower sees it: a grid of depths (positive inside), metres.
pub struct Field<'a> {
    pub grid: &'a crate::geometry::grid::GridSpec,
    pub depth: &'a [f32],
}

/// A path's voxels claimed around it: its local depth plus this, metres.
const TUBE_MARGIN: f64 = 0.03;

/// The least geodesic distance from the torso at which an extremity counts, metres.
const MIN_REACH: f64 = 0.2;

/// The geodesic ball claimed around a tip: this share of its distance from the torso, at
/// least [`MIN_TIP_BALL`] metres (a hand or a foot, not its neighbour).
const TIP_BALL_SHARE: f64 = 0.25;
const MIN_TIP_BALL: f64 = 0.15;

/// The most extremities looked for.
const MOST_EXTREMITIES: usize = 20;

/// An extremity, as its path from the torso's seed.
#[derive(Debug, Clone)]
pub struct Extremity {
    /// Voxel centres from the seed to the extremity.
    pub path: Vec<Vector3<f64>>,
    /// How far the extremity stands out of the torso and of the extremities found before
    /// it: the path's length from its tip back to where the interior grows deeper than
    /// [`LIMB_DEPTH_SHARE`] of the seed's depth or the path enters an earlier one's claim,
    /// metres.
    pub length: f64,
    /// The mean depth along that protruding part, metres (about a limb's radius).
    pub depth: f64,
}

/// A limb is thinner than this share of the torso's depth (the deepest point near the
/// torso's centre): the synthetic humanoid's thigh 0.55, upper arm 0.35.
pub const LIMB_DEPTH_SHARE: f64 = 0.6;

/// An extremity standing out of the torso by at least this is limb-shaped, metres (a hand
/// and forearm; a shoulder or a phantom wedge stands out less, or is thicker).
pub const LIMB_LENGTH: f64 = 0.2;

impl Extremity {
    /// Whether it is long and thin: an arm, a leg, the neck and head.
    pub fn limb_shaped(&self) -> bool {
        self.length >= LIMB_LENGTH
    }
}

/// The inside voxels among the 26 around voxel `i`, with the step to each, metres.
fn inside_neighbours<'a>(field: &'a Field, i: usize) -> impl Iterator<Item = (usize, f64)> + 'a {
    let g = field.grid;
    let [x, y, z] = g.coords(i);
    let [nx, ny, nz] = g.dims.map(|d| d as i64);
    (-1i64..=1)
        .flat_map(|dz| (-1i64..=1).flat_map(move |dy| (-1i64..=1).map(move |dx| (dx, dy, dz))))
        .filter(|&d| d != (0, 0, 0))
        .filter_map(move |(dx, dy, dz)| {
            let (a, b, c) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
            if a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz {
                return None;
            }
            let j = g.index(a as usize, b as usize, c as usize);
            (field.depth[j] > 0.0)
                .then(|| (j, g.voxel * ((dx * dx + dy * dy + dz * dz) as f64).sqrt()))
        })
}

/// The extremities of the interior, farthest first, from the deepest inside voxel within
/// `radius` of `near`.
pub fn extremities(field: &Field, near: &Vector3<f64>, radius: f64) -> Vec<Extremity> {
    let g = field.grid;
    let inside = |i: usize| field.depth[i] > 0.0;
    // The seed: the deepest voxel near the torso.
    let mut seed = None;
    let mut deepest = 0.0f32;
    for i in 0..g.len() {
        if inside(i) && field.depth[i] > deepest {
            let [x, y, z] = g.coords(i);
            if (g.centre(x, y, z) - near).norm() <= radius {
                (seed, deepest) = (Some(i), field.depth[i]);
            }
        }
    }
    let Some(seed) = seed else {
        return Vec::new();
    };
    // Dijkstra over the inside voxels. A step costs its length over the depth there (in
    // voxels, at least one), so that paths run along the middle of each part (the medial
    // axis) rather than hugging its inner wall; `dist` is a path's cost, `length` its
    // length in metres.
    let mut dist = vec![f64::INFINITY; g.len()];
    let mut length = vec![0.0f64; g.len()];
    let mut from = vec![usize::MAX; g.len()];
    let mut heap = BinaryHeap::new();
    dist[seed] = 0.0;
    heap.push((Reverse(0u64), seed));
    let [nx, ny, nz] = g.dims;
    while let Some((Reverse(key), i)) = heap.pop() {
        let d = key as f64 * 1e-9;
        if d > dist[i] + 1e-12 {
            continue;
        }
        for (j, step) in inside_neighbours(field, i) {
            let nd = d + step * g.voxel / (field.depth[j] as f64).max(g.voxel);
            if nd < dist[j] {
                dist[j] = nd;
                length[j] = length[i] + step;
                from[j] = i;
                heap.push((Reverse((nd * 1e9) as u64), j));
            }
        }
    }
    let centre = |i: usize| {
        let [x, y, z] = g.coords(i);
        g.centre(x, y, z)
    };
    let mut claimed = vec![false; g.len()];
    let mut out = Vec::new();
    while out.len() < MOST_EXTREMITIES {
        let far = (0..g.len())
            .filter(|&i| dist[i].is_finite() && !claimed[i])
            .max_by(|&a, &b| dist[a].total_cmp(&dist[b]));
        let Some(far) = far else { break };
        if length[far] < MIN_REACH {
            break;
        }
        // How far the tip stands out of the torso and of the extremities found before it,
        // through voxels thinner than a limb.
        let mut path = vec![far];
        while let Some(&last) = path.last() {
            if from[last] == usize::MAX {
                break;
            }
            path.push(from[last]);
        }
        path.reverse();
        let thin = LIMB_DEPTH_SHARE * deepest as f64;
        let (mut stands_out, mut depth_sum, mut steps) = (0.0, 0.0, 0usize);
        for w in path.windows(2).rev() {
            if field.depth[w[0]] as f64 > thin || claimed[w[0]] {
                break;
            }
            stands_out += (centre(w[1]) - centre(w[0])).norm();
            depth_sum += field.depth[w[1]] as f64;
            steps += 1;
        }
        // Claim the tube around the path.
        for &p in &path {
            let r = field.depth[p].max(0.0) as f64 + TUBE_MARGIN;
            let k = (r / g.voxel).ceil() as i64;
            let [x, y, z] = g.coords(p);
            for c in (z as i64 - k).max(0)..=(z as i64 + k).min(nz as i64 - 1) {
                for b in (y as i64 - k).max(0)..=(y as i64 + k).min(ny as i64 - 1) {
                    for a in (x as i64 - k).max(0)..=(x as i64 + k).min(nx as i64 - 1) {
                        let j = g.index(a as usize, b as usize, c as usize);
                        if (centre(j) - centre(p)).norm() <= r {
                            claimed[j] = true;
                        }
                    }
                }
            }
        }
        // And the geodesic ball around the tip: the rest of this hand or foot.
        let reach = (TIP_BALL_SHARE * length[far]).max(MIN_TIP_BALL);
        let mut ball = vec![(far, 0.0f64)];
        let mut seen = std::collections::HashMap::new();
        seen.insert(far, 0.0f64);
        while let Some((i, d)) = ball.pop() {
            claimed[i] = true;
            for (j, step) in inside_neighbours(field, i) {
                let nd = d + step;
                if nd <= reach && seen.get(&j).is_none_or(|&old| nd < old) {
                    seen.insert(j, nd);
                    ball.push((j, nd));
                }
            }
        }
        out.push(Extremity {
            path: path.iter().map(|&i| centre(i)).collect(),
            length: stands_out,
            depth: depth_sum / steps.max(1) as f64,
        });
    }
    out
}

/// The point `length` metres along `path` from its point `start` (clamped to its end).
pub fn along(path: &[Vector3<f64>], start: usize, length: f64) -> Vector3<f64> {
    let mut left = length;
    for k in start..path.len().saturating_sub(1) {
        let step = (path[k + 1] - path[k]).norm();
        if step >= left {
            return path[k] + (path[k + 1] - path[k]) * (left / step.max(1e-12));
        }
        left -= step;
    }
    *path.last().expect("a path has its seed")
}

/// The path's length from its point `start` to its end, metres.
pub fn remaining(path: &[Vector3<f64>], start: usize) -> f64 {
    path[start.min(path.len())..]
        .windows(2)
        .map(|w| (w[1] - w[0]).norm())
        .sum()
}

/// The index of `path`'s point nearest `p`.
pub fn nearest_on(path: &[Vector3<f64>], p: &Vector3<f64>) -> usize {
    (0..path.len())
        .min_by(|&a, &b| (path[a] - p).norm().total_cmp(&(path[b] - p).norm()))
        .unwrap_or(0)
}
