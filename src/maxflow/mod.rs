//! Maximum flow / minimum cut by the Boykov-Kolmogorov algorithm (PAMI 2004), for the large
//! sparse graphs of volumetric graph cuts.
//!
//! Layout: compact flat arrays with 32-bit indices and no per-node allocation. Arcs are
//! stored by tail node (CSR) once the graph is built; every arc knows its sister (the reverse
//! arc). Two search trees grow from the terminals (growth), a path found between them is
//! saturated (augmentation), and nodes cut off from their tree look for a new parent among
//! their neighbours before they are freed (adoption). Trees are reused from one augmentation
//! to the next; the distance/timestamp heuristics of Kolmogorov's maxflow v3 keep them
//! shallow. Capacities are `f32` on arcs (sums of a few weights) and `f64` on the terminal
//! links and the flow total; integer capacities stay exact.

pub mod fixture;

use std::collections::VecDeque;

/// Parent marks besides arc indices.
const NONE: u32 = u32::MAX; // free node
const TERMINAL: u32 = u32::MAX - 1; // child of a terminal
const ORPHAN: u32 = u32::MAX - 2; // lost its parent, awaiting adoption
/// End-of-list mark of the active queue (a node's `next` pointing at itself).
const INFINITE_D: u32 = u32::MAX;

/// A graph for one max-flow computation.
pub struct Graph {
    n: usize,
    edges: Vec<(u32, u32, f32, f32)>,
    /// Residual capacity of the terminal links: positive = from the source, negative = to
    /// the sink.
    tr_cap: Vec<f64>,
    /// Flow already pushed through both terminal links of a node.
    flow: f64,
    // Built by `maxflow`:
    first: Vec<u32>,
    arcs: Vec<Arc>,
    nodes: Vec<Node>,
}

/// An arc, with what the inner loops read together kept together.
#[derive(Clone, Copy, Default)]
struct Arc {
    head: u32,
    sister: u32,
    r_cap: f32,
}

/// Per-node search state (one cache line holds two nodes).
#[derive(Clone, Copy)]
struct Node {
    parent: u32,
    next: u32,
    ts: u32,
    dist: u32,
    is_sink: bool,
}

/// Progress report of a long cut: called with the flow so far and the augmentations done.
pub type Progress<'a> = &'a mut dyn FnMut(f64, u64);

impl Graph {
    /// A graph of `n` nodes (indices 0..n) without edges.
    pub fn new(n: usize) -> Graph {
        assert!(n < (u32::MAX - 3) as usize, "at most 2^32 - 4 nodes");
        Graph {
            n,
            edges: Vec::new(),
            tr_cap: vec![0.0; n],
            flow: 0.0,
            first: Vec::new(),
            arcs: Vec::new(),
            nodes: Vec::new(),
        }
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.n
    }

    /// Reserves room for `m` edges.
    pub fn reserve_edges(&mut self, m: usize) {
        self.edges.reserve(m);
    }

    /// Adds an edge i -> j of capacity `cap` and j -> i of capacity `rev_cap` (both >= 0).
    pub fn add_edge(&mut self, i: usize, j: usize, cap: f32, rev_cap: f32) {
        debug_assert!(i < self.n && j < self.n && i != j && cap >= 0.0 && rev_cap >= 0.0);
        self.edges.push((i as u32, j as u32, cap, rev_cap));
    }

    /// Adds terminal links: source -> i of capacity `source_cap`, i -> sink of `sink_cap`.
    pub fn add_terminal_weights(&mut self, i: usize, source_cap: f64, sink_cap: f64) {
        let delta = self.tr_cap[i];
        let (mut cs, mut ct) = (source_cap, sink_cap);
        if delta > 0.0 {
            cs += delta;
        } else {
            ct -= delta;
        }
        // The part both links share flows straight through the node.
        self.flow += cs.min(ct);
        self.tr_cap[i] = cs - ct;
    }

