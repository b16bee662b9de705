"""``gegnn`` command line: train, eval, query."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import click

from .model import PRETRAINED, GeGnnConfig
from .render import UP_AXES

MODEL_ARG = dict(nargs=-1, required=True, type=click.Path(dir_okay=False), metavar="[CHECKPOINT|NAME] MESH")
UP_OPTION = click.option("--up", type=click.Choice(["auto", *UP_AXES]), default="auto", show_default=True,
                         callback=lambda ctx, param, value: None if value == "auto" else value,
                         help="The mesh's up axis in pictures (auto: +y or +z, by how the mesh stands).")
PREPARE_OPTION = click.option("--prepare", is_flag=True, help="Run the geodata pipeline first (watertight, remesh "
                              "to ~5k vertices: the meshes the model was trained on).")
DEVICE_OPTION = click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
PRECISION_OPTION = click.option(
    "--precision", type=click.Choice(["fp32", "bf16", "auto"]), default="fp32", show_default=True,
    help="Network and decoder precision. bf16: 1.6x faster (measured) where the hardware has native bf16 "
         "(AVX512-BF16 or AMX CPUs, CUDA GPUs from compute capability 8.0), slower where it is emulated, "
         "distances within ~1%. auto: bf16 only where it is native.")
SIZE_OPTION = click.option("--size", default=480, show_default=True, help="Pixels across a rendered mesh (PNG).")
PRETRAINED_HELP = ("Use a model shipped in the package instead of CHECKPOINT: the most accurate one, or NAME "
                   f"({', '.join(repr(name) for name in PRETRAINED)}).")


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="geogegnn")
def main():
    """Learned geodesic embeddings (GeGnn): train on a geodata store, evaluate, query, and the paper's
    applications (finetune, geodesic paths, texture mapping, shape distributions).

    \b
    Typical use:
      gegnn train out/ --run runs/a --epochs 100
      gegnn eval runs/a/best.safetensors out/
      gegnn query runs/a/best.safetensors mesh.obj --source 0 -o field.ply
      gegnn query --pretrained mesh.obj --source 0 --exact -o field.png
      gegnn query --pretrained mesh.obj --source 0 --path 99 -o path.png
      gegnn query --pretrained mesh.obj --points points.csv -o distances.npy
      gegnn pairwise --pretrained mesh.obj -o D.npy
      gegnn finetune --pretrained mesh.obj -o tuned.safetensors
      gegnn texture --pretrained mesh.obj --center 0 -o textured.png
      gegnn view --pretrained mesh.obj -o view.html
      gegnn shape-distribution --pretrained a.obj b.obj -o d2.png
      torchrun --nproc-per-node 4 -m gegnn.cli train out/ --run-dir runs/a
    """


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
              help="Continue RUN/last.safetensors (its own options): bitwise-exact on a CPU, on a GPU with "
                   "--deterministic.")
@click.option("--deterministic", is_flag=True,
              help="torch's deterministic algorithms: identical runs and resumes on a GPU too, where atomic "
                   "scatter-adds otherwise sum in a varying order (slower; CPU runs are deterministic anyway).")
@click.option("--field-cache", type=click.Path(file_okay=False),
              help="Zarr cache of the landmark fields or spectral codes, filled before the first step and read "
                   "by every loader worker and rank (default RUN/fields.zarr; keyed by mesh content, so runs "
                   "may share one). ~2.5 MB per mesh and draw at K = 128, 5k vertices.")
@click.option("--init", "init_ckpt", type=click.Path(exists=True, dir_okay=False), help="Start from these weights.")
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
@click.option("--points", type=click.IntRange(0), default=0, is_flag=False, flag_value=8, metavar="[K]",
              help="Point-cloud model: each mesh's vertices are read as a cloud (faces unused): graph of the K "
                   "nearest neighbours (--points alone: 8), estimated normals, point-cloud heat-method landmark "
                   "fields (default 0: meshes). With --init, a mesh model's weights start it.")
def train(store, run_dir, epochs, batch_size, lr, weight_decay, warmup_epochs, clip_grad, distance,
          pairs_per_mesh, val_fraction, val_store, no_rotate, seed, device, workers, resume, deterministic,
          field_cache, init_ckpt, channels, blocks, aggr, no_edge_length, no_relative_position, plain_grid_pool,
          euclidean_decoder, landmarks, landmark_no_embedding, landmark_no_euclidean, spectral,
          spectral_no_embedding, decoder_warmup, landmark_output, points):
    """Train GeGnn on the geodata store STORE."""
    from .train import TrainConfig, train as run_training

    cfg = TrainConfig(store=store, run=run_dir, epochs=epochs, batch_size=batch_size, lr=lr,
                      weight_decay=weight_decay, warmup_epochs=warmup_epochs, clip_grad=clip_grad,
                      distance=distance, pairs_per_mesh=pairs_per_mesh, val_fraction=val_fraction, val_store=val_store,
                      rotate=not no_rotate, seed=seed, device=device, workers=workers, resume=resume,
                      init=init_ckpt, decoder_warmup=decoder_warmup, field_cache=field_cache,
                      deterministic=deterministic)
    extra = dict(encoder_blocks=blocks, decoder_blocks=blocks) if blocks else {}
    model_cfg = GeGnnConfig(channels=channels, embed_dim=channels, decoder_hidden=channels, aggr=aggr,
                            edge_length=not no_edge_length, relative_position=not no_relative_position,
                            sigma_n=math.inf if plain_grid_pool else GeGnnConfig.sigma_n,
                            decoder="euclidean" if euclidean_decoder else "mlp", landmarks=landmarks,
                            landmark_embedding=not landmark_no_embedding,
                            landmark_euclidean=not landmark_no_euclidean, landmark_output=landmark_output,
                            spectral=spectral, spectral_embedding=not spectral_no_embedding, points=points, **extra)
    run_training(cfg, model_cfg)


@main.command("eval")
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False))
@click.argument("store", type=click.Path(exists=True, file_okay=False))
@click.option("--distance", type=click.Choice(["geodesic", "biharmonic"]),
              help="Which stored distances to compare with (default: those the model was trained on).")
@DEVICE_OPTION
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), help="Also write the table as CSV.")
def evaluate(checkpoint, store, distance, device, csv_path):
    """Mean relative error of CHECKPOINT on every mesh of STORE (all stored pairs), and overall."""
    from .model import GeGnn
    from .train import evaluate_store, pick_device

    model = GeGnn.from_checkpoint(checkpoint)
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


@main.command(context_settings={"max_content_width": 100})
@click.argument("files", **MODEL_ARG)
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("--source", type=int, help="Source vertex index (the file's own numbering).")
@click.option("--pairs", "pairs_csv", type=click.Path(exists=True, dir_okay=False),
              help="Answer the pairs of this CSV (two integer columns i,j; a header is allowed).")
@click.option("--points", "points_file", type=click.Path(exists=True, dir_okay=False),
              help="Distances between points anywhere on the surface: xyz in a .npy array (P, 3) or a CSV x,y,z "
                   "(a header is allowed), in the mesh's units; each is moved to the closest surface point.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="With --source: field.npy (per file vertex), field.ply (colored mesh) or field.png "
                   "(rendered). With --pairs: a CSV i,j,distance (default: stdout). With --points: the "
                   "(P, P) matrix as .npy or .csv (default: stdout).")
@click.option("--exact", is_flag=True, help="Also compute the exact field (geodata's exact solver of the distance "
                                            "the model predicts: geodesic or biharmonic) and report the error; a "
                                            "PNG shows predicted | exact | relative error.")
@click.option("--mesh", "cloud_mesh", type=click.Path(exists=True, dir_okay=False),
              help="For a point-cloud model: the surface the cloud was taken from; with --exact, the exact field "
                   "on it from the source point, read at every point.")
@click.option("--path", "path_to", type=int, metavar="J",
              help="Trace the geodesic path from --source to vertex J on the predicted field (a PNG draws "
                   "it); with --exact also potpourri3d's exact edge-flip path, and the lengths of both.")
@PREPARE_OPTION
@DEVICE_OPTION
@PRECISION_OPTION
@UP_OPTION
@SIZE_OPTION
def query(files, pretrained, source, pairs_csv, points_file, output, exact, cloud_mesh, path_to, prepare, device,
          precision, up, size):
    """Distances on MESH (OBJ/OFF/PLY/STL/GLB, any units) predicted by CHECKPOINT or --pretrained: geodesic,
    or biharmonic with a biharmonic model (--pretrained biharmonic).

    \b
    Examples:
      gegnn query --pretrained bunny.obj --source 0 -o field.png
      gegnn query --pretrained bunny.obj --source 0 --exact -o compare.png
      gegnn query --pretrained bunny.obj --source 0 --path 1234 --exact -o path.png
      gegnn query --pretrained paper bunny.obj --source 0 --exact -o compare.png
      gegnn query --pretrained biharmonic bunny.obj --source 0 --exact -o compare.png
      gegnn query runs/a/best.safetensors bunny.obj --pairs pairs.csv -o distances.csv
      gegnn query --pretrained bunny.obj --points clicks.csv --exact -o distances.npy
      gegnn query --pretrained points scan.xyz --pairs pairs.csv -o distances.csv

    Distances are in the mesh's units. The PLY and PNG show the mesh the network ran on (with
    --prepare, the remeshed one); .npy and CSV outputs use the file's vertex numbering. A point-cloud
    model (--pretrained points) reads a cloud (.xyz .txt .pts .csv .npy .ply) instead of MESH and answers
    --source or --pairs in the file's point numbering.
    """
    import numpy as np

    from geodata.mesh import MeshError

    from .query import read_pairs

    model_spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    if _model_config(model_spec, pretrained).points:
        if (source is None) == (pairs_csv is None) or points_file or path_to is not None or prepare:
            raise click.UsageError("a point-cloud model answers --source I (with --exact --mesh MESH to compare) "
                                   "or --pairs FILE")
        if exact and pairs_csv:
            raise click.UsageError("--exact goes with --source (it compares whole fields)")
        if pairs_csv:
            _output_suffix(output, (".csv",))
            return _query_cloud_pairs(model_spec, pretrained, mesh_path, pairs_csv, output, device, precision)
        return _query_cloud(model_spec, pretrained, mesh_path, source, output,
                            _output_suffix(output, (".npy", ".ply", ".png")), exact, cloud_mesh, device, precision,
                            up, size)
    if cloud_mesh:
        raise click.UsageError("--mesh goes with a point-cloud model (the file is the mesh here)")
    if sum(x is not None for x in (source, pairs_csv, points_file)) != 1:
        raise click.UsageError("give one of --source, --pairs or --points")
    if exact and pairs_csv:
        raise click.UsageError("--exact goes with --source or --points (it compares whole fields)")
    if path_to is not None and source is None:
        raise click.UsageError("--path goes with --source (the path runs from the source)")
    if points_file:
        return _query_points(model_spec, pretrained, mesh_path, points_file, output,
                             _output_suffix(output, (".npy", ".csv")), exact, prepare, device, precision)
    suffix = _output_suffix(output, (".csv",) if pairs_csv else (".npy", ".ply", ".png"))
    qm = _load_mesh(mesh_path, prepare)
    try:
        pairs = read_pairs(pairs_csv) if pairs_csv else np.array([[source, source if path_to is None else path_to]])
        net_pairs = qm.vertices(pairs)
    except (MeshError, ValueError) as exc:
        raise click.ClickException(f"{mesh_path}: {exc}") from None
    src = int(net_pairs[0, 0])
    config = _model_config(model_spec, pretrained)
    kind = config.distance
    exact_d = err = None
    if exact and source is not None:  # before the network: the exact solver runs in a forked child
        from .query import exact_field
        try:
            exact_d = exact_field(qm.mesh, src, kind)
        except MeshError as exc:
            raise click.ClickException(f"{mesh_path}: --exact: {exc.reason}") from None

    emb = _load_model(model_spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces, precision=precision)
    if pairs_csv:
        return _write_pairs(pairs, emb.distance(net_pairs[:, 0], net_pairs[:, 1]), output)

    from .query import resolution_note, source_part

    name = Path(mesh_path).name
    note = None if prepare else resolution_note(len(qm.mesh.vertices), config)
    if note:
        click.echo(f"{name}: note: {note}")
    on, n_parts = source_part(qm.mesh, src)
    # Other parts than the source's have no distance from it: NaN (grey in pictures).
    field = np.where(on, emb.field(src), np.nan)
    click.echo(f"{name}: {len(qm.mesh.vertices)} vertices; {kind} distance from {source}: "
               f"min {np.nanmin(field):.4g} max {np.nanmax(field):.4g}")
    if n_parts > 1:
        click.echo(f"{name}: {n_parts} separate parts; source {source} is on a part of {int(on.sum())} vertices; "
                   f"the other parts have no {kind} distance from it (NaN in .npy, grey in pictures, "
                   "left out of the error)")
    title = f"{name}, source {source}"
    if exact_d is not None:
        from .query import relative_errors
        exact_d = np.where(on, exact_d, np.nan)
        err = relative_errors(field, exact_d, qm.scale, src)
        mre = float(np.nanmean(err))
        click.echo(f"mean relative error vs exact: {100 * mre:.2f}% (median {100 * np.nanmedian(err):.2f}%, "
                   f"max {100 * np.nanmax(err):.1f}%)" + (" on the source's part" if n_parts > 1 else ""))
        title += f": MRE {100 * mre:.2f}%"
    lines = []
    if path_to is not None:
        lines = _paths(emb, qm, src, int(net_pairs[0, 1]), path_to, exact_d, name)
    top = float(np.nanmax(exact_d if exact_d is not None else field))
    if suffix == ".npy":
        np.save(output, qm.to_file(field))
    elif suffix == ".ply":
        import trimesh
        trimesh.Trimesh(qm.mesh.vertices, qm.mesh.faces, vertex_colors=_field_colors(field, top),
                        process=False).export(output)
    elif suffix == ".png":
        from .render import Row, save_panels
        save_panels(output, [Row(qm.mesh.vertices, qm.mesh.faces, src, _field_panels(field, exact_d, err, src, top),
                                 lines)], suptitle=title, size=size, up=up)
    if output:
        click.echo(f"written {output}")


@main.command(context_settings={"max_content_width": 100})
@click.argument("files", **MODEL_ARG)
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The page (.html).")
@click.option("--source", "sources", type=int, multiple=True,
              help="The vertex whose field the page opens with (the file's numbering; repeat for more, e.g. "
                   "for --exact)  [default: 0]")
@click.option("--exact", is_flag=True, help="Also the exact fields of the --source vertices: the page shows "
                                            "predicted, exact and relative error for them.")
@click.option("--mesh", "cloud_mesh", type=click.Path(exists=True, dir_okay=False),
              help="With a point-cloud model and --exact: the mesh the cloud was taken from.")
@click.option("--dtype", type=click.Choice(["float32", "float16"]), default="float32", show_default=True,
              help="Codes in the page (float16: half the size; distances move by ~1e-3 relative).")
@PREPARE_OPTION
@DEVICE_OPTION
@PRECISION_OPTION
@UP_OPTION
def view(files, pretrained, output, sources, exact, cloud_mesh, dtype, prepare, device, precision, up):
    """An interactive page of MESH, or of a point cloud with a point-cloud model: coloured by the distance
    field of a vertex (a point), with isolines; click any vertex and the page decodes its field at once
    from the codes of one forward pass, with the model's own decoder (no server, no network: one
    self-contained HTML file for any browser or notebook).

    \b
    Examples:
      gegnn view --pretrained bunny.obj -o bunny.html
      gegnn view --pretrained bunny.obj --source 0 --source 1234 --exact -o compare.html
      gegnn view --pretrained biharmonic bunny.obj -o biharmonic.html
      gegnn view runs/a/best.safetensors part.obj --dtype float16 -o part.html
      gegnn view --pretrained points scan.xyz -o scan.html
      gegnn view --pretrained points scan.xyz --source 0 --exact --mesh scan.obj -o compare.html

    The page holds the mesh and the codes (N x 196 values for the landmark model: 5 MB at 5k vertices,
    half with --dtype float16). With --prepare it shows the remeshed mesh, numbered as such. A cloud
    (.xyz .txt .pts .csv .npy, or a PLY without faces) is drawn as discs of about its points' spacing,
    numbered as in its file; points far from all others are left out.
    """
    import numpy as np

    from geodata.mesh import MeshError

    from .viewer import view_page

    spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    _output_suffix(output, (".html", ".htm"))
    if _model_config(spec, pretrained).points:
        if prepare:
            raise click.UsageError("--prepare remeshes a mesh: a point cloud is shown as it is")
        return _view_cloud(spec, pretrained, mesh_path, sources or (0,), exact, cloud_mesh, output, dtype, device,
                           precision, up)
    if cloud_mesh:
        raise click.UsageError("--mesh goes with a point-cloud model (the file is the mesh here)")
    qm = _load_mesh(mesh_path, prepare)
    sources = sources or (0,)
    try:
        net_sources = [int(qm.vertices(s)) for s in sources]
    except ValueError as exc:
        raise click.ClickException(f"{mesh_path}: {exc}") from None
    config = _model_config(spec, pretrained)
    fields = {}
    if exact:
        from .query import exact_fields
        try:
            fields = dict(zip(net_sources, exact_fields(qm.mesh, np.array(net_sources), config.distance)))
        except MeshError as exc:
            raise click.ClickException(f"{mesh_path}: --exact: {exc.reason}") from None
    emb = _load_model(spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces, precision=precision)
    file_index = None
    if not prepare:  # the smallest file vertex of each mesh vertex
        used = np.flatnonzero(qm.to_mesh >= 0)[::-1]
        file_index = np.full(len(qm.mesh.vertices), -1, dtype=np.int64)
        file_index[qm.to_mesh[used]] = used
    name = Path(mesh_path).name
    model = f"--pretrained {spec or next(iter(PRETRAINED))}" if pretrained else Path(spec).name
    page = view_page(emb, title=f"{name}: {config.distance} distance predicted by GeGnn",
                     meta=f"{len(qm.mesh.vertices):,} vertices, {len(qm.mesh.faces):,} faces"
                          + (" (remeshed by --prepare)" if prepare else "") + f"; model {model}; distances in the "
                          "mesh's units", sources=net_sources, exact=fields, file_index=file_index, up=up, dtype=dtype)
    Path(output).write_text(page, encoding="utf-8")
    click.echo(f"{name}: {len(qm.mesh.vertices):,} vertices; written {output} ({len(page) / 2 ** 20:.1f} MB): "
               "open it in a browser")


@main.command(context_settings={"max_content_width": 100})
@click.argument("files", **MODEL_ARG)
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("-o", "--output", required=True, type=click.Path(),
              help="D.npy (NumPy) or D.zarr (a chunked zarr array): written tile by tile as computed, so it may "
                   "be far larger than memory; it appears under its name when complete (NAME.partial until then).")
@click.option("--rows", "rows_file", type=click.Path(exists=True, dir_okay=False),
              help="Only these rows: vertex indices (a cloud's point indices; the file's numbering) in a .npy array "
                   "or a text file of one per line. Columns are always every vertex.")
@click.option("--dtype", type=click.Choice(["float32", "float16"]), default="float32", show_default=True,
              help="float16 halves the file (relative rounding 5e-4; refuses distances over 65504).")
@click.option("--exact", is_flag=True, help="The exact solver's matrix of the model's distance instead (geodesic: "
                                            "window propagation on every core; biharmonic: geodata.biharmonic).")
@click.option("--heat", is_flag=True, help="The heat method's matrix instead (potpourri3d, one field per row).")
@click.option("--jobs", default=0, show_default=True, help="Threads of --exact (0: every core).")
@click.option("--prepare", is_flag=True, help="Run the geodata pipeline first (watertight, remesh to ~5k "
                                              "vertices); rows and columns stay the file's vertices.")
@DEVICE_OPTION
@PRECISION_OPTION
def pairwise(files, pretrained, output, rows_file, dtype, exact, heat, jobs, prepare, device, precision):
    """The whole distance matrix of MESH: every vertex (or --rows) to every vertex, predicted by
    CHECKPOINT or --pretrained, or for comparison computed by the exact solver (--exact) or the heat
    method (--heat). With a point-cloud model (--pretrained points), of a cloud's points.

    \b
    Examples:
      gegnn pairwise --pretrained bunny.obj -o D.npy
      gegnn pairwise --pretrained bunny.obj -o D.zarr --dtype float16
      gegnn pairwise --pretrained bunny.obj --rows sources.txt -o D.npy
      gegnn pairwise --pretrained bunny.obj --exact -o E.npy
      gegnn pairwise --pretrained points scan.xyz -o D.npy

    Distances are in the mesh's units; entry (r, c) is the distance from row vertex r to vertex c, in
    the file's numbering. NaN where there is no distance: a vertex used by no face (a cloud's point far
    from all others), or two separate parts. The model's matrix is exactly symmetric and 0 on the diagonal.
    """
    import time

    import numpy as np

    from geodata.mesh import MeshError, vertex_components

    from .pairwise import FileMatrix, MatrixFile, exact_rows, heat_rows

    model_spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    if exact and heat:
        raise click.UsageError("give at most one of --exact and --heat")
    if Path(output).suffix.lower() not in (".npy", ".zarr"):
        raise click.BadParameter("expected a .npy or .zarr path", param_hint="-o")
    name = Path(mesh_path).name
    config = _model_config(model_spec, pretrained)
    if config.points:
        if exact or heat or prepare:
            raise click.UsageError("a point-cloud model answers its own matrix: --exact, --heat and --prepare take a "
                                   "mesh and a mesh model")
        return _pairwise_cloud(model_spec, pretrained, mesh_path, output, rows_file, dtype, device, precision)
    qm = _load_mesh(mesh_path, prepare)
    everything = np.arange(qm.n_file_vertices)
    rows = _matrix_rows(rows_file, qm.n_file_vertices, name, "vertex", "vertices")
    kind = config.distance
    if heat and kind != "geodesic":
        raise click.UsageError(f"--heat computes geodesic distances; this model predicts {kind} distances")
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    out = MatrixFile(output, (len(rows), len(everything)), dtype)
    matrix = FileMatrix(out, vertex_components(qm.mesh), qm.to_mesh, rows, everything)
    start = time.perf_counter()
    try:
        if exact:
            what = f"exact {kind}"
            exact_rows(qm.mesh, matrix.mesh_rows, matrix.mesh_cols, matrix, kind, jobs or None, progress=True)
        elif heat:
            what = "heat-method geodesic"
            heat_rows(qm.mesh, matrix.mesh_rows, matrix.mesh_cols, matrix, progress=True)
        else:
            what = f"predicted {kind}"
            emb = _load_model(model_spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces,
                                                                    precision=precision)
            # float32 tiles: the file converts them to --dtype and checks the range, once for every source
            emb.matrix(matrix.mesh_rows, None if rows_file is None else matrix.mesh_cols, out=matrix,
                       progress=True)
    except (MeshError, ValueError) as exc:
        raise click.ClickException(f"{name}: {exc}") from None
    out.close()
    _matrix_written(name, out, what, dtype, time.perf_counter() - start, output)


def _matrix_rows(rows_file, n: int, name: str, item: str, items: str):
    """The rows of ``gegnn pairwise``: every one of the file's ``n``, or those of --rows, checked."""
    import numpy as np

    from .query import read_indices

    try:
        rows = np.arange(n) if rows_file is None else read_indices(rows_file)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from None
    bad = (rows < 0) | (rows >= n)
    if bad.any():
        raise click.ClickException(f"{rows_file}: {item} {rows[bad][0]} out of range: {name} has {n} {items}")
    return rows


