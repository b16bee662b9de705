"""The GPU path, guarded on a CPU: what would stop, slow or skew training and queries on CUDA, checked with
the meta device (where any host sync or data-dependent size fails), CPU autocast and simulated devices.
The tests marked ``cuda`` run the same paths on a real GPU (``scripts/gpu_check.sh``)."""
import numpy as np
import pytest
import torch
from gegnn_stores import ellipsoid, small_config

import gegnn.distributed as gdistributed
import gegnn.training.devices as gdevices
import gegnn.training.loop as gtrain
from gegnn import Embedding, GeGnn
from gegnn.decoders import DistanceDecoder, LandmarkDecoder
from gegnn.fields.cache import LANDMARK_DRAWS, FieldCache, FieldSpec
from geodata.store import geometry_key
from gegnn.fields.landmarks import landmark_fields
from gegnn.metrics import relative_error
from gegnn.nn import aggregate, scatter_count
from gegnn.training.data import Batch, BatchDataset

cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


# -- no host syncs: the whole training step runs on the meta device ------------------------------------
@pytest.mark.parametrize("options", [{}, {"aggr": "mean"}, {"landmarks": 4}])
def test_training_step_has_no_data_dependent_op(tiny_store, options):
    """bincount, nonzero, boolean masks and .item() cannot run on meta tensors: a forward and backward pass
    there proves the step queues its kernels without waiting on the device."""
    torch.manual_seed(0)
    model = GeGnn(small_config(**options))
    batch = BatchDataset(tiny_store, "geodesic", 0, 300, True, 5, 1 / 16, 3 / 16,
                         FieldSpec.of(model.config))[(0, ("grid", "sphere"))]
    model.to("meta")
    batch = batch.to("meta")
    loss = relative_error(model(batch.hierarchy, batch.pairs, batch.fields), batch.distances).mean()
    loss.backward()
    assert loss.device.type == "meta" and all(p.grad is not None for p in model.parameters())


def test_embed_moves_the_model_to_the_device_asked_for():
    """GeGnn.embed(..., device=d) on a model that lives elsewhere (as from pretrained()) runs there."""
    model = GeGnn.pretrained()
    v, f = ellipsoid()
    emb = model.embed(v, f, device="meta")
    assert emb.features.device.type == "meta" and next(model.parameters()).device.type == "meta"


def test_a_model_moved_by_embed_can_still_train():
    """embed(device=...) moves the model outside inference mode: its parameters stay ordinary tensors, so a
    training step (finetune, a trainer) can save them for backward afterwards."""
    model = GeGnn(small_config())
    v, f = ellipsoid()
    model.embed(v, f, device="meta")
    assert not any(p.is_inference() for p in model.parameters())
    out = model.distance(torch.ones(4, 16, device="meta", requires_grad=True), torch.ones(4, 16, device="meta"))
    out.sum().backward()
    assert all(p.grad is not None for p in model.distance.parameters())


@pytest.mark.parametrize("load", [lambda: GeGnn.pretrained(map_location="meta"),
                                  lambda: GeGnn.pretrained("paper", map_location="meta")])
def test_checkpoints_load_onto_the_device_asked_for(load):
    model = load()
    assert {p.device.type for p in model.parameters()} == {"meta"}


def test_ranks_sharing_a_gpu_use_gloo_and_one_gpu_each(monkeypatch):
    """NCCL refuses two ranks on one GPU: where a node's ranks outnumber its GPUs the group is gloo and
    LOCAL_RANK wraps around the GPUs; with a GPU per rank, NCCL and the rank's own GPU."""
    monkeypatch.setattr(torch.cuda, "set_device", lambda device: None)
    cuda = torch.device("cuda")
    for local_world, gpus, backend in [("2", 1, "gloo"), ("2", 2, "nccl"), ("8", 4, "gloo"), ("1", 1, "nccl")]:
        monkeypatch.setenv("LOCAL_WORLD_SIZE", local_world)
        assert gdistributed.dist_backend(cuda, gpus) == backend
    assert gdistributed.dist_backend(torch.device("cpu"), 4) == "gloo"
    monkeypatch.setenv("LOCAL_RANK", "3")
    assert gdevices.pick_device("cuda", gpus=2) == torch.device("cuda", 1)
    assert gdevices.pick_device("cuda", gpus=4) == torch.device("cuda", 3)
    assert gdevices.pick_device("cuda:0", gpus=4) == torch.device("cuda", 0)  # an explicit index is kept


