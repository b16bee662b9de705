import csv
import dataclasses
import json
import logging
import re
import socket
from pathlib import Path

import pytest
import torch
import torch.multiprocessing as mp
from gegnn_stores import overfit, small_config

import gegnn.training.loop as gtrain
from gegnn import GeGnn
from gegnn.checkpoint import load_checkpoint
from gegnn.distributed import Dist
from gegnn.fields.cache import FieldSpec
from gegnn.metrics import relative_error
from gegnn.training.data import BatchDataset
from gegnn.training.loop import TrainConfig, train
from gegnn.training.warmup import warm_decoder


def test_overfit_one_mesh_learns(one_mesh_store):
    first, last = overfit(one_mesh_store, 50)
    assert first > 0.5 and last < 0.10


def test_overfit_one_mesh_below_3_percent(one_mesh_store):
    assert overfit(one_mesh_store, 200)[1] < 0.03


def config(store, run, **kw):
    # deterministic: where a GPU is present (device auto), resume must be bitwise there too
    options = dict(epochs=2, batch_size=2, lr=2e-3, pairs_per_mesh=400, warmup_epochs=0.5, clip_grad=1.0,
                   deterministic=True)
    return TrainConfig(store=store, run=str(run), **{**options, **kw})


def weights(path):
    return load_checkpoint(path).model_state


