//! `pipeline bench`: timings of the stages' inner steps on real inputs, printed as a
//! table (benchmarks live here, never in tests).

use crate::artifacts::reconstruction::{self, Surface};
use crate::error::{Error, Result};
use crate::geometry::isosurface::{self, ScalarGrid};
use crate::recon::visual_hull::{self, MaskCounts};
use crate::runner::Job;
use nalgebra::Vector3;
use std::fmt::Write as _;
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

/// Times building and solving the max-flow fixture graph of size n^3, with the threads
/// rayon has and on one thread.
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
    let mut serial = crate::maxflow::fixture::fixture_graph(n);
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build();
    let t = Instant::now();
    let serial_flow = match one_thread {
        Ok(pool) => pool.install(|| serial.maxflow()),
        Err(_) => serial.maxflow(),
    };
    let solve_serial = t.elapsed().as_secs_f64();
    assert_eq!(flow, serial_flow, "the same flow on any number of threads");
    format!(
        "maxflow fixture n={n}: flow {flow}, build {build:.3} s, solve {solve:.3} s on {} threads, {solve_serial:.3} s on 1 thread, sink side {sink_side} nodes\n",
        rayon::current_num_threads()
    )
}

/// Times the graph-cut stage's steps on one frame (needs its hull in the cache).
pub fn graphcut(job: &Job, frame: u32) -> Result<String> {
    use crate::recon::graphcut as gc;
    let ctx = crate::stages::Context::new(&job.config, &job.sequence, &job.cache);
    let cams = &job.sequence.cameras;
    let p = &job.config.graphcut;
    let t = Instant::now();
    let (grid, sdf) = reconstruction::read_grid(&job.cache, Surface::Hull, frame)?;
    let hull = reconstruction::read_mesh(&job.cache, Surface::Hull, frame)?;
    use rayon::prelude::*;
    let frames: Vec<image::RgbImage> = (0..cams.len())
        .into_par_iter()
        .map(|c| job.sequence.load_frame(c, frame))
        .collect::<Result<_>>()?;
    let t_load = t.elapsed().as_secs_f64();
    let (t_depth, depth) = best_of(1, || crate::photo::depth_maps(cams, &hull));
    let (t_grey, images) = best_of(1, || crate::photo::grey(&frames));
    let occupied: Vec<bool> = sdf.iter().map(|&v| v < 0.0).collect();
    let masks = crate::stages::load_silhouettes(&ctx, frame)?;
    let mut timings = gc::Timings::default();
    let t = Instant::now();
    let refined = gc::min_cut_occupancy_timed(
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
    let (t_band, hull_on_cones) = best_of(1, || {
        reconstruction::read_hull_on_cones(&job.cache, frame, &sdf)
    });
    let hull_on_cones = hull_on_cones?;
    let (t_mesh, _) = best_of(1, || {
        gc::mesh(&grid, &refined, &hull_on_cones, p.smoothing_iterations)
    });
    Ok(format!(
        "graph cut, frame {frame}: {} band voxels\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n{:>28} {:>9.1} ms\n",
        timings.band_voxels,
        "load hull and frames", t_load * 1e3,
        "hull depth maps", t_depth * 1e3,
        "grey images", t_grey * 1e3,
        "photo-consistency", timings.photo * 1e3,
        "graph and max-flow", timings.cut * 1e3,
        "refine total", t_refine * 1e3,
        "hull on the cones (band)", t_band * 1e3,
        "mesh", t_mesh * 1e3,
    ))
}

/// Times the person model on one frame: loading it, then per camera's image the detector
/// alone and the whole (detector, crop, landmarks, the mask at full size) on one thread (the
/// best of `repeat`), then all the frame's images on every thread (one model per thread).
pub fn person(job: &Job, frame: u32, repeat: usize) -> Result<String> {
    use crate::person::PersonModel;
    use rayon::prelude::*;
    let cams = &job.sequence.cameras;
    let images: Vec<image::RgbImage> = (0..cams.len())
        .map(|c| job.sequence.load_frame(c, frame))
        .collect::<Result<_>>()?;
    let dir = crate::person::model::folder();
    let t = Instant::now();
    let mut model = PersonModel::load(&dir)?;
    let t_load = t.elapsed().as_secs_f64();
    let mut out = format!(
        "person model, frame {frame}, {} cameras: loaded in {:.0} ms\n{:>12} {:>11} {:>8} {:>7} {:>6}\n",
        cams.len(),
        t_load * 1e3,
        "camera",
        "size",
        "detector",
        "whole",
        "found"
    );
    let (mut sum_detect, mut sum_whole) = (0.0, 0.0);
    for (cam, img) in cams.iter().zip(&images) {
        let (mut detect, mut whole, mut found) = (f64::INFINITY, f64::INFINITY, false);
        for _ in 0..repeat {
            let t = Instant::now();
            model.detect(img)?;
            detect = detect.min(t.elapsed().as_secs_f64());
            let t = Instant::now();
            found = model.find(img)?.is_some();
            whole = whole.min(t.elapsed().as_secs_f64());
        }
        sum_detect += detect;
        sum_whole += whole;
        out += &format!(
            "{:>12} {:>11} {:>5.1} ms {:>4.1} ms {:>6}\n",
            crate::text::escape_controls(&cam.name),
            format!("{}x{}", img.width(), img.height()),
            detect * 1e3,
            whole * 1e3,
            if found { "yes" } else { "no" }
        );
    }
    let n = cams.len() as f64;
    let t = Instant::now();
    let all: Vec<bool> = images
        .par_iter()
        .map_init(
            || PersonModel::load(&dir),
            |model, img| -> Result<bool> {
                let model = model.as_mut().map_err(|e| Error::Usage(e.to_string()))?;
                Ok(model.find(img)?.is_some())
            },
        )
        .collect::<Result<_>>()?;
    let t_all = t.elapsed().as_secs_f64();
    out += &format!(
        "one thread: {:.1} ms per image (detector {:.1} ms); all {} images on {} threads: {:.2} s \
         ({:.1} ms per image, model loading included), a person in {}\n",
        sum_whole / n * 1e3,
        sum_detect / n * 1e3,
        images.len(),
        rayon::current_num_threads(),
        t_all,
        t_all / n * 1e3,
        all.iter().filter(|&&f| f).count()
    );
    Ok(out)
}

/// Times the reliability stage's steps on one frame: image loading and smoothing, depth
/// maps, and the ZNCC of every vertex (patch sampling included), with its throughput in
/// vertex-camera-pairs per second (one pair = two cameras seeing a vertex, scored at every
/// shift its search along the normal tries). With `dump`, also writes `pairs` pairs of raw patches sampled on the
/// surface (little-endian f32, window^2 values per patch, two patches per pair) and times
/// the crate's ZNCC on exactly those, for `tools/bench_zncc.py`.
pub fn reliability(
    job: &Job,
    frame: u32,
    dump: Option<&std::path::Path>,
    pairs: usize,
) -> Result<String> {
    use crate::recon::reliability;
    use rayon::prelude::*;
    let p = &job.config.reliability;
    let cams = &job.sequence.cameras;
    let grid = reconstruction::read_grid_spec(&job.cache, Surface::Refined, frame)?;
    let mesh = reconstruction::read_mesh(&job.cache, Surface::Refined, frame)?;
    let h = grid.voxel;
    let start = Instant::now();
    let frames: Vec<image::RgbImage> = (0..cams.len())
        .into_par_iter()
        .map(|c| job.sequence.load_frame(c, frame))
        .collect::<Result<_>>()?;
    let t_load = start.elapsed().as_secs_f64();
    let (t_blur, images) = best_of(1, || {
        crate::photo::grey(&frames)
            .par_iter()
            .map(|g| g.blurred(p.image_sigma))
            .collect::<Vec<_>>()
    });
    let (t_depth, depth) = best_of(1, || crate::photo::depth_maps(cams, &mesh));
    let normals = mesh.vertex_normals();
    let (t_zncc, (_, seen)) = best_of(3, || {
        reliability::vertex_zncc(cams, &images, &depth, &mesh, &normals, h, p)
    });
    let camera_pairs: usize = seen
        .iter()
        .map(|&k| k as usize)
        .filter(|&k| k >= 2)
        .map(|k| k * (k - 1) / 2)
        .sum();
    let mut out = format!(
        "reliability bench, frame {frame}: {} vertices, {} cameras, voxel {h} m\n\
         load images     {:>8.1} ms\n\
         grey + blur     {:>8.1} ms\n\
         depth maps      {:>8.1} ms\n\
         zncc            {:>8.1} ms  ({} camera pairs, {:.2} M pairs/s, each with its search \
         along the normal, sampling included)\n",
        mesh.vertices.len(),
        cams.len(),
        t_load * 1e3,
        t_blur * 1e3,
        t_depth * 1e3,
        t_zncc * 1e3,
        camera_pairs,
        camera_pairs as f64 / t_zncc / 1e6,
    );
    if let Some(path) = dump {
        // Raw patch pairs at the vertices' own positions, from the first cameras that see
        // each vertex.
        let window = p.window;
        let len = window * window;
        let mut data: Vec<f32> = Vec::with_capacity(2 * pairs * len);
        'vertices: for (v, n) in mesh.vertices.iter().zip(&normals) {
            let patches: Vec<Vec<f32>> = cams
                .iter()
                .zip(&images)
                .filter(|(cam, _)| n.dot(&(cam.centre() - v)) > 0.5 * (cam.centre() - v).norm())
                .filter_map(|(cam, img)| {
                    crate::photo::sample_patch(cam, img, v, n, window, p.patch_spacing * h)
                })
                .collect();
            for a in 0..patches.len() {
                for b in a + 1..patches.len() {
                    if data.len() >= 2 * pairs * len {
                        break 'vertices;
                    }
                    data.extend(&patches[a]);
                    data.extend(&patches[b]);
                }
            }
        }
        let got = data.len() / (2 * len);
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        crate::fsutil::write_atomic(path, &bytes)?;
        let (t_pairs, mean) = best_of(5, || crate::photo::zncc_of_pairs(&data, len));
        let _ = writeln!(
            out,
            "dumped {got} patch pairs ({window}x{window}) to {}\n\
             zncc of the dumped pairs: {:.1} ms, {:.2} M pairs/s (mean zncc {mean:.4})",
            path.display(),
            t_pairs * 1e3,
            got as f64 / t_pairs / 1e6
        );
    }
    Ok(out)
}

