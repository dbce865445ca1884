//! Anderson acceleration (type II) of a fixed-point iteration x <- G(x), as AA-ICP (Pavlov
//! et al. 2018) applies it to ICP: from the last m+1 iterates x_i and images g_i = G(x_i),
//! with residuals f_i = g_i - x_i, the next iterate is g_k - dG gamma, where gamma
//! minimizes |f_k - dF gamma| over the differences dF, dG of consecutive f and g.

use nalgebra::{DMatrix, DVector};
use std::collections::VecDeque;

pub struct Anderson {
    depth: usize,
    /// (g_i, f_i), oldest first.
    history: VecDeque<(DVector<f64>, DVector<f64>)>,
}

impl Anderson {
    /// Remembers `depth` differences; 0 disables the acceleration.
    pub fn new(depth: usize) -> Anderson {
        Anderson {
            depth,
            history: VecDeque::new(),
        }
    }

    pub fn reset(&mut self) {
        self.history.clear();
    }

    /// Records the round x -> g and returns the extrapolated next iterate, or `None` while
    /// there is no history yet (then g is the next iterate).
    pub fn next(&mut self, x: &[f64], g: &[f64]) -> Option<Vec<f64>> {
        if self.depth == 0 {
            return None;
        }
        let g = DVector::from_column_slice(g);
        let f = &g - DVector::from_column_slice(x);
        self.history.push_back((g.clone(), f.clone()));
        if self.history.len() > self.depth + 1 {
            self.history.pop_front();
        }
        let m = self.history.len() - 1;
        if m == 0 {
            return None;
        }
        let n = g.len();
        let mut df = DMatrix::zeros(n, m);
        let mut dg = DMatrix::zeros(n, m);
        for i in 0..m {
            df.set_column(i, &(&self.history[i + 1].1 - &self.history[i].1));
            dg.set_column(i, &(&self.history[i + 1].0 - &self.history[i].0));
        }
        // Least squares by the normal equations with a little ridge for stability.
        let mut a = df.transpose() * &df;
        let scale = a.trace() / m as f64;
        for i in 0..m {
            a[(i, i)] += 1e-10 * scale + 1e-300;
        }
        let gamma = a.cholesky()?.solve(&(df.transpose() * &f));
        let next = g - dg * gamma;
        next.iter()
            .all(|v| v.is_finite())
            .then(|| next.as_slice().to_vec())
    }
}
