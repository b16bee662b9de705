#!/usr/bin/env bash
# The whole chain: prepare (array) -> biharmonic (array) -> train, each starting when the last succeeded.
#   pipelines/slurm/submit.sh RAW_DIR OUT RUN [SHARDS] [NODES] [SECTION WORD...]...
# A SECTION is one of the words below; the words after it, up to the next section word, go where it says,
# each as the one argument it is on this command line (quote a path with spaces as on any command line):
#   --prepare WORD...      to geodata prepare         --sbatch WORD...             to every sbatch
#   --biharmonic WORD...   to geodata biharmonic      --sbatch-prepare WORD...     to the prepare array's
#   --train WORD...        to gegnn train             --sbatch-biharmonic WORD...  to the biharmonic array's
#                                                     --sbatch-train WORD...       to the training job's
# e.g.  submit.sh /data/shapenet /scratch/geo.zarr /scratch/run 200 4 --prepare --exclude "/data/my list.txt" \
#           --sbatch --account=lab --sbatch-train --partition=gpu --gpus-per-node=4 --cpus-per-task=32
# A stage's own sbatch flags follow the common ones, so they win. Logs go to ./logs, and so does the chain's
# record, logs/chain-PREPARE_JOB.sh: if a shard fails or is cancelled, pipelines/slurm/recover.sh takes it.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
usage="usage: submit.sh RAW_DIR OUT RUN [SHARDS] [NODES] [--prepare WORD...] [--biharmonic WORD...] [--train WORD...]
       [--sbatch WORD...] [--sbatch-prepare WORD...] [--sbatch-biharmonic WORD...] [--sbatch-train WORD...]"
positional=(); prepare_opts=(); biharmonic_opts=(); train_opts=()
sbatch=(); sbatch_prepare=(); sbatch_biharmonic=(); sbatch_train=()
section=""
for word in ${1+"$@"}; do
    case $word in
        --prepare|--biharmonic|--train|--sbatch|--sbatch-prepare|--sbatch-biharmonic|--sbatch-train)
            section=$word; continue ;;
    esac
    name=${word%%=*}
    if [[ $word == -* && ( $name == *[[:space:]]* || $word == *[[:space:]]-* ) ]]; then  # --sbatch "--a --b"
        echo "submit.sh: '$word' is several words in one: give each its own (--prepare --pairs 2000 --strict)" >&2
        exit 2
    fi
    case $section in
        "") [[ $word == -* ]] && { echo "$usage" >&2; exit 2; }; positional+=("$word") ;;
        --prepare) prepare_opts+=("$word") ;;
        --biharmonic) biharmonic_opts+=("$word") ;;
        --train) train_opts+=("$word") ;;
        --sbatch) sbatch+=("$word") ;;
        --sbatch-prepare) sbatch_prepare+=("$word") ;;
        --sbatch-biharmonic) sbatch_biharmonic+=("$word") ;;
        --sbatch-train) sbatch_train+=("$word") ;;
    esac
done
(( ${#positional[@]} >= 3 && ${#positional[@]} <= 5 )) || { echo "$usage" >&2; exit 2; }
raw=${positional[0]}; out=${positional[1]}; run=${positional[2]}
shards=${positional[3]:-100}; nodes=${positional[4]:-1}
[[ $shards =~ ^[1-9][0-9]*$ && $nodes =~ ^[1-9][0-9]*$ ]] || { echo "$usage" >&2; exit 2; }
prepare_flags=(${sbatch[@]+"${sbatch[@]}"} ${sbatch_prepare[@]+"${sbatch_prepare[@]}"})
biharmonic_flags=(${sbatch[@]+"${sbatch[@]}"} ${sbatch_biharmonic[@]+"${sbatch_biharmonic[@]}"})
train_flags=(${sbatch[@]+"${sbatch[@]}"} ${sbatch_train[@]+"${sbatch_train[@]}"})
mkdir -p logs
array=(sbatch --parsable --array="0-$((shards - 1))" --output="logs/%x-%A_%a.log")
prepare=$(${array[@]+"${array[@]}"} ${prepare_flags[@]+"${prepare_flags[@]}"} "$here/prepare.sbatch" "$raw" "$out" "$shards" \
    ${prepare_opts[@]+"${prepare_opts[@]}"})
prepare=${prepare%%;*}  # --parsable prints "id;cluster" on a federation

# The chain's record for recover.sh: bash it sources (every value quoted by printf %q), jobs appended as they
# are submitted.
chain=$PWD/logs/chain-$prepare.sh
record() {  # NAME [VALUE...]: one bash array assignment
    printf '%s=(' "$1"; shift
    (( $# )) && printf ' %q' "$@"
    printf ' )\n'
}
{
    echo "# The SLURM chain submitted by pipelines/slurm/submit.sh; pipelines/slurm/recover.sh reads it."
    printf 'submit_dir=%q\nscripts=%q\nraw=%q\nout=%q\nrun=%q\nshards=%q\nnodes=%q\n' "$PWD" "$here" "$raw" "$out" \
        "$run" "$shards" "$nodes"
    record prepare_opts ${prepare_opts[@]+"${prepare_opts[@]}"}
    record biharmonic_opts ${biharmonic_opts[@]+"${biharmonic_opts[@]}"}
    record train_opts ${train_opts[@]+"${train_opts[@]}"}
    record prepare_flags ${prepare_flags[@]+"${prepare_flags[@]}"}
    record biharmonic_flags ${biharmonic_flags[@]+"${biharmonic_flags[@]}"}
    record train_flags ${train_flags[@]+"${train_flags[@]}"}
    record prepare_jobs "$prepare"
} > "$chain"
biharmonic=$(${array[@]+"${array[@]}"} --dependency="afterok:$prepare" ${biharmonic_flags[@]+"${biharmonic_flags[@]}"} \
    "$here/biharmonic.sbatch" "$out" "$shards" ${biharmonic_opts[@]+"${biharmonic_opts[@]}"})
biharmonic=${biharmonic%%;*}
record biharmonic_jobs "$biharmonic" >> "$chain"
train=$(sbatch --parsable --nodes="$nodes" --output="logs/%x-%j.log" --dependency="afterok:$biharmonic" \
    ${train_flags[@]+"${train_flags[@]}"} "$here/train.sbatch" "$out" "$run" ${train_opts[@]+"${train_opts[@]}"})
train=${train%%;*}
record train_jobs "$train" >> "$chain"
echo "prepare $prepare -> biharmonic $biharmonic -> train $train"
echo "if a task fails or is cancelled: $here/recover.sh $chain"
