"""``gegnn train``, ``gegnn eval``, ``gegnn finetune`` and ``gegnn export``: training a model, measuring it on a
store, adapting it to one mesh and shipping it."""
from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import click

from ..config import LANDMARK_FIELDS, GeGnnConfig
from ..model import PRETRAINED
from ..training.presets import PRESETS, preset
from .inputs import _click_errors, _load_mesh, _load_model, _model_and_meshes, _output_suffix
from .options import DEVICE_OPTION, MODEL_ARG, PRETRAINED_HELP, either, old_name


def _workers(ctx, param, value):
    if value == "auto":
        return None
    try:
        workers = int(value)
    except ValueError:
        workers = -1
    if workers < 0:
        raise click.BadParameter("a number of processes (0 or more), or auto")
    return workers


def _init(ctx, param, value):
    """--init: a checkpoint file, a shipped model's name, or none (from scratch, without --model)."""
    if value is None or value == "none" or value in PRETRAINED or Path(value).is_file():
        return None if value == "none" else value
    raise click.BadParameter(f"{value}: no such file, and no shipped model of that name ({', '.join(PRETRAINED)})")


# The model options of `gegnn train` and the GeGnnConfig fields each sets (an explicit one overrides a preset).
MODEL_OPTIONS = {"channels": ("channels", "embed_dim", "decoder_hidden"), "blocks": ("encoder_blocks", "decoder_blocks"),
                 "aggr": ("aggr",), "no_edge_length": ("edge_length",), "no_relative_position": ("relative_position",),
                 "plain_grid_pool": ("sigma_n",), "euclidean_decoder": ("decoder",), "landmarks": ("landmarks",),
                 "landmark_fields": ("landmark_fields",), "landmark_no_embedding": ("landmark_embedding",),
                 "landmark_no_euclidean": ("landmark_euclidean",), "landmark_output": ("landmark_output",),
                 "spectral": ("spectral",),
                 "spectral_no_embedding": ("spectral_embedding",), "neighbors": ("points",), "old_points": ("points",)}


def _given(ctx) -> set[str]:
    """The parameters the user gave (command line or environment), not left at their defaults."""
    from click.core import ParameterSource

    return {name for name in ctx.params
            if ctx.get_parameter_source(name) in (ParameterSource.COMMANDLINE, ParameterSource.ENVIRONMENT)}


def _blocks(ctx, param, value):
    if value is None:
        return None
    try:
        return tuple(int(b) for b in value.split(","))
    except ValueError:
        raise click.BadParameter("comma-separated integers, e.g. 2,3,3,3,2")


@click.command()
@click.argument("store", type=click.Path(exists=True, file_okay=False))
@click.option("--run", "--run-dir", "run_dir", required=True, type=click.Path(file_okay=False),
              help="Run directory (--run-dir is the same: torchrun mistakes a bare --run for its --run-path).")
@click.option("--epochs", default=100, show_default=True)
@click.option("--batch-size", default=1, show_default=True, help="Meshes per step (per process).")
@click.option("--lr", default=1e-3, show_default=True, help="Peak learning rate (AdamW).")
@click.option("--weight-decay", default=0.01, show_default=True)
@click.option("--warmup-epochs", default=0.0, show_default=True, help="Linear warm-up length.")
@click.option("--clip-grad", default=0.0, show_default=True, help="Max gradient norm (0: off).")
@click.option("--distance", type=click.Choice(["geodesic", "biharmonic"]), default="geodesic", show_default=True)
@click.option("--pairs-per-mesh", default=100_000, show_default=True, help="Sampled pairs per mesh and step.")
@click.option("--val-fraction", default=0.1, show_default=True,
              help="Meshes of STORE held out for validation (a fixed split by id hash).")
@click.option("--val", "val_store", type=click.Path(exists=True, file_okay=False),
              help="Validate on every mesh of this store instead (train on all of STORE).")
