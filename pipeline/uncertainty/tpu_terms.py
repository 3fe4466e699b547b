"""The TPU's perturbation machinery: each input moved by a small step, the points recomputed.

Private to :mod:`pipeline.uncertainty.tpu` and its siblings: :func:`_terms` gives each
uncertainty term's effect on x, y, z and the depth at the measured position.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from pipeline.parallel import thread_map
from pipeline.process.refraction import RefractionSettings, seabed_xyz_depth
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface
from pipeline.uncertainty.tpu_screen import (
    max_timing_step_s,
)
from pipeline.uncertainty.tpu_settings import (
    CORRELATED_TERMS,
    DEPTH,
    RANDOM_TERMS,
    TpuSettings,
    index_derivatives,
)
from pipeline.uncertainty.wave_pool import surface_wave_sigma_m


def _take_surface(surface: WaterSurface, index: np.ndarray) -> WaterSurface:
    rows = {
        f.name: getattr(surface, f.name)[index]
        for f in dataclasses.fields(surface)
        if f.name not in WaterSurface.SURVEY_FIELDS and getattr(surface, f.name) is not None
    }
    return dataclasses.replace(surface, **rows)


def _on_plane(o, d, point, normal, water):
    """Range and entry of beams ``(o, d)`` on planes ``(point, normal)`` (water rows only)."""
    den = np.sum(normal * d, axis=1)
    den = np.where(water & (den < -1e-9), den, -1.0)
    r = np.sum(normal * (point - o), axis=1) / den
    return r, o + d * r[:, None]


def _rotate(v, axis, angle):
    """Rodrigues rotation of rows ``v`` about unit ``axis`` rows by ``angle`` (n,)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=1)[:, None] * (1.0 - c)


