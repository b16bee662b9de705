"""The shipped models on the shape zoo (geodata.zoo) and six classic meshes: the mean relative error of the
distance fields from 4 sources to every vertex against the exact solver, beside the heat method's and the
virtual-source fields' own, so that a model's error reads against the fields it starts from.

    python benchmarks/bench_zoo_models.py [--models landmark landmark-v2 ...] [--size 1]

A model is a shipped name or a checkpoint file (NAME=PATH to label it). One thread (torch and the field
solver), fp32. The fields' rows use the same 4 sources; the heat method is potpourri3d's through
gegnn.fields.heat.HeatDistance.
"""
from __future__ import annotations

import argparse
import warnings

import numpy as np
import torch

from bench_field_solver import CLASSIC, zoo_truth
from geodata.approximate_geodesic import ApproximateGeodesicSolver
from geodata.zoo import ZOO
from gegnn import GeGnn
from gegnn.fields.heat import HeatDistance
from machine import cpu_description


def mean_error(fields: np.ndarray, exact: np.ndarray) -> float:
    keep = exact > 0
    return float(np.mean(np.abs(fields[keep] - exact[keep]) / exact[keep]))


def model(spec: str) -> tuple[str, GeGnn]:
    label, _, path = spec.partition("=")
    return label, GeGnn.pretrained(path or label) if not (path or label).endswith(".safetensors") \
        else GeGnn.from_checkpoint(path or label)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", nargs="+", default=["landmark", "landmark-v2"])
    ap.add_argument("--size", type=float, default=1.0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    models = [model(m) for m in args.models]
    print(f"CPU: {cpu_description()}")
    print("mean relative error of fields from 4 sources to every vertex, against exact")
    print("| shape | vertices | " + " | ".join(label for label, _ in models)
          + " | heat method | virtual-source fields |\n|---|---:|" + "---:|" * (len(models) + 2))
    rows = []
    for name in [*ZOO, *CLASSIC]:
        v, f, sources, exact = zoo_truth(name, None if name in CLASSIC else args.size)
        errors = []
        for _, m in models:
            emb = m.embed(v, f)
            errors.append(mean_error(np.stack([np.asarray(emb.field(int(s)), dtype=np.float64) for s in sources]),
                                     exact))
        errors.append(mean_error(HeatDistance(v, f).distances(sources).T, exact))
        errors.append(mean_error(ApproximateGeodesicSolver(v, f).distances(sources, threads=1), exact))
        rows.append(errors)
        print(f"| {name} | {len(v):,} | " + " | ".join(f"{100 * e:.2f}%" for e in errors) + " |", flush=True)
    zoo = np.array(rows[:len(ZOO)])
    print("| zoo: mean / worst | | " + " | ".join(f"{100 * a:.2f}% / {100 * b:.2f}%"
                                                 for a, b in zip(zoo.mean(0), zoo.max(0))) + " |")


if __name__ == "__main__":
    main()
