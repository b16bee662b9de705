"""GeoPool / GeoUnpool: clustering on a 6-D grid of coordinates and normals, and the graph hierarchy."""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from ..graph import Graph, Tensors
from .scatter import scatter_mean

__all__ = ["geo_clusters", "pool_graph", "pool_features", "unpool_features", "Hierarchy",
           "build_hierarchy", "GeoPool", "GeoUnpool"]


def geo_clusters(pos: Tensor, normal: Tensor, batch: Tensor, sigma_c: float,
                 sigma_n: float) -> tuple[Tensor, int]:
    """Cluster id of every vertex: its cell on the grid of cell size ``sigma_c`` in xyz and ``sigma_n``
    in normal space (``sigma_n = inf`` gives plain grid pooling); the mesh index is part of the key, so
    clusters never join vertices of different meshes.

    Ids are the ranks of the keys (``torch.unique`` sorts), so they do not depend on vertex order and the
    clusters of mesh ``b`` come before those of mesh ``b + 1``.

    Returns:
        cluster (long (N,)) and the number of clusters.
    """
    cells = [torch.floor(pos / sigma_c)]
    if math.isfinite(sigma_n):
        cells.append(torch.floor(normal / sigma_n))
    cells = torch.cat(cells, dim=1).long()
    cells = cells - cells.min(dim=0).values
    key = batch.clone()
    for column in cells.unbind(1):  # mixed-radix number with the batch index most significant
        key = key * (int(column.max()) + 1) + column
    unique, cluster = torch.unique(key, return_inverse=True)
    return cluster, unique.numel()


def pool_features(x: Tensor, cluster: Tensor, num_clusters: int) -> Tensor:
    """Mean of ``x`` (N, C) per cluster -> (num_clusters, C)."""
    return scatter_mean(x, cluster, num_clusters)


def unpool_features(x: Tensor, cluster: Tensor) -> Tensor:
    """Copy every cluster's feature back to its vertices: (num_clusters, C) -> (N, C)."""
    return x[cluster]


def pool_graph(graph: Graph, cluster: Tensor, num_clusters: int) -> Graph:
    """The coarse graph: cluster means of coordinates and normals; coarse edges are the images of the
    fine edges, deduplicated, without self loops, sorted by receiving vertex."""
    e = cluster[graph.edge_index]
    e = e[:, e[0] != e[1]]
    key = torch.unique(e[0] * num_clusters + e[1])
    edge_index = torch.stack([key // num_clusters, key % num_clusters])
    batch = torch.zeros(num_clusters, dtype=torch.long, device=cluster.device)
    batch[cluster] = graph.batch
    return Graph(pos=pool_features(graph.pos, cluster, num_clusters),
                 normal=pool_features(graph.normal, cluster, num_clusters),
                 edge_index=edge_index, batch=batch)


@dataclass
class Hierarchy(Tensors):
    """The graphs of all levels (``graphs[0]`` is the input mesh graph) and the cluster maps between them
    (``clusters[k]`` maps level-k vertices to level-(k+1) vertices)."""

    graphs: list[Graph]
    clusters: list[Tensor]

    @property
    def depth(self) -> int:
        return len(self.clusters)


def build_hierarchy(graph: Graph, levels: int, sigma_c: float = 1 / 16,
                    sigma_n: float = 3 / 16) -> Hierarchy:
    """Pool ``levels`` times, doubling both cell sizes at each level (the paper's schedule)."""
    # Edges grouped by receiving vertex keep the scatter in GeoConv cache-friendly.
    order = torch.argsort(graph.edge_index[0], stable=True)
    graph = Graph(graph.pos, graph.normal, graph.edge_index[:, order], graph.batch)
    graphs, clusters = [graph], []
    for level in range(levels):
        scale = 2.0 ** level
        cluster, n = geo_clusters(graph.pos, graph.normal, graph.batch, sigma_c * scale, sigma_n * scale)
        graph = pool_graph(graph, cluster, n)
        graphs.append(graph)
        clusters.append(cluster)
    return Hierarchy(graphs, clusters)


class GeoPool(nn.Module):
    r"""Geodesic-aware pooling from "Learning the Geodesic Embedding with Graph Neural Networks"
    (Pang et al., ACM TOG 2023), Sec. 3.2: vertices falling in the same cell of a 6-D grid over
    coordinates (cell :math:`\sigma_c`) and normals (cell :math:`\sigma_n`) form one coarse vertex with the
    mean feature

    .. math::
        \mathbf{f}'_c = \frac{1}{|c|} \sum_{i \in c} \mathbf{f}_i .

    Normals keep the two sides of a thin plate apart where plain grid pooling would merge them and so
    create geodesic shortcuts. The cluster map comes precomputed in a :class:`Hierarchy`.

    Shapes:
        - **input:** features :math:`(N, C)`, cluster :math:`(N,)`
        - **output:** :math:`(N', C)`
    """

    def forward(self, x: Tensor, cluster: Tensor, num_clusters: int) -> Tensor:
        return pool_features(x, cluster, num_clusters)


class GeoUnpool(nn.Module):
    r"""Inverse of :class:`GeoPool`: every vertex receives its cluster's feature,
    :math:`\mathbf{f}_i = \mathbf{f}'_{c(i)}`.

    Shapes:
        - **input:** coarse features :math:`(N', C)`, cluster :math:`(N,)`
        - **output:** :math:`(N, C)`
    """

    def forward(self, x: Tensor, cluster: Tensor) -> Tensor:
        return unpool_features(x, cluster)
