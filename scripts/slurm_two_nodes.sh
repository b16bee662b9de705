#!/usr/bin/env bash
# A two-node SLURM on this one machine, for tests/test_slurm_two_nodes.py: slurmctld and two slurmd, each in a
# network namespace of its own (ip netns + veth, a bridge inside the controller's namespace; every address
# lives inside these namespaces), its own hostname (unshare --uts) and its own /etc/hosts (a private mount
# namespace: the machine's is not touched), the one file system standing in for a shared one. Everything of
# it is private: its slurm.conf, munge key and socket, state and logs are under STATE, its daemons are known
# by pid files there, so it neither needs nor touches a SLURM or munge the machine has. Run as root:
#   scripts/slurm_two_nodes.sh start     (the nodes are up and idle when it returns)
#   scripts/slurm_two_nodes.sh stop      (ends the processes of its pid files, deletes its namespaces)
# Clients run in the controller's namespace with its slurm.conf:
#   SLURM_CONF=STATE/slurm.conf nsenter --net=/run/netns/geo-ctl sbatch ...
# (slurmd is started with nsenter --net, not ip netns exec, which remounts /sys: slurmd then finds no cgroup
# file system.) STATE: SLURM_TWO_NODES_STATE, default /var/spool/slurm-two-nodes. Settings: docs/notes/slurm-test-clusters.md.
set -euo pipefail
export PATH="$PATH:/usr/sbin:/sbin"
state=${SLURM_TWO_NODES_STATE:-/var/spool/slurm-two-nodes}
net=10.213.7  # inside the namespaces only
ctl=geo-ctl; nodes=(geo-n1 geo-n2)

ours() {  # NAME PROCESS: the pid in STATE/NAME.pid if it runs and is PROCESS
    local pid
    pid=$(cat "$state/$1.pid" 2>/dev/null) || return 1
    [[ $pid =~ ^[0-9]+$ ]] && [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$2" ] && echo "$pid"
}
stop_one() {  # NAME PROCESS
    local pid
    pid=$(ours "$1" "$2") || { rm -f "$state/$1.pid"; return 0; }
    kill "$pid"
    for _ in $(seq 100); do [ -e "/proc/$pid" ] || break; sleep 0.1; done
    if ours "$1" "$2" >/dev/null; then kill -KILL "$pid"; fi  # still its own daemon after 10 s
    rm -f "$state/$1.pid"
}
stop() {
    # Its jobs first: their steps (slurmstepd) outlive slurmd, and a slurmd ends only after its steps.
    if ours slurmctld slurmctld >/dev/null; then
        export SLURM_CONF=$state/slurm.conf
        jobs=$(nsenter --net="/run/netns/$ctl" squeue -h -o %A 2>/dev/null | paste -sd' ' || true)
        if [ -n "$jobs" ]; then
            # shellcheck disable=SC2086  # job ids, one word each
            nsenter --net="/run/netns/$ctl" scancel $jobs || true
            for _ in $(seq 60); do
                [ -z "$(nsenter --net="/run/netns/$ctl" squeue -h 2>/dev/null)" ] && break
                sleep 1
            done
        fi
    fi
    stop_one geo-n2 slurmd; stop_one geo-n1 slurmd; stop_one slurmctld slurmctld; stop_one munged munged
    for ns in "$ctl" ${nodes[@]+"${nodes[@]}"}; do
        if [ -e "$state/netns-$ns" ]; then ip netns del "$ns" 2>/dev/null || true; rm -f "$state/netns-$ns"; fi
    done
}

case ${1:-start} in
stop) stop; exit 0 ;;
start) ;;
*) echo "usage: slurm_two_nodes.sh start|stop" >&2; exit 2 ;;
esac
for tool in slurmctld slurmd munged ip nsenter unshare; do
    command -v "$tool" >/dev/null || { echo "slurm_two_nodes.sh: $tool missing (apt-get install slurm-wlm munge" \
        "iproute2 util-linux)" >&2; exit 1; }
done
if ours slurmctld slurmctld >/dev/null && ours geo-n1 slurmd >/dev/null && ours geo-n2 slurmd >/dev/null; then
    echo "slurm_two_nodes.sh: already running"; exit 0
fi
stop  # whatever is left of an earlier start: only its own processes and namespaces
for ns in "$ctl" ${nodes[@]+"${nodes[@]}"}; do
    if ip netns list | grep -qw "$ns"; then
        echo "slurm_two_nodes.sh: a network namespace $ns exists that this script did not make: not touching it" >&2
        exit 1
    fi
done
mkdir -p "$state"
trap 'stop' ERR

