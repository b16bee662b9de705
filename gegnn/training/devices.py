"""Devices of training: the device a process trains on, its deterministic mode, and the CPU cores and
loader processes it may use (the process group and its sums: :mod:`gegnn.distributed`)."""
from __future__ import annotations

import os

import torch

MAX_AUTO_WORKERS = 8  # --workers auto on a GPU: one per spare CPU core, at most this many (docs/benchmarks.md)


def pick_device(name: str, gpus: int | None = None) -> torch.device:
    """The device ``name`` means for this process: ``auto`` is CUDA where there is one; a rank of torchrun
    takes GPU LOCAL_RANK (modulo the GPUs there are, so ranks may share one)."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    device = torch.device(name)
    if device.type == "cuda" and device.index is None:
        gpus = torch.cuda.device_count() if gpus is None else gpus
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")) % max(gpus, 1))
    if device.type == "cuda":
        torch.cuda.set_device(device)
    return device


def set_deterministic(enabled: bool) -> None:
    """torch's deterministic algorithms on or off. cuBLAS is deterministic only with a fixed workspace, which
    it reads when CUDA starts: set here (unless the user set one), before any CUDA work of the process."""
    if enabled:
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.use_deterministic_algorithms(enabled)


def cpus_per_process() -> int:
    """CPU cores this process may use, shared with the other processes of its node (torchrun's
    LOCAL_WORLD_SIZE)."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return max(1, cpus // int(os.environ.get("LOCAL_WORLD_SIZE", "1")))


def auto_workers(device: torch.device) -> int:
    """Loader processes for ``--workers auto``: on a GPU one per spare core of this rank (at most
    ``MAX_AUTO_WORKERS``), since a batch takes longer to build on one core than a step takes on the GPU;
    on a CPU none, since the cores are the network's."""
    if device.type == "cpu":
        return 0
    return min(MAX_AUTO_WORKERS, max(1, cpus_per_process() - 1))


