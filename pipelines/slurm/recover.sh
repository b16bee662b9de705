#!/usr/bin/env bash
# Recover a chain after a failed, cancelled or timed-out task: rerun the stage it belongs to, and let the
# stages waiting on it wait again (SLURM marks them DependencyNeverSatisfied and never releases them itself).
#   pipelines/slurm/recover.sh PREPARE_JOB BIHARMONIC_JOB TRAIN_JOB      (the ids submit.sh printed)
# A stage is requeued whole: its shards skip the meshes they committed, so the shards that had finished end
# in seconds; training resumes. A task cancelled before it ever started leaves SLURM no record to requeue:
# resubmit that shard alone (sbatch --array=K prepare.sbatch RAW_DIR OUT SHARDS, same flags), then
#   pipelines/slurm/recover.sh NEW_JOB BIHARMONIC_JOB TRAIN_JOB
set -euo pipefail
(( $# >= 1 )) || { echo "usage: recover.sh JOB [JOB...] (the chain's job ids, in order)" >&2; exit 2; }
jobs=("$@")
states() { scontrol -o show job "$1" 2>/dev/null | grep -oE "JobState=[A-Z_]+" | sort -u || true; }
stuck() { scontrol -o show job "$1" 2>/dev/null | grep -q "Reason=DependencyNeverSatisfied"; }
for i in "${!jobs[@]}"; do
    job=${jobs[$i]}
    next=${jobs[$((i + 1))]:-}
    if states "$job" | grep -qvE "JobState=(COMPLETED|PENDING|RUNNING|CONFIGURING|COMPLETING|REQUEUED)" \
        || { [ -n "$next" ] && stuck "$next"; }; then
        scontrol requeue "$job" && echo "requeued $job"
        # Release what waits on it only once it is queued again: a dependency checked while the job is
        # being requeued counts its tasks as failed once more.
        for _ in $(seq 60); do
            [ "$(states "$job")" = "JobState=PENDING" ] && break
            sleep 1
        done
    fi
    if (( i > 0 )) && stuck "$job"; then
        prev=${jobs[$((i - 1))]}
        # afterok on an array id stays failed once any task failed, even after the task succeeds on a
        # requeue: wait on each task instead, or on nothing where they all completed.
        tasks=$(squeue -h -r -t all -j "$prev" -o %i 2>/dev/null | paste -sd: || true)
        if [ -z "$tasks" ]; then  # its records are gone: it completed long ago
            scontrol update JobId="$job" Dependency= && echo "released $job"
        else
            scontrol update JobId="$job" Dependency="afterok:$tasks" && echo "released $job"
        fi
    fi
done
