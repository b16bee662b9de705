"""Exact biharmonic distances against the dense spectral definition, and their invariants."""
from __future__ import annotations

import math

import igl
import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import connected_components

from geodata.biharmonic import BiharmonicSolver, biharmonic_distances, biharmonic_pairs
from geodata.examples import bumpy_sphere
from geodata.mesh import Mesh, MeshError


# --- meshes ------------------------------------------------------------------------------------

def icosphere() -> Mesh:
    s = trimesh.creation.icosphere(subdivisions=3)              # 642 vertices, regular
    return Mesh(s.vertices, s.faces)


def bumpy(n: int = 400, seed: int = 1, offset=(0.0, 0.0, 0.0)) -> Mesh:
    """Irregular closed mesh: convex hull of random sphere points, bumped and stretched."""
    return bumpy_sphere(n, seed, amplitude=0.2, stretch=(1.4, 1.0, 0.7), offset=offset)


def two_components() -> Mesh:
    a = bumpy(250, seed=2)
    s = trimesh.creation.icosphere(subdivisions=2)              # 162 vertices
    b = Mesh(0.6 * s.vertices + np.array([4.0, 0.0, 0.0]), s.faces)
    # Interleave the vertex order so components are not contiguous index ranges.
    v = np.concatenate([a.vertices, b.vertices])
    f = np.concatenate([a.faces, b.faces + len(a.vertices)])
    perm = np.random.default_rng(3).permutation(len(v))
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(v))
    return Mesh(v[perm], inv[f])


def open_grid(k: int = 16) -> Mesh:
    """A wavy open patch (has a boundary): the definition needs no closed surface."""
    x, y = np.meshgrid(np.linspace(0, 1, k), np.linspace(0, 1.3, k), indexing="ij")
    rng = np.random.default_rng(4)
    x = x + rng.uniform(-0.01, 0.01, x.shape)
    v = np.stack([x.ravel(), y.ravel(), 0.1 * np.sin(4 * x.ravel()) * np.cos(3 * y.ravel())], 1)
    idx = np.arange(k * k).reshape(k, k)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return Mesh(v, f)


def graded(n: int = 500, power: float = 3.0) -> Mesh:
    """Closed mesh with strongly graded triangle sizes (edge-length ratio ~3000): ill-conditioned L."""
    rng = np.random.default_rng(9)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    theta = np.pi * (np.arccos(np.clip(p[:, 2], -1, 1)) / np.pi) ** power   # crowd the north pole
    phi = np.arctan2(p[:, 1], p[:, 0])
    p = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1)
    hull = trimesh.convex.convex_hull(p)
    return Mesh(np.asarray(hull.vertices) * np.array([1.5, 1.0, 0.6]), np.asarray(hull.faces))


def labels(mesh: Mesh) -> np.ndarray:
    n, f = mesh.n_vertices, mesh.faces
    adj = sp.coo_matrix((np.ones(3 * len(f)), (f.ravel(), f[:, [1, 2, 0]].ravel())), shape=(n, n))
    return connected_components(adj, directed=False)[1]


def spectral_distances(mesh: Mesh) -> np.ndarray:
    """The definition: sqrt(sum_k (phi_k(x) - phi_k(y))^2 / lambda_k^2) over all nonzero eigenpairs."""
    v, f = mesh.vertices, mesh.faces
    L = igl.cotmatrix(v, f).toarray()
    M = igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_VORONOI).toarray()
    lam, phi = la.eigh(L, M)                                    # M-orthonormal eigenvectors
    n_zero = labels(mesh).max() + 1                             # one zero eigenvalue per component
    keep = np.argsort(np.abs(lam))[n_zero:]
    emb = phi[:, keep] / np.abs(lam[keep])
    sq = np.einsum("ij,ij->i", emb, emb)
    return np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2 * emb @ emb.T, 0.0))


MESHES = {"icosphere": icosphere, "bumpy": bumpy, "two_components": two_components, "open_grid": open_grid,
          "graded": graded}


@pytest.fixture(scope="module")
def bumpy_mesh() -> Mesh:
    return bumpy()


@pytest.fixture(scope="module")
def bumpy_all(bumpy_mesh) -> np.ndarray:
    return biharmonic_distances(bumpy_mesh, np.arange(bumpy_mesh.n_vertices))