def test_deterministic_mode_sets_the_cublas_workspace_wherever_it_is_turned_on(monkeypatch):
    """The Python API (train(), benchmarks) and the CLI share one switch: cuBLAS needs a fixed workspace
    for deterministic results, and torch refuses deterministic CUDA matmuls without it."""
    monkeypatch.delenv("CUBLAS_WORKSPACE_CONFIG", raising=False)
    previous = torch.are_deterministic_algorithms_enabled()
    try:
        gdevices.set_deterministic(True)
        assert torch.are_deterministic_algorithms_enabled()
        assert __import__("os").environ["CUBLAS_WORKSPACE_CONFIG"] == ":4096:8"
    finally:
        torch.use_deterministic_algorithms(previous)


def test_chunks_are_sized_by_the_device_the_codes_are_on():
    """On a CPU, chunks that keep intermediates in cache (the torch path's features), or few calls of the
    compiled decode, which keeps its own in cache; elsewhere (here the meta device stands for a GPU) large ones, for pairs and for
    surface points alike: few launches."""
    import gegnn.queries.embedding as gemb

    decoder, unfused = LandmarkDecoder(16, 4, 32), LandmarkDecoder(16, 4, 48)
    cpu = gemb.Embedding(torch.zeros(10, 16 + 4 + 4), decoder)
    torch_path = gemb.Embedding(torch.zeros(10, 16 + 4 + 4), unfused)
    gpu = gemb.Embedding(torch.zeros(10, 16 + 4 + 4, device="meta"), decoder)
    assert cpu._fused and not torch_path._fused and not gpu._fused
    assert cpu.chunk == gemb.FUSED_CHUNK
    assert torch_path.chunk == max(1024, gemb.CHUNK_VALUES // unfused.pair_width(torch_path.features))
    assert gpu.chunk == gemb.ACCELERATOR_CHUNK_VALUES // decoder.pair_width(gpu.features)
    assert cpu.surface_chunk == gemb.SURFACE_CHUNK and gpu.surface_chunk == gemb.ACCELERATOR_SURFACE_CHUNK
    assert gpu.chunk > 50 * torch_path.chunk and gpu.surface_chunk >= 16 * cpu.surface_chunk


def test_indices_are_copied_asynchronously_only_towards_an_accelerator(monkeypatch):
    """A device-to-host copy with non_blocking=True may still be in flight when the host reads it."""
    seen = []
    to = torch.Tensor.to

    def recording_to(self, *args, **kwargs):
        seen.append(kwargs.get("non_blocking", False))
        return to(self, *args, **{k: v for k, v in kwargs.items() if k != "non_blocking"})
    monkeypatch.setattr(torch.Tensor, "to", recording_to)
    decoder = DistanceDecoder(4, 8)
    for device, asynchronous in (("cpu", False), ("meta", True)):
        emb = Embedding(torch.zeros(5, 4, device=device), decoder)
        seen.clear()
        emb._indices(torch.tensor([0, 1]))
        assert seen == [asynchronous]


def test_a_dataset_keeps_a_bounded_number_of_meshes(tiny_store, monkeypatch):
    """Every loader worker keeps meshes it has read: the last GEOMETRY_CACHE, not every mesh of the store."""
    import gegnn.training.data as gdata

    monkeypatch.setattr(gdata, "GEOMETRY_CACHE", 2)
    ds = BatchDataset(tiny_store, "geodesic", 0, 100, False, 5, 1 / 16, 3 / 16)
    ids = ds.store.mesh_ids
    for m in ids + ids[:1]:
        ds.geometry(m)
    assert list(ds._geometries) == [ids[-1], ids[0]]  # the most recent two
    np.testing.assert_array_equal(ds.geometry(ids[0]).vertices, ds.store.geometry(ids[0]).vertices)


def test_auto_workers_by_device_and_cores(monkeypatch):
    """--workers auto: none on a CPU (the cores are the network's); on a GPU one per spare core of the
    rank, at least one, at most MAX_AUTO_WORKERS."""
    for cores, on_gpu in [(1, 1), (2, 1), (6, 5), (16, gdevices.MAX_AUTO_WORKERS), (64, gdevices.MAX_AUTO_WORKERS)]:
        monkeypatch.setattr(gdevices, "cpus_per_process", lambda: cores)
        assert gdevices.auto_workers(torch.device("cpu")) == 0
        assert gdevices.auto_workers(torch.device("cuda")) == on_gpu
    monkeypatch.undo()
    monkeypatch.setenv("LOCAL_WORLD_SIZE", "4")
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(32)))
    assert gdevices.cpus_per_process() == 8  # a node's cores shared by its ranks


