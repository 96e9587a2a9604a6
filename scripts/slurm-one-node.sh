#!/usr/bin/env bash
# A real one-node Slurm cluster on this machine, for the batch's Slurm test (.ci/run) and for
# trying deploy/slurm/skydome-array.sbatch by hand. Needs root and Debian's slurm-wlm and munge
# (apt-get install slurm-wlm munge); no systemd.
#
#   scripts/slurm-one-node.sh start   # munged, slurmctld, slurmd; waits until the node is idle
#   scripts/slurm-one-node.sh stop    # stops the three daemons it started (by their pids)
#   scripts/slurm-one-node.sh status
#
# State (pid files, logs, spool) lives in $SLURM_ONE_NODE_DIR (default /tmp/skydome-slurm).
set -euo pipefail
DIR="${SLURM_ONE_NODE_DIR:-/tmp/skydome-slurm}"
HOST="$(hostname -s)"

die() { echo "slurm-one-node: $*" >&2; exit 1; }

start() {
  [ "$(id -u)" = 0 ] || die "run as root (munged and slurmd need it)"
  for c in munged mungekey slurmctld slurmd sinfo; do
    command -v "$c" >/dev/null || die "$c not found; apt-get install slurm-wlm munge"
  done
  if [ -f "$DIR/slurmd.pid" ] && kill -0 "$(cat "$DIR/slurmd.pid")" 2>/dev/null; then
    echo "slurm-one-node: already running"; return 0
  fi
  mkdir -p "$DIR/state" "$DIR/spool" /etc/munge /run/munge /var/lib/munge /var/log/munge /etc/slurm
  if [ ! -s /etc/munge/munge.key ]; then
    mungekey -c -f -k /etc/munge/munge.key
  fi
  chown -R munge: /etc/munge /run/munge /var/lib/munge /var/log/munge
  chmod 0400 /etc/munge/munge.key
  chmod 0700 /etc/munge /var/lib/munge /var/log/munge
  chmod 0755 /run/munge
  if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    # munged refuses to run as root; it forks into the background and writes its pid file.
    su -s /bin/sh munge -c "munged --pid-file=/run/munge/munged.pid" \
      || die "munged did not start (see /var/log/munge/munged.log)"
    cp /run/munge/munged.pid "$DIR/munged.pid"
  fi
  munge -n | unmunge | grep -q Success || die "munge does not work"
  cat > /etc/slurm/slurm.conf <<CONF
ClusterName=skydome
SlurmctldHost=$HOST
SlurmUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/slurmctld.log
SlurmdLogFile=$DIR/slurmd.log
ReturnToService=2
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
NodeName=$HOST CPUs=$(nproc) State=UNKNOWN
PartitionName=debug Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
CONF
  slurmctld -D >"$DIR/slurmctld.out" 2>&1 &
  echo $! > "$DIR/slurmctld.pid"
  slurmd -D >"$DIR/slurmd.out" 2>&1 &
  echo $! > "$DIR/slurmd.pid"
  for _ in $(seq 1 60); do
    if sinfo -h -o '%T' 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
      echo "slurm-one-node: node $HOST up"; return 0
    fi
    sleep 1
  done
  cat "$DIR/slurmctld.out" "$DIR/slurmd.out" >&2 || true
  die "the node did not come up within 60 s (logs in $DIR)"
}

stop() {
  for d in slurmd slurmctld munged; do
    f="$DIR/$d.pid"
    if [ -f "$f" ]; then
      pid="$(cat "$f")"
      kill "$pid" 2>/dev/null || true
      for _ in $(seq 1 20); do kill -0 "$pid" 2>/dev/null || break; sleep 0.25; done
      rm -f "$f"
    fi
  done
  echo "slurm-one-node: stopped"
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  status) sinfo ;;
  *) die "usage: $0 start|stop|status" ;;
esac
