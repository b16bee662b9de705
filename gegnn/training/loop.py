"""Training and evaluation loops (one file, nanoGPT style).

Single process: ``gegnn train OUT --run RUN``. Multi-process: ``torchrun --nproc-per-node K -m gegnn.cli
train OUT --run RUN`` (DistributedDataParallel; meshes sharded by rank; NCCL where every rank has a GPU of its
own, gloo on CPUs and where ranks share a GPU).
"""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import math
import time
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.distributed as dist

from geodata.progress import progress_bar

from ..checkpoint import load_checkpoint, save_checkpoint
from ..config import GeGnnConfig
from ..distributed import Dist, all_sum, barrier, setup_distributed
from ..fields.cache import FieldCache, FieldSpec, estimate_fill, readable
from ..fitting import show_loss
from ..metrics import pair_errors, relative_error
from ..model import GeGnn
from .data import VAL_EPOCH, BatchDataset, EpochSampler, GeodesicStore, mesh_hash, split_meshes
from .devices import auto_workers, cpus_per_process, pick_device, set_deterministic
from .estimate import StepClock, log_header
from .presets import checkpoint_file
from .rundir import METRICS, plot_curves, read_metrics, restore_rng, rng_state, run_logger, write_metrics
from .warmup import warm_decoder

__all__ = ["TrainConfig", "train", "evaluate_store", "lr_at", "store_fingerprint", "StoreMismatch"]

# Options a resumed run takes from the command line ("landmark_cache": field_cache's name in older runs; the
# store: moved, or copied to a node's scratch, it is checked by content, store_fingerprint), --val where given.
RESUME_KEEPS = ("store", "epochs", "device", "workers", "field_cache", "landmark_cache")
STORES_FILE = "stores.json"  # in the run: each store's fingerprint, parameters and mesh ids (what a resume checks)
DECODER_KINDS = ("decoder", "landmark", "spectral")  # GeGnnConfig fields that choose the decoder (name prefixes)
WARMUP_LR = 1e-3  # decoder warm-up: a small MLP on fixed codes (the network's --lr is usually lower)
VAL_WORKERS = 2  # loader processes of validation, at most (each holds its meshes while training runs)
PROGRESS_EVERY = 25  # steps between progress-bar updates (each reads a loss from the device)


@dataclass(frozen=True)
class TrainConfig:
    store: str
    run: str
    epochs: int = 100
    batch_size: int = 1              # meshes per step per process
    lr: float = 1e-3
    weight_decay: float = 0.01
    warmup_epochs: float = 0.0
    clip_grad: float = 0.0           # max gradient norm; 0 = off
    distance: str = "geodesic"
    pairs_per_mesh: int = 100_000
    val_fraction: float = 0.1
    val_store: str | None = None    # validate on every mesh of this store instead of a split of `store`
    rotate: bool = True
    seed: int = 0
    device: str = "auto"
    workers: int | None = None       # loader processes per rank (0: in the training process; None: auto)
    resume: bool = False
    init: str | None = None
    init_sha256: str | None = None   # the --init file's, recorded by the run: a name or a path may later hold others
    decoder_warmup: int = 0          # decoder-only steps on frozen network codes before the first epoch
    field_cache: str | None = None  # cache folder of the landmark fields or spectral codes (None: RUN/fields)
    deterministic: bool = False      # torch's deterministic algorithms: bitwise-exact resume on CUDA too
    model: str | None = None         # the preset (gegnn.training.presets) the options came from, for the log


def lr_at(step: int, total: int, base: float, warmup: int) -> float:
    """Linear warm-up, then polynomial decay with power 0.9 to zero at ``total``."""
    if warmup and step < warmup:
        return base * (step + 1) / warmup
    return base * max(0.0, 1 - step / max(total, 1)) ** 0.9


# -- one step, one epoch ---------------------------------------------------------------------------
def train_step(model, batch, optimizer, lr: float, clip_grad: float, device) -> torch.Tensor:
    """One optimizer step; returns the loss as a device tensor (reading it would wait for the device)."""
    for group in optimizer.param_groups:
        group["lr"] = lr
    # bf16 autocast on a GPU (the network; decoders keep their output layer in fp32), none on a CPU
    with torch.autocast("cuda", dtype=torch.bfloat16, enabled=device.type == "cuda"):
        pred = model(batch.hierarchy, batch.pairs, batch.fields)
    loss = relative_error(pred, batch.distances).mean()
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if clip_grad > 0:
        torch.nn.utils.clip_grad_norm_(model.parameters(), clip_grad)
    optimizer.step()
    return loss.detach()


