//! The reference grid graphs of `shared/fixtures/maxflow` (defined by a formula there), for
//! tests and benchmarks against PyMaxflow.

use super::GridGraph;

/// The fixture graph of shared/fixtures/maxflow for size n (see its README). Node (x, y, z)
/// is i = x + n (y + n z).
pub fn fixture_graph(n: usize) -> GridGraph {
    let mut g = GridGraph::new([n, n, n]);
    let rd = (6 * n as i64) / 10;
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let i = x + n * (y + n * z);
                let (dx, dy, dz) = (
                    2 * x as i64 + 1 - n as i64,
                    2 * y as i64 + 1 - n as i64,
                    2 * z as i64 + 1 - n as i64,
                );
                let s = dx * dx + dy * dy + dz * dz;
                let field = (s - rd * rd).abs() / n as i64;
                for (a, c) in [x, y, z].into_iter().enumerate() {
                    if c + 1 < n {
                        let hash = crate::rng::mix64(3 * i as u64 + a as u64);
                        let w = 1 + field.min(200) as u64 + hash % 8;
                        g.set_edge(i, a, w as f32, w as f32);
                    }
                }
                let border = [x, y, z].iter().any(|&c| c == 0 || c == n - 1);
                let source = if border { 1_000_000_000.0 } else { 0.0 };
                let sink = 1.0
                    + if s < (rd / 2) * (rd / 2) {
                        1_000_000_000.0
                    } else {
                        0.0
                    };
                g.add_terminal_weights(i, source, sink);
            }
        }
    }
    g
}
