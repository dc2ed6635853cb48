#!/usr/bin/env bash
# A real single-node Slurm cluster in one directory, for tests and CI.
#
#   .ci/slurm/cluster.sh start DIR   # write DIR/slurm.conf, start munged, slurmctld, slurmd
#   . DIR/env.sh                     # SLURM_CONF (and nothing else) for sbatch, squeue, ...
#   .ci/slurm/cluster.sh stop DIR    # cancel DIR's jobs, stop exactly the daemons start began
#
# Exit status of start: 0 when the node is idle and takes jobs, 3 with a line "SKIP: ..."
# when Slurm cannot run here (packages missing, a daemon fails to start: its log is printed),
# 2 for wrong usage. stop is safe to call twice, or after a start that skipped.
#
# Packages (Debian 12, Slurm 22.05, munge 0.5.15); .ci/run installs them:
#   apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge
# slurm-wlm is only a metapackage of those three Slurm packages; its recommends (the
# slurm-wlm-plugins set: ipmi, rsmi, hdf5, influxdb, ...) are not needed. Their postinst
# scripts try to start munge, slurmd and slurmctld through invoke-rc.d; in this container
# policy-rc.d (exit 101) denies it, so nothing runs after the install. munge's postinst
# also makes /etc/munge/munge.key, which this script does not use: the cluster has its own
# key, socket, state, logs and pid files, all under DIR, so it clashes with no system
# munged or Slurm (and would still start if the packages' services were running).
#
# What the configuration has to say so that Slurm runs in a container with no systemd:
# - ProctrackType=proctrack/linuxproc and TaskPlugin=task/none: no cgroups. (Tried here:
#   with proctrack/cgroup slurmd starts but every job step fails, "cgroup namespace
#   'freezer' not mounted ... Plugin initialization failed", although /sys/fs/cgroup/freezer
#   is listed as mounted.) JobAcctGatherType=jobacct_gather/none and no accounting
#   (AccountingStorageType=accounting_storage/none: no slurmdbd).
# - SlurmctldHost=NAME(127.0.0.1) and NodeAddr=127.0.0.1: the node name is the host's
#   short name (slurmd finds its NodeName by it) but no name has to resolve to an address
#   of this machine: everything talks over the loopback.
# - AuthInfo=socket=DIR/munge/munge.socket.2: daemons and clients all use this cluster's
#   munged, not /run/munge.
# - SlurmUser=root and SlurmdUser=root: no daemon changes user, so the files under DIR
#   need no chown.
# - Ports: the first free pair from 6817/6818 up (another cluster on this host keeps its).
# - Scheduling: select/cons_tres with CR_Core, so a job that asks for one CPU takes one core
#   and at most as many one-CPU tasks run at once as the node has cores.
# - SchedulerParameters=sched_interval=1: the main scheduling loop every second instead of
#   every minute, so that pending work is not left waiting for it in a short test.
# Harmless errors in the logs: slurmd and slurmctld load every MPI plugin at start and log
# that mpi/pmix cannot find libpmix (not installed; MpiDefault=none); munged logs
# "Unauthorized credential for client UID=0 GID=0" now and then (Slurm decoding a
# credential restricted to another uid; jobs run regardless: dun/munge issue 120);
# slurmctld reports missing state files on its first start (-i, an empty StateSaveLocation).
set -euo pipefail

