"""``gegnn query``: predicted (and exact) distances on a user's mesh or point cloud, as files or pictures."""
from __future__ import annotations

from pathlib import Path

import click

from .inputs import (_click_errors, _embed_cloud, _load_cloud, _load_mesh, _load_model, _model_and_meshes,
                     _model_config, _output_suffix)
from .options import (DEVICE_OPTION, FIELDS_OPTION, MODEL_ARG, PRECISION_OPTION, PREPARE_OPTION, PRETRAINED_HELP,
                      SIZE_OPTION, UP_OPTION, check_fields, either, old_name)


@click.command(context_settings={"max_content_width": 100})
@click.argument("files", **MODEL_ARG)
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("--source", type=int, help="Source vertex index (the file's own numbering).")
@click.option("--pairs-file", "pairs_csv", type=click.Path(exists=True, dir_okay=False),
              help="Answer the pairs of this CSV (two integer columns i,j; a header is allowed).")
@click.option("--points-file", "points_file", type=click.Path(exists=True, dir_okay=False),
              help="Distances between points anywhere on the surface: xyz in a .npy array (P, 3) or a CSV x,y,z "
                   "(a header is allowed), in the mesh's units; each is moved to the closest surface point.")
@old_name("--pairs", "--pairs-file", "old_pairs", type=click.Path(exists=True, dir_okay=False))
@old_name("--points", "--points-file", "old_points", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="With --source: field.npy (per file vertex), field.ply (colored mesh) or field.png "
                   "(rendered). With --pairs-file: a CSV i,j,distance (default: stdout). With --points-file: "
                   "the (P, P) matrix as .npy or .csv (default: stdout).")
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
@FIELDS_OPTION
@DEVICE_OPTION
@PRECISION_OPTION
@UP_OPTION
@SIZE_OPTION
def query(files, pretrained, source, pairs_csv, points_file, old_pairs, old_points, output, exact, cloud_mesh, path_to,
          prepare, landmark_fields, device, precision, up, size):
    """Distances on MESH (OBJ/OFF/PLY/STL/GLB, any units) predicted by CHECKPOINT or --pretrained: geodesic,
    or biharmonic with a biharmonic model (--pretrained biharmonic).

    \b
    Examples:
      gegnn query --pretrained bunny.obj --source 0 -o field.png
      gegnn query --pretrained bunny.obj --source 0 --exact -o compare.png
      gegnn query --pretrained bunny.obj --source 0 --fields paths --exact -o compare.png
      gegnn query --pretrained bunny.obj --source 0 --path 1234 --exact -o path.png
      gegnn query --pretrained paper bunny.obj --source 0 --exact -o compare.png
      gegnn query --pretrained biharmonic bunny.obj --source 0 --exact -o compare.png
      gegnn query runs/a/best.safetensors bunny.obj --pairs-file pairs.csv -o distances.csv
      gegnn query --pretrained bunny.obj --points-file clicks.csv --exact -o distances.npy
      gegnn query --pretrained points scan.xyz --pairs-file pairs.csv -o distances.csv

    Distances are in the mesh's units. The PLY and PNG show the mesh the network ran on (with
    --prepare, the remeshed one); .npy and CSV outputs use the file's vertex numbering. A point-cloud
    model (--pretrained points) reads a cloud (.xyz .txt .pts .csv .npy .ply) instead of MESH and answers
    --source or --pairs-file in the file's point numbering. (--pairs and --points, the old names of
    --pairs-file and --points-file, work until 0.4.0.)
    """
    import numpy as np

    from ..queries.files import read_pairs

    pairs_csv = either(pairs_csv, old_pairs, "--pairs-file", "--pairs")
    points_file = either(points_file, old_points, "--points-file", "--points")
    model_spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    config = _model_config(model_spec, pretrained)
    check_fields(config, landmark_fields)
    if config.points:
        if (source is None) == (pairs_csv is None) or points_file or path_to is not None or prepare:
            raise click.UsageError("a point-cloud model answers --source I (with --exact --mesh MESH to compare) "
                                   "or --pairs-file FILE")
    elif cloud_mesh:
        raise click.UsageError("--mesh goes with a point-cloud model (the file is the mesh here)")
    elif sum(x is not None for x in (source, pairs_csv, points_file)) != 1:
        raise click.UsageError("give one of --source, --pairs-file or --points-file")
    if exact and pairs_csv:
        takes = "--source" if config.points else "--source or --points-file"
        raise click.UsageError(f"--exact goes with {takes} (it compares whole fields)")
    if path_to is not None and source is None:
        raise click.UsageError("--path goes with --source (the path runs from the source)")
    suffix = _output_suffix(output, (".csv",) if pairs_csv else (".npy", ".csv") if points_file else
                            (".npy", ".ply", ".png"))
    if config.points and pairs_csv:
        return _query_cloud_pairs(model_spec, pretrained, mesh_path, pairs_csv, output, device, precision)
    if config.points:
        return _query_cloud(model_spec, pretrained, mesh_path, source, output, suffix, exact, cloud_mesh, device,
                            precision, up, size)
    if points_file:
        return _query_points(model_spec, pretrained, mesh_path, points_file, output, suffix, exact, prepare, device,
                             precision, landmark_fields)
    qm = _load_mesh(mesh_path, prepare)
    with _click_errors(mesh_path):
        pairs = read_pairs(pairs_csv) if pairs_csv else np.array([[source, source if path_to is None else path_to]])
        net_pairs = qm.vertices(pairs)
    src = int(net_pairs[0, 0])
    kind = config.distance
    exact_d = err = None
    if exact and source is not None:  # before the network: the exact solver runs in a forked child
        from ..fields.exact import exact_field
        with _click_errors(f"{mesh_path}: --exact"):
            exact_d = exact_field(qm.mesh, src, kind)

    emb = _load_model(model_spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces, precision=precision,
                                                            fields=landmark_fields)
    if pairs_csv:
        return _write_pairs(pairs, emb.distance(net_pairs[:, 0], net_pairs[:, 1]), output)

    from ..fields.exact import source_part
    from ..queries.files import resolution_note

    name = Path(mesh_path).name
    note = None if prepare else resolution_note(len(qm.mesh.vertices), config)
    if note:
        click.echo(f"{name}: note: {note}")
    on, n_parts = source_part(qm.mesh, src)
    # Other parts than the source's have no distance from it: NaN (grey in pictures).
    field = np.where(on, emb.field(src), np.nan)
    by = f" (landmark fields by {landmark_fields})" if landmark_fields else ""
    click.echo(f"{name}: {len(qm.mesh.vertices)} vertices; {kind} distance from {source}{by}: "
               f"min {np.nanmin(field):.4g} max {np.nanmax(field):.4g}")
    if n_parts > 1:
        click.echo(f"{name}: {n_parts} separate parts; source {source} is on a part of {int(on.sum())} vertices; "
                   f"the other parts have no {kind} distance from it (NaN in .npy, grey in pictures, "
                   "left out of the error)")
    title = f"{name}, source {source}"
    if exact_d is not None:
        from ..queries.files import relative_errors
        exact_d = np.where(on, exact_d, np.nan)
        err = relative_errors(field, exact_d, qm.scale, src)
        _report_errors(err, "", " on the source's part" if n_parts > 1 else "")
        title += f": MRE {100 * np.nanmean(err):.2f}%"
    lines = []
    if path_to is not None:
        lines = _paths(emb, qm, src, int(net_pairs[0, 1]), path_to, exact_d, name)
    _save_field(output, suffix, field, exact_d, err, src, qm.mesh.vertices, qm.mesh.faces, qm.to_file(field),
                title, size, up, lines=lines)


