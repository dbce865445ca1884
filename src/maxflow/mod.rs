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
    head: Vec<u32>,
    sister: Vec<u32>,
    r_cap: Vec<f32>,
    parent: Vec<u32>,
    is_sink: Vec<bool>,
    next_active: Vec<u32>,
    ts: Vec<u32>,
    dist: Vec<u32>,
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
            head: Vec::new(),
            sister: Vec::new(),
            r_cap: Vec::new(),
            parent: Vec::new(),
            is_sink: Vec::new(),
            next_active: Vec::new(),
            ts: Vec::new(),
            dist: Vec::new(),
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
        let (mut head, mut sister, mut r_cap) = (vec![0u32; m], vec![0u32; m], vec![0f32; m]);
        for &(i, j, c, rc) in &self.edges {
            let a = fill[i as usize];
            fill[i as usize] += 1;
            let b = fill[j as usize];
            fill[j as usize] += 1;
            head[a as usize] = j;
            r_cap[a as usize] = c;
            sister[a as usize] = b;
            head[b as usize] = i;
            r_cap[b as usize] = rc;
            sister[b as usize] = a;
        }
        self.edges = Vec::new();
        self.first = first;
        self.head = head;
        self.sister = sister;
        self.r_cap = r_cap;
    }

    /// Computes the maximum flow (the minimum cut's capacity).
    pub fn maxflow(&mut self) -> f64 {
        self.maxflow_with_progress(&mut |_, _| {})
    }

    /// [`Graph::maxflow`], calling `progress` every few thousand augmentations.
    pub fn maxflow_with_progress(&mut self, progress: Progress) -> f64 {
        self.build();
        let n = self.n;
        self.parent = vec![NONE; n];
        self.is_sink = vec![false; n];
        self.next_active = vec![NONE; n];
        self.ts = vec![0; n];
        self.dist = vec![0; n];
        let mut queue = ActiveQueue::default();
        for i in 0..n {
            if self.tr_cap[i] != 0.0 {
                self.is_sink[i] = self.tr_cap[i] < 0.0;
                self.parent[i] = TERMINAL;
                self.dist[i] = 1;
                queue.push(&mut self.next_active, i as u32);
            }
        }
        let mut time: u32 = 0;
        let mut current: u32 = NONE;
        let mut orphans: VecDeque<u32> = VecDeque::new();
        let mut augmentations: u64 = 0;
        loop {
            let mut i = current;
            if i != NONE {
                self.next_active[i as usize] = NONE; // removes the active mark
                if self.parent[i as usize] == NONE {
                    i = NONE;
                }
            }
            if i == NONE {
                match queue.pop(&mut self.next_active, &self.parent) {
                    Some(k) => i = k,
                    None => break,
                }
            }
            let iu = i as usize;
            // Growth.
            let mut middle = NONE;
            let (a0, a1) = (self.first[iu] as usize, self.first[iu + 1] as usize);
            if !self.is_sink[iu] {
                for a in a0..a1 {
                    if self.r_cap[a] > 0.0 {
                        let j = self.head[a] as usize;
                        if self.parent[j] == NONE {
                            self.is_sink[j] = false;
                            self.parent[j] = self.sister[a];
                            self.ts[j] = self.ts[iu];
                            self.dist[j] = self.dist[iu] + 1;
                            queue.push(&mut self.next_active, j as u32);
                        } else if self.is_sink[j] {
                            middle = a as u32;
                            break;
                        } else if self.ts[j] <= self.ts[iu] && self.dist[j] > self.dist[iu] {
                            self.parent[j] = self.sister[a];
                            self.ts[j] = self.ts[iu];
                            self.dist[j] = self.dist[iu] + 1;
                        }
                    }
                }
            } else {
                for a in a0..a1 {
                    if self.r_cap[self.sister[a] as usize] > 0.0 {
                        let j = self.head[a] as usize;
                        if self.parent[j] == NONE {
                            self.is_sink[j] = true;
                            self.parent[j] = self.sister[a];
                            self.ts[j] = self.ts[iu];
                            self.dist[j] = self.dist[iu] + 1;
                            queue.push(&mut self.next_active, j as u32);
                        } else if !self.is_sink[j] {
                            middle = self.sister[a];
                            break;
                        } else if self.ts[j] <= self.ts[iu] && self.dist[j] > self.dist[iu] {
                            self.parent[j] = self.sister[a];
                            self.ts[j] = self.ts[iu];
                            self.dist[j] = self.dist[iu] + 1;
                        }
                    }
                }
            }
            time = time.wrapping_add(1);
            if middle != NONE {
                // Keep growing from this node next time.
                self.next_active[iu] = i;
                current = i;
                self.augment(middle as usize, &mut orphans);
                augmentations += 1;
                if augmentations % 65_536 == 0 {
                    progress(self.flow, augmentations);
                }
                while let Some(o) = orphans.pop_front() {
                    if self.is_sink[o as usize] {
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
        let mut bottleneck = self.r_cap[middle] as f64;
        let mut i = self.head[self.sister[middle] as usize] as usize;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                break;
            }
            bottleneck = bottleneck.min(self.r_cap[self.sister[a as usize] as usize] as f64);
            i = self.head[a as usize] as usize;
        }
        bottleneck = bottleneck.min(self.tr_cap[i]);
        let mut i = self.head[middle] as usize;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                break;
            }
            bottleneck = bottleneck.min(self.r_cap[a as usize] as f64);
            i = self.head[a as usize] as usize;
        }
        bottleneck = bottleneck.min(-self.tr_cap[i]);
        let b = bottleneck as f32;
        // Augmentation.
        self.r_cap[self.sister[middle] as usize] += b;
        self.r_cap[middle] -= b;
        let mut i = self.head[self.sister[middle] as usize] as usize;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                break;
            }
            let (au, su) = (a as usize, self.sister[a as usize] as usize);
            self.r_cap[au] += b;
            self.r_cap[su] -= b;
            if self.r_cap[su] <= 0.0 {
                self.r_cap[su] = 0.0;
                self.parent[i] = ORPHAN;
                orphans.push_front(i as u32);
            }
            i = self.head[au] as usize;
        }
        self.tr_cap[i] -= bottleneck;
        if self.tr_cap[i] <= 0.0 {
            self.tr_cap[i] = 0.0;
            self.parent[i] = ORPHAN;
            orphans.push_front(i as u32);
        }
        let mut i = self.head[middle] as usize;
        loop {
            let a = self.parent[i];
            if a == TERMINAL {
                break;
            }
            let (au, su) = (a as usize, self.sister[a as usize] as usize);
            self.r_cap[su] += b;
            self.r_cap[au] -= b;
            if self.r_cap[au] <= 0.0 {
                self.r_cap[au] = 0.0;
                self.parent[i] = ORPHAN;
                orphans.push_front(i as u32);
            }
            i = self.head[au] as usize;
        }
        self.tr_cap[i] += bottleneck;
        if self.tr_cap[i] >= 0.0 {
            self.tr_cap[i] = 0.0;
            self.parent[i] = ORPHAN;
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
            if self.ts[j] == time {
                d += self.dist[j];
                break;
            }
            let a = self.parent[j];
            d += 1;
            if a == TERMINAL {
                self.ts[j] = time;
                self.dist[j] = 1;
                break;
            }
            if a == ORPHAN {
                return INFINITE_D;
            }
            j = self.head[a as usize] as usize;
        }
        // Set marks along the path.
        let mut j = start;
        let mut dd = d;
        while self.ts[j] != time {
            self.ts[j] = time;
            self.dist[j] = dd;
            dd -= 1;
            j = self.head[self.parent[j] as usize] as usize;
        }
        d
    }

    fn adopt_source_orphan(&mut self, i: usize, time: u32, orphans: &mut VecDeque<u32>, queue: &mut ActiveQueue) {
        self.adopt(i, time, orphans, queue, false);
    }

    fn adopt_sink_orphan(&mut self, i: usize, time: u32, orphans: &mut VecDeque<u32>, queue: &mut ActiveQueue) {
        self.adopt(i, time, orphans, queue, true);
    }

    /// Adoption of orphan `i` of the source tree (`sink == false`) or the sink tree.
    fn adopt(&mut self, i: usize, time: u32, orphans: &mut VecDeque<u32>, queue: &mut ActiveQueue, sink: bool) {
        let (a0, a1) = (self.first[i] as usize, self.first[i + 1] as usize);
        let mut best_arc = NONE;
        let mut best_d = INFINITE_D;
        for a in a0..a1 {
            // A source-tree parent must send flow to i (residual j -> i, the sister of a);
            // a sink-tree parent must receive flow from i (residual i -> j, arc a).
            let residual = if sink { self.r_cap[a] } else { self.r_cap[self.sister[a] as usize] };
            if residual <= 0.0 {
                continue;
            }
            let j = self.head[a] as usize;
            if self.is_sink[j] == sink && self.parent[j] != NONE {
                let d = self.origin_distance(j, time);
                if d < best_d {
                    best_d = d;
                    best_arc = a as u32;
                }
            }
        }
        if best_arc != NONE {
            self.parent[i] = best_arc;
            self.ts[i] = time;
            self.dist[i] = best_d + 1;
            return;
        }
        // No parent found: i becomes free; its children become orphans, and neighbours that
        // could reach it become active again.
        self.parent[i] = NONE;
        for a in a0..a1 {
            let j = self.head[a] as usize;
            let pj = self.parent[j];
            if self.is_sink[j] == sink && pj != NONE {
                let residual = if sink { self.r_cap[a] } else { self.r_cap[self.sister[a] as usize] };
                if residual > 0.0 {
                    queue.push(&mut self.next_active, j as u32);
                }
                if pj != TERMINAL && pj != ORPHAN && self.head[pj as usize] as usize == i {
                    self.parent[j] = ORPHAN;
                    orphans.push_back(j as u32);
                }
            }
        }
    }

    /// After [`Graph::maxflow`]: whether node `i` is on the source side of the minimum cut
    /// (reachable from the source in the residual graph).
    pub fn is_source_side(&self, i: usize) -> bool {
        self.parent[i] != NONE && !self.is_sink[i]
    }
}

/// FIFO of active nodes threaded through `next_active` (a node's entry is `NONE` when it is
/// not queued, itself when it is the last).
#[derive(Default)]
struct ActiveQueue {
    first: Option<u32>,
    last: u32,
}

impl ActiveQueue {
    fn push(&mut self, next: &mut [u32], i: u32) {
        if next[i as usize] != NONE {
            return; // already queued (or the current node)
        }
        next[i as usize] = i;
        match self.first {
            None => self.first = Some(i),
            Some(_) => next[self.last as usize] = i,
        }
        self.last = i;
    }

    /// Next queued node that is still in a tree.
    fn pop(&mut self, next: &mut [u32], parent: &[u32]) -> Option<u32> {
        while let Some(i) = self.first {
            let n = next[i as usize];
            self.first = if n == i { None } else { Some(n) };
            next[i as usize] = NONE;
            if parent[i as usize] != NONE {
                return Some(i);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests;
