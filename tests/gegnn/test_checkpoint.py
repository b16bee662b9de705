import json

import numpy as np
import torch
from gegnn_stores import ellipsoid, small_config
from safetensors import safe_open

from gegnn import GeGnn
from gegnn.checkpoint import load_checkpoint, save_checkpoint


def test_from_checkpoint_gives_identical_outputs(tmp_path):
    torch.manual_seed(0)
    model = GeGnn(small_config(aggr="mean", sigma_n=float("inf")))
    path = tmp_path / "m.safetensors"
    model.save(path)
    with safe_open(str(path), framework="pt") as f:  # a plain safetensors file with the config as JSON
        assert json.loads(f.metadata()["config"])["aggr"] == "mean"
    loaded = GeGnn.from_checkpoint(path)
    assert loaded.config == model.config
    v, f = ellipsoid()
    i, j = np.arange(100), np.arange(100)[::-1]
    np.testing.assert_array_equal(loaded.embed(v, f).distance(i, j), model.embed(v, f).distance(i, j))


def test_optimizer_and_rng_round_trip(tmp_path):
    torch.manual_seed(0)
    model = GeGnn(small_config())
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3)
    model.distance(torch.randn(4, 16), torch.randn(4, 16)).sum().backward()
    opt.step()
    rng = torch.get_rng_state()
    save_checkpoint(tmp_path / "c.safetensors", model, opt, {"torch": rng}, {"trainer": {"epoch": 3}})
    ckpt = load_checkpoint(tmp_path / "c.safetensors")
    opt2 = torch.optim.AdamW(GeGnn(ckpt.config).parameters(), lr=1e-3)
    opt2.load_state_dict(ckpt.optimizer_state)
    for a, b in zip(opt.state_dict()["state"].values(), opt2.state_dict()["state"].values()):
        for k in a:
            torch.testing.assert_close(a[k], b[k], rtol=0, atol=0)
    assert torch.equal(ckpt.rng["torch"], rng) and ckpt.metadata["trainer"] == {"epoch": 3}
