"""`gegnn train --model NAME` and `--init NAME` (issue 57): a preset is the shipped model's architecture, fields
and recorded schedule, fine-tuned from its weights; explicit options override it; the log says what a run is and
what it will cost."""
import hashlib
import logging
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

import gegnn.training.loop as gtrain
from gegnn import GeGnn
from gegnn.checkpoint import load_checkpoint, read_config
from gegnn.cli import main
from gegnn.model import PRETRAINED, pretrained_file
from gegnn.training.estimate import StepClock, readable_seconds
from gegnn.training.loop import TrainConfig
from gegnn.training.presets import PRESETS, RECIPES, checkpoint_file, preset, recipe_command


def resolved(store, run, *args):
    """The (TrainConfig, GeGnnConfig) `gegnn train STORE --run RUN ARGS` hands the training loop (no training)."""
    seen = []
    real, gtrain.train = gtrain.train, lambda cfg, model_cfg: seen.append((cfg, model_cfg))
    try:  # the command imports the loop's train when it runs
        result = CliRunner().invoke(main, ["train", store, "--run", str(run), *args])
    finally:
        gtrain.train = real
    assert result.exit_code == 0, result.output
    return seen[0]


def built(cfg, model_cfg):
    """The model the run would train (its config and starting weights), as the loop builds it."""
    return gtrain.build_model(cfg, model_cfg, None, torch.device("cpu"))[0]


def shipped_config(name):
    with pretrained_file(name) as path:
        return read_config(path)


@pytest.mark.parametrize("name", PRESETS)
def test_a_presets_model_is_the_shipped_models_config(name, tiny_store, tmp_path):
    cfg, model_cfg = resolved(tiny_store, tmp_path / "run", "--model", name)
    assert cfg.model == name and cfg.init == name
    assert built(cfg, model_cfg).config == shipped_config(name)


@pytest.mark.parametrize("name", PRESETS)
def test_a_preset_from_scratch_is_refused_with_the_command_of_its_whole_recipe(name, tiny_store, tmp_path):
    """The recorded schedule is the shipped file's last run (a fine-tune): on random weights it is not the recipe.
    The one-line refusal names every script of the recipe, each of which exists, the last exporting the shipped
    file itself."""
    result = CliRunner().invoke(main, ["train", tiny_store, "--run", str(tmp_path / "r"), "--model", name,
                                       "--init", "none"])
    assert result.exit_code == 1 and not (tmp_path / "r").exists()
    assert result.output.count("\n") == 1 and result.output.endswith(f"{recipe_command(name)}\n")
    root = Path(__file__).parents[2]
    assert all((root / script).is_file() for script in RECIPES[name])
    last = (root / RECIPES[name][-1]).read_text()
    assert "gegnn export" in last and PRETRAINED[name] in last
    with pytest.raises(ValueError, match="several runs"):
        preset(name, None)


def test_a_presets_schedule_is_the_recorded_one_gentled_for_a_fine_tune(tiny_store, tmp_path):
    recorded = load_checkpoint(checkpoint_file("paper")).metadata["train_config"]
    cfg, _ = resolved(tiny_store, tmp_path / "run", "--model", "paper")  # fine-tuned from its own weights
    assert (cfg.epochs, cfg.batch_size, cfg.clip_grad, cfg.pairs_per_mesh, recorded["lr"]) == \
        (recorded["epochs"], recorded["batch_size"], recorded["clip_grad"], recorded["pairs_per_mesh"], 2e-3) == \
        (27, 4, 1.0, 20000, 2e-3)
    assert cfg.lr == 1e-4 and cfg.warmup_epochs == recorded["warmup_epochs"] == 0.5 and cfg.init == "paper"
    landmark = load_checkpoint(checkpoint_file("landmark")).metadata["train_config"]
    assert landmark["decoder_warmup"] == 20000  # trained a decoder new to K = 256 ...
    assert preset("landmark").schedule["decoder_warmup"] == 0  # ... which its own fine-tune has already
    assert preset("landmark", "landmark-v1").schedule["decoder_warmup"] == 20000
    cfg, _ = resolved(tiny_store, tmp_path / "run", "--model", "biharmonic")
    assert cfg.distance == "biharmonic" and cfg.lr == 1e-4 and cfg.warmup_epochs == 0.1


def test_init_by_name_loads_the_shipped_weights(tiny_store, tmp_path):
    shipped = GeGnn.pretrained("landmark").state_dict()
    for args in (["--model", "landmark"], ["--init", "landmark", "--landmarks", "256"]):
        model = built(*resolved(tiny_store, tmp_path / "run", *args))
        state = model.state_dict()
        assert state.keys() == shipped.keys()
        assert all(torch.equal(state[k], shipped[k]) for k in shipped)