@click.option("--no-rotate", is_flag=True, help="Disable random-rotation augmentation.")
@click.option("--seed", default=0, show_default=True)
@DEVICE_OPTION
@click.option("--workers", callback=_workers, default="auto", show_default=True, metavar="N|auto",
              help="Loader processes per process building batches (0: in the training process). auto: on a "
                   "GPU one per spare CPU core, at most 8 (an H100 needs 2-3 at batch 4: docs/gpu.md); "
                   "on a CPU 0.")
@click.option("--resume", is_flag=True,
              help="Continue RUN/last.safetensors (its own options; STORE, and --val where given, from the command "
                   "line: a moved or copied store is taken, another dataset refused by content): bitwise-exact on a "
                   "CPU, on a GPU with --deterministic.")
@click.option("--deterministic", is_flag=True,
              help="torch's deterministic algorithms: identical runs and resumes on a GPU too, where atomic "
                   "scatter-adds otherwise sum in a varying order (slower; CPU runs are deterministic anyway).")
@click.option("--field-cache", type=click.Path(file_okay=False),
              help="Cache folder of the landmark fields or spectral codes, filled before the first step and read "
                   "by every loader worker and rank (default RUN/fields; keyed by mesh content, so runs, even "
                   "concurrent ones, may share one). ~1.3 MB per mesh and draw at K = 128, 5k vertices (float16).")
@click.option("--model", "preset_name", type=click.Choice(PRESETS),
              help="Train the architecture, fields and schedule of the shipped model of this name (its config and "
                   "recorded training options; docs/model-card.md), fine-tuned from its weights unless --init says "
                   "otherwise. Options given explicitly override the preset's.")
@click.option("--init", "init_ckpt", callback=_init, metavar="CKPT|NAME|none",
              help="Start from these weights: a checkpoint file, or a shipped model's name "
                   f"({', '.join(PRETRAINED)}). With --model the default is that model's own weights; none: "
                   "from scratch (without --model: a preset's recipe has several runs, and the error names them).")
@click.option("--channels", default=256, show_default=True)
@click.option("--blocks", callback=_blocks, help="ResBlocks per level, encoder = decoder [2,3,3,3,2].")
@click.option("--aggr", type=click.Choice(["max", "mean", "sum"]), default="max", show_default=True)
@click.option("--no-edge-length", is_flag=True, help="Ablation: drop |v_i - v_j| from GeoConv.")
@click.option("--no-relative-position", is_flag=True, help="Ablation: drop v_i - v_j from GeoConv.")
@click.option("--plain-grid-pool", is_flag=True, help="Ablation: pool on xyz only (sigma_n = inf).")
@click.option("--euclidean-decoder", is_flag=True, help="Ablation: distance = ||e_i - e_j||.")
@click.option("--landmarks", default=0, show_default=True,
              help="Landmark-guided model: K farthest-point landmark distance fields per mesh (heat method) "
                   "bound the decoder (0: the paper's model). With --init from a paper model, its network "
                   "is kept and the landmark decoder starts fresh; from a landmark model with another K, "
                   "its decoder is kept too (its weights do not depend on K).")
@click.option("--landmark-fields", type=click.Choice(LANDMARK_FIELDS), default="heat", show_default=True,
              help="The landmark fields' solver: the heat method (~1.9% from exact; the shipped landmark models "
                   "up to v2), virtual source propagation (vsp: 0.1-0.3% from exact, ~2 ms a field at 5k "
                   "vertices; a point-cloud model's on its points' local triangles), the exact solver (exact, "
                   "meshes only: 4-15x a vsp field's time) or real paths within 0.05% of exact (paths, meshes "
                   "only: 3-5x a vsp field's time). A model reads the fields it was trained with.")
@click.option("--landmark-no-embedding", is_flag=True, help="Ablation: the decoder reads landmarks only.")
@click.option("--landmark-no-euclidean", is_flag=True, help="Ablation: drop the straight-line distance input.")
@click.option("--spectral", default=0, show_default=True, metavar="M",
              help="Biharmonic model (with --distance biharmonic): M truncated spectral modes per mesh and their "
                   "Weyl-law tail, corrected by the decoder from the embeddings (0: none). With --init, the "
                   "network is kept and the decoder starts as the Weyl estimate.")
