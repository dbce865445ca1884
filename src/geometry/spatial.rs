//! Exact nearest-point queries on a fixed point set, with a uniform hash grid searched in
//! growing shells. Suited to surface samples, whose density is roughly uniform.

use nalgebra::Vector3;
use std::collections::HashMap;

/// A nearest-neighbour index over points.
pub struct PointIndex {
    points: Vec<Vector3<f64>>,
    cell: f64,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl PointIndex {
    /// Indexes `points` with cells of `cell` metres (about the typical point spacing times
    /// a few works well).
    pub fn new(points: Vec<Vector3<f64>>, cell: f64) -> PointIndex {
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            cells.entry(Self::key(p, cell)).or_default().push(i as u32);
        }
        PointIndex {
            points,
            cell,
            cells,
        }
    }

    fn key(p: &Vector3<f64>, cell: f64) -> [i64; 3] {
        [
            (p.x / cell).floor() as i64,
            (p.y / cell).floor() as i64,
            (p.z / cell).floor() as i64,
        ]
    }

    pub fn points(&self) -> &[Vector3<f64>] {
        &self.points
    }

    /// The nearest indexed point to `q`: (index, distance). `None` for an empty index.
    pub fn nearest(&self, q: &Vector3<f64>) -> Option<(usize, f64)> {
        if self.points.is_empty() {
            return None;
        }
        let c = Self::key(q, self.cell);
        let mut best = (usize::MAX, f64::INFINITY);
        for r in 0i64.. {
            // Points in shell r are at least (r - 1) * cell away.
            if best.1 < (r - 1).max(0) as f64 * self.cell {
                break;
            }
            for dz in -r..=r {
                for dy in -r..=r {
                    for dx in -r..=r {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                            continue;
                        }
                        if let Some(list) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                            for &i in list {
                                let d = (self.points[i as usize] - q).norm();
                                if d < best.1 {
                                    best = (i as usize, d);
                                }
                            }
                        }
                    }
                }
            }
            if r > 100_000 {
                break;
            }
        }
        Some(best)
    }

    /// Whether some indexed point lies within `radius` metres of `q`.
    pub fn any_within(&self, q: &Vector3<f64>, radius: f64) -> bool {
        let (lo, hi) = (
            Self::key(&q.add_scalar(-radius), self.cell),
            Self::key(&q.add_scalar(radius), self.cell),
        );
        (lo[2]..=hi[2]).any(|z| {
            (lo[1]..=hi[1]).any(|y| {
                (lo[0]..=hi[0]).any(|x| {
                    self.cells.get(&[x, y, z]).is_some_and(|list| {
                        list.iter()
                            .any(|&i| (self.points[i as usize] - q).norm() <= radius)
                    })
                })
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agrees_with_brute_force() {
        let mut rng = crate::rng::Rng::new(1, 1);
        let pts: Vec<Vector3<f64>> = (0..500)
            .map(|_| Vector3::new(rng.uniform(), rng.uniform(), rng.uniform()))
            .collect();
        let index = PointIndex::new(pts.clone(), 0.05);
        for _ in 0..200 {
            let q = Vector3::new(
                rng.range(-0.5, 1.5),
                rng.range(-0.5, 1.5),
                rng.range(-0.5, 1.5),
            );
            let brute = pts
                .iter()
                .map(|p| (p - q).norm())
                .fold(f64::INFINITY, f64::min);
            assert_eq!(index.nearest(&q).unwrap().1, brute);
            for radius in [0.01, 0.05, 0.2] {
                assert_eq!(index.any_within(&q, radius), brute <= radius);
            }
        }
    }
}
