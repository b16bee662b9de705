"""Mesh graphs as plain tensors: directed edges, disjoint unions of meshes, random rotations.

Everything here is layout only (no learning): the layers in :mod:`gegnn.nn` consume these tensors.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from functools import partial

import numpy as np
import torch
from torch import Tensor

__all__ = ["Graph", "Tensors", "directed_edges", "disjoint_union", "mesh_graph", "random_rotation"]


class Tensors:
    """A dataclass of tensors, lists of them and such dataclasses (other values are kept as they are):
    ``apply(fn)`` maps every tensor; ``to`` and ``pin_memory`` (a page-locked copy, so that ``to(cuda)`` is
    an asynchronous copy: the DataLoader's ``pin_memory`` calls it in its pinning thread) through it."""

    def apply(self, fn: Callable[[Tensor], Tensor]):
        """A copy with ``fn`` applied to every tensor."""
        return type(self)(*(_apply(fn, getattr(self, f.name)) for f in fields(self)))

    def to(self, device):
        return self.apply(partial(Tensor.to, device=device, non_blocking=True))

    def pin_memory(self):
        return self.apply(Tensor.pin_memory)


def _apply(fn: Callable[[Tensor], Tensor], value):
    if isinstance(value, Tensor):
        return fn(value)
    if isinstance(value, Tensors):
        return value.apply(fn)
    return [_apply(fn, v) for v in value] if isinstance(value, list) else value


@dataclass
class Graph(Tensors):
    """One level of a (batched) mesh graph.

    Attributes:
        pos: vertex coordinates, float (N, 3).
        normal: vertex normals, float (N, 3) (cluster means at coarse levels, so not exactly unit).
        edge_index: directed edges, long (2, E); row 0 is the receiving vertex ``i``, row 1 the
            neighbour ``j``. Every undirected mesh edge appears in both directions.
        batch: index of the mesh each vertex belongs to, long (N,), non-decreasing.
    """

    pos: Tensor
    normal: Tensor
    edge_index: Tensor
    batch: Tensor

    @property
    def num_nodes(self) -> int:
        return self.pos.shape[0]


def mesh_graph(vertices, normals, edges) -> Graph:
    """A single mesh (normalized vertices, unit normals, undirected edges (E, 2)) as a Graph."""
    pos = torch.as_tensor(np.asarray(vertices, dtype=np.float32))
    return Graph(pos=pos, normal=torch.as_tensor(np.asarray(normals, dtype=np.float32)),
                 edge_index=directed_edges(torch.as_tensor(np.asarray(edges, dtype=np.int64))),
                 batch=torch.zeros(len(pos), dtype=torch.long))


def directed_edges(edges: Tensor) -> Tensor:
    """Undirected edges (E, 2) -> edge_index (2, 2E) with both directions."""
    e = edges.long()
    return torch.cat([e, e.flip(1)], dim=0).t().contiguous()


def disjoint_union(graphs: list[Graph]) -> tuple[Graph, Tensor]:
    """Concatenate graphs into one graph without edges between them.

    Returns the union and the vertex offset of each input graph (long (B,)).
    """
    sizes = torch.tensor([g.num_nodes for g in graphs])
    offsets = torch.cumsum(sizes, 0) - sizes
    union = Graph(
        pos=torch.cat([g.pos for g in graphs]),
        normal=torch.cat([g.normal for g in graphs]),
        edge_index=torch.cat([g.edge_index + o for g, o in zip(graphs, offsets.tolist())], dim=1),
        batch=torch.repeat_interleave(torch.arange(len(graphs)), sizes),
    )
    return union, offsets


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (3, 3) (QR of a Gaussian matrix, sign-fixed, det +1)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q
