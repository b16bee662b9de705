#!/usr/bin/env bash
# The whole chain: prepare (array) -> biharmonic (array) -> train, each starting when the last succeeded.
#   pipelines/slurm/submit.sh RAW_DIR OUT RUN [SHARDS] [NODES] [--prepare "OPTIONS"] [--biharmonic "OPTIONS"]
#                             [--train "OPTIONS"] [--sbatch "FLAGS"]
# Each quoted OPTIONS goes to its stage's command (geodata prepare, geodata biharmonic, gegnn train), FLAGS to
# every sbatch (site resources: --partition, --account, --gpus-per-node=4, --cpus-per-task, --mem). Logs go to
# ./logs. If a shard fails or is cancelled: pipelines/slurm/recover.sh, with the job ids printed here.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
usage="usage: submit.sh RAW_DIR OUT RUN [SHARDS] [NODES] [--prepare OPTS] [--biharmonic OPTS] [--train OPTS] [--sbatch FLAGS]"
positional=(); prepare_opts=""; biharmonic_opts=""; train_opts=""; sbatch_flags=""
while (( $# )); do
    case $1 in
        --prepare) prepare_opts=${2?$usage}; shift 2 ;;
        --biharmonic) biharmonic_opts=${2?$usage}; shift 2 ;;
        --train) train_opts=${2?$usage}; shift 2 ;;
        --sbatch) sbatch_flags=${2?$usage}; shift 2 ;;
        -*) echo "$usage" >&2; exit 2 ;;
        *) positional+=("$1"); shift ;;
    esac
done
raw=${positional[0]:?$usage}; out=${positional[1]:?$usage}; run=${positional[2]:?$usage}
shards=${positional[3]:-100}; nodes=${positional[4]:-1}
read -ra prepare_opts <<< "$prepare_opts"; read -ra biharmonic_opts <<< "$biharmonic_opts"
read -ra train_opts <<< "$train_opts"; read -ra sbatch_flags <<< "$sbatch_flags"
mkdir -p logs
array=(sbatch --parsable --array="0-$((shards - 1))" --output="logs/%x-%A_%a.log" "${sbatch_flags[@]}")
prepare=$("${array[@]}" "$here/prepare.sbatch" "$raw" "$out" "$shards" "${prepare_opts[@]}")
biharmonic=$("${array[@]}" --dependency="afterok:$prepare" "$here/biharmonic.sbatch" "$out" "$shards" \
    "${biharmonic_opts[@]}")
train=$(sbatch --parsable --nodes="$nodes" --output="logs/%x-%j.log" --dependency="afterok:$biharmonic" \
    "${sbatch_flags[@]}" "$here/train.sbatch" "$out" "$run" "${train_opts[@]}")
echo "prepare $prepare -> biharmonic $biharmonic -> train $train"
echo "if a task fails: $here/recover.sh $prepare $biharmonic $train"
