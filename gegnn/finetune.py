"""Finetuning a trained GeGnn on one mesh (the paper's Section 4.3: MRE 4.1% -> 1.0% on an unseen mesh).

Exact geodesic fields from random sources of the mesh (the geodata solver, in a forked child) are
the training data; more sources are held out and measure the error before and after on every other
vertex. Three phases, all on this one mesh and its fixed hierarchy, from cheap to dear:

1. ``decoder_steps`` steps of the distance decoder alone on the frozen network's codes (~15 ms a step
   at 5k vertices on one CPU thread);
2. ``head_steps`` steps of the embedding head and the decoder on the U-Net's frozen output features
   (~30 ms a step: the U-Net runs once);
3. ``steps`` steps of the whole network (one forward and backward pass each, ~0.45 s a step; the
   paper's 2,500 are for a GPU).

All with AdamW and the training loss (mean relative error), the learning rate decaying linearly to 0.
Measured on 2 validation meshes with the paper model, under one CPU minute (``benchmarks/
bench_applications.py`` has the 5-mesh numbers): the frozen-trunk phase 2 halves the held-out error
(camel 10.6% -> 4.6%) where 100 whole-network steps in the same time reach 0.62x; 64 training
sources generalize better than 32 (cow 0.60x against 0.77x); lr 3e-3 for the whole network
diverges, for phases 1-2 it is the best of 1e-3 and 3e-3.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np
import torch

from .fitting import fit_pairs
from .metrics import pair_errors, relative_error

__all__ = ["FinetuneResult", "finetune", "split_sources"]


@dataclass
class FinetuneResult:
    """Held-out MRE (relative error over every (held-out source, vertex) pair) before and after, the
    sources used, and seconds spent: on exact distances and on training."""

    mre_before: float
    mre_after: float
    train_sources: np.ndarray
    held_out_sources: np.ndarray
    exact_seconds: float
    train_seconds: float
    losses: list[float] = field(default_factory=list)


def split_sources(part: np.ndarray, n_train: int, n_held_out: int, seed: int = 0):
    """Random distinct sources among the vertices where ``part`` is True (the largest connected part: the
    others have no distances to its vertices), ``n_train`` for training and ``n_held_out`` held out."""
    part = np.flatnonzero(part)
    if n_train + n_held_out > len(part):
        raise ValueError(f"{n_train} + {n_held_out} sources asked for, the mesh's largest part has "
                         f"{len(part)} vertices")
    pick = np.random.default_rng(seed).choice(part, n_train + n_held_out, replace=False)
    return pick[:n_train], pick[n_train:]


def _pairs(sources: np.ndarray, fields: np.ndarray, device) -> tuple[torch.Tensor, torch.Tensor]:
    """(P, 2) pairs (source, vertex) and their distances, over the finite entries of ``fields`` (S, N)."""
    s_idx, v_idx = np.nonzero(np.isfinite(fields) & (fields > 0))
    pairs = torch.as_tensor(np.stack([sources[s_idx], v_idx], axis=1), device=device)
    return pairs, torch.as_tensor(fields[s_idx, v_idx], dtype=torch.float32, device=device)


def finetune(model, vertices, faces, sources: int = 64, held_out: int = 8, steps: int = 0,
             decoder_steps: int = 300, head_steps: int = 1500, lr: float = 1e-3, head_lr: float = 3e-3,
             pairs_per_step: int = 20_000, seed: int = 0, progress: bool = False) -> FinetuneResult:
    """Finetune ``model`` in place on one mesh (vertices (N, 3) in any units, faces (F, 3)).

    Raises :class:`geodata.mesh.MeshError` where the exact solver cannot take the mesh (non-manifold
    edges) or dies on it.
    """
    from geodata.mesh import Mesh

    from .fields.exact import exact_fields, largest_part

    t0 = time.perf_counter()
    device = next(model.parameters()).device
    hierarchy, lm_fields, scale = model.inputs(vertices, faces, device)
    h, lm_fields = hierarchy(), lm_fields()
    mesh = Mesh(vertices, faces)  # float64 and int64 arrays
    train_src, held_src = split_sources(largest_part(mesh), sources, held_out, seed)
    exact = exact_fields(mesh, np.concatenate([train_src, held_src]), model.config.distance) / scale  # normalized
    train_pairs, train_d = _pairs(train_src, exact[:sources], device)
    held_pairs, held_d = _pairs(held_src, exact[sources:], device)
    t1 = time.perf_counter()
    model.eval()
    with torch.no_grad():
        trunk = model._unet(h)
        codes = model.codes(trunk, h, lm_fields)
        before = float(pair_errors(model.distance, codes, held_pairs, held_d).mean())
    model.train()

    def pair_loss(z, pick):
        p = train_pairs[pick]
        return relative_error(model.distance(z[p[:, 0]], z[p[:, 1]]), train_d[pick]).mean()

    generator = torch.Generator(device).manual_seed(seed)
    fit = partial(fit_pairs, n_pairs=len(train_pairs), pairs_per_step=pairs_per_step, generator=generator,
                  progress=progress)
    losses = []
    if decoder_steps:
        losses += fit(list(model.distance.parameters()), lambda pick: pair_loss(codes, pick),
                      steps=decoder_steps, lr=head_lr, desc="finetune: decoder")
    if head_steps:
        losses += fit(list(model.head.parameters()) + list(model.distance.parameters()),
                      lambda pick: pair_loss(model.codes(trunk, h, lm_fields), pick),
                      steps=head_steps, lr=head_lr, desc="finetune: head")
    if steps:
        losses += fit(list(model.parameters()), lambda pick: pair_loss(model(h, fields=lm_fields), pick),
                      steps=steps, lr=lr, desc="finetune: network")
    model.zero_grad(set_to_none=True)
    model.eval()
    with torch.no_grad():
        after = float(pair_errors(model.distance, model(h, fields=lm_fields), held_pairs, held_d).mean())
    return FinetuneResult(before, after, train_src, held_src, t1 - t0, time.perf_counter() - t1, losses)
