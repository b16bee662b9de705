#!/usr/bin/env bash
# More landmarks for the landmark-guided GeGnn (docs/model-card.md, "K ablation"), after
# pipelines/pretrained/data.sh:   bash pipelines/landmark/more_landmarks.sh data/ runs/ K [INIT] [NAME] [FIELDS]
# Starts from INIT (default the shipped gegnn-landmark-v1, trained at K = 128): its network and its decoder,
# whose weights do not depend on K; then 20,000 decoder steps on the frozen network's codes at K landmarks
# and one gentle end-to-end epoch, as phase 2 of pipelines/landmark/train.sh, in runs/NAME (default
# lm<K>-v2). gegnn-landmark-v2: K = 256 from v1; the K = 384 ablation from v2
# (INIT gegnn/weights/gegnn-landmark-v2.safetensors, NAME lm384-v3, not shipped); gegnn-landmark-v3: K = 256 from
# v2 on landmark fields by virtual sources (NAME lm256-v3, FIELDS vsp; FIELDS: heat, the default, or vsp). K = 128 from v1 is the control: the
# same extra training without more landmarks. One thread of a 2-core CPU; a killed run continues with the
# same command (--resume is in it).
set -euo pipefail
data=${1:?usage: more_landmarks.sh DATA_DIR RUNS_DIR K [INIT] [NAME] [FIELDS]}
runs=${2:?usage: more_landmarks.sh DATA_DIR RUNS_DIR K [INIT] [NAME] [FIELDS]}
k=${3:?usage: more_landmarks.sh DATA_DIR RUNS_DIR K [INIT] [NAME] [FIELDS]}
init=${4:-gegnn/weights/gegnn-landmark-v1.safetensors}
name=${5:-lm$k-v2}
fields=${6:-heat}

OMP_NUM_THREADS=1 gegnn train "$data/train.zarr" --val "$data/val.zarr" --run "$runs/$name" --resume \
    --batch-size 4 --pairs-per-mesh 20000 --warmup-epochs 0.1 --clip-grad 1.0 --epochs 1 --lr 1e-4 \
    --init "$init" --landmarks "$k" --landmark-fields "$fields" --decoder-warmup 20000
