#!/usr/bin/env bash
# The whole chain: prepare (array) -> biharmonic (array) -> train, each starting when the last succeeded.
#   pipelines/slurm/submit.sh RAW_DIR OUT RUN [SHARDS] [NODES]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
raw=${1:?usage: submit.sh RAW_DIR OUT RUN [SHARDS] [NODES]}; out=${2:?}; run=${3:?}
shards=${4:-100}; nodes=${5:-1}
mkdir -p logs
prepare=$(sbatch --parsable --array="0-$((shards - 1))" "$here/prepare.sbatch" "$raw" "$out")
biharmonic=$(sbatch --parsable --array="0-$((shards - 1))" --dependency="afterok:$prepare" \
    "$here/biharmonic.sbatch" "$out")
train=$(sbatch --parsable --nodes="$nodes" --dependency="afterok:$biharmonic" "$here/train.sbatch" "$out" "$run")
echo "prepare $prepare -> biharmonic $biharmonic -> train $train"
