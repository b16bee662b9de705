"""Table of the landmark-guided GeGnn ablation (pipelines/landmark/ablation.sh): validation MRE over all
stored pairs of every trained variant, against the shipped paper model and the landmark lower bound
alone (no learning) at several K.

    python benchmarks/ablation_landmarks.py VAL_STORE RUNS_DIR

Prints a markdown table (one row per variant: K, what the decoder reads, steps, minutes of one CPU
thread including the decoder warm-up, MRE).
"""
from __future__ import annotations

import argparse
import csv
from datetime import datetime
from pathlib import Path

import numpy as np

from gegnn import GeGnn
from gegnn.checkpoint import load_checkpoint
from gegnn.training.data import GeodesicStore
from gegnn.fields.landmarks import landmark_fields
from gegnn.metrics import METRIC_EPS
from gegnn.training.loop import evaluate_store
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs


def bound_mre(store: GeodesicStore, k: int) -> float:
    """Mean over meshes of the MRE of max_k |d_ik - d_jk| (seed 0, as the models use)."""
    errors = []
    for mesh_id in store.mesh_ids:
        g = store.geometry(mesh_id)
        pairs, d = store.pairs(mesh_id)
        f = landmark_fields(g.vertices, g.faces, k).distances
        lower = np.abs(f[pairs[:, 0]] - f[pairs[:, 1]]).max(axis=1)
        errors.append(np.mean(np.abs(lower - d) / (d + METRIC_EPS)))
    return float(np.mean(errors))


def mean_mre(rows) -> float:
    return float(np.mean([float(r["mre"]) for r in rows if r["mesh_id"] != "overall"]))


def setup_seconds(log: Path) -> float:
    """From the run's first log line to its 'N train / M val meshes' line: the decoder warm-up."""
    stamps = [(datetime.strptime(line[:19], "%Y-%m-%d %H:%M:%S"), line) for line in log.read_text().splitlines()]
    start = stamps[0][0]
    ready = next(t for t, line in stamps if " train / " in line)
    return (ready - start).total_seconds()


def describe(config) -> str:
    if not config.landmarks:
        return "paper decoder"
    reads = (["embedding"] if config.landmark_embedding else []) + ["landmark features"]
    reads += ["euclidean"] if config.landmark_euclidean else []
    return f"{config.landmark_output}: " + " + ".join(reads)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("val_store")
    ap.add_argument("runs")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    store = GeodesicStore(args.val_store, "geodesic")
    lines = ["| variant | K | decoder reads | start | network steps | CPU min | val MRE |",
             "|---|---:|---|---|---:|---:|---:|"]
    paper = mean_mre(evaluate_store(GeGnn.pretrained("paper"), args.val_store))
    lines.append(f"| shipped paper model | 0 | paper decoder | — | 2,457 + phase 1 | 98 | {100 * paper:.2f}% |")
    for k in (16, 32, 64, 128):
        lines.append(f"| lower bound alone | {k} | — | — | 0 | 0 | {100 * bound_mre(store, k):.2f}% |")
    for run in sorted(p for p in Path(args.runs).iterdir() if (p / "eval.csv").exists()):
        with open(run / "eval.csv", newline="") as f:
            mre = mean_mre(list(csv.DictReader(f)))
        ckpt = load_checkpoint(run / "last.safetensors")
        with open(run / "metrics.csv", newline="") as f:
            metrics = list(csv.DictReader(f))
        minutes = (sum(float(r["seconds"]) for r in metrics) + setup_seconds(run / "train.log")) / 60
        tc = ckpt.metadata["train_config"]
        init = ("paper model" if tc.get("init") else "scratch") + \
            (f", decoder warm-up {tc['decoder_warmup']}" if tc.get("decoder_warmup") else "")
        c = ckpt.config
        lines.append(f"| {run.name} | {c.landmarks} | {describe(c)} | {init} | {int(metrics[-1]['step']):,} | "
                     f"{minutes:.0f} | {100 * mre:.2f}% |")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
