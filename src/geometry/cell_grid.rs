//! Exact bounded two-nearest queries on a uniform grid of cubic cells, for the fit's short
//! searches (method.md "Stage 6", step (a)): a query that knows its nearest point lies
//! within a few millimetres visits only the handful of cells that ball touches, where a
//! k-d tree walks from the root. The cells are one flat array over the points' bounding
//! box (counting sort), so building costs one pass over the points and is cheap enough to
//! redo every round for the moving model.
//!
//! Distances are measured exactly as [`NearestTree`](super::nearest::NearestTree) measures
//! them ([`key_distance2`]: f32 coordinates, the axes summed in order) and the radius test
//! is the tree's (inclusive, on the f32 squared radius), so an answer equals the tree's
//! bounded search. Where the two nearest lie at exactly the same distance the tree's choice
//! depends on its layout: such a query answers [`TwoNearest::Unsure`] and the caller asks
//! the tree.

use crate::geometry::nearest::{key_distance2, TwoSmallest};

/// At most this many cells per point (and at least [`MIN_CELLS`] in all); a larger box gets
/// larger cells. The cell array is cleared and summed on every rebuild, so its size, not
/// the points', would otherwise set the cost (53k model vertices in a 1.1 cm grid of the
/// tripod's box: 2.3 M cells, 4 ms a rebuild).
const CELLS_PER_POINT: usize = 16;

/// See [`CELLS_PER_POINT`].
const MIN_CELLS: usize = 4096;

/// At most this many cells are visited by one query; a wider search answers
/// [`TwoNearest::Unsure`].
const MAX_VISITED: usize = 512;

/// The answer of [`CellGrid::nearest_two_within`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TwoNearest {
    /// The nearest point within the radius: its index, its squared distance (m^2), and the
    /// second-nearest's squared distance, or the squared radius (as f32) when no second
    /// point lies within it.
    Found(usize, f64, f64),
    /// No point lies within the radius.
    None,
    /// A tie for the nearest, or a search too wide for the grid: ask the k-d tree.
    Unsure,
}

/// Which cells a ball touches.
enum Cells {
    /// The ball lies wholly outside the grid's box.
    None,
    /// More than [`MAX_VISITED`] cells.
    TooMany,
    /// An inclusive range of cell coordinates per axis.
    Range([(usize, usize); 3]),
}

/// Points sorted into cubic cells over their bounding box.
#[derive(Debug, Default)]
pub struct CellGrid {
    /// Corner of cell (0, 0, 0), metres.
    origin: [f64; 3],
    /// Cell edge, metres.
    size: f64,
    dims: [usize; 3],
    /// Cell c's points are `order[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    /// Point indices, cell by cell (in index order within a cell).
    order: Vec<u32>,
    /// `keys[order[i]]`, for scans without indirection.
    sorted: Vec<[f32; 3]>,
    /// Each point's cell (scratch space of [`CellGrid::rebuild`]).
    cells: Vec<u32>,
}

impl CellGrid {
    /// Sorts `keys` (points as the k-d tree stores them) into cells of about `size` metres.
    pub fn new(keys: &[[f32; 3]], size: f64) -> CellGrid {
        let mut grid = CellGrid::default();
        grid.rebuild(keys, size);
        grid
    }

