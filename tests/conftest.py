"""Shared fixtures: a small raw folder (example soups + every kind of bad file) and its reference store."""
import importlib.metadata

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




# The release of potpourri3d that tests/gegnn/test_landmarks.py, test_cloud_heat.py and test_pointcloud.py
# compare with (fields to 1e-9, normals and triangles bit for bit); pyproject.toml pins its minor version.
POTPOURRI3D_COMPARED = "1.4.0"


def pytest_report_header(config):
    installed = importlib.metadata.version("potpourri3d")
    note = "" if installed == POTPOURRI3D_COMPARED else " (another release: comparisons with it may differ)"
    return f"potpourri3d {installed}, compared with {POTPOURRI3D_COMPARED}{note}"