usage() {
  echo "usage: $0 start DIR | stop DIR | status DIR" >&2
  exit 2
}
[ $# -eq 2 ] || usage
cmd=$1
dir=$2

skip() {
  echo "SKIP: $*" >&2
  exit 3
}

# A port nobody listens on (bash's /dev/tcp connects if someone does).
port_free() {
  ! (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null
}

pid_alive() {
  [ -n "$1" ] && kill -0 "$1" 2>/dev/null
}

show_logs() {
  local f
  for f in "$dir"/log/*.log; do
    [ -f "$f" ] || continue
    echo "----- $f (last 40 lines) -----" >&2
    tail -n 40 "$f" >&2
  done
}

# Waits up to $2 seconds for file $1 to hold a live pid; prints it.
wait_pidfile() {
  local file=$1 secs=$2 i pid
  for ((i = 0; i < secs * 10; i++)); do
    if [ -s "$file" ]; then
      pid=$(head -n 1 "$file")
      if pid_alive "$pid"; then
        echo "$pid"
        return 0
      fi
    fi
    sleep 0.1
  done
  return 1
}

start() {
  local missing=() c
  for c in munged mungekey slurmctld slurmd sinfo sbatch squeue scontrol scancel; do
    command -v "$c" >/dev/null 2>&1 || missing+=("$c")
  done
  [ ${#missing[@]} -eq 0 ] ||
    skip "Slurm/munge not installed (missing ${missing[*]}): apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge"
  [ "$(id -u)" = 0 ] || skip "the test cluster runs its daemons as root (SlurmUser=root); run as root"

  mkdir -p "$dir"
  dir=$(cd "$dir" && pwd)
  if [ -s "$dir/run/slurmctld.pid" ] && pid_alive "$(head -n 1 "$dir/run/slurmctld.pid")"; then
    echo "cluster in $dir already running; stop it first" >&2
    exit 1
  fi
  rm -rf "$dir/munge" "$dir/munge-key" "$dir/state" "$dir/spool" "$dir/log" "$dir/run"
  mkdir -p "$dir/munge" "$dir/munge-key" "$dir/state" "$dir/spool" "$dir/log" "$dir/run"
  # munged checks that no one but its user can write to the directories of its key, socket,
  # log and pid files, and wants the socket's directory searchable by all (0755); the key's
  # directory is private.
  chmod 0700 "$dir/munge-key"
  chmod 0755 "$dir" "$dir/munge" "$dir/state" "$dir/spool" "$dir/log" "$dir/run"

  # --- configuration ---------------------------------------------------------------------
  local host node_line cpus sockets cores threads mem realmem ctld_port slurmd_port
  host=$(hostname -s)
  # slurmd -C prints this node's line as slurmd sees the hardware, e.g.
  #   NodeName=vm CPUs=2 Boards=1 SocketsPerBoard=1 CoresPerSocket=2 ThreadsPerCore=1 RealMemory=24105
  node_line=$(slurmd -C 2>/dev/null | head -n 1) || skip "slurmd -C failed"
  field() { sed -n "s/.* $1=\([0-9]*\).*/\1/p" <<<"$node_line"; }
  cpus=$(field CPUs)
  sockets=$(field SocketsPerBoard)
  cores=$(field CoresPerSocket)
  threads=$(field ThreadsPerCore)
  mem=$(field RealMemory)
  [ -n "$cpus" ] && [ -n "$mem" ] || skip "could not read the node's CPUs and memory from 'slurmd -C': $node_line"
  # A little below what the machine has: slurmd drains a node that reports less memory than
  # its configured RealMemory, and what it reports can move by a few MB.
  realmem=$((mem * 95 / 100))

  ctld_port=6817
  while ! port_free "$ctld_port" || ! port_free $((ctld_port + 1)); do
    ctld_port=$((ctld_port + 2))
    [ "$ctld_port" -lt 6917 ] || skip "no free port pair in 6817-6916 for slurmctld/slurmd"
  done
  slurmd_port=$((ctld_port + 1))

  cat >"$dir/slurm.conf" <<EOF
# Written by .ci/slurm/cluster.sh: a single-node test cluster on $host.
ClusterName=dofraytest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket.2
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SwitchType=switch/none
# No mail server here: a job's --mail-type would otherwise log "MailProg is invalid".
MailProg=/bin/true
ReturnToService=2
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=1
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/run/slurmctld.pid
SlurmdPidFile=$dir/run/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
# Finished jobs stay visible to scontrol for 5 minutes (the default), then go.
MinJobAge=300
# Quick to notice a dead slurmd, quick to give up on a stuck job at the end of a test.
SlurmdTimeout=30
KillWait=5
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus SocketsPerBoard=${sockets:-1} CoresPerSocket=${cores:-$cpus} ThreadsPerCore=${threads:-1} RealMemory=$realmem State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  printf 'export SLURM_CONF=%q\n' "$dir/slurm.conf" >"$dir/env.sh"
  export SLURM_CONF="$dir/slurm.conf"

  # --- munge -----------------------------------------------------------------------------
  # Its own key (munged wants it readable by its user only), its own socket, pid and log.
  mungekey --create --bits=1024 --keyfile="$dir/munge-key/munge.key" >/dev/null 2>&1 ||
    dd if=/dev/urandom of="$dir/munge-key/munge.key" bs=128 count=1 status=none
  chmod 0400 "$dir/munge-key/munge.key"
  # munged runs as root here, like the other daemons. --force: munged refuses insecure
  # permissions on the directories above its files (e.g. a group-writable parent of DIR);
  # with it, it only warns. The key stays 0400 in a 0700 directory either way.
  munged --force \
    --key-file="$dir/munge-key/munge.key" \
    --socket="$dir/munge/munge.socket.2" \
    --pid-file="$dir/run/munged.pid" \
    --log-file="$dir/log/munged.log" \
    --seed-file="$dir/munge-key/munged.seed" \
    >"$dir/log/munged.start.log" 2>&1 || true
  if ! wait_pidfile "$dir/run/munged.pid" 10 >/dev/null; then
    cat "$dir/log/munged.start.log" >&2
    show_logs
    skip "munged did not start"
  fi
  if ! munge -S "$dir/munge/munge.socket.2" -n | unmunge -S "$dir/munge/munge.socket.2" >/dev/null 2>&1; then
    show_logs
    stop_daemons
    skip "munge round trip through $dir/munge/munge.socket.2 failed"
  fi

  # --- slurmctld, slurmd -----------------------------------------------------------------
  # Both daemonize (their stdout/stderr go to /dev/null, so a caller's pipe does not stay
  # open) and write their pid files; -i: ignore state saved by an earlier run in DIR.
  slurmctld -f "$dir/slurm.conf" -i >"$dir/log/slurmctld.start.log" 2>&1 || true
  if ! wait_pidfile "$dir/run/slurmctld.pid" 15 >/dev/null; then
    cat "$dir/log/slurmctld.start.log" >&2
    show_logs
    stop_daemons
    skip "slurmctld did not start"
  fi
  slurmd -f "$dir/slurm.conf" >"$dir/log/slurmd.start.log" 2>&1 || true
  if ! wait_pidfile "$dir/run/slurmd.pid" 15 >/dev/null; then
    cat "$dir/log/slurmd.start.log" >&2
    show_logs
    stop_daemons
    skip "slurmd did not start"
  fi

  # --- wait until the node takes jobs ----------------------------------------------------
  local i state=""
  for ((i = 0; i < 60; i++)); do
    state=$(sinfo -h -n "$host" -o '%T' 2>/dev/null | head -n 1 || true)
    [ "$state" = idle ] && break
    sleep 1
  done
  if [ "$state" != idle ]; then
    sinfo -N -l >&2 || true
    scontrol show node "$host" >&2 || true
    show_logs
    stop_daemons
    skip "node $host not idle after 60 s (state '${state:-none}')"
  fi
  echo "slurm cluster up in $dir: node $host idle ($cpus CPUs, RealMemory=$realmem MB), ports $ctld_port/$slurmd_port"
  echo "  export SLURM_CONF=$dir/slurm.conf   (or: . $dir/env.sh)"
}

# Sends TERM to the daemon in pid file $1 and waits up to 20 s for it to exit, then KILL.
stop_one() {
  local file=$1 name=$2 pid i
  [ -s "$file" ] || return 0
  pid=$(head -n 1 "$file")
  if pid_alive "$pid"; then
    kill -TERM "$pid" 2>/dev/null || true
    for ((i = 0; i < 200; i++)); do
      pid_alive "$pid" || break
      sleep 0.1
    done
    if pid_alive "$pid"; then
      echo "$name ($pid) still running after 20 s: KILL" >&2
      kill -KILL "$pid" 2>/dev/null || true
      sleep 0.5
    fi
  fi
  rm -f "$file"
}

stop_daemons() {
  stop_one "$dir/run/slurmd.pid" slurmd
  stop_one "$dir/run/slurmctld.pid" slurmctld
  stop_one "$dir/run/munged.pid" munged
}

stop() {
  [ -d "$dir" ] || return 0
  dir=$(cd "$dir" && pwd)
  if [ -f "$dir/slurm.conf" ] && [ -s "$dir/run/slurmctld.pid" ] &&
    pid_alive "$(head -n 1 "$dir/run/slurmctld.pid")"; then
    export SLURM_CONF="$dir/slurm.conf"
    # Cancel what is still queued or running, so no job step outlives its slurmd, and give
    # the steps a moment to end (KillWait=5).
    if [ -n "$(squeue -h -o %i 2>/dev/null)" ]; then
      scancel --full --quiet -u root 2>/dev/null || true
      local i
      for ((i = 0; i < 20; i++)); do
        [ -z "$(squeue -h -o %i 2>/dev/null)" ] && break
        sleep 0.5
      done
    fi
  fi
  stop_daemons
  echo "slurm cluster in $dir stopped"
}

status() {
  local name f pid
  for name in munged slurmctld slurmd; do
    f="$dir/run/$name.pid"
    pid=$([ -s "$f" ] && head -n 1 "$f" || true)
    if pid_alive "$pid"; then echo "$name running ($pid)"; else echo "$name not running"; fi
  done
}

case "$cmd" in
  start) start ;;
  stop) stop ;;
  status) status ;;
  *) usage ;;
esac
