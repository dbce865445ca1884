#!/usr/bin/env python3
"""Surface error of cached reconstructions against the ground-truth meshes, by area.

For each frame and stage: the 90th percentile of vertex distances (as `pipeline evaluate`
reports accuracy90), the same percentile weighted by triangle area, and the area of the
surface farther than --far metres from the truth (m^2). Needs trimesh and scipy.

    python3 tools/error_area.py RUN_DIR --frames 8 9 10 [--far 0.02]

RUN_DIR holds pipeline.yaml's cache/ and data/<sequence>/ground_truth/meshes/ (a
`pipeline synth` folder).
"""
import argparse
import glob
import os

import numpy as np
import trimesh
from scipy.spatial import cKDTree

ap = argparse.ArgumentParser()
ap.add_argument("run_dir")
ap.add_argument("--frames", type=int, nargs="+", required=True)
ap.add_argument("--far", type=float, default=0.02)
ap.add_argument("--samples", type=int, default=400000)
a = ap.parse_args()
truth_dir = glob.glob(os.path.join(a.run_dir, "data/*/ground_truth/meshes"))[0]
print("frame,stage,vertices,vertex_p90_m,area_p90_m,area_far_m2,area_m2")
for f in a.frames:
    truth = trimesh.load(os.path.join(truth_dir, f"{f:06d}.ply"))
    np.random.seed(f)
    tree = cKDTree(truth.sample(a.samples))
    for stage in ["visual_hull", "graphcut"]:
        mesh = trimesh.load(os.path.join(a.run_dir, "cache", stage, f"{f:06d}.ply"))
        d_vertex, _ = tree.query(mesh.vertices)
        area = mesh.area_faces
        d_face, _ = tree.query(mesh.triangles_center)
        order = np.argsort(d_face)
        cumulative = np.cumsum(area[order]) / area.sum()
        area_p90 = d_face[order][np.searchsorted(cumulative, 0.9)]
        far = area[d_face > a.far].sum()
        print(f"{f},{stage},{len(mesh.vertices)},{np.percentile(d_vertex, 90):.4f},"
              f"{area_p90:.4f},{far:.4f},{area.sum():.4f}")
