"""Checks a scene must pass before a run starts: the CRS parses, the survey fits the machine.

Validation of each key alone (:mod:`pipeline.config`) cannot see that ``scanner.prf_hz = 1e300``
makes more pulses than can be counted, that ``seabed.mesh_resolution_m = 1e-300`` asks for a
mesh of 1e600 nodes, or that ``frame.crs = "text"`` is no CRS; those used to fail at run time
with a traceback (OverflowError, a CRS error at output time). Here they are one
:class:`~pipeline.errors.SceneError` line with the figure, at ``bathy validate`` and
``bathy run`` alike.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from pathlib import Path

from pipeline.errors import SceneError
from pipeline.memory_budget import (
    MEMORY_SHARE,
    VIEWS_CHILD_BYTES,
    held_bytes,
    held_whole,
    machine_memory_bytes,
)

__all__ = ["blocked_grid_cells", "check_disk", "check_feasible", "machine_memory_bytes"]

#: Per node of a meshed seabed tile (:mod:`pipeline.simulate.tiled_seabed`): float64 vertices
#: (24 B), two triangles' indices, normals and points (144 B), open3d's float32 copy and BVH.
BYTES_PER_MESH_NODE = 256.0
#: Per node of the roughness field's periodic tile: heights, spline coefficients, the FFT's
#: complex spectrum while it is synthesised.
BYTES_PER_ROUGHNESS_NODE = 48.0
#: Per node of the seabed grid's two axes (float64, kept whole for the tiles' exact nodes).
BYTES_PER_AXIS_NODE = 8.0
#: Disk a survey run writes per pulse: its detection store (337 B measured on the Palmer scene,
#: plus the fields processing rewrites) and its points (41 B in LAZ).
DISK_BYTES_PER_PULSE = 450.0
#: Share of the free disk a run may plan to fill.
DISK_SHARE = 0.9
#: Temporary disk a blocked survey's grid takes per cell at its fullest
#: (:class:`~pipeline.outputs.grid_tiles.GridTiles`, in the system's temporary directory): the
#: cells' raw file (29 B, for the whole run), and while ``grid.tif`` is written the tiled
#: GeoTIFF it is copied from (6 float32 bands, uncompressed: 24 B) beside the finished COG
#: (at most those bands and their overviews, 32 B: DEFLATE only shrinks them). ``grid.nc`` is
#: staged there after the GeoTIFFs are gone (compressed, less than them).
TEMP_BYTES_PER_CELL = 29.0 + 24.0 + 32.0


def check_feasible(scene) -> None:
    """Raise :class:`SceneError` if ``scene`` cannot run here; return None otherwise.

    Parameters
    ----------
    scene : Scene
        A scene whose keys passed validation one by one.
    """
    _check_crs(scene.frame.crs)
    if scene.flight is not None:
        _check_survey(scene)


def _check_crs(crs: str) -> None:
    import pyproj

    try:
        parsed = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError as exc:
        raise SceneError(
            f"`frame.crs` must be a projected CRS in metres (e.g. 'EPSG:32631'); got {crs!r}: "
            f"{str(exc).splitlines()[0]}"
        ) from None
    units = {a.unit_name for a in parsed.axis_info[:2]}
    if not parsed.is_projected or not units <= {"metre", "meter"}:
        raise SceneError(
            f"`frame.crs` must be a projected CRS in metres (e.g. 'EPSG:32631'); got {crs!r}"
            f" ({parsed.name}, axis units {', '.join(sorted(units)) or 'none'})."
        )


def _check_survey(scene) -> None:
    from pipeline.run_survey import survey_extent_m
    from pipeline.simulate.trajectory import plan_lines

    fl, sc = scene.flight, scene.scanner
    try:
        lines = plan_lines(fl, sc)
    except (OverflowError, ValueError, MemoryError):
        raise SceneError(
            f"the flight plan gives more pulses than can be counted: `scanner.prf_hz` ="
            f" {sc.prf_hz:g}, `flight.speed_m_s` = {fl.speed_m_s:g}, `flight.area_m` ="
            f" {list(fl.area_m)}, `flight.line_length_m` = {fl.line_length_m},"
            f" `flight.run_in_m` = {fl.run_in_m:g}, `flight.altitude_m` = {fl.altitude_m:g}"
            " (the swath sets the number of lines); lower the pulse rate or the area."
        ) from None
    _check_photon_windows(scene)
    mem = MEMORY_SHARE * machine_memory_bytes()
    n = lines.n_pulses_total
    run = getattr(scene, "run", None)
    blocked = run is not None and not held_whole(run, n)
    if run is None:
        need = held_bytes(n, n, n, False)
    else:
        need = held_bytes(n, run.block_pulses, run.sample_pulses, blocked)
        need += VIEWS_CHILD_BYTES if run.views else 0.0
    if need > mem:
        if not blocked:
            how = (
                "held whole"
                if run is None
                else "held whole (no more pulses than the smaller of `run.whole_pulses` ="
                f" {run.whole_pulses:_} and `run.block_pulses` = {run.block_pulses:_})"
            )
        else:
            size = (
                f"`run.block_m` = {run.block_m:g} m, at most `run.block_pulses` ="
                f" {run.block_pulses:_} planned"
                if run.block_m is not None
                else f"`run.block_pulses` = {run.block_pulses:_}"
            )
            how = (
                f"blocked: its sample (`run.sample_pulses` = {run.sample_pulses:_}) held whole"
                f" and blocks of {size}"
            )
        raise SceneError(
            f"`scanner.prf_hz` = {sc.prf_hz:g} over `flight.area_m` = {list(fl.area_m)} gives"
            f" {n:.3g} pulses, {how}: about {need / 1e9:.3g} GB"
            f" (pipeline/memory_budget.py), more than {mem / 1e9:.3g} GB ({MEMORY_SHARE:.0%} of"
            " this machine's memory); lower the pulse rate, the area, `flight.n_lines`,"
            " `run.whole_pulses`, `run.block_pulses` or `run.sample_pulses`."
        )
    extent = survey_extent_m(scene, lines)
    _check_window_keys(scene, lines, extent)
    sb = scene.seabed
    if sb.kind == "dem":
        return
    _check_seabed_grid(sb, extent, mem)


def _existing(path: Path) -> Path:
    """``path``'s nearest existing ancestor (itself when it exists), absolute."""
    where = Path(path).absolute()
    while not where.exists() and where != where.parent:
        where = where.parent
    return where


