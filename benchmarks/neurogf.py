"""NeuroGF's generalizable model (Zhang et al., NeurIPS 2023; github.com/keeganhk/NeuroGF, MIT) on this CPU,
for benchmarks/bench_points.py: distances between points of a cloud.

    python benchmarks/neurogf.py REPO --sphere      # self-check: a 2,048-point unit sphere, great circles

REPO is a checkout of that repository; its checkpoint ``ckpt/neurogf_gen/GenNeuroGF.pth`` (a plain
state dict, loaded with ``weights_only=True``) and its modules ``code/neurogf_gen/neurogf_gen_models.py``
and ``cdbs/general.py`` are used as they are. What they import and this machine lacks is replaced at
import time, none of it on the model's path:

* ``cdbs.pkgs`` (a hub that star-imports ~30 libraries: cv2, open3d, vedo, ...) by the standard-library,
  NumPy and torch names the model code uses;
* the prebuilt CPython 3.9 / CUDA extensions ``cdbs/general.py`` imports (nanoflann kNN, EMD, Chamfer,
  grid subsampling) by stubs that raise if called (nothing calls them here);
* ``knn_search`` (a CUDA kNN) by an exact ``torch.cdist`` + top-k, nearest first, the point itself included.

The model: a DGCNN encoder (EdgeConv, k = 40) of a 2,048-point cloud of xyz only (no normals), trained on
ShapeNet13; a query is two 3D points, each read with the features of its nearest cloud point; the output
is the ratio geodesic / straight line. Clouds of more points are reduced to 2,048 by the repository's own
farthest-point sampling for the encoder (queries still use every point); coordinates are normalized as
the repository's ``bounding_box_normalization`` does (box centred, farthest point at radius 1; the
training data's own convention is not published: the sphere's error is 2.3% at radius 0.5 and 3.0% at 1).
"""
from __future__ import annotations

import argparse
import sys
import time
import types
from pathlib import Path

import numpy as np
import torch
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

TRAIN_POINTS = 2048  # the ShapeNet13 training clouds


def _module(name: str, **attrs) -> None:
    module = types.ModuleType(name)
    module.__dict__.update(attrs)
    sys.modules[name] = module


def _missing(what: str):
    def call(*args, **kwargs):
        raise RuntimeError(f"{what}: a compiled extension that does not run here")
    return call


def knn(source: torch.Tensor, query: torch.Tensor, k: int) -> torch.Tensor:
    """(B, M, k) indices of each query point's k nearest source points, nearest first (exact)."""
    d = torch.cdist(query, source, compute_mode="donot_use_mm_for_euclid_dist")
    return d.topk(k, dim=-1, largest=False, sorted=True).indices


class _Features(torch.nn.Module):
    """Stands in for the encoder: its output for the cloud, so that every query chunk reuses one pass."""

    def __init__(self, features: torch.Tensor):
        super().__init__()
        self.features = features

    def forward(self, points):
        return self.features


class NeuroGF:
    """The generalizable model of a checkout ``repo``; :meth:`distances` between points of one cloud."""

    def __init__(self, repo):
        import glob
        import itertools
        import os
        import random

        import torch.nn as nn
        import torch.nn.functional as F
        import torch.optim as optim
        from tqdm import tqdm

        repo = Path(repo)
        _module("cdbs.pkgs", os=os, sys=sys, glob=glob, time=time, itertools=itertools, random=random, np=np,
                tqdm=tqdm, torch=torch, nn=nn, F=F, optim=optim)
        _module("cdbs.KNN_CPU.nearest_neighbors", knn_batch=_missing("KNN_CPU"))
        _module("cdbs.EMD.emd", earth_mover_distance_unwrapped=_missing("EMD"))
        _module("cdbs.CD.chamferdist", ChamferDistance=_missing("chamferdist"))
        _module("cdbs.CD.chamferdist.chamfer", knn_points=_missing("chamferdist"))
        _module("cdbs.GS_CPU.cpp_subsampling.grid_subsampling", subsample=_missing("grid subsampling"))
        sys.path[:0] = [str(repo), str(repo / "code" / "neurogf_gen")]
        import cdbs.general as general
        import neurogf_gen_models as models

        general.knn_search = models.knn_search = knn
        self.general = general
        self.net = models.GenNeuroGF()
        self.net.load_state_dict(torch.load(repo / "ckpt" / "neurogf_gen" / "GenNeuroGF.pth", map_location="cpu",
                                            weights_only=True))
        self.net.eval()

    @torch.no_grad()
    def distances(self, cloud: np.ndarray, pairs: np.ndarray, chunk: int = 65536) -> np.ndarray:
        """Predicted geodesic distances (P,) between the cloud's points ``pairs`` (P, 2), in its units."""
        cloud = np.asarray(cloud, dtype=np.float64)
        center = (cloud.min(axis=0) + cloud.max(axis=0)) / 2
        radius = np.linalg.norm(cloud - center, axis=1).max()
        x = torch.from_numpy((cloud - center) / radius).float()[None]
        p = x
        if x.shape[1] > TRAIN_POINTS:
            p = self.general.index_points(x, self.general.get_fps_idx_zero_as_first(x, TRAIN_POINTS))
        features = self.net.backbone(p)
        backbone, self.net.backbone = self.net.backbone, _Features(features)
        try:
            out = []
            for start in range(0, len(pairs), chunk):
                s, t = x[0, pairs[start:start + chunk, 0]], x[0, pairs[start:start + chunk, 1]]
                out.append(self.net(p, s[None], t[None])[0] * (s - t).norm(dim=-1))
        finally:
            self.net.backbone = backbone
        return torch.cat(out).double().numpy() * radius


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("repo")
    ap.add_argument("--sphere", action="store_true", required=True)
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    rng = np.random.default_rng(0)
    v = rng.normal(size=(TRAIN_POINTS, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    pairs = rng.integers(0, TRAIN_POINTS, size=(20000, 2))
    exact = np.arccos(np.clip((v[pairs[:, 0]] * v[pairs[:, 1]]).sum(axis=1), -1, 1))
    t = time.perf_counter()
    d = NeuroGF(args.repo).distances(v, pairs)
    far = exact > 0.1
    print(f"unit sphere, {TRAIN_POINTS} points: MRE {100 * np.mean(np.abs(d[far] - exact[far]) / exact[far]):.2f}% "
          f"({time.perf_counter() - t:.1f} s)")


if __name__ == "__main__":
    main()
