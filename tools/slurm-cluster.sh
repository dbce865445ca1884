#!/usr/bin/env bash
# slurm-cluster.sh - throw-away single-machine Slurm cluster for hullpose's CI (no systemd):
# .ci/run starts it to submit the bundled sample in shards (tools/slurm-check.sh).
#
# Installs Debian's slurm-wlm + munge (if missing), starts a private munged,
# slurmctld and one slurmd (node = `hostname -s`, real CPUs/memory from
# `slurmd -C`), with every file under $SLURM_LOCAL_DIR. The daemons listen on
# loopback only if the hostname resolves to a 127.x address (else on 0.0.0.0,
# with a warning; see "bind" below). Debian bookworm, Slurm 22.05, as root.
# Runs a smoke test (4-task job array + an afterok dependent job), optionally
# runs a user command against the live cluster, then stops the daemons it
# started (by PID, from an EXIT trap). Exits non-zero on any failure.
#
# Usage (as root):
#   slurm-cluster.sh                 # install, start, smoke test, stop
#   slurm-cluster.sh -- CMD ARGS...  # ... and also run CMD (with SLURM_CONF
#                                  # exported) before stopping; CMD's exit code
#                                  # becomes the script's exit code
# Environment knobs:
#   SLURM_LOCAL_DIR      work dir, wiped at start     [/tmp/hullpose-slurm]
#   SLURM_LOCAL_CTLD_PORT / SLURM_LOCAL_SLURMD_PORT   [6817 / 6818]
#   SLURM_LOCAL_TIMEOUT  seconds to wait for each readiness/job step [120]
#   SLURM_LOCAL_SKIP_SMOKE=1  skip the built-in smoke test
# Afterwards $SLURM_LOCAL_DIR keeps etc/ (slurm.conf, cgroup.conf), log/
# (munged, slurmctld, slurmd, jobcomp, apt) and job/ (smoke-test files).
#
# Nothing outside $SLURM_LOCAL_DIR is written except by apt-get (and a
# temporary /usr/sbin/policy-rc.d during install if none exists, so the
# packages' postinst does not start system-wide munge/slurm services).
set -euo pipefail

WORKDIR=${SLURM_LOCAL_DIR:-/tmp/hullpose-slurm}
CTLD_PORT=${SLURM_LOCAL_CTLD_PORT:-6817}
SLURMD_PORT=${SLURM_LOCAL_SLURMD_PORT:-6818}
TIMEOUT=${SLURM_LOCAL_TIMEOUT:-120}
CLUSTER=hullpose
PKGS=(slurm-wlm slurmctld slurmd slurm-client munge)

if [ "${1:-}" = "--" ]; then shift; fi
USER_CMD=("$@")

# fd 3/4 = the script's original stderr/stdout: log() writes to 3 so messages
# survive a caller's 2>/dev/null, and cleanup() restores 1/2 from them (an
# exit from inside wait_for's redirected condition would otherwise run the
# EXIT trap with stdout/stderr pointing at /dev/null)
exec 3>&2 4>&1
log() { printf '[slurm-cluster %s] %s\n' "$(date +%H:%M:%S)" "$*" >&3; }
now() { date +%s.%N; }
dt()  { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }

