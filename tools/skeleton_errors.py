"""Joint errors of a skeleton.yaml against the true one (same bones): mean and worst, cm.

Reads the files hullpose writes (`- name:`, `head: [x, y, z]`, `tail: [x, y, z]` per bone);
standard library only.
Usage: python3 tools/skeleton_errors.py TRUTH.yaml MADE.yaml
"""
import math
import re
import sys


def joints(path):
    bones, name = {}, None
    with open(path) as f:
        for line in f:
            m = re.match(r"\s*- name:\s*(\S+)", line)
            if m:
                name = m.group(1)
                bones[name] = {}
                continue
            m = re.match(r"\s*(head|tail):\s*\[([^\]]*)\]", line)
            if m and name:
                bones[name][m.group(1)] = [float(v) for v in m.group(2).split(",")]
    return bones


truth, made = joints(sys.argv[1]), joints(sys.argv[2])
errors = sorted(
    (
        (100 * math.dist(made[n][end], truth[n][end]), f"{n} {end}")
        for n in truth
        for end in ("head", "tail")
    ),
    reverse=True,
)
mean = sum(e for e, _ in errors) / len(errors)
worst = ", ".join(f"{n} {e:.1f}" for e, n in errors[:3])
print(f"mean {mean:.1f} cm, worst {errors[0][0]:.1f} cm ({worst})")
