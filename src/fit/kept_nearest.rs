//! Nearest partners kept from round to round, exactly (method.md "Stage 6", step (a)).
//!
//! Late in a frame's rounds the pose moves by micrometres, and almost every vertex keeps its
//! nearest partner on the other surface. A search remembers, besides the partner, how far
//! the second-nearest point was. By the triangle inequality the partner is still the
//! nearest while
//!
//! `|q - partner| + (how far the query or the other points moved since) < second distance`
//!
//! so the answer is reused without a search. With a margin for the f32 coordinates the
//! tree measures in, the reused answer is the one a fresh search would give: same point,
//! same squared distance ([`key_distance2`] is the tree's own arithmetic).
//!
//! A fresh search is bounded by the old partner's current distance, so it is short: it goes
//! through a [`CellGrid`], which gives the k-d tree's answer and defers to the tree where
//! two points tie or the ball is wide.
//!
//! A moving query far from the fixed points (a model vertex where the observation is
//! missing) has many points nearly as near as its nearest, so the rule above seldom holds.
//! Once it moves slowly, its fresh search also lists every point within a few millimetres
//! beyond the nearest ([`Listed`]); while the query stays near, a scan of that list gives
//! the exact answer.

use crate::geometry::cell_grid::{CellGrid, TwoNearest};
use crate::geometry::nearest::{key_distance2, NearestTree, TwoSmallest};
use rayon::prelude::*;
use std::sync::OnceLock;

/// How far beyond the previous partner's distance a search looks for the second-nearest
/// point, metres. The previous partner bounds the search, which makes it about as fast as a
/// plain nearest search (without a bound, looking for two is 1.7x slower: `pipeline bench
/// nearest`); an answer whose second point lies beyond is kept with this bound as its
/// second distance, good for motions up to about half of it.
pub const SECOND_REACH: f64 = 0.002;

/// A query whose nearest point lies farther than this has its neighbourhood listed
/// ([`Listed`]), metres. Away from the surface (model vertices where the observation is
/// missing) many points lie nearly as near as the nearest, so the second-nearest rule above
/// rarely holds from one round to the next, and each fresh search is wide.
pub const LIST_FROM: f64 = 0.005;

/// How far beyond the nearest point a listed neighbourhood reaches, metres: the list then
/// serves until the query has moved about half of it. (Tripod tracking, `pipeline bench
/// track`: 5 mm from 5 mm on, 1 cm from 2 cm on, and 5 mm from 1 cm on were level within the
/// machine's noise, all 4-7% faster than no lists.)
pub const LIST_SLACK: f64 = 0.005;

/// Every point within `radius` of where a query stood (`at`), listed by a search, so that
/// while the query stays near, its nearest point is found by scanning the list: exactly,
/// since any point not listed lies farther than `radius` minus the query's motion.
#[derive(Debug, Clone)]
struct Listed {
    at: [f32; 3],
    /// Metres.
    radius: f64,
    points: Vec<u32>,
}

impl Listed {
    /// Lists the points of `tree` within `radius` of `q`.
    fn new(tree: &NearestTree, q: &[f32; 3], radius: f64) -> Listed {
        let mut points = Vec::new();
        // The tree's radius test is on f32 squared distances: a little slack keeps every
        // point within `radius` (metres, exactly) in the list.
        tree.within_key(q, radius * (1.0 + 1e-5) + 1e-6, |i, _| {
            points.push(i as u32)
        });
        Listed {
            at: *q,
            radius,
            points,
        }
    }

    /// The nearest point of `tree` to `q` and the second-nearest's distance, found in the
    /// list: (index, squared distance in m^2 as the tree measures it, a distance within which
    /// no other point lies, metres). `None` when the list cannot tell: the query has moved
    /// too far from where it was listed, or the two nearest listed points tie (the tree's
    /// pick then depends on its layout).
    fn nearest(&self, q: &[f32; 3], tree: &NearestTree) -> Option<(usize, f64, f64)> {
        let mut two = TwoSmallest::new();
        for &i in &self.points {
            two.offer(i as usize, key_distance2(q, tree.key(i as usize)));
        }
        // Every point not listed lies farther than this from q (triangle inequality).
        let unlisted = self.radius - key_distance(q, &self.at);
        let TwoSmallest {
            item,
            best2,
            second2,
        } = two;
        if item == usize::MAX || best2 == second2 || best2.sqrt() + margin(q) >= unlisted {
            return None;
        }
        Some((item, best2, second2.sqrt().min(unlisted)))
    }
}