/// Point i of n on a sphere of `radius` metres (a Fibonacci lattice): the same points as
/// `tools/bench_fit.py` makes, so both sides query identical data.
pub fn fibonacci_point(i: usize, n: usize, radius: f64) -> Vector3<f64> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
    let r = (1.0 - z * z).sqrt();
    let a = golden * i as f64;
    Vector3::new(r * a.cos(), r * a.sin(), z) * radius
}

/// Nearest-neighbour throughput: `points` on a 0.5 m sphere, `queries` on a 0.51 m sphere,
/// one thread (as scipy's cKDTree.query with workers=1) and all threads.
pub fn nearest(points: usize, queries: usize) -> String {
    use crate::geometry::nearest::NearestTree;
    use rayon::prelude::*;
    let p: Vec<Vector3<f64>> = (0..points)
        .map(|i| fibonacci_point(i, points, 0.5))
        .collect();
    let q: Vec<Vector3<f64>> = (0..queries)
        .map(|i| fibonacci_point(i, queries, 0.51))
        .collect();
    let t = Instant::now();
    let tree = NearestTree::new(&p);
    let build = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let sum1: f64 = q.iter().map(|x| tree.nearest(x).map_or(0.0, |n| n.1)).sum();
    let one = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let sum2: f64 = q
        .par_iter()
        .map(|x| tree.nearest(x).map_or(0.0, |n| n.1))
        .sum();
    let all = t.elapsed().as_secs_f64();
    // With the second-nearest distance, as the fit's kept answers need it.
    let keys: Vec<[f32; 3]> = q.iter().map(crate::geometry::nearest::key).collect();
    let t = Instant::now();
    let sum3: f64 = keys
        .iter()
        .map(|x| tree.nearest_two(x).map_or(0.0, |n| n.2))
        .sum();
    let two = t.elapsed().as_secs_f64();
    let mut out = format!(
        "kiddo nearest: {points} points, {queries} queries\n  build {:.1} ms\n  1 thread: {:.2} M queries/s\n  {} threads: {:.2} M queries/s\n  1 thread, with the second nearest: {:.2} M queries/s\n  (mean squared distance {:.3e} / {:.3e} m^2, second {:.3e})\n",
        build * 1e3,
        queries as f64 / one / 1e6,
        rayon::current_num_threads(),
        queries as f64 / all / 1e6,
        queries as f64 / two / 1e6,
        sum1 / queries as f64,
        sum2 / queries as f64,
        sum3 / queries as f64
    );
    out.push_str(&bounded_two_nearest(&tree, &keys));
    out
}

