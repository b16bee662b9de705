#!/usr/bin/env bash
# Training recipe of the shipped landmark-guided GeGnn (docs/model-card.md), after
# pipelines/pretrained/data.sh:   bash pipelines/landmark/train.sh data/ runs/
# Starts from the network of the shipped paper model; ran 80 min on one thread of a 2-core CPU. A
# killed run continues with the same command (--resume is in it).
set -euo pipefail
data=${1:?usage: train.sh DATA_DIR RUNS_DIR}
runs=${2:?usage: train.sh DATA_DIR RUNS_DIR}

gegnn train "$data/train.zarr" --val "$data/val.zarr" --run "$runs/lm128" \
    --init gegnn/weights/gegnn-classic-v1.safetensors --landmarks 128 --decoder-warmup 4000 \
    --epochs 8 --batch-size 4 --pairs-per-mesh 20000 --lr 3e-4 --warmup-epochs 0.1 --clip-grad 1.0 --resume

gegnn export "$runs/lm128/best.safetensors" gegnn/weights/gegnn-landmark-v1.safetensors --dtype fp16
bash pipelines/landmark/ablation.sh "$data" "$runs/ablation"
python benchmarks/bench_results.py "$data/val.zarr" --ablation "$runs/ablation/ablation.md"   # docs/results.md