def test_validation_keeps_few_loader_workers(tiny_store, tmp_path, monkeypatch):
    """Validation's loader workers persist all run long beside training's: at most VAL_WORKERS of them."""
    made = []
    make_loader = gtrain.make_loader

    def recording(dataset, sampler, workers, device, persistent=True):
        made.append(workers)
        return make_loader(dataset, sampler, 0, device, persistent)  # build in-process: the count is the point
    monkeypatch.setattr(gtrain, "make_loader", recording)
    gtrain.train(gtrain.TrainConfig(store=tiny_store, run=str(tmp_path / "run"), epochs=1, batch_size=2,
                                    pairs_per_mesh=100, workers=6), small_config())
    assert made == [gtrain.VAL_WORKERS, 6]  # validation, then training

def test_loader_processes_end_with_the_run_whatever_holds_its_frames(tiny_store, tmp_path, monkeypatch):
    """A run's persistent loader processes end when ``train`` returns, not when the garbage collector
    frees the loaders: a kept exception (a library's cache of one suffices) holds the training frame,
    and at exit torch 2.11 then waits 5 s for each process (the H100's 50 s exit)."""
    import multiprocessing

    kept = []

    def plot_keeping_an_exception(run, rows):
        try:
            raise RuntimeError("kept")
        except RuntimeError as e:
            kept.append(e)  # its traceback holds this frame and the loop's frames below it
    monkeypatch.setattr(gtrain, "plot_curves", plot_keeping_an_exception)
    gtrain.train(gtrain.TrainConfig(store=tiny_store, run=str(tmp_path / "run"), epochs=1, batch_size=2,
                                    pairs_per_mesh=100, workers=1), small_config())
    assert kept and multiprocessing.active_children() == []


# -- ScatterMax: ties share the gradient ---------------------------------------------------------------
def _max_gradient(msg, index, grad_out, reference=False):
    msg = msg.detach().requires_grad_()
    if reference:  # torch's own backward
        out = torch.zeros(len(grad_out), msg.shape[1], dtype=msg.dtype).scatter_reduce(
            0, index.unsqueeze(1).expand_as(msg), msg, "amax", include_self=False)
    else:
        out = aggregate(msg, index, len(grad_out), "max")
    (out * grad_out).sum().backward()
    return msg.grad


@pytest.mark.parametrize("dtype", [torch.float64, torch.bfloat16])
def test_scatter_max_splits_the_gradient_among_ties(dtype):
    """Messages with many exact ties (small integers, as bf16 rounding makes them): each vertex's output
    gradient is split evenly among its tied maxima, so per vertex and channel the message gradients sum to
    it (none is inflated k-fold), and they equal torch's own scatter_reduce backward."""
    gen = torch.Generator().manual_seed(0)
    index = torch.randint(0, 40, (300,), generator=gen)
    grad_out = torch.randn(41, 5, generator=gen).to(dtype)  # vertex 40 receives nothing
    msg = torch.randint(-1, 2, (300, 5), generator=gen).to(dtype)
    grad = _max_gradient(msg, index, grad_out)
    received = scatter_count(index, 41) > 0
    per_vertex = torch.zeros(41, 5, dtype=torch.float64).index_add_(0, index, grad.double())
    torch.testing.assert_close(per_vertex[received], grad_out.double()[received], rtol=1e-2, atol=1e-2)
    assert (per_vertex[~received] == 0).all()
    # torch's backward counts the excluded initial value as one more tie where the maximum is exactly 0
    # (torch 2.13), so it is the reference only for positive messages.
    positive = msg + 2
    torch.testing.assert_close(_max_gradient(positive, index, grad_out),
                               _max_gradient(positive, index, grad_out, reference=True))


