"""One precision for the network and the decoder, chosen the same way on every machine: the hardware probe
is forced both ways, so these tests pass alike on CPUs with and without native bf16."""
import numpy as np
import pytest
import torch
from gegnn_stores import ellipsoid

import gegnn.precision as gprecision
from gegnn import GeGnn


@pytest.fixture(params=[True, False], ids=["native-bf16", "no-native-bf16"])
def native(request, monkeypatch):
    monkeypatch.setattr(gprecision, "native_bf16", lambda device: request.param)
    return request.param


def test_auto_is_bf16_only_where_native(native):
    assert gprecision.resolve("auto", "cpu") == ("bf16" if native else "fp32")
    assert gprecision.resolve("fp32", "cpu") == "fp32" and gprecision.resolve("bf16", "cpu") == "bf16"
    with pytest.raises(ValueError, match="precision must be one of"):
        gprecision.resolve("fp16", "cpu")


def test_auto_keeps_a_compiled_fp32_decoder_on_a_cpu(native):
    """A decoder with a compiled fp32 decode stays fp32 under auto on a CPU; any other follows the hardware;
    an explicit choice is kept."""
    assert gprecision.resolve_decoder("auto", "cpu", compiled=True) == "fp32"
    assert gprecision.resolve_decoder("auto", "cpu", compiled=False) == ("bf16" if native else "fp32")
    assert gprecision.resolve_decoder("bf16", "cpu", compiled=True) == "bf16"
    with pytest.raises(ValueError, match="precision must be one of"):
        gprecision.resolve_decoder("fp16", "cpu", compiled=True)


def test_the_probe_reads_the_hardware(monkeypatch):
    """CPUs: AVX512-BF16 or AMX tiles (AVX512 alone emulates bf16); CUDA: compute capability 8.0 or newer."""
    for avx512_bf16, amx, expected in [(False, False, False), (True, False, True), (False, True, True)]:
        monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda: avx512_bf16)
        monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda: amx)
        assert gprecision.native_bf16("cpu") is expected
    for capability, expected in [((7, 5), False), ((8, 0), True), ((9, 0), True)]:
        monkeypatch.setattr(torch.cuda, "get_device_capability", lambda device: capability)
        assert gprecision.native_bf16("cuda") is expected
    assert gprecision.native_bf16("meta") is False


@pytest.fixture(scope="module")
def landmark_model():
    return GeGnn.pretrained()


def test_embed_gives_its_precision_to_the_decoder(native, landmark_model):
    """The default is fp32 for the network and the decoder whatever the CPU (the bug: a bf16 decoder
    wherever oneDNN reported bf16 support, emulated or not); bf16 and auto reach the decoder too."""
    v, f = ellipsoid(subdivisions=3)
    fp32 = landmark_model.embed(v, f)
    assert fp32.dtype == torch.float32 and fp32.precision == "fp32"
    assert landmark_model.embed(v, f, precision="bf16").dtype == torch.bfloat16
    # auto: the landmark decoder's compiled fp32 decode is faster than bf16 through torch, native or not
    assert landmark_model.embed(v, f, precision="auto").dtype == torch.float32
    i, j = np.arange(0, 600, 3), np.arange(1, 601, 3)
    d32 = fp32.distance(i, j)
    d16 = landmark_model.embed(v, f, precision="bf16").distance(i, j)
    rel = np.abs(d16 - d32) / d32
    assert 0 < rel.max() and np.median(rel) < 0.01  # bf16 is a real change, and a small one


def test_embed_refuses_an_unknown_precision(landmark_model):
    v, f = ellipsoid()
    with pytest.raises(ValueError, match="precision must be one of"):
        landmark_model.embed(v, f, precision="half")
