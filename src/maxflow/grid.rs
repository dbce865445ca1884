//! The grid solver: Boykov-Kolmogorov on a 6-connected grid with implicit neighbours (see the
//! module's documentation in `mod.rs` for the layout).

use std::collections::VecDeque;

/// Parent codes besides the directions 0..6.
const TERMINAL: u8 = 6;
const ORPHAN: u8 = 7;
const FREE: u8 = 8;
const NOT_QUEUED: u32 = u32::MAX;
const INFINITE_D: u32 = u32::MAX;
/// Grids with fewer planes along z, or fewer nodes with a link, are cut in one piece.
/// Splitting pays on large dense grids (the 64^3 fixture: 0.70 s in one piece, 0.29 s in
/// parts on 2 threads, 0.46 s on one) but not on the thin band of a graph-cut frame (62 k
/// band nodes in a 246 k box: 25 ms in one piece, 45 ms in parts).
const MIN_SPLIT_PLANES: usize = 16;
const MIN_SPLIT_LINKED: usize = 1 << 17;

/// What the tree walks read, packed in 8 bytes.
#[derive(Clone, Copy)]
struct State {
    ts: u32,
    /// Distance to the terminal (a heuristic; saturates).
    dist: u16,
    parent: u8,
    is_sink: bool,
}

const FREE_STATE: State = State {
    ts: 0,
    dist: 0,
    parent: FREE,
    is_sink: false,
};

/// A 6-connected grid graph for one max-flow computation.
pub struct GridGraph {
    dims: [usize; 3],
    /// Padded dimensions (dims + 2).
    pdims: [usize; 3],
    off: [isize; 6],
    rc: Vec<[f32; 6]>,
    tr: Vec<f64>,
    flow: f64,
    state: Vec<State>,
    next: Vec<u32>,
    /// The search's clock (time stamps of `State::ts` are never above it).
    time: u32,
    /// Paths saturated so far.
    augmentations: u64,
    /// Parts are split while they have at least this many planes and linked nodes.
    split_at: (usize, usize),
}

impl GridGraph {
    /// A grid of `dims[0] x dims[1] x dims[2]` nodes without edges; node (x, y, z) has the
    /// index `x + dims[0] * (y + dims[1] * z)`.
    pub fn new(dims: [usize; 3]) -> GridGraph {
        let pdims = [dims[0] + 2, dims[1] + 2, dims[2] + 2];
        let total = pdims[0] * pdims[1] * pdims[2];
        assert!(
            total < u32::MAX as usize,
            "at most 2^32 - 1 nodes with the margin"
        );
        let (sx, sy) = (pdims[0] as isize, (pdims[0] * pdims[1]) as isize);
        GridGraph {
            dims,
            pdims,
            off: [1, -1, sx, -sx, sy, -sy],
            rc: vec![[0.0; 6]; total],
            tr: vec![0.0; total],
            flow: 0.0,
            state: vec![FREE_STATE; total],
            next: vec![NOT_QUEUED; total],
            time: 0,
            augmentations: 0,
            split_at: (MIN_SPLIT_PLANES, MIN_SPLIT_LINKED),
        }
    }

    /// Splits parts of at least `planes` planes (at least 2) and `linked` linked nodes,
    /// instead of the defaults (tests exercise the merging on small graphs with this).
    #[cfg(test)]
    pub(crate) fn split_at(&mut self, planes: usize, linked: usize) {
        self.split_at = (planes.max(2), linked);
    }

    /// Number of (real) nodes.
    pub fn node_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Coordinates (x, y, z) of real node `i`.
    fn coords(&self, i: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [i % nx, (i / nx) % ny, i / (nx * ny)]
    }

    /// Storage index of real node `i`.
    #[inline]
    fn padded(&self, i: usize) -> usize {
        let [x, y, z] = self.coords(i);
        (x + 1) + self.pdims[0] * ((y + 1) + self.pdims[1] * (z + 1))
    }