def test_run_files_and_resume_equals_uninterrupted(tiny_store, tmp_path, monkeypatch):
    full = train(config(tiny_store, tmp_path / "full"), small_config())
    run = tmp_path / "killed"
    original = gtrain.save_run

    def save_then_die(*args, **kw):  # kill the run right after epoch 0 was saved
        original(*args, **kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(gtrain, "save_run", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        train(config(tiny_store, run), small_config())
    monkeypatch.setattr(gtrain, "save_run", original)
    resumed = train(config(tiny_store, run, resume=True), small_config(channels=8))  # config from ckpt

    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in full]
    assert [{k: v for k, v in r.items() if k != "seconds"} for r in resumed] == strip
    a, b = weights(tmp_path / "full" / "last.safetensors"), weights(run / "last.safetensors")
    assert all(torch.equal(a[k], b[k]) for k in a)

    out = tmp_path / "full"
    assert {"metrics.csv", "last.safetensors", "best.safetensors", "curves.png", "train.log"} <= \
        {p.name for p in out.iterdir()}
    with open(out / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["epoch"]) for r in rows] == [0, 1] and list(rows[0]) == gtrain.METRICS
    assert [r["step"] for r in rows] == ["2", "4"]  # 4 training meshes, batches of 2
    log = (out / "train.log").read_text()
    assert "epoch 1 step 4 lr" in log and "train_mre" in log and "val_mre" in log
    assert all(re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d ", line) for line in log.splitlines())  # greppable by time


def test_the_curves_are_drawn_at_once_and_with_the_last_epoch(tiny_store, tmp_path, monkeypatch):
    """curves.png: drawn after the first epoch, then at most every 30 s, and always after the last one."""
    drawn = []
    monkeypatch.setattr(gtrain, "plot_curves", lambda run, rows: drawn.append(len(rows)))
    train(config(tiny_store, tmp_path / "run", epochs=3), small_config())
    assert drawn[0] == 1 and drawn[-1] == 3


def test_a_run_warms_the_decoder_alone_first_and_not_again_when_resumed(tiny_store, tmp_path, monkeypatch):
    """--decoder-warmup N: N decoder-only steps before the first epoch (the network untouched, the decoder
    moved), its validation logged; a resumed run does not warm again."""
    real, calls = gtrain.warm_decoder, []

    def spy(model, loader, steps, *args):
        before = {k: v.clone() for k, v in model.state_dict().items()}
        real(model, loader, steps, *args)
        after = model.state_dict()
        calls.append(steps)
        assert all(torch.equal(after[k], v) for k, v in before.items() if not k.startswith("distance."))
        assert not all(torch.equal(after[k], v) for k, v in before.items() if k.startswith("distance."))

    monkeypatch.setattr(gtrain, "warm_decoder", spy)
    run = tmp_path / "run"
    train(config(tiny_store, run, epochs=1, decoder_warmup=5), small_config(landmarks=4))
    assert calls == [5]
    log = (run / "train.log").read_text()
    assert "decoder warm-up: 5 steps on" in log and "after the decoder warm-up: val_mre" in log
    train(config(tiny_store, run, epochs=2, decoder_warmup=5, resume=True), small_config(landmarks=4))
    assert calls == [5]


def test_a_step_sets_the_learning_rate_it_is_given(tiny_store):
    torch.manual_seed(0)
    model = GeGnn(small_config())
    batch = BatchDataset(tiny_store, "geodesic", 0, 200, False, 5, 1 / 16, 3 / 16)[(0, ("grid", "sphere"))]
    optimizer = torch.optim.AdamW(model.parameters(), lr=1.0, weight_decay=0.05)
    before = {k: v.clone() for k, v in model.state_dict().items()}
    gtrain.train_step(model, batch, optimizer, 0.0, 1.0, torch.device("cpu"))
    assert optimizer.param_groups[0]["lr"] == 0.0
    assert all(torch.equal(v, before[k]) for k, v in model.state_dict().items())  # lr 0: nothing moves
    gtrain.train_step(model, batch, optimizer, 1e-3, 1.0, torch.device("cpu"))
    assert optimizer.param_groups[0]["lr"] == 1e-3
    assert not all(torch.equal(v, before[k]) for k, v in model.state_dict().items())


@pytest.mark.parametrize("batch_size", [1, 3])
def test_an_epochs_train_mre_is_the_mean_of_its_steps_losses(tiny_store, tmp_path, monkeypatch, batch_size):
    """Also for an epoch of one step (3 training meshes in one batch)."""
    losses, real = [], gtrain.train_step
    monkeypatch.setattr(gtrain, "train_step", lambda *a: losses.append(real(*a)) or losses[-1])
    rows = train(config(tiny_store, tmp_path / "run", epochs=1, batch_size=batch_size), small_config())
    assert len(losses) == 3 // batch_size
    assert float(rows[0]["train_mre"]) == pytest.approx(torch.stack(losses).double().mean().item(), abs=1e-6)


def test_a_run_without_resume_starts_afresh_where_one_ended(tiny_store, tmp_path):
    train(config(tiny_store, tmp_path / "run"), small_config())
    rows = train(config(tiny_store, tmp_path / "run", epochs=1), small_config())
    assert [r["epoch"] for r in rows] == ["0"]
    with open(tmp_path / "run" / "metrics.csv") as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["0"]


def test_a_run_reads_the_distances_and_the_graph_it_is_asked_for(tiny_store, one_mesh_store, tmp_path, monkeypatch):
    """--distance biharmonic on a store without biharmonic distances is refused (never trained on geodesic
    ones); a point-cloud model's batches are built on its k-nearest-neighbour graph."""
    with pytest.raises(ValueError, match="no committed meshes with biharmonic distances"):
        train(config(one_mesh_store, tmp_path / "b", distance="biharmonic"), small_config(spectral=4))
    made = []
    monkeypatch.setattr(gtrain, "BatchDataset", lambda *a: made.append(a[-1]) or BatchDataset(*a))
    train(config(tiny_store, tmp_path / "p", epochs=1), small_config(landmarks=4, points=8))
    assert made == [8, 8]  # the training and the validation batches


def test_init_starts_from_weights(tiny_store, tmp_path):
    train(config(tiny_store, tmp_path / "a", epochs=1), small_config())
    rows = train(config(tiny_store, tmp_path / "b", epochs=1, init=str(tmp_path / "a" / "best.safetensors"),
                        distance="biharmonic"), small_config(channels=8))
    # The network's config comes from the checkpoint; the distance trained on is recorded.
    got = load_checkpoint(tmp_path / "b" / "last.safetensors").config
    assert got == small_config(distance="biharmonic") and len(rows) == 1


def test_init_weights_are_the_starting_point(tiny_store, tmp_path):
    """--init: every tensor of the checkpoint is the new model's starting value; a landmark decoder on a
    paper model's network keeps the network's tensors and starts its own decoder fresh."""
    train(config(tiny_store, tmp_path / "a", epochs=1), small_config())
    ckpt = load_checkpoint(tmp_path / "a" / "best.safetensors")
    same = TrainConfig(store=tiny_store, run=str(tmp_path / "b"), init=str(tmp_path / "a" / "best.safetensors"))
    model = gtrain.build_model(same, small_config(channels=8), None, torch.device("cpu"))[0]
    state = model.state_dict()
    assert state.keys() == ckpt.model_state.keys()
    assert all(torch.equal(state[k], ckpt.model_state[k].to(state[k].dtype)) for k in state)
    torch.manual_seed(1)
    landmark = gtrain.build_model(same, small_config(landmarks=4), None, torch.device("cpu"))[0].state_dict()
    network = [k for k in landmark if not k.startswith("distance.")]
    assert network and all(torch.equal(landmark[k], ckpt.model_state[k].to(landmark[k].dtype)) for k in network)
    assert all(k not in ckpt.model_state or landmark[k].shape != ckpt.model_state[k].shape
               or not torch.equal(landmark[k], ckpt.model_state[k]) for k in landmark if k.startswith("distance."))


def test_init_keeps_a_landmark_decoder_for_another_k(tiny_store, tmp_path):
    """--init from a K = 4 landmark model with --landmarks 8: every tensor, the decoder's included, is the
    checkpoint's (its weights do not depend on K), also with fields of another solver (--landmark-fields vsp);
    another decoder form (interval) starts its own."""
    torch.manual_seed(0)
    k4 = GeGnn(small_config(landmarks=4))
    with torch.no_grad():  # a decoder unlike a fresh one (whose last layer is zero)
        for p in k4.distance.parameters():
            p.normal_()
    k4.save(tmp_path / "k4.safetensors")
    init = TrainConfig(store=tiny_store, run=str(tmp_path / "b"), init=str(tmp_path / "k4.safetensors"))
    k8 = gtrain.build_model(init, small_config(landmarks=8), None, torch.device("cpu"))[0]
    assert k8.config == small_config(landmarks=8)
    ckpt = load_checkpoint(tmp_path / "k4.safetensors").model_state
    assert k8.state_dict().keys() == ckpt.keys()
    assert all(torch.equal(v, ckpt[k].to(v.dtype)) for k, v in k8.state_dict().items())
    vsp = gtrain.build_model(init, small_config(landmarks=8, landmark_fields="vsp"), None, torch.device("cpu"))[0]
    assert vsp.config.landmark_fields == "vsp"  # fields of another solver: the same decoder, kept whole
    assert all(torch.equal(v, ckpt[k].to(v.dtype)) for k, v in vsp.state_dict().items())
    interval = gtrain.build_model(init, small_config(landmarks=8, landmark_output="interval"), None,
                                  torch.device("cpu"))[0].state_dict()
    decoder = [k for k in interval if k.startswith("distance.") and k.endswith("weight")]
    assert decoder and not any(torch.equal(interval[k], ckpt[k].to(interval[k].dtype)) for k in decoder)


def test_init_takes_the_decoder_kind_asked_for_and_the_networks_shape_from_the_checkpoint(tiny_store, tmp_path):
    """--init from a paper model: --euclidean-decoder is taken (the network's tensors kept); the network's
    blocks come from the checkpoint whatever the command line says; training it for biharmonic distances
    keeps the same decoder's weights (another distance, the same inputs); the fresh tensors are logged."""
    torch.manual_seed(0)
    paper = GeGnn(small_config())
    with torch.no_grad():
        for p in paper.distance.parameters():
            p.normal_()
    paper.save(tmp_path / "paper.safetensors")
    ckpt = load_checkpoint(tmp_path / "paper.safetensors").model_state
    init = TrainConfig(store=tiny_store, run=str(tmp_path / "b"), init=str(tmp_path / "paper.safetensors"))
    messages = []
    log = logging.getLogger("test_init")
    log.info = messages.append
    euclidean = gtrain.build_model(init, small_config(blocks=2, decoder="euclidean"), None, torch.device("cpu"), log)[0]
    assert euclidean.config == small_config(decoder="euclidean")
    assert not any(k.startswith("distance.") for k in euclidean.state_dict())  # the Euclidean decoder has no weights
    assert all(torch.equal(v, ckpt[k]) for k, v in euclidean.state_dict().items())
    spectral = gtrain.build_model(init, small_config(blocks=2, spectral=4), None, torch.device("cpu"), log)[0]
    assert spectral.config.decoder_blocks == (1,) * 5 and spectral.config.spectral == 4
    assert len(messages) == 1 and messages[0].startswith(f"--init {init.init}: ")
    assert "start fresh (distance." in messages[0]
    biharmonic = dataclasses.replace(init, distance="biharmonic")
    model = gtrain.build_model(biharmonic, small_config(), None, torch.device("cpu"))[0]
    assert model.config.distance == "biharmonic"
    assert all(torch.equal(v, ckpt[k]) for k, v in model.state_dict().items())


def test_the_schedule_at_known_steps():
    """Linear warm-up to the peak, then (1 - step / total)^0.9 down to 0 at the last step."""
    base, total, warmup = 1e-3, 100, 10
    assert gtrain.lr_at(0, total, base, warmup) == pytest.approx(1e-4)
    assert gtrain.lr_at(4, total, base, warmup) == pytest.approx(5e-4)
    assert gtrain.lr_at(9, total, base, warmup) == pytest.approx(1e-3)
    assert gtrain.lr_at(10, total, base, warmup) == pytest.approx(1e-3 * 0.9 ** 0.9)
    assert gtrain.lr_at(50, total, base, warmup) == pytest.approx(1e-3 * 0.5 ** 0.9)
    assert gtrain.lr_at(100, total, base, warmup) == 0.0 and gtrain.lr_at(0, total, base, 0) == base


def test_separate_validation_store(tiny_store, one_mesh_store, tmp_path):
    """--val: train on every mesh of the store, validate on every mesh of the other one."""
    rows = train(config(tiny_store, tmp_path / "v", epochs=1, val_store=one_mesh_store), small_config())
    assert "4 train / 1 val meshes" in (tmp_path / "v" / "train.log").read_text()
    model = GeGnn.from_checkpoint(tmp_path / "v" / "last.safetensors")
    ds = BatchDataset(one_mesh_store, "geodesic", 0, 400, False, 5, 1 / 16, 3 / 16)
    batch = ds[(-1, ("ellipsoid",))]  # the fixed validation sample of the other store
    with torch.no_grad():
        expected = relative_error(model(batch.hierarchy, batch.pairs), batch.distances).mean().item()
    assert float(rows[0]["val_mre"]) == pytest.approx(expected, rel=1e-5)


# -- DistributedDataParallel with two gloo processes ------------------------------------------------
def _ddp_worker(rank, port, store, out):
    import torch.distributed as dist

    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=2)
    try:
        torch.manual_seed(0)
        model = GeGnn(small_config())
        ddp = torch.nn.parallel.DistributedDataParallel(model)
        ds = BatchDataset(store, "geodesic", 0, 500, True, 5, 1 / 16, 3 / 16)
        batch = ds[(0, (["grid", "sphere"][rank],))]
        relative_error(ddp(batch.hierarchy, batch.pairs), batch.distances).mean().backward()
        if rank == 0:
            torch.save({k: p.grad for k, p in model.named_parameters()}, Path(out) / "ddp_grads.pt")
        train(TrainConfig(store=store, run=str(Path(out) / "run"), epochs=1, batch_size=1,
                          pairs_per_mesh=200, device="cpu"), small_config())
        # The decoder warm-up runs on every rank, each on its own meshes and pairs, gradients averaged.
        torch.manual_seed(0)
        model = GeGnn(small_config(landmarks=4))
        initial = {k: v.clone() for k, v in model.distance.state_dict().items()}
        ds = BatchDataset(store, "geodesic", 0, 200, False, 5, 1 / 16, 3 / 16, FieldSpec("landmark", 4))
        ctx = Dist(rank, 2)
        keys = gtrain.single_mesh_keys(["grid", "sphere", "ellipsoid_a", "ellipsoid_b"], ctx)
        warm_decoder(model, (ds[k] for k in keys), 20, 3e-3, torch.device("cpu"),
                     logging.getLogger("test"), ctx, pairs_per_step=256)
        assert not torch.equal(model.distance.mlp[0].weight, initial["mlp.0.weight"])
        torch.save(model.distance.state_dict(), Path(out) / f"decoder{rank}.pt")
        train(TrainConfig(store=store, run=str(Path(out) / "lm"), epochs=1, batch_size=1, pairs_per_mesh=200,
                          decoder_warmup=10, device="cpu"), small_config(landmarks=4))
    finally:
        dist.destroy_process_group()


