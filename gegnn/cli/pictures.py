"""``gegnn view`` and ``gegnn texture``: an interactive page of the distance fields, and a texture laid
out by the learned log map."""
from __future__ import annotations

from pathlib import Path

import click

from ..model import PRETRAINED
from ..pictures.display import DISPLAY_VERTICES
from .inputs import (_click_errors, _embed_cloud, _load_cloud, _load_mesh, _load_model, _model_and_meshes,
                     _model_config, _output_suffix)
from .options import (DEVICE_OPTION, FIELDS_OPTION, MODEL_ARG, PRECISION_OPTION, PREPARE_OPTION, PRETRAINED_HELP,
                      SIZE_OPTION, UP_OPTION, check_fields)


@click.command(context_settings={"max_content_width": 100})
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
@click.option("--dtype", type=click.Choice(["auto", "float32", "float16"]), default="auto", show_default=True,
              help="Codes in the page (float16: half the size; distances move by ~1e-3 relative; auto: float32 "
                   "up to 64 MiB of codes, ~51k vertices at K = 256, float16 above).")
@click.option("--display-vertices", type=click.IntRange(min=0), default=DISPLAY_VERTICES, show_default=True,
              help="A mesh with more vertices is drawn decimated to this many, a cloud with more points as a "
                   "random sample of this many (0: never).")
@PREPARE_OPTION
@FIELDS_OPTION
@DEVICE_OPTION
@PRECISION_OPTION
@UP_OPTION
def view(files, pretrained, output, sources, exact, cloud_mesh, dtype, display_vertices, prepare, landmark_fields,
         device, precision, up):
    """An interactive page of MESH, or of a point cloud with a point-cloud model: coloured by the distance
    field of a vertex (a point), with isolines; click any vertex and the page decodes its field at once
    from the codes of one forward pass, with the model's own decoder (no server, no network: one
    self-contained HTML file for any browser or notebook).

    \b
    Examples:
      gegnn view --pretrained bunny.obj -o bunny.html
      gegnn view --pretrained bunny.obj --source 0 --source 1234 --exact -o compare.html
      gegnn view --pretrained bunny.obj --fields paths --source 0 --exact -o paths.html
      gegnn view --pretrained biharmonic bunny.obj -o biharmonic.html
      gegnn view runs/a/best.safetensors part.obj --dtype float16 -o part.html
      gegnn view --pretrained points scan.xyz -o scan.html
      gegnn view --pretrained points scan.xyz --source 0 --exact --mesh scan.obj -o compare.html

    The page holds the mesh and the codes (N x 324 values for the default landmark model, K = 256: 8.2 MiB
    at 4,762 vertices, half with --dtype float16). A mesh of more than --display-vertices is drawn
    decimated (quadric edge collapse) to that many, each display vertex with the full embedding's
    distances at its point and named by the mesh vertex nearest it, and the page says how much: a mesh
    of 1M vertices is drawn at 10%, in a page of 88 MiB whose clicks decode in about 1 s. With --prepare
    it shows the remeshed mesh, numbered as such. A cloud (.xyz .txt .pts .csv .npy, or a PLY without
    faces) is drawn as discs of about its points' spacing, numbered as in its file (a random sample of
    --display-vertices points if it has more); points far from all others are left out.
    """
    import numpy as np

    from ..pictures.viewer import view_page

    spec, (mesh_path,) = _model_and_meshes(files, pretrained)
    _output_suffix(output, (".html", ".htm"))
    config = _model_config(spec, pretrained)
    check_fields(config, landmark_fields)
    sources = sources or (0,)
    if config.points:
        if prepare:
            raise click.UsageError("--prepare remeshes a mesh: a point cloud is shown as it is")
        return _view_cloud(spec, pretrained, mesh_path, sources, exact, cloud_mesh, output, dtype, display_vertices,
                           device, precision, up)
    if cloud_mesh:
        raise click.UsageError("--mesh goes with a point-cloud model (the file is the mesh here)")
    qm = _load_mesh(mesh_path, prepare)
    with _click_errors(mesh_path):
        net_sources = [int(qm.vertices(s)) for s in sources]
    fields = {}
    if exact:
        from ..fields.exact import exact_fields
        with _click_errors(f"{mesh_path}: --exact"):
            fields = dict(zip(net_sources, exact_fields(qm.mesh, np.array(net_sources), config.distance)))
    emb = _load_model(spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces, precision=precision,
                                                      fields=landmark_fields)
    file_index = None
    if not prepare:  # the smallest file vertex of each mesh vertex
        used = np.flatnonzero(qm.to_mesh >= 0)[::-1]
        file_index = np.full(len(qm.mesh.vertices), -1, dtype=np.int64)
        file_index[qm.to_mesh[used]] = used
    name = Path(mesh_path).name
    model = f"--pretrained {spec or next(iter(PRETRAINED))}" if pretrained else Path(spec).name
    page = view_page(emb, title=f"{name}: {config.distance} distance predicted by GeGnn",
                     meta=f"{len(qm.mesh.vertices):,} vertices, {len(qm.mesh.faces):,} faces"
                          + (" (remeshed by --prepare)" if prepare else "") + f"; model {model}"
                          + (f", landmark fields by {landmark_fields}" if landmark_fields else "") + "; distances in the "
                          "mesh's units", sources=net_sources, exact=fields, file_index=file_index, up=up, dtype=dtype,
                     display_vertices=display_vertices)
    Path(output).write_text(page, encoding="utf-8")
    shown = ("" if len(qm.mesh.vertices) <= (display_vertices or np.inf)
             else f", drawn decimated to about {display_vertices:,}")
    click.echo(f"{name}: {len(qm.mesh.vertices):,} vertices{shown}; written {output} ({len(page) / 2 ** 20:.1f} MB): "
               "open it in a browser")