# --- the definition ----------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(MESHES))
def test_equals_dense_spectral_sum(name):
    mesh = MESHES[name]()
    n = mesh.n_vertices
    D = biharmonic_distances(mesh, np.arange(n))
    R = spectral_distances(mesh)
    lab = labels(mesh)
    same = lab[:, None] == lab[None, :]
    off = same & ~np.eye(n, dtype=bool)
    assert D.shape == (n, n) and D.dtype == np.float64
    assert np.isfinite(D[same]).all()
    rel = np.abs(D[off] - R[off]) / R[off]
    # Round-off level (well under the 1e-5 asked for): a method that factors L M^-1 L (condition number squared)
    # loses ~1e-7 on the graded mesh; factoring L alone stays near 1e-9.
    assert rel.max() < 1e-8, rel.max()
    # Between components the distance is undefined.
    assert np.isnan(D[~same]).all()


def test_targets_subset_and_repeated_sources(bumpy_mesh, bumpy_all):
    rng = np.random.default_rng(5)
    src = np.array([7, 3, 7, 0, bumpy_mesh.n_vertices - 1])
    tgt = rng.choice(bumpy_mesh.n_vertices, 37, replace=False)
    D = biharmonic_distances(bumpy_mesh, src, tgt)
    assert D.shape == (len(src), len(tgt))
    np.testing.assert_allclose(D, bumpy_all[src][:, tgt], rtol=1e-10, atol=1e-12)


def test_symmetric_and_zero_diagonal(bumpy_all):
    assert np.all(np.diag(bumpy_all) == 0.0)
    off = ~np.eye(len(bumpy_all), dtype=bool)
    assert (bumpy_all[off] > 0).all()
    np.testing.assert_allclose(bumpy_all, bumpy_all.T, rtol=1e-9, atol=0)


def test_triangle_inequality(bumpy_all):
    """Biharmonic distance is a metric (an embedding distance)."""
    D = bumpy_all[:60, :60]
    viol = D[:, None, :] - (D[:, :, None] + D[None, :, :])      # d(i,k) - d(i,j) - d(j,k)
    assert viol.max() < 1e-9 * D.max()


def test_scaling_scales_distances_linearly(bumpy_mesh, bumpy_all):
    # Cotangent weights are scale-free, masses scale by s^2, so lambda ~ 1/s^2, phi ~ 1/s, d ~ s.
    s = 3.7
    src = np.arange(0, bumpy_mesh.n_vertices, 9)
    D = biharmonic_distances(Mesh(s * bumpy_mesh.vertices, bumpy_mesh.faces), src)
    np.testing.assert_allclose(D, s * bumpy_all[src], rtol=1e-8, atol=1e-12)


def test_invariant_to_rigid_motion(bumpy_mesh, bumpy_all):
    q, _ = np.linalg.qr(np.random.default_rng(6).normal(size=(3, 3)))
    moved = Mesh(bumpy_mesh.vertices @ q.T + np.array([10.0, -3.0, 2.5]), bumpy_mesh.faces)
    src = np.arange(0, bumpy_mesh.n_vertices, 7)
    np.testing.assert_allclose(biharmonic_distances(moved, src), bumpy_all[src], rtol=1e-8, atol=1e-12)


def test_invariant_to_vertex_relabelling(bumpy_mesh, bumpy_all):
    n = bumpy_mesh.n_vertices
    perm = np.random.default_rng(7).permutation(n)              # new vertex i = old perm[i]
    inv = np.empty(n, dtype=np.int64)
    inv[perm] = np.arange(n)
    relabelled = Mesh(bumpy_mesh.vertices[perm], inv[bumpy_mesh.faces])
    D = biharmonic_distances(relabelled, np.arange(n))
    np.testing.assert_allclose(D, bumpy_all[np.ix_(perm, perm)], rtol=1e-8, atol=1e-12)


def test_two_components_are_independent():
    """Within a component, the distances equal those of that component on its own."""
    mesh = two_components()
    lab = labels(mesh)
    D = biharmonic_distances(mesh, np.arange(mesh.n_vertices))
    for c in range(2):
        verts = np.flatnonzero(lab == c)
        remap = np.full(mesh.n_vertices, -1)
        remap[verts] = np.arange(len(verts))
        faces = remap[mesh.faces[np.isin(mesh.faces[:, 0], verts)]]
        alone = biharmonic_distances(Mesh(mesh.vertices[verts], faces), np.arange(len(verts)))
        np.testing.assert_allclose(D[np.ix_(verts, verts)], alone, rtol=1e-8, atol=1e-12)
        assert np.isnan(D[np.ix_(verts, np.flatnonzero(lab != c))]).all()