def _matrix_written(name, out, what, dtype, seconds, output) -> None:
    import numpy as np

    size = out.shape[0] * out.shape[1] * np.dtype(dtype).itemsize
    click.echo(f"{name}: {out.shape[0]} x {out.shape[1]} {what} distances ({dtype}, {size / 2**20:.1f} MiB) in "
               f"{seconds:.1f} s, written to {output}")


def _pairwise_cloud(model_spec, pretrained, cloud_path, output, rows_file, dtype, device, precision):
    """``gegnn pairwise`` with a point-cloud model: the matrix of the cloud's points (or --rows) to all of
    them, in the file's numbering; NaN for far outliers and between parts of the neighbour graph."""
    import time

    import numpy as np

    from .pairwise import FileMatrix, MatrixFile

    name = Path(cloud_path).name
    cloud, keep = _load_cloud(cloud_path, [])
    n = len(cloud.points)
    rows = _matrix_rows(rows_file, n, name, "point", "points")
    model = _load_model(model_spec, pretrained, device, clouds=True)
    start = time.perf_counter()
    emb = _embed_cloud(model, cloud, keep, cloud_path, precision)
    to_kept = np.full(n, -1)
    to_kept[keep] = np.arange(len(keep))
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    out = MatrixFile(output, (len(rows), n), dtype)
    matrix = FileMatrix(out, emb.part, to_kept, rows, np.arange(n))
    try:
        emb.matrix(matrix.mesh_rows, None if rows_file is None else matrix.mesh_cols, out=matrix, progress=True)
    except ValueError as exc:
        raise click.ClickException(f"{name}: {exc}") from None
    out.close()
    _matrix_written(name, out, f"predicted {model.config.distance}", dtype, time.perf_counter() - start, output)


