#!/usr/bin/env bash
# Training recipe of the shipped biharmonic GeGnn (docs/model-card.md), after pipelines/pretrained/data.sh:
#   bash pipelines/biharmonic/train.sh data/ runs/
# One thread of a 2-core CPU. A killed phase continues with the same command (--resume is in it).
set -euo pipefail
data=${1:?usage: train.sh DATA_DIR RUNS_DIR}
runs=${2:?usage: train.sh DATA_DIR RUNS_DIR}

# Exact biharmonic distances (Lipman et al. 2010) for the same meshes and the same pair counts as the
# geodesic ones (about 2 s per mesh).
geodata biharmonic "$data/val.zarr" --pairs 200000 --jobs 2
geodata biharmonic "$data/train.zarr" --pairs 100000 --jobs 2

# The paper model's network and decoder as the start (geodesic and biharmonic distances share the
# local geometry), its decoder re-fitted to the frozen codes first, then end to end.
OMP_NUM_THREADS=1 gegnn train "$data/train.zarr" --distance biharmonic --val "$data/val.zarr" \
    --run "$runs/bih" --init gegnn/weights/gegnn-classic-v1.safetensors --decoder-warmup 4000 \
    --epochs 8 --batch-size 4 --pairs-per-mesh 20000 --lr 1e-3 --warmup-epochs 0.1 --clip-grad 1.0 --resume

gegnn export "$runs/bih/best.safetensors" gegnn/weights/gegnn-biharmonic-v1.safetensors --dtype fp16
gegnn eval gegnn/weights/gegnn-biharmonic-v1.safetensors "$data/val.zarr" --distance biharmonic