[ "$(id -u)" = 0 ] || { log "ERROR: must run as root"; exit 1; }
case "$WORKDIR" in /*) ;; *) log "ERROR: SLURM_LOCAL_DIR must be absolute"; exit 1;; esac
[ "$WORKDIR" != / ] || { log "ERROR: refusing SLURM_LOCAL_DIR=/"; exit 1; }

# ---------------------------------------------------------------- state ----
declare -A PID=()          # daemon name -> pid (only daemons *we* started)
CREATED_POLICY_RC=0
USER_RC=; USER_PID=
T0=$(now); T_INSTALL=; T_UP=; T_SMOKE=; T_USER=

dump_logs() {
  local f
  for f in "$WORKDIR"/log/*; do
    [ -f "$f" ] || continue
    echo "----- $f (last 25 lines) -----" >&2
    tail -n 25 "$f" >&2 || true
  done
}

# alive PID: exists and is not a zombie (orphans may wait a while for init
# to reap them, and kill -0 succeeds on zombies)
alive() {
  kill -0 "$1" 2>/dev/null || return 1
  [ "$(awk '{print $3}' "/proc/$1/stat" 2>/dev/null)" != Z ]
}

# Stop one pid: TERM, wait up to 20s, then KILL. Works for non-children too.
stop_pid() {
  local name=$1 pid=$2
  alive "$pid" || return 0
  log "stopping $name (pid $pid)"
  kill -TERM "$pid" 2>/dev/null || true
  for _ in $(seq 1 100); do
    alive "$pid" || break
    sleep 0.2
  done
  if alive "$pid"; then
    log "$name (pid $pid) ignored SIGTERM, sending SIGKILL"
    kill -KILL "$pid" 2>/dev/null || true
  fi
  wait "$pid" 2>/dev/null || true   # collect exit status if it was our child
}

cleanup() {
  local rc=$?
  set +e
  trap - EXIT INT TERM
  exec 1>&4 2>&3
  if [ -n "$USER_PID" ]; then stop_pid "user command" "$USER_PID"; fi
  # Cancel every job still in this private cluster (smoke test or user
  # command), and give slurmd a moment to kill the job processes, so no
  # slurmstepd / job process outlives the daemons.
  if [ -n "${PID[slurmctld]:-}" ] && alive "${PID[slurmctld]}"; then
    local left
    left=$(SLURM_CONF="$WORKDIR/etc/slurm.conf" squeue -h -o %F 2>/dev/null | sort -u | tr '\n' ' ')
    if [ -n "${left// /}" ]; then
      log "cancelling leftover jobs: $left"
      # shellcheck disable=SC2086
      SLURM_CONF="$WORKDIR/etc/slurm.conf" scancel $left 2>/dev/null
      for _ in $(seq 1 75); do
        [ -z "$(SLURM_CONF="$WORKDIR/etc/slurm.conf" squeue -h -o %A 2>/dev/null)" ] && break
        sleep 0.2
      done
    fi
  fi
  local n
  for n in slurmd slurmctld munged; do
    [ -n "${PID[$n]:-}" ] && stop_pid "$n" "${PID[$n]}"
  done
  rm -f "$WORKDIR"/run/*.pid.ours
  if [ "$CREATED_POLICY_RC" = 1 ]; then rm -f /usr/sbin/policy-rc.d; fi
  local T_END; T_END=$(now)
  {
    echo "timings (s):"
    [ -n "$T_INSTALL" ] && echo "  prep + package install : $(dt "$T0" "$T_INSTALL")"
    [ -n "$T_UP" ]      && echo "  configure+start->idle  : $(dt "$T_INSTALL" "$T_UP")"
    [ -n "$T_SMOKE" ]   && echo "  smoke test (array+dep) : $(dt "$T_UP" "$T_SMOKE")"
    [ -n "$T_USER" ]    && echo "  user command           : $(dt "${T_SMOKE:-$T_UP}" "$T_USER")"
    echo "  total incl. teardown   : $(dt "$T0" "$T_END")"
  } >&2
  if [ "$rc" = 0 ]; then log "OK"
  elif [ "$USER_RC" = "$rc" ]; then log "user command failed (exit $rc); cluster logs in $WORKDIR/log"
  elif [ "$rc" = 130 ] || [ "$rc" = 143 ]; then log "interrupted (exit $rc); logs in $WORKDIR/log"
  else log "FAILED (exit $rc); logs in $WORKDIR/log"; dump_logs; fi
  exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

die() { log "ERROR: $*"; exit 1; }

# Wait until "$@" succeeds; abort early if a daemon we started has died.
wait_for() {
  local what=$1; shift
  local deadline=$(( $(date +%s) + TIMEOUT )) n
  until "$@" >/dev/null 2>&1; do
    for n in "${!PID[@]}"; do
      alive "${PID[$n]}" || die "$n (pid ${PID[$n]}) exited while waiting for $what"
    done
    [ "$(date +%s)" -lt "$deadline" ] || die "timed out after ${TIMEOUT}s waiting for $what"
    sleep 0.2
  done
}

port_in_use() {   # ss if available, else try to connect with bash's /dev/tcp
  if command -v ss >/dev/null; then [ -n "$(ss -Hltn "sport = :$1" 2>/dev/null)" ]
  else (exec 9<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; fi
}

# --------------------------------------- 0. leftovers from a previous run ----
# Only processes whose pid we recorded in a previous run *and* whose command
# line still mentions our work dir are stopped (protects against pid reuse).
for n in slurmd slurmctld munged; do
  f="$WORKDIR/run/$n.pid.ours"
  [ -f "$f" ] || continue
  p=$(cat "$f")
  if [ -r "/proc/$p/cmdline" ] && tr '\0' ' ' < "/proc/$p/cmdline" | grep -qF "$WORKDIR"; then
    stop_pid "stale $n from a previous run" "$p"
  fi
done
rm -rf "$WORKDIR"
# munged insists: socket dir a+x and not group/world-writable; key dir private.
install -d -m 0755 "$WORKDIR" "$WORKDIR/etc" "$WORKDIR/run" "$WORKDIR/log" \
  "$WORKDIR/state" "$WORKDIR/spool" "$WORKDIR/job"
install -d -m 0700 "$WORKDIR/munge"

# ---------------------------------------------------------- 1. packages ----
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  log "installing: ${PKGS[*]} (missing: ${missing[*]})"
  if [ ! -e /usr/sbin/policy-rc.d ]; then
    printf '#!/bin/sh\nexit 101\n' > /usr/sbin/policy-rc.d
    chmod 0755 /usr/sbin/policy-rc.d
    CREATED_POLICY_RC=1
  fi
  apt-get update >"$WORKDIR/log/apt.log" 2>&1 || die "apt-get update failed (see $WORKDIR/log/apt.log)"
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${PKGS[@]}" \
    >>"$WORKDIR/log/apt.log" 2>&1 || die "apt-get install failed (see $WORKDIR/log/apt.log)"
  if [ "$CREATED_POLICY_RC" = 1 ]; then rm -f /usr/sbin/policy-rc.d; CREATED_POLICY_RC=0; fi
else
  log "packages already installed"
fi
for b in munged mungekey munge unmunge slurmctld slurmd sbatch squeue sinfo scontrol scancel; do
  command -v "$b" >/dev/null || die "missing executable: $b"
done
T_INSTALL=$(now)

# ------------------------------------------------------------- 2. munge ----
MUNGE_SOCK="$WORKDIR/run/munge.sock"
mungekey --create --keyfile="$WORKDIR/munge/munge.key" 2>>"$WORKDIR/log/munged.log" \
  || dd if=/dev/urandom of="$WORKDIR/munge/munge.key" bs=1 count=1024 status=none
chmod 0600 "$WORKDIR/munge/munge.key"
munged --foreground \
  --key-file="$WORKDIR/munge/munge.key" --socket="$MUNGE_SOCK" \
  --pid-file="$WORKDIR/run/munged.pid" --seed-file="$WORKDIR/munge/munged.seed" \
  --log-file="$WORKDIR/log/munged.log" >>"$WORKDIR/log/munged.log" 2>&1 </dev/null &
PID[munged]=$!; echo "${PID[munged]}" > "$WORKDIR/run/munged.pid.ours"
munge_ok() { munge -S "$MUNGE_SOCK" -n | unmunge -S "$MUNGE_SOCK"; }
wait_for "munged" munge_ok
log "munged up (pid ${PID[munged]})"

# ------------------------------------------------------- 3. slurm.conf ----
NODE=$(hostname -s)
[ -n "$NODE" ] || die "empty hostname -s"
HW=$(slurmd -C | head -n1)   # NodeName=x CPUs=.. Boards=.. ... RealMemory=..
case "$HW" in NodeName=*CPUs=*RealMemory=*) ;; *) die "unexpected 'slurmd -C' output: $HW";; esac
HW=${HW#NodeName=* }          # drop the NodeName=... token
for p in "$CTLD_PORT" "$SLURMD_PORT"; do
  port_in_use "$p" && die "TCP port $p already in use (set SLURM_LOCAL_CTLD_PORT/SLURM_LOCAL_SLURMD_PORT)"
done

# bind: Slurm 22.05 has no bind-address setting. CommunicationParameters=
# NoCtldInAddrAny,NoInAddrAny makes the daemons bind to whatever gethostname()
# resolves to (IPv4); without it they bind 0.0.0.0. So: if the hostname
# resolves to a loopback address, bind there (loopback-only); otherwise (no
# resolution, or a LAN address) fall back to 0.0.0.0 - with NoInAddrAny the
# daemons would die ("Unable to resolve", or be unreachable on 127.0.0.1).
HOST_IP=$(getent ahostsv4 "$(hostname)" 2>/dev/null | awk 'NR == 1 { print $1 }') || true
case "$HOST_IP" in
  127.*) ADDR=$HOST_IP; COMM_PARAMS="CommunicationParameters=NoCtldInAddrAny,NoInAddrAny"
         BIND_NOTE="loopback only ($ADDR)" ;;
  *)     ADDR=127.0.0.1; COMM_PARAMS="#CommunicationParameters=NoCtldInAddrAny,NoInAddrAny  (hostname does not resolve to loopback)"
         BIND_NOTE="ALL interfaces (0.0.0.0)"
         log "WARNING: hostname '$(hostname)' resolves to '${HOST_IP:-nothing}', not a loopback address;" \
             "slurmctld/slurmd will listen on 0.0.0.0:$CTLD_PORT/$SLURMD_PORT. Map the hostname to 127.0.0.1" \
             "in /etc/hosts to keep them loopback-only." ;;
esac

export SLURM_CONF="$WORKDIR/etc/slurm.conf"
cat > "$SLURM_CONF" <<EOF
# generated by slurm-cluster.sh
ClusterName=$CLUSTER
SlurmctldHost=$NODE($ADDR)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
# bind to the hostname's (loopback) address instead of 0.0.0.0, see script
$COMM_PARAMS
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$MUNGE_SOCK
StateSaveLocation=$WORKDIR/state
SlurmdSpoolDir=$WORKDIR/spool
SlurmctldPidFile=$WORKDIR/run/slurmctld.pid
SlurmdPidFile=$WORKDIR/run/slurmd.pid
SlurmctldLogFile=$WORKDIR/log/slurmctld.log
SlurmdLogFile=$WORKDIR/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
MailProg=/bin/true
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
# no slurmdbd, so no sacct; finished jobs are appended to this text file
# (scontrol show job also works for MinJobAge=300 s after a job ends)
JobCompType=jobcomp/filetxt
JobCompLoc=$WORKDIR/log/jobcomp.log
MpiDefault=none
SchedulerType=sched/backfill
# react to job submit/completion at once instead of every 3 s (the default)
SchedulerParameters=batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
NodeName=$NODE NodeAddr=$ADDR NodeHostname=$NODE $HW State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
# slurmd 22.05 always loads a cgroup plugin. Its autodetection fails without
# a (hybrid-with-name=systemd or pure v1) cgroup tree ("can't stat
# /sys/fs/cgroup/systemd/", "Hybrid mode is not supported"), and cgroup/v2
# wants systemd/dbus. With proctrack/linuxproc + task/none no cgroup is ever
# created, so pin cgroup/v1: it loads even when /sys/fs/cgroup is empty.
cat > "$WORKDIR/etc/cgroup.conf" <<EOF
CgroupPlugin=cgroup/v1
CgroupAutomount=no
ConstrainCores=no
ConstrainRAMSpace=no
ConstrainDevices=no
EOF

# --------------------------------------------------------- 4. daemons ----
slurmctld -D -f "$SLURM_CONF" >"$WORKDIR/log/slurmctld.out" 2>&1 </dev/null &
PID[slurmctld]=$!; echo "${PID[slurmctld]}" > "$WORKDIR/run/slurmctld.pid.ours"
ctld_up() { scontrol ping | grep -q 'is UP'; }
wait_for "slurmctld" ctld_up
log "slurmctld up (pid ${PID[slurmctld]}, port $CTLD_PORT, listening on $BIND_NOTE)"

slurmd -D -N "$NODE" -f "$SLURM_CONF" >"$WORKDIR/log/slurmd.out" 2>&1 </dev/null &
PID[slurmd]=$!; echo "${PID[slurmd]}" > "$WORKDIR/run/slurmd.pid.ours"
node_idle() { [ "$(sinfo -h -n "$NODE" -o %T)" = idle ]; }
wait_for "node $NODE idle" node_idle
T_UP=$(now)
log "slurmd up (pid ${PID[slurmd]}, port $SLURMD_PORT); cluster ready in $(dt "$T_INSTALL" "$T_UP")s"
sinfo >&2
if command -v ss >/dev/null; then ss -Hltnp 2>/dev/null | grep -E "slurm|munge" >&2 || true; fi

# ------------------------------------------------------- 5. smoke test ----
job_state() { scontrol -o show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2 | sort -u | tr '\n' ' '; }
# submit VAR sbatch-args...  -> job id in $VAR (no command substitution, so die exits the script)
submit() { local v=$1 id; shift; id=$(sbatch --parsable "$@") || die "sbatch $* failed"; id=${id%%;*}; printf -v "$v" %s "$id"; }

if [ "${SLURM_LOCAL_SKIP_SMOKE:-0}" != 1 ]; then
  cd "$WORKDIR/job"
  submit A --array=0-3 -o 'slurm-%A_%a.out' \
        --wrap 'echo task $SLURM_ARRAY_TASK_ID > out_$SLURM_ARRAY_TASK_ID.txt'
  submit B --dependency=afterok:"$A" -o 'slurm-%j.out' \
        --wrap 'cat out_0.txt out_1.txt out_2.txt out_3.txt > all.txt'
  log "submitted array job $A and dependent job $B"
  squeue >&2
  smoke_done() {
    local sa sb
    sa=$(job_state "$A"); sb=$(job_state "$B")
    case "$sa $sb" in *FAILED*|*CANCELLED*|*TIMEOUT*|*NODE_FAIL*|*OUT_OF_MEMORY*) die "job failed: array=[$sa] dep=[$sb]";; esac
    [ "$sa" = "COMPLETED " ] && [ "$sb" = "COMPLETED " ] && [ -s all.txt ]
  }
  wait_for "smoke-test jobs" smoke_done
  expected=$'task 0\ntask 1\ntask 2\ntask 3'
  [ "$(cat all.txt)" = "$expected" ] || die "all.txt has unexpected content: $(cat all.txt)"
  T_SMOKE=$(now)
  log "smoke test passed in $(dt "$T_UP" "$T_SMOKE")s: array $A (4 tasks) -> $B; all.txt:"
  sed 's/^/    /' all.txt >&2
  cd - >/dev/null
fi

# ---------------------------------------------------- 6. user command ----
if [ ${#USER_CMD[@]} -gt 0 ]; then
  log "running user command with SLURM_CONF=$SLURM_CONF: ${USER_CMD[*]}"
  # background + wait, so a SIGTERM/SIGINT to this script is handled at once
  "${USER_CMD[@]}" & USER_PID=$!
  set +e; wait "$USER_PID"; USER_RC=$?; set -e; USER_PID=
  T_USER=$(now)
  [ "$USER_RC" = 0 ] || exit "$USER_RC"
fi
exit 0   # cleanup trap stops slurmd, slurmctld, munged