def _query_points(model_spec, pretrained, mesh_path, points_file, output, suffix, exact, prepare, device,
                  precision):
    """``gegnn query --points``: the (P, P) matrix between surface points, optionally against exact distances
    between the same points inserted as vertices."""
    import numpy as np

    from geodata.mesh import MeshError
    from geodata.surface_points import insert_points, locate_points

    from .query import exact_fields, read_points, relative_errors

    qm = _load_mesh(mesh_path, prepare)
    name = Path(mesh_path).name
    try:
        points = read_points(points_file)
    except (OSError, ValueError) as exc:
        raise click.ClickException(str(exc)) from None
    located = locate_points(qm.mesh, points)
    click.echo(f"{name}: {len(points)} points, at most {located.offset.max():.3g} from the surface (each moved to "
               "the closest surface point)")
    kind = _model_config(model_spec, pretrained).distance
    exact_d = None
    if exact:  # before the network: the exact solver runs in a forked child
        refined, vertex = insert_points(qm.mesh, located.face, located.bary)
        try:
            exact_d = exact_fields(refined, vertex, kind)[:, vertex]
        except MeshError as exc:
            raise click.ClickException(f"{name}: --exact: {exc.reason}") from None
    emb = _load_model(model_spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces, precision=precision)
    d = emb.surface_distance(located.face[:, None], located.bary[:, None], located.face[None], located.bary[None])
    if exact_d is not None:
        errors = np.concatenate([relative_errors(d[p], exact_d[p], qm.scale, p) for p in range(len(d))])
        click.echo(f"mean relative error vs exact (points inserted as vertices): {100 * np.nanmean(errors):.2f}% "
                   f"(median {100 * np.nanmedian(errors):.2f}%, max {100 * np.nanmax(errors):.1f}%)")
    if suffix == ".npy":
        np.save(output, d)
    else:
        text = "\n".join(",".join(f"{x:.6g}" for x in row) for row in d.tolist()) + "\n"
        if output:
            Path(output).write_text(text)
        else:
            click.echo(text, nl=False)
    if output:
        click.echo(f"written {output}")


