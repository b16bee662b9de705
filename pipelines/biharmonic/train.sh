#!/usr/bin/env bash
# Biharmonic GeGnn experiments (docs/applications.md, "Biharmonic distances"), after
# pipelines/pretrained/data.sh:   bash pipelines/biharmonic/train.sh data/ runs/
# One thread of a 2-core CPU. A killed run continues with the same command (--resume is in it).
# Neither model is useful yet (validation MRE 18-26%), so none is shipped.
set -euo pipefail
data=${1:?usage: train.sh DATA_DIR RUNS_DIR}
runs=${2:?usage: train.sh DATA_DIR RUNS_DIR}
common="--distance biharmonic --val $data/val.zarr --batch-size 4 --pairs-per-mesh 20000 --warmup-epochs 0.1"
common="$common --clip-grad 1.0 --decoder-warmup 4000 --resume"

# Exact biharmonic distances (Lipman et al. 2010) for the same meshes and pair counts as the geodesic
# ones (2 to 6 s per mesh).
geodata biharmonic "$data/val.zarr" --pairs 200000 --jobs 2
geodata biharmonic "$data/train.zarr" --pairs 100000 --jobs 2

# 1. The paper model's network and decoder, the decoder re-fitted on the frozen codes, then end to end:
#    validation 23.6% after the warm-up, 25.0% and 26.1% after epochs 0 and 1 (stopped).
OMP_NUM_THREADS=1 gegnn train "$data/train.zarr" --run "$runs/bih" $common --epochs 8 --lr 1e-3 \
    --init gegnn/weights/gegnn-classic-v1.safetensors

# 2. The landmark model (heat-method *geodesic* landmark fields), its decoder re-fitted: 18.6% after
#    the warm-up, 19.4% after one epoch; 19.4% on all stored pairs (gegnn eval ... --distance biharmonic).
OMP_NUM_THREADS=1 gegnn train "$data/train.zarr" --run "$runs/bih-lm" $common --epochs 1 --lr 3e-4 \
    --init gegnn/weights/gegnn-landmark-v1.safetensors
