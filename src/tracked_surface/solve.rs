//! The tracked surface's normal equations and their solution by conjugate gradients.
//!
//! Unknowns: one offset δ_i (metres) per vertex from its target. The energy is quadratic:
//!
//!   E(δ) = Σ_i (δ_i − g_i)ᵀ D_i (δ_i − g_i) + λ_e Σ_(i,j) |δ_i − δ_j|² + λ_a Σ_i |δ_i|²
//!
//! with D_i a symmetric 3x3 block (the data terms of the vertex) and D_i g_i their pull
//! (`rhs`), so its minimum solves (D + λ_e K + λ_a I) δ = b, K the mesh's graph Laplacian
//! (degree on the diagonal, −1 per edge). The matrix is symmetric positive definite
//! (λ_a > 0) and applied without being stored; a block-Jacobi preconditioner and a warm
//! start (the previous round's offsets) make a few dozen iterations enough.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// The system of one round: the data blocks and pulls over a fixed graph (the mesh's
/// vertices and edges, or [`Coarse`] patches of them with the edges between them counted).
pub struct System<'a> {
    /// Each node's neighbours with the number of edges to each (sorted, no repeats).
    pub neighbours: &'a [Vec<(u32, f64)>],
    /// How many vertices each node stands for (1 on the mesh itself).
    pub mass: &'a [f64],
    /// D_i, per node.
    pub blocks: Vec<Matrix3<f64>>,
    /// b_i = the data terms' pull, per node.
    pub rhs: Vec<Vector3<f64>>,
    /// λ_e, the weight of the edges' offsets' differences.
    pub shape: f64,
    /// λ_a, the weight of the offsets themselves (per vertex).
    pub anchor: f64,
}

/// Patches of the mesh: the connected pieces of the mesh within each cell of a grid. As
/// one offset per patch, the system has a tenth to a fiftieth of the unknowns and its
/// smooth part, which conjugate gradients on the vertices converge to slowest, is solved
/// there first (a two-level solve: the patches' correction, then a few iterations on the
/// vertices smooth the steps between patches).
pub struct Coarse {
    /// Each vertex's patch.
    pub patch: Vec<u32>,
    /// The patches' graph: neighbours with the number of mesh edges between them.
    pub neighbours: Vec<Vec<(u32, f64)>>,
    /// Vertices per patch.
    pub mass: Vec<f64>,
}

impl Coarse {
    /// Patches of `vertices` (metres) joined by `neighbours` (the mesh's edges) within
    /// cells of `cell` metres.
    pub fn new(vertices: &[Vector3<f64>], neighbours: &[Vec<(u32, f64)>], cell: f64) -> Coarse {
        let n = vertices.len();
        let cell_of =
            |v: &Vector3<f64>| -> [i64; 3] { [v.x, v.y, v.z].map(|c| (c / cell).floor() as i64) };
        let cells: Vec<[i64; 3]> = vertices.iter().map(cell_of).collect();
        // Connected pieces within a cell, by a flood over the edges inside it.
        let mut patch = vec![u32::MAX; n];
        let mut count = 0u32;
        let mut stack = Vec::new();
        for start in 0..n {
            if patch[start] != u32::MAX {
                continue;
            }
            patch[start] = count;
            stack.push(start);
            while let Some(i) = stack.pop() {
                for &(j, _) in &neighbours[i] {
                    let j = j as usize;
                    if patch[j] == u32::MAX && cells[j] == cells[i] {
                        patch[j] = count;
                        stack.push(j);
                    }
                }
            }
            count += 1;
        }
        let mut mass = vec![0.0; count as usize];
        let mut links: Vec<std::collections::BTreeMap<u32, f64>> =
            vec![Default::default(); count as usize];
        for i in 0..n {
            mass[patch[i] as usize] += 1.0;
            for &(j, w) in &neighbours[i] {
                let (a, b) = (patch[i], patch[j as usize]);
                if a != b {
                    *links[a as usize].entry(b).or_insert(0.0) += w;
                }
            }
        }
        Coarse {
            patch,
            neighbours: links.into_iter().map(|m| m.into_iter().collect()).collect(),
            mass,
        }
    }
}

