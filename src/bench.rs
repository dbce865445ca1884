//! `pipeline bench`: timings of the stages' inner steps on real inputs, printed as a
//! table (benchmarks live here, never in tests).

use crate::error::Result;
use crate::geometry::isosurface::{self, ScalarGrid};
use crate::runner::Job;
use crate::stages::visual_hull::{self, MaskCounts};
use nalgebra::Vector3;
use std::time::Instant;

fn best_of<T>(repeat: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        let v = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best, out.expect("ran once"))
}

/// Times the visual hull's steps on one frame's cached silhouettes (best of `repeat`). With
/// `cube = Some(n)` the grid is n^3 voxels centred on the derived box (for comparisons on a
/// fixed grid size).
pub fn visual_hull(job: &Job, frame: u32, repeat: usize, cube: Option<usize>) -> Result<String> {
    let ctx = crate::stages::Context::new(&job.config, &job.sequence, &job.cache);
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    let cams = &job.sequence.cameras;
    let p = &job.config.visual_hull;
    let (t_counts, counts) = best_of(repeat, || {
        masks
            .iter()
            .zip(cams)
            .map(|(m, c)| MaskCounts::new(m, c))
            .collect::<Vec<_>>()
    });
    let (t_box, bbox) = best_of(repeat, || visual_hull::carving_box(cams, &counts, p));
    let (lo, hi) =
        bbox.ok_or_else(|| crate::Error::Usage(format!("frame {frame} has empty silhouettes")))?;
    let grid = match cube {
        None => crate::geometry::grid::GridSpec::covering(lo, hi, p.voxel_size),
        Some(n) => crate::geometry::grid::GridSpec {
            origin: (lo + hi) / 2.0 - Vector3::repeat(n as f64 * p.voxel_size / 2.0),
            voxel: p.voxel_size,
            dims: [n, n, n],
        },
    };
    let (t_carve, occupied) = best_of(repeat, || visual_hull::carve(&grid, cams, &counts, p));
    let (t_sdf, sdf) = best_of(repeat, || {
        crate::geometry::distance::signed_distance(&grid, &occupied)
    });
    let (t_mesh, mesh) = best_of(repeat, || visual_hull::mesh_sdf(&grid, &sdf));
    let (t_smooth, _) = best_of(repeat, || {
        let mut m = mesh.clone();
        crate::geometry::smooth::taubin(&mut m, p.smoothing_iterations);
        m
    });
    let kept = occupied.iter().filter(|&&o| o).count();
    Ok(format!(
        "grid origin {} {} {} voxel {} dims {} {} {}\n\
         visual hull, frame {frame}: {} cameras, grid {}x{}x{} ({:.1} M voxels of {} m, {} kept), mesh {} vertices\n\
         {:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n",
        grid.origin.x,
        grid.origin.y,
        grid.origin.z,
        grid.voxel,
        grid.dims[0],
        grid.dims[1],
        grid.dims[2],
        cams.len(),
        grid.dims[0],
        grid.dims[1],
        grid.dims[2],
        grid.len() as f64 / 1e6,
        grid.voxel,
        kept,
        mesh.vertices.len(),
        "mask summed-area tables",
        t_counts * 1e3,
        "bounding box (coarse carve)",
        t_box * 1e3,
        "carving (coarse to fine)",
        t_carve * 1e3,
        "signed distance",
        t_sdf * 1e3,
        "marching tetrahedra",
        t_mesh * 1e3,
        "taubin smoothing",
        t_smooth * 1e3,
    ))
}

/// Times iso-surface extraction of a sphere's signed distance on an n^3 grid.
pub fn meshing(n: usize, repeat: usize) -> String {
    let h = 1.0 / n as f64;
    let grid = ScalarGrid::sample(Vector3::zeros(), Vector3::repeat(1.0 - h), h, |p| {
        (p - Vector3::repeat(0.5)).norm() - 0.35
    });
    let (t, mesh) = best_of(repeat, || isosurface::extract(&grid));
    format!(
        "marching tetrahedra on a {n}^3 sphere field: {:.1} ms, {} vertices, {} triangles\n",
        t * 1e3,
        mesh.vertices.len(),
        mesh.triangles.len()
    )
}

/// Times building and solving the max-flow fixture graph of size n^3.
pub fn maxflow_fixture(n: usize) -> String {
    let t = Instant::now();
    let mut g = crate::maxflow::fixture::fixture_graph(n);
    let build = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let flow = g.maxflow();
    let solve = t.elapsed().as_secs_f64();
    let sink_side = (0..g.node_count())
        .filter(|&i| !g.is_source_side(i))
        .count();
    format!("maxflow fixture n={n}: flow {flow}, build {build:.3} s, solve {solve:.3} s, sink side {sink_side} nodes\n")
}

/// Times the graph-cut stage's steps on one frame (needs its hull in the cache).
pub fn graphcut(job: &Job, frame: u32) -> Result<String> {
    use crate::stages::graphcut as gc;
    let ctx = crate::stages::Context::new(&job.config, &job.sequence, &job.cache);
    let cams = &job.sequence.cameras;
    let p = &job.config.graphcut;
    let t = Instant::now();
    let (grid, sdf) = crate::stages::load_grid(&ctx, "visual_hull", frame)?;
    let (ply, _) = crate::stages::hull_files(frame);
    let hull = crate::geometry::ply::read_ply(&job.cache.stage_dir("visual_hull").join(ply))?;
    use rayon::prelude::*;
    let frames: Vec<image::RgbImage> = (0..cams.len())
        .into_par_iter()
        .map(|c| job.sequence.load_frame(c, frame))
        .collect::<Result<_>>()?;
    let t_load = t.elapsed().as_secs_f64();
    let (t_depth, depth) = best_of(1, || gc::depth_maps(cams, &hull, grid.voxel));
    let (t_grey, images) = best_of(1, || gc::grey(&frames));
    let occupied: Vec<bool> = sdf.iter().map(|&v| v < 0.0).collect();
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    let mut timings = gc::Timings::default();
    let t = Instant::now();
    let refined = gc::refine_timed(
        &grid,
        &occupied,
        &sdf,
        cams,
        &images,
        &depth,
        &masks,
        p,
        &mut |_, _| {},
        &mut timings,
    );
    let t_refine = t.elapsed().as_secs_f64();
    let (t_mesh, _) = best_of(1, || gc::mesh(&grid, &refined, p.smoothing_iterations));
    Ok(format!(
        "graph cut, frame {frame}: {} band voxels\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n",
        timings.band_voxels,
        "load hull and frames", t_load * 1e3,
        "hull depth maps", t_depth * 1e3,
        "grey images", t_grey * 1e3,
        "photo-consistency", timings.photo * 1e3,
        "graph and max-flow", timings.cut * 1e3,
        "refine total", t_refine * 1e3,
        "mesh", t_mesh * 1e3,
    ))
}
