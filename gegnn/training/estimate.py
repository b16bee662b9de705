"""What a run will cost, said in its log's first lines: the model, its size, the device, and the time per
epoch and for the run measured from its first steps, with a hint where a preset or a GPU would be much
faster (100 epochs of the paper's 256-channel network on 1,000 meshes take about five days on a 2-core CPU:
a user should know before the run, not after)."""
from __future__ import annotations

import time
from pathlib import Path

import torch

from ..config import GeGnnConfig
from .presets import describe_config

__all__ = ["describe_device", "log_header", "StepClock", "readable_seconds"]

MEASURED_STEPS = 3     # steps timed after the first (which also starts the loader and the allocator)
GPU_STEP_S = 0.09      # an H100's training step, batch 4 x 5k vertices (docs/gpu.md: 74-86 ms at 256 channels)
GPU_HINT_S = 1800      # a CPU run longer than this gets the GPU hint
# CPU seconds a step of the paper's 256-channel network over the 64-channel landmark preset's, same batches
# (batch 4, 20,000 pairs a mesh, the six `geodata examples` meshes, one thread; 17.5 s against 3.9 s on a
# 2-core AMD EPYC, 2026-11-27: benchmarks/bench_own_data.py, docs/results.json).
PRESET_SPEEDUP = 4.5


def readable_seconds(s: float) -> str:
    """Seconds in the unit a person reads: 0.4 s, 40 s, 12 min, 5.3 h, 4.1 days."""
    if s < 10:  # a short epoch on a GPU: never "0 s"
        return f"{s:.1f} s"
    for unit, size, limit in (("s", 1, 120), ("min", 60, 7200), ("h", 3600, 172800)):
        if s < limit:
            return f"{s / size:.0f} {unit}" if unit == "s" else f"{s / size:.1f} {unit}"
    return f"{s / 86400:.1f} days"


def describe_device(device: torch.device) -> str:
    """The device in words: the GPU's name, or the CPU's model and the threads torch uses."""
    if device.type == "cuda":
        return f"{device} ({torch.cuda.get_device_name(device)})"
    name = ""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        name = next((line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines()
                     if line.startswith("model name")), "")
    return f"cpu ({name + ', ' if name else ''}{torch.get_num_threads()} thread(s))"


def log_header(log, cfg, model, device) -> None:
    """The run's first line: the model (its preset, if any), its parameters, the device, where it starts."""
    params = sum(p.numel() for p in model.parameters())
    what = f"preset {cfg.model}: " if cfg.model else ""
    start = f"fine-tuned from {cfg.init}" if cfg.init else "from scratch"
    log.info(f"model: {what}{describe_config(model.config)}, {params:,} parameters, on {describe_device(device)}, "
             f"{start}; {cfg.epochs} epoch(s), batch {cfg.batch_size}, {cfg.pairs_per_mesh} pairs a mesh, "
             f"lr {cfg.lr:g} after {cfg.warmup_epochs:g} epoch(s) of warm-up, decoder warm-up {cfg.decoder_warmup} step(s)")


class StepClock:
    """Times the first steps of a run's first epoch, then logs the estimated time per epoch and for the
    run; after that epoch, the time it took (validation included) and what is left."""

    def __init__(self, log, cfg, config: GeGnnConfig, device, steps_per_epoch: int, epochs_left: int):
        self.log, self.cfg, self.config, self.device = log, cfg, config, device
        self.steps_per_epoch, self.epochs_left = steps_per_epoch, epochs_left
        self.steps, self.times, self.done = 0, [], False

    def _now(self) -> float:
        if self.device.type == "cuda":  # steps are queued: the time of one is the device's
            torch.cuda.synchronize(self.device)
        return time.perf_counter()

    def start(self) -> None:
        """Before the first step."""
        self.times = [self._now()]

    def step_done(self) -> None:
        """After each step; times the first ``MEASURED_STEPS + 1``, then logs the estimate once."""
        if self.done or not self.times:
            return
        self.steps += 1
        if self.steps in (1, min(MEASURED_STEPS + 1, self.steps_per_epoch)):
            self.times.append(self._now())
        if self.steps == min(MEASURED_STEPS + 1, self.steps_per_epoch):
            self.done = True
            measured = self.times[-1] - self.times[-2] if self.steps > 1 else self.times[-1] - self.times[0]
            timed = f"steps 2-{self.steps}" if self.steps > 2 else f"step {self.steps}"
            self._log_estimate(measured / max(self.steps - 1, 1), timed)

    def _log_estimate(self, step_s: float, timed: str) -> None:
        epoch_s = step_s * self.steps_per_epoch
        run_s = epoch_s * self.epochs_left
        # a preset's run is a fine-tune (:func:`gegnn.training.presets.preset`): its recipe took several runs
        which = f"this fine-tune alone, not preset {self.cfg.model}'s whole recipe; " if self.cfg.model else ""
        self.log.info(f"estimate: {step_s:.2f} s a step ({timed} timed) -> ~{readable_seconds(epoch_s)} an epoch "
                      f"of {self.steps_per_epoch} steps, "
                      f"~{readable_seconds(run_s)} for the run's {self.epochs_left} epoch(s) ({which}validation "
                      "not included)")
        hints = []
        if not self.cfg.model and self.config.channels > 64 and not self.cfg.init:
            hints.append(f"--model landmark trains the shipped default's 64-channel network (~{PRESET_SPEEDUP}x "
                         "less time a step on a CPU, measured) from its trained weights: 1.03% validation MRE "
                         "where the paper's network reached 9.4% (docs/model-card.md)")
        if self.device.type == "cpu" and run_s > GPU_HINT_S:
            hints.append(f"one GPU takes ~{GPU_STEP_S:.2f} s a step at batch 4 (an H100, docs/gpu.md): this run "
                         f"in ~{readable_seconds(run_s / step_s * GPU_STEP_S * self.cfg.batch_size / 4)}")
        for hint in hints:
            self.log.info(f"hint: {hint}")

    def epoch_done(self, seconds: float) -> None:
        """After the first epoch of this process: its time, validation included, and the rest of the run's."""
        if self.epochs_left > 1 and self.times:
            self.log.info(f"first epoch: {readable_seconds(seconds)}, validation included; the run's other "
                          f"{self.epochs_left - 1} epoch(s) ~{readable_seconds(seconds * (self.epochs_left - 1))}")
        self.times = []
