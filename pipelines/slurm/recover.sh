#!/usr/bin/env bash
# Recover a chain after a failed, cancelled or timed-out task: rerun the stage it belongs to, and let the
# stages waiting on it wait again (SLURM marks them DependencyNeverSatisfied and never releases them itself).
#   pipelines/slurm/recover.sh PREPARE_JOB BIHARMONIC_JOB TRAIN_JOB      (the ids submit.sh printed)
# A stage is requeued whole (a task cancelled before it started has no record of its own to requeue): its
# shards skip the meshes they committed, so the shards that had finished end in seconds; training resumes.
set -euo pipefail
(( $# >= 1 )) || { echo "usage: recover.sh JOB [JOB...] (the chain's job ids, in order)" >&2; exit 2; }
jobs=("$@")
state() { scontrol -o show job "$1" 2>/dev/null || true; }
for i in "${!jobs[@]}"; do
    job=${jobs[$i]}
    next=${jobs[$((i + 1))]:-}
    if state "$job" | grep -qE "JobState=(FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY|BOOT_FAIL|DEADLINE)" \
        || { [ -n "$next" ] && state "$next" | grep -q "Reason=DependencyNeverSatisfied"; }; then
        scontrol requeue "$job" && echo "requeued $job"
    fi
    if (( i > 0 )) && state "$job" | grep -q "Reason=DependencyNeverSatisfied"; then
        scontrol update JobId="$job" Dependency="afterok:${jobs[$((i - 1))]}" && echo "released $job"
    fi
done
