#!/usr/bin/env bash
# Starts a single-node Slurm on this machine from Debian's packages (slurm-wlm, munge):
# munged, slurmctld and slurmd on localhost, for trying scripts/slurm/bake.sh and for CI's
# Slurm step. Run as root. Installs the packages with apt-get when they are missing.
#
#   scripts/slurm/local-cluster.sh          # install if needed, configure, start, wait for the node
#   scripts/slurm/local-cluster.sh stop     # stop the three daemons this script started
#
# The configuration is what a container or a small VM allows: processes are tracked through
# /proc (ProctrackType=proctrack/linuxproc), no task confinement (TaskPlugin=task/none), and
# cgroup.conf lets Slurm pick the cgroup version itself (CgroupPlugin=autodetect). The node
# offers every core of this machine and half its memory.
set -euo pipefail

conf=/etc/slurm
state=/var/spool/slurm-guidebake
logs=/var/log/slurm-guidebake

stop() {
    for pidfile in /run/slurmd-guidebake.pid /run/slurmctld-guidebake.pid /run/munge/munged-guidebake.pid; do
        if [[ -s $pidfile ]]; then
            kill "$(cat "$pidfile")" 2>/dev/null || true
            rm -f "$pidfile"
        fi
    done
}

if [[ ${1:-} == stop ]]; then
    stop
    exit 0
fi

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq slurm-wlm munge >/dev/null
fi

host=$(hostname -s)
cpus=$(nproc)
memory_mb=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 2048))
mkdir -p "$conf" "$state/ctld" "$state/d" "$logs" /run/munge
cat >"$conf/slurm.conf" <<CONF
# Written by guidebake's scripts/slurm/local-cluster.sh: a single-node cluster on $host.
ClusterName=guidebake
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d
SlurmctldPidFile=/run/slurmctld-guidebake.pid
SlurmdPidFile=/run/slurmd-guidebake.pid
SlurmctldLogFile=$logs/slurmctld.log
SlurmdLogFile=$logs/slurmd.log
NodeName=$host CPUs=$cpus RealMemory=$memory_mb State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
echo "CgroupPlugin=autodetect" >"$conf/cgroup.conf"

stop
chown munge:munge /run/munge
if [[ ! -s /etc/munge/munge.key ]]; then
    mungekey --create --keyfile=/etc/munge/munge.key
    chown munge:munge /etc/munge/munge.key
fi
runuser -u munge -- munged --pid-file=/run/munge/munged-guidebake.pid
slurmctld -f "$conf/slurm.conf"
slurmd -f "$conf/slurm.conf"

# The node comes up within seconds; wait for it to accept jobs.
for _ in $(seq 60); do
    if sinfo -h -N -o '%T' 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
        sinfo -N
        exit 0
    fi
    sleep 1
done
echo "local-cluster.sh: the Slurm node did not become idle within 60 s; see $logs/" >&2
sinfo -N >&2 || true
tail -n 20 "$logs"/*.log >&2 || true
exit 1
