#!/usr/bin/env bash
# Ablation of the landmark-guided GeGnn (docs/results.md), after pipelines/pretrained/data.sh. Every
# variant trains the same steps on the same data and is scored on all stored pairs of the validation
# meshes; RUNS/ablation.md gets the table. A killed ablation continues with the same command.
#   bash pipelines/landmark/ablation.sh DATA_DIR RUNS_DIR [EPOCHS] [PARALLEL]
# PARALLEL (default 2) runs that many variants at once, one thread each.
set -euo pipefail
data=${1:?usage: ablation.sh DATA_DIR RUNS_DIR [EPOCHS] [PARALLEL]}
runs=${2:?usage: ablation.sh DATA_DIR RUNS_DIR [EPOCHS] [PARALLEL]}
epochs=${3:-1}
parallel=${4:-2}
paper=gegnn/weights/gegnn-classic-v1.safetensors
common="--val $data/val.zarr --epochs $epochs --batch-size 4 --pairs-per-mesh 20000 --lr 1e-3 --warmup-epochs 0.1 --clip-grad 1.0 --resume"

variants=(
  "k128            --init $paper --landmarks 128 --decoder-warmup 3000"
  "k64             --init $paper --landmarks 64 --decoder-warmup 3000"
  "k128-no-embed   --init $paper --landmarks 128 --decoder-warmup 3000 --landmark-no-embedding"
  "k128-interval   --init $paper --landmarks 128 --decoder-warmup 3000 --landmark-output interval"
  "k128-no-warmup  --init $paper --landmarks 128"
  "paper-more      --init $paper"
)
mkdir -p "$runs"
printf '%s\n' "${variants[@]}" | xargs -P "$parallel" -I{} bash -c '
  set -euo pipefail
  read -r name args <<< "{}"
  [ -f '"$runs"'/$name/eval.csv ] && exit 0  # done
  OMP_NUM_THREADS=1 gegnn train '"$data"'/train.zarr --run '"$runs"'/$name '"$common"' $args > '"$runs"'/$name.log 2>&1
  OMP_NUM_THREADS=1 gegnn eval '"$runs"'/$name/best.safetensors '"$data"'/val.zarr --csv '"$runs"'/$name/eval.csv >> '"$runs"'/$name.log 2>&1
  echo "$name done"'
python benchmarks/ablation_landmarks.py "$data/val.zarr" "$runs" | tee "$runs/ablation.md"
