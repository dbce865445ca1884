//! The nearest point whose normal agrees with a query's (the `normals` baseline's search,
//! Ogawara et al.): a k-d tree whose nodes bound both their points' positions and their
//! normals, so that a subtree whose normals all turn away from the query's is skipped
//! unvisited, as one farther than the best point found is.
//!
//! Exact: the same answer as testing every point within the limit (nearest first, ties to
//! the lower index), with distances measured as [`super::nearest::NearestTree`] measures them
//! (f32 coordinates). A search that finds no agreeing point visits only the few subtrees whose
//! normals could agree, instead of every point within the limit.

use super::nearest::{key, key_distance2_f32};
use nalgebra::Vector3;

/// Points per leaf.
const LEAF_SIZE: usize = 8;

/// How much a node's normal bound is widened against the f32 rounding of the normals it
/// bounds (a dot product of unit vectors; f32 rounds each component by at most 6e-8).
const NORMAL_BOUND_SLACK: f64 = 1e-5;

/// A node: the bounds of its points, and its children or its points.
struct Node {
    /// Smallest and largest coordinates of its points (f32 keys), metres.
    lo: [f32; 3],
    hi: [f32; 3],
    /// Smallest and largest components of its points' normals.
    normal_lo: [f32; 3],
    normal_hi: [f32; 3],
    /// Leaf: its points are `order[start..end]`; inner: `left` and `right` are node indices.
    start: u32,
    end: u32,
    left: u32,
    right: u32,
}

/// A k-d tree over points with normals ([module docs](self)), answering with the points'
/// indices.
pub struct OrientedTree {
    nodes: Vec<Node>,
    /// Point indices, each leaf's a contiguous run.
    order: Vec<u32>,
    /// Points as keys and their normals (f32), in `order`'s order.
    keys: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
}

/// Where a query stands: its point, its normal, the agreement threshold, and the best point
/// found so far (index, squared distance in m^2).
struct Search<'a, F> {
    q: [f32; 3],
    normal: [f64; 3],
    min_dot: f64,
    accept: &'a F,
    best: Option<u32>,
    best_d2: f32,
}

impl OrientedTree {
    /// Indexes `points` (metres) with their unit `normals`; index i answers for `points[i]`.
    pub fn new(points: &[Vector3<f64>], normals: &[Vector3<f64>]) -> OrientedTree {
        assert_eq!(points.len(), normals.len(), "a normal per point");
        let f32s = |v: &Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32];
        let all_keys: Vec<[f32; 3]> = points.iter().map(key).collect();
        let all_normals: Vec<[f32; 3]> = normals.iter().map(f32s).collect();
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * points.len() / LEAF_SIZE + 1);
        if !points.is_empty() {
            build(&mut nodes, &mut order, 0, &all_keys, &all_normals);
        }
        let keys = order.iter().map(|&i| all_keys[i as usize]).collect();
        let normals = order.iter().map(|&i| all_normals[i as usize]).collect();
        OrientedTree {
            nodes,
            order,
            keys,
            normals,
        }
    }

    /// The nearest point to `q` within `limit` metres whose normal may agree with `normal`
    /// (unit) at a dot product of at least `min_dot` and which `accept`s (the exact test):
    /// (index, squared distance in m^2; ties to the lower index). `accept` must refuse every
    /// point whose normal's dot product with `normal` is below `min_dot`: subtrees are skipped
    /// on that test alone, so a point it would accept there is never offered.
    pub fn nearest_agreeing(
        &self,
        q: &Vector3<f64>,
        normal: &Vector3<f64>,
        min_dot: f64,
        limit: f64,
        accept: &impl Fn(usize) -> bool,
    ) -> Option<(usize, f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut search = Search {
            q: key(q),
            normal: [normal.x, normal.y, normal.z],
            min_dot: min_dot - NORMAL_BOUND_SLACK,
            accept,
            best: None,
            best_d2: (limit * limit) as f32,
        };
        self.visit(0, &mut search);
        search.best.map(|i| (i as usize, search.best_d2 as f64))
    }

    /// Searches node `n` for a point nearer than `search`'s best.
    fn visit<F: Fn(usize) -> bool>(&self, n: usize, search: &mut Search<F>) {
        let node = &self.nodes[n];
        if node.left == u32::MAX {
            for k in node.start as usize..node.end as usize {
                let d2 = key_distance2_f32(&self.keys[k], &search.q);
                let i = self.order[k];
                let nearer = d2 < search.best_d2
                    || (d2 == search.best_d2 && search.best.is_none_or(|b| i < b));
                // The leaf's own normals first (read in order, unlike `accept`'s): 10% of a
                // round on the tripod.
                if nearer
                    && normal_bound(&self.normals[k], &self.normals[k], &search.normal)
                        >= search.min_dot
                    && (search.accept)(i as usize)
                {
                    search.best = Some(i);
                    search.best_d2 = d2;
                }
            }
            return;
        }
        // The nearer child first, so that the farther one is more often pruned.
        let (a, b) = (node.left as usize, node.right as usize);
        let (da, db) = (self.reach(a, search), self.reach(b, search));
        let (first, d_first, second, d_second) = if da <= db {
            (a, da, b, db)
        } else {
            (b, db, a, da)
        };
        if let Some(d) = d_first {
            if d <= search.best_d2 {
                self.visit(first, search);
            }
        }
        if let Some(d) = d_second {
            if d <= search.best_d2 {
                self.visit(second, search);
            }
        }
    }

    /// The squared distance from the query to node `n`'s box, m^2, or `None` when no normal
    /// in the node can agree with the query's.
    fn reach<F>(&self, n: usize, search: &Search<F>) -> Option<f32> {
        let node = &self.nodes[n];
        if normal_bound(&node.normal_lo, &node.normal_hi, &search.normal) < search.min_dot {
            return None;
        }
        // Each axis's gap rounds no larger than the gap to any point inside, so the box's
        // distance never exceeds a point's as the leaves measure it.
        let mut d2 = 0.0f32;
        for axis in 0..3 {
            let gap = if search.q[axis] < node.lo[axis] {
                node.lo[axis] - search.q[axis]
            } else if search.q[axis] > node.hi[axis] {
                search.q[axis] - node.hi[axis]
            } else {
                0.0
            };
            d2 += gap * gap;
        }
        Some(d2)
    }
}

