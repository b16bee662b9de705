#!/usr/bin/env bash
# The shipped point-cloud GeGnn (gegnn/weights/gegnn-points-v3.safetensors, "points"; docs/model-card.md) and its
# side-by-side tables (docs/pointclouds.md) against points-v2, after pipelines/pretrained/data.sh:
#     bash pipelines/points/ship.sh data/ runs/ [NEUROGF_REPO]
# NEUROGF_REPO: a checkout of github.com/keeganhk/NeuroGF for its column (left out without it).
# points-v2 and points-v1 were made the same way from landmark-v2 and landmark-v1 (pipelines/landmark/ship.sh).
set -euo pipefail
data=${1:?usage: ship.sh DATA_DIR RUNS_DIR [NEUROGF_REPO]}
runs=${2:?usage: ship.sh DATA_DIR RUNS_DIR [NEUROGF_REPO]}
neurogf=${3:-}
mkdir -p "$runs"

# The landmark model's weights as they are, read as a point-cloud model (8 neighbours; landmark-v3's fields by
# virtual sources, on the cloud's local triangles).
gegnn export gegnn/weights/gegnn-landmark-v3.safetensors gegnn/weights/gegnn-points-v3.safetensors --neighbors 8

# Area-uniform surface points per validation mesh with exact distances between them (the `surface` kind):
# 8,000 in the store itself, 32,000 in a copy made before (a store holds one points subgroup a mesh): the
# copy without the 8k points (meshes/<id>.points.zip) or their failure records (failed/<id>.points).
[ -d "$data/val-32k.zarr" ] || { cp -r "$data/val.zarr" "$data/val-32k.zarr" &&
    rm -rf "$data"/val-32k.zarr/meshes/*.points.zip "$data"/val-32k.zarr/failed/*.points; }
geodata points "$data/val.zarr" --points 8000 --pairs 160000
geodata points "$data/val-32k.zarr" --points 32000 --pairs 160000

for v in v3 v2; do
    OMP_NUM_THREADS=1 python benchmarks/bench_points.py "$data/val.zarr" --model gegnn/weights/gegnn-points-$v.safetensors \
        --kinds clean noisy density 2k surface normals ${neurogf:+--neurogf "$neurogf"} --csv "$runs/bench-points-$v.csv"
done
OMP_NUM_THREADS=1 python benchmarks/bench_points.py "$data/val-32k.zarr" --model gegnn/weights/gegnn-points-v3.safetensors \
    --kinds surface ${neurogf:+--neurogf "$neurogf"} --csv "$runs/bench-points-32k.csv"
OMP_NUM_THREADS=1 gegnn eval gegnn/weights/gegnn-points-v3.safetensors "$data/val.zarr"
