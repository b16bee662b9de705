"""Point-cloud files: every format gives the file's points (and normals) in its order, and every bad file a
reason in the file's terms."""
import numpy as np
import pytest

from geodata.mesh import MeshError
from geodata.stages.cloud import load_cloud_file, outliers

P = np.random.default_rng(0).normal(size=(40, 3))
N = P / np.linalg.norm(P, axis=1, keepdims=True)


def write(tmp_path, name, data) -> str:
    path = tmp_path / name
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return str(path)


def text(rows, sep=" ") -> str:
    return "".join(sep.join(f"{x:.9g}" for x in row) + "\n" for row in rows)


def ply(rows, binary=False) -> bytes:
    head = (f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {len(rows)}\n"
            + "".join(f"property float {a}\n" for a in ("x", "y", "z", "nx", "ny", "nz")[:rows.shape[1]])
            + "end_header\n").encode()
    return head + (rows.astype("<f4").tobytes() if binary else text(rows).encode())


@pytest.mark.parametrize("name,data,normals", [
    ("a.xyz", "# scan\nx y z\n" + text(P), False),
    ("a.csv", text(P, ","), False),
    ("b.csv", text(P, ";"), False),  # a spreadsheet's export where the decimal mark is a comma
    ("a.pts", text(np.hstack([P, N])), True),
    ("a.ply", ply(np.hstack([P, N])), True),
    ("b.ply", ply(np.hstack([P, N]), binary=True), True),
    ("c.ply", ply(P), False),
])
def test_formats_give_the_files_points_and_normals(tmp_path, name, data, normals):
    cloud = load_cloud_file(write(tmp_path, name, data))
    np.testing.assert_allclose(cloud.points, P, atol=1e-6)
    assert (cloud.normals is not None) == normals and not cloud.notes
    if normals:
        np.testing.assert_allclose(cloud.normals, N, atol=1e-6)


def test_npy_points_and_normals(tmp_path):
    np.save(tmp_path / "a.npy", np.hstack([P, N]))
    cloud = load_cloud_file(tmp_path / "a.npy")
    np.testing.assert_array_equal(cloud.points, P)
    np.testing.assert_allclose(cloud.normals, N)


def test_other_column_counts_and_bad_normals_are_noted_not_guessed(tmp_path):
    cloud = load_cloud_file(write(tmp_path, "a.xyz", text(np.hstack([P, N, P[:, :1]]))))  # x y z + 4 values
    assert cloud.normals is None and "7 values a point" in cloud.notes[0]
    np.testing.assert_allclose(cloud.points, P, atol=1e-6)
    zero = np.hstack([P, N])
    zero[5, 3:] = 0
    cloud = load_cloud_file(write(tmp_path, "z.xyz", text(zero)))
    assert cloud.normals is None and "the first at point 5" in cloud.notes[0]


@pytest.mark.parametrize("name,data,reason", [
    ("a.xyz", text(P[:3]) + "1 2 x\n", "line 4: 'x' is not a number"),
    ("a.xyz", text(P[:3]) + "1 2\n", "line 4: 2 values where the lines before have 3"),
    ("a.xyz", "1 2\n", "line 1: 2 values (expected x y z"),
    ("a.xyz", text(P[:2]) + "1 nan 2\n", "line 3: a value is not finite"),
    ("a.xyz", "# nothing\n", "no points"),
    ("a.obj", "v 0 0 0\n", "not a point-cloud file"),
    ("a.npy", b"\x93NUMPY garbage", "not a readable NumPy .npy file"),
    ("a.ply", b"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nend_header\n1\n", "PLY"),
])
def test_bad_files_fail_with_a_reason_in_the_files_terms(tmp_path, name, data, reason):
    with pytest.raises(MeshError) as info:
        load_cloud_file(write(tmp_path, name, data))
    assert reason in info.value.reason and "\n" not in info.value.reason


def test_an_object_array_is_refused(tmp_path):
    np.save(tmp_path / "o.npy", np.array([P, "x"], dtype=object), allow_pickle=True)
    with pytest.raises(MeshError, match="object arrays are refused"):
        load_cloud_file(tmp_path / "o.npy")


def test_outliers_are_the_points_far_from_all_others():
    p = np.concatenate([P, [[30.0, 0, 0], [0, -25.0, 0]]])
    assert outliers(p).tolist() == [40, 41]
    assert outliers(P).tolist() == []
    for scale in (1e-3, 1e3):  # in any unit
        assert outliers(p * scale).tolist() == [40, 41] and outliers(P * scale).tolist() == []


def test_a_tenfold_density_change_is_not_an_outlier():
    rng = np.random.default_rng(1)
    dense, sparse = rng.random((2000, 2)), rng.random((200, 2)) + (1.0, 0)
    flat = np.concatenate([dense, sparse])
    assert outliers(np.hstack([flat, np.zeros((len(flat), 1))])).tolist() == []