@click.option("--spectral-no-embedding", is_flag=True, help="Ablation: the correction reads no embeddings.")
@click.option("--decoder-warmup", default=0, show_default=True,
              help="Decoder-only steps on the frozen network's codes before the first epoch (a fresh "
                   "decoder on an --init network; ~10 ms a step on CPU against ~3 s for a network step).")
@click.option("--landmark-output", type=click.Choice(["ratio", "interval"]), default="ratio", show_default=True,
              help="d = L exp(MLP), or (ablation) d = L + (U - L) sigmoid(MLP); L, U: the landmark bounds.")
@click.option("--neighbors", type=click.IntRange(0), default=None, is_flag=False, flag_value=8, metavar="[K]",
              help="Point-cloud model: each mesh's vertices are read as a cloud (faces unused): graph of the K "
                   "nearest neighbours (--neighbors alone: 8), estimated normals, landmark fields from the points "
                   "alone (default 0: meshes). With --init, a mesh model's weights start it.")
@old_name("--points", "--neighbors", "old_points", type=click.IntRange(0), is_flag=False, flag_value=8)
def train(run_dir, no_rotate, preset_name, init_ckpt, channels, blocks, aggr, no_edge_length, no_relative_position,
          plain_grid_pool, euclidean_decoder, landmarks, landmark_fields, landmark_no_embedding, landmark_no_euclidean,
          spectral, spectral_no_embedding, landmark_output, neighbors, old_points, **options):
    """Train GeGnn on the geodata store STORE.

    \b
    Examples:
      gegnn train data.zarr --run runs/mine --model landmark          # fine-tunes the shipped default
      gegnn train data.zarr --run runs/mine --model landmark --epochs 4 --lr 5e-5
      gegnn train data.zarr --run runs/paper --channels 64 --epochs 27  # the paper's network, from scratch
    """
    points = either(neighbors, old_points, "--neighbors", "--points") or 0
    from ..training.loop import StoreMismatch, TrainConfig
    from ..training.loop import train as run_training

    given = _given(click.get_current_context())
    if preset_name:
        try:
            chosen = preset(preset_name, "default" if "init_ckpt" not in given else init_ckpt)
        except ValueError as exc:  # from scratch: the recipe's command, in one line
            raise click.ClickException(str(exc)) from None
        options.update({k: v for k, v in chosen.schedule.items() if k not in given})
        init_ckpt = chosen.init
    # The other options are TrainConfig's fields by name (store, epochs, ..., deterministic).
    cfg = TrainConfig(run=run_dir, rotate=not no_rotate, init=init_ckpt, model=preset_name, **options)
    extra = dict(encoder_blocks=blocks, decoder_blocks=blocks) if blocks else {}
    model_cfg = GeGnnConfig(channels=channels, embed_dim=channels, decoder_hidden=channels, aggr=aggr,
                            edge_length=not no_edge_length, relative_position=not no_relative_position,
                            sigma_n=math.inf if plain_grid_pool else GeGnnConfig.sigma_n,
                            decoder="euclidean" if euclidean_decoder else "mlp", landmarks=landmarks,
                            landmark_fields=landmark_fields, landmark_embedding=not landmark_no_embedding,
                            landmark_euclidean=not landmark_no_euclidean, landmark_output=landmark_output,
                            spectral=spectral, spectral_embedding=not spectral_no_embedding, points=points, **extra)
    if preset_name:  # the preset's architecture where no option asked for another
        model_cfg = dataclasses.replace(chosen.config, **{f: getattr(model_cfg, f) for option, fields in
                                                          MODEL_OPTIONS.items() if option in given for f in fields})
    try:
        run_training(cfg, model_cfg)
    except StoreMismatch as exc:  # another dataset on --resume: one line, no traceback
        raise click.ClickException(str(exc)) from None


