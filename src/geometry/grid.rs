//! Regular voxel grids: voxel (x, y, z) is the cube `origin + size * [x, x+1] x [y, y+1] x
//! [z, z+1]` (metres), stored x fastest.

use nalgebra::Vector3;

/// Geometry of a voxel grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    /// Corner of voxel (0, 0, 0), metres.
    pub origin: Vector3<f64>,
    /// Voxel edge length, metres.
    pub voxel: f64,
    /// Voxels along x, y, z.
    pub dims: [usize; 3],
}

/// The six face neighbours' offsets (x, y, z): the positive one of each axis first.
pub const FACE_OFFSETS: [[i64; 3]; 6] = [
    [1, 0, 0],
    [-1, 0, 0],
    [0, 1, 0],
    [0, -1, 0],
    [0, 0, 1],
    [0, 0, -1],
];

impl GridSpec {
    /// The grid of `voxel`-sized cells covering the box [lo, hi].
    pub fn covering(lo: Vector3<f64>, hi: Vector3<f64>, voxel: f64) -> GridSpec {
        let dims = [0, 1, 2].map(|a| (((hi[a] - lo[a]) / voxel).ceil() as usize).max(1));
        GridSpec {
            origin: lo,
            voxel,
            dims,
        }
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// The voxel one step from voxel `i` along `offset` (one of [`FACE_OFFSETS`]), or `None`
    /// where that lies outside the grid.
    pub fn face_neighbour(&self, i: usize, offset: [i64; 3]) -> Option<usize> {
        let c = self.coords(i);
        let mut at = [0usize; 3];
        for axis in 0..3 {
            let v = c[axis] as i64 + offset[axis];
            if v < 0 || v >= self.dims[axis] as i64 {
                return None;
            }
            at[axis] = v as usize;
        }
        Some(self.index(at[0], at[1], at[2]))
    }

    pub fn coords(&self, i: usize) -> [usize; 3] {
        [
            i % self.dims[0],
            (i / self.dims[0]) % self.dims[1],
            i / (self.dims[0] * self.dims[1]),
        ]
    }

    /// Centre of voxel (x, y, z), metres.
    pub fn centre(&self, x: usize, y: usize, z: usize) -> Vector3<f64> {
        self.origin + self.voxel * Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5)
    }

    /// The box's far corner, metres.
    pub fn max_corner(&self) -> Vector3<f64> {
        self.origin
            + self.voxel
                * Vector3::new(
                    self.dims[0] as f64,
                    self.dims[1] as f64,
                    self.dims[2] as f64,
                )
    }

    /// Trilinear interpolation of per-voxel `values` (sampled at voxel centres) at `p`;
    /// `outside` beyond the grid.
    pub fn interpolate(&self, values: &[f32], p: &Vector3<f64>, outside: f32) -> f32 {
        let g = (p - self.origin) / self.voxel - Vector3::repeat(0.5);
        let base = g.map(f64::floor);
        if (0..3).any(|a| base[a] < 0.0 || base[a] + 1.0 >= self.dims[a] as f64) {
            return outside;
        }
        let f = g - base;
        let (x, y, z) = (base.x as usize, base.y as usize, base.z as usize);
        let mut acc = 0.0;
        for dz in 0..2 {
            for dy in 0..2 {
                for dx in 0..2 {
                    let w = (if dx == 1 { f.x } else { 1.0 - f.x })
                        * (if dy == 1 { f.y } else { 1.0 - f.y })
                        * (if dz == 1 { f.z } else { 1.0 - f.z });
                    acc += w * values[self.index(x + dx, y + dy, z + dz)] as f64;
                }
            }
        }
        acc as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn face_neighbours_stay_inside_the_grid() {
        let g = GridSpec {
            origin: Vector3::zeros(),
            voxel: 0.01,
            dims: [3, 4, 5],
        };
        // A corner voxel has three neighbours, an inner one six, each one step away.
        let count = |i: usize| {
            FACE_OFFSETS
                .iter()
                .filter_map(|&o| g.face_neighbour(i, o))
                .count()
        };
        assert_eq!(count(g.index(0, 0, 0)), 3);
        assert_eq!(count(g.index(2, 3, 4)), 3);
        assert_eq!(count(g.index(1, 2, 3)), 6);
        let i = g.index(1, 2, 3);
        assert_eq!(g.face_neighbour(i, [0, -1, 0]), Some(g.index(1, 1, 3)));
        assert_eq!(g.face_neighbour(i, [0, 0, 1]), Some(g.index(1, 2, 4)));
        assert_eq!(g.face_neighbour(g.index(2, 0, 0), [1, 0, 0]), None);
    }
}
