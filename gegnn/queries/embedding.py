"""Per-vertex embeddings of one mesh and fast distance queries on them."""
from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from .. import precision as _precision

__all__ = ["Embedding"]

CHUNK_VALUES = 1 << 20  # values a decoded chunk holds in flight on a CPU: intermediates stay in cache
ACCELERATOR_CHUNK_VALUES = 1 << 27  # ... on a GPU: few launches (512 MB of fp32 codes)
FUSED_CHUNK = 1 << 22  # pairs per call of the compiled decode on a CPU: 16 bytes a pair in flight (64 MiB)
SURFACE_CHUNK = 4096  # pairs of distinct surface points blended at once on a CPU (6 code rows a pair)
ACCELERATOR_SURFACE_CHUNK = 1 << 16  # ... on a GPU: 1M pairs in 16 rounds (~0.3 GB of blended codes in flight)


class Embedding:
    """The result of :meth:`gegnn.GeGnn.embed`: per-vertex codes (N, C) plus the decoder and the mesh scale.

    Distances come back in the units of the mesh that was embedded.

    Args:
        features: vertex codes (N, C): the embeddings, or for a landmark-guided model the embeddings
            with the landmark fields and positions (:meth:`gegnn.decoders.LandmarkDecoder.codes`).
        decoder: the model's :class:`gegnn.decoders.DistanceDecoder` or ``LandmarkDecoder``.
        scale: factor from normalized units to the input's units.
        precision: the decoder's hidden layers in ``"fp32"`` (the default), ``"bf16"``, or ``"auto"``:
            bf16 only where the hardware has native bf16 and no compiled fp32 decode is faster
            (:func:`gegnn.precision.resolve_decoder`). bf16 changes distances by ~0.3% relative (median),
            below the model's error.
        chunk: pairs decoded per batch. For the compiled decode on a CPU
            (:meth:`gegnn.decoders.PairDecoder.fused_decode`, which works through its pairs in tiles of 64
            held in cache) 4M pairs, 16 bytes each in flight: each call starts threads, which wait for torch's
            (1M landmark queries: 0.14 s in one call, 0.17 s in chunks of 262k, 0.28 s in chunks of 16k).
            Else about 1M values in flight, the decoder's ``pair_width`` a pair (8192 pairs of two 64-d
            embeddings, 14768 of the landmark decoder's 71 inputs): large enough for the matmul kernels,
            small enough that intermediates stay in cache. On a GPU 128M values (342k pairs of 196-d
            codes): 1M queries in 3 chunks, where the CPU's size would launch thousands of kernels.
        vertices: the embedded mesh's vertices in its own units (:meth:`gegnn.GeGnn.embed` passes them
            and ``faces``): needed by the geometric queries, :meth:`path` and :meth:`log_map`.
        faces: the embedded mesh's faces.
        part: for a point cloud, the part of every point (N,): the connected components of the neighbour
            graph it was embedded on (distances between parts mean nothing); None for a mesh.
        ambiguous: for a point cloud, whether each point (N,) lies where two sheets of surface come closer than
            the points' spacing and the sides cannot be told apart (no normals, or normals that do not face
            away there): distances from such a point may run through the wall, short by the way round it
            (:func:`gegnn.fields.cloud_sides.close_walls`); None for a mesh.
        walls: for a point cloud, whether each point (N,) lies where two sheets of surface come closer than
            its neighbourhood is wide, whether or not the sides are told apart (``ambiguous`` are those they
            are not): with normals that tell them apart the fields keep to each side, but where such a wall
            also ends or creases within a spacing they can still cross it; None for a mesh.
        scatter: for a point cloud, how far its points lie off a smooth surface, in spacings (median): noise
            as large as the gap between two sheets hides them from ``ambiguous``; None for a mesh.
    """

    def __init__(self, features: Tensor, decoder, scale: float = 1.0, precision: str = "fp32",
                 chunk: int | None = None, vertices: np.ndarray | None = None, faces: np.ndarray | None = None,
                 part: np.ndarray | None = None, ambiguous: np.ndarray | None = None,
                 walls: np.ndarray | None = None, scatter: float | None = None):
        self.features = features.detach()
        self.part = part
        self.ambiguous, self.walls, self.scatter = ambiguous, walls, scatter
        self.vertices = None if vertices is None else np.asarray(vertices, dtype=np.float64)
        self.faces = None if faces is None else np.asarray(faces, dtype=np.int64)
        self._topology = None
        self.decoder, self.scale = decoder, float(scale)
        on_cpu = self.features.device.type == "cpu"
        self.surface_chunk = SURFACE_CHUNK if on_cpu else ACCELERATOR_SURFACE_CHUNK
        self.precision = _precision.resolve_decoder(precision, self.features.device, decoder.fused_layout() is not None)
        self.dtype = _precision.DTYPES[self.precision]
        self._layers = self._decoder_layers()
        self._fused = self._layers is not None and decoder.fuses(self.features, self._layers)
        values = CHUNK_VALUES if on_cpu else ACCELERATOR_CHUNK_VALUES
        self.chunk = chunk or (FUSED_CHUNK if self._fused else max(1024, values // decoder.pair_width(self.features)))

    @property
    def num_vertices(self) -> int:
        """Number of embedded vertices (points, for a cloud)."""
        return self.features.shape[0]

    def distance(self, i, j):
        """Distances between vertices ``i`` and ``j`` (index arrays, broadcast against each other).

        NumPy arrays, lists or ints give a NumPy array; torch tensors (on any device) give a float32
        tensor on the device of the codes, computed there without leaving it (one host sync, for the
        index range check)."""
        as_tensor = torch.is_tensor(i) or torch.is_tensor(j)
        i, j = torch.broadcast_tensors(self._indices(i), self._indices(j))
        shape = i.shape
        i, j = i.reshape(-1), j.reshape(-1)
        if len(i):
            lo_i, hi_i, lo_j, hi_j = torch.stack([*i.aminmax(), *j.aminmax()]).tolist()
            lo, hi = min(lo_i, lo_j), max(hi_i, hi_j)
            if lo < 0 or hi >= self.num_vertices:
                raise IndexError(f"vertex index out of range: {lo if lo < 0 else hi} "
                                 f"(the mesh has {self.num_vertices} vertices)")
        out = torch.empty(len(i), dtype=torch.float32, device=self.features.device)
        with torch.inference_mode():
            for s in range(0, len(i), self.chunk):
                out[s:s + self.chunk] = self._decode(self.features, i[s:s + self.chunk], j[s:s + self.chunk])
            # The decoder of a zero difference is not exactly 0; a distance is. masked_fill, unlike
            # out[i == j] = 0, needs no count of the mask, so no host sync.
            out = out.masked_fill_(i == j, 0).mul_(self.scale).reshape(shape)
        return out if as_tensor else out.cpu().numpy()

    def surface_distance(self, face_a, bary_a, face_b, bary_b) -> np.ndarray:
        """Distances between points anywhere on the surface, each given by a face and its barycentric
        coordinates (the weights of the corners ``faces[face]``; :meth:`locate` finds them for xyz points).

        ``face_a`` (...) with ``bary_a`` (..., 3) and ``face_b`` with ``bary_b`` broadcast against each
        other as :meth:`distance`'s indices do (``face_a[:, None]``, ``face_b[None, :]``: all pairs).
        A point's code is the barycentric blend of its face's vertex codes (the decoder's
        ``point_codes``: landmark fields and spectral modes are piecewise linear, as the solvers that
        made them define them between vertices), so a point at a vertex gets that vertex's distances
        and the distance is continuous across edges; points at the same place are at distance 0.
        """
        (corners_a, weights_a, pos_a, shape_a), (corners_b, weights_b, pos_b, shape_b) = (
            self._points(face_a, bary_a), self._points(face_b, bary_b))
        device = self.features.device
        i, j = torch.broadcast_tensors(torch.arange(len(pos_a), device=device).reshape(shape_a),
                                       torch.arange(len(pos_b), device=device).reshape(shape_b))
        shape, i, j = i.shape, i.reshape(-1), j.reshape(-1)
        with torch.inference_mode():
            if 2 * (len(pos_a) + len(pos_b)) <= len(i):  # few points, many pairs (e.g. all): blend each once
                codes = torch.cat([self._blend(corners_a, weights_a), self._blend(corners_b, weights_b)])
                out = self._decode_points(codes, torch.cat([pos_a, pos_b]), i, j + len(pos_a))
            else:  # pairs of distinct points: blend chunk by chunk (1M pairs would hold 2M codes at once)
                parts = []
                for s in range(0, len(i), self.surface_chunk):
                    a, b = i[s:s + self.surface_chunk], j[s:s + self.surface_chunk]
                    codes = torch.cat([self._blend(corners_a[a], weights_a[a]),
                                       self._blend(corners_b[b], weights_b[b])])
                    n = torch.arange(len(a), device=device)
                    parts.append(self._decode_points(codes, torch.cat([pos_a[a], pos_b[b]]), n, n + len(a)))
                out = torch.cat(parts) if parts else torch.empty(0, device=device)
        return out.reshape(shape).cpu().numpy()

    def at_points(self, face, bary, vertices: np.ndarray | None = None, faces: np.ndarray | None = None
                  ) -> "Embedding":
        """An embedding of surface points (each a face and barycentric coordinates, (P,) and (P, 3), as
        :meth:`surface_distance` takes them) whose codes are their blends: its :meth:`distance` between
        points ``a`` and ``b`` is :meth:`surface_distance` between them, and every other query (fields,
        matrices) runs on the points as on vertices. ``vertices``/``faces``: the mesh these points are the
        vertices of, if any (another mesh of the same surface: a full-resolution mesh embedded through a
        coarse proxy, a decimated display surface), for the geometric queries."""
        corners, weights, _, _ = self._points(np.asarray(face).reshape(-1), np.asarray(bary).reshape(-1, 3))
        return self.blended(corners, weights, vertices, faces)

    def blended(self, corners, weights, vertices: np.ndarray | None = None, faces: np.ndarray | None = None,
                part: np.ndarray | None = None, chunk: int = 1 << 16, ambiguous: np.ndarray | None = None,
                walls: np.ndarray | None = None, scatter: float | None = None) -> "Embedding":
        """An embedding whose row p is the blend of rows ``corners[p]`` (P, 3) with ``weights[p]`` (P, 3; >= 0,
        summing to 1) by the decoder's ``point_codes``: points inside faces (:meth:`at_points`), or the points of
        a dense cloud between the points of its embedded subset. ``vertices``, ``faces``, ``part``,
        ``ambiguous``, ``walls``, ``scatter``: as for any Embedding."""
        device = self.features.device
        corners = torch.as_tensor(np.asarray(corners, dtype=np.int64), device=device)
        weights = torch.as_tensor(np.asarray(weights, dtype=np.float32), device=device)
        with torch.inference_mode():
            codes = torch.cat([self._blend(corners[s:s + chunk], weights[s:s + chunk])
                               for s in range(0, len(corners), chunk)]) if len(corners) else self.features[:0]
        return Embedding(codes, self.decoder, self.scale, self.precision, vertices=vertices, faces=faces, part=part,
                         ambiguous=ambiguous, walls=walls, scatter=scatter)

    def locate(self, points):
        """The closest surface point of each xyz point (P, 3) (in the mesh's units), as
        :class:`geodata.surface_points.SurfacePoints` ``(face, bary, offset)``: the input of
        :meth:`surface_distance`, and how far each point was from the surface."""
        from geodata.mesh import Mesh
        from geodata.surface_points import locate_points
        self._require_mesh()
        return locate_points(Mesh(self.vertices, self.faces), points)

    def _points(self, face, bary) -> tuple[Tensor, Tensor, Tensor, tuple]:
        """Surface points as their faces' corners (P, 3), weights (P, 3), positions (P, 3) (float64, the
        mesh's units) on the codes' device, and the shape the faces came in."""
        self._require_mesh()
        face, bary = np.asarray(face), np.asarray(bary, dtype=np.float64)
        if bary.shape[-1:] != (3,) or bary.shape[:-1] != face.shape or not np.issubdtype(face.dtype, np.integer):
            raise ValueError(f"need integer faces (...) and barycentric coordinates (..., 3); got {face.shape} "
                             f"{face.dtype} and {bary.shape}")
        flat_face, flat_bary = face.reshape(-1), bary.reshape(-1, 3)
        bad = np.flatnonzero((flat_face < 0) | (flat_face >= len(self.faces)))
        if len(bad):
            raise IndexError(f"face index out of range: {flat_face[bad[0]]} (the mesh has {len(self.faces)} faces)")
        bad = np.flatnonzero((flat_bary < -1e-6).any(axis=1) | (np.abs(flat_bary.sum(axis=1) - 1) > 1e-6))
        if len(bad):
            raise ValueError(f"barycentric coordinates {flat_bary[bad[0]].tolist()} are not >= 0 summing to 1")
        corners = self.faces[flat_face]
        positions = np.einsum("pk,pkd->pd", flat_bary, self.vertices[corners])
        device = self.features.device
        return (torch.as_tensor(corners, device=device), torch.as_tensor(flat_bary, dtype=torch.float32, device=device),
                torch.as_tensor(positions, device=device), face.shape)

    def _decode_points(self, codes: Tensor, points: Tensor, i: Tensor, j: Tensor) -> Tensor:
        """Distances in the mesh's units of the pairs (codes[i], codes[j]) of surface points at ``points``:
        0 where two points are at the same place."""
        out = torch.empty(len(i), dtype=torch.float32, device=codes.device)
        for s in range(0, len(i), self.chunk):
            a, b = i[s:s + self.chunk], j[s:s + self.chunk]
            same = (points[a] - points[b]).abs().amax(dim=1) <= 1e-12 * self.scale
            out[s:s + len(a)] = self._decode(codes, a, b).masked_fill_(same, 0)
        return out.mul_(self.scale)

    def _blend(self, corners: Tensor, weights: Tensor) -> Tensor:
        """Codes (P, C) of points with corners (P, 3) and weights (P, 3) (the decoder's ``point_codes``)."""
        rows = self.features.index_select(0, corners.reshape(-1)).view(len(corners), 3, -1)
        return self.decoder.point_codes(rows, weights)

    def matrix(self, rows=None, cols=None, dtype=np.float32, out=None, tile: int = 2048,
               progress: bool = False):
        """Distances of every row vertex to every column vertex, (len(rows), len(cols)).

        Computed tile by tile (``tile`` x ``tile`` pairs at a time), so memory stays bounded whatever
        the size, and written into ``out`` when given: any array that takes slice assignment, e.g. a
        ``numpy.lib.format.open_memmap`` or a chunked zarr array, for matrices larger than memory (a
        50k-vertex mesh has 2.5e9 entries). When the columns are the rows (the default: all x all), only
        the tiles on and above the diagonal are decoded and mirrored: the matrix is exactly symmetric,
        and 0 on the diagonal (as :meth:`distance`, whose values every entry equals).

        Args:
            rows: vertex indices (default: every vertex).
            cols: vertex indices (default: ``rows``).
            dtype: of the result; float16 halves the size (relative rounding 5e-4, far below the
                model's error) and raises if a distance exceeds its range (65504).
            out: where to write (shape (len(rows), len(cols))); default a new NumPy array.
            tile: rows and columns per tile.
            progress: show a progress bar.

        Returns:
            ``out``, filled.
        """
        from geodata.progress import progress_bar

        rows = np.arange(self.num_vertices) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
        symmetric = cols is None or np.array_equal(rows, cols)
        cols = rows if cols is None else np.asarray(cols, dtype=np.int64).reshape(-1)
        dtype = np.dtype(dtype)
        shape = (len(rows), len(cols))
        if out is None:
            out = np.empty(shape, dtype=dtype)
        elif tuple(out.shape) != shape:
            raise ValueError(f"out has shape {tuple(out.shape)}, the matrix {shape}")
        row_starts, col_starts = range(0, shape[0], tile), range(0, shape[1], tile)
        tiles = [(r, c) for r in row_starts for c in col_starts if not symmetric or c >= r]
        with progress_bar(total=sum(min(tile, shape[0] - r) * min(tile, shape[1] - c) for r, c in tiles), unit="pair",
                  unit_scale=True, disable=not progress, desc="distance matrix") as bar:
            for r, c in tiles:
                i, j = rows[r:r + tile], cols[c:c + tile]
                block = self.distance(i[:, None], j[None, :])
                if symmetric and r == c:  # mirror the upper triangle: exactly symmetric
                    block = np.triu(block) + np.triu(block, 1).T
                if block.size and block.max() > np.finfo(dtype).max:
                    raise ValueError(f"a distance exceeds the range of {dtype} ({np.finfo(dtype).max:g}): "
                                     "use float32, or scale the mesh down")
                block = block.astype(dtype)
                out[r:r + len(i), c:c + len(j)] = block
                if symmetric and r != c:
                    out[c:c + len(j), r:r + len(i)] = block.T
                bar.update(block.size)
        return out

    def _indices(self, x) -> Tensor:
        if torch.is_tensor(x):
            # Asynchronous only towards an accelerator, whose stream runs the copy before the kernels that
            # read it; towards the host, the host reads the indices next (a pending copy would be read).
            return x.to(self.features.device, torch.long, non_blocking=self.features.device.type != "cpu")
        return torch.as_tensor(np.asarray(x).astype(np.int64), device=self.features.device)

    def field(self, source: int) -> np.ndarray:
        """Distances from vertex ``source`` to every vertex, (N,)."""
        return self.distance(np.full(self.num_vertices, int(source)), np.arange(self.num_vertices))

    def path(self, i: int, j: int):
        """The geodesic path from vertex ``i`` to vertex ``j``: the steepest descent of the predicted field
        d(i, .) traced back from ``j`` (:mod:`gegnn.queries.paths`); O(k) queries for the k faces it crosses.

        Returns:
            :class:`gegnn.queries.paths.Path`: ``points`` (K, 3) on the surface from i to j, ``length``.
        """
        from .paths import trace_path
        i, j = int(i), int(j)
        return trace_path(self.topology, lambda v: self.distance(i, v), i, j)

    def log_map(self, center: int, radius: float | None = None):
        """Geodesic polar coordinates around vertex ``center`` (the discrete logarithmic map) of the
        vertices within ``radius`` (default: all), from distance queries alone (:mod:`gegnn.queries.logmap`).

        Returns:
            :class:`gegnn.queries.logmap.LogMap`: ``vertices`` (M,), ``uv`` (M, 2), the tangent ``frame``.
        """
        from .logmap import log_map
        return log_map(self.topology, self.distance, int(center), radius)

    @property
    def topology(self):
        """Adjacency of the embedded mesh (built on first use)."""
        self._require_mesh()
        if self._topology is None:
            from .paths import SurfaceTopology
            self._topology = SurfaceTopology(self.vertices, self.faces)
        return self._topology

    def _require_mesh(self):
        if self.vertices is None or self.faces is None:
            raise ValueError("this Embedding has no mesh: make it with GeGnn.embed, or pass vertices and faces")

    def _decoder_layers(self):
        if self.decoder.mlp is None:
            return None
        linears = [m for m in self.decoder.mlp if isinstance(m, torch.nn.Linear)]
        return [(m.weight.detach().t().to(self.dtype).contiguous(), m.bias.detach().to(self.dtype))
                for m in linears]

    def _decode(self, codes: Tensor, i: Tensor, j: Tensor) -> Tensor:
        """Distances of the pairs (codes[i], codes[j]) (normalized units, diagonal not zeroed)."""
        if self._layers is None:  # Euclidean decoder: no MLP, fp32 is cheap
            return (codes.index_select(0, i) - codes.index_select(0, j)).norm(dim=1)
        if self._fused:  # features and MLP in one compiled pass, tile by tile
            return self.decoder.fused_decode(codes, i, j, self._layers)
        x, extra = self.decoder.pair_inputs(codes, i, j)
        x = x.to(self.dtype)
        *hidden, (w_out, b_out) = self._layers
        for w, b in hidden:  # fused bias add, in-place ReLU: fewer passes over memory
            x = torch.addmm(b, x, w).relu_()
        # The last layer is a dot product: fp32 costs nothing and avoids a bf16 rounding of the output.
        return self.decoder.output((x.float() @ w_out.float()).add_(b_out.float()), extra)