def blocked_grid_cells(scene, lines) -> int:
    """Cells of the grid a blocked survey writes through temporary disk; 0: not blocked.

    The grid's bounds are the survey's extent (:func:`~pipeline.run_survey.survey_extent_m`)
    snapped outwards to whole cells: at most one more cell each way than the extent holds.
    """
    from pipeline.run_survey import survey_extent_m
    from pipeline.survey_blocks import is_blocked

    if not is_blocked(scene, lines.n_pulses_total):
        return 0
    xmin, xmax, ymin, ymax = survey_extent_m(scene, lines)
    r = scene.process.grid_resolution_m
    return (math.ceil((xmax - xmin) / r) + 1) * (math.ceil((ymax - ymin) / r) + 1)


def check_disk(n_pulses: int, out: Path, grid_cells: int = 0, resolution_m: float = 0.0) -> None:
    """Raise :class:`SceneError` if the run's files overfill ``out``'s or the temporary disk.

    Parameters
    ----------
    n_pulses : int
        The survey's pulses: their detections and points go under ``out``.
    out : Path
        The output folder, or any path under which it will be (its nearest existing parent
        is measured).
    grid_cells : int
        Cells of a blocked survey's grid (:func:`blocked_grid_cells`), written through the
        system's temporary directory (``tempfile.gettempdir()``: ``TMPDIR``, else ``/tmp``);
        0: none.
    resolution_m : float
        Their side (``process.grid_resolution_m``), for the message.
    """
    where = _existing(out)
    free = DISK_SHARE * shutil.disk_usage(where).free
    need = DISK_BYTES_PER_PULSE * n_pulses
    if need > free:
        raise SceneError(
            f"the survey's {n_pulses:.3g} pulses need about {need / 1e9:.3g} GB of disk at"
            f" {DISK_BYTES_PER_PULSE:g} B per pulse, more than the {free / 1e9:.3g} GB free at"
            f" {where}; lower `scanner.prf_hz`, the area or `flight.n_lines`, or write elsewhere."
        )
    if grid_cells <= 0:
        return
    tmp = _existing(Path(tempfile.gettempdir()))
    tmp_free = DISK_SHARE * shutil.disk_usage(tmp).free
    tmp_need = TEMP_BYTES_PER_CELL * grid_cells
    # one disk for both: the outputs' share of it is taken already
    same = os.stat(tmp).st_dev == os.stat(where).st_dev
    total = tmp_need + (need if same else 0.0)
    if total > tmp_free:
        also = f" (with the outputs' {need / 1e9:.3g} GB: the same disk)" if same else ""
        raise SceneError(
            f"`process.grid_resolution_m` = {resolution_m:g} gives the blocked survey's grid"
            f" {grid_cells:.3g} cells: about {tmp_need / 1e9:.3g} GB of temporary disk at"
            f" {TEMP_BYTES_PER_CELL:g} B per cell{also}, more than the {tmp_free / 1e9:.3g} GB"
            f" free at {tmp} (the system's temporary directory, TMPDIR); raise"
            " `process.grid_resolution_m`, lower the area, or set TMPDIR to a larger disk."
        )


