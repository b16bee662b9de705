"""Processes of a DistributedDataParallel run: the process group torchrun describes, and the sums and
gradient averages across its ranks (one process: no-ops)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import timedelta

import torch
import torch.distributed as dist

# Collectives may wait this long: ranks meet after filling the field cache, whose shares can differ by many
# meshes (NCCL's default of 10 minutes would end a long fill).
DIST_TIMEOUT = timedelta(hours=6)


@dataclass
class Dist:
    rank: int = 0
    world: int = 1
    owned: bool = False  # this module made the process group, and ends it

    @property
    def main(self) -> bool:
        return self.rank == 0


def dist_backend(device: torch.device, gpus: int | None = None) -> str:
    """NCCL where each of this node's ranks drives a GPU of its own; gloo on CPUs and where ranks share a
    GPU (NCCL refuses two ranks on one device)."""
    if device.type != "cuda":
        return "gloo"
    gpus = torch.cuda.device_count() if gpus is None else gpus
    return "nccl" if int(os.environ.get("LOCAL_WORLD_SIZE", "1")) <= gpus else "gloo"


def setup_distributed(device: torch.device) -> Dist:
    """Join the process group torchrun describes (or one the caller already made)."""
    if not dist.is_initialized() and int(os.environ.get("WORLD_SIZE", "1")) > 1:
        dist.init_process_group(dist_backend(device), timeout=DIST_TIMEOUT)
        return Dist(dist.get_rank(), dist.get_world_size(), owned=True)
    if not dist.is_initialized():
        return Dist()
    return Dist(dist.get_rank(), dist.get_world_size())


def barrier(ctx: Dist) -> None:
    if ctx.world > 1:
        dist.barrier()


def all_sum(values: list[float], ctx: Dist, device) -> list[float]:
    if ctx.world == 1:
        return values
    t = torch.tensor(values, dtype=torch.float64, device=device)
    dist.all_reduce(t)
    return t.tolist()


def average_gradients(params: list[torch.Tensor], ctx: Dist) -> None:
    """Mean of the gradients over the processes: one all-reduce of all of them, flattened."""
    grads = [p.grad for p in params if p.grad is not None]
    flat = torch.cat([g.reshape(-1) for g in grads])
    dist.all_reduce(flat)
    flat /= ctx.world
    for g, part in zip(grads, flat.split([g.numel() for g in grads])):
        g.copy_(part.view_as(g))
