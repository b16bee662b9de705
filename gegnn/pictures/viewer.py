"""One self-contained HTML page of a mesh, or of a point cloud, and its learned distance fields (``gegnn view``).

The page carries the mesh (or the cloud: its points drawn as discs of about their spacing, lit by their
normals), the per-vertex codes of one forward pass (:class:`gegnn.queries.embedding.Embedding`)
and the decoder's weights, and decodes the field of any clicked vertex itself, with the same formulas as
:mod:`gegnn.decoders` (``assets/viewer.js``): the constant-time query, one per vertex, in the browser. It
needs no network and no server (the script is inlined), so it opens from a laptop's disk, from a copy of a
file made on a cluster, or in a notebook (``IPython.display.IFrame("view.html", 900, 700)``).
"""
from __future__ import annotations

import base64
import html
import json
from importlib.resources import files
from string import Template

import numpy as np
from torch import nn

from geodata.mesh import Mesh, vertex_components

from ..decoders import MAX_LOG_RATIO, DistanceDecoder, LandmarkDecoder, SpectralDecoder
from ..fields.spectral import S_MAX
from ..metrics import METRIC_EPS
from .display import DISPLAY_VERTICES, at_display, display_surface
from .render import POINT_DISC, UP_AXES, default_view, point_spacing, up_axis

__all__ = ["view_page", "decoder_spec", "FLOAT32_CODES"]

FLOAT32_CODES = 64 * 2 ** 20  # dtype "auto": float32 codes up to this many bytes (a page of ~88 MiB), float16 above


def _blob(values, dtype: str) -> dict:
    """An array as {dtype, base64 of its little-endian bytes}."""
    data = np.ascontiguousarray(values, dtype=np.dtype(dtype).newbyteorder("<"))
    return {"dtype": dtype, "data": base64.b64encode(data.tobytes()).decode("ascii")}


def decoder_spec(decoder) -> dict:
    """What the page's decoder needs: the kind, its sizes and flags, and the MLP's layers (fp32)."""
    layers = [] if decoder.mlp is None else [
        {"weight": _blob(m.weight.detach().cpu(), "float32"), "bias": _blob(m.bias.detach().cpu(), "float32"),
         "n_in": m.in_features, "n_out": m.out_features} for m in decoder.mlp if isinstance(m, nn.Linear)]
    spec = {"layers": layers, "max_log_ratio": MAX_LOG_RATIO}
    if isinstance(decoder, LandmarkDecoder):
        return spec | {"kind": "landmark", "embed_dim": decoder.embed_dim, "k": decoder.k,
                       "embedding": decoder.embedding, "euclidean": decoder.euclidean, "output": decoder.kind}
    if isinstance(decoder, SpectralDecoder):
        return spec | {"kind": "spectral", "embed_dim": decoder.embed_dim, "m": decoder.m,
                       "embedding": decoder.embedding, "weyl": _blob(decoder.weyl.cpu(), "float32"), "s_max": S_MAX}
    if isinstance(decoder, DistanceDecoder):
        return spec | {"kind": "distance"}
    raise TypeError(f"no page decoder for {type(decoder).__name__}")


