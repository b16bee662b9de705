"""Shared fixtures: a small raw folder (example soups + every kind of bad file) and its reference store."""
import pytest
from storetools import BAD, GOOD, prepare

from geodata.examples import example_soups


@pytest.fixture(scope="session")
def raw(tmp_path_factory):
    root = tmp_path_factory.mktemp("raw")
    soups = example_soups()
    (root / "nested").mkdir()
    for i, name in enumerate(GOOD):
        soups[name].export(root / ("nested" if i == 0 else "") / f"{name}.{['obj', 'ply', 'glb'][i]}")
    for name, data in BAD.items():
        (root / name).write_bytes(data)
    (root / "notes.txt").write_text("not a mesh suffix: ignored")
    return root


@pytest.fixture(scope="session")
def reference(raw, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "out.zarr"
    result = prepare(raw, out)
    return out, result.output


