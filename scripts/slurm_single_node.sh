#!/usr/bin/env bash
# A single-node SLURM on this machine, for the end-to-end tests of pipelines/slurm (tests/test_slurm_cluster.py)
# and for trying the recipes: Debian's slurm-wlm and munge (apt-get install slurm-wlm munge), the daemons run
# directly (no systemd), no accounting, no cgroups. Run as root:
#   scripts/slurm_single_node.sh start      (idempotent: the node is up and idle when it returns)
#   scripts/slurm_single_node.sh stop       (stops the daemons it started, by their pid files, and removes
#                                            the slurm.conf it wrote)
# It refuses a machine with a SLURM of its own: a slurm.conf it did not write, or a munged, slurmctld or slurmd
# it did not start; it never stops a process by name. Its settings, and which are SLURM's defaults:
# docs/notes/slurm-test-clusters.md. SLURM_SINGLE_NODE_CONF and SLURM_SINGLE_NODE_STATE move its slurm.conf and state (tests).
set -euo pipefail
export PATH="$PATH:/usr/sbin:/sbin"  # the daemons, where a user's PATH lacks them
conf=${SLURM_SINGLE_NODE_CONF:-/etc/slurm/slurm.conf}
state=${SLURM_SINGLE_NODE_STATE:-/var/spool/slurm-single}
mark="# written by scripts/slurm_single_node.sh: removed by its stop"

ours() {  # NAME: the pid in NAME's pid file, if that process runs and is NAME
    local pid
    pid=$(cat "$state/$1.pid" 2>/dev/null) || return 1
    [[ $pid =~ ^[0-9]+$ ]] && [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$1" ] && echo "$pid"
}
others() {  # NAME: the pids of the live processes called NAME that this script did not start
    local mine pid
    mine=$(ours "$1" || true)
    for pid in $(pgrep -x "$1" || true); do
        [ "$pid" != "$mine" ] && [ "$(awk '{print $3}' "/proc/$pid/stat" 2>/dev/null)" != Z ] && echo "$pid"
    done
    return 0
}

case ${1:-start} in
stop)
    for name in slurmd slurmctld munged; do
        pid=$(ours "$name") || continue
        kill "$pid"
        for _ in $(seq 100); do [ -e "/proc/$pid" ] || break; sleep 0.1; done
        rm -f "$state/$name.pid"
    done
    if [ "$(head -n 1 "$conf" 2>/dev/null)" = "$mark" ]; then rm -f "$conf"; fi
    exit 0 ;;
start) ;;
*) echo "usage: slurm_single_node.sh start|stop" >&2; exit 2 ;;
esac

if [ -e "$conf" ] && [ "$(head -n 1 "$conf")" != "$mark" ]; then
    echo "slurm_single_node.sh: $conf exists and is not this script's: this machine has a SLURM of its own;" \
        "not touching it" >&2
    exit 1
fi
foreign=()
for name in munged slurmctld slurmd; do
    pids=$(others "$name" | paste -sd' ')
    [ -z "$pids" ] || foreign+=("$name (pid $pids)")
done
if (( ${#foreign[@]} )); then
    echo "slurm_single_node.sh: daemons this script did not start run: ${foreign[*]-}; this machine has a" \
        "SLURM or munge of its own: not touching it" >&2
    exit 1
fi
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    echo "slurm_single_node.sh: slurmctld or munged missing (apt-get install slurm-wlm munge)" >&2
    exit 1
fi
host=$(hostname -s)
cpus=$(nproc --all)  # the machine's: nproc alone follows OMP_NUM_THREADS, which a library may have set in the caller
memory=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024 ))  # MiB, 1 GiB left to the system
mkdir -p "$(dirname "$conf")" /etc/munge /var/log/munge /run/munge /var/lib/munge "$state/ctld" "$state/d" \
    /var/log/slurm-single
if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
chown -R munge:munge /etc/munge /var/log/munge /run/munge /var/lib/munge 2>/dev/null || true
chmod 0700 /etc/munge; chmod 0400 /etc/munge/munge.key
# Defaults of slurm.conf unless said: docs/notes/slurm-test-clusters.md has the table.
cat > "$conf" <<CONF
$mark
ClusterName=single
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=/var/log/slurm-single/slurmctld.log
SlurmdLogFile=/var/log/slurm-single/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/affinity
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MinJobAge=30
NodeName=$host CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
touch "$state/munged.pid"; chown munge:munge "$state/munged.pid" 2>/dev/null || true
if ! ours munged >/dev/null; then
    runuser -u munge -- munged --pid-file="$state/munged.pid" 2>/dev/null \
        || munged --force --pid-file="$state/munged.pid"
fi
export SLURM_CONF=$conf
ours slurmctld >/dev/null || slurmctld -c -f "$conf"  # a fresh start: no jobs of an earlier one
ours slurmd >/dev/null || slurmd -f "$conf"
for _ in $(seq 60); do
    if sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
        sinfo; exit 0
    fi
    scontrol update NodeName="$host" State=RESUME >/dev/null 2>&1 || true
    sleep 1
done
echo "slurm_single_node.sh: the node did not come up; see /var/log/slurm-single/" >&2
exit 1
