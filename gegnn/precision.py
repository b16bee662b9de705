"""The arithmetic precision of inference: one choice for the network and the decoder.

``"fp32"`` is the default everywhere: the same results and, within the hardware's speed, the same
relative speed on every machine. ``"bf16"`` runs the network under bf16 autocast and the decoder's hidden
layers in bf16 (distances move by ~0.1-1% relative, below the models' errors). ``"auto"`` is bf16 only
where the hardware computes bf16 natively and it was measured faster: CUDA GPUs of compute capability
8.0 or newer, and CPUs with AVX512-BF16 or AMX (1M landmark queries 1.57x faster than fp32 on an AMD EPYC
with AVX512-BF16, docs/benchmarks.md). Elsewhere bf16 is emulated: on an Intel Xeon with AVX512 but without
AVX512-BF16, oneDNN's emulated bf16 decode took 2.0-2.4x the time of fp32, so "auto" is fp32 there.
"""
from __future__ import annotations

import torch

PRECISIONS = ("fp32", "bf16", "auto")
DTYPES = {"fp32": torch.float32, "bf16": torch.bfloat16}


def native_bf16(device) -> bool:
    """Whether ``device`` computes bf16 in hardware (not emulated): a CUDA GPU of compute capability 8.0 or
    newer, or a CPU with AVX512-BF16 or AMX tiles."""
    device = torch.device(device)
    if device.type == "cuda":
        return torch.cuda.get_device_capability(device)[0] >= 8
    if device.type == "cpu":
        return bool(torch.cpu._is_avx512_bf16_supported() or torch.cpu._is_amx_tile_supported())
    return False


def resolve(precision: str, device) -> str:
    """``"fp32"`` or ``"bf16"`` for ``precision`` (one of :data:`PRECISIONS`) on ``device``."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(map(repr, PRECISIONS))}, got {precision!r}")
    if precision == "auto":
        return "bf16" if native_bf16(device) else "fp32"
    return precision


def resolve_decoder(precision: str, device, compiled: bool) -> str:
    """The decoder's precision: :func:`resolve`, except that ``"auto"`` stays ``"fp32"`` on a CPU where the
    decoder has a ``compiled`` fp32 decode."""
    if precision == "auto" and compiled and torch.device(device).type == "cpu":
        return "fp32"
    return resolve(precision, device)
