"""Where a benchmark ran: the line every benchmark prints, and docs tables carry, so that a number is
never read apart from the machine that produced it."""
from __future__ import annotations

import os
import platform
from pathlib import Path

import torch


def cpu_description() -> str:
    """CPU model, cores, the instruction sets that decide our kernels' speed (AVX2, AVX512, native bf16:
    AVX512-BF16 or AMX; without it bf16 is emulated) and the inference precision "auto" picks here."""
    from gegnn.precision import resolve

    info = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    model = next((line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")),
                 platform.processor() or platform.machine())
    isa = {"AVX2": torch.cpu._is_avx2_supported(), "AVX512": torch.cpu._is_avx512_supported(),
           "AVX512-BF16": torch.cpu._is_avx512_bf16_supported(), "AMX": torch.cpu._is_amx_tile_supported()}
    flags = ", ".join(name if present else f"no {name}" for name, present in isa.items())
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    from gegnn.decoders import compiled_isa

    return (f"{model}, {cores} cores ({flags}); precision fp32 unless a row says otherwise "
            f"(auto: {resolve('auto', 'cpu')} here); compiled decode: {compiled_isa()}")
