#!/usr/bin/env bash
# Sets up the person model once: MediaPipe's BlazePose pose detector and pose landmark model
# (Apache-2.0, shipped inside the mediapipe 0.10.14 wheel on PyPI) converted to ONNX, and
# ONNX Runtime's library (MIT, from the onnxruntime wheel on PyPI) that runs them.
#
#   bash tools/setup-person-model.sh [FOLDER]
#
# FOLDER defaults to $HULLPOSE_PERSON_MODEL, else ~/.local/share/hullpose/person-model (where
# hullpose looks). The conversion needs tensorflow-cpu and tf2onnx (about 600 MB), installed
# into a temporary virtual environment that is removed afterwards; the folder keeps about
# 50 MB. Nothing is downloaded when hullpose runs.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:-${HULLPOSE_PERSON_MODEL:-$HOME/.local/share/hullpose/person-model}}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
python3 -m venv "$work/venv"
pip=("$work/venv/bin/python" -m pip --disable-pip-version-check --quiet)
echo "person model: fetching mediapipe 0.10.14 (the models) and the converters from PyPI"
"${pip[@]}" download --no-deps -d "$work/wheels" mediapipe==0.10.14
"${pip[@]}" install tensorflow-cpu==2.21.0 tf2onnx==1.17.0 onnx==1.23.2 onnxruntime==1.31.1
mkdir -p "$out"
echo "person model: converting to ONNX"
TF_CPP_MIN_LOG_LEVEL=3 PYTHONWARNINGS=ignore "$work/venv/bin/python" "$here/person_model/convert.py" \
  "$(ls "$work"/wheels/mediapipe-0.10.14-*.whl)" "$out"
lib="$(ls "$work"/venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so.*)"
cp "$lib" "$out/libonnxruntime.so.part"
mv "$out/libonnxruntime.so.part" "$out/libonnxruntime.so"
cat > "$out/README.txt" <<'TXT'
hullpose's person model, written by tools/setup-person-model.sh.
person_detector.onnx, person_landmarks.onnx: MediaPipe BlazePose pose detection and pose
landmark (full) models from the mediapipe 0.10.14 wheel, Apache License 2.0, converted to
ONNX with tf2onnx 1.17.0. libonnxruntime.so: ONNX Runtime 1.31.1, MIT License.
TXT
echo "person model: ready in $out"
