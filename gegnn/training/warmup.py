"""The decoder warm-up of training: the decoder alone, fitted on the frozen network's codes before the first
epoch (:func:`gegnn.fitting.fit_pairs`, the loop finetuning uses too)."""
from __future__ import annotations

import torch

from geodata.progress import progress_bar

from ..distributed import Dist
from ..fitting import fit_pairs
from ..metrics import relative_error

WARMUP_BYTES = 2 << 30  # decoder warm-up: codes and pairs kept on the device, per rank


def warm_decoder(model, loader, steps: int, lr: float, device, log, ctx: Dist | None = None,
                 pairs_per_step: int = 16384, budget: int = WARMUP_BYTES) -> None:
    """Train the decoder alone on the frozen network's codes of the meshes of ``loader`` (validation-style
    batches of one mesh: no rotation, landmark seed 0).

    A fresh decoder needs thousands of optimizer steps, the network a few hundred: one network step
    costs ~3 s on a 2-core CPU, one decoder step on precomputed codes ~10 ms. The codes (one forward
    pass per mesh) and a fixed sample of pairs are kept on the device (~4 MB per 5k-vertex mesh at
    K = 128 and 20k pairs, ~10 MB at 100k pairs), up to ``budget`` bytes per process: the meshes beyond it
    are left out. Under DDP every rank does this with its own meshes and pairs, and the gradients are
    averaged, so all ranks leave with the same decoder. Decays linearly to 0 over ``steps``."""
    ctx = ctx or Dist()
    model.eval()
    codes, pairs, dists, offset, used = [], [], [], 0, 0
    with torch.no_grad():
        for batch in progress_bar(loader, desc="decoder warm-up: codes", leave=False, disable=not ctx.main,
                          dynamic_ncols=True):
            batch = batch.to(device)
            z = model(batch.hierarchy, fields=batch.fields)
            codes.append(z)
            pairs.append(batch.pairs + offset)
            dists.append(batch.distances)
            offset += len(z)
            used += sum(t.numel() * t.element_size() for t in (z, batch.pairs, batch.distances))
            if used >= budget:
                break
    n_meshes = len(codes)
    codes, pairs, dists = torch.cat(codes), torch.cat(pairs), torch.cat(dists)
    model.train()

    def loss(pick):
        p = pairs[pick]
        return relative_error(model.distance(codes[p[:, 0]], codes[p[:, 1]]), dists[pick]).mean()

    generator = torch.Generator(device).manual_seed(ctx.rank)
    losses = fit_pairs(model.distance.parameters(), loss, len(pairs), steps, lr, pairs_per_step, generator,
                       "decoder warm-up", progress=ctx.main, ctx=ctx)
    model.zero_grad(set_to_none=True)
    log.info(f"decoder warm-up: {steps} steps on {n_meshes} meshes' codes per process "
             f"({used / 2 ** 20:.0f} MiB), MRE {losses[0]:.4f} -> {sum(losses[-50:]) / len(losses[-50:]):.4f}")