    /// Sets the edge between node `i` and its neighbour one step along +`axis` (0 x, 1 y,
    /// 2 z): capacity `cap` from i to the neighbour and `rev_cap` back (both >= 0).
    pub fn set_edge(&mut self, i: usize, axis: usize, cap: f32, rev_cap: f32) {
        debug_assert!(cap >= 0.0 && rev_cap >= 0.0 && axis < 3);
        let c = self.coords(i);
        assert!(
            c[axis] + 1 < self.dims[axis],
            "the neighbour lies outside the grid"
        );
        let p = self.padded(i);
        let d = 2 * axis;
        let q = self.step(p, d as u8);
        self.rc[p][d] = cap;
        self.rc[q][d ^ 1] = rev_cap;
    }

    /// Adds terminal links: source -> i of capacity `source_cap`, i -> sink of `sink_cap`.
    pub fn add_terminal_weights(&mut self, i: usize, source_cap: f64, sink_cap: f64) {
        let p = self.padded(i);
        let delta = self.tr[p];
        let (mut cs, mut ct) = (source_cap, sink_cap);
        if delta > 0.0 {
            cs += delta;
        } else {
            ct -= delta;
        }
        // The part both links share flows straight through the node.
        self.flow += cs.min(ct);
        self.tr[p] = cs - ct;
    }

    /// After [`GridGraph::maxflow`]: whether node `i` is on the source side of the minimum
    /// cut (reachable from the source in the residual graph).
    pub fn is_source_side(&self, i: usize) -> bool {
        let s = self.state[self.padded(i)];
        s.parent != FREE && !s.is_sink
    }

    /// Computes the maximum flow (the minimum cut's capacity).
    pub fn maxflow(&mut self) -> f64 {
        self.maxflow_with_progress(&mut |_, _| {})
    }

    /// [`GridGraph::maxflow`], calling `progress` every 65,536 augmentations with the flow so
    /// far and the augmentations done.
    ///
    /// A grid of at least `MIN_SPLIT_PLANES` planes is cut in two halves along z first (each
    /// the same way, recursively; in parallel when rayon has two threads or more), with the
    /// arcs between them left out; then the whole graph
    /// is finished from their residual graphs and search trees, its search restarted from the
    /// tree nodes beside the seam only (bottom-up merging, Liu and Sun, CVPR 2010). Both
    /// halves' flows are flows of the whole graph, and the trees stay valid, so the result
    /// is the exact maximum flow.
    pub fn maxflow_with_progress(&mut self, progress: super::Progress) -> f64 {
        let nz = self.dims[2];
        if nz < self.split_at.0 || self.linked_nodes() < self.split_at.1 {
            let queue = self.terminal_queue();
            return self.grow_augment_adopt(queue, progress);
        }
        let mid = nz / 2;
        let (mut lower, mut upper) = (self.part(0, mid), self.part(mid, nz));
        rayon::join(|| lower.maxflow(), || upper.maxflow());
        self.take_back(&lower, 0);
        self.take_back(&upper, mid);
        self.time = lower.time.max(upper.time);
        progress(self.flow, self.augmentations);
        // Only the nodes beside the seam have arcs not yet searched.
        let mut queue = Queue::default();
        let [nx, ny, _] = self.dims;
        for z in [mid - 1, mid] {
            for i in (0..nx * ny).map(|k| k + z * nx * ny) {
                let p = self.padded(i);
                if self.state[p].parent != FREE {
                    queue.push(&mut self.next, p as u32);
                }
            }
        }
        self.grow_augment_adopt(queue, progress)
    }

    /// Number of nodes with a terminal link or an arc of nonzero capacity.
    fn linked_nodes(&self) -> usize {
        (self.tr.iter().zip(&self.rc))
            .filter(|(t, r)| **t != 0.0 || r.iter().any(|&c| c != 0.0))
            .count()
    }

    /// Number of storage nodes in one z plane (margin included).
    fn plane(&self) -> usize {
        self.pdims[0] * self.pdims[1]
    }

