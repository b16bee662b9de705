"""Exact biharmonic distances (Lipman, Rustamov, Funkhouser 2010), stage 7 of geodata.

Definition (contract, DESIGN.md): with libigl's cotangent Laplacian ``L = igl.cotmatrix(V, F)`` and
Voronoi mass matrix ``M = igl.massmatrix(V, F, MASSMATRIX_TYPE_VORONOI)``,

    d(x, y)^2 = g(x, x) + g(y, y) - 2 g(x, y)

with ``g`` the Green's function of ``L M^-1 L`` on functions M-orthogonal to constants, i.e.
``G = sum_k phi_k phi_k^T / lambda_k^2`` over the nonzero eigenpairs of ``L phi = lambda M phi``
(M-orthonormal ``phi``).

Method (no eigen-decomposition, no N x N matrix, and no squared condition number):

* With ``K = sum_k phi_k phi_k^T / lambda_k`` (the Green's function of ``L`` itself, M-orthogonal to
  constants), ``G = K M K``. So ``g(x, y) = k_x^T M k_y`` with ``k_x = K e_x``: the biharmonic
  distance is the M-norm distance between Green's functions of the Laplacian, and only ``L`` (not
  ``L M^-1 L``, whose condition number is the square of L's) is ever factored.
* ``k_x`` comes from one sparse solve: pin one vertex ``r`` per connected component (delete its row
  and column of ``-L``, which leaves a positive definite matrix), solve for ``e_x``, and subtract the
  M-weighted mean on the component; that gives ``K e_x - K e_r``. ``K e_r`` itself is
  ``-(centered solve of M 1) / area`` (because ``K M 1 = 0``), so ``k_x`` is exact, not shifted.
* ``-L_red`` is factored once per component with SuperLU in symmetric mode (minimum degree on
  ``A + A^T``, no pivoting: an ``L D L^T`` factorization of an SPD matrix). The targets' columns
  ``k_y`` are solved in blocks of identity columns; each block gives ``g(y, y)`` and, with one GEMM
  against the sources' ``M k_s``, ``g(s, y)``. Nothing larger than (N, block) or (N, S) is held.
* All of ``g`` is computed from the same columns, so errors in ``k`` largely cancel in ``d``.

Distances between different connected components are undefined and returned as NaN.
"""
from __future__ import annotations


import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from geodata.geodesic import sample_sources
from geodata.mesh import Mesh, MeshError, degenerate_faces, label_groups, vertex_components

__all__ = ["biharmonic_distances", "biharmonic_pairs", "BiharmonicSolver", "cotan_operators", "ldlt"]

STAGE = "biharmonic"
_BLOCK = 32               # right-hand sides per sparse solve (measured best on 5k meshes)


def cotan_operators(mesh: Mesh) -> tuple[sp.csc_matrix, np.ndarray]:
    """Cotangent Laplacian (libigl) and Voronoi masses; MeshError on anything that is not usable."""
    import igl

    v, f = mesh.vertices, mesh.faces
    n = len(v)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise MeshError(STAGE, f"bad array shapes vertices {v.shape} faces {f.shape}")
    if len(f) == 0:
        raise MeshError(STAGE, "no faces")
    if not np.isfinite(v).all():
        raise MeshError(STAGE, "non-finite vertex coordinates")
    if f.min() < 0 or f.max() >= n:
        raise MeshError(STAGE, "face index out of range")
    if np.bincount(f.ravel(), minlength=n).min() == 0:
        raise MeshError(STAGE, "unreferenced vertices")
    n_degenerate = int(degenerate_faces(mesh, 1e-14).sum())
    if n_degenerate:
        raise MeshError(STAGE, f"{n_degenerate} zero-area faces")
    L = sp.csc_matrix(igl.cotmatrix(v, f))
    m = np.asarray(igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_VORONOI).diagonal(), dtype=np.float64)
    if not np.isfinite(L.data).all():
        raise MeshError(STAGE, "non-finite cotangent Laplacian")
    if not (np.isfinite(m).all() and (m > 0).all()):
        raise MeshError(STAGE, "non-positive or non-finite vertex masses")
    return L, m


def ldlt(matrix: sp.csc_matrix):
    """SuperLU in symmetric mode (minimum degree on A + A^T, no pivoting): the L D L^T of a symmetric
    positive definite sparse matrix, with ``solve``; RuntimeError where it cannot factor."""
    return spla.splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))


class _Component:
    """One connected component (`verts`: its vertex ids, ascending): masses, L D L^T of -L with one vertex pinned."""

    def __init__(self, neg_L: sp.csc_matrix, m: np.ndarray, verts: np.ndarray):
        self.n = len(verts)
        self.m = m[verts]
        self.area = float(self.m.sum())
        # The pinned vertex (any gives the same distances) is the last: k = n - 1 rows remain.
        self.pin = self.k = k = self.n - 1
        Lc = neg_L[verts][:, verts][:k, :k].tocsc()
        Lc = ((Lc + Lc.T) * 0.5).tocsc()
        try:
            lu = ldlt(Lc)
        except RuntimeError as exc:
            raise MeshError(STAGE, f"Laplacian cannot be factorized ({exc})") from None
        d = lu.U.diagonal()
        if not np.array_equal(lu.perm_r, lu.perm_c):
            raise MeshError(STAGE, "Laplacian needed pivoting (not positive definite beyond constants)")
        if not (np.isfinite(d).all() and (d > 0).all()):
            raise MeshError(STAGE, "Laplacian is singular beyond constants (not positive definite)")
        if d.min() <= 1e-14 * d.max():
            raise MeshError(STAGE, "Laplacian is numerically singular beyond constants")
        self.lu = lu
        # K e_r, from K M 1 = 0: sum_y m_y (K e_y - K e_r) = -area K e_r.
        self.k_pin = -self._centered(self._solve_rhs(self.m[:k, None]))[:, 0] / self.area

    def _solve_rhs(self, rhs: np.ndarray) -> np.ndarray:
        """Solutions with the pinned Laplacian for rhs (k, c); zero at the pin. Returns (n, c)."""
        out = np.zeros((self.n, rhs.shape[1]))
        out[:self.k] = self.lu.solve(rhs)
        return out

    def _centered(self, w: np.ndarray) -> np.ndarray:
        return w - (self.m @ w) / self.area

    def green(self, local_idx: np.ndarray) -> np.ndarray:
        """Columns K e_j (n, len(j)) of the M-orthogonal Green's function of the Laplacian."""
        rhs = np.zeros((self.k, len(local_idx)))
        live = np.flatnonzero(local_idx != self.pin)
        rhs[local_idx[live], live] = 1.0
        return self._centered(self._solve_rhs(rhs)) + self.k_pin[:, None]


