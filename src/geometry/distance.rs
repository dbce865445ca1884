//! Exact Euclidean distance transforms on voxel grids (Felzenszwalb and Huttenlocher's
//! separable lower-envelope algorithm), and the signed distance of an occupancy.

use super::grid::GridSpec;
use rayon::prelude::*;

const INF: f64 = 1e20;

/// 1D squared distance transform of `f` in place (`f[i]` = 0 at sites, INF elsewhere, or
/// the result of a previous pass).
fn dt_1d(f: &mut [f64], v: &mut [usize], z: &mut [f64], out: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut k = 0usize;
    v[0] = 0;
    z[0] = -INF;
    z[1] = INF;
    for q in 1..n {
        loop {
            let p = v[k];
            let s = ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64))
                / (2.0 * q as f64 - 2.0 * p as f64);
            if s <= z[k] && k > 0 {
                k -= 1;
                continue;
            }
            if s <= z[k] {
                // k == 0: replace the first parabola.
                v[0] = q;
                z[0] = -INF;
                z[1] = INF;
                break;
            }
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = INF;
            break;
        }
    }
    k = 0;
    for (q, o) in out.iter_mut().enumerate().take(n) {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let d = q as f64 - v[k] as f64;
        *o = d * d + f[v[k]];
    }
    f.copy_from_slice(&out[..n]);
}

/// Squared distance (in voxels) from every voxel to the nearest voxel where `site` is true.
pub fn squared_distance_to(grid: &GridSpec, site: &[bool]) -> Vec<f64> {
    let [nx, ny, nz] = grid.dims;
    let mut d: Vec<f64> = site.iter().map(|&s| if s { 0.0 } else { INF }).collect();
    let scratch = |n: usize| (vec![0usize; n], vec![0f64; n + 1], vec![0f64; n]);
    // Along x: contiguous rows.
    d.par_chunks_mut(nx).for_each(|row| {
        let (mut v, mut z, mut out) = scratch(nx);
        dt_1d(row, &mut v, &mut z, &mut out);
    });
    // Along y and z: gather lines per z-slab (y) and per column (z).
    d.par_chunks_mut(nx * ny).for_each(|slab| {
        let (mut v, mut z, mut out) = scratch(ny);
        let mut line = vec![0f64; ny];
        for x in 0..nx {
            for y in 0..ny {
                line[y] = slab[x + nx * y];
            }
            dt_1d(&mut line, &mut v, &mut z, &mut out);
            for y in 0..ny {
                slab[x + nx * y] = line[y];
            }
        }
    });
    let plane = nx * ny;
    if nz == 1 {
        return d; // an image: nothing along z
    }
    let columns: Vec<Vec<f64>> = (0..plane)
        .into_par_iter()
        .map(|i| {
            let (mut v, mut z, mut out) = scratch(nz);
            let mut line: Vec<f64> = (0..nz).map(|k| d[i + plane * k]).collect();
            dt_1d(&mut line, &mut v, &mut z, &mut out);
            line
        })
        .collect();
    for (i, col) in columns.into_iter().enumerate() {
        for (k, val) in col.into_iter().enumerate() {
            d[i + plane * k] = val;
        }
    }
    d
}

/// Signed distance of an occupancy, metres, sampled at voxel centres: negative inside,
/// with the surface half a voxel beyond the outermost occupied centres (so the zero level
/// runs between occupied and empty voxels).
pub fn signed_distance(grid: &GridSpec, occupied: &[bool]) -> Vec<f32> {
    let empty: Vec<bool> = occupied.iter().map(|&o| !o).collect();
    let to_inside = squared_distance_to(grid, occupied);
    let to_outside = squared_distance_to(grid, &empty);
    occupied
        .par_iter()
        .zip(to_inside.par_iter().zip(to_outside.par_iter()))
        .map(|(&occ, (&di, &dout))| {
            let v = if occ {
                -(dout.sqrt() - 0.5)
            } else {
                di.sqrt() - 0.5
            };
            // Without any site of the other kind the distance is "infinite": clamp.
            (v.clamp(-1e6, 1e6) * grid.voxel) as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn matches_brute_force() {
        let grid = GridSpec {
            origin: Vector3::zeros(),
            voxel: 1.0,
            dims: [7, 5, 6],
        };
        let site: Vec<bool> = (0..grid.len()).map(|i| i % 17 == 3 || i == 100).collect();
        let d = squared_distance_to(&grid, &site);
        for (i, &di) in d.iter().enumerate() {
            let a = grid.coords(i);
            let brute = (0..grid.len())
                .filter(|&j| site[j])
                .map(|j| {
                    let b = grid.coords(j);
                    (0..3)
                        .map(|k| (a[k] as f64 - b[k] as f64).powi(2))
                        .sum::<f64>()
                })
                .fold(f64::INFINITY, f64::min);
            assert_eq!(di, brute, "voxel {a:?}");
        }
    }
}