/// The fit's short searches between rounds ([`crate::fit::kept_nearest`]): the two nearest
/// within each query's nearest distance plus `SECOND_REACH`, by the k-d tree and by the
/// cell grid (cells twice the points' mean spacing on the sphere), with the grid's answers
/// checked against the tree's.
fn bounded_two_nearest(tree: &crate::geometry::nearest::NearestTree, keys: &[[f32; 3]]) -> String {
    use crate::fit::kept_nearest::SECOND_REACH;
    use crate::geometry::cell_grid::{CellGrid, TwoNearest};
    let radii: Vec<f64> = keys
        .iter()
        .map(|q| tree.nearest_key(q).map_or(0.0, |n| n.1.sqrt()) + SECOND_REACH)
        .collect();
    let points = tree.keys();
    let spacing = (4.0 * std::f64::consts::PI * 0.25 / points.len() as f64).sqrt();
    let t = Instant::now();
    let grid = CellGrid::new(points, 2.0 * spacing);
    let grid_build = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let by_tree: Vec<Option<(usize, f64, f64)>> = keys
        .iter()
        .zip(&radii)
        .map(|(q, &r)| tree.nearest_two_within(q, r))
        .collect();
    let tree_time = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let by_grid: Vec<TwoNearest> = keys
        .iter()
        .zip(&radii)
        .map(|(q, &r)| grid.nearest_two_within(q, r))
        .collect();
    let grid_time = t.elapsed().as_secs_f64();
    let (mut unsure, mut differ) = (0, 0);
    for (g, t) in by_grid.iter().zip(&by_tree) {
        match g {
            TwoNearest::Found(i, d2, s2) => differ += usize::from(Some((*i, *d2, *s2)) != *t),
            TwoNearest::None => differ += usize::from(t.is_some()),
            TwoNearest::Unsure => unsure += 1,
        }
    }
    let n = keys.len() as f64;
    format!(
        "bounded two nearest (within the nearest's distance + {:.0} mm, as the fit's searches), 1 thread:\n  k-d tree: {:.2} M queries/s\n  cell grid ({:.1} mm cells, built in {:.1} ms): {:.2} M queries/s, {unsure} deferred to the tree, {differ} answers differing from the tree's\n",
        SECOND_REACH * 1e3,
        n / tree_time / 1e6,
        2e3 * spacing,
        grid_build * 1e3,
        n / grid_time / 1e6,
    )
}

