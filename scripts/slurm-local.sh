#!/usr/bin/env bash
# A real Slurm job array on this machine (docs/scale.md): starts munged, slurmctld and slurmd on
# localhost (Debian 12's slurm-wlm and munge, installed when missing; configuration, state and logs
# in a temporary folder), submits examples/slurm/render_array.sbatch as a 4-task array over the
# bundled trajectory three times (frame folders, .h5 shards, ROS 2 bags), waits, merges with 'vksonar merge',
# compares the merged output with a single-process run, and stops every daemon it started.
#
#   sudo bash scripts/slurm-local.sh [path/to/vksonar]      (default: build/vksonar)
#
# Needs root (packages, slurmd). Exit 0: all three merged outputs equal the single-process run's; 77: this
# machine cannot run it (not root, no apt, Slurm already running here); anything else: a failure.
# ctest runs it as the test slurm_local when VKSONAR_SLURM_TEST=1.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
vksonar=$(realpath "${1:-$repo/build/vksonar}")
trajectory="$repo/assets/trajectories/survey_line.csv"
tasks=4
say() { echo "slurm-local: $*"; }

[ -x "$vksonar" ] || { say "no vksonar at $vksonar (build it first)"; exit 1; }
[ "$(id -u)" -eq 0 ] || { say "skipped: needs root (it installs slurm-wlm and munge and runs slurmd)"; exit 77; }
for daemon in slurmctld slurmd munged; do
  if pgrep -x "$daemon" >/dev/null; then
    say "skipped: a $daemon is already running here; this script starts and stops its own"; exit 77
  fi
done

# ---- packages ------------------------------------------------------------------------------------
packages=(slurmctld slurmd slurm-client munge)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  command -v apt-get >/dev/null || { say "skipped: no apt-get to install ${missing[*]}"; exit 77; }
  say "installing ${missing[*]}"
  apt-get update -qq
  # policy-rc.d keeps the packages' own services from starting: this script runs its own daemons.
  policy=/usr/sbin/policy-rc.d
  had_policy=0; [ -e "$policy" ] && had_policy=1
  [ $had_policy -eq 1 ] || { printf '#!/bin/sh\nexit 101\n' > "$policy"; chmod +x "$policy"; }
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  [ $had_policy -eq 1 ] || rm -f "$policy"
fi

