"""Offscreen pictures of scalar fields on meshes: a small NumPy z-buffer rasterizer plus matplotlib.

The field is interpolated per pixel (barycentric), shaded by the face normal and cut by isolines, so
pictures look the same on any machine without OpenGL. Used by ``gegnn query -o field.png`` and the
results report.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["View", "UP_AXES", "up_axis", "tipping_margin", "default_view", "project", "rasterize", "shade_field",
           "shade_points", "point_spacing", "checkerboard", "visible_polyline",
           "Panel", "Row", "save_panels"]


@dataclass(frozen=True)
class View:
    """Orthographic camera: rows of ``rotation`` are screen right, screen up, towards the viewer."""

    rotation: np.ndarray
    center: np.ndarray


UP_AXES = {"+x": (1.0, 0, 0), "-x": (-1.0, 0, 0), "+y": (0, 1.0, 0), "-y": (0, -1.0, 0), "+z": (0, 0, 1.0),
           "-z": (0, 0, -1.0)}
FRONTS = {"x": (0, 0, 1.0), "y": (0, 0, 1.0), "z": (0, -1.0, 0)}  # where a model faces, by its up axis
SUPPORT = 0.02  # the points a mesh stands on: within this fraction of its largest extent of its lowest


def tipping_margin(vertices: np.ndarray, faces: np.ndarray | None, up: np.ndarray) -> float:
    r"""How stably the mesh stands on its lowest points along ``up``: the tangent of the angle it can be
    tipped before its centroid leaves its base, :math:`m = s / h` with :math:`h` the height of the area
    centroid (a point cloud's: the mean point, ``faces`` None) over the lowest point and :math:`s` the
    distance of its projection to the edge of the base (the convex hull of the points within SUPPORT of
    the lowest), positive inside, negative outside; -inf where the base is a point or a line."""
    from scipy.spatial import ConvexHull, QhullError

    if faces is None:
        centroid = vertices.mean(axis=0)
    else:
        from geodata.mesh import face_areas

        area = face_areas(vertices, faces)
        centroid = (vertices[faces].mean(axis=1) * area[:, None]).sum(axis=0) / max(area.sum(), 1e-300)
    height = vertices @ up
    base = vertices[height <= height.min() + SUPPORT * np.ptp(vertices, axis=0).max()]
    e1 = np.cross(up, (1.0, 0, 0) if abs(up[0]) < 0.9 else (0, 1.0, 0))
    e1 /= np.linalg.norm(e1)
    plane = np.stack([e1, np.cross(up, e1)], axis=1)
    try:
        hull = ConvexHull(base @ plane)
    except (QhullError, ValueError):  # fewer than 3 points, or all on a line
        return -np.inf
    inside = -(hull.equations[:, :2] @ (centroid @ plane) + hull.equations[:, 2]).max()
    return float(inside / max(centroid @ up - height.min(), 1e-300))


def up_axis(vertices: np.ndarray, faces: np.ndarray | None) -> str:
    """The direction that is up in the mesh's own coordinates, "+y" or "+z": mesh files are written y-up
    (OBJ and glTF conventions, most scans) or z-up (CAD, 3D printing, some scans, e.g. Stanford's Lucy).

    A flat mesh (thinnest extent under 1e-3 of the largest) has the in-plane one of the two; a mesh
    whose lowest point lies exactly on the plane y = 0 or z = 0, as modelling tools place an object on
    the ground, has that one. Otherwise +z when the mesh stands on its lowest z points
    (:func:`tipping_margin` > 0) and not on its lowest y points, or twice as stably; else +y.

    Right on 50 of 51 meshes whose up axis was judged by eye (tests/gegnn/test_render.py): the 44
    development meshes of shared/meshes that have one, as their files come, the 6 examples and Lucy turned
    z-up; the miss, igea.ply, is a head without a base. Turned to the other convention, 34 of those 44: a
    mesh that stands on nothing (a head, a lying animal) is called y-up, so a z-up one needs ``--up``.
    """
    extent = np.ptp(vertices, axis=0)
    largest = extent.max()
    if extent.min() < 1e-3 * largest:
        return "+y" if extent[1] >= 1e-3 * largest else "+z"
    grounded = [axis for axis in (1, 2) if abs(vertices[:, axis].min()) <= 1e-9 * largest]
    if len(grounded) == 1:
        return "+y" if grounded[0] == 1 else "+z"
    m_y, m_z = (tipping_margin(vertices, faces, np.asarray(UP_AXES[a])) for a in ("+y", "+z"))
    return "+z" if m_z > 0 and (m_y < 0 or m_z > 2 * m_y) else "+y"


def default_view(vertices: np.ndarray, faces: np.ndarray | None, up: str | None = None,
                 towards: np.ndarray | None = None, elevation: float = 0.35, azimuth: float = 0.35) -> View:
    """The camera of a picture: ``up`` (a key of UP_AXES; default :func:`up_axis`) is vertical on the
    screen, and the camera looks from the horizontal direction that shows the largest area (a point
    cloud's, ``faces`` None: along which it is thinnest), turned by ``azimuth`` about the up axis and
    raised by ``elevation`` (radians) for depth.

    Of the two sides, the camera takes the one of ``towards`` (a direction, e.g. the source's normal)
    when given, else the files' front: +z for a y-up mesh, -y for a z-up one.
    """
    up_name = up or up_axis(vertices, faces)
    u = np.asarray(UP_AXES[up_name])
    front = np.asarray(FRONTS[up_name[1]])
    e1 = np.roll(np.abs(u), 1)  # a horizontal axis; e2 = u x e1 the other
    e2 = np.cross(u, e1)
    angles = np.linspace(0, np.pi, 36, endpoint=False)
    directions = np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2
    if faces is None:
        forward = directions[(vertices @ directions.T).std(axis=0).argmin()]
    else:
        tri = vertices[faces]
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # area-weighted
        forward = directions[np.abs(normals @ directions.T).sum(axis=0).argmax()]  # the largest projected area
    side = front if towards is None or abs(towards @ forward) < 1e-12 else towards
    if forward @ side < 0:
        forward = -forward
    horizontal = np.cos(azimuth) * forward + np.sin(azimuth) * np.cross(u, forward)
    toward = np.cos(elevation) * horizontal + np.sin(elevation) * u
    right = np.cross(u, toward)
    right /= np.linalg.norm(right)
    center = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    return View(np.stack([right, np.cross(toward, right), toward]), center)


def project(vertices: np.ndarray, view: View, points: np.ndarray, size: int = 512, margin: float = 0.05):
    """Pixel coordinates (P, 2) and depths (P,) of ``points`` in the picture of the mesh ``vertices``
    (the mesh fills the picture up to ``margin``)."""
    p = (vertices - view.center) @ view.rotation.T
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    scale = (1 - 2 * margin) * size / max((hi - lo).max(), 1e-12)
    q = (np.asarray(points, dtype=np.float64) - view.center) @ view.rotation.T
    xy = (q[:, :2] - (lo + hi) / 2) * scale + size / 2
    xy[:, 1] = size - xy[:, 1]  # image rows grow downwards
    return xy, q[:, 2]


def rasterize(vertices: np.ndarray, faces: np.ndarray, view: View, size: int = 512, margin: float = 0.05):
    """Z-buffer rasterization. Returns (face index (H, W) with -1 for background, barycentric
    coordinates (H, W, 3), projected vertex pixels (N, 2), vertex depths (N,))."""
    xy, depth = project(vertices, view, vertices, size, margin)
    tri = xy[faces]                                          # (F, 3, 2)
    x0 = np.clip(np.floor(tri.min(axis=1)).astype(int), 0, size - 1)
    x1 = np.clip(np.ceil(tri.max(axis=1)).astype(int), 0, size - 1)
    extent = (x1 - x0).max(axis=1) + 1
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    valid = np.abs(area) > 1e-12
    pix, zs, fid, bar = [], [], [], []
    # Triangles grouped by pixel extent, so every group is one vectorized pass over a small square.
    for k in range(int(np.ceil(np.log2(max(extent.max(), 1)))) + 1):
        side = 2 ** k
        group = np.flatnonzero(valid & (extent <= side) & (extent > side // 2 if k else True))
        if not len(group):
            continue
        oy, ox = np.mgrid[0:side, 0:side]
        offsets = np.stack([ox.ravel(), oy.ravel()], axis=1)
        for chunk in np.array_split(group, max(1, len(group) * side * side // 2_000_000)):
            px = x0[chunk, None, :] + offsets[None]           # (T, K, 2) integer pixels
            q = px + 0.5
            ta, tb, tc = (t[chunk, None, :] for t in (a, b, c))
            w0 = (tb[..., 0] - q[..., 0]) * (tc[..., 1] - q[..., 1]) - (tb[..., 1] - q[..., 1]) * (tc[..., 0] - q[..., 0])
            w1 = (tc[..., 0] - q[..., 0]) * (ta[..., 1] - q[..., 1]) - (tc[..., 1] - q[..., 1]) * (ta[..., 0] - q[..., 0])
            ar = area[chunk, None]
            l0, l1 = w0 / ar, w1 / ar
            l2 = 1 - l0 - l1
            inside = (l0 >= -1e-9) & (l1 >= -1e-9) & (l2 >= -1e-9) & (px < size).all(axis=2)
            t_idx, k_idx = np.nonzero(inside)
            f = chunk[t_idx]
            lam = np.stack([l0[t_idx, k_idx], l1[t_idx, k_idx], l2[t_idx, k_idx]], axis=1)
            pix.append(px[t_idx, k_idx, 1] * size + px[t_idx, k_idx, 0])
            zs.append((depth[faces[f]] * lam).sum(axis=1))
            fid.append(f)
            bar.append(lam)
    face_img = np.full(size * size, -1, dtype=np.int64)
    bary_img = np.zeros((size * size, 3))
    if pix:
        pix, zs, fid, bar = (np.concatenate(x) for x in (pix, zs, fid, bar))
        order = np.lexsort((-zs, pix))                       # per pixel, nearest first
        first = order[np.r_[True, pix[order][1:] != pix[order][:-1]]]
        face_img[pix[first]] = fid[first]
        bary_img[pix[first]] = bar[first]
    return face_img.reshape(size, size), bary_img.reshape(size, size, 3), xy, depth


UNREACHABLE = (0.62, 0.62, 0.62, 1.0)  # grey: vertices without a value


def checkerboard(uv: np.ndarray, square: float) -> np.ndarray:
    """RGBA (..., 4) of a two-color checkerboard with squares of side ``square`` in (u, v), its axes
    tinted (u > 0 red, v > 0 blue squares lighter) so the orientation shows."""
    cell = np.floor(uv / square).astype(np.int64)
    dark = (cell[..., 0] + cell[..., 1]) % 2 == 0
    rgba = np.ones(uv.shape[:-1] + (4,))
    rgba[..., :3] = np.where(dark[..., None], (0.15, 0.2, 0.35), (0.95, 0.9, 0.8))
    axis = (np.abs(uv[..., 1]) < square / 8) & (uv[..., 0] > 0)
    rgba[axis, :3] = (0.85, 0.1, 0.1)
    return rgba


def _depth_tolerance(depth: np.ndarray) -> float:
    return 0.02 * float(np.ptp(depth))


def _surface_depth(raster, faces: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Depth of the surface drawn at the pixels of ``xy`` (P, 2) (-inf where the background shows)."""
    face_img, bary, _, depth = raster
    size = face_img.shape[0]
    px = np.clip(np.floor(xy), 0, size - 1).astype(np.int64)
    f = face_img[px[:, 1], px[:, 0]]
    drawn = (depth[faces[np.maximum(f, 0)]] * bary[px[:, 1], px[:, 0]]).sum(axis=1)
    return np.where(f >= 0, drawn, -np.inf)


def visible_polyline(vertices, faces, view: View, points: np.ndarray, size: int = 512, raster=None) -> np.ndarray:
    """Pixel coordinates (P, 2) of ``points`` on the mesh, NaN where the surface hides them (``raster``:
    the mesh's :func:`rasterize` in this view, when the caller has it)."""
    raster = rasterize(vertices, faces, view, size) if raster is None else raster
    xy, z = project(vertices, view, points, size)
    hidden = z < _surface_depth(raster, faces, xy) - _depth_tolerance(raster[3])
    return np.where(hidden[:, None], np.nan, xy)


def shade_field(vertices, faces, field, view: View, *, size=512, cmap="viridis", vmin=None, vmax=None,
                isolines: int = 12, marker: int | None = None, raster=None) -> np.ndarray:
    """RGBA image (H, W, 4) of ``field`` (per vertex) with Lambert shading and ``isolines`` levels
    between vmin and vmax; ``marker`` draws a red dot on that vertex when it is visible. A field of
    (u, v) pairs (N, 2) is drawn as a checkerboard with squares of side ``vmax`` instead. ``raster``: the
    mesh's :func:`rasterize` in this view and size, when the caller has it."""
    raster = rasterize(vertices, faces, view, size) if raster is None else raster
    face_img, bary, xy, depth = raster
    covered = face_img >= 0
    f = np.where(covered, face_img, 0)
    n = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    n_view = (n @ view.rotation.T)[:, 2] / np.maximum(np.linalg.norm(n, axis=1), 1e-30)
    light = 0.45 + 0.55 * np.abs(n_view)[f]
    if field.ndim == 2:  # (u, v) per vertex: a checkerboard texture, interpolated per pixel
        uv = (field[faces[f]] * bary[..., None]).sum(axis=2)
        unreachable = covered & np.isnan(uv).any(axis=2)
        rgba = _paint(checkerboard(np.nan_to_num(uv), vmax), np.zeros(uv.shape[:2]), covered, unreachable, light, 0)
    else:
        value = (field[faces[f]] * bary).sum(axis=2)
        rgba = _paint_values(value, covered, light, field, cmap, vmin, vmax, isolines)
    if marker is not None:
        shown = _surface_depth(raster, faces, xy[[marker]])[0]
        _marker(rgba, xy[marker], np.isfinite(shown) and depth[marker] >= shown - _depth_tolerance(depth))
    return rgba


POINT_DISC = 1.6  # a cloud's disc radius in point_spacing: at 0.9, random samples left ~20% of the surface
                  # uncovered (the back showing through); at 1.6 only spots where points are sparser than usual


def point_spacing(points: np.ndarray) -> float:
    """A cloud's spacing: half the median distance of a point to its 8th nearest (robust to duplicates and
    near-duplicates); 0 for 8 points or fewer."""
    from scipy.spatial import cKDTree

    return float(0.5 * np.median(cKDTree(points).query(points, 9)[0][:, -1])) if len(points) > 8 else 0.0


def shade_points(points, field, view: View, *, normals=None, size=512, cmap="viridis", vmin=None, vmax=None,
                 isolines: int = 12, marker: int | None = None) -> np.ndarray:
    """RGBA image (H, W, 4) of a point cloud coloured by ``field`` (per point): every point a disc of
    radius POINT_DISC :func:`point_spacing`, the nearest in front, lit by its normal (``normals``; unlit without),
    with ``isolines`` where neighbouring discs fall in different levels; ``marker``: a red dot on that
    point."""
    xy, depth = project(points, view, points, size)
    plane = (points - view.center) @ view.rotation[:2].T
    pixels_per_unit = np.ptp(xy, axis=0).max() / max(np.ptp(plane, axis=0).max(), 1e-12)  # project's scale
    r = max(1.0, POINT_DISC * point_spacing(points) * pixels_per_unit)
    oy, ox = np.mgrid[-int(np.ceil(r)):int(np.ceil(r)) + 1, -int(np.ceil(r)):int(np.ceil(r)) + 1]
    disc = np.stack([ox.ravel(), oy.ravel()], axis=1)[(ox ** 2 + oy ** 2).ravel() <= r * r]
    px = np.floor(xy).astype(np.int64)[:, None, :] + disc[None]
    inside = ((px >= 0) & (px < size)).all(axis=2)
    who, k = np.nonzero(inside)
    pix = px[who, k, 1] * size + px[who, k, 0]
    order = np.lexsort((-depth[who], pix))  # per pixel, nearest first
    first = order[np.r_[True, pix[order][1:] != pix[order][:-1]]] if len(order) else order
    point_img = np.full(size * size, -1, dtype=np.int64)
    point_img[pix[first]] = who[first]
    point_img = point_img.reshape(size, size)
    covered = point_img >= 0
    p = np.where(covered, point_img, 0)
    light = np.ones((size, size)) if normals is None else 0.45 + 0.55 * np.abs((normals @ view.rotation.T)[:, 2])[p]
    rgba = _paint_values(field[p], covered, light, field, cmap, vmin, vmax, isolines)
    if marker is not None:
        x, y = np.clip(np.floor(xy[marker]), 0, size - 1).astype(int)
        _marker(rgba, xy[marker], depth[marker] >= depth[point_img[y, x]] - _depth_tolerance(depth)
                if point_img[y, x] >= 0 else False)
    return rgba


def _paint_values(value, covered, light, field, cmap, vmin, vmax, isolines) -> np.ndarray:
    """Colormap (grey where NaN: no value, e.g. another part than the source's), light and isolines of a
    per-pixel value image."""
    import matplotlib

    vmin = float(np.nanmin(field)) if vmin is None else vmin
    vmax = float(np.nanmax(field)) if vmax is None else vmax
    unreachable = covered & np.isnan(value)
    t = np.clip((np.nan_to_num(value) - vmin) / max(vmax - vmin, 1e-12), 0, 1)
    return _paint(matplotlib.colormaps[cmap](t), t, covered, unreachable, light, isolines)


def _paint(rgba, t, covered, unreachable, light, isolines) -> np.ndarray:
    rgba[unreachable] = UNREACHABLE
    rgba[..., :3] *= light[..., None]
    if isolines:
        band = np.floor(t * isolines - 1e-9)
        edge = np.zeros_like(covered)
        for shift in ((0, 1), (1, 0)):
            other = np.roll(band, shift, axis=(0, 1))
            both = covered & np.roll(covered, shift, axis=(0, 1))
            edge |= both & (other != band) & ~unreachable & ~np.roll(unreachable, shift, axis=(0, 1))
        rgba[edge, :3] *= 0.25
    rgba[~covered] = (1, 1, 1, 0)
    return rgba


def _marker(rgba, xy, visible: bool) -> None:
    """A red dot at pixel ``xy`` where ``visible`` (not hidden behind the surface drawn there)."""
    if not visible:
        return
    size = rgba.shape[0]
    r = max(2, size // 120)
    yy, xx = np.mgrid[0:size, 0:size]
    rgba[(xx - xy[0]) ** 2 + (yy - xy[1]) ** 2 <= r * r] = (0.85, 0.1, 0.1, 1)


@dataclass
class Panel:
    """One picture of a figure: a per-vertex field, its title, colormap, color bar label and range.
    A (u, v) field (N, 2) is a checkerboard texture with squares of side ``vmax`` (no color bar)."""

    field: np.ndarray
    title: str
    cmap: str = "viridis"
    label: str = "distance"
    vmin: float | None = None
    vmax: float | None = None
    isolines: int = 12


@dataclass
class Row:
    """One mesh's row of a figure: its panels, the source vertex to mark (None: no marker), and polylines
    on the surface drawn on every panel (e.g. geodesic paths), with their legend labels. A point cloud's
    row has ``faces`` None (and no lines), and its ``normals`` if it has them."""

    vertices: np.ndarray
    faces: np.ndarray | None
    source: int | None
    panels: list[Panel]
    lines: list[tuple[np.ndarray, str]] = field(default_factory=list)
    normals: np.ndarray | None = None


def save_panels(path, rows: list[Row], *, suptitle: str | None = None, size: int = 480, up: str | None = None) -> None:
    """A grid of rendered fields, one row per mesh or point cloud, each panel with a color bar, saved as
    PNG, each rendered at ``size`` x ``size`` pixels (the figure scales with it). A row's camera is
    `default_view` with ``up`` (default: each row's :func:`up_axis`), on the side of the source if any."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from geodata.mesh import Mesh, vertex_normals

    ncols = max(len(row.panels) for row in rows)
    fig, axes = plt.subplots(len(rows), ncols, figsize=(3.6 * ncols, 3.4 * len(rows)), squeeze=False)
    for r, row in enumerate(rows):
        v, f, src = row.vertices, row.faces, row.source
        normals = row.normals if f is None else vertex_normals(Mesh(v, f))
        cam = default_view(v, f, up, None if src is None or normals is None else normals[src])
        if f is None:
            raster, lines = None, []
        else:
            raster = rasterize(v, f, cam, size)  # one camera per row: every panel and line shares it
            lines = [(visible_polyline(v, f, cam, points, size, raster), label) for points, label in row.lines]
        for c in range(ncols):
            ax = axes[r, c]
            ax.set_axis_off()
            if c >= len(row.panels):
                continue
            p = row.panels[c]
            vmin = float(np.min(p.field)) if p.vmin is None else p.vmin
            vmax = float(np.max(p.field)) if p.vmax is None else p.vmax
            style = dict(size=size, cmap=p.cmap, vmin=vmin, vmax=vmax, isolines=p.isolines, marker=src)
            ax.imshow(shade_points(v, p.field, cam, normals=normals, **style) if f is None else
                      shade_field(v, f, p.field, cam, raster=raster, **style))
            ax.set_title(p.title, fontsize=10)
            for (xy, label), color, style in zip(lines, ("#e8196b", "#ffd400", "#00e5ff"), ("-", "--", ":")):
                ax.plot(xy[:, 0], xy[:, 1], style, color=color, lw=1.6, label=label)
            if row.lines and c == 0:
                ax.legend(loc="lower left", fontsize=7, framealpha=0.7)
            if p.field.ndim == 2:
                continue
            mappable = matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(vmin, vmax), p.cmap)
            fig.colorbar(mappable, ax=ax, fraction=0.046, pad=0.02, label=p.label)
    if suptitle:
        fig.suptitle(suptitle)
    fig.tight_layout()
    fig.savefig(path, dpi=100 * size / 480)  # the figure scales with the rendering
    plt.close(fig)