# -- pinned batches --------------------------------------------------------------------------------------
def test_loader_pins_every_tensor_of_a_batch(tiny_store, monkeypatch):
    """The DataLoader's pinning calls Batch.pin_memory: every tensor of the batch, hierarchy included, is
    pinned (simulated: pinning needs an accelerator), none is left pageable."""
    from torch.utils.data._utils.pin_memory import pin_memory

    spec = FieldSpec("landmark", 4)
    batch = BatchDataset(tiny_store, "geodesic", 0, 300, True, 5, 1 / 16, 3 / 16, spec)[(0, ("grid", "sphere"))]
    pinned_ids = set()

    def fake_pin(t, *args, **kwargs):
        out = t.clone()
        pinned_ids.add(id(out))
        return out

    monkeypatch.setattr(torch.Tensor, "pin_memory", fake_pin)
    pinned = pin_memory(batch)
    assert isinstance(pinned, Batch)
    tensors = []
    pinned.apply(lambda t: tensors.append(t) or t)
    assert len(tensors) == 4 * 6 + 5 + 3 and all(id(t) in pinned_ids for t in tensors)
    original = []
    batch.apply(lambda t: original.append(t) or t)
    assert all(torch.equal(a, b) for a, b in zip(original, tensors))


# -- decoders: output layer in fp32 under autocast ----------------------------------------------------------
@pytest.mark.parametrize("decoder", [DistanceDecoder(16, 32), LandmarkDecoder(16, 4, 32)])
def test_decoder_output_is_fp32_under_bf16_autocast(decoder):
    """A bf16 output layer would round every distance to 2^-8 relative, a floor on a 1% model's error."""
    torch.manual_seed(0)
    if isinstance(decoder, LandmarkDecoder):
        torch.nn.init.normal_(decoder.mlp[-1].weight, std=0.1)
        a, b = (LandmarkDecoder.codes(torch.randn(64, 16), torch.rand(64, 4), torch.randn(64, 3)) for _ in range(2))
    else:
        a, b = torch.randn(64, 16), torch.randn(64, 16)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        mixed = decoder(a, b)
        *hidden, last = decoder.mlp
        x = decoder.inputs(a, b)[0]
        for layer in hidden:
            x = layer(x)
    assert mixed.dtype == torch.float32 and x.dtype == torch.bfloat16  # hidden layers stay in bf16
    expected = decoder.output(last(x.float()), decoder.inputs(a, b)[1])
    torch.testing.assert_close(mixed, expected)
    assert (mixed != mixed.bfloat16().float()).any()


# -- Embedding.distance takes tensors ------------------------------------------------------------------
def test_distance_takes_tensors_and_answers_in_kind():
    model = GeGnn.pretrained()
    v, f = ellipsoid()
    emb = model.embed(v, f)
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(v), (2, 500))
    i[:7] = j[:7]
    expected = emb.distance(i, j)
    got = emb.distance(torch.as_tensor(i), torch.as_tensor(j, dtype=torch.int32))
    assert isinstance(expected, np.ndarray) and torch.is_tensor(got) and got.dtype == torch.float32
    np.testing.assert_array_equal(got.numpy(), expected)
    assert (got[:7] == 0).all()
    col = emb.distance(torch.as_tensor(i[:5]).reshape(5, 1), torch.as_tensor(j[:3]))  # broadcast
    np.testing.assert_array_equal(col.numpy(), emb.distance(i[:5, None], j[:3]))
    with pytest.raises(IndexError, match="out of range"):
        emb.distance(torch.tensor([0]), torch.tensor([len(v)]))


# -- RNG states on resume ------------------------------------------------------------------------------
def test_resume_restores_this_devices_cuda_rng_whatever_the_device_count(monkeypatch):
    """Checkpoints keep this process's CUDA generator; legacy ones kept every device's (cuda0..cudaN): a
    resume on fewer GPUs, or as rank 11 of 12, takes its own device's state and never indexes past them."""
    restored = []
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "set_rng_state", lambda s: restored.append(int(s[0])))
    cpu = torch.get_rng_state()
    legacy = {"torch": cpu, **{f"cuda{k}": torch.tensor([k], dtype=torch.uint8) for k in range(12)}}
    for device in (0, 2, 11):
        monkeypatch.setattr(torch.cuda, "current_device", lambda d=device: d)
        gtrain.restore_rng(legacy)
    gtrain.restore_rng({"torch": cpu, "cuda": torch.tensor([7], dtype=torch.uint8)})
    gtrain.restore_rng({"torch": cpu})  # saved by a CPU run
    assert restored == [0, 2, 11, 7]


