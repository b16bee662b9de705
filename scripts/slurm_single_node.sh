#!/usr/bin/env bash
# A single-node SLURM on this machine, for the end-to-end tests of pipelines/slurm (tests/test_slurm.py) and
# for trying the recipes: Debian's slurm-wlm and munge (apt-get install slurm-wlm munge), the daemons run
# directly (no systemd), no accounting, no cgroups. Run as root:
#   scripts/slurm_single_node.sh start      (idempotent: the node is up and idle when it returns)
#   scripts/slurm_single_node.sh stop
set -euo pipefail
export PATH="$PATH:/usr/sbin:/sbin"  # the daemons, where a user's PATH lacks them
conf=/etc/slurm/slurm.conf
state=/var/spool/slurm-single
case ${1:-start} in
stop)
    pkill -x slurmd || true; pkill -x slurmctld || true; pkill -x munged || true
    exit 0 ;;
start) ;;
*) echo "usage: slurm_single_node.sh start|stop" >&2; exit 2 ;;
esac
command -v slurmctld >/dev/null && command -v munged >/dev/null || {
    echo "slurm_single_node.sh: slurmctld or munged missing (apt-get install slurm-wlm munge)" >&2; exit 1; }
host=$(hostname -s)
cpus=$(nproc)
memory=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024 ))  # MiB, 1 GiB left to the system
mkdir -p /etc/slurm /etc/munge /var/log/munge /run/munge "$state/ctld" "$state/d" /var/log/slurm-single
if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
chown -R munge:munge /etc/munge /var/log/munge /run/munge 2>/dev/null || true
chmod 0700 /etc/munge; chmod 0400 /etc/munge/munge.key
cat > "$conf" <<CONF
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
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
JobRequeue=1
MaxArraySize=10001
MinJobAge=3600
NodeName=$host CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
pgrep -x munged >/dev/null || runuser -u munge -- /usr/sbin/munged 2>/dev/null || /usr/sbin/munged --force
pgrep -x slurmctld >/dev/null || slurmctld
pgrep -x slurmd >/dev/null || slurmd
for _ in $(seq 60); do
    if sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
        sinfo; exit 0
    fi
    scontrol update NodeName="$host" State=RESUME >/dev/null 2>&1 || true
    sleep 1
done
echo "slurm_single_node.sh: the node did not come up; see /var/log/slurm-single/" >&2
exit 1