    /// The nodes of planes z0..z1 as a graph of their own, arcs to other planes left out: a
    /// copy of the storage planes z0..z1 with the planes on either side as its margin.
    fn part(&self, z0: usize, z1: usize) -> GridGraph {
        let plane = self.plane();
        let range = z0 * plane..(z1 + 2) * plane;
        let len = range.len();
        let mut g = GridGraph {
            dims: [self.dims[0], self.dims[1], z1 - z0],
            pdims: self.pdims,
            off: self.off,
            rc: self.rc[range.clone()].to_vec(),
            tr: self.tr[range.clone()].to_vec(),
            flow: 0.0,
            state: self.state[range].to_vec(),
            next: vec![NOT_QUEUED; len],
            time: 0,
            augmentations: 0,
            split_at: (MIN_SPLIT_PLANES, MIN_SPLIT_LINKED),
        };
        for p in (0..plane).chain(len - plane..len) {
            g.rc[p] = [0.0; 6];
            g.tr[p] = 0.0;
            g.state[p] = FREE_STATE;
        }
        for p in plane..2 * plane {
            g.rc[p][5] = 0.0;
        }
        for p in len - 2 * plane..len - plane {
            g.rc[p][4] = 0.0;
        }
        g
    }

    /// Takes over the residual graph, search trees and flow of `part`, made by
    /// `self.part(z0, ..)`; the arcs between the part and other planes keep their capacity.
    fn take_back(&mut self, part: &GridGraph, z0: usize) {
        let plane = self.plane();
        let inner = plane..part.rc.len() - plane;
        let to = (z0 + 1) * plane..(z0 + 1) * plane + inner.len();
        let below: Vec<f32> = self.rc[to.start..to.start + plane]
            .iter()
            .map(|r| r[5])
            .collect();
        let above: Vec<f32> = self.rc[to.end - plane..to.end]
            .iter()
            .map(|r| r[4])
            .collect();
        self.rc[to.clone()].copy_from_slice(&part.rc[inner.clone()]);
        self.tr[to.clone()].copy_from_slice(&part.tr[inner.clone()]);
        self.state[to.clone()].copy_from_slice(&part.state[inner]);
        for (k, (b, a)) in below.into_iter().zip(above).enumerate() {
            self.rc[to.start + k][5] = b;
            self.rc[to.end - plane + k][4] = a;
        }
        self.flow += part.flow;
        self.augmentations += part.augmentations;
    }

    /// Every node with a terminal link, as the roots of the two search trees, all active.
    fn terminal_queue(&mut self) -> Queue {
        let mut queue = Queue::default();
        for p in 0..self.tr.len() {
            if self.tr[p] != 0.0 {
                self.state[p] = State {
                    ts: self.time,
                    dist: 1,
                    parent: TERMINAL,
                    is_sink: self.tr[p] < 0.0,
                };
                queue.push(&mut self.next, p as u32);
            }
        }
        queue
    }