/// One kept answer.
#[derive(Debug, Clone, Copy)]
struct Kept<When> {
    /// The nearest point's index.
    item: u32,
    /// The second-nearest point's distance when the answer was found, metres (infinite for
    /// a tree of one point; 0 when it was not searched, so that the answer never passes).
    second: f64,
    /// When the answer was found: where the query stood, or the moving points' running sum
    /// of motion.
    when: When,
}

/// A margin covering the f32 rounding of distances measured at `q`, metres: a few units in
/// the last place of the coordinates (about 1e-7 m at 1 m) and a fixed 10 micrometres.
fn margin(q: &[f32; 3]) -> f64 {
    let size = q.iter().fold(0.0f64, |m, &c| m.max((c as f64).abs()));
    1e-5 + 4e-6 * size
}

/// Squared Euclidean distance between two keys, in f64, m^2.
fn key_distance2_f64(a: &[f32; 3], b: &[f32; 3]) -> f64 {
    (0..3).map(|i| (a[i] as f64 - b[i] as f64).powi(2)).sum()
}

/// Euclidean distance between two keys, in f64, metres.
fn key_distance(a: &[f32; 3], b: &[f32; 3]) -> f64 {
    key_distance2_f64(a, b).sqrt()
}

/// Where fresh answers come from: a [`CellGrid`] over the points for the short bounded
/// searches, and the k-d tree over the same points (built only when first asked for) for
/// the first, unbounded search and for the grid's [`TwoNearest::Unsure`] answers.
struct Searcher<'a> {
    grid: &'a CellGrid,
    tree: &'a (dyn Fn() -> &'a NearestTree + Sync),
}

/// A fresh search. `bound` is the current distance of the point that was nearest before,
/// metres, so the nearest is within it; the search then also finds the second-nearest up
/// to [`SECOND_REACH`] farther. Without one (infinite: the first search) the second is not
/// looked for, as the first rounds move too far for an answer to be kept. The answers are
/// the k-d tree's (the grid's equal them, and it defers to the tree where it cannot).
fn search<When>(
    from: &Searcher,
    q: &[f32; 3],
    bound: f64,
    when: When,
) -> (Option<Kept<When>>, (usize, f64)) {
    let found = if bound.is_finite() {
        let radius = bound + SECOND_REACH;
        match from.grid.nearest_two_within(q, radius) {
            TwoNearest::Found(item, d2, second2) => Some((item, d2, second2)),
            TwoNearest::None => (from.tree)().nearest_two(q),
            TwoNearest::Unsure => {
                let tree = (from.tree)();
                tree.nearest_two_within(q, radius)
                    .or_else(|| tree.nearest_two(q))
            }
        }
    } else {
        (from.tree)()
            .nearest_key(q)
            .map(|(item, d2)| (item, d2, 0.0))
    };
    match found {
        Some((item, d2, second2)) => (
            Some(Kept {
                item: item as u32,
                second: second2.sqrt(),
                when,
            }),
            (item, d2),
        ),
        None => (None, (0, f64::INFINITY)),
    }
}

/// Nearest answers for queries that move against a tree that does not (each model vertex's
/// nearest observed vertex).
#[derive(Debug, Default)]
pub struct MovingQueries {
    kept: Vec<Option<Kept<[f32; 3]>>>,
    /// The neighbourhoods of the queries far from every point.
    listed: Vec<Option<Listed>>,
    /// Answers reused, over every call (for benchmarks).
    pub reused: usize,
}