def _view_cloud(model_spec, pretrained, cloud_path, sources, exact, mesh_path, output, dtype, display_vertices,
                device, precision, up):
    """``gegnn view`` with a point-cloud model: the page of the cloud's points (outliers left out)."""
    import numpy as np

    from ..pictures.viewer import view_page

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
        from ..fields.exact import exact_at_points
        from ..queries.files import load_query_mesh
        with _click_errors(f"{mesh_path}: --exact"):
            qm = load_query_mesh(mesh_path)
            fields = {s: exact_at_points(qm.mesh, points, s, model.config.distance)[0] for s in local}
    emb = _embed_cloud(model, cloud, keep, cloud_path, precision)
    label = f"--pretrained {model_spec}" if pretrained else Path(model_spec).name
    page = view_page(emb, title=f"{name}: {model.config.distance} distance predicted by GeGnn",
                     meta=f"{len(points):,} points of {len(cloud.points):,}"
                          f"{'' if normals is None else ' with normals'}; {int(emb.part.max()) + 1} part(s) in the "
                          f"{model.config.points}-neighbour graph; model {label}; distances in the cloud's units",
                     sources=local, exact=fields, file_index=keep, up=up, dtype=dtype, normals=normals,
                     display_vertices=display_vertices)
    Path(output).write_text(page, encoding="utf-8")
    shown = "" if len(points) <= (display_vertices or np.inf) else f", drawn as a sample of {display_vertices:,}"
    click.echo(f"{name}: {len(points):,} points{shown}; written {output} ({len(page) / 2 ** 20:.1f} MB): open it in "
               "a browser")


@click.command(context_settings={"max_content_width": 100})
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
    with _click_errors(mesh_path):
        c = int(qm.vertices(center))
    radius = radius or 0.4 * qm.scale
    emb = _load_model(spec, pretrained, device).embed(qm.mesh.vertices, qm.mesh.faces)
    lm = emb.log_map(c, radius)
    uv = np.full((len(qm.mesh.vertices), 2), np.nan)
    uv[lm.vertices] = lm.uv
    name = Path(mesh_path).name
    click.echo(f"{name}: {len(lm.vertices)} vertices within {radius:.4g} of vertex {center}")
    panels = [("log map from distance queries", uv)]
    if compare:
        from ..queries.logmap import vector_heat_log_map
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
        from ..pictures.render import Panel, Row, save_panels
        save_panels(output, [Row(qm.mesh.vertices, qm.mesh.faces, c, [
            Panel(f, title, vmax=2 * radius / squares) for title, f in panels])],
            suptitle=f"{name}, center {center}, radius {radius:.3g}", size=size, up=up)
    click.echo(f"written {output}")
