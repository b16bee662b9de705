#!/usr/bin/env bash
# More landmarks for the landmark-guided GeGnn (docs/model-card.md, "K ablation"), after
# pipelines/pretrained/data.sh:   bash pipelines/landmark/more_landmarks.sh data/ runs/ K
# Starts from the shipped gegnn-landmark-v1 (trained at K = 128): its network and its decoder, whose
# weights do not depend on K; then 20,000 decoder steps on the frozen network's codes at K landmarks and
# one gentle end-to-end epoch, as phase 2 of pipelines/landmark/train.sh. K = 128 is the control: the
# same extra training without more landmarks. One thread of a 2-core CPU; a killed run continues with the
# same command (--resume is in it).
set -euo pipefail
data=${1:?usage: more_landmarks.sh DATA_DIR RUNS_DIR K}
runs=${2:?usage: more_landmarks.sh DATA_DIR RUNS_DIR K}
k=${3:?usage: more_landmarks.sh DATA_DIR RUNS_DIR K}

OMP_NUM_THREADS=1 gegnn train "$data/train.zarr" --val "$data/val.zarr" --run "$runs/lm$k-v2" --resume \
    --batch-size 4 --pairs-per-mesh 20000 --warmup-epochs 0.1 --clip-grad 1.0 --epochs 1 --lr 1e-4 \
    --init gegnn/weights/gegnn-landmark-v1.safetensors --landmarks "$k" --decoder-warmup 20000