def _query_points(model_spec, pretrained, mesh_path, points_file, output, suffix, exact, prepare, device,
                  precision, landmark_fields):
    """``gegnn query --points-file``: the (P, P) matrix between surface points, optionally against exact distances
    between the same points inserted as vertices."""
    import numpy as np

    from geodata.surface_points import insert_points, locate_points

    from ..fields.exact import exact_fields
    from ..queries.files import read_points, relative_errors

    qm = _load_mesh(mesh_path, prepare)
    name = Path(mesh_path).name
    with _click_errors("", OSError):
        points = read_points(points_file)
    located = locate_points(qm.mesh, points)
    click.echo(f"{name}: {len(points)} points, at most {located.offset.max():.3g} from the surface (each moved to "
               "the closest surface point)")
    kind = _model_config(model_spec, pretrained).distance
    exact_d = None
    if exact:  # before the network: the exact solver runs in a forked child
        refined, vertex = insert_points(qm.mesh, located.face, located.bary)
        with _click_errors(f"{name}: --exact"):
            exact_d = exact_fields(refined, vertex, kind)[:, vertex]
    emb = _load_model(model_spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces, precision=precision,
                                                            fields=landmark_fields)
    d = emb.surface_distance(located.face[:, None], located.bary[:, None], located.face[None], located.bary[None])
    if exact_d is not None:
        errors = np.concatenate([relative_errors(d[p], exact_d[p], qm.scale, p) for p in range(len(d))])
        _report_errors(errors, " (points inserted as vertices)")
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


def _write_pairs(pairs, distances, output) -> None:
    """A CSV i,j,distance of the pairs in the file's numbering, to ``output`` or stdout."""
    lines = ["i,j,distance"] + [f"{i},{j},{x:.6g}" for (i, j), x in zip(pairs.tolist(), distances.tolist())]
    if output:
        Path(output).write_text("\n".join(lines) + "\n")
        click.echo(f"{len(pairs)} distances written to {output}")
    else:
        click.echo("\n".join(lines))


