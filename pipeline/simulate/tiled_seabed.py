"""The seabed as the tracer sees it, meshed tile by tile as rays reach it (memory bounded by area).

A whole-survey seabed mesh grows with the surveyed area: ~130 bytes per triangle held, ~250
while it is built (two triangles per square metre at the default 1 m resolution, 1.1 GiB for a
3 M-pulse Palmer survey; 100 M pulses would not fit). :class:`TiledSeabed` keeps the same
regular node grid over the world's extent (:func:`terrain.surface.grid_axis`, the nodes
:meth:`terrain.Surface.to_mesh` uses) but meshes it in square tiles of :data:`TILE_CELLS` cells
on demand, keeping the last :data:`CACHE_TILES` in memory. A chunk of pulses lies along one
flight line, so successive chunks reach the same few tiles.

Exactness. A tile's nodes are the whole grid's nodes over it (the same axis values, heights
from the same surface), triangulated the same way (:func:`terrain.surface.grid_faces`), and a
box (IHO cube, wreck) is meshed whole into every tile its footprint touches
(:func:`terrain.box_mesh.box_triangles`). Each ray walks the tiles its horizontal path crosses,
in order (a 2-D grid traversal, Amanatides & Woo 1987), over the extent and the boxes' parts
past it, casting against each tile's mesh. It keeps the first hit on the tile's own grid (a
triangle of the whole mesh, found as the whole mesh finds it: open3d in float32, the distance
solved in float64 against that triangle's plane, :meth:`MeshCaster.cast`), or on a box where
the hit lies over the tile (a box's triangles past the tile could hide the next tile's seabed,
met first). The path moves away from its start, so no earlier hit lies in a later tile. A
descending ray is not cast against a tile while it stays above the tile's highest vertex (with
a float32 margin), so rays from a high aircraft mesh only the tiles they reach.
Only a ray through an edge shared by two tiles can take the neighbour's triangle: the same
point to float32 rounding (``tests/simulate/test_tiled_seabed.py``; a review's brute force, 6 M
survey-like rays near the origin: 1 distance 3e-8 m apart; 2 M at 10 km: 2 at ~4e-6 m; grazing
rays from kilometres away aimed at tile edges over a 30-degree rough slope: 1 in 200 000 lost,
12 up to 1 cm). Tiles are fixed in space, so chunking and workers do not change hits.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

__all__ = ["CACHE_TILES", "TILE_CELLS", "TiledSeabed"]

#: Cells per tile side (256 m at the default 1 m mesh: ~131 k triangles, ~17 MB held).
TILE_CELLS = 256
#: Tiles kept meshed per process (a chunk's swath crosses 2-4 tiles of 256 m).
CACHE_TILES = 12


def _box_xy_bounds(box) -> tuple[float, float, float, float]:
    """The footprint's corners' box ``(xmin, xmax, ymin, ymax)`` (walls are vertical)."""
    s, c = np.sin(box.heading_rad), np.cos(box.heading_rad)
    u = 0.5 * box.length_m * np.array([-1.0, 1.0, 1.0, -1.0])
    v = 0.5 * box.width_m * np.array([-1.0, -1.0, 1.0, 1.0])
    x = box.x_m + u * s + v * c
    y = box.y_m + u * c - v * s
    return float(x.min()), float(x.max()), float(y.min()), float(y.max())


class TiledSeabed:
    """A seabed caster meshed in tiles on demand (module docstring); same ``cast`` as a mesh.

    Parameters
    ----------
    seabed : terrain.Surface
        The truth's seabed (boxes among its parts are meshed exactly).
    resolution_m : float
        Largest grid spacing, metres.
    extent_m : tuple of 4 float
        ``(xmin, xmax, ymin, ymax)`` meshed, metres.
    tile_cells : int
        Cells per tile side.
    cache_tiles : int
        Tiles kept meshed.
    """

    def __init__(
        self,
        seabed,
        resolution_m: float,
        extent_m,
        tile_cells: int = TILE_CELLS,
        cache_tiles: int = CACHE_TILES,
    ) -> None:
        from terrain.box_mesh import split_boxes
        from terrain.surface import grid_axis

        self.base, self.boxes = split_boxes(seabed)
        self.resolution_m = float(resolution_m)
        xmin, xmax, ymin, ymax = (float(v) for v in extent_m)
        self.x_m = grid_axis(xmin, xmax, self.resolution_m)
        self.y_m = grid_axis(ymin, ymax, self.resolution_m)
        self.tile_cells = int(tile_cells)
        self.cache_tiles = max(1, int(cache_tiles))
        # node indices of the tile edges, and their coordinates
        self.ix = self._edges(self.x_m.size - 1)
        self.iy = self._edges(self.y_m.size - 1)
        self.bx = self.x_m[self.ix]
        self.by = self.y_m[self.iy]
        self.box_bounds = np.array([_box_xy_bounds(b) for b in self.boxes]).reshape(-1, 4)
        # the walk covers the extent and the boxes' parts past it (the whole mesh has them)
        bb = self.box_bounds
        self.walk_m = (
            float(np.min(np.r_[xmin, bb[:, 0]])),
            float(np.max(np.r_[xmax, bb[:, 1]])),
            float(np.min(np.r_[ymin, bb[:, 2]])),
            float(np.max(np.r_[ymax, bb[:, 3]])),
        )
        # how far past its tile a box triangle's hit may lie: open3d picks the triangle in
        # float32 (rounding ~1e-7 of the coordinates), the distance is solved in float64
        self._edge_m = 1e-6 * (1.0 + max(abs(xmin), abs(xmax), abs(ymin), abs(ymax)))
        # a seabed that does not cover the extent (a DEM) fails here, not in a worker's cast
        for x, y in ((self.x_m, ymin), (self.x_m, ymax), (xmin, self.y_m), (xmax, self.y_m)):
            self.base.height_m(*np.broadcast_arrays(np.asarray(x), np.asarray(y)))
        self._tiles: OrderedDict = OrderedDict()
        self._zmax: dict[tuple[int, int], float] = {}  # of each tile asked (zmax)
        self.tiles_built = 0

    def _edges(self, n_cells: int) -> np.ndarray:
        n_tiles = max(1, -(-n_cells // self.tile_cells))
        return np.minimum(np.arange(n_tiles + 1) * self.tile_cells, n_cells)

    @property
    def shape(self) -> tuple[int, int]:
        """Tiles along ``(y, x)``."""
        return self.by.size - 1, self.bx.size - 1

    def __getstate__(self) -> dict:
        # a worker meshes its own tiles: only the recipe travels
        state = dict(self.__dict__)
        state["_tiles"] = OrderedDict()
        return state

    def tile(self, i: int, j: int):
        """The :class:`~pipeline.simulate.trace.MeshCaster` of tile column ``i``, row ``j``."""
        key = (int(i), int(j))
        caster = self._tiles.get(key)
        if caster is not None:
            self._tiles.move_to_end(key)
            return caster
        caster = self._mesh(*key)
        self._tiles[key] = caster
        self.tiles_built += 1
        while len(self._tiles) > self.cache_tiles:
            self._tiles.popitem(last=False)
        return caster

    def zmax(self, i: int, j: int) -> float:
        """Height of tile ``(i, j)``'s highest vertex (its nodes and the boxes on it), m.

        Kept for every tile once asked (a float each), so a ray passing high over a tile
        (from a high aircraft, many tiles) never has it meshed.
        """
        key = (int(i), int(j))
        z = self._zmax.get(key)
        if z is None:
            _, _, heights = self._nodes(*key)
            tops = [self._box_verts(k)[0][:, 2].max() for k in self._touching(*key)]
            z = self._zmax[key] = float(max([heights.max(), *tops]))
        return z

    def _nodes(self, i: int, j: int):
        x = self.x_m[self.ix[i] : self.ix[i + 1] + 1]
        y = self.y_m[self.iy[j] : self.iy[j + 1] + 1]
        xx, yy = np.meshgrid(x, y)
        return xx, yy, np.asarray(self.base.height_m(xx, yy), dtype=np.float64)

    def _touching(self, i: int, j: int) -> np.ndarray:
        """Indices of the boxes whose footprint touches tile ``(i, j)``."""
        x0, x1, y0, y1 = self.bx[i], self.bx[i + 1], self.by[j], self.by[j + 1]
        bb = self.box_bounds
        touch = (bb[:, 0] <= x1) & (bb[:, 1] >= x0) & (bb[:, 2] <= y1) & (bb[:, 3] >= y0)
        return np.flatnonzero(touch)

    def _box_verts(self, k: int):
        from terrain.box_mesh import box_triangles

        return box_triangles(self.boxes[k], self.base, self.resolution_m)

    def _mesh(self, i: int, j: int):
        from pipeline.simulate.trace import MeshCaster
        from terrain.surface import grid_faces

        xx, yy, z = self._nodes(i, j)
        verts = [np.column_stack([xx.ravel(), yy.ravel(), z.ravel()])]
        faces = [grid_faces(xx.shape[1], xx.shape[0])]
        n = verts[0].shape[0]
        for k in self._touching(i, j):
            v, f = self._box_verts(k)
            verts.append(v)
            faces.append(f + n)
            n += v.shape[0]
        return MeshCaster(np.vstack(verts), np.vstack(faces))

    def _over_tile(self, p: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Whether points ``p`` (n, 3) lie over tiles ``(i, j)``; the edge tiles reach out."""
        nx, ny, e = self.bx.size - 1, self.by.size - 1, self._edge_m
        lo_x = np.where(i == 0, -np.inf, self.bx[i] - e)
        hi_x = np.where(i == nx - 1, np.inf, self.bx[np.minimum(i + 1, nx)] + e)
        lo_y = np.where(j == 0, -np.inf, self.by[j] - e)
        hi_y = np.where(j == ny - 1, np.inf, self.by[np.minimum(j + 1, ny)] + e)
        return (p[:, 0] >= lo_x) & (p[:, 0] <= hi_x) & (p[:, 1] >= lo_y) & (p[:, 1] <= hi_y)

    def _n_grid_faces(self, i: int, j: int) -> int:
        """Triangles of tile ``(i, j)``'s own grid (its first ones; the boxes' follow)."""
        return 2 * int(self.ix[i + 1] - self.ix[i]) * int(self.iy[j + 1] - self.iy[j])

    def cast(self, origin_m: np.ndarray, direction: np.ndarray, nthreads: int = 0, t_s=None):
        """First hit of each ray.

        Arguments and results as :meth:`pipeline.simulate.trace.MeshCaster.cast` (``t_s`` is
        ignored: the seabed does not move).
        """
        o = np.asarray(origin_m, dtype=np.float64)
        d = np.asarray(direction, dtype=np.float64)
        n = o.shape[0]
        hit = np.zeros(n, dtype=bool)
        t_hit = np.zeros(n)
        nrm = np.zeros((n, 3))
        t_in, t_out = self._extent_span(o, d)
        active = t_in <= t_out
        p = o[:, :2] + np.where(active, np.maximum(t_in, 0.0), 0.0)[:, None] * d[:, :2]
        nx, ny = self.bx.size - 1, self.by.size - 1
        i = np.clip(np.searchsorted(self.bx, p[:, 0], side="right") - 1, 0, nx - 1)
        j = np.clip(np.searchsorted(self.by, p[:, 1], side="right") - 1, 0, ny - 1)
        for _ in range(nx + ny + 1):  # a path crosses at most this many tiles
            rows = np.flatnonzero(active)
            if rows.size == 0:
                break
            key = j[rows] * nx + i[rows]
            order = np.argsort(key, kind="stable")
            rows, key = rows[order], key[order]
            starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
            for a, b in zip(starts, np.r_[starts[1:], rows.size], strict=True):
                r = rows[a:b]
                key = (int(i[r[0]]), int(j[r[0]]))
                # a descending ray still above the tile's highest vertex where it leaves the
                # tile cannot meet it there (most rays from the aircraft, first tile)
                r = r[~self._above(o[r], d[r], i[r], j[r], self.zmax(*key))]
                if r.size == 0:
                    continue
                h, t, m, face = self.tile(*key).cast_faces(o[r], d[r], nthreads)
                # the tile's own grid triangle is the whole mesh's; a box's may lie past the
                # tile, where the next tile's seabed could come first
                own = face < self._n_grid_faces(*key)
                ok = h & (own | self._over_tile(o[r] + t[:, None] * d[r], i[r], j[r]))
                got = r[ok]
                hit[got], t_hit[got], nrm[got] = True, t[ok], m[ok]
                active[got] = False
            self._step(o, d, rows[active[rows]], i, j, t_out, active)
        return hit, t_hit, nrm

    def _above(self, o, d, i, j, zmax: float) -> np.ndarray:
        """Rays that leave tile ``(i, j)`` descending and still above ``zmax``."""
        t_leave = np.minimum(*self._leave(o, d, i, j))
        down = (d[:, 2] < 0.0) & np.isfinite(t_leave)
        z = o[:, 2] + np.where(down, t_leave, 0.0) * d[:, 2]
        # the tile's triangles are met in float32: keep a ray that is only just above
        return down & (z > zmax + self._edge_m + 1e-6 * np.abs(z))

    def _leave(self, o, d, i, j) -> tuple[np.ndarray, np.ndarray]:
        """Ray parameters at which paths leave tiles ``(i, j)`` across x and across y.

        An edge tile reaches out (boxes past the extent): never left that way.
        """
        out = []
        for axis, edges, k in ((0, self.bx, i), (1, self.by, j)):
            last = edges.size - 2
            da = d[:, axis]
            outward = ((k == last) & (da > 0.0)) | ((k == 0) & (da < 0.0))
            edge = np.where(da > 0.0, edges[np.minimum(k + 1, last + 1)], edges[k])
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where((da == 0.0) | outward, np.inf, (edge - o[:, axis]) / da)
            out.append(t)
        return out[0], out[1]

    def _extent_span(self, o: np.ndarray, d: np.ndarray):
        """Ray parameters ``(t_in, t_out)`` of the horizontal path over the walked area."""
        t_in = np.zeros(o.shape[0])
        t_out = np.full(o.shape[0], np.inf)
        w = self.walk_m
        for axis, lo, hi in ((0, w[0], w[1]), (1, w[2], w[3])):
            oa, da = o[:, axis], d[:, axis]
            flat = da == 0.0
            with np.errstate(divide="ignore", invalid="ignore"):
                t0 = np.where(flat, -np.inf, (lo - oa) / da)
                t1 = np.where(flat, np.inf, (hi - oa) / da)
            inside = (oa >= lo) & (oa <= hi)
            t0, t1 = np.minimum(t0, t1), np.maximum(t0, t1)
            t0 = np.where(flat & ~inside, np.inf, t0)  # never over the area
            t1 = np.where(flat & ~inside, -np.inf, t1)
            t_in, t_out = np.maximum(t_in, t0), np.minimum(t_out, t1)
        return t_in, t_out

    def _step(self, o, d, rows, i, j, t_out, active) -> None:
        """Move rays ``rows`` to the next tile along their path; end those leaving the area."""
        if rows.size == 0:
            return
        nx, ny = self.bx.size - 1, self.by.size - 1
        tx, ty = self._leave(o[rows], d[rows], i[rows], j[rows])
        t_next = np.minimum(tx, ty)
        leave = ~np.isfinite(t_next) | (t_next >= t_out[rows])
        i[rows] += np.where(tx <= ty, np.sign(d[rows, 0]), 0).astype(i.dtype)
        j[rows] += np.where(ty <= tx, np.sign(d[rows, 1]), 0).astype(j.dtype)
        leave |= (i[rows] < 0) | (i[rows] >= nx) | (j[rows] < 0) | (j[rows] >= ny)
        active[rows[leave]] = False
