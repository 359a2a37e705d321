#!/usr/bin/env bash
# A single-node Slurm cluster on localhost (munged, slurmctld, slurmd), all state under one folder.
#
#   cluster/slurm_local.sh start [DIR]   # DIR: default /tmp/topoloc-slurm; prints the line to export
#   export SLURM_CONF=DIR/slurm.conf     # sbatch, squeue, sacct and Snakemake's Slurm executor use it
#   cluster/slurm_local.sh stop [DIR]    # stops the three daemons started by `start`
#
# Needs Debian's slurm-wlm and munge (apt-get install slurm-wlm munge) and root (the daemons run as root, the
# munge daemon as user munge); /etc/slurm/slurm.conf links to DIR/slurm.conf while it runs (srun inside a
# job reads that path). No accounting database: sacct reads the jobs from slurmctld, which keeps
# finished jobs for MinJobAge (a day); every finished job is also appended to DIR/jobcomp.txt.
# CPUS and MEM_MB (environment) size the node: default all cores and 3/4 of the memory; SLURMCTLD_PORT and
# SLURMD_PORT (default 6817, 6818) its ports.
set -euo pipefail

command=${1:-}
dir=$(realpath -m "${2:-/tmp/topoloc-slurm}")
conf="$dir/slurm.conf"

stop() {
    # the link start made (srun inside a job reads the default path, not SLURM_CONF)
    if [[ -L /etc/slurm/slurm.conf && "$(readlink /etc/slurm/slurm.conf)" == "$conf" ]]; then
        rm -f /etc/slurm/slurm.conf
    fi
    for name in slurmd slurmctld munged; do
        if [[ -f "$dir/$name.pid" ]]; then
            pid=$(cat "$dir/$name.pid")
            kill "$pid" 2>/dev/null || true
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            rm -f "$dir/$name.pid"
        fi
    done
}

start() {
    for binary in munged slurmctld slurmd sbatch sacct; do
        command -v "$binary" >/dev/null || { echo "slurm_local.sh: $binary not found (apt-get install slurm-wlm munge)" >&2; exit 2; }
    done
    stop
    mkdir -p "$dir/state" "$dir/spool" "$dir/munge" "$dir/munge-socket"
    chown munge: "$dir/munge" "$dir/munge-socket"
    chmod 700 "$dir/munge"
    chmod 755 "$dir/munge-socket"
    [[ -f "$dir/munge/munge.key" ]] || { dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none; }
    chown munge: "$dir/munge/munge.key"
    chmod 400 "$dir/munge/munge.key"
    local host cpus mem
    host=$(hostname -s)
    cpus=${CPUS:-$(nproc)}
    mem=${MEM_MB:-$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) * 3 / 4 / 1024 ))}
    cat > "$conf" <<EOF
ClusterName=topoloc
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$dir/munge-socket/munge.socket
CredType=cred/munge
SlurmctldPort=${SLURMCTLD_PORT:-6817}
SlurmdPort=${SLURMD_PORT:-6818}
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/filetxt
JobCompLoc=$dir/jobcomp.txt
MinJobAge=86400
SlurmdTimeout=300
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=main Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
    mkdir -p /etc/slurm
    if [[ -e /etc/slurm/slurm.conf && ! -L /etc/slurm/slurm.conf ]]; then
        echo "slurm_local.sh: /etc/slurm/slurm.conf exists: a Slurm is configured on this machine already" >&2
        exit 2
    fi
    ln -sfn "$conf" /etc/slurm/slurm.conf
    runuser -u munge -- munged --socket="$dir/munge-socket/munge.socket" --key-file="$dir/munge/munge.key" \
        --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" --seed-file="$dir/munge/munged.seed"
    cp "$dir/munge/munged.pid" "$dir/munged.pid"
    SLURM_CONF="$conf" slurmctld -f "$conf"
    SLURM_CONF="$conf" slurmd -f "$conf"
    for _ in $(seq 100); do
        if SLURM_CONF="$conf" sinfo -h -o %T 2>/dev/null | grep -qx idle; then
            echo "export SLURM_CONF=$conf"
            return 0
        fi
        sleep 0.2
    done
    echo "slurm_local.sh: the node did not come up; see $dir/slurmctld.log and $dir/slurmd.log" >&2
    stop
    exit 1
}

case "$command" in
    start) start ;;
    stop) stop ;;
    *) echo "usage: $0 start|stop [DIR]" >&2; exit 2 ;;
esac