    /// Builds the arc arrays (by tail node) from the edge list.
    fn build(&mut self) {
        let n = self.n;
        let mut degree = vec![0u32; n + 1];
        for &(i, j, _, _) in &self.edges {
            degree[i as usize] += 1;
            degree[j as usize] += 1;
        }
        let mut first = vec![0u32; n + 1];
        for k in 0..n {
            first[k + 1] = first[k] + degree[k];
        }
        let m = first[n] as usize;
        let mut fill = first.clone();
        let mut arcs = vec![Arc::default(); m];
        for &(i, j, c, rc) in &self.edges {
            let a = fill[i as usize];
            fill[i as usize] += 1;
            let b = fill[j as usize];
            fill[j as usize] += 1;
            arcs[a as usize] = Arc {
                head: j,
                sister: b,
                r_cap: c,
            };
            arcs[b as usize] = Arc {
                head: i,
                sister: a,
                r_cap: rc,
            };
        }
        self.edges = Vec::new();
        self.first = first;
        self.arcs = arcs;
    }

    /// Computes the maximum flow (the minimum cut's capacity).
    pub fn maxflow(&mut self) -> f64 {
        self.maxflow_with_progress(&mut |_, _| {})
    }

    /// [`Graph::maxflow`], calling `progress` every few thousand augmentations.
    pub fn maxflow_with_progress(&mut self, progress: Progress) -> f64 {
        self.build();
        let n = self.n;
        self.nodes = vec![
            Node {
                parent: NONE,
                next: NONE,
                ts: 0,
                dist: 0,
                is_sink: false,
            };
            n
        ];
        let mut queue = ActiveQueue::default();
        for i in 0..n {
            if self.tr_cap[i] != 0.0 {
                self.nodes[i].is_sink = self.tr_cap[i] < 0.0;
                self.nodes[i].parent = TERMINAL;
                self.nodes[i].dist = 1;
                queue.push(&mut self.nodes, i as u32);
            }
        }
        let mut time: u32 = 0;
        let mut current: u32 = NONE;
        let mut orphans: VecDeque<u32> = VecDeque::new();
        let mut augmentations: u64 = 0;
        loop {
            let mut i = current;
            if i != NONE {
                self.nodes[i as usize].next = NONE; // removes the active mark
                if self.nodes[i as usize].parent == NONE {
                    i = NONE;
                }
            }
            if i == NONE {
                match queue.pop(&mut self.nodes) {
                    Some(k) => i = k,
                    None => break,
                }
            }
            let iu = i as usize;
            // Growth.
            let mut middle = NONE;
            let (a0, a1) = (self.first[iu] as usize, self.first[iu + 1] as usize);
            if !self.nodes[iu].is_sink {
                for a in a0..a1 {
                    if self.arcs[a].r_cap > 0.0 {
                        let j = self.arcs[a].head as usize;
                        if self.nodes[j].parent == NONE {
                            self.nodes[j].is_sink = false;
                            self.nodes[j].parent = self.arcs[a].sister;
                            self.nodes[j].ts = self.nodes[iu].ts;
                            self.nodes[j].dist = self.nodes[iu].dist + 1;
                            queue.push(&mut self.nodes, j as u32);
                        } else if self.nodes[j].is_sink {
                            middle = a as u32;
                            break;
                        } else if self.nodes[j].ts <= self.nodes[iu].ts
                            && self.nodes[j].dist > self.nodes[iu].dist
                        {
                            self.nodes[j].parent = self.arcs[a].sister;
                            self.nodes[j].ts = self.nodes[iu].ts;
                            self.nodes[j].dist = self.nodes[iu].dist + 1;
                        }
                    }
                }
            } else {
                for a in a0..a1 {
                    if self.arcs[self.arcs[a].sister as usize].r_cap > 0.0 {
                        let j = self.arcs[a].head as usize;
                        if self.nodes[j].parent == NONE {
                            self.nodes[j].is_sink = true;
                            self.nodes[j].parent = self.arcs[a].sister;
                            self.nodes[j].ts = self.nodes[iu].ts;
                            self.nodes[j].dist = self.nodes[iu].dist + 1;
                            queue.push(&mut self.nodes, j as u32);
                        } else if !self.nodes[j].is_sink {
                            middle = self.arcs[a].sister;
                            break;
                        } else if self.nodes[j].ts <= self.nodes[iu].ts
                            && self.nodes[j].dist > self.nodes[iu].dist
                        {
                            self.nodes[j].parent = self.arcs[a].sister;
                            self.nodes[j].ts = self.nodes[iu].ts;
                            self.nodes[j].dist = self.nodes[iu].dist + 1;
                        }
                    }
                }
            }
            time = time.wrapping_add(1);
            if middle != NONE {
                // Keep growing from this node next time.
                self.nodes[iu].next = i;
                current = i;
                self.augment(middle as usize, &mut orphans);
                augmentations += 1;
                if augmentations.is_multiple_of(65_536) {
                    progress(self.flow, augmentations);
                }
                while let Some(o) = orphans.pop_front() {
                    if self.nodes[o as usize].is_sink {
                        self.adopt_sink_orphan(o as usize, time, &mut orphans, &mut queue);
                    } else {
                        self.adopt_source_orphan(o as usize, time, &mut orphans, &mut queue);
                    }
                }
            } else {
                current = NONE;
            }
        }
        self.flow
    }

