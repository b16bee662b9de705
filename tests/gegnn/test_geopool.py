import math

import numpy as np
import torch
import trimesh

from geodata.mesh import Mesh, unique_edges, vertex_normals
from gegnn.graph import Graph, directed_edges, disjoint_union
from gegnn.nn import build_hierarchy, geo_clusters, pool_features
from gegnn.nn.geopool import unpool_features


def thin_plate() -> Graph:
    """The paper's table top: a 2 x 2 x 0.04 box whose top and bottom lie in one xyz grid cell."""
    box = trimesh.creation.box(extents=[2.0, 2.0, 0.04])
    v, f = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, max_edge=0.1)
    v = v + np.array([0.0, 0.0, 0.03])  # z in [0.01, 0.05]: inside the cell [0, 1/16)
    return Graph(torch.tensor(v, dtype=torch.float32), torch.tensor(vertex_normals(Mesh(v, f)), dtype=torch.float32),
                 directed_edges(torch.tensor(unique_edges(np.asarray(f)))), torch.zeros(len(v), dtype=torch.long))


def mixed_clusters(g: Graph, cluster: torch.Tensor) -> int:
    top, bottom = g.normal[:, 2] > 0.9, g.normal[:, 2] < -0.9
    return len(set(cluster[top].tolist()) & set(cluster[bottom].tolist()))


def test_geopool_keeps_thin_plate_sides_apart():
    g = thin_plate()
    geo, _ = geo_clusters(g.pos, g.normal, g.batch, 1 / 16, 3 / 16)
    plain, _ = geo_clusters(g.pos, g.normal, g.batch, 1 / 16, math.inf)
    assert mixed_clusters(g, geo) == 0
    assert mixed_clusters(g, plain) > 100  # plain grid pooling short-circuits the plate


def test_clusters_never_merge_meshes_and_are_canonical():
    g = thin_plate()
    union, _ = disjoint_union([g, g])
    cluster, n = geo_clusters(union.pos, union.normal, union.batch, 1.0, 3.0)  # coarse: few cells
    half = g.num_nodes
    assert set(cluster[:half].tolist()).isdisjoint(cluster[half:].tolist())
    assert cluster[:half].max() < cluster[half:].min()  # mesh 0's clusters first
    perm = torch.randperm(union.num_nodes)
    permuted, _ = geo_clusters(union.pos[perm], union.normal[perm], union.batch[perm], 1.0, 3.0)
    assert torch.equal(permuted, cluster[perm])


def test_hierarchy_levels_and_edges():
    g = thin_plate()
    h = build_hierarchy(g, levels=5)
    sizes = [x.num_nodes for x in h.graphs]
    assert sizes == sorted(sizes, reverse=True) and sizes[-1] < sizes[0]
    for fine, coarse, cluster in zip(h.graphs, h.graphs[1:], h.clusters):
        assert (coarse.edge_index[0] != coarse.edge_index[1]).all()  # no self loops
        image = cluster[fine.edge_index]
        image = image[:, image[0] != image[1]]
        assert {tuple(e) for e in image.t().tolist()} == {tuple(e) for e in coarse.edge_index.t().tolist()}
        torch.testing.assert_close(coarse.pos, pool_features(fine.pos, cluster, coarse.num_nodes))


def test_pool_unpool():
    x = torch.tensor([[1.0], [3.0], [10.0]])
    cluster = torch.tensor([0, 0, 1])
    pooled = pool_features(x, cluster, 2)
    assert pooled.tolist() == [[2.0], [10.0]]
    assert unpool_features(pooled, cluster).tolist() == [[2.0], [2.0], [10.0]]
