"""Fixtures for the gegnn tests: tiny stores, one-thread torch."""
import sys
from pathlib import Path

import pytest
import torch

# Once tests/ is on sys.path (the root conftest's helpers), this folder is an importable namespace
# package called "gegnn" that would shadow the editable install; a regular package found anywhere on
# sys.path wins over a namespace one, so put the source tree there. Then the helpers' folder.
sys.path.insert(0, str(Path(__file__).parents[2]))
sys.path.insert(0, str(Path(__file__).parent))
from gegnn_testing import FOUR_MESHES, ellipsoid, write_store  # noqa: E402


@pytest.fixture(scope="session")
def tiny_store(tmp_path_factory) -> str:
    """Four meshes of 144-162 vertices, 8 sources each (~1.3k pairs per mesh), biharmonic marked ok."""
    return write_store(tmp_path_factory.mktemp("store") / "tiny.zarr", FOUR_MESHES, biharmonic=True)


@pytest.fixture(scope="session")
def one_mesh_store(tmp_path_factory) -> str:
    return write_store(tmp_path_factory.mktemp("store1") / "one.zarr",
                       {"ellipsoid": ellipsoid((1.0, 0.7, 0.5))}, num_sources=16)


@pytest.fixture(autouse=True, scope="session")
def _one_thread():
    # The test graphs are tiny: per-op threading overhead dominates and, on a shared 2-core machine,
    # made steps ~10x slower. One thread also makes CPU results bitwise reproducible.
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)
