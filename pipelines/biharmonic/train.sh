#!/usr/bin/env bash
# The shipped biharmonic GeGnn (gegnn/weights/gegnn-biharmonic-v1.safetensors; docs/model-card.md) and
# its ablation, after pipelines/pretrained/data.sh:   bash pipelines/biharmonic/train.sh data/ runs/
# On the 2-core development CPU, one thread each (the times in docs/model-card.md). A killed run continues with the same command (--resume is in it).
set -euo pipefail
export OMP_NUM_THREADS=1  # one thread per run: two runs at once on the 2 cores
data=${1:?usage: train.sh DATA_DIR RUNS_DIR}
runs=${2:?usage: train.sh DATA_DIR RUNS_DIR}

# Exact biharmonic distances (Lipman et al. 2010) of every validation and training mesh (~1.5 s a mesh).
geodata biharmonic "$data/val.zarr" --pairs 200000 --jobs 2
geodata biharmonic "$data/train.zarr" --pairs 100000 --jobs 2

common="--distance biharmonic --val $data/val.zarr --batch-size 4 --pairs-per-mesh 20000 --clip-grad 1.0 --resume"
landmark=gegnn/weights/gegnn-landmark-v1.safetensors

# 1. Shipped: the landmark model's network (its embeddings describe the shape), 32 spectral modes and
#    their Weyl-law tail; the decoder's correction fitted on the frozen codes, then one end-to-end
#    epoch at a low rate.
gegnn train "$data/train.zarr" --run "$runs/bih-s32" $common --init $landmark --spectral 32 \
    --decoder-warmup 6000 --epochs 1 --lr 1e-4 --warmup-epochs 0.1
gegnn export "$runs/bih-s32/best.safetensors" gegnn/weights/gegnn-biharmonic-v1.safetensors --dtype fp16

# 2. Ablation: the correction without the embeddings (spectral features only). Its number is the val_mre
#    after the decoder warm-up in its train.log (the epoch at lr 0 changes nothing; stop it there).
gegnn train "$data/train.zarr" --run "$runs/bih-s32-noembed" $common --init $landmark --spectral 32 \
    --spectral-no-embedding --decoder-warmup 6000 --epochs 1 --lr 0 --warmup-epochs 0 \
    --field-cache "$runs/bih-s32/fields"

# 3. The pure learned model (no eigen-solve; the paper's claim): the paper model's network with the
#    Euclidean decoder (a biharmonic distance is a Euclidean distance of an embedding), end to end.
gegnn train "$data/train.zarr" --run "$runs/bih-pure" $common --init gegnn/weights/gegnn-classic-v1.safetensors \
    --euclidean-decoder --epochs 3 --lr 1e-3 --warmup-epochs 0.2

# Tables of docs/results.md ("Biharmonic distances").
python benchmarks/bench_biharmonic_model.py "$data/val.zarr" --checkpoint "$runs/bih-s32/best.safetensors" \
    --pure "$runs/bih-pure/best.safetensors" --out "$runs/biharmonic-table.md"