    /// The algorithm's main loop, from the trees in `state` and the active nodes in `queue`
    /// until no active node is left.
    fn grow_augment_adopt(&mut self, mut queue: Queue, progress: super::Progress) -> f64 {
        let mut time = self.time;
        let mut current = NOT_QUEUED;
        let mut orphans: VecDeque<u32> = VecDeque::new();
        loop {
            let mut i = current;
            if i != NOT_QUEUED {
                self.next[i as usize] = NOT_QUEUED;
                if self.state[i as usize].parent == FREE {
                    i = NOT_QUEUED;
                }
            }
            if i == NOT_QUEUED {
                match queue.pop(&mut self.next, &self.state) {
                    Some(k) => i = k,
                    None => break,
                }
            }
            let iu = i as usize;
            let si = self.state[iu];
            let child_dist = si.dist.saturating_add(1);
            // Growth: the middle arc found, as (source-tree node, direction).
            let mut middle = None;
            for d in 0..6 {
                let j = self.step(iu, d as u8);
                if self.tree_residual(iu, j, d, si.is_sink) <= 0.0 {
                    continue;
                }
                let sj = &mut self.state[j];
                if sj.parent == FREE {
                    *sj = State {
                        ts: si.ts,
                        dist: child_dist,
                        parent: (d ^ 1) as u8,
                        is_sink: si.is_sink,
                    };
                    queue.push(&mut self.next, j as u32);
                } else if sj.is_sink != si.is_sink {
                    middle = Some(if si.is_sink { (j, d ^ 1) } else { (iu, d) });
                    break;
                } else if sj.ts <= si.ts && sj.dist > si.dist {
                    sj.parent = (d ^ 1) as u8;
                    sj.ts = si.ts;
                    sj.dist = child_dist;
                }
            }
            time = time.wrapping_add(1);
            if let Some((s, d)) = middle {
                // Keep growing from this node next time.
                self.next[iu] = i;
                current = i;
                self.augment(s, d, &mut orphans);
                self.augmentations += 1;
                if self.augmentations.is_multiple_of(65_536) {
                    progress(self.flow, self.augmentations);
                }
                while let Some(o) = orphans.pop_front() {
                    self.adopt(o as usize, time, &mut orphans, &mut queue);
                }
            } else {
                current = NOT_QUEUED;
            }
        }
        self.time = time;
        self.flow
    }

    /// Neighbour of storage node `i` in direction `d`.
    #[inline]
    fn step(&self, i: usize, d: u8) -> usize {
        (i as isize + self.off[d as usize]) as usize
    }

    /// Residual capacity, in the direction a tree's flow takes, of the arc between `parent`
    /// and its neighbour `child` in direction `d`: parent -> child in the source tree,
    /// child -> parent in the sink tree.
    #[inline]
    fn tree_residual(&self, parent: usize, child: usize, d: usize, sink: bool) -> f32 {
        if sink {
            self.rc[child][d ^ 1]
        } else {
            self.rc[parent][d]
        }
    }

    /// Saturates the path through the arc from source-tree node `s` in direction `d`.
    fn augment(&mut self, s: usize, d: usize, orphans: &mut VecDeque<u32>) {
        let t = self.step(s, d as u8);
        let bottleneck = (self.rc[s][d] as f64)
            .min(self.side_bottleneck(s, false))
            .min(self.side_bottleneck(t, true));
        let b = bottleneck as f32;
        self.rc[s][d] -= b;
        self.rc[t][d ^ 1] += b;
        self.push_along_side(s, bottleneck, false, orphans);
        self.push_along_side(t, bottleneck, true, orphans);
        self.flow += bottleneck;
    }

    /// Smallest residual capacity on the tree path from `start` to its terminal, the
    /// terminal link included.
    fn side_bottleneck(&self, start: usize, sink: bool) -> f64 {
        let mut bottleneck = f64::INFINITY;
        let mut i = start;
        loop {
            let p = self.state[i].parent;
            if p == TERMINAL {
                break;
            }
            let q = self.step(i, p);
            bottleneck = bottleneck.min(self.tree_residual(q, i, (p ^ 1) as usize, sink) as f64);
            i = q;
        }
        let terminal = if sink { -self.tr[i] } else { self.tr[i] };
        bottleneck.min(terminal)
    }

    /// Pushes `amount` along the tree path from `start` to its terminal; nodes whose link to
    /// their parent (or terminal) saturates become orphans.
    fn push_along_side(
        &mut self,
        start: usize,
        amount: f64,
        sink: bool,
        orphans: &mut VecDeque<u32>,
    ) {
        let b = amount as f32;
        let mut i = start;
        loop {
            let p = self.state[i].parent;
            if p == TERMINAL {
                break;
            }
            let q = self.step(i, p);
            // The tree's arc carries the flow; its reverse gains the same residual.
            let (along, back) = if sink {
                ((i, p as usize), (q, (p ^ 1) as usize))
            } else {
                ((q, (p ^ 1) as usize), (i, p as usize))
            };
            self.rc[back.0][back.1] += b;
            let r = &mut self.rc[along.0][along.1];
            *r -= b;
            if *r <= 0.0 {
                *r = 0.0;
                self.state[i].parent = ORPHAN;
                orphans.push_front(i as u32);
            }
            i = q;
        }
        let left = if sink {
            self.tr[i] + amount
        } else {
            self.tr[i] - amount
        };
        self.tr[i] = left;
        if (sink && left >= 0.0) || (!sink && left <= 0.0) {
            self.tr[i] = 0.0;
            self.state[i].parent = ORPHAN;
            orphans.push_front(i as u32);
        }
    }

