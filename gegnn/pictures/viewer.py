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
from .render import POINT_DISC, UP_AXES, default_view, point_spacing, up_axis

__all__ = ["view_page", "decoder_spec"]


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
              file_index: np.ndarray | None = None, up: str | None = None, dtype: str = "float32",
              normals: np.ndarray | None = None) -> str:
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
        dtype: of the codes in the page: "float32", or "float16" for half the size (distances then move
            by ~1e-3 relative).
        normals: a cloud's normals (N, 3), for the light only (either sign); estimated where None (the
            least-variance direction of each point's 8 nearest).
    """
    import matplotlib

    vertices, faces = emb.vertices, emb.faces
    cloud = faces is None and emb.part is not None
    if vertices is None or (faces is None and not cloud):
        raise ValueError("the embedding has no mesh or cloud: make it with GeGnn.embed")
    codes = emb.features.float().cpu().numpy()
    if dtype == "float16" and np.abs(codes).max() > np.finfo(np.float16).max:
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
    assets = files("gegnn.pictures") / "assets"
    return Template((assets / "viewer.html").read_text(encoding="utf-8")).substitute(
        title=html.escape(title), meta=html.escape(meta), item="point" if cloud else "vertex",
        data=json.dumps(data, separators=(",", ":")).replace("</", "<\\/"),
        script=(assets / "viewer.js").read_text(encoding="utf-8"))
