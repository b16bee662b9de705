"""Single-file safetensors checkpoints: tensors plus JSON metadata; nothing is pickled.

Keys: model weights under their ``state_dict`` names; optimizer state under ``optimizer/<param>/<name>``;
RNG states under ``rng/<name>``. Metadata: ``format``, ``config`` (GeGnnConfig JSON), ``optimizer``
(param groups and non-tensor state), ``trainer`` (epoch, step, ...) and anything the caller adds.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import torch
from safetensors.torch import load_file, save_file

from .config import GeGnnConfig

__all__ = ["Checkpoint", "save_checkpoint", "load_checkpoint"]

FORMAT = "gegnn-checkpoint-1"
OPT, RNG = "optimizer/", "rng/"


@dataclass
class Checkpoint:
    config: GeGnnConfig
    model_state: dict
    optimizer_state: dict | None = None
    rng: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)


def save_checkpoint(path, model, optimizer=None, rng: dict | None = None,
                    metadata: dict | None = None, dtype: torch.dtype | None = None) -> None:
    """Write atomically (temp file, then rename) so a killed run never leaves a torn checkpoint.

    ``dtype`` (e.g. torch.float16) casts the floating-point weights: for shipping, not for resuming."""
    tensors = {k: v.detach().cpu().to(dtype if dtype and v.is_floating_point() else v.dtype).contiguous()
               for k, v in model.state_dict().items()}
    meta = {"format": FORMAT, "config": model.config.to_json()}
    if optimizer is not None:
        opt_tensors, meta["optimizer"] = _flatten_optimizer(optimizer.state_dict())
        tensors.update(opt_tensors)
    tensors.update({RNG + k: v.contiguous() for k, v in (rng or {}).items()})
    meta.update({k: v if isinstance(v, str) else json.dumps(v) for k, v in (metadata or {}).items()})
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    save_file(tensors, str(tmp), metadata=meta)
    tmp.replace(path)


def read_config(path) -> GeGnnConfig:
    """The model config of a checkpoint, from its metadata alone (no tensor is read)."""
    return GeGnnConfig.from_json(_metadata(path)["config"])


def _metadata(path) -> dict:
    from safetensors import safe_open

    with safe_open(str(path), framework="pt") as f:
        meta = f.metadata() or {}
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path}: not a gegnn checkpoint (format {meta.get('format')!r})")
    return meta


def load_checkpoint(path, map_location="cpu") -> Checkpoint:
    meta = _metadata(path)
    tensors = load_file(str(path), device=str(map_location))
    model = {k: v for k, v in tensors.items() if not k.startswith((OPT, RNG))}
    opt = _unflatten_optimizer(tensors, meta["optimizer"]) if "optimizer" in meta else None
    rng = {k[len(RNG):]: v for k, v in tensors.items() if k.startswith(RNG)}
    extra = {k: _maybe_json(v) for k, v in meta.items() if k not in ("format", "config", "optimizer")}
    return Checkpoint(GeGnnConfig.from_json(meta["config"]), model, opt, rng, extra)


def _flatten_optimizer(state_dict: dict) -> tuple[dict, str]:
    tensors, scalars = {}, {}
    for pid, state in state_dict["state"].items():
        for name, value in state.items():
            if torch.is_tensor(value):
                tensors[f"{OPT}{pid}/{name}"] = value.detach().cpu().contiguous()
            else:
                scalars.setdefault(str(pid), {})[name] = value
    return tensors, json.dumps({"param_groups": state_dict["param_groups"], "scalars": scalars})


def _unflatten_optimizer(tensors: dict, text: str) -> dict:
    info = json.loads(text)
    state: dict = {}
    for key, value in tensors.items():
        if key.startswith(OPT):
            pid, name = key[len(OPT):].split("/", 1)
            state.setdefault(int(pid), {})[name] = value
    for pid, values in info["scalars"].items():
        state.setdefault(int(pid), {}).update(values)
    return {"state": state, "param_groups": info["param_groups"]}


def _maybe_json(text: str):
    try:
        return json.loads(text)
    except (json.JSONDecodeError, TypeError):
        return text