def view_page(emb, *, title: str, meta: str = "", sources=(0,), exact: dict | None = None,
              file_index: np.ndarray | None = None, up: str | None = None, dtype: str = "auto",
              normals: np.ndarray | None = None, display_vertices: int | None = DISPLAY_VERTICES) -> str:
    """The HTML page of ``emb`` (an :class:`~gegnn.queries.embedding.Embedding` with its mesh, or of a point cloud:
    its points and parts, as a point-cloud model's ``embed`` gives it).

    Args:
        title, meta: the page's heading and the line under it (plain text).
        sources: mesh vertices; the first one's field is shown when the page opens.
        exact: {mesh vertex: exact field (N,)} shown next to the prediction (predicted, exact, relative
            error) when that vertex is the source.
        file_index: the file's number of each mesh vertex, shown instead of the mesh's (None: the mesh's,
            e.g. for a remeshed file).
        up: the up axis (a key of UP_AXES; default :func:`gegnn.pictures.render.up_axis`); the camera turns about it.
        dtype: of the codes in the page: "float32", "float16" for half the size (distances then move
            by ~1e-3 relative), or "auto": float32 unless its codes pass ``FLOAT32_CODES`` bytes (51,781
            vertices at K = 256), float16 then (a decimated display of 100,000 vertices: 88 MiB).
        normals: a cloud's normals (N, 3), for the light only (either sign); estimated where None (the
            least-variance direction of each point's 8 nearest).
        display_vertices: a mesh with more vertices is drawn decimated to about this many
            (:mod:`gegnn.pictures.display`), each display vertex with the full embedding's code at its point
            and labelled by the mesh vertex nearest it; sources are display vertices put on theirs, exact
            fields interpolated there, and the line under the title says so. A cloud with more points is
            drawn as a random sample of this many (its sources among them). None or 0: never.
    """
    import matplotlib

    vertices, faces = emb.vertices, emb.faces
    cloud = faces is None and emb.part is not None
    if vertices is None or (faces is None and not cloud):
        raise ValueError("the embedding has no mesh or cloud: make it with GeGnn.embed")
    decimated = None
    if display_vertices and len(vertices) > display_vertices:
        if cloud:
            emb, meta, sources, exact, file_index, normals, decimated = _sampled(
                emb, meta, sources, exact or {}, file_index, normals, display_vertices)
        else:
            emb, meta, sources, exact, file_index, decimated = _decimated(emb, meta, sources, exact or {},
                                                                         file_index, display_vertices)
        vertices, faces = emb.vertices, emb.faces
    codes = emb.features.float().cpu().numpy()
    too_large = np.abs(codes).max(initial=0) > np.finfo(np.float16).max
    if dtype == "auto":
        dtype = "float16" if 4 * codes.size > FLOAT32_CODES and not too_large else "float32"
    if dtype == "float16" and too_large:
        raise ValueError("the codes exceed float16's range: use float32")
    up = up or up_axis(vertices, faces)
    u = np.asarray(UP_AXES[up])
    toward = default_view(vertices, faces, up).rotation[2]
    horizontal = toward - (toward @ u) * u
    if cloud and normals is None:
        from ..fields.pointcloud import unoriented_normals
        normals = unoriented_normals(vertices)
    data = {
        "vertices": _blob(vertices, "float32"),
        "faces": None if cloud else _blob(faces, "uint32"),
        "normals": _blob(normals, "float32") if cloud else None,
        "point_radius": POINT_DISC * point_spacing(vertices) if cloud else 0.0,
        "codes": _blob(codes, dtype),
        "code_width": codes.shape[1],
        "component": _blob(emb.part if cloud else vertex_components(Mesh(vertices, faces)), "int32"),
        "file_index": None if file_index is None else _blob(file_index, "int32"),
        "scale": emb.scale,
        "metric_offset": METRIC_EPS * emb.scale,
        "decoder": decoder_spec(emb.decoder),
        "sources": [int(s) for s in sources],
        "exact": {int(s): _blob(field, "float32") for s, field in (exact or {}).items()},
        "camera": {"up": u.tolist(), "horizontal": (horizontal / np.linalg.norm(horizontal)).tolist(),
                   "elevation": float(np.arcsin(np.clip(toward @ u, -1, 1))),
                   "center": ((vertices.min(axis=0) + vertices.max(axis=0)) / 2).tolist()},
        "luts": {name: _blob(matplotlib.colormaps[name](np.linspace(0, 1, 256))[:, :3], "float32")
                 for name in ("viridis", "magma")},
    }
    if decimated:  # absent from the page of a mesh or cloud drawn whole: its format is as before
        data["display"] = decimated
    assets = files("gegnn.pictures") / "assets"
    return Template((assets / "viewer.html").read_text(encoding="utf-8")).substitute(
        title=html.escape(title), meta=html.escape(meta), item="point" if cloud else "vertex",
        data=json.dumps(data, separators=(",", ":")).replace("</", "<\\/"),
        script=(assets / "viewer.js").read_text(encoding="utf-8"))


def _decimated(emb, meta, sources, exact, file_index, display_vertices):
    """``view_page``'s arguments for the display surface of ``emb``'s mesh (:func:`display_surface`): its
    embedding, the line under the title, sources, exact fields and labels on the display, and the page's
    ``display`` entry (the full mesh's size, and whose numbering labels the display's vertices)."""
    n, n_faces = len(emb.vertices), len(emb.faces)
    shown = display_surface(emb, display_vertices, [*sources, *exact])
    on_display = dict(zip([*sources, *exact], shown.sources))
    labels = shown.nearest if file_index is None else np.asarray(file_index)[shown.nearest]
    count = len(shown.embedding.vertices)
    meta = (f"{meta}; " if meta else "") + (
        f"drawn decimated: {count:,} of {n:,} vertices ({100 * count / n:.1f}%), each with the full embedding's "
        "distances at its point and named by the mesh vertex nearest it")
    exact = {on_display[s]: at_display(shown, emb.faces, field) for s, field in exact.items()}
    entry = {"vertices": n, "faces": n_faces, "numbering": "mesh" if file_index is None else "file"}
    return (shown.embedding, meta, [on_display[s] for s in sources], exact, labels, entry)


def _sampled(emb, meta, sources, exact, file_index, normals, count):
    """``view_page``'s arguments for a random sample of ``count`` of a cloud's points, the sources and the
    points of the exact fields among them (each keeps its own code: nothing to interpolate)."""
    import torch

    from ..queries.embedding import Embedding

    n = len(emb.vertices)
    forced = np.unique(np.asarray([*sources, *exact], dtype=np.int64))
    others = np.setdiff1d(np.arange(n), forced)
    rng = np.random.default_rng(0)
    keep = np.union1d(forced, rng.choice(others, max(count - len(forced), 0), replace=False))
    at = {int(s): int(np.searchsorted(keep, s)) for s in forced}
    meta = (f"{meta}; " if meta else "") + (
        f"drawn sampled: {len(keep):,} of {n:,} points ({100 * len(keep) / n:.1f}%, at random), each with its "
        "own distances")
    rows = torch.as_tensor(keep, device=emb.features.device)
    sample = Embedding(emb.features[rows], emb.decoder, emb.scale, emb.precision, vertices=emb.vertices[keep],
                       part=emb.part[keep])
    return (sample, meta, [at[int(s)] for s in sources], {at[int(s)]: np.asarray(f)[keep] for s, f in exact.items()},
            keep if file_index is None else np.asarray(file_index)[keep], None if normals is None else normals[keep],
            {"points": n})