/// The fit stage's tracking over the job's frames, in memory, with `method` overriding
/// fit.method: seconds, rounds, joint error, residual and status per frame, then
/// milliseconds per round of each step and the mean seconds per tracked frame; with
/// `joints`, the tracked joints are written there (joints.csv), with `rounds` every round
/// ([`rounds_csv`]).
pub fn track(
    job: &Job,
    method: Option<&str>,
    joints: Option<&std::path::Path>,
    rounds: Option<&std::path::Path>,
) -> Result<String> {
    // Checked before the tracking, which may take minutes.
    for (flag, path) in [("--joints", joints), ("--rounds", rounds)] {
        if let Some(path) = path {
            let dir = path
                .parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(std::path::Path::new("."));
            if !dir.is_dir() {
                return Err(crate::Error::Usage(format!(
                    "{flag} {}: the folder {} does not exist; create it or write elsewhere",
                    path.display(),
                    dir.display()
                )));
            }
        }
    }
    let ctx = job.context();
    let mut params = job.config.fit.clone();
    if let Some(name) = method {
        params.method = crate::fit::Method::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| {
                crate::Error::Usage(format!(
                    "--method {name}: expected one of icp, normals, rho_c, rho_p, proposed"
                ))
            })?;
    }
    let frames = job.tracked_frames()?;
    if frames.is_empty() {
        return Err(crate::Error::Usage(format!(
            "{} has no skeleton.yaml: there is nothing to track",
            job.sequence.dir.display()
        )));
    }
    let bar = crate::runner::bar(frames.len(), params.method.name());
    let tracked = crate::stages::fit::track_in_memory(&ctx, &frames, &params, &|_| bar.inc(1))?;
    bar.finish_and_clear();
    let model = crate::artifacts::body_model::read(&job.cache)?;
    let rows: Vec<_> = tracked
        .results
        .iter()
        .flat_map(|(f, r)| crate::stages::fit::joint_rows(&model.skeleton, *f, &r.pose))
        .collect();
    if let Some(path) = joints {
        crate::joints::write(path, &rows)?;
    }
    // With ground truth, each frame's mean joint error (cm).
    let truth = job.sequence.ground_truth_joints()?;
    let truth_path = job.sequence.dir.join("ground_truth/joints.csv");
    let errors: Vec<(u32, f64)> = match &truth {
        Some(truth) => crate::eval::pose::joint_errors(truth, &rows, &truth_path)?,
        None => Vec::new(),
    };
    if let Some(path) = rounds {
        let truth = truth.as_deref().map(|t| (t, truth_path.as_path()));
        let text = rounds_csv(&model.skeleton, &tracked.rounds, truth)?;
        crate::fsutil::write_atomic(path, text.as_bytes())?;
    }
    let mut out = format!(
        "tracking, method {}, model_spacing {} m, sample_spacing {} m\n  frame  seconds  rounds  error_cm     rms_mm  unexpl_cm2  status  recovery\n",
        params.method.name(),
        params.model_spacing,
        params.sample_spacing
    );
    let (mut fitted, mut seconds, mut rounds) = (0usize, 0.0, 0usize);
    // Frames with a recovery, and their seconds.
    let (mut recovered, mut recovery_seconds) = (0usize, 0.0);
    for (frame, secs) in &tracked.seconds {
        let Some((_, r)) = tracked.results.iter().find(|x| x.0 == *frame) else {
            continue;
        };
        let d = &r.diagnostics;
        let error = errors
            .iter()
            .find(|e| e.0 == *frame)
            .map_or("-".to_string(), |e| format!("{:.2}", e.1 * 100.0));
        let _ = writeln!(
            out,
            "  {frame:>5} {secs:>8.3} {:>7} {error:>9} {:>10.3} {:>11.0}  {}  {}",
            d.iterations,
            d.rms * 1e3,
            crate::fit::unexplained_cm2(d, params.sample_spacing),
            d.status.name(),
            d.recovery.as_deref().unwrap_or("")
        );
        if d.status != crate::fit::FitStatus::Reference {
            fitted += 1;
            seconds += secs;
            rounds += d.iterations;
            if d.recovery.is_some() {
                recovered += 1;
                recovery_seconds += secs;
            }
        }
    }
    let _ = writeln!(out, "  per round ({rounds} rounds):");
    write_round_steps(
        &mut out,
        &tracked.steps,
        rounds.max(1) as f64,
        seconds,
        tracked.reused,
    );
    let _ = writeln!(
        out,
        "  {fitted} tracked frames in {seconds:.2} s: {:.3} s per frame",
        seconds / fitted.max(1) as f64
    );
    let others = fitted - recovered;
    let _ = writeln!(
        out,
        "  recovery on {recovered} frames: {:.3} s per frame there, {:.3} s per frame on the {others} others",
        recovery_seconds / recovered.max(1) as f64,
        (seconds - recovery_seconds) / others.max(1) as f64
    );
    Ok(out)
}

