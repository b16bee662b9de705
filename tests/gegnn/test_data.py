import numpy as np
import pytest

from gegnn.training.data import BatchDataset, GeodesicStore, epoch_batches, split_meshes

MESHES = ["ellipsoid_a", "ellipsoid_b", "grid", "sphere"]


def test_store_lists_committed_meshes_only(tiny_store):
    assert GeodesicStore(tiny_store).mesh_ids == MESHES  # "unfinished" has no status "ok"
    assert GeodesicStore(tiny_store, "biharmonic").mesh_ids == MESHES
    pairs, dist = GeodesicStore(tiny_store).pairs("grid")
    assert pairs.dtype == np.int64 and pairs.shape == (8 * 143, 2) and dist.shape == (8 * 143,)


def test_grid_store_distances_are_euclidean(tiny_store):
    store = GeodesicStore(tiny_store)
    v = store.geometry("grid").vertices
    pairs, dist = store.pairs("grid")
    np.testing.assert_allclose(dist, np.linalg.norm(v[pairs[:, 0]] - v[pairs[:, 1]], axis=1), rtol=1e-5)


def test_split_is_deterministic_and_has_a_validation_mesh():
    ids = [f"mesh{k}" for k in range(50)]
    train, val = split_meshes(ids, 0.1)
    assert (train, val) == split_meshes(list(reversed(ids)), 0.1)
    assert set(train) | set(val) == set(ids) and not set(train) & set(val) and 1 <= len(val) < 15
    assert len(split_meshes(["a", "b"], 0.1)[1]) == 1
    assert split_meshes(["a"], 0.1) == (["a"], [])


def test_epoch_batches_shard_by_mesh_with_equal_counts():
    ids = [f"m{k}" for k in range(7)]
    shards = [epoch_batches(ids, 3, 0, 2, rank, 2) for rank in range(2)]
    assert len(shards[0]) == len(shards[1]) == 2
    seen = {m for shard in shards for b in shard for m in b}
    assert seen == set(ids)
    assert epoch_batches(ids, 3, 0, 2) == epoch_batches(ids, 3, 0, 2)
    assert epoch_batches(ids, 3, 0, 2) != epoch_batches(ids, 4, 0, 2)


def test_batches_are_deterministic_disjoint_unions(tiny_store):
    ds = BatchDataset(tiny_store, "geodesic", 0, 300, True, 5, 1 / 16, 3 / 16)
    a, b = ds[(2, ("grid", "sphere"))], ds[(2, ("grid", "sphere"))]
    assert np.array_equal(a.pairs, b.pairs) and np.array_equal(a.hierarchy.graphs[0].pos, b.hierarchy.graphs[0].pos)
    g = a.hierarchy.graphs[0]
    assert g.num_nodes == 144 + 162 and a.pairs.shape == (600, 2)
    assert (a.pairs[:300] < 144).all() and (a.pairs[300:] >= 144).all()
    assert (g.batch[g.edge_index[0]] == g.batch[g.edge_index[1]]).all()
    single = ds[(2, ("sphere",))]  # the same mesh sample whatever its batch
    np.testing.assert_array_equal(single.distances, a.distances[300:])


def test_bad_store(tmp_path):
    import zarr
    zarr.open_group(str(tmp_path / "x.zarr"), mode="w")
    with pytest.raises(ValueError):
        GeodesicStore(tmp_path / "x.zarr")
