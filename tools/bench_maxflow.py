#!/usr/bin/env python3
"""The max-flow solver beside PyMaxflow (Kolmogorov's maxflow v3) on the fixture graphs of
shared/fixtures/maxflow, in one run.

usage: tools/bench_maxflow.py [N ...]   (default: 16 32 64; add 128 for the 2 M-node graph)
Needs numpy and PyMaxflow (pip install PyMaxflow)."""
import subprocess, sys, time, os
import numpy as np, maxflow

root = os.path.abspath(os.path.dirname(__file__) + "/..")
exe = os.path.join(root, "target/release/pipeline")
subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=root, check=True)

def splitmix64(k):
    m = np.uint64(0xFFFFFFFFFFFFFFFF)
    z = (k + np.uint64(0x9E3779B97F4A7C15)) & m
    z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & m
    z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & m
    return z ^ (z >> np.uint64(31))

def pymaxflow(n):
    t = time.perf_counter()
    z, y, x = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    i = (x + n * (y + n * z)).astype(np.uint64)
    dx, dy, dz = 2 * x + 1 - n, 2 * y + 1 - n, 2 * z + 1 - n
    s = dx * dx + dy * dy + dz * dz
    rd = (6 * n) // 10
    field = np.abs(s - rd * rd) // n
    g = maxflow.Graph[int]()
    ids = g.add_grid_nodes((n, n, n))
    with np.errstate(over="ignore"):
        for a, axis in enumerate([2, 1, 0]):  # +x, +y, +z in (z, y, x) arrays
            w = 1 + np.minimum(field, 200) + (splitmix64(np.uint64(3) * i + np.uint64(a)) % np.uint64(8)).astype(np.int64)
            st = np.zeros((3, 3, 3)); c = [1, 1, 1]; c[axis] = 2; st[tuple(c)] = 1
            g.add_grid_edges(ids, weights=w, structure=st, symmetric=True)
    border = (x == 0) | (y == 0) | (z == 0) | (x == n - 1) | (y == n - 1) | (z == n - 1)
    src = np.where(border, 1_000_000_000, 0)
    snk = 1 + np.where(s < (rd // 2) ** 2, 1_000_000_000, 0)
    g.add_grid_tedges(ids, src, snk)
    build = time.perf_counter() - t
    t = time.perf_counter()
    flow = g.maxflow()
    return flow, build, time.perf_counter() - t

sizes = [int(a) for a in sys.argv[1:]] or [16, 32, 64]
for n in sizes:
    flow, b, sv = pymaxflow(n)
    ours = subprocess.run([exe, "bench", "maxflow", "--size", str(n)], check=True, capture_output=True, text=True).stdout.split()
    of, ob, osv, threads, one = float(ours[4].rstrip(",")), float(ours[6]), float(ours[9]), ours[12], float(ours[14])
    assert of == flow, f"n={n}: flows differ ({of} vs {flow})"
    print(f"n={n}: PyMaxflow flow {flow} build {b:.3f} s solve {sv:.3f} s | hullpose flow {of:.0f} build {ob:.3f} s "
          f"solve {osv:.3f} s on {threads} threads, {one:.3f} s on 1 thread "
          f"| solve ratio {sv / osv:.2f}x ({sv / one:.2f}x on 1 thread), total ratio {(b + sv) / (ob + osv):.2f}x")
