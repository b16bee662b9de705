"""Dask and Ray through joblib give stores byte-identical to the default backend."""
import pytest
from storetools import BAD, assert_same_arrays, prepare, store_arrays

from geodata import store


@pytest.mark.parametrize("backend", ["dask", "ray"])
def test_cluster_backend_store_equals_default(backend, raw, reference, tmp_path):
    pytest.importorskip({"dask": "distributed", "ray": "ray"}[backend])
    out = tmp_path / f"{backend}.zarr"
    prepare(raw, out, "--backend", backend, "--jobs", "2")
    assert_same_arrays(store_arrays(reference[0]), store_arrays(out))
    assert sorted(a["source"] for a in store.list_failures(out).values()) == sorted(BAD)


def test_missing_extra_gives_a_clear_message(raw, tmp_path, monkeypatch):
    import sys

    from click.testing import CliRunner

    from geodata.cli import main

    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # as if the extra were not installed
    result = CliRunner().invoke(main, ["prepare", str(raw), str(tmp_path / "o"), "--backend", "dask"])
    assert result.exit_code != 0 and "pip install 'geogegnn[dask]'" in result.output
    assert "Traceback" not in result.output
