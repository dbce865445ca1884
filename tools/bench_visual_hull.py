#!/usr/bin/env python3
"""Visual hull and meshing beside numpy / scikit-image references, in one run.

usage: tools/bench_visual_hull.py [WORKDIR]
Makes the tripod capture (15 cameras, 1024x768) in WORKDIR (default /tmp/hullpose-bench)
unless it is there, runs the pipeline's silhouettes and visual hull (release build), then
times on frame 7's silhouettes and the very same 200^3 grid of 1 cm voxels:
  - `pipeline bench visual-hull` (carving coarse to fine, signed distance, meshing, ...)
  - a plain numpy carving (every voxel centre projected into every camera)
  - a coarse-to-fine numpy carving (8 cm cells refined to 1 cm; a cell survives when its
    projected radius reaches the silhouette, via a distance transform of each mask)
and marching tetrahedra on a 256^3 sphere beside skimage.measure.marching_cubes.
Needs numpy, scipy, scikit-image, pillow, pyyaml (pip)."""
import os, subprocess, sys, time
import numpy as np, yaml
from PIL import Image
from scipy import ndimage

root = os.path.abspath(os.path.dirname(__file__) + "/..")
work = sys.argv[1] if len(sys.argv) > 1 else "/tmp/hullpose-bench"
exe = os.path.join(root, "target/release/pipeline")
subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=root, check=True)
if not os.path.exists(os.path.join(work, "pipeline.yaml")):
    subprocess.run([exe, "synth", "--scene", "tripod", "--out", work], check=True)
subprocess.run([exe, "run", os.path.join(work, "pipeline.yaml")], check=True, stdout=subprocess.DEVNULL)
FRAME = 7
CUBE = 200
ours = subprocess.run([exe, "bench", "visual-hull", os.path.join(work, "pipeline.yaml"), "--frame", str(FRAME), "--repeat", "5",
                       "--cube", str(CUBE)], check=True, capture_output=True, text=True).stdout
print(ours)

cams = yaml.safe_load(open(os.path.join(work, "calib/cameras.yaml")))["cameras"]
masks = [np.array(Image.open(f"{work}/cache/silhouette/{FRAME:06d}/{c['name']}.png")) >= 128 for c in cams]
g = ours.split("\n")[0].split()  # grid origin X Y Z voxel V dims A B C
origin = np.array([float(v) for v in g[2:5]]); voxel = float(g[6]); dims = [int(v) for v in g[8:11]]

def project(c, X):
    R = np.array(c["R"]); t = np.array(c["t"]); K = np.array(c["K"]); k1, k2, p1, p2, k3 = c["dist"]
    xc = X @ R.T + t
    x, y = xc[:, 0] / xc[:, 2], xc[:, 1] / xc[:, 2]
    r2 = x * x + y * y; rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x); yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2], xc[:, 2]

def carve_points(X, radius=None, dists=None):
    keep = np.ones(len(X), bool)
    for k, (c, m) in enumerate(zip(cams, masks)):
        u, v, z = project(c, X[keep])
        ui, vi = np.round(u).astype(int), np.round(v).astype(int)
        inside = (ui >= 0) & (vi >= 0) & (ui < m.shape[1]) & (vi < m.shape[0])
        ok = np.ones(len(ui), bool)
        if radius is None:
            ok[inside] = m[vi[inside], ui[inside]]
        else:
            r = c["K"][0][0] * radius / z
            ok[inside] = dists[k][vi[inside], ui[inside]] <= r[inside]
        idx = np.flatnonzero(keep); keep[idx[~ok]] = False
    return keep

def grid_centres(o, size, n):
    g = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, 3)
    return o + (g + 0.5) * size

t = time.perf_counter()
plain = carve_points(grid_centres(origin, voxel, dims))
t_plain = time.perf_counter() - t

t = time.perf_counter()
dists = [ndimage.distance_transform_edt(~m) for m in masks]
cell = 8 * voxel; n = [int(np.ceil(d / 8)) for d in dims]
X = grid_centres(origin, cell, n)
while True:
    X = X[carve_points(X, radius=cell * 0.87, dists=dists)]
    if cell <= voxel * 1.01:
        break
    cell /= 2
    off = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)]) * cell / 2
    X = (X[:, None, :] + off[None]).reshape(-1, 3)
t_c2f = time.perf_counter() - t
print(f"numpy plain carving: {t_plain*1e3:.0f} ms ({int(plain.sum())} voxels kept of {int(np.prod(dims))})")
print(f"numpy coarse-to-fine carving: {t_c2f*1e3:.0f} ms ({len(X)} voxels kept)")

from skimage import measure
ours_mc = subprocess.run([exe, "bench", "meshing", "--size", "256", "--repeat", "5"], check=True, capture_output=True, text=True).stdout
print(ours_mc.strip())
h = 1.0 / 256
g = np.mgrid[0:256, 0:256, 0:256].astype(np.float32) * h
field = np.sqrt(((g - 0.5) ** 2).sum(0)) - 0.35
best = 1e9
for _ in range(5):
    t = time.perf_counter(); v, f, _, _ = measure.marching_cubes(field, 0.0); best = min(best, time.perf_counter() - t)
print(f"skimage marching_cubes on a 256^3 sphere field: {best*1e3:.1f} ms, {len(v)} vertices, {len(f)} triangles")
