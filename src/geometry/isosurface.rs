//! Iso-surface extraction from a scalar field sampled on a regular grid.
//!
//! The method is marching tetrahedra on the Kuhn (Freudenthal) split of every grid cube into
//! six tetrahedra sharing the cube's main diagonal. It was chosen over table-driven marching
//! cubes because every case is unambiguous: neighbouring cubes split their shared faces along
//! the same diagonal, so the surface of a closed region is watertight and manifold by
//! construction, with vertices welded on the grid edges they lie on. The cost is about twice
//! as many triangles as marching cubes.

use super::mesh::TriMesh;
use nalgebra::Vector3;

/// Samples of a scalar field on a regular grid: `values[x + nx*(y + ny*z)]` is the value at
/// `origin + spacing * (x, y, z)`. Negative is inside.
pub struct ScalarGrid {
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// World position of sample (0, 0, 0), metres.
    pub origin: Vector3<f64>,
    /// Distance between neighbouring samples, metres.
    pub spacing: f64,
    /// Field values, x fastest.
    pub values: Vec<f32>,
}

impl ScalarGrid {
    /// Samples `f` (negative inside) over the box `[lo, hi]` at `spacing`, in parallel.
    pub fn sample(
        lo: Vector3<f64>,
        hi: Vector3<f64>,
        spacing: f64,
        f: impl Fn(&Vector3<f64>) -> f64 + Sync,
    ) -> ScalarGrid {
        use rayon::prelude::*;
        let dims = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / spacing).ceil() as usize + 1);
        let plane = dims[0] * dims[1];
        let mut values = vec![0f32; plane * dims[2]];
        values
            .par_chunks_mut(plane)
            .enumerate()
            .for_each(|(z, slab)| {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let p = lo + spacing * Vector3::new(x as f64, y as f64, z as f64);
                        slab[x + dims[0] * y] = f(&p) as f32;
                    }
                }
            });
        ScalarGrid {
            dims,
            origin: lo,
            spacing,
            values,
        }
    }

    fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// Value at sample `i`, with exact zeros nudged inside so that no vertex lies exactly on
    /// the surface (which would make degenerate triangles).
    fn value(&self, i: usize) -> f32 {
        let v = self.values[i];
        if v == 0.0 {
            -1e-12
        } else {
            v
        }
    }
}