/// The largest dot product of `normal` with any vector inside the box `lo..hi`: an upper
/// bound on its agreement with every normal the box holds.
fn normal_bound(lo: &[f32; 3], hi: &[f32; 3], normal: &[f64; 3]) -> f64 {
    (0..3)
        .map(|axis| (normal[axis] * lo[axis] as f64).max(normal[axis] * hi[axis] as f64))
        .sum()
}

/// Builds the subtree over `order[offset..offset + order.len()]` (the slice given), splitting
/// at the median of its points' widest coordinate; returns its node index.
fn build(
    nodes: &mut Vec<Node>,
    order: &mut [u32],
    offset: usize,
    keys: &[[f32; 3]],
    normals: &[[f32; 3]],
) -> u32 {
    let mut bounds = [[f32::INFINITY; 3], [f32::NEG_INFINITY; 3]];
    let mut normal_bounds = bounds;
    for &i in order.iter() {
        for axis in 0..3 {
            let (p, n) = (keys[i as usize][axis], normals[i as usize][axis]);
            bounds[0][axis] = bounds[0][axis].min(p);
            bounds[1][axis] = bounds[1][axis].max(p);
            normal_bounds[0][axis] = normal_bounds[0][axis].min(n);
            normal_bounds[1][axis] = normal_bounds[1][axis].max(n);
        }
    }
    let index = nodes.len();
    nodes.push(Node {
        lo: bounds[0],
        hi: bounds[1],
        normal_lo: normal_bounds[0],
        normal_hi: normal_bounds[1],
        start: offset as u32,
        end: (offset + order.len()) as u32,
        left: u32::MAX,
        right: u32::MAX,
    });
    if order.len() > LEAF_SIZE {
        let axis = (0..3)
            .max_by(|&a, &b| {
                (bounds[1][a] - bounds[0][a]).total_cmp(&(bounds[1][b] - bounds[0][b]))
            })
            .unwrap_or(0);
        let mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |&a, &b| {
            keys[a as usize][axis]
                .total_cmp(&keys[b as usize][axis])
                .then(a.cmp(&b))
        });
        let (left_half, right_half) = order.split_at_mut(mid);
        let left = build(nodes, left_half, offset, keys, normals);
        let right = build(nodes, right_half, offset + mid, keys, normals);
        nodes[index].left = left;
        nodes[index].right = right;
    }
    index as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Against a scan of every point: the same index and distance, agreeing normals only.
    #[test]
    fn the_tree_answers_as_a_scan_of_every_point() {
        let mut rng = Rng::new(7, 0);
        let unit =
            |rng: &mut Rng| Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
        // Points on a sphere of 10 cm with outward normals, and scattered ones, some repeated
        // (ties).
        let mut points = Vec::new();
        let mut normals = Vec::new();
        for _ in 0..1500 {
            let n = unit(&mut rng);
            points.push(n * 0.1);
            normals.push(n);
        }
        for _ in 0..500 {
            points.push(Vector3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 0.3);
            normals.push(unit(&mut rng));
        }
        for k in 0..50 {
            points.push(points[k * 3]);
            normals.push(normals[k * 3]);
        }
        let tree = OrientedTree::new(&points, &normals);
        let min_dot = 45f64.to_radians().cos();
        for _ in 0..400 {
            let q = Vector3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 0.4
                - Vector3::repeat(0.05);
            let qn = unit(&mut rng);
            let agree = |i: usize| normals[i].dot(&qn) >= min_dot;
            let limit = 0.12;
            let mut truth: Option<(usize, f32)> = None;
            for (i, p) in points.iter().enumerate() {
                let d2 = key_distance2_f32(&key(p), &key(&q));
                if d2 <= (limit * limit) as f32
                    && agree(i)
                    && truth.is_none_or(|(j, e)| d2 < e || (d2 == e && i < j))
                {
                    truth = Some((i, d2));
                }
            }
            let found = tree.nearest_agreeing(&q, &qn, min_dot, limit, &agree);
            assert_eq!(found, truth.map(|(i, d2)| (i, d2 as f64)));
        }
        assert_eq!(
            OrientedTree::new(&[], &[]).nearest_agreeing(
                &Vector3::zeros(),
                &Vector3::z(),
                0.0,
                1.0,
                &|_| true
            ),
            None
        );
    }
}
