"""Whole distance matrices of a user's mesh, written to disk as they are computed: the work behind
``gegnn pairwise``.

A matrix is written tile by tile into a :class:`MatrixFile` (``.npy`` or a chunked ``.zarr`` array), so a
50k-vertex mesh's 2.5e9 entries never sit in memory. Three sources fill it: the model
(:meth:`gegnn.queries.embedding.Embedding.matrix`), the exact solver of the model's distance (geodesic: one field
per row by window propagation, on every core; biharmonic: :mod:`geodata.biharmonic`) and the heat method
(potpourri3d, one field per row: the loop its users write). Rows and columns are the file's vertices;
pairs with no distance (a vertex used by no face, or two separate parts of the mesh) are NaN.
"""
from __future__ import annotations

import os
import shutil
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from itertools import islice
from pathlib import Path

import numpy as np

from geodata.mesh import Mesh

from ..fields.exact import require_edge_manifold

__all__ = ["MatrixFile", "FileMatrix", "exact_rows", "heat_rows", "ROW_BLOCK"]

ROW_BLOCK = 16  # rows per task of the row-by-row solvers


class MatrixFile:
    """A (rows, cols) array on disk, written by slice assignment, visible under its name only once
    :meth:`close` ran (a killed run leaves ``NAME.partial``, never a plausible but unfinished file).

    ``.npy``: the NumPy format, each assigned row segment written at its offset (no memory map, so
    memory stays at one tile). ``.zarr``: a zarr array of ``chunk`` x ``chunk`` chunks (compressed).
    """

    def __init__(self, path, shape: tuple[int, int], dtype, chunk: int = 2048):
        self.path, self.shape, self.dtype = Path(path), tuple(shape), np.dtype(dtype)
        self.partial = self.path.with_name(self.path.name + ".partial")
        self._remove(self.partial)
        if self.path.suffix == ".zarr":
            import zarr

            self._zarr = zarr.create_array(self.partial, shape=self.shape, dtype=self.dtype,
                                           chunks=tuple(min(chunk, max(size, 1)) for size in self.shape))
            self._file = None
        else:
            header = {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False, "shape": self.shape}
            self._file = open(self.partial, "wb")
            np.lib.format.write_array_header_1_0(self._file, header)
            self._offset = self._file.tell()
            self._file.truncate(self._offset + self.dtype.itemsize * self.shape[0] * self.shape[1])

    def __setitem__(self, key: tuple[slice, slice], block: np.ndarray):
        if np.nanmax(block, initial=0) > np.finfo(self.dtype).max:
            raise ValueError(f"a distance exceeds the range of {self.dtype} ({np.finfo(self.dtype).max:g}): use "
                             "float32, or scale the mesh down")
        if self._file is None:
            self._zarr[key] = block
            return
        rows, cols = key
        block = np.ascontiguousarray(block, dtype=self.dtype)
        for r, row in zip(range(*rows.indices(self.shape[0])), block):
            start = self._offset + (r * self.shape[1] + cols.indices(self.shape[1])[0]) * self.dtype.itemsize
            os.pwrite(self._file.fileno(), row.tobytes(), start)

    def close(self) -> None:
        """Finish: the file appears under its name (replacing an older one)."""
        if self._file is not None:
            self._file.close()
        self._remove(self.path)
        os.replace(self.partial, self.path)

    @staticmethod
    def _remove(path: Path) -> None:
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()


class FileMatrix:
    """The matrix of a file's vertices (or a cloud's points) written through the network's: ``rows`` and
    ``cols`` are file indices, ``to_mesh`` maps them to the network's vertices (-1: used by no face, or a
    cloud's outlier), ``labels`` gives each network vertex its part (``vertex_components`` of a mesh, a
    cloud embedding's ``part``). Assigned blocks get NaN where a row or column is not on the network or
    the two lie on separate parts, then go to ``out``."""

    def __init__(self, out, labels: np.ndarray, to_mesh: np.ndarray, rows: np.ndarray, cols: np.ndarray):
        self.out, self.shape = out, (len(rows), len(cols))
        self.row_vertex, self.col_vertex = to_mesh[rows], to_mesh[cols]
        self.row_part = np.where(self.row_vertex >= 0, labels[np.maximum(self.row_vertex, 0)], -1)
        self.col_part = np.where(self.col_vertex >= 0, labels[np.maximum(self.col_vertex, 0)], -2)

    @property
    def mesh_rows(self) -> np.ndarray:
        return np.maximum(self.row_vertex, 0)

    @property
    def mesh_cols(self) -> np.ndarray:
        return np.maximum(self.col_vertex, 0)

    def __setitem__(self, key: tuple[slice, slice], block: np.ndarray):
        rows, cols = key
        same = self.row_part[rows][:, None] == self.col_part[cols][None, :]
        self.out[key] = np.where(same, block, np.nan)


def exact_rows(mesh: Mesh, rows: np.ndarray, cols: np.ndarray, out, distance: str = "geodesic",
               jobs: int | None = None, progress: bool = False) -> None:
    """Exact distances of mesh vertices ``rows`` x ``cols`` into ``out`` (slice assignment), ROW_BLOCK rows
    per task on ``jobs`` threads (default: every core; the exact geodesic solver releases the GIL)."""
    if distance == "geodesic":
        require_edge_manifold(mesh)
        import threading

        from geodata.geodesic import geodesic_solver

        local = threading.local()

        def solve(sources):
            if not hasattr(local, "solve"):
                local.solve = geodesic_solver(mesh)  # one solver per thread: it keeps scratch state
            return np.stack([local.solve(int(s)) for s in sources])
        jobs = jobs or os.cpu_count() or 1
    else:
        from geodata.biharmonic import BiharmonicSolver

        solver = BiharmonicSolver(mesh)  # one factorization, many right-hand sides a block: one thread

        def solve(sources):
            return solver.distances(np.asarray(sources))
        jobs = 1
    _by_row_blocks(lambda sources: solve(sources)[:, cols], rows, out, jobs, progress, f"exact {distance}")


def heat_rows(mesh: Mesh, rows: np.ndarray, cols: np.ndarray, out, progress: bool = False) -> None:
    """Heat-method distances (potpourri3d's defaults: t = mean edge length squared; one factorization, one
    field per row) into ``out``."""
    import potpourri3d as pp3d

    solver = pp3d.MeshHeatMethodDistanceSolver(mesh.vertices, mesh.faces)
    _by_row_blocks(lambda sources: np.stack([solver.compute_distance(int(s))[cols] for s in sources]), rows, out,
                   1, progress, "heat method")


def _by_row_blocks(solve, rows: np.ndarray, out, jobs: int, progress: bool, what: str) -> None:
    from geodata.progress import progress_bar

    starts = iter(range(0, len(rows), ROW_BLOCK))
    with ThreadPoolExecutor(jobs) as pool, progress_bar(total=len(rows), unit="row", disable=not progress,
                                                desc=what) as bar:
        def submit(count):
            return (pool.submit(lambda s=s: (s, solve(rows[s:s + ROW_BLOCK]))) for s in islice(starts, count))

        # At most 2 blocks per thread in flight: memory stays bounded however fast the solvers run.
        running = deque(submit(2 * jobs))
        while running:
            s, block = running.popleft().result()
            running.extend(submit(1))
            block = np.where(np.isfinite(block), block, np.nan)  # unreached (another part): no distance
            out[s:s + len(block), 0:out.shape[1]] = block
            bar.update(len(block))
