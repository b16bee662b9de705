#!/usr/bin/env bash
# The GPU check: on a machine with CUDA, in about ten minutes, everything this project claims of GPUs.
#
#   scripts/gpu_check.sh [OUT]        (default OUT: gpu-check/; the report is OUT/REPORT.md)
#
# Run from the repository root, with the package installed (`pip install -e .`, torch with CUDA). It
#   1. runs the tests that need CUDA (tests/gegnn/test_gpu_path.py: no host sync in a training step,
#      CUDA embedding and queries equal the CPU's), the GPU-path guards that run anywhere, and the trainer's
#      tests, which train on the GPU there (a killed and resumed run equals an uninterrupted one bitwise,
#      with --deterministic);
#   2. times embed and 1M queries against the paper's RTX 3090 figures (89 ms, 42 ms at 256 channels),
#      compares fp32 with bf16 and CUDA with the CPU, and times a training step with and without
#      --deterministic (benchmarks/bench_gpu.py);
#   3. prepares the toolkit's sample meshes and trains a few hundred steps of the paper model and of the
#      landmark model (decoder warm-up included) with loader workers, then evaluates both on the GPU and
#      on the CPU (fp32: the two must agree);
#   4. runs the paper model's training as a 1-process torchrun (DDP over NCCL);
#   5. measures the loader against the measured GPU step (benchmarks/bench_train_throughput.py).
# Every step's log is kept under OUT/; the report collects them and a PASS/FAIL line per step.
set -uo pipefail
out=${1:-gpu-check}
mkdir -p "$out"
report="$out/REPORT.md"
python -c "import torch, sys; sys.exit(0 if torch.cuda.is_available() else 'no CUDA device: nothing to check')" || exit 1
jobs=$(python -c "import os; print(len(os.sched_getaffinity(0)))")

status=()
step() {  # step NAME COMMAND...: run, log to OUT/NAME.log, record PASS/FAIL and the time
    local name=$1; shift
    local t0=$SECONDS
    echo "== $name: $*"
    if "$@" >"$out/$name.log" 2>&1; then status+=("| $name | PASS | $((SECONDS - t0)) s |")
    else status+=("| $name | **FAIL** (see $name.log) | $((SECONDS - t0)) s |"); fi
}

step tests python -m pytest -q -p no:cacheprovider tests/gegnn/test_gpu_path.py tests/gegnn/test_model.py \
    tests/gegnn/test_train.py
step bench-gpu python benchmarks/bench_gpu.py
step data bash -c "geodata examples '$out/raw' && geodata prepare '$out/raw' '$out/store' --pairs 20000 --jobs $jobs"
train=(--epochs 60 --batch-size 1 --pairs-per-mesh 20000 --lr 1e-3 --device cuda)
step train-paper gegnn train "$out/store" --run "$out/paper" --channels 64 "${train[@]}"
step train-landmark gegnn train "$out/store" --run "$out/landmark" --init "$out/paper/best.safetensors" \
    --landmarks 128 --decoder-warmup 500 "${train[@]}"
step eval bash -c "for m in paper landmark; do for d in cuda cpu; do
    echo \"\$m \$d\"; gegnn eval '$out/'\$m/best.safetensors '$out/store' --device \$d | tail -n 1; done; done"
step torchrun torchrun --nproc-per-node 1 -m gegnn.cli train "$out/store" --run-dir "$out/ddp" --channels 64 \
    --epochs 3 --batch-size 1 --pairs-per-mesh 20000 --device cuda
step throughput python benchmarks/bench_train_throughput.py --steps 5

{
    echo "# GPU check"
    echo
    echo "\`scripts/gpu_check.sh\` on $(date -u +%Y-%m-%d), commit $(git rev-parse --short HEAD 2>/dev/null || echo '?')."
    echo
    nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader | sed 's/^/GPU: /'
    echo "CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $jobs cores"
    echo
    echo "| step | result | time |"
    echo "|---|---|---|"
    printf '%s\n' "${status[@]}"
    echo
    cat "$out/bench-gpu.log"
    echo
    echo "## Training (sample meshes, ${train[*]})"
    for run in paper landmark; do
        echo
        echo "### $run"
        echo '```'
        grep -E "warm-up|loader worker|landmark fields|epoch (0|59) " "$out/$run/train.log" || true
        echo '```'
    done
    echo
    echo "## Evaluation, CUDA and CPU"
    echo '```'
    cat "$out/eval.log"
    echo '```'
    echo
    echo "## torchrun (1 process, NCCL)"
    echo '```'
    grep -E "process|epoch 2 " "$out/ddp/train.log" || true
    echo '```'
    echo
    echo "## Loader throughput"
    echo '```'
    cat "$out/throughput.log"
    echo '```'
} >"$report"
echo "report: $report"
printf '%s\n' "${status[@]}"
