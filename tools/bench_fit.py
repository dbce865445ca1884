#!/usr/bin/env python3
"""Reference timings for the fit's benchmarks (BENCHMARKS.md), beside `pipeline bench`.

1. scipy's cKDTree on the same points as `pipeline bench nearest` (a Fibonacci lattice of
   100k points on a 0.5 m sphere, 1M queries on a 0.51 m sphere), one worker and all.
2. One Open3D point-to-point rigid ICP iteration on two 50k-point clouds (when open3d is
   installed: pip install open3d, and Debian's libusb-1.0-0 for it to import), the
   yardstick for one articulated fit round: a call of one iteration (with its k-d tree
   build and evaluations), and one more iteration within a longer run.

usage: python3 tools/bench_fit.py [--points 100000] [--queries 1000000]
"""
import argparse
import time

import numpy as np


def fibonacci(n, radius):
    i = np.arange(n, dtype=np.float64)
    golden = np.pi * (3.0 - np.sqrt(5.0))
    z = 1.0 - 2.0 * (i + 0.5) / n
    r = np.sqrt(1.0 - z * z)
    a = golden * i
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1) * radius


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--queries", type=int, default=1_000_000)
    args = ap.parse_args()
    from scipy.spatial import cKDTree

    p = fibonacci(args.points, 0.5)
    q = fibonacci(args.queries, 0.51)
    t = time.perf_counter()
    tree = cKDTree(p)
    build = time.perf_counter() - t
    for workers in (1, -1):
        t = time.perf_counter()
        d, _ = tree.query(q, workers=workers)
        dt = time.perf_counter() - t
        print(f"scipy cKDTree: workers={workers}: {args.queries / dt / 1e6:.2f} M queries/s "
              f"(build {build * 1e3:.1f} ms, mean squared distance {np.mean(d * d):.3e} m^2)")
    try:
        import open3d as o3d
    except ImportError:
        print("open3d not installed: skipping the ICP yardstick (pip install open3d)")
        return
    a = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(fibonacci(50_000, 0.5)))
    b = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(fibonacci(50_000, 0.5) + [0.01, 0.0, 0.0]))
    est = o3d.pipelines.registration.TransformationEstimationPointToPoint()

    def fastest_call(iterations, repeats):
        """Seconds of the fastest of `repeats` ICP calls of exactly `iterations` iterations."""
        crit = o3d.pipelines.registration.ICPConvergenceCriteria(
            relative_fitness=0.0, relative_rmse=0.0, max_iteration=iterations)
        fastest = 1e9
        for _ in range(repeats):
            t = time.perf_counter()
            o3d.pipelines.registration.registration_icp(a, b, 0.05, np.eye(4), est, crit)
            fastest = min(fastest, time.perf_counter() - t)
        return fastest

    best = fastest_call(1, 5)
    print(f"open3d point-to-point ICP, one iteration, 50k + 50k points: {best * 1e3:.1f} ms")
    # A call of one iteration also builds the target's k-d tree and evaluates the start and
    # end poses. The cost of one more iteration inside a longer run, from calls of 11 and 31
    # iterations (no early stop), leaves those out.
    marginal = (fastest_call(31, 3) - fastest_call(11, 3)) / 20
    print(f"open3d point-to-point ICP, one more iteration within a run, 50k + 50k points: "
          f"{marginal * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