def _free_ports(n):
    sockets = [socket.socket() for _ in range(n)]
    for s in sockets:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_ddp_two_processes_average_gradients(tiny_store, tmp_path):
    mp.spawn(_ddp_worker, args=(_free_port(), tiny_store, str(tmp_path)), nprocs=2, join=True)
    ddp_grads = torch.load(tmp_path / "ddp_grads.pt", weights_only=True)
    torch.manual_seed(0)
    model = GeGnn(small_config())  # single process, the union of both ranks' data in one batch
    batch = BatchDataset(tiny_store, "geodesic", 0, 500, True, 5, 1 / 16, 3 / 16)[(0, ("grid", "sphere"))]
    relative_error(model(batch.hierarchy, batch.pairs), batch.distances).mean().backward()
    for k, p in model.named_parameters():
        torch.testing.assert_close(ddp_grads[k], p.grad, atol=1e-6, rtol=1e-4)
    with open(tmp_path / "run" / "metrics.csv") as f:
        assert len(list(csv.DictReader(f))) == 1
    decoders = [torch.load(tmp_path / f"decoder{r}.pt", weights_only=True) for r in (0, 1)]
    assert all(torch.equal(decoders[0][k], decoders[1][k]) for k in decoders[0])
    log = (tmp_path / "lm" / "train.log").read_text()
    assert "decoder warm-up: 10 steps on 2 meshes' codes per process" in log and "epoch 0" in log


