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


def synthetic_catalog(raw, out, n: int) -> list[str]:
    """A scale store without running the stages: ``n`` input files (SYNSET/MODEL/models/model_normalized.obj,
    each a few bytes of its own), one prepare ledger for them, and each published in the store's format as a
    copy of one small mesh's zip (so the store holds ``n`` mesh files). Returns the mesh ids."""
    import hashlib
    import shutil

    from geodata.prepare import ledger_name, mesh_id_of

    store.create_store(out, {"pairs": 1})
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int32)
    store.write_mesh(out, "template", {"vertices": v, "faces": f, "normals": v, "edges": f[:, :2],
                                       "geodesic/pairs": np.array([[0, 1]], np.uint32),
                                       "geodesic/distances": np.ones(1, np.float32)},
                     {"source": "template.obj", "geometry_key": store.geometry_key(v, f), "n_vertices": 4,
                      "n_pairs": 1})
    template = store.mesh_file(out, "template")
    inputs, ids = {}, []
    for i in range(n):
        source = f"{i % 50:08d}/{i:08x}/models/model_normalized.obj"
        data = f"# model {i}\n".encode()
        path = raw / source
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
        digest = hashlib.sha256(data).hexdigest()
        mesh_id = mesh_id_of(source, digest)
        shutil.copyfile(template, store.mesh_file(out, mesh_id))
        stat = path.stat()
        inputs[source] = {"sha256": digest, "mesh_id": mesh_id, "size": stat.st_size, "mtime_ns": stat.st_mtime_ns}
        ids.append(mesh_id)
    template.unlink()
    store.write_ledger(out, ledger_name(raw, (0, 1), None, None),
                       {"root": str(raw.resolve()), "shard": "0/1", "written": 0.0, "inputs": inputs})
    return ids


def ball_obj(z_scale: float = 1.0) -> bytes:
    """An icosphere squashed along z by ``z_scale``, its numbers fixed-width: every such file has the same size."""
    import trimesh

    sphere = trimesh.creation.icosphere(1)
    lines = [f"v {x:+.6f} {y:+.6f} {z * z_scale:+.6f}" for x, y, z in sphere.vertices]
    lines += [f"f {a + 1:3d} {b + 1:3d} {c + 1:3d}" for a, b, c in sphere.faces]
    return ("\n".join(lines) + "\n").encode()