/// Cube corner offsets, bit k of the corner index = step along axis k.
const CORNER: [[usize; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [0, 1, 0],
    [1, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [0, 1, 1],
    [1, 1, 1],
];

/// The six Kuhn tetrahedra of a cube: paths from corner 0 to corner 7 adding one axis at a
/// time, in each of the 3! axis orders.
const TETS: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// Offsets (in cube-corner bits) of the seven edge directions a Kuhn tetrahedron uses:
/// every edge joins a corner to one with a superset of its bits.
fn edge_slot(from_bits: usize, to_bits: usize) -> usize {
    debug_assert!(to_bits & from_bits == from_bits && to_bits != from_bits);
    (to_bits ^ from_bits) - 1
}

/// Vertex ids of the grid edges starting in two consecutive z-slabs of samples: dense
/// arrays instead of a hash map (7 edge directions per sample). Only the entries a slab
/// used are reset when moving on.
struct EdgeSlabs {
    ids: [Vec<u32>; 2],
    touched: [Vec<u32>; 2],
}

impl EdgeSlabs {
    fn new(plane: usize) -> EdgeSlabs {
        EdgeSlabs {
            ids: [vec![u32::MAX; plane * 7], vec![u32::MAX; plane * 7]],
            touched: [Vec::new(), Vec::new()],
        }
    }

    /// Moves on by one z-slab: the upper slab becomes the lower one.
    fn advance(&mut self) {
        for &i in &self.touched[0] {
            self.ids[0][i as usize] = u32::MAX;
        }
        self.touched[0].clear();
        self.ids.swap(0, 1);
        self.touched.swap(0, 1);
    }
}

/// Extracts the zero level set of `grid` as an outward-oriented triangle mesh (normals point
/// towards positive values). Samples outside the grid count as outside, so a region that
/// touches the grid's border is not closed there: sample with a margin.
pub fn extract(grid: &ScalarGrid) -> TriMesh {
    let [nx, ny, nz] = grid.dims;
    let plane = nx * ny;
    let mut mesh = TriMesh::default();
    let mut slabs = EdgeSlabs::new(plane);
    for z in 0..nz.saturating_sub(1) {
        if z > 0 {
            slabs.advance();
        }
        for y in 0..ny.saturating_sub(1) {
            // Values of the cube's x = 0 face, carried along the row.
            let face = |x: usize| {
                [
                    grid.value(grid.index(x, y, z)),
                    grid.value(grid.index(x, y + 1, z)),
                    grid.value(grid.index(x, y, z + 1)),
                    grid.value(grid.index(x, y + 1, z + 1)),
                ]
            };
            let mut left = face(0);
            for x in 0..nx.saturating_sub(1) {
                let right = face(x + 1);
                // Corner bits: 1 = +x, 2 = +y, 4 = +z.
                let values = [
                    left[0], right[0], left[1], right[1], left[2], right[2], left[3], right[3],
                ];
                left = right;
                let inside_count = values.iter().filter(|&&v| v < 0.0).count();
                if inside_count == 0 || inside_count == 8 {
                    continue;
                }
                let base = grid.origin + grid.spacing * Vector3::new(x as f64, y as f64, z as f64);
                let corner_pos = |c: usize| {
                    base + grid.spacing
                        * Vector3::new(
                            CORNER[c][0] as f64,
                            CORNER[c][1] as f64,
                            CORNER[c][2] as f64,
                        )
                };
                for tet in TETS {
                    let (mut ins, mut outs) = ([0usize; 4], [0usize; 4]);
                    let (mut n_in, mut n_out) = (0, 0);
                    for c in tet {
                        if values[c] < 0.0 {
                            ins[n_in] = c;
                            n_in += 1;
                        } else {
                            outs[n_out] = c;
                            n_out += 1;
                        }
                    }
                    if n_in == 0 || n_out == 0 {
                        continue;
                    }
                    // The vertex on the edge between cube corners a and b, welded across
                    // cubes through the slab tables.
                    let mut vertex_on = |a: usize, b: usize, mesh: &mut TriMesh| -> u32 {
                        let (lo, hi) = if a & b == a { (a, b) } else { (b, a) };
                        let o = CORNER[lo];
                        let slab = o[2];
                        let slot = ((x + o[0]) + nx * (y + o[1])) * 7 + edge_slot(lo, hi);
                        let id = &mut slabs.ids[slab][slot];
                        if *id == u32::MAX {
                            let (va, vb) = (values[lo] as f64, values[hi] as f64);
                            let s = va / (va - vb);
                            let pa = corner_pos(lo);
                            mesh.vertices.push(pa + s * (corner_pos(hi) - pa));
                            *id = (mesh.vertices.len() - 1) as u32;
                            slabs.touched[slab].push(slot as u32);
                        }
                        *id
                    };
                    let inside_centre: Vector3<f64> = ins[..n_in]
                        .iter()
                        .map(|&c| corner_pos(c))
                        .sum::<Vector3<f64>>()
                        / n_in as f64;
                    // Orientation is decided on the edges' midpoints, which never form a
                    // degenerate triangle (interpolated vertices can, at samples on the
                    // surface), so it is the same for every cube sharing a face.
                    let mid = |a: usize, b: usize| (corner_pos(a) + corner_pos(b)) / 2.0;
                    let emit = |tri: [u32; 3], m: [Vector3<f64>; 3], mesh: &mut TriMesh| {
                        let n = (m[1] - m[0]).cross(&(m[2] - m[0]));
                        if n.dot(&(m[0] - inside_centre)) < 0.0 {
                            mesh.triangles.push([tri[0], tri[2], tri[1]]);
                        } else {
                            mesh.triangles.push(tri);
                        }
                    };
                    if n_in == 2 {
                        let e = [
                            (ins[0], outs[0]),
                            (ins[0], outs[1]),
                            (ins[1], outs[1]),
                            (ins[1], outs[0]),
                        ];
                        let q = e.map(|(a, b)| vertex_on(a, b, &mut mesh));
                        let m = e.map(|(a, b)| mid(a, b));
                        emit([q[0], q[1], q[2]], [m[0], m[1], m[2]], &mut mesh);
                        emit([q[0], q[2], q[3]], [m[0], m[2], m[3]], &mut mesh);
                    } else {
                        let (lone, others) = if n_in == 1 {
                            (ins[0], outs)
                        } else {
                            (outs[0], ins)
                        };
                        let tri = [0, 1, 2].map(|k| vertex_on(lone, others[k], &mut mesh));
                        emit(tri, [0, 1, 2].map(|k| mid(lone, others[k])), &mut mesh);
                    }
                }
            }
        }
    }
    mesh
}

/// A sphere of radius `r` (metres) about `centre`, meshed from its distance field sampled
/// every `spacing` metres: a closed test surface.
#[cfg(test)]
pub fn sphere(r: f64, centre: Vector3<f64>, spacing: f64) -> TriMesh {
    let e = Vector3::repeat(r + 2.0 * spacing.max(0.005));
    extract(&ScalarGrid::sample(centre - e, centre + e, spacing, |p| {
        (p - centre).norm() - r
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_is_watertight_outward_and_accurate() {
        let r = 0.3;
        let grid = ScalarGrid::sample(Vector3::repeat(-0.4), Vector3::repeat(0.4), 0.02, |p| {
            p.norm() - r
        });
        let mesh = extract(&grid);
        assert!(mesh.is_watertight());
        let vol = mesh.signed_volume();
        let truth = 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
        assert!(
            (vol - truth).abs() / truth < 0.01,
            "volume {vol} vs {truth}"
        );
        for v in &mesh.vertices {
            assert!((v.norm() - r).abs() < 0.002);
        }
    }

    #[test]
    fn random_fields_give_closed_oriented_surfaces() {
        let mut rng = crate::rng::Rng::new(9, 9);
        for trial in 0..20 {
            let n = 6 + trial % 5;
            let mut values = vec![1.0f32; n * n * n];
            for z in 1..n - 1 {
                for y in 1..n - 1 {
                    for x in 1..n - 1 {
                        // Many exact zeros and ties, the hard cases.
                        values[x + n * (y + n * z)] = (rng.uniform() * 3.0).floor() as f32 - 1.0;
                    }
                }
            }
            let grid = ScalarGrid {
                dims: [n, n, n],
                origin: Vector3::zeros(),
                spacing: 1.0,
                values,
            };
            let mesh = extract(&grid);
            assert!(mesh.is_watertight(), "trial {trial}");
            assert!(mesh.signed_volume() > 0.0, "trial {trial}");
        }
    }
}