# -- every model kind under DDP, as torchrun starts it: the trainer makes and ends the process group ---------
KINDS = {"paper": ("geodesic", {}), "landmark": ("geodesic", {"landmarks": 4}),
         "spectral": ("biharmonic", {"spectral": 4}),
         "spectral-no-embedding": ("biharmonic", {"spectral": 4, "spectral_embedding": False}),
         "points": ("geodesic", {"landmarks": 4, "points": 8})}


def _ddp_kinds_worker(rank, ports, store, out):
    import os

    import torch.distributed as dist

    import gegnn.fields.cache

    os.environ.update(MASTER_ADDR="127.0.0.1", RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE="2",
                      LOCAL_WORLD_SIZE="2")
    torch.set_num_threads(1)
    # After the fill, the loader must read every field from the cache: computing one fails the run.
    gegnn.fields.cache.FieldSpec.compute = lambda *a, **k: (_ for _ in ()).throw(AssertionError("a field was computed"))
    for port, (name, (distance, options)) in zip(ports, KINDS.items()):
        os.environ["MASTER_PORT"] = str(port)  # a run of its own, as torchrun would start it
        train(TrainConfig(store=store, run=str(Path(out) / name), epochs=2, batch_size=1, pairs_per_mesh=200,
                          distance=distance, device="cpu", workers=0), small_config(**options))
        assert not dist.is_initialized()  # the trainer made the group, and ended it


