#!/usr/bin/env bash
# A one-node Slurm cluster on this machine (Debian's slurm-wlm and munge), for trying a sharded
# build's batch scripts for real (gimlod build ... --emit-slurm DIR; docs/distributed.md):
#   scripts/slurm/local_cluster.sh start DIR   starts munged (unless running), slurmctld and slurmd,
#                                              their configuration, state and logs in DIR, on free
#                                              ports; prints the `export SLURM_CONF=...` to use
#   scripts/slurm/local_cluster.sh stop DIR    stops the daemons started in DIR
# Needs root (slurmd starts the jobs as their users). Nothing outside DIR is written, but munge's
# key and socket, which the package installs.
set -euo pipefail
cmd=${1:-}
dir=${2:-}
if [ -z "$cmd" ] || [ -z "$dir" ]; then
  echo "usage: $0 start|stop DIR" >&2
  exit 2
fi
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
conf="$dir/slurm.conf"

stop() {
  for d in slurmd slurmctld; do
    if [ -f "$dir/$d.pid" ]; then
      kill "$(cat "$dir/$d.pid")" 2>/dev/null || true
      rm -f "$dir/$d.pid"
    fi
  done
}

if [ "$cmd" = stop ]; then
  stop
  exit 0
fi
[ "$cmd" = start ] || { echo "$0: unknown command $cmd" >&2; exit 2; }
if [ "$(id -u)" -ne 0 ]; then
  echo "$0: a local Slurm cluster needs root (slurmd)" >&2
  exit 1
fi
for tool in slurmctld slurmd munged sbatch sinfo; do
  command -v "$tool" >/dev/null || { echo "$0: $tool is missing (apt-get install slurm-wlm munge)" >&2; exit 1; }
done
if ! pgrep -x munged >/dev/null; then
  mkdir -p /run/munge && chown munge:munge /run/munge 2>/dev/null || true
  [ -f /etc/munge/munge.key ] || { echo "$0: /etc/munge/munge.key is missing" >&2; exit 1; }
  su -s /bin/sh munge -c /usr/sbin/munged 2>/dev/null || /usr/sbin/munged --force
fi
host=$(hostname -s)
cpus=$(nproc)
mem=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 * 3 / 4 ))
# Ports of our own, so that a cluster already on this machine is left alone.
port=$(( 20000 + ($$ % 20000) * 2 ))
mkdir -p "$dir/state" "$dir/spool"
cat > "$conf" <<CONF
ClusterName=gimlod-local
SlurmctldHost=$host
SlurmUser=root
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$conf
slurmctld -f "$conf"
slurmd -f "$conf"
for _ in $(seq 60); do
  if sinfo -h -o %t 2>/dev/null | grep -q idle; then
    echo "export SLURM_CONF=$conf"
    exit 0
  fi
  sleep 0.5
done
echo "$0: the node did not come up; see $dir/slurmctld.log and $dir/slurmd.log" >&2
stop
exit 1