def _perp_axes(d):
    """Two unit vectors perpendicular to the unit rows ``d`` (and to each other)."""
    ref = np.where(np.abs(d[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    a = np.cross(d, ref)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    return a, np.cross(d, a)


@dataclass(frozen=True)
class _Inputs:
    """The bottom pulses and everything the perturbations need."""

    ret: DetectedReturns
    surf: WaterSurface
    rst: RefractionSettings
    sig_ts: np.ndarray
    sig_tb: np.ndarray
    wave_h: np.ndarray
    row: np.ndarray
    grad: np.ndarray
    #: derivatives already made of these rows (``moves`` of
    #: :class:`~pipeline.uncertainty.tpu_derivatives.Derivatives`), or None
    derivatives: dict | None = None


def _take_inputs(inp: _Inputs, keep: np.ndarray) -> _Inputs:
    """The rows ``keep`` (bool over the bottom rows, or their indices) of every per-pulse input."""
    known = inp.derivatives
    return dataclasses.replace(
        inp,
        ret=inp.ret.select(keep),
        surf=_take_surface(inp.surf, keep),
        derivatives=None if known is None else {k: v[keep] for k, v in known.items()},
        **{k: getattr(inp, k)[keep] for k in ("sig_ts", "sig_tb", "wave_h", "row", "grad")},
    )


def _per_row(name, value, n, cols=None):
    """A per-bottom-row input, validated; None gives zeros; NaN becomes 0."""
    shape = (n,) if cols is None else (n, cols)
    if value is None:
        return np.zeros(shape)
    a = np.asarray(value, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"`{name}` must have the shape (n_bottom[, 2]) = {shape}; got {a.shape}")
    return np.where(np.isfinite(a), a, 0.0)


def _inputs(
    returns, surface, rst, st, seabed_gradient=None, surface_tilt_sigma_rad=None, wave_sigma_m=None
):
    if len(surface) != len(returns):
        raise ValueError(f"`surface` has {len(surface)} pulses; `returns` has {len(returns)}")
    row = np.flatnonzero(returns.has_bottom)
    ret, surf = returns.select(row), _take_surface(surface, row)
    n = len(row)
    grad = _per_row("seabed_gradient", seabed_gradient, n, 2)
    if surface_tilt_sigma_rad is not None:
        tilt = np.maximum(
            surf.normal_sigma_rad, _per_row("surface_tilt_sigma_rad", surface_tilt_sigma_rad, n)
        )
        surf = dataclasses.replace(surf, normal_sigma_rad=tilt)
    sig_ts = (
        np.full(n, st.timing_sigma_s) if ret.t_surface_sigma_s is None else ret.t_surface_sigma_s
    )
    sig_ts = np.where(ret.has_surface, sig_ts, 0.0)
    sig_tb = np.full(n, st.timing_sigma_s) if ret.t_bottom_sigma_s is None else ret.t_bottom_sigma_s
    # wave height: the fit residual in excess of the surface points' ranging noise, pooled
    # over every surface pulse of a cell (pipeline.uncertainty.wave_pool)
    if wave_sigma_m is None:
        wave_sigma_m = surface_wave_sigma_m(
            returns, surface, st.timing_sigma_s, st.wave_pool_cell_m
        )
    wave_all = np.asarray(wave_sigma_m, dtype=np.float64)
    if wave_all.shape != (len(returns),):
        raise ValueError(
            f"`wave_sigma_m` must be (n_pulses,) = ({len(returns)},); got {wave_all.shape}"
        )
    wave_h = np.nan_to_num(wave_all[row], nan=0.0, posinf=0.0)
    wave_h = np.where(surf.is_water, wave_h, 0.0)
    return _Inputs(ret, surf, rst, sig_ts, sig_tb, wave_h, row, grad)


def _xyzd(inp: _Inputs, *, ret=None, surf=None, rst=None) -> np.ndarray:
    """Seabed points and their depths, ``(n, 4)``."""
    return seabed_xyz_depth(ret or inp.ret, surf or inp.surf, rst or inp.rst)


def _at_measured(t: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """A term's depth change compared at the measured position: ``depth - g . (dx, dy)``."""
    t = t.copy()
    t[:, DEPTH] -= np.sum(grad * t[:, :2], axis=1)
    return t


def _with_times(inp, dts, dtb):
    r = inp.ret
    return dataclasses.replace(
        r,
        t_surface_s=np.where(r.has_surface, r.t_surface_s + dts, 0.0),
        t_bottom_s=r.t_bottom_s + dtb,
    )


def _with_direction(inp, d_new):
    """Beams turned to ``d_new``; entry re-intersected with the unchanged local planes."""
    s = inp.surf
    r, e = _on_plane(inp.ret.origin_meas_m, d_new, s.entry_m, s.normal, s.is_water)
    ret = dataclasses.replace(inp.ret, direction_meas=d_new)
    w = s.is_water
    surf = dataclasses.replace(
        s,
        entry_m=np.where(w[:, None], e, s.entry_m),
        range_to_entry_m=np.where(w, r, s.range_to_entry_m),
    )
    return ret, surf


def _with_plane(inp, dh, tilt_axis=None, tilt=None):
    """Local planes raised by ``dh`` and/or turned by ``tilt`` about ``tilt_axis``.

    The turn is about the entry point; the beams are re-intersected with the new planes.
    """
    s, o, d = inp.surf, inp.ret.origin_meas_m, inp.ret.direction_meas
    nrm = s.normal if tilt is None else _rotate(s.normal, tilt_axis, tilt)
    point = s.entry_m + np.column_stack([np.zeros((len(dh), 2)), dh])
    r, e = _on_plane(o, d, point, nrm, s.is_water)
    w = s.is_water[:, None]
    return dataclasses.replace(
        s,
        entry_m=np.where(w, e, s.entry_m),
        range_to_entry_m=np.where(w[:, 0], r, s.range_to_entry_m),
        normal=np.where(w, nrm, s.normal),
    )


#: The central differences' steps of the inputs the terms move (:func:`_moves`): steps of
#: the input, not of a term's sigma, so that one derivative serves every term moving that
#: input (the fit's and the waves' plane terms) and both TPU passes
#: (:func:`~pipeline.uncertainty.tpu_neighbours.timing_from_scatter`'s, then
#: :func:`~pipeline.uncertainty.tpu.point_tpu`'s: :mod:`pipeline.uncertainty.tpu_derivatives`).
#: Each is ~1/100 of its input's usual sigma (a timing of 0.1 ns, a plane height of 0.1 m,
#: a tilt of 1 mrad), as the steps of 1/100 of each term's sigma before them: the tangent,
#: far above the points' rounding (1e-11 m at 100 km). The terms moved from those steps'
#: by at most 4e-4 of themselves, a median of 1e-10 (``benchmarks/RESULTS_e2e.md``,
#: session 41).
TIMING_STEP_S = 1e-12
PLANE_STEP_M = 1e-3
TILT_STEP_RAD = 1e-5


def _white_terms(inp: _Inputs, st: TpuSettings):
    """``(name, move, sigma)`` of every term that goes through ``seabed_points``.

    ``move`` names the input the term moves (:func:`_moves`); ``sigma`` is (n,).
    """
    n = len(inp.row)
    water = inp.surf.is_water
    fit_tilt = np.where(water, inp.surf.normal_sigma_rad / math.sqrt(2.0), 0.0)
    wave_tilt = np.where(water, st.wave_slope_sigma_rad, 0.0)
    jitter = np.full(n, np.radians(st.pointing_jitter_deg))
    return [
        ("timing_surface", "t_surface", inp.sig_ts),
        ("timing_bottom", "t_bottom", inp.sig_tb),
        ("pointing_a", "pointing_a", jitter),
        ("pointing_b", "pointing_b", jitter),
        ("wave_height", "plane_height", inp.wave_h),
        ("wave_slope_x", "plane_tilt_x", wave_tilt),
        ("wave_slope_y", "plane_tilt_y", wave_tilt),
        ("surface_height", "plane_height", np.where(water, inp.surf.height_sigma_m, 0.0)),
        ("surface_tilt_x", "plane_tilt_x", fit_tilt),
        ("surface_tilt_y", "plane_tilt_y", fit_tilt),
    ]


def _moves(inp: _Inputs, st: TpuSettings):
    """``{move: (step, f)}``: each input the white terms move, its step ``(n,)`` and ``f``.

    ``f`` maps a signed step ``(n,)`` to the points and depths ``(n, 4)``. The steps are the
    input's (:data:`TIMING_STEP_S`, :data:`PLANE_STEP_M`, :data:`TILT_STEP_RAD`; the pointing
    jitter's 1/100, a setting), never past the surface-bottom gap for a time (the depth is
    linear in it there).
    """
    n = len(inp.row)
    zeros = np.zeros(n)
    ex, ey = np.tile([1.0, 0.0, 0.0], (n, 1)), np.tile([0.0, 1.0, 0.0], (n, 1))
    pa, pb = _perp_axes(inp.ret.direction_meas)
    d = inp.ret.direction_meas
    cap = max_timing_step_s(inp.ret) if n else zeros
    t_step = np.minimum(TIMING_STEP_S, cap)

    def turn(axis):
        def f(a):
            d_new = _rotate(d, axis, a)
            ret, surf = _with_direction(inp, d_new / np.linalg.norm(d_new, axis=1, keepdims=True))
            return _xyzd(inp, ret=ret, surf=surf)

        return f

    def plane(axis=None):
        if axis is None:
            return lambda a: _xyzd(inp, surf=_with_plane(inp, a))
        return lambda a: _xyzd(inp, surf=_with_plane(inp, zeros, axis, a))

    point_step = np.full(n, 0.01 * np.radians(st.pointing_jitter_deg))
    return {
        "t_surface": (t_step, lambda a: _xyzd(inp, ret=_with_times(inp, a, zeros))),
        "t_bottom": (t_step, lambda a: _xyzd(inp, ret=_with_times(inp, zeros, a))),
        "pointing_a": (point_step, turn(pa)),
        "pointing_b": (point_step, turn(pb)),
        "plane_height": (np.full(n, PLANE_STEP_M), plane()),
        "plane_tilt_x": (np.full(n, TILT_STEP_RAD), plane(ex)),
        "plane_tilt_y": (np.full(n, TILT_STEP_RAD), plane(ey)),
    }


def _footprint(inp: _Inputs, xyz: np.ndarray, st: TpuSettings) -> np.ndarray:
    """Per-axis horizontal sigma ``D / 4`` of the bottom footprint (n,)."""
    gamma = st.beam_divergence_mrad * 1e-3
    o = inp.ret.origin_meas_m
    water = inp.surf.is_water
    r_air = np.where(water, inp.surf.range_to_entry_m, np.linalg.norm(xyz - o, axis=1))
    in_water = np.where(water, np.linalg.norm(xyz - inp.surf.entry_m, axis=1), 0.0)
    return gamma * (r_air + in_water / inp.rst.phase_index) / 4.0


def _forward_scatter_term(inp: _Inputs, n: int) -> np.ndarray:
    """The forward-scattering correction wrong by its ``relative_sigma`` (n, 4).

    One water for the whole survey, so a correlated term; zeros without a correction.
    """
    fs = inp.rst.forward_scatter
    if n == 0 or fs is None or fs.relative_sigma == 0.0:
        return np.zeros((n, 4))
    h = 0.01

    def scaled(sign):
        model = dataclasses.replace(fs, scale=fs.scale * (1.0 + sign * h))
        return _xyzd(inp, rst=dataclasses.replace(inp.rst, forward_scatter=model))

    return _at_measured((scaled(1.0) - scaled(-1.0)) / (2.0 * h) * fs.relative_sigma, inp.grad)


#: Bottom rows per block of :func:`_terms`: the ~25 refraction passes' temporaries stay
#: bounded (~60 arrays of the block's rows each) and the blocks run on the stage's threads.
TERMS_BLOCK = 16384


def _terms(
    inp: _Inputs, st: TpuSettings, names=None, block: int | None = None, keep_moves: bool = False
):
    """The nominal points ``(n, 4)`` and the one-sigma term rows ``(n, 4)`` asked for.

    Every row's terms are its own (each pass recomputes each point from its own inputs), so
    the rows go in blocks of ``block`` (default :data:`TERMS_BLOCK`), side by side on
    :func:`~pipeline.parallel.thread_map`'s threads: the same values for any block size and
    thread count (``tests/uncertainty/test_tpu_survey_wide.py``). The derivatives of
    ``inp.derivatives`` are read, not made again.

    Returns
    -------
    xyzd0, terms
        And with ``keep_moves``, the derivatives made or read third (``moves`` of
        :class:`~pipeline.uncertainty.tpu_derivatives.Derivatives`).
    """
    n, block = len(inp.row), TERMS_BLOCK if block is None else block
    if n <= block:
        out = _terms_rows(inp, st, names, keep_moves)
    else:
        parts = thread_map(
            lambda lo: _terms_rows(
                _take_inputs(inp, np.arange(lo, min(lo + block, n))), st, names, keep_moves
            ),
            range(0, n, block),
        )
        terms = {k: np.concatenate([p[1][k] for p in parts]) for k in parts[0][1]}
        moves = None
        if keep_moves:
            # a block whose rows have no sigma of a move's terms made no derivative of it
            made = set.intersection(*(set(p[2]) for p in parts))
            moves = {k: np.concatenate([p[2][k] for p in parts]) for k in sorted(made)}
        out = (np.concatenate([p[0] for p in parts]), terms, moves)
    return out if keep_moves else out[:2]


def _terms_rows(inp: _Inputs, st: TpuSettings, names=None, keep_moves: bool = False):
    """:func:`_terms` of all of ``inp``'s rows at once (the moves third: None unless kept)."""
    n = len(inp.row)
    known = {} if inp.derivatives is None else inp.derivatives
    xyzd0 = known.get("xyzd") if "xyzd" in known else (_xyzd(inp) if n else np.zeros((0, 4)))
    made = {"xyzd": xyzd0}
    want = set(RANDOM_TERMS + CORRELATED_TERMS) if names is None else set(names)
    terms: dict[str, np.ndarray] = {}
    moves = None
    for name, move, sigma in _white_terms(inp, st):
        if name not in want:
            continue
        if n == 0 or not np.any(sigma != 0):
            terms[name] = np.zeros((n, 4))
            continue
        jac = made.get(move, known.get(move))
        if jac is None:
            moves = _moves(inp, st) if moves is None else moves
            h, f = moves[move]
            jac = (f(h) - f(-h)) / np.where(h > 0, 2.0 * h, 1.0)[:, None]
        made[move] = jac
        # a row without the term (sigma 0) has none, whatever its derivative; a NaN sigma
        # gives a NaN term: the pulse is left out (TERM_NOT_FINITE), not understated
        term = np.where(sigma[:, None] == 0, 0.0, jac * sigma[:, None])
        terms[name] = _at_measured(term, inp.grad)
    for name, (dp, dg) in index_derivatives(st).items():
        if name not in want:
            continue
        sig = st.temperature_sigma_c if name == "temperature" else st.salinity_sigma_psu
        h = 0.01 * sig
        if n == 0 or h == 0.0:
            terms[name] = np.zeros((n, 4))
            continue

        def shifted(sign, dp=dp, dg=dg, h=h):
            r = dataclasses.replace(
                inp.rst,
                phase_index=inp.rst.phase_index + sign * h * dp,
                group_index=inp.rst.group_index + sign * h * dg,
            )
            return _xyzd(inp, rst=r)

        terms[name] = _at_measured((shifted(1.0) - shifted(-1.0)) / (2.0 * h) * sig, inp.grad)
    if "forward_scatter" in want:
        terms["forward_scatter"] = _forward_scatter_term(inp, n)
    # rigid motions of the whole measured scene (exact): a rotation w about the origin keeps
    # the distance from the point to its (rotated) plane, N . (E - B); the depth is that over
    # N_z, so it changes by -depth (w x N)_z / N_z
    arm = xyzd0[:, :3] - inp.ret.origin_meas_m
    nrm = inp.surf.normal
    tilt, head = np.radians(st.attitude_sigma_deg), np.radians(st.heading_sigma_deg)
    for name, axis, sig in (
        ("attitude_x", [1.0, 0.0, 0.0], tilt),
        ("attitude_y", [0.0, 1.0, 0.0], tilt),
        ("heading", [0.0, 0.0, 1.0], head),
    ):
        if name not in want:
            continue
        w = sig * np.asarray(axis)
        dz_n = np.cross(w, nrm)[:, 2]
        ddepth = -xyzd0[:, DEPTH] * dz_n / np.where(np.abs(nrm[:, 2]) > 0, nrm[:, 2], 1.0)
        terms[name] = _at_measured(np.column_stack([np.cross(w, arm), ddepth]), inp.grad)
    if "navigation" in want:
        nav = np.tile([st.position_sigma_h_m, st.position_sigma_h_m, st.position_sigma_v_m], (n, 1))
        # a translation moves surface and seabed alike: only the sideways part, over the slope
        nav_depth = st.position_sigma_h_m * np.hypot(inp.grad[:, 0], inp.grad[:, 1])
        terms["navigation"] = np.column_stack([nav, nav_depth])
    if "footprint" in want:
        fp = _footprint(inp, xyzd0[:, :3], st) if n else np.zeros(0)
        slope = math.tan(math.radians(st.seabed_slope_deg))
        terms["footprint"] = np.column_stack([fp, fp, fp * slope, np.zeros(n)])
    return xyzd0, terms, made if keep_moves else None