def _view_cloud(model_spec, pretrained, cloud_path, sources, exact, mesh_path, output, dtype, device, precision,
                up):
    """``gegnn view`` with a point-cloud model: the page of the cloud's points (outliers left out)."""
    import numpy as np

    from geodata.mesh import MeshError

    from .viewer import view_page

    name = Path(cloud_path).name
    if exact and not mesh_path:
        raise click.UsageError("--exact with a point cloud needs --mesh MESH, the surface it was taken from")
    cloud, keep = _load_cloud(cloud_path, sources)
    local = [int(np.searchsorted(keep, s)) for s in sources]
    points = cloud.points[keep]
    normals = None if cloud.normals is None else cloud.normals[keep]
    model = _load_model(model_spec, pretrained, device, clouds=True)
    fields = {}
    if exact:
        from .query import exact_at_points, load_query_mesh
        try:
            qm = load_query_mesh(mesh_path)
            fields = {s: exact_at_points(qm.mesh, points, s, model.config.distance)[0] for s in local}
        except MeshError as exc:
            raise click.ClickException(f"{mesh_path}: --exact: {exc.reason}") from None
    emb = _embed_cloud(model, cloud, keep, cloud_path, precision)
    label = f"--pretrained {model_spec}" if pretrained else Path(model_spec).name
    page = view_page(emb, title=f"{name}: {model.config.distance} distance predicted by GeGnn",
                     meta=f"{len(points):,} points of {len(cloud.points):,}"
                          f"{'' if normals is None else ' with normals'}; {int(emb.part.max()) + 1} part(s) in the "
                          f"{model.config.points}-neighbour graph; model {label}; distances in the cloud's units",
                     sources=local, exact=fields, file_index=keep, up=up, dtype=dtype, normals=normals)
    Path(output).write_text(page, encoding="utf-8")
    click.echo(f"{name}: {len(points):,} points; written {output} ({len(page) / 2 ** 20:.1f} MB): open it in a "
               "browser")


