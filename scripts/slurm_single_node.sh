#!/usr/bin/env bash
# A single-node Slurm on this machine, from Debian's packages, for testing `semdynreg sweep
# --backend slurm` (crates/cli/tests/sweep_slurm.rs):
#
#   apt-get install -y slurmctld slurmd munge      # Debian 12: Slurm 22.05, MUNGE 0.5.15
#   scripts/slurm_single_node.sh start STATE_DIR   # then: export SLURM_CONF=STATE_DIR/slurm.conf
#   scripts/slurm_single_node.sh stop STATE_DIR
#
# Everything it writes stays in STATE_DIR (config, MUNGE key and socket, state, spool, logs,
# pid files), so it leaves the system's /etc/slurm and /etc/munge alone and several copies
# can live side by side with other ports (SLURM_PORT, default 6817; slurmd takes the next).
# It needs root: slurmd runs jobs as their submitter, and SlurmUser=root keeps the daemons
# from needing a `slurm` user with write access to STATE_DIR. What a container without
# systemd or cgroup delegation needs is in the config below: proctrack/linuxproc and
# task/none (no cgroup plugin at all), no accounting (so `sacct` is unavailable; poll
# `squeue`), and a node with CPUs=2 and a small RealMemory so that slurmd's own measurement
# never finds the node smaller than configured (it would drain it).
set -euo pipefail

usage() { echo "usage: $0 start|stop STATE_DIR" >&2; exit 2; }
[ $# -eq 2 ] || usage
action=$1
mkdir -p "$2"
state=$(realpath "$2")
conf=$state/slurm.conf
port=${SLURM_PORT:-6817}

stop() {
  local f
  for f in slurmd slurmctld munged; do
    if [ -f "$state/$f.pid" ]; then
      kill "$(cat "$state/$f.pid")" 2>/dev/null || true
      rm -f "$state/$f.pid"
    fi
  done
}

write_conf() {
  local host
  host=$(hostname -s)
  cat >"$conf" <<EOF
ClusterName=semdynreg-test
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$state/munge/munge.socket
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/spool
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=$state/slurmctld.log
SlurmdLogFile=$state/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
SlurmdTimeout=30
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 RealMemory=1000 State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

start_munge() {
  mkdir -p "$state/munge"
  chmod 700 "$state/munge"
  [ -f "$state/munge/munge.key" ] ||
    dd if=/dev/urandom of="$state/munge/munge.key" bs=1024 count=1 status=none
  chmod 600 "$state/munge/munge.key"
  # --force: MUNGE refuses to run as root, or with a key outside /etc/munge, without it.
  munged --force --socket="$state/munge/munge.socket" --key-file="$state/munge/munge.key" \
    --pid-file="$state/munged.pid" --log-file="$state/munge/munged.log" \
    --seed-file="$state/munge/munge.seed"
}

wait_idle() {
  local i
  for i in $(seq 1 60); do
    if SLURM_CONF=$conf sinfo -h -o '%T' 2>/dev/null | grep -qx idle; then
      return 0
    fi
    sleep 0.5
  done
  echo "the node did not become idle in 30 s; sinfo says:" >&2
  SLURM_CONF=$conf sinfo -N -l >&2 || true
  tail -n 20 "$state/slurmctld.log" "$state/slurmd.log" >&2 || true
  return 1
}

case $action in
  start)
    stop
    for cmd in munged slurmctld slurmd sinfo sbatch squeue; do
      command -v "$cmd" >/dev/null ||
        { echo "$cmd not found (apt-get install -y slurmctld slurmd munge)" >&2; exit 1; }
    done
    mkdir -p "$state/ctld" "$state/spool"
    write_conf
    start_munge
    # -c: a clean start (no jobs or node state from an earlier run of this folder).
    slurmctld -c -f "$conf"
    slurmd -f "$conf"
    wait_idle
    echo "export SLURM_CONF=$conf"
    ;;
  stop) stop ;;
  *) usage ;;
esac
