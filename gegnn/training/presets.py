"""Training presets: ``gegnn train OUT --model NAME`` trains the architecture, fields and schedule of the
shipped model NAME (:data:`gegnn.model.PRETRAINED`), by default fine-tuned from its weights.

Nothing here is a copy of a number: the architecture is the config in the shipped file's metadata, the
schedule the ``train_config`` that file's training run recorded (its last phase: the recipes under
``pipelines/landmark``, ``pipelines/biharmonic`` and ``pipelines/pretrained``). A fine-tune differs from
it in two ways, both measured: lr 1e-3 without warm-up took the shipped landmark model from
1.1% to 3.8% on six unseen meshes after one epoch, so a fine-tune starts at most at :data:`FINE_TUNE_LR`
after at least :data:`FINE_TUNE_WARMUP` epochs of warm-up; and a model fine-tuned from its own shipped
weights skips the recorded decoder warm-up, which trained a decoder new to its fields (from K = 128 to
256 landmarks for ``landmark``, from geodesic to biharmonic for ``biharmonic``).

A preset is not trained from scratch (``--init none``): each shipped model is the last of several runs (the
paper model's two phases, then the landmark or spectral decoder's), and the recorded schedule is only the
last one's: a fine-tune's, which on random weights is no recipe at all. The refusal
gives the scripts that run every phase (:data:`RECIPES`)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..checkpoint import load_checkpoint
from ..config import GeGnnConfig
from ..model import PRETRAINED, pretrained_file

__all__ = ["PRESETS", "RECIPES", "Preset", "preset", "recipe_command", "checkpoint_file", "describe_config"]

PRESETS = ("landmark", "paper", "biharmonic", "points")  # --model NAME: the shipped models users train
SCHEDULE = ("epochs", "batch_size", "lr", "weight_decay", "warmup_epochs", "clip_grad", "distance",
            "pairs_per_mesh", "decoder_warmup")  # TrainConfig fields a preset sets
FINE_TUNE_LR = 1e-4       # the highest peak learning rate of a fine-tune (the shipped fine-tunes' own)
FINE_TUNE_WARMUP = 0.1    # ... and the shortest warm-up, in epochs
# The scripts that train each preset's shipped file from nothing, in order: each exports its model into
# gegnn/weights/, where the next one starts from it (landmark/ship.sh also exports the points model).
RECIPES = {
    "paper": ("pipelines/pretrained/train.sh",),
    "landmark": ("pipelines/pretrained/train.sh", "pipelines/landmark/train.sh", "pipelines/landmark/ship.sh"),
    "biharmonic": ("pipelines/pretrained/train.sh", "pipelines/landmark/train.sh", "pipelines/biharmonic/train.sh"),
    "points": ("pipelines/pretrained/train.sh", "pipelines/landmark/train.sh", "pipelines/landmark/ship.sh"),
}


@dataclass(frozen=True)
class Preset:
    """What ``--model NAME`` sets: the shipped model's config, the schedule (TrainConfig fields) and the
    weights a run starts from by default."""

    name: str
    config: GeGnnConfig
    schedule: dict
    init: str


def checkpoint_file(spec: str) -> str:
    """The file of a checkpoint given by path or by a shipped model's name (a file of that name wins)."""
    if spec in PRETRAINED and not Path(spec).exists():
        with pretrained_file(spec) as path:  # a plain file in an installed package
            return str(path)
    return spec


def recipe_command(name: str) -> str:
    """The shell command, run in a checkout of the repository, that trains preset ``name``'s shipped model from
    nothing: the data, then every phase of its recipe (:data:`RECIPES`)."""
    return " && ".join(["bash pipelines/pretrained/data.sh data/",
                        *(f"bash {script} data/ runs/" for script in RECIPES[name])])


def preset(name: str, init: str | None = "default") -> Preset:
    """The preset ``name`` for a run started from ``init``: ``"default"`` (the shipped model ``name``
    itself), a shipped model's name or a path (any trained weights: fine-tune learning rate and warm-up).
    ValueError for None (from scratch), naming the command of the whole recipe instead."""
    if name not in PRESETS:
        raise ValueError(f"no preset {name!r}; presets: {', '.join(PRESETS)}")
    if init is None:
        raise ValueError(f"--model {name} --init none: the shipped {name} model is the last of several runs, and "
                         f"its recorded schedule only the last one's; its whole recipe from scratch, in a checkout "
                         f"(it overwrites gegnn/weights/): {recipe_command(name)}")
    ckpt = load_checkpoint(checkpoint_file(name))
    recorded = {**{"decoder_warmup": 0}, **ckpt.metadata["train_config"]}
    schedule = {k: recorded[k] for k in SCHEDULE if k in recorded}
    init = name if init == "default" else init
    schedule["lr"] = min(schedule["lr"], FINE_TUNE_LR)
    schedule["warmup_epochs"] = max(schedule["warmup_epochs"], FINE_TUNE_WARMUP)
    if init == name:  # its own decoder, trained on these very fields
        schedule["decoder_warmup"] = 0
    return Preset(name, ckpt.config, schedule, init)


def describe_config(config: GeGnnConfig) -> str:
    """A model's kind and size in words, for the first lines of a run's log."""
    kind = (f"landmark-guided, K = {config.landmarks}" if config.landmarks else
            f"biharmonic, {config.spectral} spectral modes" if config.spectral else
            "Euclidean decoder" if config.decoder == "euclidean" else "the paper's decoder")
    cloud = f", point clouds (k = {config.points})" if config.points else ""
    return f"GeGnn ({kind}{cloud}, {config.channels} channels, blocks {list(config.encoder_blocks)})"