def _load_cloud(cloud_path, sources, err: bool = False):
    """A cloud file and its points that are not far outliers (sorted indices), after checking that every
    source is one of them; its notes and the outliers' count echoed (to stderr with ``err``)."""
    import numpy as np

    from geodata.mesh import MeshError
    from geodata.stages.cloud import load_cloud_file, outliers

    name = Path(cloud_path).name
    try:
        cloud = load_cloud_file(cloud_path)
    except MeshError as exc:
        raise click.ClickException(f"{cloud_path}: {exc.reason}") from None
    n = len(cloud.points)
    for note in cloud.notes:
        click.echo(f"{name}: note: {note}", err=err)
    far = outliers(cloud.points)
    for source in sources:
        if not 0 <= source < n:
            raise click.ClickException(f"{cloud_path}: point {source} out of range: {name} has {n} points")
        if source in far:
            raise click.ClickException(f"{cloud_path}: point {source} is far from all other points (an outlier): "
                                       "no distances from it")
    if len(far):
        click.echo(f"{name}: note: {len(far)} points far from all others (the first: point {far[0]}) are left out "
                   "(NaN)", err=err)
    return cloud, np.setdiff1d(np.arange(n), far)


def _embed_cloud(model, cloud, keep, cloud_path, precision):
    """The model's embedding of a cloud file's kept points (with the file's normals, if it has them); a cloud
    the model cannot take fails naming the file."""
    try:
        return model.embed(cloud.points[keep], normals=None if cloud.normals is None else cloud.normals[keep],
                           precision=precision)
    except ValueError as exc:
        raise click.ClickException(f"{cloud_path}: {exc}") from None


def _write_pairs(pairs, distances, output) -> None:
    """A CSV i,j,distance of the pairs in the file's numbering, to ``output`` or stdout."""
    lines = ["i,j,distance"] + [f"{i},{j},{x:.6g}" for (i, j), x in zip(pairs.tolist(), distances.tolist())]
    if output:
        Path(output).write_text("\n".join(lines) + "\n")
        click.echo(f"{len(pairs)} distances written to {output}")
    else:
        click.echo("\n".join(lines))


