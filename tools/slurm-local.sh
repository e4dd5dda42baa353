#!/usr/bin/env bash
# Bring up (and tear down) a real single-node Slurm cluster on this Debian
# machine, from Debian's packages, for tests. See docs/slurm.md.
#
#   tools/slurm-local.sh up       install if missing, configure, start, wait for the node
#   tools/slurm-local.sh down     stop slurmd, slurmctld and munged (packages stay)
#   tools/slurm-local.sh status   daemons, sinfo and squeue
#
# Needs root (CI runs as root). No systemd: munged, slurmctld and slurmd are
# started here as plain daemons and stopped by the PIDs in their PID files.
#
# Environment:
#   SLURM_LOCAL_TIMEOUT  seconds `up` waits for the node to be usable (default 60)
set -euo pipefail
export PATH=$PATH:/usr/sbin:/sbin

CONF_DIR=/etc/slurm
CONF=$CONF_DIR/slurm.conf
CGROUP_CONF=$CONF_DIR/cgroup.conf
LOG_DIR=/var/log/slurm
CTLD_LOG=$LOG_DIR/slurmctld.log
SLURMD_LOG=$LOG_DIR/slurmd.log
STATE_DIR=/var/spool/slurmctld
SPOOL_DIR=/var/spool/slurmd
CTLD_PID=/run/slurmctld.pid
SLURMD_PID=/run/slurmd.pid
MUNGE_KEY=/etc/munge/munge.key
MUNGE_RUN=/run/munge
MUNGE_PID=$MUNGE_RUN/munged.pid
MUNGE_LOG=/var/log/munge/munged.log
TIMEOUT=${SLURM_LOCAL_TIMEOUT:-60}

say() { echo "slurm-local: $*" >&2; }
die() { say "error: $*"; show_logs; exit 1; }

show_logs() {
  local f
  for f in "$MUNGE_LOG" "$CTLD_LOG" "$SLURMD_LOG"; do
    if [[ -s $f ]]; then
      echo "----- last lines of $f -----" >&2
      tail -n 25 "$f" >&2 || true
    fi
  done
}

short_host() {
  local h
  h=$(hostname -s 2>/dev/null || uname -n)
  echo "${h%%.*}"
}

# PID from a PID file if that process is alive and is the daemon the file
# belongs to (its name is the file's name less .pid), else nothing (status 1).
# A stale file whose PID was reused by another process does not count.
live_pid() {
  local f=$1 pid comm want
  want=$(basename "$f" .pid)
  [[ -s $f ]] || return 1
  pid=$(tr -dc '0-9' <"$f")
  [[ -n $pid ]] && alive "$pid" || return 1
  comm=$(cat "/proc/$pid/comm" 2>/dev/null) || return 1
  [[ $comm == "$want" ]] || return 1
  echo "$pid"
}

# A killed daemon can linger a moment as a zombie: that is not running.
alive() {
  kill -0 "$1" 2>/dev/null || return 1
  [[ $(awk '{print $3}' "/proc/$1/stat" 2>/dev/null) != Z ]]
}

need_root() {
  [[ $(id -u) -eq 0 ]] || { say "error: must run as root"; exit 1; }
}

# --- install -----------------------------------------------------------------

install_packages() {
  local missing=0 b
  for b in slurmctld slurmd sinfo squeue sbatch scontrol munged munge unmunge; do
    command -v "$b" >/dev/null 2>&1 || missing=1
  done
  if ((missing == 0)); then
    return 0
  fi
  say "installing slurmctld slurmd slurm-client munge (apt-get)"
  apt-get update -q
  # Recommends would pull ~35 extra plugin and -dev packages (hdf5, influxdb,
  # rrd, rocm, ...); none is needed for a single test node.
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
    slurmctld slurmd slurm-client munge
}

# --- munge -------------------------------------------------------------------

