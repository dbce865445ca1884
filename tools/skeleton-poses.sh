#!/usr/bin/env bash
# The automatic skeleton on every held pose of `pipeline synth --pose`, bodies 1-4, upright
# and in a world tilted by 25 degrees (no up given), against the generator's true skeleton.
# Prints one line per capture: mean and worst joint error (cm) and the worst joints, or the
# refusal. Usage: tools/skeleton-poses.sh PIPELINE_BINARY WORK_DIR [CAMERAS]
set -euo pipefail
bin=$1
work=$2
cameras=${3:-8}
here=$(cd "$(dirname "$0")" && pwd)
for pose in a-pose t-pose arms-down arms-out-bent arms-overhead one-arm-forward hands-on-hips; do
  for body in 1 2 3 4; do
    for tilt in 0 25; do
      d="$work/$pose-$body-$tilt-$cameras"
      if [ ! -f "$d/truth.yaml" ]; then
        rm -rf "$d"
        "$bin" synth --scene humanoid --pose "$pose" --cameras "$cameras" --width 640 \
          --height 480 --body "$body" --seed "$body" --world-tilt "$tilt" --out "$d" >/dev/null
        mv "$d/data/humanoid/skeleton.yaml" "$d/truth.yaml"
      fi
      rm -f "$d/data/humanoid/skeleton.yaml"
      if "$bin" skeleton "$d/pipeline.yaml" >"$d/skeleton.log" 2>&1; then
        echo "$pose body $body tilt $tilt: $(python3 "$here/skeleton_errors.py" "$d/truth.yaml" "$d/data/humanoid/skeleton.yaml")"
      else
        echo "$pose body $body tilt $tilt: refused: $(grep -o 'frame 0: .*' "$d/skeleton.log" | cut -c10-120)"
      fi
    done
  done
done
