"""``gegnn`` command line: train, eval, query."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import click

from .model import GeGnnConfig


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="geogegnn")
def main():
    """Learned geodesic embeddings (GeGnn): train on a geodata store, evaluate, query.

    \b
    Typical use:
      gegnn train out/ --run runs/a --epochs 100
      gegnn eval runs/a/best.safetensors out/
      gegnn query runs/a/best.safetensors mesh.obj --source 0 -o field.ply
      torchrun --nproc-per-node 4 -m gegnn.cli train out/ --run-dir runs/a
    """


def _blocks(ctx, param, value):
    if value is None:
        return None
    try:
        return tuple(int(b) for b in value.split(","))
    except ValueError:
        raise click.BadParameter("comma-separated integers, e.g. 2,3,3,3,2")


@main.command()
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
@click.option("--val-fraction", default=0.1, show_default=True)
@click.option("--no-rotate", is_flag=True, help="Disable random-rotation augmentation.")
@click.option("--seed", default=0, show_default=True)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--workers", default=0, show_default=True, help="Loader processes building batches.")
@click.option("--resume", is_flag=True, help="Continue RUN/last.safetensors exactly (its own options).")
@click.option("--init", "init_ckpt", type=click.Path(exists=True, dir_okay=False), help="Start from these weights.")
@click.option("--channels", default=256, show_default=True)
@click.option("--blocks", callback=_blocks, help="ResBlocks per level, encoder = decoder [2,3,3,3,2].")
@click.option("--aggr", type=click.Choice(["max", "mean", "sum"]), default="max", show_default=True)
@click.option("--no-edge-length", is_flag=True, help="Ablation: drop |v_i - v_j| from GeoConv.")
@click.option("--no-relative-position", is_flag=True, help="Ablation: drop v_i - v_j from GeoConv.")
@click.option("--plain-grid-pool", is_flag=True, help="Ablation: pool on xyz only (sigma_n = inf).")
@click.option("--euclidean-decoder", is_flag=True, help="Ablation: distance = ||e_i - e_j||.")
def train(store, run_dir, epochs, batch_size, lr, weight_decay, warmup_epochs, clip_grad, distance,
          pairs_per_mesh, val_fraction, no_rotate, seed, device, workers, resume, init_ckpt, channels,
          blocks, aggr, no_edge_length, no_relative_position, plain_grid_pool, euclidean_decoder):
    """Train GeGnn on the geodata store STORE."""
    from .train import TrainConfig, train as run_training

    cfg = TrainConfig(store=store, run=run_dir, epochs=epochs, batch_size=batch_size, lr=lr,
                      weight_decay=weight_decay, warmup_epochs=warmup_epochs, clip_grad=clip_grad,
                      distance=distance, pairs_per_mesh=pairs_per_mesh, val_fraction=val_fraction,
                      rotate=not no_rotate, seed=seed, device=device, workers=workers, resume=resume,
                      init=init_ckpt)
    extra = dict(encoder_blocks=blocks, decoder_blocks=blocks) if blocks else {}
    model_cfg = GeGnnConfig(channels=channels, embed_dim=channels, decoder_hidden=channels, aggr=aggr,
                            edge_length=not no_edge_length, relative_position=not no_relative_position,
                            sigma_n=math.inf if plain_grid_pool else GeGnnConfig.sigma_n,
                            decoder="euclidean" if euclidean_decoder else "mlp", **extra)
    run_training(cfg, model_cfg)


@main.command("eval")
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False))
@click.argument("store", type=click.Path(exists=True, file_okay=False))
@click.option("--distance", type=click.Choice(["geodesic", "biharmonic"]), default="geodesic", show_default=True)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), help="Also write the table as CSV.")
def evaluate(checkpoint, store, distance, device, csv_path):
    """Mean relative error of CHECKPOINT on every mesh of STORE (all stored pairs), and overall."""
    from .model import GeGnn
    from .train import evaluate_store, pick_device

    model = GeGnn.from_checkpoint(checkpoint)
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


@main.command()
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False))
@click.argument("mesh", type=click.Path(exists=True, dir_okay=False))
@click.option("--source", required=True, type=int, help="Source vertex index.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Write the field: .npy, or .ply (colored).")
def query(checkpoint, mesh, source, output):
    """Distance field from vertex SOURCE on MESH (any units; the field is in the mesh's units)."""
    import numpy as np
    import trimesh

    from .model import GeGnn

    m = trimesh.load(mesh, force="mesh", process=False)  # process=True would reorder vertices
    if not 0 <= source < len(m.vertices):
        raise click.BadParameter(f"source must be in [0, {len(m.vertices)})", param_hint="--source")
    field = GeGnn.from_checkpoint(checkpoint).embed(m.vertices, m.faces).field(source)
    click.echo(f"{len(field)} vertices; distance from {source}: min {field.min():.4g} max {field.max():.4g}")
    if output and Path(output).suffix == ".ply":
        import matplotlib

        m.visual.vertex_colors = (matplotlib.colormaps["viridis"](field / field.max()) * 255).astype(np.uint8)
        m.export(output)
    elif output:
        np.save(output, field)


if __name__ == "__main__":
    main()