def test_ddp_trains_every_model_kind_from_a_cache_both_ranks_filled(tmp_path):
    """Two gloo processes, two epochs each (several steps: DDP raises on the second step where a parameter
    got no gradient it did not expect), for the paper, landmark, spectral (with and without embeddings) and
    point-cloud models; the store holds one mesh twice under two ids, whose fields are stored once (the ranks
    share meshes by id: both may compute them, the first to publish wins, and the log counts what was stored).
    The loaders never compute a field (FieldSpec.compute raises in both ranks)."""
    from gegnn_stores import FOUR_MESHES, write_store

    from gegnn.training.data import GeodesicStore

    store = write_store(tmp_path / "dup.zarr", {**FOUR_MESHES, "sphere_copy": FOUR_MESHES["sphere"]}, biharmonic=True)
    mp.spawn(_ddp_kinds_worker, args=(_free_ports(len(KINDS)), store, str(tmp_path)), nprocs=2, join=True)
    s = GeodesicStore(store)
    train_ids, val_ids = gtrain.split_meshes(s.mesh_ids, 0.1)
    train_keys = {s.geometry(m).key for m in train_ids}
    val_keys = {s.geometry(m).key for m in val_ids} - train_keys
    assert len(train_keys | val_keys) == 4  # the copy shares the sphere's key
    for name, (_, options) in KINDS.items():
        log = (tmp_path / name / "train.log").read_text()
        assert "2 process(es)" in log and "epoch 1 " in log
        if options.get("landmarks"):
            assert f"landmark fields: {4 * len(train_keys) + len(val_keys)} computed" in log
        elif options.get("spectral"):
            assert f"spectral fields: {len(train_keys | val_keys)} computed" in log


