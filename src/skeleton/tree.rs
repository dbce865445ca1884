//! The bone hierarchy as a graph: cycle detection and a parents-first order.

use petgraph::algo::{kosaraju_scc, toposort};
use petgraph::graph::{DiGraph, NodeIndex};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// A parents-first order of the bones whose parents are `parents` (indices into the same
/// list), keeping the given order wherever it already is parents-first. On a cycle, returns
/// the bones on it.
pub fn parents_first(parents: &[Option<usize>]) -> Result<Vec<usize>, Vec<usize>> {
    let mut graph: DiGraph<usize, ()> = DiGraph::with_capacity(parents.len(), parents.len());
    let nodes: Vec<NodeIndex> = (0..parents.len()).map(|i| graph.add_node(i)).collect();
    for (child, parent) in parents.iter().enumerate() {
        if let Some(p) = parent {
            graph.add_edge(nodes[*p], nodes[child], ());
        }
    }
    if toposort(&graph, None).is_err() {
        // The strongly connected component with more than one bone (or a self-parent).
        let cycle = kosaraju_scc(&graph)
            .into_iter()
            .find(|c| c.len() > 1 || graph.contains_edge(c[0], c[0]))
            .unwrap_or_default();
        let mut bones: Vec<usize> = cycle.into_iter().map(|n| graph[n]).collect();
        bones.sort_unstable();
        return Err(bones);
    }
    // Kahn's algorithm taking the earliest listed ready bone first: the file order when the
    // file is already parents first.
    let mut children = vec![Vec::new(); parents.len()];
    for (c, p) in parents.iter().enumerate() {
        if let Some(p) = p {
            children[*p].push(c);
        }
    }
    let mut ready: BinaryHeap<Reverse<usize>> = (0..parents.len())
        .filter(|&i| parents[i].is_none())
        .map(Reverse)
        .collect();
    let mut order = Vec::with_capacity(parents.len());
    while let Some(Reverse(b)) = ready.pop() {
        order.push(b);
        ready.extend(children[b].iter().copied().map(Reverse));
    }
    Ok(order)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_a_parents_first_order_and_reorders_others() {
        assert_eq!(parents_first(&[None, Some(0), Some(1)]), Ok(vec![0, 1, 2]));
        assert_eq!(parents_first(&[Some(2), None, Some(1)]), Ok(vec![1, 2, 0]));
    }

    #[test]
    fn finds_cycles() {
        assert_eq!(
            parents_first(&[None, Some(2), Some(3), Some(1)]),
            Err(vec![1, 2, 3])
        );
        assert_eq!(parents_first(&[None, Some(1)]), Err(vec![1]));
    }
}
