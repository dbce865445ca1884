//! Maximum flow / minimum cut by the Boykov-Kolmogorov algorithm (PAMI 2004), built for the
//! 6-connected grid graphs of volumetric graph cuts, in the manner of GridCut.
//!
//! Layout: flat per-node arrays with 32-bit indices and no per-node allocation; a node's
//! neighbours are found by index arithmetic, so no arc list, head or sister index is stored:
//! - `rc[i][d]`: residual capacity of the arc from node i to its neighbour in direction d
//!   (0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z); the reverse arc is the neighbour's `rc[j][d ^ 1]`;
//! - `tr[i]`: residual terminal capacity (> 0 from the source, < 0 to the sink);
//! - `state[i]`: 8 bytes read by the search-tree walks: the parent as a direction (or a
//!   mark), the tree, a time stamp and the distance to the terminal;
//! - `next[i]`: the active-node queue link.
//!
//! The grid is stored with a one-node margin of inert nodes, so every neighbour index of a
//! real node is valid. The algorithm is Kolmogorov's maxflow v3: two search trees grow from
//! the terminals (growth, from a FIFO of active nodes), a path found between them is
//! saturated (augmentation), and nodes cut off from their tree look for a new parent among
//! their neighbours before they are freed (adoption); trees are reused from one
//! augmentation to the next, and the time-stamp/distance heuristics keep them shallow.
//! Large grids are cut in halves first and merged (see [`GridGraph::maxflow_with_progress`]).
//! Capacities are `f32` on arcs and `f64` on terminal links and the flow total; integer
//! capacities stay exact.

pub mod fixture;
mod grid;

pub use grid::GridGraph;

/// Progress report of a long cut: called with the flow so far and the augmentations done.
pub type Progress<'a> = &'a mut dyn FnMut(f64, u64);

#[cfg(test)]
mod tests;