# -- --resume on the store given: moved or copied it continues, another dataset is refused ----------------
def _killed_after_epoch_0(cfg, monkeypatch, model_config=None):
    original = gtrain.save_run

    def save_then_die(*args, **kw):
        original(*args, **kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(gtrain, "save_run", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, model_config or small_config())
    monkeypatch.setattr(gtrain, "save_run", original)


def test_a_resumed_run_trains_on_the_store_given_moved_or_copied(tiny_store, tmp_path, monkeypatch):
    """The store and its --val store renamed after epoch 0: the resume reads them where they are now, and
    ends as the uninterrupted run (the fingerprints are of the content, not the path)."""
    import shutil

    full = train(config(tiny_store, tmp_path / "full"), small_config())
    store, val = (str(shutil.copytree(tiny_store, tmp_path / name)) for name in ("a.zarr", "v.zarr"))
    run = tmp_path / "run"
    _killed_after_epoch_0(config(store, run), monkeypatch)
    moved = (tmp_path / "a.zarr").rename(tmp_path / "scratch.zarr")
    resumed = train(config(str(moved), run, resume=True), small_config())
    assert [{k: v for k, v in r.items() if k != "seconds"} for r in resumed] == \
        [{k: v for k, v in r.items() if k != "seconds"} for r in full]
    assert load_checkpoint(run / "last.safetensors").metadata["train_config"]["store"] == str(moved)
    record = json.loads((run / "stores.json").read_text())
    assert record["store"]["path"] == str(moved) and record["val_store"] is None
    assert record["store"]["mesh_ids"] == ["ellipsoid_a", "ellipsoid_b", "grid", "sphere"]

    # --val too: taken from the command line where given, else the run's own
    run = tmp_path / "val-run"
    _killed_after_epoch_0(config(str(moved), run, val_store=str(val)), monkeypatch)
    other_val = (tmp_path / "v.zarr").rename(tmp_path / "v2.zarr")
    rows = train(config(str(moved), run, val_store=str(other_val), resume=True, epochs=3), small_config())
    assert [r["epoch"] for r in rows] == ["0", "1", "2"]
    assert "4 train / 4 val meshes" in (run / "train.log").read_text()


def test_a_resume_on_another_dataset_is_refused_in_one_line_saying_what_differs(tiny_store, one_mesh_store,
                                                                               tmp_path, monkeypatch):
    from click.testing import CliRunner
    from gegnn_stores import FOUR_MESHES, write_store

    from gegnn.cli import main

    run = tmp_path / "run"
    _killed_after_epoch_0(config(tiny_store, run), monkeypatch)
    three = write_store(tmp_path / "three.zarr", {k: v for k, v in FOUR_MESHES.items() if k != "grid"})

    def resume(store, *extra):
        return CliRunner().invoke(main, ["train", store, "--run", str(run), "--resume", "--device", "cpu", *extra])

    result = resume(three)
    assert result.exit_code == 1 and result.output == (
        f"Error: --resume: STORE {three} is not the store this run trained on ({tiny_store}): 1 missing\n")
    result = resume(one_mesh_store)  # one mesh of its own, the four missing, 16 sources a mesh instead of 8
    assert result.output == (f"Error: --resume: STORE {one_mesh_store} is not the store this run trained on "
                             f"({tiny_store}): 1 mesh(es) added, 4 missing, other params (pairs)\n")
    result = resume(tiny_store, "--val", tiny_store)
    assert result.output == "Error: --resume: this run validated on a split of its STORE: resume it without --val\n"
    assert load_checkpoint(run / "last.safetensors").metadata["trainer"]["epoch"] == 0  # nothing trained
    (run / "stores.json").unlink()  # the run's record lost: the fingerprint alone still tells
    assert resume(three).output == (f"Error: --resume: STORE {three} is not the store this run trained on "
                                    "(another content fingerprint)\n")


def test_each_rank_fills_its_share_by_mesh_id_reading_only_meshes_with_missing_fields(tiny_store, tmp_path,
                                                                                     monkeypatch):
    """Two ranks, in turn (the collectives stubbed): each reads the geometry of its own meshes (by id hash)
    and only while their fields are missing; the next start reads none. The log says first how many fields,
    bytes and seconds the fill will take."""
    from gegnn.fields.cache import FieldCache
    from gegnn.training.data import GeodesicStore, mesh_hash

    monkeypatch.setattr(gtrain, "barrier", lambda ctx: None)
    monkeypatch.setattr(gtrain, "all_sum", lambda values, ctx, device: values)
    reads, geometry = [], GeodesicStore.geometry
    monkeypatch.setattr(GeodesicStore, "geometry", lambda self, m: reads.append(m) or geometry(self, m))
    spec, path = FieldSpec("landmark", 4), str(tmp_path / "fields")
    ds = BatchDataset(tiny_store, "geodesic", 0, 200, False, 5, 1 / 16, 3 / 16, spec, path)
    ids, lines = ds.store.mesh_ids, []
    log = logging.getLogger("test.fill")
    monkeypatch.setattr(log, "info", lines.append)
    shares = [[m for m in ids if mesh_hash(m) % 2 == rank] for rank in (0, 1)]
    assert all(shares)  # the four meshes fall to both ranks
    for rank, share in enumerate(shares):
        reads.clear()
        gtrain.fill_field_cache(path, spec, [(ds, ids, range(3))], Dist(rank, 2), torch.device("cpu"), log)
        assert sorted(reads) == share
        assert lines[-2].startswith(f"landmark fields: {3 * len(share)} to compute (k4-rounds16), ~")
        assert "with " in lines[-2] and lines[-1].startswith(f"landmark fields: {3 * len(share)} computed in ")
    cache = FieldCache(path, spec)
    assert all(cache.has(ds.store.key(m), seed) for m in ids for seed in range(3))
    reads.clear()
    for rank in (0, 1):  # a resume: every field there, no geometry read, no estimate
        gtrain.fill_field_cache(path, spec, [(ds, ids, range(3))], Dist(rank, 2), torch.device("cpu"), log)
        assert lines[-1].startswith("landmark fields: 0 computed")
    assert reads == []
