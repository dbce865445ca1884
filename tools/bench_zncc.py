#!/usr/bin/env python3
"""ZNCC throughput of the reliability stage beside a vectorized numpy reference on the same
patches, in one run.

usage: tools/bench_zncc.py PIPELINE_YAML [FRAME]
The frame's refined surface must be in the cache (`pipeline run PIPELINE_YAML --frames F
--until graphcut`). `pipeline bench reliability` samples raw 7x7 patch pairs on the
surface, writes them to a temporary file and times the crate's ZNCC on them; this script
then times numpy's (one core, patches given, sampling excluded) on the same file.
Needs numpy."""
import os, subprocess, sys, tempfile, time
import numpy as np

root = os.path.abspath(os.path.dirname(__file__) + "/..")
exe = os.path.join(root, "target/release/pipeline")
subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=root, check=True)
yaml = sys.argv[1]
frame = sys.argv[2] if len(sys.argv) > 2 else "0"
with tempfile.TemporaryDirectory() as tmp:
    dump = os.path.join(tmp, "patches.f32")
    out = subprocess.run([exe, "bench", "reliability", yaml, "--frame", frame,
                          "--dump-patches", dump], check=True, capture_output=True, text=True).stdout
    print(out, end="")
    data = np.fromfile(dump, dtype="<f4").reshape(-1, 2, 49)
a, b = data[:, 0, :].astype(np.float32), data[:, 1, :].astype(np.float32)

def zncc(a, b):
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    num = np.einsum("ij,ij->i", a, b)
    den = np.sqrt(np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b))
    z = np.where(den > 1e-6, num / np.maximum(den, 1e-30), 0.0)
    return z

best = float("inf")
for _ in range(5):
    t = time.perf_counter()
    z = zncc(a, b)
    best = min(best, time.perf_counter() - t)
n = len(a)
print(f"numpy zncc of the same {n} pairs: {best*1e3:.1f} ms, {n/best/1e6:.2f} M pairs/s "
      f"(mean zncc {z.mean():.4f})")
rust_kernel = float(out.split("zncc of the dumped pairs: ")[1].split(" ms")[0])
stage = float(out.split(" camera pairs, ")[1].split(" M pairs/s")[0])
print(f"ratio, crate kernel / numpy: {best*1e3/rust_kernel:.1f}x; "
      f"stage with sampling and the normal search ({stage:.2f} M camera pairs/s) / numpy: {stage/(n/best/1e6):.1f}x")