def _query_cloud_pairs(model_spec, pretrained, cloud_path, pairs_csv, output, device, precision):
    """``gegnn query --pairs`` with a point-cloud model: the distance of every pair of the file's points, NaN
    where a point is a far outlier or the two lie on different parts of the neighbour graph."""
    import numpy as np

    from .query import read_pairs

    name = Path(cloud_path).name
    try:
        pairs = read_pairs(pairs_csv)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from None
    cloud, keep = _load_cloud(cloud_path, [], err=output is None)  # notes apart from a CSV on stdout
    n = len(cloud.points)
    bad = (pairs < 0) | (pairs >= n)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        raise click.ClickException(f"{pairs_csv}: pair {row + 1}: point {pairs[bad][0]} out of range: {name} has "
                                   f"{n} points")
    emb = _embed_cloud(_load_model(model_spec, pretrained, device, clouds=True), cloud, keep, cloud_path, precision)
    local = np.searchsorted(keep, pairs)
    kept = (local < len(keep)) & (keep[np.minimum(local, len(keep) - 1)] == pairs)
    local = np.where(kept, local, 0)
    d = emb.distance(local[:, 0], local[:, 1])
    same = kept.all(axis=1) & (emb.part[local[:, 0]] == emb.part[local[:, 1]])
    d = np.where(same, d, np.nan)
    if not same.all():
        click.echo(f"{name}: note: {int((~same).sum())} pairs have no distance (NaN): a point far from all others, "
                   "or the two on different parts of the neighbour graph", err=output is None)
    _write_pairs(pairs, d, output)


def _query_cloud(model_spec, pretrained, cloud_path, source, output, suffix, exact, mesh_path, device, precision,
                 up, size):
    """``gegnn query`` with a point-cloud model: the field of point ``source`` over the cloud, NaN at outliers
    and on other parts of its neighbour graph; with --exact --mesh, against the exact field on the mesh."""
    import numpy as np

    from geodata.mesh import MeshError

    from .query import relative_errors

    name = Path(cloud_path).name
    if exact and not mesh_path:
        raise click.UsageError("--exact with a point cloud needs --mesh MESH, the surface it was taken from")
    cloud, keep = _load_cloud(cloud_path, [source])
    points, n = cloud.points, len(cloud.points)
    model = _load_model(model_spec, pretrained, device, clouds=True)
    emb = _embed_cloud(model, cloud, keep, cloud_path, precision)
    part = emb.part
    local = int(np.searchsorted(keep, source))
    field = np.full(n, np.nan)
    field[keep] = np.where(part == part[local], emb.field(local), np.nan)
    n_parts = int(part.max()) + 1
    click.echo(f"{name}: {n} points{'' if cloud.normals is None else ' with normals'}; {n_parts} part(s) in the "
               f"{model.config.points}-neighbour graph; {model.config.distance} distance from point {source}: "
               f"min {np.nanmin(field):.4g} max {np.nanmax(field):.4g}")
    exact_d = err = None
    if exact:
        from .query import exact_at_points, load_query_mesh
        try:
            qm = load_query_mesh(mesh_path)
            exact_d, offset = exact_at_points(qm.mesh, points, source, model.config.distance)
        except MeshError as exc:
            raise click.ClickException(f"{mesh_path}: --exact: {exc.reason}") from None
        err = relative_errors(field, exact_d, qm.scale, source)
        click.echo(f"mean relative error vs exact on {Path(mesh_path).name}: {100 * np.nanmean(err):.2f}% (median "
                   f"{100 * np.nanmedian(err):.2f}%; the points lie within {offset.max():.3g} of the surface)")
    top = float(np.nanmax(exact_d if exact_d is not None else field))
    if suffix == ".npy":
        np.save(output, field)
    elif suffix == ".ply":
        import trimesh
        trimesh.PointCloud(points, colors=_field_colors(field, top)).export(output)
    elif suffix == ".png":
        from .pointcloud import unoriented_normals
        from .render import Row, save_panels
        lit = cloud.normals if cloud.normals is not None else unoriented_normals(points)
        save_panels(output, [Row(points, None, source, _field_panels(field, exact_d, err, source, top), normals=lit)],
                    size=size, up=up, suptitle=f"{name}, point {source}")
    if output:
        click.echo(f"written {output}")


# -- shared by the commands on a user's mesh --------------------------------------------------------------
def _model_and_meshes(files, pretrained, many=False):
    """``[CHECKPOINT|NAME] MESH...`` -> (checkpoint path, pretrained name or None; mesh paths)."""
    usage = "give CHECKPOINT MESH, or --pretrained [NAME] MESH" + ("..." if many else "")
    if pretrained:
        spec = files[0] if len(files) > 1 and files[0] in PRETRAINED else None
        if spec is None and len(files) > 1 and not many:
            raise click.UsageError(f"no pretrained model {files[0]!r}; shipped: {', '.join(PRETRAINED)}")
        meshes = files[1:] if spec else files
    else:
        spec, meshes = files[0], files[1:]
    if not meshes or (len(meshes) > 1 and not many):
        raise click.UsageError(usage)
    for path in ([] if pretrained else [spec]) + list(meshes):
        if not Path(path).is_file():
            raise click.BadParameter(f"{path}: no such file", param_hint="[CHECKPOINT] MESH")
    return spec, list(meshes)


def _model_config(spec, pretrained):
    """The config of a model, from its file's metadata alone (no weights read, no torch thread started)."""
    from .checkpoint import read_config
    from .model import pretrained_file

    if not pretrained:
        return read_config(spec)
    with pretrained_file(spec) as path:
        return read_config(path)


def _field_colors(field, top: float):
    """RGBA uint8 (N, 4) of a per-vertex field for a coloured PLY: viridis over [0, top], grey where NaN."""
    import matplotlib
    import numpy as np

    from .render import UNREACHABLE
    colors = matplotlib.colormaps["viridis"](np.nan_to_num(field / max(top, 1e-30)))
    colors[np.isnan(field)] = UNREACHABLE
    return (colors * 255).astype(np.uint8)


