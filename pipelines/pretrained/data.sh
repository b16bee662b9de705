#!/usr/bin/env bash
# Data recipe of the shipped pretrained GeGnn (docs/model-card.md). Run from the repository root with
# ../shared/meshes beside it:  bash pipelines/pretrained/data.sh data/ [JOBS]
set -euo pipefail
out=${1:?usage: data.sh OUT_DIR [JOBS]}
jobs=${2:-2}
meshes=../shared/meshes
val=pipelines/pretrained/val.txt

# Validation: 19 classic meshes (14 shapes), prepared as they are, never augmented or trained on.
geodata prepare "$meshes/dev" "$out/val.zarr" --include "$val" --pairs 200000 --jobs "$jobs" --log "$out/prepare-val.log"

# Training: the 114 man-made meshes with 1 variant each, the 28 other classic meshes with 4 each.
geodata augment "$meshes/train" "$out/aug/train" --variants 1 --jobs "$jobs"
geodata augment "$meshes/dev" "$out/aug/dev" --variants 4 --exclude "$val" --jobs "$jobs"
for raw in "$meshes/train" "$out/aug/train" "$out/aug/dev"; do
  geodata prepare "$raw" "$out/train.zarr" --pairs 100000 --jobs "$jobs" --log "$out/prepare-train.log"
done
geodata prepare "$meshes/dev" "$out/train.zarr" --exclude "$val" --pairs 100000 --jobs "$jobs" --log "$out/prepare-train.log"
geodata info "$out/val.zarr"
geodata info "$out/train.zarr"