def _query_cloud_pairs(model_spec, pretrained, cloud_path, pairs_csv, output, device, precision):
    """``gegnn query --pairs-file`` with a point-cloud model: the distance of every pair of the file's points, NaN
    where a point is a far outlier or the two lie on different parts of the neighbour graph."""
    import numpy as np

    from ..queries.files import read_pairs

    name = Path(cloud_path).name
    with _click_errors():
        pairs = read_pairs(pairs_csv)
    cloud, keep = _load_cloud(cloud_path, [], err=output is None)  # notes apart from a CSV on stdout
    n = len(cloud.points)
    bad = (pairs < 0) | (pairs >= n)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        raise click.ClickException(f"{pairs_csv}: pair {row + 1}: point {pairs[bad][0]} out of range: {name} has "
                                   f"{n} points")
    emb = _embed_cloud(_load_model(model_spec, pretrained, device, clouds=True), cloud, keep, cloud_path, precision)
    kept = np.isin(pairs, keep)
    local = np.where(kept, np.searchsorted(keep, pairs), 0)
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

    from ..queries.files import relative_errors

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
        from ..fields.exact import exact_at_points
        from ..queries.files import load_query_mesh
        with _click_errors(f"{mesh_path}: --exact"):
            qm = load_query_mesh(mesh_path)
            exact_d, offset = exact_at_points(qm.mesh, points, source, model.config.distance)
        err = relative_errors(field, exact_d, qm.scale, source)
        _report_errors(err, f" on {Path(mesh_path).name}", f"; the points lie within {offset.max():.3g} of the surface")
    lit = cloud.normals
    if suffix == ".png" and lit is None:
        from ..fields.pointcloud import unoriented_normals
        lit = unoriented_normals(points)
    _save_field(output, suffix, field, exact_d, err, source, points, None, field, f"{name}, point {source}", size, up,
                normals=lit)


def _report_errors(err, where: str, after: str = "") -> None:
    """The line reporting relative errors against exact distances (NaN left out)."""
    import numpy as np

    click.echo(f"mean relative error vs exact{where}: {100 * np.nanmean(err):.2f}% (median "
               f"{100 * np.nanmedian(err):.2f}%, max {100 * np.nanmax(err):.1f}%){after}")


def _save_field(output, suffix, field, exact_d, err, source: int, vertices, faces, saved, title: str, size, up,
                **row) -> None:
    """Write a query's field: ``saved`` (the field in the file's numbering) as .npy; a .ply of the vertices
    coloured by it (a mesh, or points where ``faces`` is None); or a .png of its panels (``row``: a Row's
    lines or normals), all on one scale: the exact field's where there is one."""
    import numpy as np

    top = float(np.nanmax(exact_d if exact_d is not None else field))
    if suffix == ".npy":
        np.save(output, saved)
    elif suffix == ".ply":
        import trimesh
        colors = _field_colors(field, top)
        (trimesh.PointCloud(vertices, colors=colors) if faces is None else
         trimesh.Trimesh(vertices, faces, vertex_colors=colors, process=False)).export(output)
    elif suffix == ".png":
        from ..pictures.render import Row, save_panels
        save_panels(output, [Row(vertices, faces, source, _field_panels(field, exact_d, err, source, top), **row)],
                    suptitle=title, size=size, up=up)
    if output:
        click.echo(f"written {output}")


def _field_colors(field, top: float):
    """RGBA uint8 (N, 4) of a per-vertex field for a coloured PLY: viridis over [0, top], grey where NaN."""
    import matplotlib
    import numpy as np

    from ..pictures.render import UNREACHABLE
    colors = matplotlib.colormaps["viridis"](np.nan_to_num(field / max(top, 1e-30)))
    colors[np.isnan(field)] = UNREACHABLE
    return (colors * 255).astype(np.uint8)


def _field_panels(field, exact_d, err, source: int, top: float) -> list:
    """The panels of a query's picture: predicted, and with an exact field, exact and the relative error
    (0 at the source; NaN, grey, where there is no distance)."""
    from ..pictures.render import Panel

    panels = [Panel(field, "predicted", vmin=0, vmax=top)]
    if exact_d is not None:
        shown = err.copy()
        shown[source] = 0.0
        panels += [Panel(exact_d, "exact", vmin=0, vmax=top),
                   Panel(shown, "relative error", "magma", "|pred - exact| / exact", 0, 0.1, isolines=0)]
    return panels


def _paths(emb, qm, src, dst, path_to, exact_d, name) -> list:
    """Trace the predicted path (and with the exact field, the edge-flip one); report; lines to draw."""
    with _click_errors(f"{name}: --path {path_to}"):
        path = emb.path(src, dst)
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
