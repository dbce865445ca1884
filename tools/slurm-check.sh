#!/usr/bin/env bash
# slurm-check.sh PIPELINE - runs inside a live Slurm cluster (tools/slurm-cluster.sh -- ...):
#  1. the bundled sample run locally, plainly;
#  2. the same submitted with `pipeline slurm --shards 3 --submit`: its joints.csv must be
#     identical to the local run's;
#  3. again in a fresh folder, with array task 1 cancelled (scancel) midway, then resubmitted:
#     the run completes, the resubmitted task reuses the frames its cancelled run finished,
#     and joints.csv is again identical.
# Exits non-zero on any failure. Needs SLURM_CONF (set by slurm-cluster.sh).
set -euo pipefail
PIPELINE=$(realpath "$1")
REPO=$(cd "$(dirname "$0")/.." && pwd)
WORK=$(mktemp -d /tmp/hullpose-slurm-check.XXXXXX)
TIMEOUT=${SLURM_CHECK_TIMEOUT:-900}
log() { printf '[slurm-check %s] %s\n' "$(date +%H:%M:%S)" "$*"; }
die() { log "FAILED: $*"; exit 1; }

# A copy of the sample with settings that keep the check short (the same in every copy).
make_copy() {
  local d=$WORK/$1
  mkdir -p "$d"
  cp -r "$REPO/calib" "$REPO/data" "$d/"
  sed 's/^frames: all/frames: 0..5/' "$REPO/pipeline.yaml" > "$d/pipeline.yaml"
  printf 'fit:\n  stop:\n    max_rounds: 40\n  restart:\n    enabled: false\n' >> "$d/pipeline.yaml"
  sed -i 's/^\(  frame_rate: .*\)$/\1\n  formats: [bvh]/' "$d/pipeline.yaml"
  grep -q 'formats: \[bvh\]' "$d/pipeline.yaml" || die "could not set export.formats"
  echo "$d"
}

job_state() { scontrol -o show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2 | sort -u | tr '\n' ' '; }

# Waits until no job of the given ids is pending or running.
wait_jobs() {
  local deadline=$(( $(date +%s) + TIMEOUT ))
  while [ -n "$(squeue -h -j "$1" -o %A 2>/dev/null)" ]; do
    [ "$(date +%s)" -lt "$deadline" ] || die "jobs $1 still queued after ${TIMEOUT}s"
    sleep 0.5
  done
}

submit() {  # DIR -> "arrayid finalid"
  local out
  out=$(cd "$1" && "$PIPELINE" slurm pipeline.yaml --shards 3 --cpus 1 --submit) || die "submit: $out"
  echo "$out" >&2
  echo "$out" | sed -n 's/^submitted array job \([0-9]*\) .* and job \([0-9]*\) .*/\1 \2/p'
}

log "1. local run"
LOCAL=$(make_copy local)
(cd "$LOCAL" && "$PIPELINE" run pipeline.yaml) > "$WORK/local.log" 2>&1 || { cat "$WORK/local.log"; die "local run"; }
[ -s "$LOCAL/output/joints.csv" ] || die "no local joints.csv"

log "2. sharded run: 3 array tasks, then the fit"
SHARDED=$(make_copy sharded)
read -r A B <<<"$(submit "$SHARDED")"
[ -n "$A" ] && [ -n "$B" ] || die "no job ids"
wait_jobs "$A,$B"
state=$(job_state "$B")
[ "$state" = "COMPLETED " ] || { cat "$SHARDED"/cache/slurm/*.out; die "final job $B ended $state"; }
cmp "$LOCAL/output/joints.csv" "$SHARDED/output/joints.csv" || die "sharded joints.csv differs from the local run's"
log "sharded joints.csv is identical to the local run's"
# The scripts' #SBATCH --output values are double-quoted: sbatch must have taken them as
# the paths they quote (a log per array task and one for the final job, in cache/slurm).
logs=$(ls "$SHARDED"/cache/slurm/frames-*.out "$SHARDED"/cache/slurm/fit-*.out 2>/dev/null | wc -l)
[ "$logs" -eq 4 ] || die "expected 4 job logs in $SHARDED/cache/slurm, found $logs"

log "3. cancel array task 1 midway, then resubmit"
CANCEL=$(make_copy cancel)
read -r A B <<<"$(submit "$CANCEL")"
# Task 1 holds frames 2..3: cancel it once its first hull is cached (frame 2's silhouettes
# and hull done, its reliability not yet; the per-frame stages run frame by frame).
deadline=$(( $(date +%s) + TIMEOUT ))
until [ -e "$CANCEL/cache/visual_hull/000002.manifest.yaml" ]; do
  [ "$(date +%s)" -lt "$deadline" ] || die "task 1 never started"
  sleep 0.05
done
scancel "${A}_1"
log "cancelled ${A}_1"
wait_jobs "$A,$B"
[ ! -e "$CANCEL/output/joints.csv" ] || die "the fit ran although a shard was cancelled"
[ ! -e "$CANCEL/cache/reliability/000003.manifest.yaml" ] || die "task 1 finished before the cancel; nothing to resume"
read -r A2 B2 <<<"$(submit "$CANCEL")"
wait_jobs "$A2,$B2"
state=$(job_state "$B2")
[ "$state" = "COMPLETED " ] || { cat "$CANCEL"/cache/slurm/*.out; die "resubmitted final job $B2 ended $state"; }
task1="$CANCEL/cache/slurm/frames-${A2}_1.out"
cat "$task1"
grep -Eq 'silhouette: [01] computed, [12] reused' "$task1" || die "the resubmitted task 1 recomputed frame 2's silhouettes"
grep -Eq 'visual_hull: [01] computed, [12] reused' "$task1" || die "the resubmitted task 1 recomputed frame 2's hull"
grep -Eq 'reliability: 2 computed, 0 reused' "$task1" || die "the resubmitted task 1 did not compute the rest"
for k in 0 2; do
  grep -Eq 'reliability: 0 computed, 2 reused' "$CANCEL/cache/slurm/frames-${A2}_$k.out" \
    || die "resubmitted task $k recomputed frames"
done
cmp "$LOCAL/output/joints.csv" "$CANCEL/output/joints.csv" || die "resumed joints.csv differs from the local run's"
log "OK: resumed run reused the finished frames; joints.csv identical to the local run's"
rm -rf "$WORK"