impl MovingQueries {
    /// Each query's nearest point in `tree`: (index, squared distance in m^2 as the tree
    /// measures it), (0, inf) for an empty tree. `tree` and `grid` (a [`CellGrid`] over the
    /// tree's points) must be the same in every call.
    pub fn partners(
        &mut self,
        queries: &[[f32; 3]],
        tree: &NearestTree,
        grid: &CellGrid,
    ) -> Vec<(usize, f64)> {
        let whole = || tree;
        let from = Searcher { grid, tree: &whole };
        if self.kept.len() != queries.len() {
            self.kept = vec![None; queries.len()];
            self.listed = vec![None; queries.len()];
        }
        let answers: Vec<(usize, f64, bool)> = self
            .kept
            .par_iter_mut()
            .zip(self.listed.par_iter_mut())
            .zip(queries)
            .map(|((kept, listed), q)| {
                let (mut bound, mut slow) = (f64::INFINITY, false);
                if let Some(k) = kept {
                    let d2 = key_distance2(q, tree.key(k.item as usize));
                    let moved = key_distance(q, &k.when);
                    if d2.sqrt() + moved + margin(q) < k.second {
                        return (k.item as usize, d2, true);
                    }
                    bound = d2.sqrt();
                    slow = moved < 0.5 * LIST_SLACK;
                }
                if let Some((item, d2, second)) = listed.as_ref().and_then(|l| l.nearest(q, tree)) {
                    *kept = Some(Kept {
                        item: item as u32,
                        second,
                        when: *q,
                    });
                    return (item, d2, true);
                }
                let (fresh, (item, d2)) = search(&from, q, bound, *q);
                *kept = fresh;
                let far = d2.sqrt();
                // Listed only once the query moves slowly enough for a list to serve (the
                // first rounds from a frame's start move too far).
                *listed = (slow && far.is_finite() && far > LIST_FROM)
                    .then(|| Listed::new(tree, q, far + LIST_SLACK));
                (item, d2, false)
            })
            .collect();
        self.reused += answers.iter().filter(|a| a.2).count();
        answers.into_iter().map(|(i, d2, _)| (i, d2)).collect()
    }
}

/// Nearest answers for queries that stay against points that move (each observed vertex's
/// nearest model vertex). Every call adds the points' largest motion since the call before
/// to a running sum: since an answer was found, no point has moved farther than the sum's
/// growth since then (triangle inequality), so no other point has come nearer to a query
/// by more than that.
#[derive(Debug, Default)]
pub struct MovingPoints {
    /// Each answer, with the running sum when it was found, metres.
    kept: Vec<Option<Kept<f64>>>,
    /// The points at the last call.
    last: Vec<[f32; 3]>,
    /// The running sum of the points' largest motion per call, metres.
    path: f64,
    /// The points of the last call in cells, for [`MovingPoints::search`] (rebuilt by the
    /// caller, in place).
    pub grid: CellGrid,
    /// Answers reused, over every call (for benchmarks).
    pub reused: usize,
}

impl MovingPoints {
    /// The answers that still hold for `queries` (the same in every call) against `points`
    /// now; where a search is needed ([`MovingPoints::search`]), the distance of the point
    /// that was nearest before (infinite for none), metres.
    pub fn kept(
        &mut self,
        queries: &[[f32; 3]],
        points: &[[f32; 3]],
    ) -> Vec<Result<(usize, f64), f64>> {
        if self.kept.len() != queries.len() || self.last.len() != points.len() {
            self.kept = vec![None; queries.len()];
        } else {
            let most2 = self
                .last
                .par_iter()
                .zip(points)
                .map(|(a, b)| key_distance2_f64(a, b))
                .reduce(|| 0.0, f64::max);
            self.path += most2.sqrt();
        }
        self.last.clear();
        self.last.extend_from_slice(points);
        let path = self.path;
        let answers: Vec<Result<(usize, f64), f64>> = self
            .kept
            .par_iter()
            .zip(queries)
            .map(|(kept, q)| {
                let k = kept.as_ref().ok_or(f64::INFINITY)?;
                let d2 = key_distance2(q, &points[k.item as usize]);
                if d2.sqrt() + (path - k.when) + margin(q) < k.second {
                    Ok((k.item as usize, d2))
                } else {
                    Err(d2.sqrt())
                }
            })
            .collect();
        self.reused += answers.iter().filter(|a| a.is_ok()).count();
        answers
    }