def train_epoch(model, loader, optimizer, cfg: TrainConfig, step: int, total: int, warmup: int,
                device, ctx: Dist, clock: StepClock | None = None) -> tuple[float, int]:
    model.train()
    losses = []
    bar = progress_bar(loader, desc="train", leave=False, disable=not ctx.main, dynamic_ncols=True)
    for batch in bar:
        losses.append(train_step(model, batch.to(device), optimizer, lr_at(step, total, cfg.lr, warmup),
                                 cfg.clip_grad, device))
        step += 1
        if clock is not None:
            clock.step_done()
        if len(losses) % PROGRESS_EVERY == 1:
            show_loss(bar, losses)
    total_loss = torch.stack(losses).double().sum().item() if losses else 0.0
    total_loss, count = all_sum([total_loss, len(losses)], ctx, device)
    return total_loss / max(count, 1), step


@torch.no_grad()
def validate(model, loader, device, ctx: Dist) -> float:
    """MRE over a fixed sample of pairs (same every epoch, no rotation) of this rank's share, in fp32 (as
    ``gegnn eval``: the choice of ``best.safetensors`` must not depend on bf16 rounding)."""
    model.eval()
    err, count = torch.zeros((), dtype=torch.float64, device=device), 0
    for batch in loader:
        batch = batch.to(device)
        e = relative_error(model(batch.hierarchy, batch.pairs, batch.fields), batch.distances)
        err += e.sum()
        count += e.numel()
    err, count = all_sum([err.item(), count], ctx, device)
    return err / count if count else float("nan")


# -- the run -------------------------------------------------------------------------------------
def train(cfg: TrainConfig, model_config: GeGnnConfig | None = None) -> list[dict]:
    """Train; returns the metrics rows. ``model_config`` is ignored when resuming or with ``init``."""
    run = Path(cfg.run)
    resume = load_checkpoint(run / "last.safetensors") if cfg.resume and (run / "last.safetensors").exists() \
        else None
    if resume is not None:  # continue with the run's own options
        keeps = RESUME_KEEPS + (("val_store",) if cfg.val_store else ())
        saved = {k: v for k, v in resume.metadata["train_config"].items() if k not in keeps}
        cfg = dataclasses.replace(cfg, **saved)
    elif cfg.init:  # the weights it starts from, by their bytes
        init_bytes = Path(checkpoint_file(cfg.init)).read_bytes()
        cfg = dataclasses.replace(cfg, init_sha256=hashlib.sha256(init_bytes).hexdigest())
    previous = torch.are_deterministic_algorithms_enabled()
    set_deterministic(previous or cfg.deterministic)
    device = pick_device(cfg.device)
    ctx = setup_distributed(device)
    try:
        with contextlib.ExitStack() as loaders:  # their worker processes end with the run (close_loader)
            return _train(cfg, model_config, resume, run, device, ctx, loaders)
    finally:
        torch.use_deterministic_algorithms(previous)
        if ctx.owned:
            dist.destroy_process_group()