start_munge() {
  if [[ ! -s $MUNGE_KEY ]]; then
    say "creating $MUNGE_KEY"
    install -d -o munge -g munge -m 0700 /etc/munge
    mungekey --create --keyfile="$MUNGE_KEY"
  fi
  # munged refuses a key readable by others or owned by someone else.
  chown munge:munge "$MUNGE_KEY"
  chmod 0400 "$MUNGE_KEY"
  install -d -o munge -g munge -m 0755 "$MUNGE_RUN"
  install -d -o munge -g munge -m 0700 /var/log/munge
  install -d -o munge -g munge -m 0711 /var/lib/munge

  if ! live_pid "$MUNGE_PID" >/dev/null; then
    say "starting munged"
    # A stale socket or PID file from an unclean stop makes munged give up;
    # --force lets it take them over (nothing alive owns them, checked above).
    runuser -u munge -- /usr/sbin/munged --force
  fi
  local i
  for ((i = 0; i < 50; i++)); do
    munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && return 0
    sleep 0.2
  done
  die "munge does not work (munge -n | unmunge)"
}

# --- configuration -------------------------------------------------------------

# Install file $1 as $2 if the contents differ; note the change.
put_conf() {
  if ! cmp -s "$1" "$2"; then
    install -m 0644 "$1" "$2"
    CONF_CHANGED=1
    say "wrote $2"
  fi
  rm -f "$1"
}

