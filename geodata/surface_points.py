"""Points anywhere on a triangle mesh's surface, given by a face and barycentric coordinates: where xyz
points land on the surface (:func:`locate_points`), and the same surface with the points as vertices
(:func:`insert_points`), so that exact vertex-to-vertex solvers answer distances between them."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .mesh import Mesh

__all__ = ["SurfacePoints", "locate_points", "insert_points"]


class SurfacePoints(NamedTuple):
    """Points on a mesh's surface: ``face`` (P,) int64, ``bary`` (P, 3) float64 (the weights of the corners
    ``faces[face]``, >= 0, summing to 1) and ``offset`` (P,): how far each given point was from the surface."""

    face: np.ndarray
    bary: np.ndarray
    offset: np.ndarray


def locate_points(mesh: Mesh, points) -> SurfacePoints:
    """The closest surface point of each xyz point (P, 3) (libigl's AABB tree), as a face and barycentric
    coordinates; on an edge or a corner, one of the faces there."""
    import igl

    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not np.isfinite(points).all():
        raise ValueError(f"points must be finite xyz coordinates (P, 3), got an array of shape {points.shape}")
    if not mesh.n_faces:
        raise ValueError("the mesh has no faces to put points on")
    sq, face, closest = igl.point_mesh_squared_distance(points, mesh.vertices, mesh.faces)
    a, b, c = (mesh.vertices[mesh.faces[face, k]] for k in range(3))
    bary = np.clip(igl.barycentric_coordinates(closest, a, b, c), 0.0, None)  # rounding: -1e-17 at an edge
    return SurfacePoints(face.astype(np.int64), bary / bary.sum(axis=1, keepdims=True), np.sqrt(sq))


def insert_points(mesh: Mesh, face: np.ndarray, bary: np.ndarray, tol: float = 1e-9) -> tuple[Mesh, np.ndarray]:
    """Mesh with the surface points (face index, barycentric coordinates) inserted as vertices, and the
    vertex of each point (P,) int64 in the new mesh: exact geodesics between points inside faces are then
    exact vertex-to-vertex distances on the result.

    face (P,) int, bary (P, 3): weights of the corners mesh.faces[face] (>= 0, summing to 1, within tol);
    coordinates within tol of 0 are set to 0, putting the point on that edge or corner. Point p sits at
    x_p = sum_k bary[p, k] * vertices[faces[face[p], k]]. Points go in one at a time, each into the current
    (sub-)triangle of its face that contains it, with distances measured in the face's barycentric
    coordinates (relative to its size):
    - within tol of a corner (of the face, or a vertex inserted before): that vertex, nothing inserted;
    - within tol of an edge: a new vertex splits the edge and every triangle on it in two (both sides, the
      one on a boundary, all on a non-manifold edge), so no T-junction remains;
    - otherwise: a new vertex splits the triangle into three.
    Vertices 0..N-1 are the original ones, unchanged; new ones follow in order of first use. The surface is
    the same and every new triangle keeps its face's orientation, so a closed manifold stays one.
    """
    face, bary = _checked_points(mesh, face, bary, tol)
    position = np.einsum("pk,pkd->pd", bary, mesh.vertices[mesh.faces[face]])
    split = _Subdivision(mesh)
    vertex = [split.insert(p, f, b, tol) for p, (f, b) in enumerate(zip(face.tolist(), map(tuple, bary.tolist())))]
    return split.mesh(position), np.array(vertex, dtype=np.int64)


def _checked_points(mesh: Mesh, face, bary, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """face int64 (P,) and bary (P, 3) with coordinates within tol of 0 set to 0 (rows rescaled to sum 1);
    ValueError naming the first point that is not on the mesh."""
    face, bary = np.asarray(face), np.asarray(bary, dtype=np.float64)
    if face.ndim != 1 or bary.shape != (len(face), 3) or (face.size and not np.issubdtype(face.dtype, np.integer)):
        raise ValueError(f"insert_points: need face (P,) integers and bary (P, 3); got face {face.shape} "
                         f"{face.dtype}, bary {bary.shape}")
    bad = np.flatnonzero((face < 0) | (face >= mesh.n_faces))
    if len(bad):
        raise ValueError(f"insert_points: point {bad[0]} has face {face[bad[0]]}, not in 0..{mesh.n_faces - 1}")
    bad = np.flatnonzero(~np.isfinite(bary).all(axis=1) | (bary < -tol).any(axis=1)
                         | (np.abs(bary.sum(axis=1) - 1) > tol))
    if len(bad):
        raise ValueError(f"insert_points: point {bad[0]} has barycentric coordinates {bary[bad[0]].tolist()}, "
                         f"not finite, >= 0 and summing to 1 within {tol:g}")
    bary = np.where(bary <= tol, 0.0, bary)
    return face.astype(np.int64), bary / bary.sum(axis=1, keepdims=True)


_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


class _Subdivision:
    """A mesh whose triangles are being split: each sub-face keeps its original face and the barycentric
    coordinates of its corners in that face (a face's edge points have an exact 0, its corners are
    _IDENTITY), so a point is located in its own face's frame and an original edge is recognized exactly.
    Only split faces and new ones are stored: O(N + F) once, then O(sub-faces of a face) a point."""

    def __init__(self, mesh: Mesh):
        self.original = mesh
        self.n_faces = mesh.n_faces
        self.corners: dict[int, tuple] = {}  # sub-face -> vertices, once its slot was rewritten
        self.coords: dict[int, tuple] = {}   # sub-face -> its corners' barycentric coordinates in its face
        self.origin: dict[int, int] = {}     # new sub-face -> its face (a face's own slot keeps it)
        self.subs: dict[int, list] = {}      # face -> its sub-faces, once split
        self.new_points: list[int] = []      # the point placed at each new vertex
        edges = np.sort(mesh.faces[:, [1, 2, 2, 0, 0, 1]].reshape(-1, 2), axis=1)
        self.edge_key = edges[:, 0] * mesh.n_vertices + edges[:, 1]  # row 3f + j: edge of f opposite corner j
        self.edge_order = np.argsort(self.edge_key, kind="stable")
        self.sorted_key = self.edge_key[self.edge_order]

    def vertices_of(self, s: int) -> tuple:
        return self.corners.get(s) or tuple(self.original.faces[s].tolist())

    def insert(self, p: int, f: int, b: tuple, tol: float) -> int:
        """The vertex of point p (face f, barycentric b), inserted unless within tol of an existing one."""
        s, lam = self._locate(f, b)
        q = self.coords.get(s, _IDENTITY)
        gap = [max(abs(x - y) for x, y in zip(b, q[k])) for k in range(3)]
        k = min(range(3), key=gap.__getitem__)
        if gap[k] <= tol:
            return self.vertices_of(s)[k]
        v = self.original.n_vertices + len(self.new_points)
        self.new_points.append(p)
        # b = lam_k q_k + (1 - lam_k) r with r on the edge opposite corner k, so |b - r| = |lam_k| |q_k - r|, and
        # |q_k - r| is at most the larger distance from q_k to the edge's ends (1 in an unsplit face).
        to_edge = [abs(lam[k]) * max(max(abs(x - y) for x, y in zip(q[k], q[k - i])) for i in (1, 2)) for k in range(3)]
        k = min(range(3), key=to_edge.__getitem__)
        if to_edge[k] <= tol:
            self._split_edge(s, k, v, b, lam[(k + 2) % 3] / (lam[(k + 1) % 3] + lam[(k + 2) % 3]))
        else:
            self._split_face(s, v, b)
        return v

    def mesh(self, position: np.ndarray) -> Mesh:
        """The split mesh: original vertices, then the new ones at the positions of their points."""
        faces = np.concatenate([self.original.faces, np.zeros((self.n_faces - self.original.n_faces, 3), np.int64)])
        faces[list(self.corners)] = np.array(list(self.corners.values()), dtype=np.int64).reshape(-1, 3)
        new_vertices = position[np.array(self.new_points, dtype=np.int64)]
        return Mesh(np.concatenate([self.original.vertices, new_vertices]), faces)

    def _locate(self, f: int, b: tuple) -> tuple[int, tuple]:
        """The sub-face of face f that contains b (the one whose smallest barycentric coordinate of b is
        largest, robust to rounding on shared edges) and b's barycentric coordinates in it."""
        candidates = ((s, _barycentric(self.coords.get(s, _IDENTITY), b)) for s in self.subs.get(f, (f,)))
        return max(candidates, key=lambda pair: min(pair[1]))

    def _split_face(self, s: int, v: int, b: tuple):
        """Sub-face s into three around its interior vertex v (barycentric b in its face)."""
        (v0, v1, v2), (q0, q1, q2), f = self.vertices_of(s), self.coords.get(s, _IDENTITY), self.origin.get(s, s)
        self._set(s, (v0, v1, v), (q0, q1, b))
        self._set(self._new(f), (v1, v2, v), (q1, q2, b))
        self._set(self._new(f), (v2, v0, v), (q2, q0, b))

    def _split_edge(self, s: int, k: int, v: int, b: tuple, t: float):
        """Every sub-face on the edge of s opposite its corner k, in two at v: the point at b in the face of
        s, and at fraction t of the way along the edge (from corner k + 1 to k + 2) for the other faces."""
        a, c = self.vertices_of(s)[(k + 1) % 3], self.vertices_of(s)[(k + 2) % 3]
        f = self.origin.get(s, s)
        for s2 in self._faces_on_edge(s, k):
            verts, q, f2 = self.vertices_of(s2), self.coords.get(s2, _IDENTITY), self.origin.get(s2, s2)
            k2 = next(i for i in range(3) if verts[i] not in (a, c))
            w0, w1, w2 = verts[k2], verts[(k2 + 1) % 3], verts[(k2 + 2) % 3]
            q0, q1, q2 = q[k2], q[(k2 + 1) % 3], q[(k2 + 2) % 3]
            u = t if w1 == a else 1.0 - t
            qv = b if f2 == f else tuple((1.0 - u) * x + u * y for x, y in zip(q1, q2))
            self._set(s2, (w0, w1, v), (q0, q1, qv))
            self._set(self._new(f2), (w0, v, w2), (q0, qv, q2))

    def _faces_on_edge(self, s: int, k: int) -> list[int]:
        """The sub-faces (s among them) on the edge of s opposite its corner k: within its face, or, when
        the edge lies on an edge of the face (an exact 0 shared by its ends), on all faces of that edge."""
        verts, q, f = self.vertices_of(s), self.coords.get(s, _IDENTITY), self.origin.get(s, s)
        ends = {verts[(k + 1) % 3], verts[(k + 2) % 3]}
        j = next((j for j in range(3) if q[(k + 1) % 3][j] == 0.0 == q[(k + 2) % 3][j]), None)
        faces = [f] if j is None else self._faces_on_original_edge(f, j)
        return [s2 for g in faces for s2 in self.subs.get(g, (g,)) if ends <= set(self.vertices_of(s2))]

    def _faces_on_original_edge(self, f: int, j: int) -> list[int]:
        key = self.edge_key[3 * f + j]
        lo, hi = np.searchsorted(self.sorted_key, key, "left"), np.searchsorted(self.sorted_key, key, "right")
        return (self.edge_order[lo:hi] // 3).tolist()

    def _new(self, f: int) -> int:
        """A new sub-face slot of face f."""
        s, self.n_faces = self.n_faces, self.n_faces + 1
        self.origin[s] = f
        self.subs.setdefault(f, [f]).append(s)
        return s

    def _set(self, s: int, vertices: tuple, coords: tuple):
        self.corners[s], self.coords[s] = vertices, coords


def _barycentric(q: tuple, b: tuple) -> tuple:
    """Barycentric coordinates of b in the triangle with corners q, all given as barycentric coordinates in
    one face (their last two serve as plane coordinates: barycentrics are affine invariant)."""
    (_, x0, y0), (_, x1, y1), (_, x2, y2) = q
    _, x, y = b
    area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    l1 = ((x - x0) * (y2 - y0) - (x2 - x0) * (y - y0)) / area
    l2 = ((x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)) / area
    return 1.0 - l1 - l2, l1, l2