def _train(cfg: TrainConfig, model_config, resume, run: Path, device, ctx: Dist,
           loaders: contextlib.ExitStack) -> list[dict]:
    if ctx.main:
        run.mkdir(parents=True, exist_ok=True)
    barrier(ctx)
    log = run_logger(run, ctx.main)

    torch.manual_seed(cfg.seed)
    model, optimizer, start_epoch, step, best = build_model(cfg, model_config, resume, device, log)
    store = GeodesicStore(cfg.store, cfg.distance)
    val_store = GeodesicStore(cfg.val_store, cfg.distance) if cfg.val_store else None
    stores = {"store": store_fingerprint(store), "val_store": val_store and store_fingerprint(val_store)}
    if resume is not None:
        check_stores(resume.metadata.get("stores"), stores, run, cfg, log)
    log_header(log, cfg, model, device)  # the first line of a run that starts
    if ctx.main:  # the run's record of them (whole or not at all), to say what differs on a resume
        record = {k: v and {"path": getattr(cfg, k), **v} for k, v in stores.items()}
        (run / ".stores.tmp").write_text(json.dumps(record))
        os.replace(run / ".stores.tmp", run / STORES_FILE)
    if val_store is not None:
        train_ids, val_ids = store.mesh_ids, val_store.mesh_ids
    else:
        train_ids, val_ids = split_meshes(store.mesh_ids, cfg.val_fraction)
    if not train_ids:
        raise ValueError(f"{cfg.store}: no committed meshes with {cfg.distance} distances")
    spec = FieldSpec.of(model.config)
    cache = (cfg.field_cache or str(run / "fields")) if spec else None
    dataset, val_dataset = (BatchDataset(path, cfg.distance, cfg.seed, cfg.pairs_per_mesh, cfg.rotate,
                                         model.config.levels, model.config.sigma_c, model.config.sigma_n,
                                         spec, cache, model.config.points)
                            for path in (cfg.store, cfg.val_store or cfg.store))
    if cache:
        fill_field_cache(cache, spec, [(dataset, train_ids, range(spec.draws)), (val_dataset, val_ids, [0])],
                         ctx, device, log)
    workers = auto_workers(device) if cfg.workers is None else cfg.workers
    # Validation runs once an epoch, on one mesh a batch: a few workers, kept between epochs, suffice.
    val_loader = make_loader(val_dataset, single_mesh_keys(val_ids, ctx), min(workers, VAL_WORKERS), device)
    loaders.callback(close_loader, val_loader)
    if cfg.decoder_warmup and start_epoch == 0:
        # A rank beyond the number of meshes borrows one: every rank must take part in the all-reduces.
        keys = single_mesh_keys(train_ids, ctx) or [(VAL_EPOCH, (train_ids[ctx.rank % len(train_ids)],))]
        warm_decoder(model, make_loader(dataset, keys, workers, device, persistent=False), cfg.decoder_warmup,
                     WARMUP_LR, device, log, ctx)
        log.info(f"after the decoder warm-up: val_mre {validate(model, val_loader, device, ctx):.4f}")
    # A decoder that reads no embeddings leaves the network without gradients: DDP must expect that.
    net = torch.nn.parallel.DistributedDataParallel(
        model, find_unused_parameters=not model.config.reads_embeddings) if ctx.world > 1 else model
    sampler = EpochSampler(train_ids, cfg.seed, cfg.batch_size, ctx.rank, ctx.world)
    loader = make_loader(dataset, sampler, workers, device)
    loaders.callback(close_loader, loader)
    steps_per_epoch = len(sampler)
    total, warmup = cfg.epochs * steps_per_epoch, round(cfg.warmup_epochs * steps_per_epoch)
    log.info(f"{len(train_ids)} train / {len(val_ids)} val meshes, {ctx.world} process(es) on {device}, "
             f"{workers} loader worker(s) each, {steps_per_epoch} steps per epoch, "
             f"{sum(p.numel() for p in model.parameters()):,} parameters")

    rows = read_metrics(run, start_epoch) if ctx.main else []
    last_plot = -math.inf
    clock = StepClock(log, cfg, model.config, device, steps_per_epoch, cfg.epochs - start_epoch)
    for epoch in range(start_epoch, cfg.epochs):
        t0 = time.perf_counter()
        sampler.set_epoch(epoch)
        if epoch == start_epoch:
            clock.start()
        train_mre, step = train_epoch(net, loader, optimizer, cfg, step, total, warmup, device, ctx, clock)
        val_mre = validate(model, val_loader, device, ctx)
        row = dict(epoch=str(epoch), step=str(step), lr=f"{lr_at(step - 1, total, cfg.lr, warmup):.3e}",
                   train_mre=f"{train_mre:.6f}", val_mre=f"{val_mre:.6f}",
                   seconds=f"{time.perf_counter() - t0:.2f}")
        log.info(f"epoch {epoch} step {step} lr {float(row['lr']):.2e} train_mre {train_mre:.4f} "
                 f"val_mre {val_mre:.4f} {float(row['seconds']):.1f}s")
        clock.epoch_done(float(row["seconds"]))  # the first epoch's only
        score = val_mre if math.isfinite(val_mre) else train_mre
        improved = score < best
        best = min(best, score)
        if ctx.main:
            rows.append(row)
            # Plotting costs ~0.5 s: at most every 30 s, and always after the last epoch.
            plot = epoch == cfg.epochs - 1 or time.perf_counter() - last_plot > 30
            last_plot = time.perf_counter() if plot else last_plot
            save_run(run, model, optimizer, cfg, epoch, step, best, rows, improved, plot,
                     {k: v and v["sha256"] for k, v in stores.items()})
    return rows