write_conf() {
  local host node_line tmp
  host=$(short_host)
  # "NodeName=vm CPUs=2 Boards=1 SocketsPerBoard=1 CoresPerSocket=2 ThreadsPerCore=1 RealMemory=..."
  node_line=$(slurmd -C | grep '^NodeName=' | head -n 1)
  [[ -n $node_line ]] || die "slurmd -C printed no NodeName line"
  local node_name=${node_line%% *}
  node_name=${node_name#NodeName=}
  [[ $node_name == "$host" ]] || die "slurmd -C names the node '$node_name', hostname -s says '$host'"

  tmp=$(mktemp)
  cat >"$tmp" <<EOF
# Written by tools/slurm-local.sh: a single-node test cluster.
ClusterName=oils-local
# An explicit address: works whether or not the hostname resolves.
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
# No systemd and no cgroup delegation in containers: nothing here uses
# cgroups (and cgroup.conf names a plugin that needs none).
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
# Start pending jobs right when CPUs free up (small test jobs).
SchedulerParameters=batch_sched_delay=0
ReturnToService=2
MailProg=/bin/true
StateSaveLocation=$STATE_DIR
SlurmdSpoolDir=$SPOOL_DIR
SlurmctldPidFile=$CTLD_PID
SlurmdPidFile=$SLURMD_PID
SlurmctldLogFile=$CTLD_LOG
SlurmdLogFile=$SLURMD_LOG
SlurmctldDebug=info
SlurmdDebug=info
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
KillWait=10
Waittime=0
$node_line NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=debug Nodes=$node_name Default=YES MaxTime=INFINITE State=UP
EOF
  install -d -m 0755 "$CONF_DIR"
  CONF_CHANGED=0
  put_conf "$tmp" "$CONF"

  # slurmd loads a cgroup plugin whatever ProctrackType and TaskPlugin say
  # (22.05: slurmd.c calls cgroup_g_init() unconditionally), and the default,
  # CgroupPlugin=autodetect, fails where /sys/fs/cgroup has no systemd
  # hierarchy ("can't stat /sys/fs/cgroup/systemd/") or is cgroup v2 without
  # a systemd-delegated scope. Name a plugin that does nothing at init:
  # "disabled" from 24.05 on; before that cgroup/v1, whose init() touches no
  # file and which nothing else here uses.
  local ver major minor plugin=cgroup/v1
  ver=$(slurmd -V | awk '{print $NF}')
  major=${ver%%.*}
  minor=${ver#*.}
  minor=${minor%%.*}
  if ((10#$major > 24 || (10#$major == 24 && 10#$minor >= 5))); then
    plugin=disabled
  fi
  tmp=$(mktemp)
  cat >"$tmp" <<EOF
# Written by tools/slurm-local.sh: no cgroup use (no systemd in containers).
CgroupPlugin=$plugin
EOF
  put_conf "$tmp" "$CGROUP_CONF"
  NODE=$node_name
  install -d -m 0755 "$LOG_DIR" "$STATE_DIR" "$SPOOL_DIR"
}

# --- daemons -------------------------------------------------------------------

# The daemons fork and the parent returns before the child writes its PID
# file: wait (bounded) for a live PID there.
wait_pidfile() {
  local name=$1 f=$2 i
  for ((i = 0; i < 50; i++)); do
    live_pid "$f" >/dev/null && return 0
    sleep 0.2
  done
  die "$name did not stay up (no live PID in $f after 10 s)"
}

start_slurm() {
  if ((CONF_CHANGED)) && { live_pid "$CTLD_PID" >/dev/null || live_pid "$SLURMD_PID" >/dev/null; }; then
    say "configuration changed: restarting the running daemons"
    stop_slurm
  fi
  if ! live_pid "$CTLD_PID" >/dev/null; then
    say "starting slurmctld"
    # -i: ignore errors in state files (e.g. left by an older configuration).
    slurmctld -i || die "slurmctld failed to start"
    wait_pidfile slurmctld "$CTLD_PID"
  fi
  if ! live_pid "$SLURMD_PID" >/dev/null; then
    say "starting slurmd"
    slurmd || die "slurmd failed to start"
    wait_pidfile slurmd "$SLURMD_PID"
  fi
}

node_state() {
  sinfo -h -n "$NODE" -o %T 2>/dev/null | head -n 1
}

wait_idle() {
  local deadline=$((SECONDS + TIMEOUT)) st="" resumed=0
  while ((SECONDS < deadline)); do
    live_pid "$CTLD_PID" >/dev/null || die "slurmctld is not running"
    live_pid "$SLURMD_PID" >/dev/null || die "slurmd is not running"
    st=$(node_state || true)
    case $st in
      idle | mixed | allocated | completing)
        say "node $NODE is $st"
        return 0
        ;;
      down | drain* | fail*)
        # Responding (no '*') but held down, e.g. by an earlier unclean stop.
        if ((resumed < 3)); then
          say "node $NODE is $st: resuming it"
          scontrol update nodename="$NODE" state=resume || true
          resumed=$((resumed + 1))
        fi
        ;;
    esac
    sleep 1
  done
  sinfo -N -l >&2 || true
  scontrol show node "$NODE" >&2 || true
  die "node $NODE not usable after ${TIMEOUT}s (state '${st:-?}')"
}

# Send TERM to the process in a PID file and wait (bounded) for it to exit.
stop_pidfile() {
  local name=$1 f=$2 pid i
  pid=$(live_pid "$f") || { rm -f "$f"; return 0; }
  say "stopping $name (pid $pid)"
  kill -TERM "$pid" 2>/dev/null || true
  for ((i = 0; i < 100; i++)); do
    alive "$pid" || { rm -f "$f"; return 0; }
    sleep 0.2
  done
  say "$name (pid $pid) ignored TERM for 20 s: killing it"
  kill -KILL "$pid" 2>/dev/null || true
  rm -f "$f"
}

stop_slurm() {
  stop_pidfile slurmd "$SLURMD_PID"
  stop_pidfile slurmctld "$CTLD_PID"
}

stop_munge() {
  stop_pidfile munged "$MUNGE_PID"
}

# --- commands ------------------------------------------------------------------

cmd_up() {
  need_root
  local t0=$SECONDS
  install_packages
  say "$(slurmd -V)"
  start_munge
  write_conf
  start_slurm
  wait_idle
  say "up in $((SECONDS - t0)) s"
  sinfo
}

cmd_down() {
  need_root
  stop_slurm
  stop_munge
  say "down"
}

cmd_status() {
  local rc=0 name f pid
  for name in munged slurmctld slurmd; do
    case $name in
      munged) f=$MUNGE_PID ;;
      slurmctld) f=$CTLD_PID ;;
      slurmd) f=$SLURMD_PID ;;
    esac
    if pid=$(live_pid "$f"); then
      echo "$name: running (pid $pid)"
    else
      echo "$name: stopped"
      rc=1
    fi
  done
  if ((rc == 0)); then
    sinfo
    squeue
  fi
  return $rc
}

case ${1:-} in
  up) cmd_up ;;
  down) cmd_down ;;
  status) cmd_status ;;
  *)
    echo "usage: $0 up|down|status" >&2
    exit 2
    ;;
esac
