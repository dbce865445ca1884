//! The reference grid graphs of `shared/fixtures/maxflow` (defined by a formula there), for
//! tests and benchmarks against PyMaxflow.

use super::Graph;

/// The fixture graph of shared/fixtures/maxflow for size n (see its README).
pub fn fixture_graph(n: usize) -> Graph {
    fn splitmix64(k: u64) -> u64 {
        crate::synth::rng::mix64(k)
    }
    let idx = |x: usize, y: usize, z: usize| x + n * (y + n * z);
    let mut g = Graph::new(n * n * n);
    let rd = (6 * n as i64) / 10;
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let i = idx(x, y, z);
                let (dx, dy, dz) = (
                    2 * x as i64 + 1 - n as i64,
                    2 * y as i64 + 1 - n as i64,
                    2 * z as i64 + 1 - n as i64,
                );
                let s = dx * dx + dy * dy + dz * dz;
                let field = (s - rd * rd).abs() / n as i64;
                for (a, (nx, ny, nz)) in [(x + 1, y, z), (x, y + 1, z), (x, y, z + 1)]
                    .into_iter()
                    .enumerate()
                {
                    if nx < n && ny < n && nz < n {
                        let w = 1 + field.min(200) as u64 + splitmix64(3 * i as u64 + a as u64) % 8;
                        g.add_edge(i, idx(nx, ny, nz), w as f32, w as f32);
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
