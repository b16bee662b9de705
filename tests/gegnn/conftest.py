"""Fixtures for the gegnn tests: tiny stores, one-thread torch."""
import pytest
import torch
from gegnn_stores import FOUR_MESHES, ellipsoid, write_store


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
