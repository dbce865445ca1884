//! Exact nearest-neighbour and radius queries on a point set that is rebuilt, not edited
//! (a k-d tree from `kiddo`; coordinates stored as f32, which keeps sub-micrometre precision
//! at capture-volume scale and halves the memory traffic).

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Vector3;

/// A k-d tree over points, answering with the points' indices.
pub struct NearestTree {
    /// `None` when built from no point (kiddo needs at least one).
    tree: Option<ImmutableKdTree<f32, 3>>,
    /// The points as the tree stores them.
    keys: Vec<[f32; 3]>,
}

/// A point as the tree stores it (f32 coordinates).
pub fn key(p: &Vector3<f64>) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

/// [`tree_distance2`] between points already turned to [`key`]s, m^2.
pub fn key_distance2(a: &[f32; 3], b: &[f32; 3]) -> f64 {
    key_distance2_f32(a, b) as f64
}

/// [`key_distance2`] before widening to f64 (the same order of points: for scans that
/// compare many distances), m^2.
pub fn key_distance2_f32(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    let mut sum = 0.0f32;
    for axis in 0..3 {
        let d = a[axis] - b[axis];
        sum += d * d;
    }
    sum
}

/// The squared distance between `a` and `b` exactly as the tree measures it (f32
/// coordinates, the axes summed in order), m^2: a search that replaces a tree query then
/// picks the same point.
pub fn tree_distance2(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    key_distance2(&key(a), &key(b))
}

impl NearestTree {
    /// Indexes `points` (metres); index i answers for `points[i]`.
    pub fn new(points: &[Vector3<f64>]) -> NearestTree {
        Self::from_keys(points.iter().map(key).collect())
    }

    /// Indexes points already turned to [`key`]s.
    pub fn from_keys(keys: Vec<[f32; 3]>) -> NearestTree {
        NearestTree {
            tree: if keys.is_empty() {
                None
            } else {
                ImmutableKdTree::new_from_slice(&keys).ok()
            },
            keys,
        }
    }

    /// Point `i` as the tree stores it.
    pub fn key(&self, i: usize) -> &[f32; 3] {
        &self.keys[i]
    }

    /// Every point as the tree stores it, in index order.
    pub fn keys(&self) -> &[[f32; 3]] {
        &self.keys
    }

    /// The nearest point to `q`: (index, squared distance in m^2); `None` for an empty
    /// tree.
    pub fn nearest(&self, q: &Vector3<f64>) -> Option<(usize, f64)> {
        self.nearest_key(&key(q))
    }

    /// [`NearestTree::nearest`] for a query already turned to a [`key`].
    pub fn nearest_key(&self, q: &[f32; 3]) -> Option<(usize, f64)> {
        let tree = self.tree.as_ref()?;
        let n = tree
            .query(q)
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute();
        Some((n.item as usize, n.distance as f64))
    }

    /// [`NearestTree::nearest`] for a query already turned to a [`key`], together with the
    /// squared distance of the second-nearest point (infinite when there is none), m^2.
    pub fn nearest_two(&self, q: &[f32; 3]) -> Option<(usize, f64, f64)> {
        self.nearest_two_within(q, f64::INFINITY)
    }

    /// [`NearestTree::nearest_two`] searching only within `radius` metres of `q`: the
    /// second distance is `radius` squared when no second point lies that near (every
    /// other point is then farther), `None` when none does.
    pub fn nearest_two_within(&self, q: &[f32; 3], radius: f64) -> Option<(usize, f64, f64)> {
        let tree = self.tree.as_ref()?;
        let two = std::num::NonZeroUsize::new(2).expect("2 is not zero");
        let r2 = (radius * radius) as f32;
        let found = tree
            .query(q)
            .nearest_n::<SquaredEuclidean<f32>>(two)
            .within(r2)
            .execute();
        let first = found.first()?;
        let second = found.get(1).map_or(r2 as f64, |n| n.distance as f64);
        Some((first.item as usize, first.distance as f64, second))
    }

    /// Calls `visit(index, squared distance)` for every point within `radius` metres of `q`,
    /// in no particular order.
    pub fn within(&self, q: &Vector3<f64>, radius: f64, visit: impl FnMut(usize, f64)) {
        self.within_key(&key(q), radius, visit)
    }

    /// [`NearestTree::within`] for a query already turned to a [`key`].
    pub fn within_key(&self, q: &[f32; 3], radius: f64, mut visit: impl FnMut(usize, f64)) {
        if let Some(tree) = &self.tree {
            tree.query(q)
                .within::<SquaredEuclidean<f32>>((radius * radius) as f32)
                .unsorted()
                .visit(|r| visit(r.item as usize, r.distance as f64));
        }
    }
}

/// The nearest and second-nearest of the squared distances offered one by one to
/// [`TwoSmallest::offer`]: a distance replaces the nearest only when strictly smaller, so
/// of equal ones the first offered stays, and `second2 == best2` tells a tie.
#[derive(Debug, Clone, Copy)]
pub struct TwoSmallest {
    /// The nearest's item (`usize::MAX` while none was offered).
    pub item: usize,
    /// Squared distances, m^2 (infinite while fewer were offered).
    pub best2: f64,
    pub second2: f64,
}

impl TwoSmallest {
    pub fn new() -> TwoSmallest {
        TwoSmallest {
            item: usize::MAX,
            best2: f64::INFINITY,
            second2: f64::INFINITY,
        }
    }

    pub fn offer(&mut self, item: usize, d2: f64) {
        if d2 < self.best2 {
            self.second2 = self.best2;
            (self.item, self.best2) = (item, d2);
        } else if d2 < self.second2 {
            self.second2 = d2;
        }
    }
}

impl Default for TwoSmallest {
    fn default() -> Self {
        TwoSmallest::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Agrees with a brute-force search, including on points sharing coordinates (as
    /// marching-cubes vertices do).
    #[test]
    fn agrees_with_brute_force() {
        let mut uniform = crate::rng::chained_uniform(7);
        let mut rnd = move || (uniform() * 20.0).floor() * 0.01;
        let points: Vec<Vector3<f64>> = (0..3000)
            .map(|_| Vector3::new(rnd(), rnd(), rnd()))
            .collect();
        let tree = NearestTree::new(&points);
        for _ in 0..300 {
            let q = Vector3::new(rnd(), rnd(), rnd()) + Vector3::new(0.003, 0.001, 0.002);
            let best = points
                .iter()
                .map(|p| (p - q).norm_squared())
                .fold(f64::INFINITY, f64::min);
            let (i, d2) = tree.nearest(&q).unwrap();
            assert!(
                (d2 - best).abs() < 1e-6 && ((points[i] - q).norm_squared() - best).abs() < 1e-6
            );
            let mut count = 0;
            tree.within(&q, 0.025, |i, d2| {
                assert!(d2 <= 0.025f64.powi(2) + 1e-7 && (points[i] - q).norm() <= 0.025 + 1e-6);
                count += 1;
            });
            let truth = points
                .iter()
                .filter(|p| (*p - q).norm() < 0.025 - 1e-6)
                .count();
            assert!(count >= truth, "{count} < {truth}");
        }
        assert!(NearestTree::new(&[]).nearest(&Vector3::zeros()).is_none());
    }
}