def build_model(cfg: TrainConfig, model_config, resume, device, log=None):
    """Model and optimizer, fresh, from ``--init`` weights, or restored from ``--resume``.

    With ``--init`` the network is the checkpoint's; where ``model_config`` asks for a decoder of its own
    (landmarks, spectral modes or the Euclidean decoder), its decoder options replace the checkpoint's,
    so a paper model's weights can start a landmark-guided or a biharmonic one (the new decoder starts
    fresh). A landmark decoder is kept for another K (its features are means and extremes over the
    landmarks, its weights the same for any K) and for fields of another solver (``landmark_fields``)."""
    if resume is not None:
        model_config = resume.config
    elif cfg.init:
        init = load_checkpoint(checkpoint_file(cfg.init))
        own_decoder = model_config is not None and (model_config.landmarks or model_config.spectral
                                                    or model_config.decoder != "mlp")
        # The kind of decoder from the command line; its width, like the network, from the checkpoint.
        guide = {f.name: getattr(model_config, f.name) for f in dataclasses.fields(GeGnnConfig)
                 if f.name.startswith(DECODER_KINDS) and f.name not in ("decoder_hidden", "decoder_blocks")
                 } if own_decoder else {}
        # The input, meshes or point clouds, from the command line too: a mesh model can start a cloud one.
        model_config = dataclasses.replace(init.config, **guide,
                                           points=model_config.points if model_config else init.config.points)
    if resume is None:  # the model says what it predicts
        model_config = dataclasses.replace(model_config or GeGnnConfig(), distance=cfg.distance)
    model = GeGnn(model_config)
    if cfg.init and resume is None:
        state = init.model_state
        # The same decoder reads other inputs: another distance, points instead of meshes, or (its
        # weights do not depend on K) another number of landmarks, or fields of another solver.
        same_input = dict(distance=init.config.distance, points=init.config.points)
        if model_config.landmarks and init.config.landmarks:
            same_input.update(landmarks=init.config.landmarks, landmark_fields=init.config.landmark_fields)
        if dataclasses.replace(model_config, **same_input) != init.config:
            # another decoder: none of the old one's weights
            state = {k: v for k, v in state.items() if not k.startswith("distance.")}
        fresh = load_matching(model, state)
        if fresh and log is not None:
            log.info(f"--init {cfg.init}: {len(fresh)} tensors start fresh ({', '.join(sorted(fresh)[:4])}...)")
    model.to(device)
    optimizer = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    if resume is None:
        return model, optimizer, 0, 0, math.inf
    model.load_state_dict(resume.model_state)
    optimizer.load_state_dict(resume.optimizer_state)
    restore_rng(resume.rng)
    state = resume.metadata["trainer"]
    return model, optimizer, state["epoch"] + 1, state["step"], state["best"]


def load_matching(model, state: dict) -> list[str]:
    """Load the tensors of ``state`` whose name and shape match ``model``'s; returns the names left as
    initialized. A checkpoint with the same config loads whole (nothing is left)."""
    own = model.state_dict()
    matching = {k: v for k, v in state.items() if k in own and own[k].shape == v.shape}
    model.load_state_dict(matching, strict=False)
    return [k for k in own if k not in matching]