    /// [`CellGrid::new`] in place, reusing this grid's memory (the moving model's grid is
    /// rebuilt every round; fresh allocations of its cell array cost page faults).
    pub fn rebuild(&mut self, keys: &[[f32; 3]], size: f64) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for k in keys {
            for a in 0..3 {
                lo[a] = lo[a].min(k[a] as f64);
                hi[a] = hi[a].max(k[a] as f64);
            }
        }
        if keys.is_empty() || lo.iter().chain(&hi).any(|x| !x.is_finite()) {
            lo = [0.0; 3];
            hi = [0.0; 3];
        }
        // The requested size, or the smallest that keeps the cells within the cap.
        let cap = (CELLS_PER_POINT * keys.len()).max(MIN_CELLS) as f64;
        let volume: f64 = (0..3).map(|a| hi[a] - lo[a] + size).product();
        let size = size.max((volume / cap).cbrt());
        let dims: [usize; 3] =
            std::array::from_fn(|a| ((hi[a] - lo[a]) / size).floor() as usize + 1);
        self.origin = lo;
        self.size = size;
        self.dims = dims;
        self.starts.clear();
        self.starts.resize(dims[0] * dims[1] * dims[2] + 1, 0);
        // Counting sort by cell: stable, so a cell lists its points in index order.
        let mut cells = std::mem::take(&mut self.cells);
        cells.clear();
        cells.extend(keys.iter().map(|k| self.cell_index(k) as u32));
        self.cells = cells;
        for &c in &self.cells {
            self.starts[c as usize + 1] += 1;
        }
        for c in 0..self.starts.len() - 1 {
            self.starts[c + 1] += self.starts[c];
        }
        self.order.clear();
        self.order.resize(keys.len(), 0);
        // Each cell's next free slot: its start, moved along as points are placed (then
        // shifted back by one cell below).
        for (i, &c) in self.cells.iter().enumerate() {
            let slot = &mut self.starts[c as usize];
            self.order[*slot as usize] = i as u32;
            *slot += 1;
        }
        // Now starts[c] is where cell c ends, which is where cell c + 1 begins.
        for c in (1..self.starts.len()).rev() {
            self.starts[c] = self.starts[c - 1];
        }
        self.starts[0] = 0;
        self.sorted.clear();
        self.sorted
            .extend(self.order.iter().map(|&i| keys[i as usize]));
    }

    /// The cell coordinate of `x` (metres) along axis `a`, clamped to the grid.
    fn coordinate(&self, x: f64, a: usize) -> usize {
        let c = ((x - self.origin[a]) / self.size).floor();
        c.clamp(0.0, (self.dims[a] - 1) as f64) as usize
    }

    fn cell_index(&self, k: &[f32; 3]) -> usize {
        let c: [usize; 3] = std::array::from_fn(|a| self.coordinate(k[a] as f64, a));
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The cells (an inclusive range per axis) that hold every point within `radius`
    /// metres of `q`.
    fn cells_within(&self, q: &[f32; 3], radius: f64) -> Cells {
        // Every point within the radius lies in these cells (a little slack for rounding;
        // every point lies in the box, so clamping the range to the grid loses none, and a
        // ball wholly outside the box finds none).
        let reach = radius * (1.0 + 1e-5) + 1e-6;
        let mut range = [(0usize, 0usize); 3];
        for (a, r) in range.iter_mut().enumerate() {
            let x = q[a] as f64;
            let (from, to) = (x - reach, x + reach);
            let last = self.origin[a] + self.size * self.dims[a] as f64;
            if to < self.origin[a] - self.size || from > last + self.size || !x.is_finite() {
                return Cells::None;
            }
            *r = (self.coordinate(from, a), self.coordinate(to, a));
        }
        let visited: usize = range.iter().map(|(a, b)| b - a + 1).product();
        if visited > MAX_VISITED {
            return Cells::TooMany;
        }
        Cells::Range(range)
    }

    /// Whether any point lies within `radius` metres of `q` (the tree's inclusive test on
    /// the f32 squared radius); stops at the first one found, the query's own cell first.
    pub fn any_within(&self, q: &[f32; 3], radius: f64) -> bool {
        let r2 = (radius * radius) as f32 as f64;
        let near = |cell: usize| {
            let (from, to) = (self.starts[cell] as usize, self.starts[cell + 1] as usize);
            self.sorted[from..to]
                .iter()
                .any(|p| key_distance2(q, p) <= r2)
        };
        let range = match self.cells_within(q, radius) {
            Cells::None => return false,
            Cells::TooMany => return self.sorted.iter().any(|p| key_distance2(q, p) <= r2),
            Cells::Range(range) => range,
        };
        // The query's own cell lies in the range (the range's ends are the cells of
        // coordinates either side of it).
        if near(self.cell_index(q)) {
            return true;
        }
        (range[2].0..=range[2].1).any(|z| {
            (range[1].0..=range[1].1).any(|y| {
                let row = (z * self.dims[1] + y) * self.dims[0];
                (range[0].0..=range[0].1).any(|x| near(row + x))
            })
        })
    }

    /// The nearest and second-nearest points within `radius` metres of `q`, as the k-d
    /// tree's bounded two-nearest search answers them (see [`TwoNearest`]).
    pub fn nearest_two_within(&self, q: &[f32; 3], radius: f64) -> TwoNearest {
        let r2 = (radius * radius) as f32 as f64;
        let range = match self.cells_within(q, radius) {
            Cells::None => return TwoNearest::None,
            Cells::TooMany => return TwoNearest::Unsure,
            Cells::Range(range) => range,
        };
        let mut two = TwoSmallest::new();
        for z in range[2].0..=range[2].1 {
            for y in range[1].0..=range[1].1 {
                let row = (z * self.dims[1] + y) * self.dims[0];
                let from = self.starts[row + range[0].0] as usize;
                let to = self.starts[row + range[0].1 + 1] as usize;
                for (i, p) in self.sorted[from..to].iter().enumerate() {
                    let d2 = key_distance2(q, p);
                    if d2 <= r2 {
                        two.offer(from + i, d2);
                    }
                }
            }
        }
        if two.item == usize::MAX {
            TwoNearest::None
        } else if two.second2 == two.best2 {
            TwoNearest::Unsure
        } else {
            let second = if two.second2.is_finite() {
                two.second2
            } else {
                r2
            };
            TwoNearest::Found(self.order[two.item] as usize, two.best2, second)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::nearest::NearestTree;

    /// Every answer equals the k-d tree's bounded two-nearest search, on scattered points
    /// and on a lattice with repeated points (ties, which must answer `Unsure`), for radii
    /// from a millimetre to beyond the grid, with queries inside and outside the box; and
    /// `any_within` always agrees with whether the tree finds a point.
    #[test]
    fn agrees_with_the_tree() {
        let mut rnd = crate::rng::chained_uniform(5);
        let mut unsure = 0;
        for lattice in [false, true] {
            let keys: Vec<[f32; 3]> = (0..3000)
                .map(|_| {
                    let mut c = || {
                        let x = rnd() * 0.3 - 0.1;
                        (if lattice {
                            (x * 100.0).floor() / 100.0
                        } else {
                            x
                        }) as f32
                    };
                    [c(), c(), c() * 0.5]
                })
                .collect();
            let tree = NearestTree::from_keys(keys.clone());
            let grid = CellGrid::new(&keys, 0.01);
            for i in 0..4000 {
                let spread = if i % 8 == 0 { 0.8 } else { 0.32 };
                let q: [f32; 3] = std::array::from_fn(|_| (rnd() * spread - 0.11) as f32);
                let radius = [0.001, 0.004, 0.012, 0.03, 2.0][i % 5];
                let truth = tree.nearest_two_within(&q, radius);
                assert_eq!(
                    grid.any_within(&q, radius),
                    truth.is_some(),
                    "{q:?} within {radius}"
                );
                match grid.nearest_two_within(&q, radius) {
                    TwoNearest::Found(item, d2, second2) => {
                        assert_eq!(Some((item, d2, second2)), truth, "{q:?} within {radius}")
                    }
                    TwoNearest::None => assert_eq!(truth, None, "{q:?} within {radius}"),
                    TwoNearest::Unsure => unsure += 1,
                }
            }
        }
        assert!((100..3000).contains(&unsure), "{unsure} unsure answers");
        let empty = CellGrid::new(&[], 0.01);
        assert_eq!(empty.nearest_two_within(&[0.0; 3], 1.0), TwoNearest::None);
        assert!(!empty.any_within(&[0.0; 3], 1.0));
    }
}
