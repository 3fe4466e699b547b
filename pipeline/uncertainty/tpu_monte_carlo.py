"""Monte Carlo check of the TPU's linearisation: every input redrawn, points recomputed."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface
from pipeline.uncertainty.tpu_settings import DEPTH, TpuSettings, index_derivatives
from pipeline.uncertainty.tpu_terms import (
    _footprint,
    _inputs,
    _on_plane,
    _perp_axes,
    _rotate,
    _xyzd,
)


def monte_carlo_points(
    returns: DetectedReturns,
    surface: WaterSurface,
    refraction_settings: RefractionSettings | None = None,
    settings: TpuSettings | None = None,
    *,
    n_draws: int = 1000,
    seed: int = 0,
    seabed_gradient: Any = None,
    surface_tilt_sigma_rad: Any = None,
) -> np.ndarray:
    """Seabed points recomputed with every TPU input redrawn, ``(n_draws, n, 4)``.

    Columns: x, y, z and the depth at the measured position (the perturbed point's depth less
    ``g . (dx, dy)``, its horizontal displacement over the seabed gradient; see
    :func:`point_tpu`). Each draw perturbs the navigation (the origin, the beam and the fitted
    planes moved and turned together: the rigid-motion model), the per-pulse jitter, times and
    planes, the water's temperature and salinity (both indices) and its forward-scattering delay
    (one fraction of every in-water time), then calls
    :func:`~pipeline.process.refraction.seabed_points`; the footprint centroid offset is added
    last to x, y, z (it is not a georeferencing input; over a plane it leaves the depth).
    Full-size (not infinitesimal) perturbations: the check of :func:`point_tpu`'s
    linearisation.
    """
    st = settings or TpuSettings()
    rst = refraction_settings or RefractionSettings()
    inp = _inputs(returns, surface, rst, st, seabed_gradient, surface_tilt_sigma_rad)
    n = len(inp.row)
    rng = np.random.default_rng(seed)
    out = np.empty((n_draws, n, 4))
    ex, ey, ez = (np.tile(v, (n, 1)) for v in np.eye(3))
    o0, d0 = inp.ret.origin_meas_m, inp.ret.direction_meas
    water = inp.surf.is_water
    deriv = index_derivatives(st)
    jitter = np.radians(st.pointing_jitter_deg)
    tilt, head = np.radians(st.attitude_sigma_deg), np.radians(st.heading_sigma_deg)
    fit_tilt = np.where(water, inp.surf.normal_sigma_rad / math.sqrt(2.0), 0.0)
    wave_tilt = np.where(water, st.wave_slope_sigma_rad, 0.0)
    nominal = _xyzd(inp)
    fp = _footprint(inp, nominal[:, :3], st)
    slope = math.tan(math.radians(st.seabed_slope_deg))
    pa, pb = _perp_axes(d0)
    for k in range(n_draws):
        g = rng.standard_normal((n, 16))
        # per-pulse: jitter, times, planes (fit and waves)
        d = _rotate(_rotate(d0, pa, jitter * g[:, 0]), pb, jitter * g[:, 1])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        dh = np.where(water, inp.surf.height_sigma_m * g[:, 2] + inp.wave_h * g[:, 3], 0.0)
        nrm = _rotate(inp.surf.normal, ex, fit_tilt * g[:, 4] + wave_tilt * g[:, 5])
        nrm = _rotate(nrm, ey, fit_tilt * g[:, 6] + wave_tilt * g[:, 7])
        point = inp.surf.entry_m + np.column_stack([np.zeros((n, 2)), dh])
        # rigid motion of the scene about each origin: rotation, then translation
        rot_angles = np.column_stack([tilt * g[:, 8], tilt * g[:, 9], head * g[:, 10]])
        shift = g[:, 11:14] * [st.position_sigma_h_m, st.position_sigma_h_m, st.position_sigma_v_m]

        def rigid(v, about=None, rot_angles=rot_angles):
            w = v if about is None else v - about
            for j, ax in enumerate((ex, ey, ez)):
                w = _rotate(w, ax, rot_angles[:, j])
            return w if about is None else w + about

        d = rigid(d)
        nrm = rigid(nrm)
        point = rigid(point, o0) + shift
        o = o0 + shift
        r, e = _on_plane(o, d, point, nrm, water)
        ret = dataclasses.replace(
            inp.ret,
            origin_meas_m=o,
            direction_meas=d,
            t_surface_s=np.where(
                inp.ret.has_surface, inp.ret.t_surface_s + inp.sig_ts * g[:, 14], 0.0
            ),
            t_bottom_s=inp.ret.t_bottom_s + inp.sig_tb * g[:, 15],
        )
        w = water[:, None]
        surf = dataclasses.replace(
            inp.surf,
            entry_m=np.where(w, e, inp.surf.entry_m),
            range_to_entry_m=np.where(water, r, inp.surf.range_to_entry_m),
            normal=np.where(w, nrm, inp.surf.normal),
        )
        dt_, ds_, dfs = rng.standard_normal(3)
        (tp, tg), (sp, sg) = deriv["temperature"], deriv["salinity"]
        dtemp, dsal = st.temperature_sigma_c * dt_, st.salinity_sigma_psu * ds_
        fs = rst.forward_scatter
        if fs is not None:  # the correction wrong by its relative sigma, survey-wide
            fs = dataclasses.replace(fs, scale=fs.scale * (1.0 + fs.relative_sigma * dfs))
        r_set = dataclasses.replace(
            rst,
            phase_index=rst.phase_index + tp * dtemp + sp * dsal,
            group_index=rst.group_index + tg * dtemp + sg * dsal,
            forward_scatter=fs,
        )
        p = seabed_points(ret, surf, r_set)
        out[k, :, :3] = p.xyz_m
        moved = p.xyz_m[:, :2] - nominal[:, :2]
        out[k, :, DEPTH] = p.depth_m - np.sum(inp.grad * moved, axis=1)
        out[k, :, :2] += rng.standard_normal((n, 2)) * fp[:, None]
        out[k, :, 2] += fp * slope * rng.standard_normal(n)
    return out
