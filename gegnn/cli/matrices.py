"""``gegnn pairwise``: distance matrices of a user's mesh or point cloud, written row block by row block."""
from __future__ import annotations

from pathlib import Path

import click

from .inputs import (_click_errors, _embed_cloud, _load_cloud, _load_mesh, _load_model, _model_and_meshes,
                     _model_config)
from .options import DEVICE_OPTION, FIELDS_OPTION, MODEL_ARG, PRECISION_OPTION, PRETRAINED_HELP, check_fields


@click.command(context_settings={"max_content_width": 100})
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
@FIELDS_OPTION
@DEVICE_OPTION
@PRECISION_OPTION
def pairwise(files, pretrained, output, rows_file, dtype, exact, heat, jobs, prepare, landmark_fields, device,
             precision):
    """The whole distance matrix of MESH: every vertex (or --rows) to every vertex, predicted by
    CHECKPOINT or --pretrained, or for comparison computed by the exact solver (--exact) or the heat
    method (--heat). With a point-cloud model (--pretrained points), of a cloud's points.

    \b
    Examples:
      gegnn pairwise --pretrained bunny.obj -o D.npy
      gegnn pairwise --pretrained bunny.obj -o D.zarr --dtype float16
      gegnn pairwise --pretrained bunny.obj --rows sources.txt -o D.npy
      gegnn pairwise --pretrained bunny.obj --fields paths -o D.npy
      gegnn pairwise --pretrained bunny.obj --exact -o E.npy
      gegnn pairwise --pretrained points scan.xyz -o D.npy

    Distances are in the mesh's units; entry (r, c) is the distance from row vertex r to vertex c, in
    the file's numbering. NaN where there is no distance: a vertex used by no face (a cloud's point far
    from all others), or two separate parts. The model's matrix is exactly symmetric and 0 on the diagonal.
    """
    import time

    import numpy as np

    from geodata.mesh import vertex_components

    from ..queries.pairwise import FileMatrix, MatrixFile, exact_rows, heat_rows

    model_spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    if exact and heat:
        raise click.UsageError("give at most one of --exact and --heat")
    if Path(output).suffix.lower() not in (".npy", ".zarr"):
        raise click.BadParameter("expected a .npy or .zarr path", param_hint="-o")
    name = Path(mesh_path).name
    config = _model_config(model_spec, pretrained)
    check_fields(config, landmark_fields)
    if landmark_fields and (exact or heat):
        raise click.UsageError("--fields goes with the model's matrix (not --exact or --heat)")
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
    with _click_errors(name):
        if exact:
            what = f"exact {kind}"
            exact_rows(qm.mesh, matrix.mesh_rows, matrix.mesh_cols, matrix, kind, jobs or None, progress=True)
        elif heat:
            what = "heat-method geodesic"
            heat_rows(qm.mesh, matrix.mesh_rows, matrix.mesh_cols, matrix, progress=True)
        else:
            what = f"predicted {kind}"
            emb = _load_model(model_spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces,
                                                                    precision=precision, fields=landmark_fields)
            # float32 tiles: the file converts them to --dtype and checks the range, once for every source
            emb.matrix(matrix.mesh_rows, None if rows_file is None else matrix.mesh_cols, out=matrix,
                       progress=True)
    out.close()
    _matrix_written(name, out, what, dtype, time.perf_counter() - start, output)


def _matrix_rows(rows_file, n: int, name: str, item: str, items: str):
    """The rows of ``gegnn pairwise``: every one of the file's ``n``, or those of --rows, checked."""
    import numpy as np

    from ..queries.files import read_indices

    with _click_errors():
        rows = np.arange(n) if rows_file is None else read_indices(rows_file)
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

    from ..queries.pairwise import FileMatrix, MatrixFile

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
    with _click_errors(name):
        emb.matrix(matrix.mesh_rows, None if rows_file is None else matrix.mesh_cols, out=matrix, progress=True)
    out.close()
    _matrix_written(name, out, f"predicted {model.config.distance}", dtype, time.perf_counter() - start, output)
