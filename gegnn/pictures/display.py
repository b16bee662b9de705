"""The surface ``gegnn view`` draws of a mesh too large for a page: the same surface with fewer vertices
(quadric edge collapse, fast-simplification), each display vertex put on the embedded mesh's surface and
given the full embedding's code at that point (:meth:`gegnn.queries.embedding.Embedding.at_points`). A
click on the display decodes the full embedding's distances between surface points, as
:meth:`~gegnn.queries.embedding.Embedding.surface_distance` gives them, at the display's vertices only.

The page's size and a click's decode grow with the display's vertices, not the mesh's: at K = 256 a
vertex carries 324 codes (864 bytes in float16, base64) and the page's decoder takes 6-14 microseconds a
vertex in headless Chromium on the 2-core development CPU. A mesh of ~1M vertices drawn with 100,000: a
page of 88 MiB, a click decoded in 0.6-1.4 s (docs/queries.md#looking-at-the-fields-gegnn-view, with why
the collapse and not the embedding proxy's remesh: 6x faster, the same median error of the field drawn).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from geodata.surface_points import SurfacePoints

if TYPE_CHECKING:
    from ..queries.embedding import Embedding

__all__ = ["DISPLAY_VERTICES", "Display", "display_surface", "at_display"]

DISPLAY_VERTICES = 100_000  # meshes with more vertices are drawn decimated to this many: ~1 s a click, 88 MiB


class Display(NamedTuple):
    """A decimated display surface: ``embedding`` (its vertices, faces and codes), ``place`` (each display
    vertex on the embedded mesh: face and barycentric coordinates), ``nearest`` (the embedded mesh's
    vertex nearest each display vertex, its face's corner of largest weight) and ``sources`` (the display
    vertex of each source asked for: put exactly on it)."""

    embedding: "Embedding"
    place: SurfacePoints
    nearest: np.ndarray
    sources: list


def display_surface(emb, vertices: int = DISPLAY_VERTICES, sources=()) -> Display:
    """``emb``'s mesh decimated to about ``vertices`` vertices (exactly that many for a closed manifold mesh),
    each on the surface with the full embedding's code there. Each of ``sources`` (vertices of the
    embedded mesh) moves the display vertex nearest it onto it, so its field is the full embedding's."""
    import fast_simplification
    from scipy.spatial import cKDTree

    full_v, full_f = emb.vertices, emb.faces
    collapses = len(full_v) - vertices  # each removes a vertex and two faces (one on a boundary)
    v, f = fast_simplification.simplify(full_v, full_f.astype(np.int32),
                                        target_count=max(4, len(full_f) - 2 * collapses))
    used, f = np.unique(np.asarray(f, dtype=np.int64), return_inverse=True)
    v, f = np.array(v, dtype=np.float64)[used], f.reshape(-1, 3)
    taken, display_sources = {}, []
    tree = cKDTree(v) if len(sources) else None
    for s in map(int, sources):
        if s not in taken:  # the nearest display vertex no other source took: one of the len(taken) + 1 nearest
            _, near = tree.query(full_v[s], k=min(len(v), len(taken) + 1))
            free = [int(j) for j in np.atleast_1d(near) if int(j) not in set(taken.values())]
            if not free:
                raise ValueError(f"more sources than the {len(v)} display vertices")
            taken[s] = free[0]
            v[taken[s]] = full_v[s]
        display_sources.append(taken[s])
    place = emb.locate(v)
    corners = full_f[place.face]
    on_surface = np.einsum("pk,pkd->pd", place.bary, full_v[corners])
    nearest = corners[np.arange(len(corners)), place.bary.argmax(axis=1)]
    return Display(emb.at_points(place.face, place.bary, vertices=on_surface, faces=f), place, nearest,
                   display_sources)


def at_display(display: Display, full_faces: np.ndarray, field: np.ndarray) -> np.ndarray:
    """A per-vertex field of the embedded mesh (N,) at the display's vertices: linear in each face."""
    corners = full_faces[display.place.face]
    return np.einsum("pk,pk->p", display.place.bary, np.asarray(field)[corners])