    /// Saturates the path through arc `middle` (source-tree tail to sink-tree head).
    fn augment(&mut self, middle: usize, orphans: &mut VecDeque<u32>) {
        // Bottleneck.
        let mut bottleneck = self.arcs[middle].r_cap as f64;
        let mut i = self.arcs[self.arcs[middle].sister as usize].head as usize;
        loop {
            let a = self.nodes[i].parent;
            if a == TERMINAL {
                break;
            }
            bottleneck =
                bottleneck.min(self.arcs[self.arcs[a as usize].sister as usize].r_cap as f64);
            i = self.arcs[a as usize].head as usize;
        }
        bottleneck = bottleneck.min(self.tr_cap[i]);
        let mut i = self.arcs[middle].head as usize;
        loop {
            let a = self.nodes[i].parent;
            if a == TERMINAL {
                break;
            }
            bottleneck = bottleneck.min(self.arcs[a as usize].r_cap as f64);
            i = self.arcs[a as usize].head as usize;
        }
        bottleneck = bottleneck.min(-self.tr_cap[i]);
        let b = bottleneck as f32;
        // Augmentation.
        let middle_sister = self.arcs[middle].sister as usize;
        self.arcs[middle_sister].r_cap += b;
        self.arcs[middle].r_cap -= b;
        let mut i = self.arcs[self.arcs[middle].sister as usize].head as usize;
        loop {
            let a = self.nodes[i].parent;
            if a == TERMINAL {
                break;
            }
            let (au, su) = (a as usize, self.arcs[a as usize].sister as usize);
            self.arcs[au].r_cap += b;
            self.arcs[su].r_cap -= b;
            if self.arcs[su].r_cap <= 0.0 {
                self.arcs[su].r_cap = 0.0;
                self.nodes[i].parent = ORPHAN;
                orphans.push_front(i as u32);
            }
            i = self.arcs[au].head as usize;
        }
        self.tr_cap[i] -= bottleneck;
        if self.tr_cap[i] <= 0.0 {
            self.tr_cap[i] = 0.0;
            self.nodes[i].parent = ORPHAN;
            orphans.push_front(i as u32);
        }
        let mut i = self.arcs[middle].head as usize;
        loop {
            let a = self.nodes[i].parent;
            if a == TERMINAL {
                break;
            }
            let (au, su) = (a as usize, self.arcs[a as usize].sister as usize);
            self.arcs[su].r_cap += b;
            self.arcs[au].r_cap -= b;
            if self.arcs[au].r_cap <= 0.0 {
                self.arcs[au].r_cap = 0.0;
                self.nodes[i].parent = ORPHAN;
                orphans.push_front(i as u32);
            }
            i = self.arcs[au].head as usize;
        }
        self.tr_cap[i] += bottleneck;
        if self.tr_cap[i] >= 0.0 {
            self.tr_cap[i] = 0.0;
            self.nodes[i].parent = ORPHAN;
            orphans.push_front(i as u32);
        }
        self.flow += bottleneck;
    }

    /// Distance of `j` to its tree's terminal through valid parents (`INFINITE_D` when the
    /// path meets an orphan), marking the nodes on the way with the current time.
    fn origin_distance(&mut self, start: usize, time: u32) -> u32 {
        let mut j = start;
        let mut d: u32 = 0;
        loop {
            if self.nodes[j].ts == time {
                d += self.nodes[j].dist;
                break;
            }
            let a = self.nodes[j].parent;
            d += 1;
            if a == TERMINAL {
                self.nodes[j].ts = time;
                self.nodes[j].dist = 1;
                break;
            }
            if a == ORPHAN {
                return INFINITE_D;
            }
            j = self.arcs[a as usize].head as usize;
        }
        // Set marks along the path.
        let mut j = start;
        let mut dd = d;
        while self.nodes[j].ts != time {
            self.nodes[j].ts = time;
            self.nodes[j].dist = dd;
            dd -= 1;
            j = self.arcs[self.nodes[j].parent as usize].head as usize;
        }
        d
    }