@click.command("eval")
@click.argument("checkpoint", callback=_init, metavar="CHECKPOINT|NAME")
@click.argument("store", type=click.Path(exists=True, file_okay=False))
@click.option("--distance", type=click.Choice(["geodesic", "biharmonic"]),
              help="Which stored distances to compare with (default: those the model was trained on).")
@DEVICE_OPTION
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), help="Also write the table as CSV.")
def evaluate(checkpoint, store, distance, device, csv_path):
    """Mean relative error of CHECKPOINT (a file, or a shipped model's name: landmark, paper, ...) on every mesh
    of STORE (all stored pairs), and overall."""
    from ..model import GeGnn
    from ..training.devices import pick_device
    from ..training.loop import evaluate_store
    from ..training.presets import checkpoint_file

    if checkpoint is None:
        raise click.BadParameter("a checkpoint file or a shipped model's name", param_hint="CHECKPOINT")
    model = GeGnn.from_checkpoint(checkpoint_file(checkpoint))
    distance = distance or model.config.distance
    rows = evaluate_store(model, store, distance, device=pick_device(device))
    if not rows:
        raise click.ClickException(f"{store}: no committed meshes with {distance} distances")
    pairs = sum(r["pairs"] for r in rows)
    overall = dict(mesh_id="overall", vertices=sum(r["vertices"] for r in rows), pairs=pairs,
                   mre=sum(r["sum"] for r in rows) / pairs)
    width = max(len(r["mesh_id"]) for r in rows + [overall])
    click.echo(f"{'mesh':<{width}}  {'vertices':>8}  {'pairs':>9}  {'MRE %':>7}")
    for r in rows + [overall]:
        click.echo(f"{r['mesh_id']:<{width}}  {r['vertices']:>8}  {r['pairs']:>9}  {100 * r['mre']:>7.3f}")
    if csv_path:
        with open(csv_path, "w", newline="") as f:
            w = csv.DictWriter(f, ["mesh_id", "vertices", "pairs", "mre"], extrasaction="ignore")
            w.writeheader()
            w.writerows(rows + [overall])


@click.command(context_settings={"max_content_width": 100})
@click.argument("files", **MODEL_ARG)
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The finetuned checkpoint (.safetensors): a normal checkpoint for query, eval, train --init.")
@click.option("--sources", default=64, show_default=True, help="Random sources whose exact fields train.")
@click.option("--held-out", default=8, show_default=True, help="More sources, never trained on: the error "
                                                                "before and after is measured on their fields.")
@click.option("--decoder-steps", default=300, show_default=True,
              help="Phase 1: steps of the distance decoder alone on the frozen codes (~15 ms each at 5k vertices).")
@click.option("--head-steps", default=1500, show_default=True,
              help="Phase 2: steps of the embedding head and the decoder on the frozen U-Net (~30 ms each).")
@click.option("--steps", default=0, show_default=True,
              help="Phase 3: steps of the whole network (~0.45 s each on one CPU thread; the paper's 2,500 "
                   "are for a GPU).")
@click.option("--head-lr", default=3e-3, show_default=True, help="Learning rate of phases 1 and 2.")
@click.option("--lr", default=1e-3, show_default=True, help="Learning rate of phase 3.")
@click.option("--pairs-per-step", default=20_000, show_default=True)
@click.option("--prepare", is_flag=True, help="Run the geodata pipeline first (watertight, ~5k vertices); the "
                                              "model is then tuned to the prepared mesh.")