# -- landmark fields: computed once, shared -----------------------------------------------------------
def test_training_fills_the_landmark_cache_and_workers_only_read_it(tiny_store, tmp_path, monkeypatch):
    cfg = gtrain.TrainConfig(store=tiny_store, run=str(tmp_path / "run"), epochs=1, batch_size=2,
                             pairs_per_mesh=200, workers=0)
    gtrain.train(cfg, small_config(landmarks=4))
    cache = FieldCache(tmp_path / "run" / "fields", FieldSpec("landmark", 4))
    ds = BatchDataset(tiny_store, "geodesic", 0, 200, True, 5, 1 / 16, 3 / 16, cache.spec, str(cache.path))
    train_ids, val_ids = gtrain.split_meshes(ds.store.mesh_ids, cfg.val_fraction)
    # every training mesh's every draw is its own: the landmark fields of that mesh with that seed
    drawn = {}
    for mesh_id in train_ids:
        g = ds.store.geometry(mesh_id)
        draws = [cache.get(geometry_key(g.vertices, g.faces), seed) for seed in range(LANDMARK_DRAWS)]
        for seed, fields in enumerate(draws):
            expected = landmark_fields(g.vertices, g.faces, 4, seed).distances  # stored as float16
            np.testing.assert_array_equal(fields, expected.astype(np.float16).astype(np.float32))
        assert all(not np.array_equal(a, b) for k, a in enumerate(draws) for b in draws[k + 1:])
        drawn[mesh_id] = draws

    def no_compute(*args, **kwargs):
        raise AssertionError("a landmark field was computed, not read from the cache")

    monkeypatch.setattr("gegnn.fields.cache.landmark_solver", no_compute)
    for epoch in (-1, 0, 1, 2):
        for mesh_id in train_ids + [(-1, m) for m in val_ids]:
            if isinstance(mesh_id, tuple):  # validation meshes: seed 0 only
                epoch, mesh_id = mesh_id
            fields = ds.sample(epoch, mesh_id).fields
            assert fields.shape[1] == 4
            if epoch >= 0:  # a training sample reads one of its mesh's draws
                assert any(np.array_equal(fields, d) for d in drawn[mesh_id])
    log = (tmp_path / "run" / "train.log").read_text()
    assert f"landmark fields: {4 * len(train_ids) + len(val_ids)} computed" in log  # 4 draws; val: seed 0
    cache_again = gtrain.TrainConfig(**{**cfg.__dict__, "run": str(tmp_path / "run2"),
                                        "field_cache": str(cache.path)})
    gtrain.train(cache_again, small_config(landmarks=4))
    assert "landmark fields: 0 computed" in (tmp_path / "run2" / "train.log").read_text()


# -- on a real GPU (scripts/gpu_check.sh) --------------------------------------------------------------
@cuda
def test_cuda_training_step_never_syncs(tiny_store):
    torch.manual_seed(0)
    model = GeGnn(small_config(landmarks=4)).cuda()
    opt = torch.optim.AdamW(model.parameters())
    ds = BatchDataset(tiny_store, "geodesic", 0, 300, True, 5, 1 / 16, 3 / 16, FieldSpec("landmark", 4))
    batches = [ds[(e, ("grid", "sphere"))].pin_memory() for e in range(3)]
    gtrain.train_step(model, batches[0].to("cuda"), opt, 1e-3, 1.0, torch.device("cuda"))  # warm caches
    torch.cuda.set_sync_debug_mode("error")
    try:
        for b in batches[1:]:
            gtrain.train_step(model, b.to("cuda"), opt, 1e-3, 1.0, torch.device("cuda"))
    finally:
        torch.cuda.set_sync_debug_mode("default")


@cuda
def test_cuda_embedding_equals_cpu():
    """Both fp32, pinned (a bf16 decoder on either side would differ by ~0.3%, not by rounding)."""
    model = GeGnn.pretrained()
    v, f = ellipsoid()
    cpu = model.embed(v, f, device="cpu", precision="fp32")
    gpu = model.embed(v, f, device="cuda", precision="fp32")
    assert cpu.dtype == gpu.dtype == torch.float32
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(v), (2, 100_000))
    d_gpu = gpu.distance(torch.as_tensor(i, device="cuda"), torch.as_tensor(j, device="cuda"))
    assert d_gpu.device.type == "cuda"
    np.testing.assert_allclose(d_gpu.cpu().numpy(), cpu.distance(i, j), rtol=1e-3, atol=1e-5)