# The network: a bridge in the controller's namespace, a veth from it to each node's namespace.
ip netns add "$ctl"; touch "$state/netns-$ctl"
ip -n "$ctl" link set lo up
ip -n "$ctl" link add br0 type bridge
ip -n "$ctl" addr add "$net.1/24" dev br0
ip -n "$ctl" link set br0 up
hosts="127.0.0.1 localhost\n$net.1 $ctl\n"
for i in "${!nodes[@]}"; do
    node=${nodes[$i]}; address=$net.$((11 + i))
    ip netns add "$node"; touch "$state/netns-$node"
    ip -n "$node" link set lo up
    ip -n "$ctl" link add "veth$i" type veth peer name eth0 netns "$node"
    ip -n "$ctl" link set "veth$i" master br0 up
    ip -n "$node" addr add "$address/24" dev eth0
    ip -n "$node" link set eth0 up
    hosts+="$address $node\n"
done
printf "%b" "$hosts" > "$state/hosts"

# munge of its own: key, socket, pid, log and seed under STATE (the socket's folder open to all, as munged asks).
mkdir -p "$state/munge" "$state/munge-socket"
[ -s "$state/munge/munge.key" ] || dd if=/dev/urandom of="$state/munge/munge.key" bs=1024 count=1 status=none
chown -R munge:munge "$state/munge" "$state/munge-socket"
chmod 0700 "$state/munge"; chmod 0400 "$state/munge/munge.key"; chmod 0755 "$state/munge-socket"
# setpriv runs munged as munge in the same process (runuser would fork): the pid is munged's.
setpriv --reuid=munge --regid=munge --init-groups munged -F --socket="$state/munge-socket/munge.sock" \
    --key-file="$state/munge/munge.key" --pid-file="$state/munge/munged.pid" --log-file="$state/munge/munged.log" \
    --seed-file="$state/munge/seed" > "$state/munge/munged.out" 2>&1 &
echo $! > "$state/munged.pid"

cpus=$(nproc --all)  # the machine's: nproc alone follows OMP_NUM_THREADS, which a library may have set in the caller
memory=$(( ($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 2048) / 2 ))  # MiB per node
mkdir -p "$state/ctld" "$state/log" "$state/d-${nodes[0]}" "$state/d-${nodes[1]}"
cat > "$state/slurm.conf" <<CONF
# written by scripts/slurm_two_nodes.sh; defaults of slurm.conf unless said (docs/notes/slurm-test-clusters.md has the table)
ClusterName=geotwo
SlurmctldHost=$ctl($net.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$state/munge-socket/munge.sock
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d-%n
SlurmctldPidFile=$state/slurmctld-own.pid
SlurmdPidFile=$state/slurmd-%n-own.pid
SlurmctldLogFile=$state/log/slurmctld.log
SlurmdLogFile=$state/log/slurmd-%n.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/affinity
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MinJobAge=30
NodeName=${nodes[0]} NodeAddr=$net.11 CPUs=$cpus RealMemory=$memory State=UNKNOWN
NodeName=${nodes[1]} NodeAddr=$net.12 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=main Nodes=${nodes[0]},${nodes[1]} Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
export SLURM_CONF=$state/slurm.conf

# A daemon in namespace NS: its hostname NS (gloo and c10d resolve it) and STATE/hosts bound over /etc/hosts in
# a mount namespace of its own (its jobs inherit both). nsenter, unshare and sh each exec the next, so $! is
# the daemon's pid.
# shellcheck disable=SC2016  # expanded by that sh
launch='hostname "$0" && mount --bind "$1" /etc/hosts && shift && exec "$@"'
within() {  # NS: the command prefix, into the array prefix
    prefix=(nsenter --net="/run/netns/$1" unshare --uts --mount --propagation private sh -c "$launch" "$1"
            "$state/hosts")
}
within "$ctl"  # slurmctld -c: a fresh start, without the jobs of an earlier one
${prefix[@]+"${prefix[@]}"} slurmctld -D -c -f "$SLURM_CONF" > "$state/log/slurmctld.out" 2>&1 &
echo $! > "$state/slurmctld.pid"
for node in ${nodes[@]+"${nodes[@]}"}; do
    within "$node"
    ${prefix[@]+"${prefix[@]}"} slurmd -D -N "$node" -f "$SLURM_CONF" > "$state/log/slurmd-$node.out" 2>&1 &
    echo $! > "$state/$node.pid"
done
trap - ERR
for _ in $(seq 60); do
    up=$(nsenter --net="/run/netns/$ctl" sinfo -h -N -o '%N %T' 2>/dev/null | grep -cE ' (idle|mixed|allocated)$' || true)
    if [ "$up" = 2 ]; then
        nsenter --net="/run/netns/$ctl" sinfo -N; exit 0
    fi
    for node in ${nodes[@]+"${nodes[@]}"}; do
        nsenter --net="/run/netns/$ctl" scontrol update NodeName="$node" State=RESUME >/dev/null 2>&1 || true
    done
    sleep 1
done
echo "slurm_two_nodes.sh: the nodes did not come up; see $state/log/" >&2
stop
exit 1
