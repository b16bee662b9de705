#!/usr/bin/env bash
# Training recipe of the shipped pretrained GeGnn (docs/model-card.md), after data.sh:
#   bash pipelines/pretrained/train.sh data/ runs/
# Phase 1 ran 13 min and phase 2 85 min on a 2-core CPU. On a GPU the same commands use it (bf16
# autocast); a killed phase continues with the same command plus --resume.
set -euo pipefail
data=${1:?usage: train.sh DATA_DIR RUNS_DIR}
runs=${2:?usage: train.sh DATA_DIR RUNS_DIR}

# Phase 1: the 114 man-made meshes alone (600k pairs each; 4 held out by id hash), 64 channels.
geodata prepare ../shared/meshes/train "$data/manmade.zarr" --pairs 600000 --jobs 2
gegnn train "$data/manmade.zarr" --run "$runs/run1" --epochs 12 --batch-size 4 --pairs-per-mesh 20000 \
    --lr 2e-3 --warmup-epochs 0.5 --channels 64

# Phase 2: all training meshes and variants, validated on the fixed classic-mesh list.
gegnn train "$data/train.zarr" --val "$data/val.zarr" --run "$runs/pre1" --init "$runs/run1/best.safetensors" \
    --epochs 27 --batch-size 4 --pairs-per-mesh 20000 --lr 2e-3 --warmup-epochs 0.5 --clip-grad 1.0

gegnn export "$runs/pre1/best.safetensors" gegnn/weights/gegnn-classic-v1.safetensors --dtype fp16
python benchmarks/bench_results.py "$data/val.zarr"   # docs/results.md
