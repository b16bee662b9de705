"""The model, meshes and point clouds a command on a user's files reads, and its output's kind."""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import click

from ..model import PRETRAINED


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


@contextmanager
def _click_errors(where: str = "", *errors):
    """The block's failures on a user's file (MeshError, ValueError and ``errors``) as click's one-line error
    "WHERE: message" (the message alone without WHERE; a MeshError by its reason)."""
    from geodata.mesh import MeshError

    try:
        yield
    except (MeshError, ValueError, *errors) as exc:
        text = exc.reason if isinstance(exc, MeshError) else str(exc)
        raise click.ClickException(f"{where}: {text}" if where else text) from None


def _model_config(spec, pretrained):
    """The config of a model, from its file's metadata alone (no weights read, no torch thread started)."""
    from ..checkpoint import read_config
    from ..model import pretrained_file

    if not pretrained:
        return read_config(spec)
    with pretrained_file(spec) as path:
        return read_config(path)


def _load_model(spec, pretrained, device, clouds: bool = False):
    """The model, on its device; a point-cloud model only where ``clouds`` (the command takes clouds)."""
    from ..model import GeGnn
    from ..training.devices import pick_device

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

    from ..queries.files import load_query_mesh

    hint = ("point clouds are answered by a point-cloud model: gegnn query --pretrained points "
            f"{Path(path).name} --source I")
    if Path(path).suffix.lower() in set(CLOUD_SUFFIXES) - {".ply"}:
        raise click.ClickException(f"{path}: a point-cloud file, not a mesh ({hint})")
    try:
        return load_query_mesh(path, prepare=prepare)
    except (MeshError, ValueError) as exc:
        cloud = isinstance(exc, MeshError) and exc.reason.startswith("point cloud")
        raise click.ClickException(f"{path}: {exc}" + (f" ({hint})" if cloud else "")) from None


def _load_cloud(cloud_path, sources, err: bool = False):
    """A cloud file and its points that are not far outliers (sorted indices), after checking that every
    source is one of them; its notes and the outliers' count echoed (to stderr with ``err``)."""
    import numpy as np

    from geodata.stages.cloud import load_cloud_file, outliers

    name = Path(cloud_path).name
    with _click_errors(cloud_path):
        cloud = load_cloud_file(cloud_path)
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


WARN_SHARE = 0.005  # ambiguous points from which the line saying so is a warning (fewer: a note)
SCATTER_NOTE = 0.2  # spacings: from this scatter on, a cloud without normals is told that close sheets may go unseen
WALLS_NOTE = 0.05   # close walls that the normals tell apart, from which a cloud is told where they can still fail


def _embed_cloud(model, cloud, keep, cloud_path, precision):
    """The model's embedding of a cloud file's kept points (with the file's normals, if it has them); a cloud
    the model cannot take fails naming the file. Points where two sheets of the surface come closer than
    the spacing and the sides cannot be told apart are named in a warning (stderr), as is a scatter that
    could hide such sheets, and a cloud with many close sheets that its normals tell apart in a note."""
    with _click_errors(cloud_path):
        emb = model.embed(cloud.points[keep], normals=None if cloud.normals is None else cloud.normals[keep],
                          precision=precision)
    name = Path(cloud_path).name
    flagged = 0 if emb.ambiguous is None else int(emb.ambiguous.sum())
    if flagged:
        why = ("no normals: give the points' normals (x y z nx ny nz, or a PLY's nx ny nz) to tell the sides apart"
               if cloud.normals is None else "the file's normals do not face away from each other there")
        kind = "warning" if flagged >= WARN_SHARE * len(keep) else "note"
        click.echo(f"{name}: {kind}: {flagged} of {len(keep)} points lie where two sheets of the surface come "
                   f"closer than the points' spacing and the sides cannot be told apart ({why}): distances from "
                   "them may run through the wall, short by the way round it (Embedding.ambiguous)", err=True)
    apart = 0 if emb.walls is None else int((emb.walls & ~emb.ambiguous).sum())
    if cloud.normals is not None and apart >= WALLS_NOTE * len(keep):
        click.echo(f"{name}: note: {apart} of {len(keep)} points lie where two sheets of the surface come closer "
                   "than the points' spacing and the file's normals tell the sides apart; where such a wall also "
                   "ends or creases within a spacing (a rim, a slit) distances can still cross it, short by the way "
                   "round (Embedding.walls)", err=True)
    if not flagged and cloud.normals is None and emb.scatter is not None and emb.scatter > SCATTER_NOTE:
        click.echo(f"{name}: note: the points scatter {emb.scatter:.2f} spacings about a smooth surface (median): "
                   "two sheets of it closer than a few spacings would not be told apart, nor seen; normals (nx ny "
                   "nz) would tell them apart", err=True)
    return emb