# --- pairs -------------------------------------------------------------------------------------

def test_pairs_contract(bumpy_mesh, bumpy_all):
    n = bumpy_mesh.n_vertices
    n_pairs = 2000
    pairs, dist = biharmonic_pairs(bumpy_mesh, n_pairs, np.random.default_rng(11))
    n_sources = math.ceil(n_pairs / (n - 1))
    assert pairs.dtype == np.uint32 and pairs.shape == (n_sources * (n - 1), 2)
    assert dist.dtype == np.float32 and dist.shape == (len(pairs),)
    sources = np.unique(pairs[:, 0])
    assert len(sources) == n_sources
    assert not (pairs[:, 0] == pairs[:, 1]).any()
    for s in sources:                                           # every other vertex exactly once
        t = pairs[pairs[:, 0] == s, 1]
        assert np.array_equal(np.sort(t), np.setdiff1d(np.arange(n), [s]))
    ref = bumpy_all[pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)]
    np.testing.assert_allclose(dist, ref, rtol=1e-6)


def test_pairs_deterministic(bumpy_mesh):
    a = biharmonic_pairs(bumpy_mesh, 1500, np.random.default_rng(3))
    b = biharmonic_pairs(bumpy_mesh, 1500, np.random.default_rng(3))
    c = biharmonic_pairs(bumpy_mesh, 1500, np.random.default_rng(4))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(np.unique(a[0][:, 0]), np.unique(c[0][:, 0]))


def test_pairs_capped_at_all_vertices_and_empty():
    mesh = icosphere()
    n = mesh.n_vertices
    pairs, dist = biharmonic_pairs(mesh, 10 * n * n, np.random.default_rng(0))
    assert len(np.unique(pairs[:, 0])) == n and len(pairs) == n * (n - 1)
    assert (dist > 0).all()
    pairs, dist = biharmonic_pairs(mesh, 0, np.random.default_rng(0))
    assert pairs.shape == (0, 2) and pairs.dtype == np.uint32 and dist.shape == (0,) and dist.dtype == np.float32


def test_pairs_stay_within_components():
    mesh = two_components()
    lab = labels(mesh)
    pairs, dist = biharmonic_pairs(mesh, 3000, np.random.default_rng(8))
    p = pairs.astype(np.int64)
    assert (lab[p[:, 0]] == lab[p[:, 1]]).all()
    sources = np.unique(p[:, 0])
    sizes = np.bincount(lab)
    assert len(pairs) == int((sizes[lab[sources]] - 1).sum())
    # just enough sources: without the last one drawn, fewer than the pairs asked for
    last = p[-1, 0]
    assert 3000 <= len(pairs) and len(pairs) - (sizes[lab[last]] - 1) < 3000
    assert np.isfinite(dist).all() and (dist > 0).all()


# --- bad meshes --------------------------------------------------------------------------------

def test_bad_meshes_raise_mesh_error():
    good = icosphere()
    v = good.vertices.copy()
    v[0] = np.nan
    with pytest.raises(MeshError, match="non-finite") as e:
        biharmonic_distances(Mesh(v, good.faces), [1])
    assert e.value.stage == "biharmonic"
    # A zero-area face: collapse one vertex onto another.
    v = good.vertices.copy()
    a, b = good.faces[0, :2]
    v[a] = v[b]
    with pytest.raises(MeshError, match="zero-area"):
        biharmonic_distances(Mesh(v, good.faces), [1])
    # An isolated vertex has no mass.
    v = np.concatenate([good.vertices, [[5.0, 5.0, 5.0]]])
    with pytest.raises(MeshError, match="unreferenced"):
        biharmonic_distances(Mesh(v, good.faces), [1])


def test_solver_reuse_matches_function(bumpy_mesh, bumpy_all):
    solver = BiharmonicSolver(bumpy_mesh)
    for src in ([0, 5], [bumpy_mesh.n_vertices - 1], [17]):
        np.testing.assert_allclose(solver.distances(np.array(src)), bumpy_all[src], rtol=1e-10, atol=1e-12)