def _field_panels(field, exact_d, err, source: int, top: float) -> list:
    """The panels of a query's picture: predicted, and with an exact field, exact and the relative error
    (0 at the source; NaN, grey, where there is no distance)."""
    from .render import Panel

    panels = [Panel(field, "predicted", vmin=0, vmax=top)]
    if exact_d is not None:
        shown = err.copy()
        shown[source] = 0.0
        panels += [Panel(exact_d, "exact", vmin=0, vmax=top),
                   Panel(shown, "relative error", "magma", "|pred - exact| / exact", 0, 0.1, isolines=0)]
    return panels


def _load_model(spec, pretrained, device, clouds: bool = False):
    """The model, on its device; a point-cloud model only where ``clouds`` (the command takes clouds)."""
    from .model import GeGnn
    from .train import pick_device

    model = GeGnn.pretrained(spec) if pretrained else GeGnn.from_checkpoint(spec)
    if model.config.points and not clouds:
        raise click.UsageError(f"{spec} is a point-cloud model: it answers gegnn query and gegnn view on a "
                               "cloud; this command takes a mesh model")
    return model.to(pick_device(device))


def _output_suffix(output, allowed) -> str:
    """The suffix of ``output`` (checked against ``allowed``), its folder made; "" without output."""
    if not output:
        return ""
    suffix = Path(output).suffix.lower()
    if suffix not in allowed:
        raise click.BadParameter(f"expected one of {', '.join(allowed)}", param_hint="-o")
    try:
        Path(output).parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise click.ClickException(f"{output}: cannot write there: {exc.strerror or exc}") from None
    return suffix


def _load_mesh(path, prepare):
    """The query mesh of a mesh model's command; a point cloud is refused with the command that takes it."""
    from geodata.mesh import MeshError
    from geodata.stages.cloud import CLOUD_SUFFIXES

    from .query import load_query_mesh

    hint = ("point clouds are answered by a point-cloud model: gegnn query --pretrained points "
            f"{Path(path).name} --source I")
    if Path(path).suffix.lower() in set(CLOUD_SUFFIXES) - {".ply"}:
        raise click.ClickException(f"{path}: a point-cloud file, not a mesh ({hint})")
    try:
        return load_query_mesh(path, prepare=prepare)
    except (MeshError, ValueError) as exc:
        cloud = isinstance(exc, MeshError) and exc.reason.startswith("point cloud")
        raise click.ClickException(f"{path}: {exc}" + (f" ({hint})" if cloud else "")) from None


def _paths(emb, qm, src, dst, path_to, exact_d, name) -> list:
    """Trace the predicted path (and with the exact field, the edge-flip one); report; lines to draw."""
    try:
        path = emb.path(src, dst)
    except ValueError as exc:
        raise click.ClickException(f"{name}: --path {path_to}: {exc}") from None
    note = "" if path.traced else " (the field has a local minimum on the way: finished along edges)"
    click.echo(f"{name}: path to {path_to}: {len(path.points)} points, length {path.length:.4g}, predicted "
               f"distance {float(emb.distance(src, dst)):.4g}{note}")
    lines = [(path.points, f"predicted path ({path.length:.3g})")]
    if exact_d is not None and dst != src:
        from geodata.geodesic import edge_flip_paths, polyline_length
        try:
            flip = edge_flip_paths(qm.mesh, [(src, dst)])[0]
        except (RuntimeError, ValueError) as exc:
            click.echo(f"{name}: no edge-flip path: {exc}")
        else:
            flip_len = polyline_length(flip)
            click.echo(f"{name}: exact distance {exact_d[dst]:.4g}; edge-flip path length {flip_len:.4g}; "
                       f"predicted path / edge-flip path {path.length / flip_len:.4f}")
            lines.append((flip, f"exact path ({flip_len:.3g})"))
    return lines


@main.command(context_settings={"max_content_width": 100})
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

    from geodata.mesh import MeshError

    from .finetune import finetune as run_finetune

    spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    _output_suffix(output, (".safetensors",))
    qm = _load_mesh(mesh_path, prepare)
    model = _load_model(spec, pretrained, device)
    name = Path(mesh_path).name
    click.echo(f"{name}: {len(qm.mesh.vertices)} vertices; exact fields from {sources} + {held_out} sources, "
               f"then {decoder_steps} decoder, {head_steps} head and {steps} network steps")
    t0 = time.process_time()
    try:
        r = run_finetune(model, qm.mesh.vertices, qm.mesh.faces, sources=sources, held_out=held_out,
                         decoder_steps=decoder_steps, head_steps=head_steps, steps=steps, head_lr=head_lr, lr=lr,
                         pairs_per_step=pairs_per_step, seed=seed, progress=True)
    except MeshError as exc:
        raise click.ClickException(f"{mesh_path}: {exc.reason}") from None
    except ValueError as exc:
        raise click.ClickException(f"{mesh_path}: {exc}") from None
    model.save(output, metadata={"finetuned_on": name, "finetune": dict(
        sources=sources, held_out=held_out, decoder_steps=decoder_steps, head_steps=head_steps, steps=steps,
        head_lr=head_lr, lr=lr, seed=seed,
        prepare=prepare, held_out_mre_before=r.mre_before, held_out_mre_after=r.mre_after)})
    click.echo(f"{name}: held-out MRE {100 * r.mre_before:.2f}% -> {100 * r.mre_after:.2f}% "
               f"({len(r.held_out_sources)} sources x all vertices); exact fields {r.exact_seconds:.1f} s, "
               f"training {r.train_seconds:.1f} s ({time.process_time() - t0:.0f} CPU s); written {output}")


@main.command(context_settings={"max_content_width": 100})
@click.argument("files", **MODEL_ARG)
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("--center", required=True, type=int, help="Center vertex of the map (the file's own numbering).")
@click.option("--radius", type=float, help="Geodesic radius of the textured disc, in the mesh's units "
                                           "[default: 0.4 of the mesh's half-extent].")
