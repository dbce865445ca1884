use super::*;
use crate::maxflow::fixture::fixture_graph;

#[test]
fn splitmix_matches_the_fixture_definition() {
    // splitmix64(0) from the reference definition.
    assert_eq!(crate::rng::mix64(0), 0xE220A8397B1DCDAF);
}

/// The fixture values PyMaxflow computed (shared/fixtures/maxflow/expected.json).
fn expected(n: usize) -> f64 {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/fixtures/maxflow/expected.json");
    let text = std::fs::read_to_string(&path).unwrap_or_default();
    // Each graph sits on one line: {"n": N, "nodes": .., "flow": F, ...}
    for line in text.lines() {
        if line.contains(&format!("\"n\": {n},")) {
            let after = &line[line.find("\"flow\":").unwrap() + 7..];
            return after.split(',').next().unwrap().trim().parse().unwrap();
        }
    }
    // Without the shared folder: the values as published there.
    match n {
        16 => 4655.0,
        32 => 36184.0,
        64 => 261587.0,
        128 => 1979111.0,
        _ => panic!("no fixture {n}"),
    }
}

#[test]
fn reproduces_pymaxflow_on_the_fixtures_up_to_64() {
    for n in [16, 32, 64] {
        let flow = expected(n);
        let mut g = fixture_graph(n);
        let f = g.maxflow();
        assert!((f - flow).abs() <= 1e-6 * flow, "n = {n}: {f} vs {flow}");
    }
}

/// The 128^3 fixture (2 M nodes, about 30 s at the test profile's optimization).
#[test]
fn reproduces_pymaxflow_on_the_128_fixture() {
    let flow = expected(128);
    let f = fixture_graph(128).maxflow();
    assert!((f - flow).abs() <= 1e-6 * flow, "{f} vs {flow}");
}

/// Edmonds-Karp on a dense capacity matrix: the reference.
fn edmonds_karp(cap: &[Vec<f64>], s: usize, t: usize) -> f64 {
    let n = cap.len();
    let mut r = cap.to_vec();
    let mut flow = 0.0;
    loop {
        let mut prev = vec![usize::MAX; n];
        prev[s] = s;
        let mut q = std::collections::VecDeque::from([s]);
        while let Some(u) = q.pop_front() {
            for v in 0..n {
                if prev[v] == usize::MAX && r[u][v] > 1e-12 {
                    prev[v] = u;
                    q.push_back(v);
                }
            }
        }
        if prev[t] == usize::MAX {
            return flow;
        }
        let mut b = f64::INFINITY;
        let mut v = t;
        while v != s {
            b = b.min(r[prev[v]][v]);
            v = prev[v];
        }
        let mut v = t;
        while v != s {
            r[prev[v]][v] -= b;
            r[v][prev[v]] += b;
            v = prev[v];
        }
        flow += b;
    }
}

/// One random grid graph (integer capacities, some zero) beside its dense capacity matrix
/// (nodes 0..n, source n, sink n + 1).
fn random_grid(rng: &mut crate::rng::Rng, dims: [usize; 3]) -> (GridGraph, Vec<Vec<f64>>) {
    let n = dims[0] * dims[1] * dims[2];
    let mut cap = vec![vec![0.0; n + 2]; n + 2];
    let mut g = GridGraph::new(dims);
    let steps = [1, dims[0], dims[0] * dims[1]];
    for i in 0..n {
        let c = [
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        ];
        for axis in 0..3 {
            if c[axis] + 1 < dims[axis] {
                let (w, rw) = ((rng.next_u64() % 10) as f64, (rng.next_u64() % 10) as f64);
                g.set_edge(i, axis, w as f32, rw as f32);
                cap[i][i + steps[axis]] += w;
                cap[i + steps[axis]][i] += rw;
            }
        }
        let (cs, ct) = ((rng.next_u64() % 12) as f64, (rng.next_u64() % 12) as f64);
        let (cs, ct) = (
            if rng.uniform() < 0.6 { 0.0 } else { cs },
            if rng.uniform() < 0.6 { 0.0 } else { ct },
        );
        g.add_terminal_weights(i, cs, ct);
        cap[n][i] += cs;
        cap[i][n + 1] += ct;
    }
    (g, cap)
}

/// Random grids, some tall enough to be cut in parts and merged, on one thread and on two:
/// the flow equals Edmonds-Karp's, and the cut between the source side and the rest carries
/// exactly the flow.
#[test]
fn random_grids_agree_with_edmonds_karp_and_the_cut_equals_the_flow() {
    let mut rng = crate::rng::Rng::new(42, 0);
    let pools = [1, 2].map(|t| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
    });
    for trial in 0..300 {
        let dims = [
            1 + (rng.next_u64() % 3) as usize,
            1 + (rng.next_u64() % 3) as usize,
            1 + (rng.next_u64() % 40) as usize,
        ];
        let n = dims[0] * dims[1] * dims[2];
        let (mut g, cap) = random_grid(&mut rng, dims);
        if trial % 3 != 0 {
            g.split_at(2 + trial % 5, 0);
        }
        let reference = edmonds_karp(&cap, n, n + 1);
        let flow = pools[trial % 2].install(|| g.maxflow());
        assert_eq!(flow, reference, "trial {trial}, dims {dims:?}");
        let side: Vec<bool> = (0..n)
            .map(|i| g.is_source_side(i))
            .chain([true, false])
            .collect();
        let mut cut = 0.0;
        for u in 0..n + 2 {
            for v in 0..n + 2 {
                if side[u] && !side[v] {
                    cut += cap[u][v];
                }
            }
        }
        assert_eq!(cut, flow, "trial {trial}, dims {dims:?}: cut capacity");
    }
}

#[test]
fn zero_capacities_give_zero_flow_and_every_node_on_the_sink_side() {
    for dims in [[5, 1, 1], [3, 2, 40]] {
        let mut g = GridGraph::new(dims);
        for i in 0..g.node_count() {
            g.add_terminal_weights(i, 0.0, 0.0);
        }
        assert_eq!(g.maxflow(), 0.0);
        assert!((0..g.node_count()).all(|i| !g.is_source_side(i)));
    }
    let mut empty = GridGraph::new([0, 0, 0]);
    assert_eq!(empty.maxflow(), 0.0);
}

/// A source and a sink link on the same node: the shared part flows straight through.
#[test]
fn both_terminal_links_on_one_node() {
    let mut g = GridGraph::new([2, 1, 1]);
    g.add_terminal_weights(0, 5.0, 3.0);
    g.add_terminal_weights(0, 1.0, 0.0);
    g.add_terminal_weights(1, 0.0, 10.0);
    g.set_edge(0, 0, 2.0, 0.0);
    assert_eq!(g.maxflow(), 5.0);
    assert!(g.is_source_side(0) && !g.is_source_side(1));
}