/// The mesh's edges as unit-weight neighbour lists.
pub fn unit_neighbours(lists: &[Vec<u32>]) -> Vec<Vec<(u32, f64)>> {
    lists
        .iter()
        .map(|l| l.iter().map(|&j| (j, 1.0)).collect())
        .collect()
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solved {
    pub iterations: usize,
    /// |residual| / |b| at the end.
    pub relative_residual: f64,
}

/// Entries per block of a dot product's partial sums.
const DOT_BLOCK: usize = 4096;

/// a · b, summed in fixed blocks and then in order: the same bits whatever the threads
/// did (a parallel sum's order, and so its rounding, depends on how the work was split),
/// so that a resumed run writes what a fresh one writes.
fn dot(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    let partial: Vec<f64> = a
        .par_chunks(DOT_BLOCK)
        .zip(b.par_chunks(DOT_BLOCK))
        .map(|(x, y)| x.iter().zip(y).map(|(x, y)| x.dot(y)).sum::<f64>())
        .collect();
    partial.iter().sum()
}

impl System<'_> {
    /// out = A x.
    pub fn apply(&self, x: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
        out.par_iter_mut().enumerate().for_each(|(i, out)| {
            let mut sum = Vector3::zeros();
            let mut degree = 0.0;
            for &(j, w) in &self.neighbours[i] {
                sum += w * x[j as usize];
                degree += w;
            }
            *out = self.blocks[i] * x[i]
                + (self.anchor * self.mass[i]) * x[i]
                + self.shape * (degree * x[i] - sum);
        });
    }

    /// The residual b − A x.
    pub fn residual(&self, x: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        let mut ax = vec![Vector3::zeros(); x.len()];
        self.apply(x, &mut ax);
        self.rhs.iter().zip(&ax).map(|(b, a)| b - a).collect()
    }

    /// Solves A x = b from `x`: first the correction on the `coarse` patches (solved to
    /// `tolerance`), then conjugate gradients on the nodes themselves from there, at most
    /// `max_iterations`.
    pub fn solve_two_level(
        &self,
        coarse: &Coarse,
        x: &mut [Vector3<f64>],
        tolerance: f64,
        max_iterations: usize,
    ) -> Solved {
        let np = coarse.mass.len();
        let mut blocks = vec![Matrix3::zeros(); np];
        let mut rhs = vec![Vector3::zeros(); np];
        let residual = self.residual(x);
        for (i, &p) in coarse.patch.iter().enumerate() {
            blocks[p as usize] += self.blocks[i];
            rhs[p as usize] += residual[i];
        }
        let system = System {
            neighbours: &coarse.neighbours,
            mass: &coarse.mass,
            blocks,
            rhs,
            shape: self.shape,
            anchor: self.anchor,
        };
        let mut correction = vec![Vector3::zeros(); np];
        let first = system.solve(&mut correction, tolerance, 20 * max_iterations);
        x.par_iter_mut()
            .zip(&coarse.patch)
            .for_each(|(x, &p)| *x += correction[p as usize]);
        let then = self.solve(x, tolerance, max_iterations);
        Solved {
            iterations: first.iterations + then.iterations,
            relative_residual: then.relative_residual,
        }
    }

    /// Solves A x = b from `x` (the warm start) by preconditioned conjugate gradients,
    /// until the residual is `tolerance` times |b| or after `max_iterations`.
    pub fn solve(&self, x: &mut [Vector3<f64>], tolerance: f64, max_iterations: usize) -> Solved {
        // Block-Jacobi: the inverse of each vertex's 3x3 diagonal block.
        let inverse: Vec<Matrix3<f64>> = (0..x.len())
            .into_par_iter()
            .map(|i| {
                let degree: f64 = self.neighbours[i].iter().map(|x| x.1).sum();
                let diag = self.anchor * self.mass[i] + self.shape * degree;
                let m = self.blocks[i] + Matrix3::identity() * diag;
                m.try_inverse()
                    .unwrap_or_else(|| Matrix3::identity() / diag)
            })
            .collect();
        let norm_b = dot(&self.rhs, &self.rhs).sqrt();
        if norm_b == 0.0 {
            x.iter_mut().for_each(|v| *v = Vector3::zeros());
            return Solved {
                iterations: 0,
                relative_residual: 0.0,
            };
        }
        let mut ap = vec![Vector3::zeros(); x.len()];
        self.apply(x, &mut ap);
        let mut r: Vec<Vector3<f64>> = self.rhs.iter().zip(&ap).map(|(b, a)| b - a).collect();
        let mut z: Vec<Vector3<f64>> = r.par_iter().zip(&inverse).map(|(r, m)| m * r).collect();
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        let mut iterations = 0;
        let mut residual = dot(&r, &r).sqrt() / norm_b;
        while iterations < max_iterations && residual > tolerance {
            self.apply(&p, &mut ap);
            let pap = dot(&p, &ap);
            if pap <= 0.0 {
                break;
            }
            let alpha = rz / pap;
            x.par_iter_mut().zip(&p).for_each(|(x, p)| *x += alpha * p);
            r.par_iter_mut()
                .zip(&ap)
                .for_each(|(r, ap)| *r -= alpha * ap);
            z.par_iter_mut()
                .zip(&r)
                .zip(&inverse)
                .for_each(|((z, r), m)| *z = m * r);
            let rz_next = dot(&r, &z);
            let beta = rz_next / rz;
            rz = rz_next;
            p.par_iter_mut()
                .zip(&z)
                .for_each(|(p, z)| *p = z + beta * *p);
            iterations += 1;
            residual = dot(&r, &r).sqrt() / norm_b;
        }
        Solved {
            iterations,
            relative_residual: residual,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain of 50 vertices, one end pulled 1 cm along x: the solve agrees with the
    /// directly computed minimum (a dense solve of the same system).
    #[test]
    fn conjugate_gradients_reach_the_direct_solution() {
        let n = 50;
        let neighbours: Vec<Vec<u32>> = (0..n)
            .map(|i| {
                let mut v = Vec::new();
                if i > 0 {
                    v.push(i as u32 - 1);
                }
                if i + 1 < n {
                    v.push(i as u32 + 1);
                }
                v
            })
            .collect();
        let mut blocks = vec![Matrix3::zeros(); n];
        let mut rhs = vec![Vector3::zeros(); n];
        blocks[0] = Matrix3::identity() * 2.0;
        rhs[0] = Vector3::new(0.02, 0.0, 0.0);
        let neighbours = unit_neighbours(&neighbours);
        let mass = vec![1.0; n];
        let system = System {
            neighbours: &neighbours,
            mass: &mass,
            blocks,
            rhs,
            shape: 1.0,
            anchor: 0.01,
        };
        let mut x = vec![Vector3::zeros(); n];
        let solved = system.solve(&mut x, 1e-10, 500);
        assert!(solved.relative_residual <= 1e-10, "{solved:?}");
        // Dense: the x components form a tridiagonal system.
        let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            a[(i, i)] = 0.01 + neighbours[i].len() as f64 + if i == 0 { 2.0 } else { 0.0 };
            for &(j, _) in &neighbours[i] {
                a[(i, j as usize)] = -1.0;
            }
        }
        let mut b = nalgebra::DVector::<f64>::zeros(n);
        b[0] = 0.02;
        let direct = a.lu().solve(&b).expect("invertible");
        for i in 0..n {
            assert!((x[i].x - direct[i]).abs() < 1e-9, "vertex {i}");
            assert!(x[i].y.abs() < 1e-12 && x[i].z.abs() < 1e-12);
        }
        // The pull spreads and fades along the chain.
        assert!(x[0].x > x[10].x && x[10].x > x[40].x && x[40].x > 0.0);
        // The two-level solve, over patches of 5 vertices, reaches the same minimum.
        let along: Vec<Vector3<f64>> = (0..n).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        let coarse = Coarse::new(&along, &neighbours, 5.0);
        assert_eq!(coarse.mass.len(), 10);
        let mut y = vec![Vector3::zeros(); n];
        system.solve_two_level(&coarse, &mut y, 1e-10, 500);
        for i in 0..n {
            assert!((y[i].x - direct[i]).abs() < 1e-9, "two-level, vertex {i}");
        }
    }
}