@click.option("--squares", default=8, show_default=True, help="Checker squares across the disc's diameter.")
@click.option("--compare", is_flag=True, help="Also the vector-heat log map (potpourri3d, Sharp et al. 2019) "
                                              "side by side, and the mean difference of the two.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="textured.png (rendered), or uv.npy ((u, v) per file vertex, NaN outside the disc).")
@click.option("--prepare", is_flag=True, help="Run the geodata pipeline first (watertight, ~5k vertices).")
@DEVICE_OPTION
@UP_OPTION
@SIZE_OPTION
def texture(files, pretrained, center, radius, squares, compare, output, prepare, device, up, size):
    """Texture MESH around a vertex with the geodesic polar coordinates (discrete log map) that the
    model's distance queries give: a checkerboard decal, its u axis drawn red.

    \b
    Examples:
      gegnn texture --pretrained bunny.obj --center 0 -o textured.png
      gegnn texture --pretrained bunny.obj --center 0 --radius 0.05 --compare -o compare.png
      gegnn texture runs/a/best.safetensors part.obj --center 10 -o uv.npy
    """
    import numpy as np

    spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    suffix = _output_suffix(output, (".png", ".npy"))
    qm = _load_mesh(mesh_path, prepare)
    try:
        c = int(qm.vertices(center))
    except ValueError as exc:
        raise click.ClickException(f"{mesh_path}: {exc}") from None
    radius = radius or 0.4 * qm.scale
    emb = _load_model(spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces)
    lm = emb.log_map(c, radius)
    uv = np.full((len(qm.mesh.vertices), 2), np.nan)
    uv[lm.vertices] = lm.uv
    name = Path(mesh_path).name
    click.echo(f"{name}: {len(lm.vertices)} vertices within {radius:.4g} of vertex {center}")
    panels = [("log map from distance queries", uv)]
    if compare:
        from .logmap import vector_heat_log_map
        try:
            ref, diff = vector_heat_log_map(qm.mesh.vertices, qm.mesh.faces, lm)
        except ValueError as exc:
            raise click.ClickException(f"{mesh_path}: --compare: {exc} (--prepare makes a clean mesh)") from None
        click.echo(f"{name}: vs the vector-heat log map: mean |difference| {diff:.4f} of the radius "
                   f"(after the best rotation of the tangent frames)")
        full = np.full_like(uv, np.nan)
        full[lm.vertices] = ref
        panels.append(("vector heat (potpourri3d)", full))
    if suffix == ".npy":
        np.save(output, np.stack([qm.to_file(uv[:, 0]), qm.to_file(uv[:, 1])], axis=1))
    else:
        from .render import Panel, Row, save_panels
        save_panels(output, [Row(qm.mesh.vertices, qm.mesh.faces, c, [
            Panel(f, title, vmax=2 * radius / squares) for title, f in panels])],
            suptitle=f"{name}, center {center}, radius {radius:.3g}", size=size, up=up)
    click.echo(f"written {output}")


@main.command("shape-distribution", context_settings={"max_content_width": 100})
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False),
                metavar="[CHECKPOINT|NAME] MESH...")
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("--pairs", default=1_000_000, show_default=True, help="Random point pairs per mesh.")
@click.option("--bins", default=64, show_default=True)
@click.option("--seed", default=0, show_default=True)
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="d2.png (geodesic and Euclidean histograms), or d2.csv (the densities).")
@DEVICE_OPTION
def shape_distribution(files, pretrained, pairs, bins, seed, output, device):
    """Shape distributions (D2, Osada et al. 2002) of each MESH with predicted geodesic distances, next to
    the Euclidean ones: histograms of the distance between random surface points (of a mesh's largest
    part) over its mean. With several meshes, the L1 distance of each histogram to the first mesh's
    (0: equal, 2: disjoint).

    \b
    Examples:
      gegnn shape-distribution --pretrained horse.obj horse-bent.obj -o d2.png
      gegnn shape-distribution runs/a/best.safetensors *.obj --pairs 200000 -o d2.csv
    """
    import numpy as np

    from .query import largest_part
    from .statistics import geodesic_and_euclidean_d2, histogram_l1

    spec, meshes = _model_and_meshes(files, pretrained, many=True)
    suffix = _output_suffix(output, (".png", ".csv"))
    model = _load_model(spec, pretrained, device)
    results = []
    for path in meshes:
        qm = _load_mesh(path, False)
        v, f = qm.mesh.vertices, qm.mesh.faces
        geo, euc = geodesic_and_euclidean_d2(model.embed(v, f).distance, v, f, pairs, seed, bins, largest_part(qm.mesh))
        results.append((Path(path).name, geo, euc))
        line = f"{Path(path).name}: mean geodesic {geo.mean:.4g}, mean Euclidean {euc.mean:.4g}"
        if len(results) > 1:
            line += (f"; L1 to {results[0][0]}: geodesic {histogram_l1(geo, results[0][1]):.3f}, "
                     f"Euclidean {histogram_l1(euc, results[0][2]):.3f}")
        click.echo(line)
    if suffix == ".csv":
        header = ["ratio_lo", "ratio_hi"] + [f"{n}:{k}" for n, *_ in results for k in ("geodesic", "euclidean")]
        columns = [geo.edges[:-1], geo.edges[1:]] + [h.density for _, *hs in results for h in hs]
        with open(output, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(np.stack(columns, axis=1).round(6).tolist())
    elif suffix == ".png":
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
        for ax, k, title in ((axes[0], 1, "geodesic (predicted)"), (axes[1], 2, "Euclidean")):
            for r in results:
                ax.stairs(r[k].density, r[k].edges, label=r[0], lw=1.5)
            ax.set(title=title, xlabel="distance / mean distance")
        axes[0].set_ylabel("density")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(output, dpi=100)
        plt.close(fig)
    if output:
        click.echo(f"written {output}")


@main.command()
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False))
@click.argument("output", type=click.Path(dir_okay=False))
@click.option("--dtype", type=click.Choice(["fp16", "bf16", "fp32"]), default="fp16", show_default=True)
@click.option("--points", type=click.IntRange(min=1), metavar="K",
              help="Export a landmark mesh model as a point-cloud model of the same weights (graph of the K "
                   "nearest neighbours; the network reads any graph with positions and normals).")
def export(checkpoint, output, dtype, points):
    """Weights-only copy of CHECKPOINT for shipping: no optimizer or RNG state, weights in DTYPE.

    Keeps the config and the training metadata (epoch, metrics, options)."""
    import dataclasses

    import torch

    from .checkpoint import load_checkpoint, save_checkpoint
    from .model import GeGnn

    ckpt = load_checkpoint(checkpoint)
    config = ckpt.config
    if points is not None:
        if not config.landmarks:
            raise click.UsageError(f"--points: {Path(checkpoint).name} is not a landmark model (a point-cloud "
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


if __name__ == "__main__":
    main()