def test_an_explicit_option_overrides_the_preset(tiny_store, tmp_path):
    cfg, model_cfg = resolved(tiny_store, tmp_path / "run", "--model", "landmark", "--lr", "3e-4", "--epochs", "2",
                              "--landmarks", "8", "--batch-size", "2", "--decoder-warmup", "5", "--init", "landmark-v1")
    assert (cfg.lr, cfg.epochs, cfg.batch_size, cfg.decoder_warmup, cfg.init) == (3e-4, 2, 2, 5, "landmark-v1")
    assert (cfg.pairs_per_mesh, cfg.clip_grad, cfg.warmup_epochs) == (20000, 1.0, 0.1)  # the preset's
    model = built(cfg, model_cfg)
    assert model.config.landmarks == 8 and model.config.channels == 64
    v1 = GeGnn.pretrained("landmark-v1").state_dict()  # its decoder's weights do not depend on K
    assert all(torch.equal(model.state_dict()[k], v1[k]) for k in v1)


def test_plain_train_is_the_paper_network_with_the_old_defaults(tiny_store, tmp_path):
    cfg, model_cfg = resolved(tiny_store, tmp_path / "run")
    assert cfg == TrainConfig(store=tiny_store, run=str(tmp_path / "run"))
    assert model_cfg.channels == 256 and model_cfg.landmarks == 0


def test_an_unknown_init_or_model_is_refused(tiny_store, tmp_path):
    for args, words in ((["--init", "landmark-v9"], "no such file"), (["--model", "bunny"], "bunny")):
        result = CliRunner().invoke(main, ["train", tiny_store, "--run", str(tmp_path / "r"), *args])
        assert result.exit_code == 2 and words in result.output


def test_the_log_says_model_size_device_and_the_estimate(tiny_store, tmp_path):
    run = tmp_path / "run"
    result = CliRunner().invoke(main, ["train", tiny_store, "--run", str(run), "--model", "landmark", "--landmarks",
                                       "8", "--pairs-per-mesh", "200", "--batch-size", "1", "--epochs", "2",
                                       "--device", "cpu"])
    assert result.exit_code == 0, result.output
    lines = [line.split(" ", 2)[2] for line in (run / "train.log").read_text().splitlines()]
    params = sum(p.numel() for p in GeGnn.pretrained("landmark").parameters())
    assert lines[0].startswith("model: preset landmark: GeGnn (landmark-guided, K = 8, 64 channels")
    assert f"{params:,} parameters, on cpu (" in lines[0] and "fine-tuned from landmark" in lines[0]
    estimate = next(line for line in lines if line.startswith("estimate: "))
    assert " s a step (steps 2-3 timed) -> ~" in estimate and "an epoch of 3 steps" in estimate
    assert "for the run's 2 epoch(s)" in estimate
    assert any(line.startswith("first epoch: ") for line in lines)
    assert lines.index(estimate) < next(i for i, line in enumerate(lines) if line.startswith("epoch 0 "))
    with pretrained_file("landmark") as path:  # the weights it started from, by their bytes: a name can move
        started_from = hashlib.sha256(path.read_bytes()).hexdigest()
    assert load_checkpoint(run / "best.safetensors").metadata["train_config"]["init_sha256"] == started_from


def test_the_estimate_hints_at_a_preset_and_a_gpu_where_they_would_be_much_faster(caplog):
    log = logging.getLogger("test_presets")
    paper = TrainConfig(store="s", run="r", epochs=100, batch_size=4)
    clock = StepClock(log, paper, GeGnn().config, torch.device("cpu"), steps_per_epoch=250, epochs_left=100)
    with caplog.at_level(logging.INFO, logger="test_presets"):
        clock._log_estimate(step_s=4.0, timed="steps 2-4")
    text = caplog.text
    assert "4.00 s a step (steps 2-4 timed) -> ~16.7 min an epoch of 250 steps, ~27.8 h for the run's 100 epoch(s)" in text
    assert "hint: --model landmark" in text and "hint: one GPU takes ~0.09 s a step at batch 4" in text
    assert "this run in ~37.5 min" in text  # 25,000 steps of 0.09 s
    assert "epoch(s) (validation not included)" in text  # no preset: the run is the whole of it
    caplog.clear()
    small = TrainConfig(store="s", run="r", epochs=1, batch_size=4, model="landmark", init="landmark")
    clock = StepClock(log, small, shipped_config("landmark"), torch.device("cpu"), 10, 1)
    with caplog.at_level(logging.INFO, logger="test_presets"):
        clock._log_estimate(step_s=1.0, timed="steps 2-4")
    assert "estimate" in caplog.text and "hint" not in caplog.text
    assert "(this fine-tune alone, not preset landmark's whole recipe; validation not included)" in caplog.text
    assert [readable_seconds(s) for s in (0.4, 40, 600, 7200, 86400 * 3)] == [
        "0.4 s", "40 s", "10.0 min", "2.0 h", "3.0 days"]


def test_eval_takes_a_shipped_models_name(tiny_store):
    result = CliRunner().invoke(main, ["eval", "paper", tiny_store, "--device", "cpu"])
    assert result.exit_code == 0, result.output
    assert result.stdout.strip().splitlines()[-1].startswith("overall")
