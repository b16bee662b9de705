"""gegnn.threads: work spread over torch's thread count gives what one thread gives, bit for bit."""
import threading

import numpy as np
import pytest
import torch

from geodata.examples import bumpy_sphere
from gegnn import GeGnn, threads


@pytest.fixture
def torch_threads():
    """Set torch's thread count within a test; the count before is restored after it."""
    before = torch.get_num_threads()
    yield torch.set_num_threads
    torch.set_num_threads(before)


def test_by_rows_splits_on_threads_and_stacks_in_order(torch_threads):
    x = np.random.default_rng(0).normal(size=(3 * threads.MIN_ROWS, 4))
    seen = []

    def compute(rows):
        seen.append((rows.start, rows.stop))
        return x[rows] * 2, np.cumsum(x[rows], axis=1)

    torch_threads(2)
    doubled, summed = threads.by_rows(compute, len(x))
    assert sorted(seen) == [(0, len(x) // 2), (len(x) // 2, len(x))]
    np.testing.assert_array_equal(doubled, x * 2)
    np.testing.assert_array_equal(summed, np.cumsum(x, axis=1))
    seen.clear()
    torch_threads(1)
    np.testing.assert_array_equal(threads.by_rows(lambda rows: x[rows] + 1, len(x)), x + 1)
    assert threads.by_rows(lambda rows: seen.append(rows) or x[rows], len(x)).shape == x.shape
    assert seen == [slice(0, len(x))]


def test_beside_runs_on_another_thread_only_with_several(torch_threads):
    caller = threading.get_ident()
    torch_threads(1)
    assert threads.beside(threading.get_ident).result() == caller
    torch_threads(2)
    assert threads.beside(threading.get_ident).result() != caller

    def fail():
        raise ValueError("from the task")
    for n in (1, 2):
        torch_threads(n)
        with pytest.raises(ValueError, match="from the task"):
            threads.beside(fail).result()


def test_fewer_for_torch_leaves_our_work_its_threads_and_restores_torchs(torch_threads):
    for n in (1, 2, 3):
        torch_threads(n)
        with threads.fewer_for_torch():
            assert torch.get_num_threads() == max(1, n - 1) and threads.count() == n
            with threads.fewer_for_torch():  # nested: no fewer again
                assert torch.get_num_threads() == max(1, n - 1) and threads.count() == n
            assert threads.beside(threads.count).result() == n
        assert torch.get_num_threads() == n and threads.count() == n
    with pytest.raises(ValueError, match="inside"):
        with threads.fewer_for_torch():
            raise ValueError("inside")
    assert torch.get_num_threads() == 3 and threads.count() == 3


@pytest.mark.parametrize("name", ["points", "landmark"])
def test_embed_is_the_same_on_one_and_two_threads(name, torch_threads):
    """The cloud model's projection, normals, surface neighbours, local triangulations (cut into blocks of
    rows) and the U-Net beside the fields; the mesh model's U-Net beside its fields."""
    mesh = bumpy_sphere(2 * threads.MIN_ROWS + 500, seed=1)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = None if name == "points" else np.asarray(mesh.faces)
    model = GeGnn.pretrained(name)
    codes = []
    for n in (1, 2):
        torch_threads(n)
        codes.append(model.embed(vertices, faces).features.numpy())
    np.testing.assert_array_equal(codes[0], codes[1])
