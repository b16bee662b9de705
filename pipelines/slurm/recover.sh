#!/usr/bin/env bash
# Recover a chain after a failed, cancelled, timed-out or lost task, from what the STORE holds, not from
# SLURM's records (SLURM forgets a finished job after MinJobAge, 300 s by default, and then knows nothing):
#   pipelines/slurm/recover.sh logs/chain-PREPARE_JOB.sh        (the file submit.sh printed)
# Stage by stage: each shard is asked of the store (geodata prepare|biharmonic ... --shard K/N --check,
# which does no work: exit 0 done, 3 not yet). A shard not done and not queued or running in SLURM is
# resubmitted alone (sbatch --array=K,..., the stage's flags and options as submitted); nothing queued or
# running is cancelled or requeued. The next stage then waits on exactly the jobs that still have shards to
# finish, or is released where the store has them all; a stage after one that is not done is not asked (on
# a store that misses meshes its shards would look done): it waits. Exits non-zero, naming the shards, when
# the store or SLURM cannot say (an exit of --check other than 0 or 3, squeue failing) or a resubmission
# fails: then nothing after that stage is released. Run it again whenever a stage is stuck
# (DependencyNeverSatisfied); it is safe to run at any time. RECOVER_CHECKS shards are asked at once (4).
set -euo pipefail
usage="usage: recover.sh logs/chain-PREPARE_JOB.sh (the chain's record, printed by submit.sh)"
if (( $# != 1 )) || [ ! -f "$1" ]; then echo "$usage" >&2; exit 2; fi
chain=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
submit_dir="" scripts="" raw="" out="" run="" shards="" nodes=""
prepare_opts=() biharmonic_opts=() train_opts=() prepare_flags=() biharmonic_flags=() train_flags=()
prepare_jobs=() biharmonic_jobs=() train_jobs=()
# shellcheck source=/dev/null
. "$chain"
cd "$submit_dir"  # the record's relative paths and logs/ are the submitter's
fail() { echo "recover.sh: $*" >&2; exit 1; }

# What SLURM runs: "ARRAY_JOB TASK STATE" per task (TASK is N/A for a job that is not an array).
queue=$(squeue -h -r -u "$(id -un)" -o '%F %K %T') || fail "squeue failed: cannot tell what is queued; nothing done"

queued() {  # JOB...: "JOB TASK" for each of their tasks that is queued or running (not ending)
    local job
    for job in "$@"; do
        awk -v job="$job" '$1 == job && $3 ~ /^(PENDING|RUNNING|CONFIGURING|SUSPENDED|REQUEUED|REQUEUE_HOLD|REQUEUE_FED|RESIZING)$/ {
            print $1, $2 }' <<< "$queue"
    done
}

incomplete() {  # STAGE: the shards of STAGE the store has not finished, one a line; fails if it cannot tell
    local stage=$1 tmp k first argv unknown=()
    tmp=$(mktemp -d)
    for (( first = 0; first < shards; first += ${RECOVER_CHECKS:-4} )); do
        for (( k = first; k < shards && k < first + ${RECOVER_CHECKS:-4}; k++ )); do
            if [ "$stage" = prepare ]; then
                argv=(geodata prepare "$raw" "$out" ${prepare_opts[@]+"${prepare_opts[@]}"})
            else
                argv=(geodata biharmonic "$out" ${biharmonic_opts[@]+"${biharmonic_opts[@]}"})
            fi
            { rc=0; ${argv[@]+"${argv[@]}"} --shard "$k/$shards" --check > "$tmp/$k.out" 2>&1 || rc=$?; echo "$rc" > "$tmp/$k.rc"; } &
        done
        wait
    done
    for (( k = 0; k < shards; k++ )); do
        case $(cat "$tmp/$k.rc") in
            0) ;;
            3) echo "$k"; echo "$stage shard $k/$shards not done: $(tail -n 1 "$tmp/$k.out")" >&2 ;;
            *) unknown+=("$k"); echo "$stage shard $k/$shards: --check failed: $(tail -n 3 "$tmp/$k.out")" >&2 ;;
        esac
    done
    rm -rf "$tmp"
    (( ${#unknown[@]} == 0 )) || fail "the store cannot say whether $stage shards ${unknown[*]-} are done;" \
        "nothing after $stage released"
}

resubmit() {  # STAGE DEPENDENCY SHARD...: submit these shards of STAGE again; prints the new job's id
    local stage=$1 dependency=$2 ids job argv
    shift 2
    ids=$(IFS=,; echo "$*")
    argv=(sbatch --parsable --array="$ids" --output="logs/%x-%A_%a.log")
    [ -n "$dependency" ] && argv+=(--dependency="$dependency")
    if [ "$stage" = prepare ]; then
        argv+=(${prepare_flags[@]+"${prepare_flags[@]}"} "$scripts/prepare.sbatch" "$raw" "$out" "$shards"
                  ${prepare_opts[@]+"${prepare_opts[@]}"})
    else
        argv+=(${biharmonic_flags[@]+"${biharmonic_flags[@]}"} "$scripts/biharmonic.sbatch" "$out" "$shards"
                  ${biharmonic_opts[@]+"${biharmonic_opts[@]}"})
    fi
    job=$(${argv[@]+"${argv[@]}"}) || fail "resubmitting $stage shards $ids failed; nothing after $stage released"
    job=${job%%;*}
    printf '%s_jobs+=(%q)\n' "$stage" "$job" >> "$chain"
    echo "$stage shards $ids resubmitted: job $job" >&2
    echo "$job"
}

dependency_ids() {  # "afterok:55_*(unfulfilled):54_1" or "afterok:55:54_1" -> "54_1 55": the jobs waited on
    grep -oE '[0-9]+(_[0-9]+)?' <<< "${1#*:}" | sort -u | paste -sd' ' || true
}

wait_on() {  # JOB DEPENDENCY: let the pending tasks of JOB wait on DEPENDENCY ("" releases them)
    if [ -n "$(awk -v job="$1" '$1 == job && $3 == "PENDING"' <<< "$queue")" ]; then
        local now
        now=$(scontrol -o show job "$1" 2>/dev/null | grep -oE 'Dependency=[^ ]+' | head -1 || true)
        now=${now#Dependency=}; [ "$now" = "(null)" ] && now=""
        # Already waiting on exactly these jobs: no update (SLURM 22.05 refused one such, "Requested partition
        # configuration not available now", on a job it had accepted unchanged).
        if [ -n "$2" ] && [ -n "$now" ] && [ "$(dependency_ids "$now")" = "$(dependency_ids "$2")" ]; then
            echo "$1 waits on ${2#afterok:}"
            return 0
        fi
        # A busy controller may refuse for a moment ("Requested partition configuration not available now"
        # while a node does not respond): three tries, 5 s apart, then fail loudly.
        local try
        for try in 1 2 3; do
            scontrol update JobId="$1" Dependency="$2" && break
            [ "$try" = 3 ] && fail "scontrol could not update job $1"
            sleep 5
        done
        if [ -n "$2" ]; then echo "$1 waits on ${2#afterok:}"; else echo "released $1"; fi
    fi
}

# Each array stage, in order. "after" is what the next stage must wait on: "" when this stage is done.
after=""; settled=1
for stage in prepare biharmonic; do
    if [ "$stage" = prepare ]; then
        stage_jobs=(${prepare_jobs[@]+"${prepare_jobs[@]}"})
    else
        stage_jobs=(${biharmonic_jobs[@]+"${biharmonic_jobs[@]}"})
    fi
    tasks=$(queued ${stage_jobs[@]+"${stage_jobs[@]}"})
    if (( settled )); then
        if [ "$stage" != prepare ]; then  # the stage before is done: nothing to wait on
            for job in ${stage_jobs[@]+"${stage_jobs[@]}"}; do wait_on "$job" ""; done
        fi
        todo=$(incomplete "$stage")
        waits=(); missing=()
        for k in $todo; do
            task=$(awk -v k="$k" '$2 == k {print $1 "_" $2; exit}' <<< "$tasks")
            if [ -n "$task" ]; then waits+=("$task"); else missing+=("$k"); fi
        done
        if (( ${#missing[@]} )); then
            job=$(resubmit "$stage" "" ${missing[@]+"${missing[@]}"})
            waits+=("$job")
        fi
        if [ -z "$todo" ]; then
            echo "$stage: every shard done"
        else
            settled=0; after="afterok:$(IFS=:; echo "${waits[*]-}")"
        fi
    else  # the stage before is not done: this one waits on it, queued again if SLURM has nothing of it
        waiting=$(awk '{print $1}' <<< "$tasks" | sort -u)
        if [ -z "$waiting" ]; then
            all=$(seq -s ' ' 0 $((shards - 1)))
            # shellcheck disable=SC2086  # the shard numbers, one word each
            waiting=$(resubmit "$stage" "$after" $all)
        else
            for job in $waiting; do wait_on "$job" "$after"; done
        fi
        after="afterok:$(paste -sd: <<< "$waiting")"
    fi
done

# Training: no store check of its own; it waits on the biharmonic stage or starts, and resumes when rerun.
train_tasks=$(queued ${train_jobs[@]+"${train_jobs[@]}"})
if [ -n "$train_tasks" ]; then
    mapfile -t train_waiting < <(awk '{print $1}' <<< "$train_tasks" | sort -u)
    for job in ${train_waiting[@]+"${train_waiting[@]}"}; do wait_on "$job" "$after"; done
else
    last="" state=""
    if (( ${#train_jobs[@]} )); then
        last=${train_jobs[${#train_jobs[@]}-1]}
        state=$(scontrol -o show job "$last" 2>/dev/null | grep -oE "JobState=[A-Z_]+" || true)
    else  # submit.sh's sbatch for training failed (a typo in --sbatch-train, a partition refused): never ran
        echo "train: the chain's record has no training job (its submission failed): submitting it" >&2
    fi
    if [ -n "$last" ] && [ "$state" = "JobState=COMPLETED" ] && (( settled )); then
        echo "train: job $last completed"
    elif [ -n "$last" ] && [ -z "$state" ] && (( settled )); then
        fail "SLURM no longer knows training job $last and it is not queued: whether it finished is in" \
            "$run/train.log; to train (resuming from $run/last.safetensors), run sbatch" \
            "${train_flags[*]-} $scripts/train.sbatch $out $run ${train_opts[*]-}"
    else
        dependency=(); [ -n "$after" ] && dependency=(--dependency="$after")
        job=$(sbatch --parsable --nodes="$nodes" --output="logs/%x-%j.log" ${dependency[@]+"${dependency[@]}"} \
            ${train_flags[@]+"${train_flags[@]}"} "$scripts/train.sbatch" "$out" "$run" \
            ${train_opts[@]+"${train_opts[@]}"}) || fail "submitting training failed; correct its sbatch flags" \
            "(train_flags=(${train_flags[*]-}) in $chain) and run recover.sh again"
        job=${job%%;*}
        printf 'train_jobs+=(%q)\n' "$job" >> "$chain"
        echo "train resubmitted (${state:-no record}): job $job"
    fi
fi
