"""A worker's start at catalog scale: what a prepare shard, a biharmonic shard and a training rank read before
their first mesh does not grow with the store. Counted (mesh files opened, input files hashed), not timed:
benchmarks/bench_store_scale.py times the same steps at 2,000 and 20,000 meshes."""
import hashlib

import pytest
import zarr

from geodata import store
from geodata.parallel import in_shard
from geodata.prepare import plan_shard
from geodata.subgroup import pending
from storetools import synthetic_catalog


class Opened:
    """Counts the mesh zips opened (zarr's ZipStore) and the file contents hashed while installed."""

    def __init__(self, monkeypatch):
        import geodata.prepare

        self.zips, self.hashed = [], 0
        real_zip, real_sha = zarr.storage.ZipStore, hashlib.sha256

        def zip_store(path, *args, **kwargs):
            self.zips.append(str(path))
            return real_zip(path, *args, **kwargs)

        def sha256(data=b""):
            self.hashed += data.startswith(b"# model")
            return real_sha(data)

        monkeypatch.setattr(zarr.storage, "ZipStore", zip_store)
        monkeypatch.setattr(geodata.prepare.hashlib, "sha256", sha256)


@pytest.mark.parametrize("n", [200, 2000,
                               pytest.param(20000, marks=pytest.mark.slow)])
def test_a_workers_start_reads_its_own_share_only(tmp_path, monkeypatch, n):
    from gegnn.training.data import GeodesicStore, split_meshes

    raw, out = tmp_path / "raw", tmp_path / "out.zarr"
    ids = synthetic_catalog(raw, out, n)
    opened = Opened(monkeypatch)
    shard = (7, 200)
    plan = plan_shard(raw, str(out), shard)  # a prepare shard of a mostly committed catalog
    mine = [t.mesh_id for t in plan.tasks]
    assert plan.pending() == [] and plan.published == set(mine) and 0 < len(mine) < 3 * n / 200
    assert opened.hashed == len(plan.ledger["inputs"]) and opened.zips == []  # its own files, on a first run
    todo, done, failed = pending(str(out), "biharmonic", lambda m: in_shard(m, shard))  # a biharmonic shard
    assert len(todo) == sum(in_shard(m, shard) for m in ids) and (done, failed) == (0, 0)
    assert opened.zips == []
    train, val = split_meshes(GeodesicStore(out).mesh_ids)  # a training rank: the list, no mesh read
    assert sorted(train + val) == sorted(ids) and opened.zips == []
    assert GeodesicStore(out).key(ids[0]) and opened.zips == [str(store.mesh_file(out, ids[0]))]