    /// Fills the answers [`MovingPoints::kept`] left out by searching [`MovingPoints::grid`],
    /// which must hold the `points` given to that call (a k-d tree over them is built where
    /// the grid defers to one), and keeps them.
    pub fn search(
        &mut self,
        queries: &[[f32; 3]],
        points: &[[f32; 3]],
        answers: Vec<Result<(usize, f64), f64>>,
    ) -> Vec<(usize, f64)> {
        let path = self.path;
        let grid = &self.grid;
        let tree = OnceLock::new();
        let whole = || tree.get_or_init(|| NearestTree::from_keys(points.to_vec()));
        let from = Searcher { grid, tree: &whole };
        self.kept
            .par_iter_mut()
            .zip(queries)
            .zip(answers)
            .map(|((kept, q), answer)| {
                answer.unwrap_or_else(|bound| {
                    let (fresh, found) = search(&from, q, bound, path);
                    *kept = fresh;
                    found
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::nearest::key;
    use nalgebra::Vector3;

    /// A random walk on a 1 cm lattice (ties, as marching-cubes vertices give) plus small
    /// steps: each round's kept answers equal a fresh search's, point for point, and most
    /// are reused.
    fn lattice(seed: u64, count: usize) -> (Vec<[f32; 3]>, impl FnMut() -> f64) {
        let mut rnd = crate::rng::chained_uniform(seed);
        let points = (0..count)
            .map(|_| {
                let mut c = || (rnd() * 20.0).floor() * 0.01 + 1.0;
                key(&Vector3::new(c(), c(), c()))
            })
            .collect();
        (points, rnd)
    }

    fn walk(points: &mut [[f32; 3]], rnd: &mut impl FnMut() -> f64, step: f64) {
        for p in points.iter_mut() {
            for c in p.iter_mut() {
                *c += ((rnd() - 0.5) * 2.0 * step) as f32;
            }
        }
    }

    /// 30 rounds of `queries` walking against `tree`'s points (mostly slow steps, now and
    /// then a jump), every answer checked against a fresh search.
    fn track_queries(
        queries: &mut [[f32; 3]],
        rnd: &mut impl FnMut() -> f64,
        tree: &NearestTree,
        grid: &CellGrid,
    ) -> MovingQueries {
        let mut kept = MovingQueries::default();
        for round in 0..30 {
            let got = kept.partners(queries, tree, grid);
            for (q, g) in queries.iter().zip(&got) {
                assert_eq!(Some(*g), tree.nearest_key(q), "round {round}");
            }
            walk(queries, rnd, if round % 7 == 6 { 0.004 } else { 0.0003 });
        }
        kept
    }

    #[test]
    fn moving_queries_agree_with_fresh_searches() {
        let (fixed, _) = lattice(3, 2000);
        let tree = NearestTree::from_keys(fixed.clone());
        let grid = CellGrid::new(&fixed, 0.01);
        let (mut queries, mut rnd) = lattice(5, 1500);
        walk(&mut queries, &mut rnd, 0.002);
        let kept = track_queries(&mut queries, &mut rnd, &tree, &grid);
        assert!(kept.reused > 30 * 1500 / 2, "reused {}", kept.reused);
    }

    /// Queries 1-10 cm above a sheet of points, drifting: the listed neighbourhoods give
    /// every answer a fresh search gives, and serve most rounds.
    #[test]
    fn far_queries_agree_with_fresh_searches() {
        // Scattered on the sheet (a lattice's repeated points would tie, which the lists
        // leave to a fresh search).
        let (_, mut scatter) = lattice(13, 0);
        let fixed: Vec<[f32; 3]> = (0..3000)
            .map(|_| {
                let (x, y) = (scatter(), scatter());
                [1.0 + 0.2 * x as f32, 1.0 + 0.2 * y as f32, 1.0]
            })
            .collect();
        let tree = NearestTree::from_keys(fixed.clone());
        let grid = CellGrid::new(&fixed, 0.02);
        let (mut queries, mut rnd) = lattice(17, 800);
        for q in &mut queries {
            q[2] = 1.01 + (q[2] - 1.0) * 0.55;
        }
        let kept = track_queries(&mut queries, &mut rnd, &tree, &grid);
        let listed = kept.listed.iter().filter(|l| l.is_some()).count();
        assert!(listed > 700, "{listed} listed");
        assert!(kept.reused > 30 * 800 / 2, "reused {}", kept.reused);
    }

    #[test]
    fn moving_points_agree_with_fresh_searches() {
        let (queries, _) = lattice(7, 1500);
        let (mut points, mut rnd) = lattice(11, 2000);
        walk(&mut points, &mut rnd, 0.002);
        let mut kept = MovingPoints::default();
        let mut searched = 0;
        for round in 0..30 {
            let tree = NearestTree::from_keys(points.clone());
            let answers = kept.kept(&queries, &points);
            kept.grid.rebuild(&points, 0.01);
            searched += answers.iter().filter(|a| a.is_err()).count();
            let got = kept.search(&queries, &points, answers);
            for (q, g) in queries.iter().zip(&got) {
                assert_eq!(Some(*g), tree.nearest_key(q), "round {round}");
            }
            walk(
                &mut points,
                &mut rnd,
                if round % 7 == 6 { 0.004 } else { 0.0002 },
            );
        }
        assert_eq!(kept.reused + searched, 30 * 1500);
        assert!(kept.reused > 30 * 1500 / 3, "reused {}", kept.reused);
    }
}