/// Header of [`rounds_csv`].
pub const ROUNDS_HEADER: &str = "frame,start,round,kind,moved_mm,energy,error_cm";

/// The rounds of a tracking as CSV, a row per round in computation order: the frame, which
/// of its fits (`start`: 0 the first, 1 and on the restarts), the round's number in that
/// fit, its kind ([`crate::fit::RoundKind`]), its largest joint motion (mm), eq. 4 after it
/// (m^2) and, with `truth` (ground-truth joints and their file), the mean joint error of
/// its pose (cm; empty without).
pub fn rounds_csv(
    skeleton: &crate::skeleton::Skeleton,
    rounds: &[(u32, crate::fit::RoundRecord)],
    truth: Option<(&[crate::joints::JointRow], &std::path::Path)>,
) -> Result<String> {
    let mut out = format!("{ROUNDS_HEADER}\n");
    for (frame, r) in rounds {
        let error = match truth {
            Some((truth, path)) => {
                let rows = crate::stages::fit::joint_rows(skeleton, *frame, &r.pose);
                let e = crate::eval::pose::joint_errors(truth, &rows, path)?;
                e.first()
                    .map_or(String::new(), |e| format!("{:.4}", e.1 * 100.0))
            }
            None => String::new(),
        };
        let _ = writeln!(
            out,
            "{frame},{},{},{},{:.4},{:.6e},{error}",
            r.start,
            r.round,
            r.kind.name(),
            r.moved * 1e3,
            r.energy
        );
    }
    Ok(out)
}

