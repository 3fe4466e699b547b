"""Surveys too large to hold: processing block by block after the chunk loop (issue 15).

A survey whose pulses outnumber ``run.whole_pulses`` or ``run.block_pulses`` (or any survey,
when ``run.block_m`` is set: :func:`~pipeline.memory_budget.held_whole`) is not loaded back
from the :class:`~pipeline.detection_store.DetectionStore` whole.
After the chunk loop it runs in four passes, each holding a bounded part of the survey:

1. **Blocks.** Square blocks of whole grid cells over the grid's bounds (:func:`block_layout`:
   ``run.block_m``, else sized so that a block and its halo hold about ``run.block_pulses``
   pulses). A pulse belongs to the block of its position
   (:func:`~pipeline.detection_store.pulse_position_m`); one pass over the stored chunks counts
   them.
2. **Sample.** Whole blocks (of about an eighth of ``run.sample_pulses`` each) spread over
   the survey, at most ``run.sample_pulses`` pulses in all (:func:`sample_blocks`: every block
   when the survey has fewer), are loaded (no halo) and processed as a survey of their own
   (:func:`~pipeline.survey_processing.process_survey`). They give the survey-wide figures
   (:class:`~pipeline.survey_processing.SurveyFigures`: processing's water level, sea and
   facet figures, the TPU's, the datum, the class-41 height range) and they are what the
   posteriors, the evaluation, the views and the report see.
3. **Beam reach.** One pass over the chunks measures the farthest reach of a beam from its
   pulse's position (:func:`~pipeline.process_tiles.beam_reach_m`, a maximum: the same
   streamed) at the sample's water level; it sets the halo (:func:`block_halo_m`).
4. **Every block** with its halo: processed with the sample's figures handed in (its local
   planes and kriged sea made only where what it keeps reads them,
   :mod:`pipeline.survey_block_reach`; its TPU and tests only at the points it keeps,
   :func:`tpu_points`); its own pulses' points are appended to ``points.laz``
   (:class:`~pipeline.outputs.las.LazTileWriter`)
   and its own cells (:func:`own_cells`) go to disk at once, into the survey's grid
   (:class:`~pipeline.outputs.grid_tiles.GridTiles`, which writes ``grid.tif`` and
   ``grid.nc`` from there window by window). Nothing of a block stays. The blocks run side
   by side on the run's executor (:mod:`pipeline.survey_block_task`: a pure function of the
   block, written in block order), its workers reading the store through
   :meth:`~pipeline.detection_store.DetectionStore.reader`.

What stays in memory across blocks: the coverage's cells (one byte per grid cell, sized by
the area), the sample's products (set aside on disk while the blocks run; its own grid and
cells hold only the rows and columns of the survey's grid its points are in,
:mod:`pipeline.process.grid_axes`), the kept waveforms (bounded by the posterior budget) and
at most as many blocks' own points as blocks run at once.

**Exact where the searches stay in the halo.** With every block in the sample, the figures
are the whole survey's, and each block's own points, cells and TPU are the whole survey's
wherever its neighbour searches stay inside its halo (as for tiles,
:mod:`pipeline.process_tiles`): ``tests/test_survey_blocks.py`` compares a blocked run with
the same survey processed whole. With a sample smaller than the survey, the figures are the
sample's: a survey has one sea and one water level, which whole blocks spread over it measure.

Posteriors sample the sample's soundings; the delivered grid's cells carry the TPU (no
posterior), and the views show the sample's points.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.detection_store import POSITION_FIELDS, detected_returns, pulse_position_m
from pipeline.survey_tiles import TileLayout, chunks_meeting, snap_tile_m

__all__ = [
    "is_blocked",
    "block_layout",
    "block_halo_m",
    "pulse_counts",
    "sample_blocks",
    "blocks_to_process",
    "load_blocks",
    "own_cells",
    "tests_reach_m",
    "tpu_points",
    "LineSums",
    "with_survey_lines",
]


def is_blocked(scene, n_pulses: int) -> bool:
    """Whether the survey is processed block by block (module notes)."""
    from pipeline.memory_budget import held_whole

    return not held_whole(scene.run, n_pulses)


def block_halo_m(ctx, ps, beam_reach_m: float) -> float:
    """How far past a block its pulses are loaded (m).

    In turn, from a block's own cells outwards: a cell holds the points of pulses positioned
    up to a beam reach outside the block; the class-43 and rejection tests read their
    neighbours' TPU within ``process.objects.radius_m`` (and the reference cells at the far
    edge); each TPU its neighbours' points within the TPU's reach
    (:func:`~pipeline.uncertainty.tpu_survey_wide.tpu_halo_m`); each point its processing's
    neighbours (:func:`~pipeline.process_tiles.processing_halo_m`: the beam reach, the surface
    fit's, kriging's, land's and the class-45 test's radii).
    """
    from pipeline.process_tiles import processing_halo_m
    from pipeline.uncertainty.tpu_survey_wide import tpu_halo_m

    proc = processing_halo_m(ctx, beam_reach_m, classify=ps.classify)
    return float(beam_reach_m + tests_reach_m(ps) + tpu_halo_m(ctx.tpu) + proc)


def tests_reach_m(ps) -> float:
    """How far the class-43 and rejection tests of a point read other points' TPU (m).

    The rejection test (:func:`~pipeline.process.seabed_outliers.reject_seabed_outliers`)
    fits its plane to the reference points (a cell median each) of the soundings within
    ``process.objects.radius_m`` that are still class 40: which they are depends on their
    own TPU (their class-43 test and the TVU rule), up to a reference cell's diagonal
    further. The class-43 test reads only the point's own TPU.
    """
    return float(ps.objects.radius_m + math.sqrt(2.0) * ps.objects.reference_cell_m)


def tpu_points(points, own_pulse_id: np.ndarray, box_m, reach_m: float) -> np.ndarray:
    """The points whose TPU a block keeps, ``(n_points,)`` bool; its tests are made there too.

    A block keeps the TPU of its own pulses' points and of the points in its own cells, and
    the tests of those read the TPU of the points within ``reach_m`` (:func:`tests_reach_m`).
    The class-43 and rejection tests are made at the same points
    (:func:`~pipeline.survey_cleanup.objects_and_rejections`): a kept point's rejection reads
    the class-43 results within ``reach_m``, and those read nothing but their own TPU.
    So: every point within ``reach_m`` of the box holding the block (``box_m``, ``(w, e, s,
    n)``) and its own pulses' points (a beam reach beyond it, at most), a square margin (a
    superset of the round one).

    Parameters
    ----------
    points : Points
        The block's points, its halo's included, ``(n_points,)``.
    own_pulse_id : (n_own,) int
        The block's own pulses.
    box_m : (4,) float
        The block's own cells, ``(w, e, s, n)`` (m, local frame).
    reach_m : float
    """
    own = np.isin(points.pulse_id, own_pulse_id)
    x, y = points.xyz_m[:, 0], points.xyz_m[:, 1]
    w, e, s, n = (float(v) for v in box_m)
    if own.any():
        w, e = min(w, float(x[own].min())), max(e, float(x[own].max()))
        s, n = min(s, float(y[own].min())), max(n, float(y[own].max()))
    near = (x >= w - reach_m) & (x <= e + reach_m) & (y >= s - reach_m) & (y <= n + reach_m)
    return near | own


def block_layout(
    scene, bounds_m: np.ndarray, n_pulses: int, halo_m: float, pulses: int | None = None
) -> TileLayout:
    """The blocks over the grid ``bounds_m`` (``run.block_m``, else from the pulse density).

    Without ``run.block_m`` a block's side ``s`` is such that ``(s + 2 halo)²`` holds
    ``pulses`` (default ``run.block_pulses``) pulses at the survey's mean density over the
    bounds (at least the halo, so the halo does not dominate the work), whole grid cells.
    """
    r = scene.process.grid_resolution_m
    w, e, s, n = bounds_m
    extent = max(e - w, n - s)
    side = scene.run.block_m
    if side is None:
        density = max(n_pulses, 1) / max((e - w) * (n - s), r * r)
        want = scene.run.block_pulses if pulses is None else pulses
        side = max(math.sqrt(want / density) - 2.0 * halo_m, halo_m, r)
    return TileLayout(np.asarray(bounds_m, dtype=np.float64), r, snap_tile_m(side, r, extent))


def _positions(store, c: int) -> np.ndarray:
    names = [k for k in POSITION_FIELDS if k in store.fields(c)]
    return pulse_position_m(store.load_chunk(c, names), store.air_index)


def pulse_counts(store, layout: TileLayout) -> np.ndarray:
    """Pulses of each block, ``(n_blocks,)`` int64: one pass over the stored chunks."""
    counts = np.zeros(layout.n_tiles, dtype=np.int64)
    for c in range(len(store.chunks)):
        pos = _positions(store, c)
        counts += np.bincount(layout.tile_of_xy(pos[:, 0], pos[:, 1]), minlength=counts.size)
    return counts


def _halton(k: int, base: int) -> float:
    """The ``k``-th term of the van der Corput sequence in ``base`` (Halton's coordinate)."""
    out, f = 0.0, 1.0 / base
    while k:
        k, digit = divmod(k, base)
        out += digit * f
        f /= base
    return out


def sample_blocks(
    counts: np.ndarray, max_pulses: int, shape: tuple[int, int] | None = None
) -> np.ndarray:
    """Blocks spread over the survey holding at most ``max_pulses`` pulses (sorted indices).

    Every block with a pulse when they hold at most ``max_pulses``. Else, for the Halton
    points ``(h_2(k), h_3(k))``, ``k = 1, 2, ...`` over the layout (columns by rows, scaled
    to 1), the block with a pulse nearest each not yet taken, while their pulses stay within
    ``max_pulses``; at least one block. Halton points fill the square evenly at every
    length, so every prefix is spread over both axes, whatever the layout's shape.

    Parameters
    ----------
    counts : (n_blocks,) int
        Pulses per block, the layout's order (row by row from the north-west).
    max_pulses : int
    shape : (int, int), optional
        The layout's rows and columns; default one row.
    """
    used = np.flatnonzero(counts > 0)
    if used.size == 0 or counts[used].sum() <= max_pulses:
        return used
    rows, cols = (1, counts.size) if shape is None else shape
    row, col = np.divmod(used, cols)
    u, v = (col + 0.5) / cols, (row + 0.5) / rows
    free = np.ones(used.size, dtype=bool)
    picked, total, k = [], 0, 0
    while free.any():
        k += 1
        d = (u - _halton(k, 2)) ** 2 + (v - _halton(k, 3)) ** 2
        j = int(np.argmin(np.where(free, d, np.inf)))
        if picked and total + counts[used[j]] > max_pulses:
            break
        free[j] = False
        picked.append(used[j])
        total += int(counts[used[j]])
    return np.sort(np.array(picked, dtype=np.int64))


def blocks_to_process(layout: TileLayout, counts: np.ndarray, reach_m: float) -> np.ndarray:
    """Blocks whose cells can hold a point: within a beam reach of a block with pulses.

    A pulse's points lie up to ``reach_m`` from its position, so a block without pulses of
    its own next to one with them can hold points in its cells (the edge of a swath). Sorted
    indices of the blocks within ``ceil(reach / side)`` blocks of one with a pulse.
    """
    rows, cols = layout.shape
    has = (counts > 0).reshape(rows, cols)
    k = int(math.ceil(reach_m / layout.tile_m)) if reach_m > 0.0 else 0
    near = has.copy()
    for di in range(-k, k + 1):
        for dj in range(-k, k + 1):
            src = has[max(0, -di) : rows - max(0, di), max(0, -dj) : cols - max(0, dj)]
            near[max(0, di) : rows - max(0, -di), max(0, dj) : cols - max(0, -dj)] |= src
    return np.flatnonzero(near.ravel())


def _grown_boxes(layout: TileLayout, blocks, halo: float) -> np.ndarray:
    """``(m, 4)`` boxes of ``blocks`` grown by ``halo``; open outwards at the grid's edges."""
    w, e, s, n = layout.bounds_m
    out = []
    for b in blocks:
        x0, x1, y0, y1 = layout.box_m(int(b))
        # an edge block owns the pulses beyond the grid (the nearest tile): its box is open
        out.append(
            [
                -np.inf if x0 <= w else x0 - halo,
                np.inf if x1 >= e else x1 + halo,
                -np.inf if y0 <= s else y0 - halo,
                np.inf if y1 >= n else y1 + halo,
            ]
        )
    return np.array(out, dtype=np.float64).reshape(-1, 4)


def load_blocks(store, layout: TileLayout, blocks, halo: float):
    """The stored pulses of ``blocks`` and of their halo, in pulse order.

    Returns
    -------
    returns : DetectedReturns or None
        None: no stored pulse lies there.
    own : (n,) bool or None
        The pulse's position lies in one of ``blocks``.
    """
    blocks = np.asarray(blocks, dtype=np.int64)
    boxes = _grown_boxes(layout, blocks, halo)
    chunks = sorted({c for box in boxes for c in chunks_meeting(store.chunks, box, 0.0)})
    parts, owns = [], []
    for c in chunks:
        part = store.load_chunk(c)
        pos = pulse_position_m(part, store.air_index)
        x, y = pos[:, 0], pos[:, 1]
        own = np.isin(layout.tile_of_xy(x, y), blocks)
        near = own.copy()
        for x0, x1, y0, y1 in boxes:
            near |= (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        parts.append({k: v[near] for k, v in part.items()})
        owns.append(own[near])
    if not parts or not sum(len(o) for o in owns):
        return None, None
    keys = set.intersection(*(set(p) for p in parts))
    cat = {k: np.concatenate([p[k] for p in parts]) for k in keys}
    return detected_returns(cat), np.concatenate(owns)


def _sub_layout(layout: TileLayout, b: int, halo: float) -> tuple[TileLayout, int, int]:
    """A one-tile layout over block ``b`` grown by ``halo`` (whole cells, within the grid).

    Returns the layout and the survey grid's row and column of its north-west cell.
    """
    r = layout.resolution_m
    w, e, s, n = layout.bounds_m
    x0, x1, y0, y1 = layout.box_m(b)
    cw = max(w, w + math.floor((x0 - halo - w) / r) * r)
    ce = min(e, w + math.ceil((x1 + halo - w) / r) * r)
    cn = min(n, n - math.floor((n - y1 - halo) / r) * r)
    cs = max(s, n - math.ceil((n - y0 + halo) / r) * r)
    bounds = np.array([cw, ce, cs, cn])
    sub = TileLayout(bounds, r, snap_tile_m(None, r, max(ce - cw, cn - cs)))
    return sub, int(round((n - cn) / r)), int(round((cw - w) / r))


def own_cells(
    layout: TileLayout, b: int, row0: int, col0: int
) -> tuple[tuple[slice, slice], tuple[slice, slice]]:
    """Block ``b``'s own cells, ``(dst, src)``: their rows and columns in the survey's grid.

    ``dst`` in the survey's grid, ``src`` in the block's grid, whose north-west cell is the
    survey grid's ``row0, col0`` (:func:`_sub_layout`).
    """
    k = layout.cells_per_tile
    ny, nx = layout.grid_shape
    i, j = divmod(int(b), layout.shape[1])
    r0, r1 = i * k, min((i + 1) * k, ny)
    c0, c1 = j * k, min((j + 1) * k, nx)
    dst = (slice(r0, r1), slice(c0, c1))
    return dst, (slice(r0 - row0, r1 - row0), slice(c0 - col0, c1 - col0))


@dataclass
class LineSums:
    """Each flight line's pulse origins as sums, gathered part by part: its axis streamed.

    The axis is :func:`~pipeline.process.facet_excess.line_axes`' (the major axis of the
    origins' 2 x 2 scatter), from sums about the first origin seen of each line (the same
    figure up to rounding).
    """

    line: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    ref: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    s: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    ss: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def add(self, returns) -> None:
        """Take in more pulses (``origin_meas_m``, ``line_id``)."""
        xy = returns.origin_meas_m[:, :2]
        ids, first, inv = np.unique(returns.line_id, return_index=True, return_inverse=True)
        line = np.union1d(self.line, ids)
        at_old, at_new = np.searchsorted(line, self.line), np.searchsorted(line, ids)
        ref = np.zeros((line.size, 2))
        ref[at_new] = xy[first]
        ref[at_old] = self.ref  # a line keeps the first reference it had
        grow = [np.zeros((line.size, *a.shape[1:])) for a in (self.n, self.s, self.ss)]
        for g, a in zip(grow, (self.n, self.s, self.ss), strict=True):
            g[at_old] = a
        d = xy - ref[at_new][inv.ravel()]
        k = at_new[inv.ravel()]
        np.add.at(grow[0], k, 1.0)
        np.add.at(grow[1], k, d)
        np.add.at(grow[2], k, np.column_stack([d[:, 0] ** 2, d[:, 1] ** 2, d[:, 0] * d[:, 1]]))
        self.line, self.ref, (self.n, self.s, self.ss) = line, ref, grow

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """``(line_ids (m,), unit axes (m, 2))``."""
        n = np.maximum(self.n, 1.0)
        sxx = self.ss[:, 0] - self.s[:, 0] ** 2 / n
        syy = self.ss[:, 1] - self.s[:, 1] ** 2 / n
        sxy = self.ss[:, 2] - self.s[:, 0] * self.s[:, 1] / n
        ang = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
        return self.line, np.column_stack([np.cos(ang), np.sin(ang)])


def _with_more_lines(ids, axes, more_ids, more_axes):
    """``ids, axes`` with the lines of ``more_ids`` they lack (sorted by line)."""
    ids, axes = np.asarray(ids), np.asarray(axes).reshape(-1, 2)
    missing = ~np.isin(more_ids, ids)
    if not missing.any():
        return ids, axes
    all_ids = np.concatenate([ids, more_ids[missing]])
    all_axes = np.concatenate([axes, more_axes[missing]])
    order = np.argsort(all_ids, kind="stable")
    return all_ids[order], all_axes[order]


def with_survey_lines(figures, line_ids: np.ndarray, line_axes: np.ndarray):
    """``figures`` whose line tables hold every line of the survey.

    A sample of blocks may miss flight lines (or hold only a part of one): a block on a line
    the sample missed needs its axis (the facet correction's and the TPU's along-track axes).
    The sample's own lines keep the axes it measured (so a sample of every block keeps the
    whole survey's); the others get the streamed ones (:class:`LineSums`).
    """
    wide, tw = figures.wide, figures.tpu_wide
    if wide is not None and wide.sea.facets is not None:
        f = wide.sea.facets
        ids, axes = _with_more_lines(f.line_id, f.axis_xy, line_ids, line_axes)
        sea = dataclasses.replace(
            wide.sea, facets=dataclasses.replace(f, line_id=ids, axis_xy=axes)
        )
        wide = dataclasses.replace(wide, sea=sea)
    if tw is not None:
        ids, axes = _with_more_lines(tw.line_ids, tw.line_axes, line_ids, line_axes)
        facets = tw.facets
        if facets is not None:
            f_ids, f_axes = _with_more_lines(facets.line_id, facets.axis_xy, line_ids, line_axes)
            facets = dataclasses.replace(facets, line_id=f_ids, axis_xy=f_axes)
        tw = dataclasses.replace(tw, line_ids=ids, line_axes=axes, facets=facets)
    return dataclasses.replace(figures, wide=wide, tpu_wide=tw)
