"""Helpers for the geodata tests: a small raw folder's contents and store comparisons."""
import numpy as np
from click.testing import CliRunner

from geodata import store
from geodata.cli import main

ARGS = ["--pairs", "3000", "--target-vertices", "600"]
GOOD = ("table", "lamp", "crate")
BAD = {
    "empty.obj": b"",
    "garbage.ply": bytes(range(256)) * 8,
    "nan.obj": b"v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n",
    "bad_index.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n",
    "points_only.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\n",
    "flat.obj": b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
    "picture.stl": b"\x89PNG\r\n\x1a\n" + bytes(300),
}


def prepare(raw, out, *extra):
    result = CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, *extra])
    assert result.exit_code == 0, result.output
    return result


def published(out) -> dict:
    """Every published mesh's attributes, by mesh id."""
    return {mesh_id: store.mesh_attrs(out, mesh_id) for mesh_id in store.list_meshes(out)}


def store_arrays(out) -> dict:
    """Every array of every published mesh, keyed by path."""
    data = {}
    for mesh_id in store.list_meshes(out):
        with store.read_mesh(out, mesh_id) as g:
            for name in ("vertices", "faces", "normals", "edges", "geodesic/pairs", "geodesic/distances",
                         "input/face", "input/bary", "input/offset"):
                data[f"{mesh_id}/{name}"] = g[name][:]
    return data


def assert_same_arrays(a: dict, b: dict):
    assert a.keys() == b.keys()
    for key in a:
        assert a[key].dtype == b[key].dtype and np.array_equal(a[key], b[key]), key