/// The fit's steps on one frame (needs the model and the frame's reliability in the cache):
/// one tracked fit from t0's pose, with `spacing` (the fit's sample_spacing and
/// model_spacing both, when given), reporting the
/// vertex counts and the time per round of each step.
pub fn fit(job: &Job, frame: u32, spacing: Option<f64>) -> Result<String> {
    let ctx = job.context();
    let model = crate::artifacts::body_model::read(&job.cache)?;
    let mut params = job.config.fit.clone();
    if let Some(s) = spacing {
        params.sample_spacing = s;
        params.model_spacing = s;
    }
    let obs = crate::stages::fit::cached_observation(&ctx, frame)?;
    let model_count = crate::fit::thin(&model.mesh.vertices, params.model_spacing).len();
    let obs_count = crate::fit::thin(&obs.vertices, params.sample_spacing).len();
    let t = Instant::now();
    let fitter = crate::fit::Fitter::new(&model, params.clone());
    let setup = t.elapsed().as_secs_f64();
    let start = crate::skeleton::Pose::rest(model.skeleton.bones.len());
    let probe = crate::fit::Probe::default();
    let t = Instant::now();
    let result = fitter.fit(&obs, &start, &probe);
    let total = t.elapsed().as_secs_f64();
    let rounds = result.diagnostics.iterations.max(1) as f64;
    let mut out = format!(
        "fit of frame {frame} from t0's pose, method {}: {model_count} model and {obs_count} observed vertices (model_spacing {} m, sample_spacing {} m)\n  setup {:.1} ms, fit {:.3} s, {} rounds ({:?})\n  per round:\n",
        params.method.name(),
        params.model_spacing,
        params.sample_spacing,
        setup * 1e3,
        total,
        result.diagnostics.iterations,
        result.diagnostics.status
    );
    write_round_steps(
        &mut out,
        &probe.timings(),
        rounds,
        total,
        probe.reused_shares(),
    );
    Ok(out)
}

/// Writes a fit's milliseconds per round of each step, their sum and the wall clock
/// (`wall` seconds over `rounds`), then the shares of answers `reused` (nearest
/// model->observed and observed->model, rho_c's lists). rho_c and the nearest searches run side by side, so the sum exceeds the
/// wall clock by their overlap.
fn write_round_steps(
    out: &mut String,
    steps: &[(&'static str, f64)],
    rounds: f64,
    wall: f64,
    reused: [f64; 3],
) {
    let mut sum = 0.0;
    for (step, secs) in steps {
        // A step's parts are printed indented, and already in its sum.
        if let Some(part) = step.strip_prefix(crate::fit::STEP_PART_PREFIX) {
            let _ = writeln!(out, "      {part:<24} {:8.2} ms", secs * 1e3 / rounds);
            continue;
        }
        sum += secs;
        let _ = writeln!(out, "    {step:<26} {:8.2} ms", secs * 1e3 / rounds);
    }
    let _ = writeln!(
        out,
        "    {:<26} {:8.2} ms",
        "sum of steps",
        sum * 1e3 / rounds
    );
    let _ = writeln!(
        out,
        "    {:<26} {:8.2} ms   (rho_c and the nearest searches overlap)",
        "wall clock",
        wall * 1e3 / rounds
    );
    let _ = writeln!(
        out,
        "  reused from an earlier round: nearest {:.1}% model->observed, {:.1}% observed->model; rho_c lists {:.1}%",
        100.0 * reused[0],
        100.0 * reused[1],
        100.0 * reused[2]
    );
}
