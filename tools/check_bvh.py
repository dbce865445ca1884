#!/usr/bin/env python3
"""Checks an exported BVH against the pipeline's joints.csv with an independent reader.

bvhio (PyPI) parses the file; its own forward kinematics (readAsHierarchy, PositionWorld)
gives every joint's position per frame, and each End Site is placed from bvhio's parsed
per-frame rotations (parent rotation times channel rotation, the BVH rule). The positions are
turned back from +Y-up export axes to world axes (--up, as pipeline.yaml's export.up_axis)
and compared with joints.csv: each bone's head is the joint of its name, its tail the End
Site of a leaf, the `<bone>_tail` joint, or the child joint at its tail.

Usage: python3 tools/check_bvh.py FILE.bvh joints.csv [--up +z] [--floor F] [--tolerance 0.001]
Prints the largest distance (metres) and exits 1 if it exceeds the tolerance.
"""
import argparse
import csv
import sys

import bvhio
import glm

from export_axes import TO_Y_UP


def to_world(p, up, floor=0.0):
    """C^T (p + floor Y): export axes (floor at Y = 0) back to world axes."""
    c = TO_Y_UP[up]
    p = [p[0], p[1] + floor, p[2]]
    return [sum(c[r][k] * p[r] for r in range(3)) for k in range(3)]


def end_sites(bvh_root, frame):
    """World positions of the End Sites of leaf joints at `frame` (export axes)."""
    out = {}

    def walk(j, parent_pos, parent_rot):
        key = j.Keyframes[frame]
        if parent_pos is None:
            pos = glm.vec3(key.Position)
            rot = glm.quat(key.Rotation)
        else:
            pos = parent_pos + parent_rot * glm.vec3(j.Offset)
            rot = parent_rot * glm.quat(key.Rotation)
        if not j.Children:
            out[j.Name] = (pos + rot * glm.vec3(j.EndSite), pos)
        for c in j.Children:
            walk(c, pos, rot)

    walk(bvh_root, None, None)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("bvh")
    ap.add_argument("joints")
    ap.add_argument("--up", default="+y", choices=sorted(TO_Y_UP))
    ap.add_argument("--floor", type=float, default=0.0, help="the floor's height along up, metres (export/world.yaml)")
    ap.add_argument("--tolerance", type=float, default=0.001)
    a = ap.parse_args()

    rows = {}
    with open(a.joints) as f:
        for r in csv.DictReader(f):
            head = [float(r[k]) for k in ("head_x", "head_y", "head_z")]
            tail = [float(r[k]) for k in ("tail_x", "tail_y", "tail_z")]
            rows.setdefault(int(r["frame"]), []).append((r["bone"], head, tail))
    frames = sorted(rows)

    bvh = bvhio.readAsBvh(a.bvh)
    root = bvhio.readAsHierarchy(a.bvh)
    if bvh.FrameCount != len(frames):
        print(f"BVH has {bvh.FrameCount} frames, joints.csv {len(frames)}")
        return 1
    worst, where = 0.0, ""
    for k, frame in enumerate(frames):
        root.loadPose(k)
        joints = {j.Name: j for j, _, _ in root.layout()}
        sites = end_sites(bvh.Root, k)
        for bone, head, tail in rows[frame]:
            if bone not in joints:
                print(f"joint {bone} is not in the BVH")
                return 1
            j = joints[bone]
            candidates = []
            if bone in sites:
                candidates = [sites[bone][0]]
                # Our FK of the joint itself must agree with bvhio's.
                gap = glm.length(sites[bone][1] - j.PositionWorld)
                if gap > 1e-5:
                    print(f"frame {frame} {bone}: end-site FK disagrees with bvhio by {gap}")
                    return 1
            elif bone + "_tail" in joints:
                candidates = [joints[bone + "_tail"].PositionWorld]
            else:
                candidates = [c.PositionWorld for c in j.Children]
            h = to_world(list(j.PositionWorld), a.up, a.floor)
            dh = sum((x - y) ** 2 for x, y in zip(h, head)) ** 0.5
            dt = min(
                sum((x - y) ** 2 for x, y in zip(to_world(list(c), a.up, a.floor), tail)) ** 0.5
                for c in candidates
            )
            for d, what in ((dh, "head"), (dt, "tail")):
                if d > worst:
                    worst, where = d, f"frame {frame} {bone} {what}"
    print(f"frames {len(frames)} bones {len(rows[frames[0]])} max_distance_m {worst:.3e} at {where}")
    return 0 if worst <= a.tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