    /// Distance of `start` to its tree's terminal through valid parents (`INFINITE_D` when
    /// the path meets an orphan), marking the nodes on the way with the current time.
    fn origin_distance(&mut self, start: usize, time: u32) -> u32 {
        let mut j = start;
        let mut d: u32 = 0;
        loop {
            let s = self.state[j];
            if s.ts == time {
                d += s.dist as u32;
                break;
            }
            d += 1;
            if s.parent == TERMINAL {
                self.state[j].ts = time;
                self.state[j].dist = 1;
                break;
            }
            if s.parent == ORPHAN {
                return INFINITE_D;
            }
            j = self.step(j, s.parent);
        }
        let mut j = start;
        let mut dd = d;
        while self.state[j].ts != time {
            let parent = self.state[j].parent;
            self.state[j].ts = time;
            self.state[j].dist = dd.min(u16::MAX as u32) as u16;
            dd -= 1;
            j = self.step(j, parent);
        }
        d
    }

    /// Adoption of orphan `i`: a new parent in its tree, or it becomes free.
    fn adopt(&mut self, i: usize, time: u32, orphans: &mut VecDeque<u32>, queue: &mut Queue) {
        let sink = self.state[i].is_sink;
        // Neighbour j in direction d could be i's parent if the arc j -> i (source tree) or
        // i -> j (sink tree) has residual capacity.
        let residual = |g: &GridGraph, d: usize, j: usize| g.tree_residual(j, i, d ^ 1, sink);
        let mut best = FREE;
        let mut best_d = INFINITE_D;
        for d in 0..6 {
            let j = self.step(i, d as u8);
            let sj = self.state[j];
            if sj.is_sink != sink || sj.parent == FREE || residual(self, d, j) <= 0.0 {
                continue;
            }
            let dj = self.origin_distance(j, time);
            if dj < best_d {
                best_d = dj;
                best = d as u8;
            }
        }
        if best != FREE {
            let s = &mut self.state[i];
            s.parent = best;
            s.ts = time;
            s.dist = best_d.saturating_add(1).min(u16::MAX as u32) as u16;
            return;
        }
        // No parent: i becomes free; its children become orphans, and neighbours that could
        // reach it become active again.
        self.state[i].parent = FREE;
        for d in 0..6 {
            let j = self.step(i, d as u8);
            let sj = self.state[j];
            if sj.is_sink != sink || sj.parent == FREE {
                continue;
            }
            if residual(self, d, j) > 0.0 {
                queue.push(&mut self.next, j as u32);
            }
            if sj.parent == (d ^ 1) as u8 {
                self.state[j].parent = ORPHAN;
                orphans.push_back(j as u32);
            }
        }
    }
}

/// FIFO of active nodes threaded through `next` (`NOT_QUEUED` when a node is not queued,
/// itself when it is the last).
#[derive(Default)]
struct Queue {
    first: Option<u32>,
    last: u32,
}

impl Queue {
    fn push(&mut self, next: &mut [u32], i: u32) {
        if next[i as usize] != NOT_QUEUED {
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
    fn pop(&mut self, next: &mut [u32], state: &[State]) -> Option<u32> {
        while let Some(i) = self.first {
            let n = next[i as usize];
            self.first = if n == i { None } else { Some(n) };
            next[i as usize] = NOT_QUEUED;
            if state[i as usize].parent != FREE {
                return Some(i);
            }
        }
        None
    }
}