def save_run(run: Path, model, optimizer, cfg, epoch, step, best, rows, improved, plot: bool,
             stores: dict | None = None) -> None:
    """Metrics, curves and checkpoints; ``stores``: each store's content fingerprint (None: not given)."""
    meta = {"trainer": {"epoch": epoch, "step": step, "best": best},
            "train_config": dataclasses.asdict(cfg), "metrics": rows[-1], "stores": stores or {}}
    if improved:
        save_checkpoint(run / "best.safetensors", model, metadata=meta)
    # last.safetensors is the resume point: written last, after metrics, so a kill between the two
    # writes redoes the epoch instead of skipping it.
    write_metrics(run, rows)
    if plot:
        plot_curves(run, rows)
    save_checkpoint(run / "last.safetensors", model, optimizer, rng_state(), metadata=meta)


class StoreMismatch(ValueError):
    """``--resume`` given a store whose content is not the run's (one line: what differs)."""


def store_fingerprint(store: GeodesicStore) -> dict:
    """A store's content as a run records it: ``sha256`` of its parameters and its sorted committed mesh
    ids (JSON, sorted keys), and those parameters and ids, to say what differs. Its path is no part of it:
    a store moved or copied keeps its fingerprint."""
    content = {"params": store.root.attrs.get("params"), "mesh_ids": sorted(store.mesh_ids)}
    return {"sha256": hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest(), **content}


def check_stores(saved: dict | None, now: dict, run: Path, cfg: TrainConfig, log) -> None:
    """Refuse a resume whose stores are not the run's by content (:class:`StoreMismatch`), saying what
    differs from the run's own record (RUN/stores.json)."""
    if not saved:  # a checkpoint from before fingerprints: nothing to compare with
        log.info("--resume: the checkpoint records no store fingerprint (an older run): the stores are not checked")
        return
    record = json.loads((run / STORES_FILE).read_text()) if (run / STORES_FILE).exists() else {}
    for name, fingerprint in now.items():
        if saved.get(name) == (fingerprint and fingerprint["sha256"]):
            continue
        if saved.get(name) is None:
            raise StoreMismatch("--resume: this run validated on a split of its STORE: resume it without --val")
        where = f"--resume: {'STORE' if name == 'store' else '--val'} {getattr(cfg, name)} is not the store this run"
        old = record.get(name) or {}
        if old.get("sha256") != saved[name]:  # no record of the run's store: its fingerprint alone
            raise StoreMismatch(f"{where} trained on (another content fingerprint)")
        ids, old_ids = set(fingerprint["mesh_ids"]), set(old["mesh_ids"])
        params, old_params = fingerprint["params"] or {}, old["params"] or {}
        changed = sorted(k for k in {**params, **old_params} if params.get(k) != old_params.get(k))
        differs = [f"{len(ids - old_ids)} mesh(es) added"] * bool(ids - old_ids) + [f"{len(old_ids - ids)} missing"] \
            * bool(old_ids - ids) + [f"other params ({', '.join(changed)})"] * bool(changed)
        raise StoreMismatch(f"{where} trained on ({old['path']}): {', '.join(differs) or 'another content'}")


def make_loader(dataset, sampler, workers: int, device, persistent: bool = True):
    """Batches of ``dataset`` for the keys of ``sampler``, built by ``workers`` processes that keep two
    batches each ready; on a GPU pinned, so ``batch.to(device)`` copies asynchronously."""
    # Workers are spawned, not forked: zarr v3 runs an asyncio thread that a fork would copy mid-state.
    extra = dict(multiprocessing_context="spawn", persistent_workers=persistent, prefetch_factor=2) \
        if workers else {}
    return torch.utils.data.DataLoader(dataset, sampler=sampler, batch_size=None, num_workers=workers,
                                       pin_memory=device.type == "cuda", **extra)


def close_loader(loader) -> None:
    """End a loader's persistent worker processes now. Left to the garbage collector they live as long as
    any reference cycle that holds the loader (a caught exception's frames below the loop suffice, as
    matplotlib's imports make), and at exit torch 2.11 then joins each one with a 5 s timeout: a GPU run
    with 10 loader processes took 50 s to exit. torch has no public way; this is what its own exit does."""
    if loader._iterator is not None:
        loader._iterator._shutdown_workers()
        loader._iterator = None


def single_mesh_keys(mesh_ids: list[str], ctx: Dist) -> list[tuple]:
    """This rank's share of ``mesh_ids`` as validation-style keys: one mesh per batch, fixed pairs."""
    return [(VAL_EPOCH, (m,)) for m in mesh_ids[ctx.rank::ctx.world]]