@click.option("--seed", default=0, show_default=True, help="Seed of the source choice and the pair sampling.")
@DEVICE_OPTION
def finetune(files, pretrained, output, sources, held_out, decoder_steps, head_steps, steps, head_lr, lr,
             pairs_per_step, prepare, seed, device):
    """Finetune CHECKPOINT (or --pretrained) on the one mesh MESH: exact distances from --sources random
    vertices are the training data; the held-out sources' fields measure the error before and after.

    \b
    Examples:
      gegnn finetune --pretrained bunny.obj -o bunny.safetensors
      gegnn finetune --pretrained paper scan.ply --prepare -o scan.safetensors
      gegnn finetune --pretrained part.obj --steps 2500 --device cuda -o part.safetensors   # the paper's
      gegnn finetune runs/a/best.safetensors part.obj --sources 64 -o part.safetensors
      gegnn query part.safetensors part.obj --source 0 --exact -o check.png
    """
    import time

    from ..finetune import finetune as run_finetune

    spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    _output_suffix(output, (".safetensors",))
    qm = _load_mesh(mesh_path, prepare)
    model = _load_model(spec, pretrained, device)
    name = Path(mesh_path).name
    click.echo(f"{name}: {len(qm.mesh.vertices)} vertices; exact fields from {sources} + {held_out} sources, "
               f"then {decoder_steps} decoder, {head_steps} head and {steps} network steps")
    t0 = time.process_time()
    with _click_errors(mesh_path):
        r = run_finetune(model, qm.mesh.vertices, qm.mesh.faces, sources=sources, held_out=held_out,
                         decoder_steps=decoder_steps, head_steps=head_steps, steps=steps, head_lr=head_lr, lr=lr,
                         pairs_per_step=pairs_per_step, seed=seed, progress=True)
    model.save(output, metadata={"finetuned_on": name, "finetune": dict(
        sources=sources, held_out=held_out, decoder_steps=decoder_steps, head_steps=head_steps, steps=steps,
        head_lr=head_lr, lr=lr, seed=seed,
        prepare=prepare, held_out_mre_before=r.mre_before, held_out_mre_after=r.mre_after)})
    click.echo(f"{name}: held-out MRE {100 * r.mre_before:.2f}% -> {100 * r.mre_after:.2f}% "
               f"({len(r.held_out_sources)} sources x all vertices); exact fields {r.exact_seconds:.1f} s, "
               f"training {r.train_seconds:.1f} s ({time.process_time() - t0:.0f} CPU s); written {output}")


@click.command()
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False))
@click.argument("output", type=click.Path(dir_okay=False))
@click.option("--dtype", type=click.Choice(["fp16", "bf16", "fp32"]), default="fp16", show_default=True)
@click.option("--neighbors", type=click.IntRange(min=1), metavar="K",
              help="Export a landmark mesh model as a point-cloud model of the same weights (graph of the K "
                   "nearest neighbours; the network reads any graph with positions and normals).")
@old_name("--points", "--neighbors", "old_points", type=click.IntRange(min=1))
def export(checkpoint, output, dtype, neighbors, old_points):
    """Weights-only copy of CHECKPOINT for shipping: no optimizer or RNG state, weights in DTYPE.

    Keeps the config and the training metadata (epoch, metrics, options)."""
    import dataclasses

    import torch

    from ..checkpoint import load_checkpoint, save_checkpoint
    from ..model import GeGnn

    points = either(neighbors, old_points, "--neighbors", "--points")
    ckpt = load_checkpoint(checkpoint)
    config = ckpt.config
    if points is not None:
        if not config.landmarks:
            raise click.UsageError(f"--neighbors: {Path(checkpoint).name} is not a landmark model (a point-cloud "
                                   "model reads landmark fields)")
        config = dataclasses.replace(config, points=points)
    model = GeGnn(config)
    model.load_state_dict(ckpt.model_state)
    torch_dtype = {"fp16": torch.float16, "bf16": torch.bfloat16, "fp32": torch.float32}[dtype]
    extra = {} if points is None else {"points_from": f"{Path(checkpoint).name}, weights as they are"}
    save_checkpoint(output, model, metadata={**ckpt.metadata, "exported_from": Path(checkpoint).name,
                                             "dtype": dtype, **extra}, dtype=torch_dtype)
    click.echo(f"{output}: {Path(output).stat().st_size / 2**20:.2f} MiB, "
               f"{sum(p.numel() for p in model.parameters()):,} parameters in {dtype}"
               + ("" if points is None else f"; a point-cloud model ({points} neighbours)"))
