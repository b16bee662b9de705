#!/usr/bin/env bash
# The shipped landmark-guided models, rebuilt and measured (docs/model-card.md), after
# pipelines/pretrained/data.sh:   bash pipelines/landmark/ship.sh data/ runs/
# landmark-v2 (K = 256, the default until 2026-11-27) from landmark-v1, and its point-cloud twin points-v2; the training on
# at K = 384 (the K ablation's v3, not shipped); then their validation MRE and the default's speed-up over
# the heat method, the shipped models' written to docs/results.json (tests/test_docs_figures.py then names
# every page that must follow).
# landmark-v2 was trained with landmarks chosen one at a time (before 0.3.0, gegnn.fields.landmarks): a
# rebuild now chooses them 16 a round, so it is a model of the same recipe, not the same file.
# One thread of a 2-core CPU for training, ~40-60 min a model; a killed run continues with the same command.
set -euo pipefail
data=${1:?usage: ship.sh DATA_DIR RUNS_DIR}
runs=${2:?usage: ship.sh DATA_DIR RUNS_DIR}
weights=gegnn/weights

bash pipelines/landmark/more_landmarks.sh "$data" "$runs" 256
gegnn export "$runs/lm256-v2/best.safetensors" "$weights/gegnn-landmark-v2.safetensors" --dtype fp16
gegnn export "$weights/gegnn-landmark-v2.safetensors" "$weights/gegnn-points-v2.safetensors" --neighbors 8

bash pipelines/landmark/more_landmarks.sh "$data" "$runs" 384 "$weights/gegnn-landmark-v2.safetensors" lm384-v3
gegnn export "$runs/lm384-v3/best.safetensors" "$runs/gegnn-landmark-v3.safetensors" --dtype fp16

# landmark-v3 (K = 256, the default since 2026-11-27): v2's weights trained on landmark fields by virtual sources,
# and its point-cloud twin points-v3 (the shipped "points" since 2026-11-28: virtual sources on the cloud's own
# local triangles)
bash pipelines/landmark/more_landmarks.sh "$data" "$runs" 256 "$weights/gegnn-landmark-v2.safetensors" lm256-v3 vsp
gegnn export "$runs/lm256-v3/best.safetensors" "$weights/gegnn-landmark-v3.safetensors" --dtype fp16
gegnn export "$weights/gegnn-landmark-v3.safetensors" "$weights/gegnn-points-v3.safetensors" --neighbors 8
# landmark-v4 (K = 256, the default since 0.3.3): v3's weights on the fields of 0.3.3 (gates at every vertex
# but a plane's, fast-marching updates), with 80 generated tori, bent tubes, helices and torus knots added to
# the training data (their geodesics wrap round saddle regions, which the classic meshes barely have)
python pipelines/landmark/zoo_meshes.py "$data/zoo-train" 80 0
geodata prepare "$data/zoo-train" "$data/train.zarr" --pairs 100000 --log "$data/prepare-train.log"
bash pipelines/landmark/more_landmarks.sh "$data" "$runs" 256 "$weights/gegnn-landmark-v3.safetensors" lm256-v4 vsp
gegnn export "$runs/lm256-v4/best.safetensors" "$weights/gegnn-landmark-v4.safetensors" --dtype fp16
# Each run records the weights it started from by path and sha256 (train_config init, init_sha256): always a
# file here, never a shipped model's name, which moves to each new default. Checked on the files just shipped:
python -m pytest -q tests/gegnn/test_weights_provenance.py -k started_from

python benchmarks/ablation_k.py "$data/val.zarr" "landmark-v4=$weights/gegnn-landmark-v4.safetensors" --record
python benchmarks/ablation_k.py "$data/val.zarr" "landmark-v3=$weights/gegnn-landmark-v3.safetensors" --record
python benchmarks/ablation_k.py "$data/val.zarr" "landmark-v2=$weights/gegnn-landmark-v2.safetensors" \
    "landmark-v1=$weights/gegnn-landmark-v1.safetensors" --record
python benchmarks/ablation_k.py "$data/val.zarr" "v2@384=$weights/gegnn-landmark-v2.safetensors@384" \
    "v3=$runs/gegnn-landmark-v3.safetensors" "v3@256=$runs/gegnn-landmark-v3.safetensors@256"
python benchmarks/bench_queries.py "$data/val.zarr" --only queries --record
OMP_NUM_THREADS=1 gegnn eval "$weights/gegnn-points-v2.safetensors" "$data/val.zarr"
OMP_NUM_THREADS=1 gegnn eval "$weights/gegnn-points-v3.safetensors" "$data/val.zarr"