def fill_field_cache(path: str, spec: FieldSpec, work: list[tuple], ctx: Dist, device, log) -> None:
    """Compute the fields that ``path`` lacks, for ``work``: (dataset, mesh ids, seeds) triples, keyed
    as the datasets' loaders look them up, with the CPU cores of this rank's share of the node; the
    fields then serve every loader worker and rank (:mod:`gegnn.fields.cache`).

    Every rank takes the meshes whose id falls to it (``mesh_hash(m) % world``), reads their keys (an
    attribute recorded at prepare time) and the geometry of those with missing fields only: a start or
    resume on a filled cache costs a key and a name lookup per entry of the rank's share, whatever the
    store's size. Two ids of one content on two ranks may both compute it; the first to publish wins.
    Before computing, the log says how many fields, bytes and seconds (:func:`~gegnn.fields.cache.estimate_fill`)."""
    cache = FieldCache(path, spec)
    if ctx.main:
        cache.create()  # once, before the ranks write into it
    barrier(ctx)
    wanted = {}  # key -> (dataset, mesh id, seeds): two ids of one content are one task
    for dataset, mesh_ids, seeds in work:
        for m in mesh_ids:
            if mesh_hash(m) % ctx.world == ctx.rank:
                wanted.setdefault(dataset.store.key(m), (dataset, m, set()))[2].update(seeds)
    todo = []
    for key, (dataset, m, seeds) in wanted.items():
        lacking = sorted(s for s in seeds if not cache.has(key, s))
        if lacking:
            g = dataset.as_input(dataset.store.geometry(m))
            todo += [(key, g.vertices, g.faces, s) for s in lacking]
    t0, jobs = time.perf_counter(), cpus_per_process()
    first = [t for t in todo if t[0] == todo[0][0]] if todo else []
    published = cache.fill(first, progress=False)  # one mesh, timed: the estimate's seconds a draw
    a_draw = (time.perf_counter() - t0) / max(len(first), 1)
    entries, nbytes, seconds = all_sum(list(estimate_fill(todo, spec, a_draw, len(first[0][1]) if first else 1)),
                                       ctx, device)
    if entries:
        log.info(f"{spec.kind} fields: {int(entries)} to compute ({spec.name}), ~{readable(nbytes, 'B')} in {path}, "
                 f"~{readable(seconds / (jobs * ctx.world), 's')} with {jobs} process(es) on each of {ctx.world} "
                 f"rank(s) (one mesh's draws measured: {a_draw:.3f} s each)")
    published += cache.fill(todo[len(first):], jobs=jobs, progress=ctx.main)
    published, computed = all_sum([published, len(todo)], ctx, device)  # a collective: the ranks meet here
    log.info(f"{spec.kind} fields: {int(published)} computed in {time.perf_counter() - t0:.1f} s, cached in {path}"
             + f" ({int(computed - published)} more published first by another rank or run)" * (computed > published))


# -- evaluation (the paper's protocol: all stored pairs) ------------------------------------------------
@torch.no_grad()
def evaluate_store(model: GeGnn, store_path, distance: str = "geodesic", mesh_ids=None, device="cpu",
                   chunk: int = 65536) -> list[dict]:
    """MRE of every committed mesh over all its stored pairs (sources x all vertices)."""
    device = torch.device(device)
    model.to(device).eval()
    dataset = BatchDataset(store_path, distance, 0, None, False, model.config.levels,
                           model.config.sigma_c, model.config.sigma_n, FieldSpec.of(model.config),
                           cloud=model.config.points)
    rows = []
    for mesh_id in progress_bar(mesh_ids or dataset.store.mesh_ids, desc="eval", leave=False):
        batch = dataset[(VAL_EPOCH, (mesh_id,))].to(device)
        e = model(batch.hierarchy, fields=batch.fields)
        err = pair_errors(model.distance, e, batch.pairs, batch.distances, chunk)
        rows.append(dict(mesh_id=mesh_id, vertices=e.shape[0], pairs=err.numel(), mre=err.mean().item(),
                         sum=err.sum().item()))
    return rows