class BiharmonicSolver:
    """Factors the cotangent Laplacian once per component; then distances from any sources."""

    def __init__(self, mesh: Mesh):
        L, m = cotan_operators(mesh)
        self.n = n = mesh.n_vertices
        self.labels = vertex_components(mesh)
        self.n_components = int(self.labels.max()) + 1
        self.local = np.empty(n, dtype=np.int64)    # global vertex -> index inside its component
        self.components = []
        neg_L = (-L).tocsr()
        for verts in label_groups(self.labels, self.n_components):
            self.local[verts] = np.arange(len(verts))
            self.components.append(_Component(neg_L, m, verts))

    def distances(self, sources: np.ndarray, targets: np.ndarray | None = None) -> np.ndarray:
        """float64 (len(sources), len(targets) or N); NaN between different components."""
        sources = _indices(sources, self.n, "sources")
        tgt = np.arange(self.n) if targets is None else _indices(targets, self.n, "targets")
        out = np.full((len(sources), len(tgt)), np.nan)
        s_lab = self.labels[sources]
        t_lab = self.labels[tgt]
        for c in np.unique(s_lab):
            t_cols = np.flatnonzero(t_lab == c)
            if len(t_cols) == 0:
                continue
            comp = self.components[c]
            s_rows = np.flatnonzero(s_lab == c)
            uniq, inv = np.unique(sources[s_rows], return_inverse=True)
            ks = comp.green(self.local[uniq])                       # (n_c, S_u)
            mks = comp.m[:, None] * ks
            g_ss = np.einsum("ij,ij->j", ks, mks)
            # Targets in blocks: their Green's columns give g(y, y) and, by GEMM, g(s, y).
            ut, t_inv = np.unique(self.local[tgt[t_cols]], return_inverse=True)
            d2 = np.empty((len(uniq), len(ut)))
            for a in range(0, len(ut), _BLOCK):
                kt = comp.green(ut[a:a + _BLOCK])                   # (n_c, b)
                g_tt = np.einsum("ij,ij->j", kt, comp.m[:, None] * kt)
                d2[:, a:a + _BLOCK] = g_ss[:, None] + g_tt[None, :] - 2.0 * (mks.T @ kt)
            np.maximum(d2, 0.0, out=d2)
            block = np.sqrt(d2)[np.ix_(inv, t_inv)]
            block[sources[s_rows, None] == tgt[None, t_cols]] = 0.0
            out[np.ix_(s_rows, t_cols)] = block
        return out


def _indices(idx, n: int, name: str) -> np.ndarray:
    idx = np.asarray(idx).reshape(-1)
    if idx.size and not np.issubdtype(idx.dtype, np.integer):
        raise ValueError(f"{name} must be integer vertex indices")
    idx = idx.astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise ValueError(f"{name} out of range [0, {n})")
    return idx


def biharmonic_distances(mesh: Mesh, sources: np.ndarray, targets: np.ndarray | None = None) -> np.ndarray:
    """Exact biharmonic distances, float64: row i holds d(sources[i], t) for every target t (every vertex
    when ``targets`` is None); d(x, x) = 0, NaN between connected components (undefined).
    Raises MeshError("biharmonic", reason) for meshes whose Laplacian cannot be factorized."""
    return BiharmonicSolver(mesh).distances(sources, targets)


def biharmonic_pairs(mesh: Mesh, n_pairs: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Pairs drawn as sources x all vertices, with their biharmonic distances.

    Sources are drawn as for geodesic pairs (`geodata.geodesic.sample_sources`: distinct, just enough
    that pairs >= n_pairs); each is paired with every other vertex of its connected component, rows
    ``[source, target]`` grouped by source (in draw order) with targets ascending.
    Returns (uint32 (P, 2), float32 (P,)).
    """
    if n_pairs <= 0 or mesh.n_vertices < 2:
        return np.zeros((0, 2), dtype=np.uint32), np.zeros(0, dtype=np.float32)
    solver = BiharmonicSolver(mesh)
    sources = sample_sources(solver.labels, n_pairs, rng).astype(np.int64)
    dist = solver.distances(sources)                           # (S, N)
    same = solver.labels[sources][:, None] == solver.labels[None, :]
    same[np.arange(len(sources)), sources] = False
    s_idx, t_idx = np.nonzero(same)                            # row-major: grouped by source
    pairs = np.stack([sources[s_idx], t_idx], axis=1).astype(np.uint32)
    return pairs, dist[s_idx, t_idx].astype(np.float32)
