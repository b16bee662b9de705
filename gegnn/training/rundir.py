"""A run directory's files: the log (``train.log`` and the console), ``metrics.csv``, ``curves.png``, and the
RNG state a resume restores (the checkpoints themselves: :mod:`gegnn.checkpoint`)."""
from __future__ import annotations

import csv
import logging
from pathlib import Path

import torch
from tqdm import tqdm

__all__ = ["METRICS", "run_logger", "read_metrics", "write_metrics", "plot_curves", "rng_state", "restore_rng"]

METRICS = ["epoch", "step", "lr", "train_mre", "val_mre", "seconds"]


def run_logger(run: Path, main: bool) -> logging.Logger:
    log = logging.getLogger(f"gegnn.train.{run.resolve()}")
    log.setLevel(logging.INFO if main else logging.WARNING)
    log.propagate = False
    for h in list(log.handlers):
        log.removeHandler(h)
        h.close()
    if main:
        fmt = logging.Formatter("%(asctime)s %(message)s", "%Y-%m-%d %H:%M:%S")
        for h in (logging.FileHandler(run / "train.log"), TqdmHandler()):
            h.setFormatter(fmt)
            log.addHandler(h)
    return log


class TqdmHandler(logging.Handler):
    """Console lines that do not tear the progress bar."""

    def emit(self, record):
        tqdm.write(self.format(record))


def read_metrics(run: Path, before_epoch: int) -> list[dict]:
    path = run / "metrics.csv"
    if not path.exists():
        return []
    with open(path, newline="") as f:
        return [r for r in csv.DictReader(f) if int(r["epoch"]) < before_epoch]


def write_metrics(run: Path, rows: list[dict]) -> None:
    with open(run / "metrics.csv", "w", newline="") as f:
        w = csv.DictWriter(f, METRICS)
        w.writeheader()
        w.writerows(rows)


def plot_curves(run: Path, rows: list[dict]) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    epochs = [int(r["epoch"]) for r in rows]
    for key in ("train_mre", "val_mre"):
        ax.plot(epochs, [float(r[key]) for r in rows], marker=".", label=key)
    ax.set(xlabel="epoch", ylabel="mean relative error", yscale="log")
    ax.legend()
    fig.tight_layout()
    fig.savefig(run / "curves.png", dpi=100)
    plt.close(fig)


def rng_state() -> dict:
    """The CPU generator's state and, where this process has used CUDA, its own device's (each rank
    drives one GPU; a resume may see another number of them)."""
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        state["cuda"] = torch.cuda.get_rng_state()
    return state


def restore_rng(state: dict) -> None:
    """Undo :func:`rng_state` on this process's current CUDA device. Checkpoints written before kept
    every device's state as ``cuda0``, ``cuda1``, ...: the current device's is taken, if saved."""
    if "torch" in state:
        torch.set_rng_state(state["torch"])
    if torch.cuda.is_available():
        cuda = state.get("cuda", state.get(f"cuda{torch.cuda.current_device()}"))
        if cuda is not None:
            torch.cuda.set_rng_state(cuda)
