#!/usr/bin/env python3
"""Checks an exported TRC or C3D against the pipeline's joints.csv with independent readers.

A TRC is read by OpenSim itself (PyPI `opensim`: TimeSeriesTableVec3), a C3D by `ezc3d`.
Each marker's positions are scaled to metres by the file's declared units, turned back from
+Y-up export axes to world axes (--up, as pipeline.yaml's export.up_axis) and compared with
joints.csv: each bone's head is the marker of its name, its tail the marker `<bone>_tail`
or (where a child starts there) the marker of that child.

Usage: python3 tools/check_markers.py FILE.trc|FILE.c3d joints.csv [--up +z] [--floor F] [--tolerance 0.0001]
Prints the frame and marker counts and the largest distance (metres); exits 1 above the
tolerance or when a joint has no marker.
"""
import argparse
import csv
import sys

from export_axes import TO_Y_UP
SCALE = {"mm": 0.001, "cm": 0.01, "m": 1.0}


def read_trc(path):
    import opensim

    table = opensim.TimeSeriesTableVec3(path)
    units = table.getTableMetaDataAsString("Units")
    names = list(table.getColumnLabels())
    frames = []
    for i in range(table.getNumRows()):
        row = table.getRowAtIndex(i)
        frames.append({n: [row[k][0], row[k][1], row[k][2]] for k, n in enumerate(names)})
    return units, frames


def read_c3d(path):
    import ezc3d

    c = ezc3d.c3d(path)
    units = c["parameters"]["POINT"]["UNITS"]["value"][0]
    names = [n.strip() for n in c["parameters"]["POINT"]["LABELS"]["value"]]
    points = c["data"]["points"]  # 4 x markers x frames
    frames = []
    for f in range(points.shape[2]):
        frames.append({n: [float(points[a, k, f]) for a in range(3)] for k, n in enumerate(names)})
    return units, frames


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("joints")
    ap.add_argument("--up", default="+z")
    ap.add_argument("--floor", type=float, default=0.0, help="the floor's height along up, metres (export/world.yaml)")
    ap.add_argument("--tolerance", type=float, default=0.0001)
    a = ap.parse_args()
    units, frames = (read_c3d if a.file.lower().endswith(".c3d") else read_trc)(a.file)
    scale = SCALE[units.strip()]
    c = TO_Y_UP[a.up]

    def world(p):
        # x_world = C^T (x_export + floor Y)
        q = [p[0] * scale, p[1] * scale + a.floor, p[2] * scale]
        return [sum(c[r][i] * q[r] for r in range(3)) for i in range(3)]

    rows = list(csv.DictReader(open(a.joints)))
    order = sorted({int(r["frame"]) for r in rows})
    if len(order) != len(frames):
        print(f"{len(frames)} frames in the file, {len(order)} in joints.csv")
        return 1
    worst = 0.0
    for r in rows:
        marks = {n: world(p) for n, p in frames[order.index(int(r["frame"]))].items()}
        head = [float(r[f"head_{x}"]) for x in "xyz"]
        tail = [float(r[f"tail_{x}"]) for x in "xyz"]
        if r["bone"] not in marks:
            print(f"no marker for bone {r['bone']}")
            return 1
        worst = max(worst, max(abs(u - v) for u, v in zip(marks[r["bone"]], head)))
        name = f"{r['bone']}_tail"
        # A tail without a marker of its own is a child's head: the nearest marker.
        if name in marks:
            d = max(abs(u - v) for u, v in zip(marks[name], tail))
        else:
            d = min(max(abs(u - v) for u, v in zip(p, tail)) for p in marks.values())
        worst = max(worst, d)
    markers = len(frames[0]) if frames else 0
    print(f"frames {len(frames)} markers {markers} units {units.strip()} largest distance {worst:.3e} m")
    return 0 if worst <= a.tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
