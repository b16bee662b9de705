"""The paper's loss and metric: the relative error of predicted distances, with its offset."""
from __future__ import annotations

import torch

__all__ = ["METRIC_EPS", "relative_error", "pair_errors"]

METRIC_EPS = 1e-3  # offset of the relative error's denominator, in normalized units


def relative_error(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Per pair |d_pred - d| / (d + 1e-3): the paper's loss and metric (mean it for the MRE)."""
    return (pred.float() - target).abs() / (target + METRIC_EPS)


def pair_errors(distance, codes: torch.Tensor, pairs: torch.Tensor, targets: torch.Tensor,
                chunk: int = 65536) -> torch.Tensor:
    """Relative errors (P,) of the decoder ``distance`` on ``pairs`` (P, 2) of vertex ``codes``, decoded
    ``chunk`` pairs at a time."""
    return torch.cat([relative_error(distance(codes[p[:, 0]], codes[p[:, 1]]), d)
                      for p, d in zip(pairs.split(chunk), targets.split(chunk))])
