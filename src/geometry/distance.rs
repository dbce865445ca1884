//! Exact Euclidean distance transforms on voxel grids (Felzenszwalb and Huttenlocher's
//! separable lower-envelope algorithm), and the signed distance of an occupancy.

use super::grid::GridSpec;
use rayon::prelude::*;

const INF: f64 = 1e20;

/// 1D squared distance transform of `f` in place (`f[i]` = 0 at sites, INF elsewhere, or
/// the result of a previous pass).
fn dt_1d(f: &mut [f64], v: &mut [usize], z: &mut [f64], out: &mut [f64]) {
    let n = f.len();
    // Lines without a site, or all sites, stay as they are.
    if n == 0 || f.iter().all(|&v| v >= INF) || f.iter().all(|&v| v == 0.0) {
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
    let mut d = vec![0f64; site.len()];
    let scratch = |n: usize| (vec![0usize; n], vec![0f64; n + 1], vec![0f64; n]);
    // Along x, contiguous rows of sites: the distance to the nearest site in the row, by a
    // forward and a backward scan (no envelope needed for 0 / infinity inputs).
    d.par_chunks_mut(nx)
        .zip(site.par_chunks(nx))
        .for_each(|(row, sites)| {
            let mut last: Option<usize> = None;
            for (x, (o, &s)) in row.iter_mut().zip(sites).enumerate() {
                if s {
                    last = Some(x);
                }
                *o = last.map_or(INF, |p| ((x - p) * (x - p)) as f64);
            }
            let mut next: Option<usize> = None;
            for x in (0..nx).rev() {
                if sites[x] {
                    next = Some(x);
                }
                if let Some(p) = next {
                    row[x] = row[x].min(((p - x) * (p - x)) as f64);
                }
            }
        });
    // Along y: gather lines per z-slab.
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
    // Along z: blocks of neighbouring columns, gathered and scattered as contiguous runs of
    // each slab (a column alone would touch one value per cache line).
    const BLOCK: usize = 64;
    let blocks: Vec<(usize, Vec<f64>)> = (0..plane)
        .step_by(BLOCK)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|i0| {
            let width = BLOCK.min(plane - i0);
            let mut block: Vec<f64> = (0..nz)
                .flat_map(|k| d[k * plane + i0..k * plane + i0 + width].iter().copied())
                .collect();
            let (mut v, mut z, mut out) = scratch(nz);
            let mut line = vec![0f64; nz];
            for c in 0..width {
                for k in 0..nz {
                    line[k] = block[k * width + c];
                }
                dt_1d(&mut line, &mut v, &mut z, &mut out);
                for k in 0..nz {
                    block[k * width + c] = line[k];
                }
            }
            (i0, block)
        })
        .collect();
    for (i0, block) in blocks {
        let width = block.len() / nz;
        for (k, run) in block.chunks_exact(width).enumerate() {
            d[k * plane + i0..k * plane + i0 + width].copy_from_slice(run);
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

    /// Exact on a grid wider than one block of columns, with sparse sites (rows and columns
    /// without any) and with no site at all.
    #[test]
    fn matches_brute_force_on_sparse_sites() {
        let grid = GridSpec {
            origin: Vector3::zeros(),
            voxel: 1.0,
            dims: [23, 9, 11],
        };
        let site: Vec<bool> = (0..grid.len()).map(|i| (i * 7919) % 211 == 5).collect();
        let sites: Vec<[usize; 3]> = (0..grid.len())
            .filter(|&j| site[j])
            .map(|j| grid.coords(j))
            .collect();
        let d = squared_distance_to(&grid, &site);
        for (i, &di) in d.iter().enumerate() {
            let a = grid.coords(i);
            let brute = sites
                .iter()
                .map(|b| (0..3).map(|k| (a[k] as f64 - b[k] as f64).powi(2)).sum())
                .fold(f64::INFINITY, f64::min);
            assert_eq!(di, brute, "voxel {a:?}");
        }
        let none = squared_distance_to(&grid, &vec![false; grid.len()]);
        assert!(none.iter().all(|&v| v >= INF));
    }
}