# ---- configuration in a temporary folder ---------------------------------------------------------
work=$(mktemp -d /tmp/vksonar-slurm.XXXXXX)
chmod 755 "$work"
mkdir -p "$work/state" "$work/spool" "$work/log" "$work/munge" "$work/out"
chmod 700 "$work/munge"
pids_started=()
stop_daemons() {
  local pidfile pid
  for pidfile in "$work/slurmd.pid" "$work/slurmctld.pid" "$work/munge/munged.pid"; do
    [ -s "$pidfile" ] || continue
    pid=$(cat "$pidfile")
    kill "$pid" 2>/dev/null || true
    for _ in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null || true
  done
}
finish() {
  local rc=$?
  stop_daemons
  if [ $rc -ne 0 ] && [ $rc -ne 77 ]; then
    say "failed (exit $rc); daemon logs:"
    tail -n 20 "$work"/log/*.log 2>/dev/null || true
  fi
  rm -rf "$work"
  for daemon in slurmctld slurmd munged; do
    pgrep -x "$daemon" >/dev/null && say "warning: a $daemon is still running"
  done
  exit $rc
}
trap finish EXIT
trap 'exit 130' INT TERM

dd if=/dev/urandom of="$work/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$work/munge/munge.key"
socket="$work/munge/munge.socket"
cpus=$(nproc)
memory=$(awk '/MemTotal/ {print int($2 / 1024 / 2)}' /proc/meminfo)
port=$((20000 + RANDOM % 20000))
cat > "$work/slurm.conf" <<CONF
ClusterName=vksonar-local
SlurmctldHost=localhost
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/log/slurmctld.log
SlurmdLogFile=$work/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MinJobAge=3600
MpiDefault=none
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=local Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$work/slurm.conf"

# ---- daemons -------------------------------------------------------------------------------------
munged --force --key-file="$work/munge/munge.key" --socket="$socket" --pid-file="$work/munge/munged.pid" \
  --log-file="$work/log/munged.log" --seed-file="$work/munge/munged.seed"
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF" -N localhost
say "munged, slurmctld and slurmd started (config $SLURM_CONF, $cpus CPUs, ports $port-$((port + 1)))"
for _ in $(seq 1 60); do
  state=$(sinfo -h -N -o '%T' 2>/dev/null | head -n 1 || true)
  [ "$state" = "idle" ] && break
  sleep 1
done
[ "$state" = "idle" ] || { say "the node did not come up (state '${state:-none}')"; exit 1; }
sinfo

# ---- the array, three times: frame folders, .h5 shards, ROS 2 bags -----------------------------
submit() { # OUT [SAVE] -> job id
  sbatch --parsable --array=0-$((tasks - 1)) --cpus-per-task=1 --mem=512M --chdir="$work/out" \
    --output="$work/out/task-%A_%a.log" --export="ALL,VKSONAR=$vksonar" \
    "$repo/examples/slurm/render_array.sbatch" "$trajectory" "$1" --save "${2:-polar,polar_u16}"
}
start=$(date +%s%N)
folders_job=$(submit "$work/out/run")
h5_job=$(submit "$work/out/run.h5")
bag_job=$(submit "$work/out/run.mcap" polar)
say "submitted array jobs $folders_job (frame folders), $h5_job (.h5) and $bag_job (ROS 2 bags), $tasks tasks each"
deadline=$((SECONDS + 600))
while [ -n "$(squeue -h -j "$folders_job,$h5_job,$bag_job" 2>/dev/null)" ]; do
  [ $SECONDS -lt $deadline ] || { say "the arrays did not finish in 600 s"; squeue; exit 1; }
  sleep 1
done
array_ms=$((($(date +%s%N) - start) / 1000000))
failed=0
for job in "$folders_job" "$h5_job" "$bag_job"; do
  for ((i = 0; i < tasks; i++)); do
    line=$(scontrol -o show job "${job}_$i" 2>/dev/null | grep -o 'JobState=[A-Z_]* .*ExitCode=[0-9:]*' |
      sed 's/ .*ExitCode=/ ExitCode=/' || true)
    echo "  task ${job}_$i: ${line:-no record}"
    case "$line" in JobState=COMPLETED*) ;; *) failed=1 ;; esac
  done
done
for log in "$work"/out/task-*.log; do
  grep -h "frames rendered" "$log" | sed "s|^|  $(basename "$log"): |"
done
[ $failed -eq 0 ] || { say "a task did not complete:"; tail -n 5 "$work"/out/task-*.log; exit 1; }
say "the three arrays ($tasks tasks each, $cpus CPUs) finished in $((array_ms / 1000)).$((array_ms % 1000 / 100)) s (submit to last task done)"

# ---- merge and compare with one process -----------------------------------------------------------
"$vksonar" merge "$work/merged" "$work"/out/run/shard_*
"$vksonar" merge "$work/merged.h5" "$work"/out/run.shard_*.h5
mkdir -p "$work/merged_bag" "$work/single_bag"
"$vksonar" merge "$work/merged_bag/run.mcap" "$work"/out/run.shard_*.mcap
start=$(date +%s%N)
"$vksonar" render --trajectory "$trajectory" --out "$work/single" --save polar,polar_u16 2>/dev/null
"$vksonar" render --trajectory "$trajectory" --out "$work/single.h5" --save polar,polar_u16 2>/dev/null
"$vksonar" render --trajectory "$trajectory" --out "$work/single_bag/run.mcap" --save polar 2>/dev/null
single_ms=$((($(date +%s%N) - start) / 1000000))
say "the same three runs in one process each: $((single_ms / 1000)).$((single_ms % 1000 / 100)) s"

frames=0
differ=0
for frame in "$work"/single/frame_*; do
  name=$(basename "$frame")
  frames=$((frames + 1))
  for file in polar.npy polar_u16.npy; do
    cmp -s "$frame/$file" "$work/merged/$name/$file" || { echo "  differs: $name/$file"; differ=1; }
  done
done
extra=$(comm -13 <(ls "$work/single") <(ls "$work/merged" | grep '^frame_') | wc -l)
[ "$extra" -eq 0 ] || { say "the merged folder has $extra frames the single run has not"; differ=1; }
say "frame folders: $frames frames, polar.npy and polar_u16.npy byte-identical: $([ $differ -eq 0 ] && echo yes || echo NO)"

python=""
for candidate in /usr/bin/python3 python3; do
  if "$candidate" -c "import h5py, numpy" 2>/dev/null; then python=$candidate; break; fi
done
if [ -n "$python" ]; then
  "$python" - "$work/single.h5" "$work/merged.h5" <<'PY' || differ=1
import sys, h5py
with h5py.File(sys.argv[1], "r") as a, h5py.File(sys.argv[2], "r") as b:
    same = set(a) == set(b) and all(a[k][:].tobytes() == b[k][:].tobytes() and a[k].dtype == b[k].dtype for k in a)
    print(f"slurm-local: .h5: {a['polar'].shape[0]} frames, datasets {', '.join(sorted(a))} byte-identical: "
          f"{'yes' if same else 'NO'}; merged complete={b.attrs['complete']} merged_shards={b.attrs['merged_shards']}")
    sys.exit(0 if same else 1)
PY
elif command -v h5diff >/dev/null; then
  h5diff "$work/single.h5" "$work/merged.h5" && say ".h5: h5diff finds no difference" || differ=1
else
  say ".h5: not compared (no python3 with h5py, no h5diff)"
fi
if cmp -s "$work/single_bag/run.mcap" "$work/merged_bag/run.mcap"; then
  say "ROS 2 bag: $(stat -c %s "$work/single_bag/run.mcap") bytes, merged byte-identical: yes"
else
  say "ROS 2 bag: the merged bag differs from the single-process one"
  differ=1
fi
[ $differ -eq 0 ] || { say "FAILED: the merged output differs from the single-process run"; exit 1; }
say "OK: the $tasks-task Slurm arrays merged equal the single-process run"