def _check_seabed_grid(sb, extent, mem: float) -> None:
    """The seabed's meshed tiles, grid axes and roughness tile fit in memory."""
    from pipeline.simulate.tiled_seabed import CACHE_TILES, TILE_CELLS

    xmin, xmax, ymin, ymax = extent
    res = sb.mesh_resolution_m
    axis_nodes = ((xmax - xmin) + (ymax - ymin)) / res if res > 1e-150 else math.inf
    need = BYTES_PER_MESH_NODE * CACHE_TILES * (TILE_CELLS + 1) ** 2
    need += BYTES_PER_AXIS_NODE * axis_nodes
    if sb.roughness_rms_m > 0:
        sp = sb.roughness_spacing_m
        px0, px1, py0, py1 = sb.roughness_period(extent)
        nodes = (px1 - px0) * (py1 - py0) / sp**2 if sp > 1e-150 else math.inf
        need += BYTES_PER_ROUGHNESS_NODE * nodes
    if need > mem:
        raise SceneError(
            f"`seabed.mesh_resolution_m` = {res:g} (roughness grid spacing"
            f" {sb.roughness_spacing_m:g} m) over the {xmax - xmin:.0f} x {ymax - ymin:.0f} m"
            f" survey extent is {axis_nodes:.3g} grid nodes along its sides: about"
            f" {need / 1e9:.3g} GB, more than {mem / 1e9:.3g} GB; use a coarser resolution"
            " (or a longer `seabed.roughness_correlation_m`)."
        )


#: Ground a photon-counting window of consecutive shots may sweep under a scanner, m: beyond
#: it the window's one surface and one bottom stand for a strip of changing sea and seabed
#: (a Palmer circle of 134 m radius sweeps 84 m per 200 shots at 32 kHz and 20 Hz).
MAX_WINDOW_SWEEP_M = 10.0


def _check_photon_windows(scene) -> None:
    """Refuse a photon-counting scanner's windows of consecutive shots (they sweep the scan)."""
    sc, pd = scene.scanner, scene.process.photon_detect
    if scene.detector.mode != "photon_counting" or pd.window_cell_m != 0.0:
        return  # cells given, or sized from the plan (None)
    if sc.kind == "profiler" or sc.scan_rate_hz == 0.0:
        return
    h = scene.flight.altitude_m
    if sc.kind == "palmer":  # the beam's ground speed on its circle
        per_s = 2.0 * math.pi * h * math.tan(math.radians(sc.off_nadir_deg)) * sc.scan_rate_hz
    else:  # a mirror sweeping the swath there and back each cycle
        per_s = 4.0 * h * math.tan(math.radians(sc.scan_half_angle_deg)) * sc.scan_rate_hz
    sweep = per_s * pd.shots_per_window / sc.prf_hz
    if sweep > MAX_WINDOW_SWEEP_M:
        raise SceneError(
            f"`process.photon_detect.window_cell_m` = 0 with `scanner.kind` = {sc.kind!r}: each"
            f" window of `shots_per_window` = {pd.shots_per_window} consecutive shots sweeps"
            f" {sweep:.0f} m of the scan (at most {MAX_WINDOW_SWEEP_M:g}); set window_cell_m > 0"
            " or leave it unset (cells sized from the plan)."
        )


def _check_window_keys(scene, lines, extent_m) -> None:
    """Refuse cell windows whose keys would not fit (before the run, not inside a chunk).

    See :func:`pipeline.process.photon_windows.window_keys`.
    """
    from pipeline.process.photon_windows import MAX_CELL_INDEX, MAX_SLABS, resolve_windows

    if scene.detector.mode != "photon_counting":
        return
    fl, pd = scene.flight, scene.process.photon_detect
    win = resolve_windows(
        pd.shots_per_window, pd.window_cell_m, scene.scanner, fl.altitude_m, fl.speed_m_s
    )
    if win.cell_m <= 0.0:
        return
    reach = max(abs(v) for v in extent_m) / win.cell_m
    slabs = lines.n_pulses_total / win.slab_shots
    if reach >= MAX_CELL_INDEX or slabs >= MAX_SLABS:
        raise SceneError(
            f"`process.photon_detect.window_cell_m` = {win.cell_m:g} m: the survey reaches"
            f" {reach:.3g} cells from the frame's origin in {slabs:.3g} slabs (at most"
            f" {MAX_CELL_INDEX} and {MAX_SLABS}); use larger cells or a closer frame origin."
        )