    fn adopt_source_orphan(
        &mut self,
        i: usize,
        time: u32,
        orphans: &mut VecDeque<u32>,
        queue: &mut ActiveQueue,
    ) {
        self.adopt(i, time, orphans, queue, false);
    }

    fn adopt_sink_orphan(
        &mut self,
        i: usize,
        time: u32,
        orphans: &mut VecDeque<u32>,
        queue: &mut ActiveQueue,
    ) {
        self.adopt(i, time, orphans, queue, true);
    }

    /// Adoption of orphan `i` of the source tree (`sink == false`) or the sink tree.
    fn adopt(
        &mut self,
        i: usize,
        time: u32,
        orphans: &mut VecDeque<u32>,
        queue: &mut ActiveQueue,
        sink: bool,
    ) {
        let (a0, a1) = (self.first[i] as usize, self.first[i + 1] as usize);
        let mut best_arc = NONE;
        let mut best_d = INFINITE_D;
        for a in a0..a1 {
            // A source-tree parent must send flow to i (residual j -> i, the sister of a);
            // a sink-tree parent must receive flow from i (residual i -> j, arc a).
            let residual = if sink {
                self.arcs[a].r_cap
            } else {
                self.arcs[self.arcs[a].sister as usize].r_cap
            };
            if residual <= 0.0 {
                continue;
            }
            let j = self.arcs[a].head as usize;
            if self.nodes[j].is_sink == sink && self.nodes[j].parent != NONE {
                let d = self.origin_distance(j, time);
                if d < best_d {
                    best_d = d;
                    best_arc = a as u32;
                }
            }
        }
        if best_arc != NONE {
            self.nodes[i].parent = best_arc;
            self.nodes[i].ts = time;
            self.nodes[i].dist = best_d + 1;
            return;
        }
        // No parent found: i becomes free; its children become orphans, and neighbours that
        // could reach it become active again.
        self.nodes[i].parent = NONE;
        for a in a0..a1 {
            let j = self.arcs[a].head as usize;
            let pj = self.nodes[j].parent;
            if self.nodes[j].is_sink == sink && pj != NONE {
                let residual = if sink {
                    self.arcs[a].r_cap
                } else {
                    self.arcs[self.arcs[a].sister as usize].r_cap
                };
                if residual > 0.0 {
                    queue.push(&mut self.nodes, j as u32);
                }
                if pj != TERMINAL && pj != ORPHAN && self.arcs[pj as usize].head as usize == i {
                    self.nodes[j].parent = ORPHAN;
                    orphans.push_back(j as u32);
                }
            }
        }
    }

    /// After [`Graph::maxflow`]: whether node `i` is on the source side of the minimum cut
    /// (reachable from the source in the residual graph).
    pub fn is_source_side(&self, i: usize) -> bool {
        self.nodes[i].parent != NONE && !self.nodes[i].is_sink
    }
}

/// FIFO of active nodes threaded through `Node::next` (a node's entry is `NONE` when it is
/// not queued, itself when it is the last).
#[derive(Default)]
struct ActiveQueue {
    first: Option<u32>,
    last: u32,
}

impl ActiveQueue {
    fn push(&mut self, nodes: &mut [Node], i: u32) {
        if nodes[i as usize].next != NONE {
            return; // already queued (or the current node)
        }
        nodes[i as usize].next = i;
        match self.first {
            None => self.first = Some(i),
            Some(_) => nodes[self.last as usize].next = i,
        }
        self.last = i;
    }

    /// Next queued node that is still in a tree.
    fn pop(&mut self, nodes: &mut [Node]) -> Option<u32> {
        while let Some(i) = self.first {
            let n = nodes[i as usize].next;
            self.first = if n == i { None } else { Some(n) };
            nodes[i as usize].next = NONE;
            if nodes[i as usize].parent != NONE {
                return Some(i);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests;
