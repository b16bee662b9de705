"""The optimizer loop on pairs of fixed codes: finetuning's phases (:mod:`gegnn.finetune`) and the decoder
warm-up of training (:mod:`gegnn.training.warmup`). It takes the parameters and a loss, never a model
class."""
from __future__ import annotations

import torch

from geodata.progress import progress_bar

from .distributed import Dist, average_gradients


def show_loss(bar, losses: list[torch.Tensor]) -> None:
    """Show the loss of the step before the last: the device is busy with the last one meanwhile, so
    reading it does not drain the queue of launched kernels."""
    if not bar.disable:
        bar.set_postfix(mre=f"{losses[-2 if len(losses) > 1 else -1].item():.4f}")


def fit_pairs(params, loss_fn, n_pairs: int, steps: int, lr: float, pairs_per_step: int,
              generator: torch.Generator, desc: str, progress: bool = True, ctx: Dist | None = None) -> list[float]:
    """``steps`` AdamW steps (no weight decay) on ``params``, each on the loss ``loss_fn(indices)`` of
    ``pairs_per_step`` random indices into ``n_pairs`` pairs, drawn on the ``generator``'s device, the
    learning rate decaying linearly from ``lr`` to 0. With ``ctx`` of several processes the gradients are
    averaged across them (each process its own pairs). Returns the losses."""
    params = list(params)
    optimizer = torch.optim.AdamW(params, lr=lr, weight_decay=0.0)
    losses = []
    bar = progress_bar(range(steps), desc=desc, leave=False, disable=not progress, dynamic_ncols=True)
    for step in bar:
        for group in optimizer.param_groups:
            group["lr"] = lr * (1 - step / steps)
        pick = torch.randint(n_pairs, (pairs_per_step,), generator=generator, device=generator.device)
        loss = loss_fn(pick)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if ctx is not None and ctx.world > 1:
            average_gradients(params, ctx)
        optimizer.step()
        losses.append(loss.detach())
        if step % 100 == 1:
            show_loss(bar, losses)
    return torch.stack(losses).tolist() if losses else []
