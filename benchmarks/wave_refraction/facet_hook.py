"""`bathy run` that also keeps, per pulse, what the facet-path diagnosis needs (evaluation side).

Usage::

    PYTHONPATH=. python benchmarks/wave_refraction/facet_hook.py OUT.npz run SCENE.toml --out DIR

The run is `bathy run` itself; just before its evaluation the measured surface points, the
refracted seabed points, the measured origins and the truth's sea and seabed heights at them are
written to ``OUT.npz`` (read by ``facet_bias.py``). Truth is read here, never by processing.
"""

from __future__ import annotations

import sys

import numpy as np

import pipeline.survey_report as survey_report
from pipeline.process.refraction import seabed_points

_evaluate = survey_report.evaluate_survey


def _sea_m(water, x_m, y_m, t_s):
    """The true sea's height at ``(x, y)`` at the pulses' times (a still sea has no time)."""
    return water.height_m(x_m, y_m, t_s) if hasattr(water, "evolving") else water.height_m(x_m, y_m)


def _keep(out_path):
    def evaluate(scene, sim, processed, ctx, *args, **kwargs):
        ret, surf, truth = sim.returns, processed.surface, sim.truth
        t = truth.pulse_time_s(ret.pulse_id)
        sp = surf.surface_point_m
        ok = ret.has_surface & surf.is_water
        sea_at_sp = np.full(len(ret), np.nan)
        sea_at_sp[ok] = _sea_m(truth.water, sp[ok, 0], sp[ok, 1], t[ok])
        rows = np.flatnonzero(ret.has_bottom)
        xyz = seabed_points(ret, surf, ctx.refraction).xyz_m
        np.savez(
            out_path,
            pulse_id=ret.pulse_id,
            has_surface=ok,
            surface_z_m=sp[:, 2],
            sea_at_surface_m=sea_at_sp,
            origin_z_m=ret.origin_meas_m[:, 2],
            altitude_m=float(scene.flight.altitude_m),
            bottom_rows=rows,
            bottom_xyz_m=xyz,
            seabed_true_m=truth.seabed.height_m(xyz[:, 0], xyz[:, 1]),
            sea_at_bottom_m=_sea_m(truth.water, xyz[:, 0], xyz[:, 1], t[rows]),
            plane_at_bottom_m=surf.surface_z_m(rows, xyz[:, 0], xyz[:, 1]),
            # what the facet excess needs (processing's own values, no truth)
            normal=surf.normal,
            normal_sigma_rad=surf.normal_sigma_rad,
            surface_flags=surf.flags,
            is_water=surf.is_water,
            entry_m=surf.entry_m,
            direction=ret.direction_meas,
            origin_xy_m=ret.origin_meas_m[:, :2],
            line_id=np.zeros(len(ret), np.int64) if ret.line_id is None else ret.line_id,
            wind_m_s=float(scene.water.wind_speed_m_s),
            own_weight=np.full(len(ret), np.nan) if surf.own_weight is None else surf.own_weight,
            fit_sigma_m=surf.fit_sigma_m,
        )
        return _evaluate(scene, sim, processed, ctx, *args, **kwargs)

    return evaluate


if __name__ == "__main__":  # pool workers import this file too: only the parent runs
    survey_report.evaluate_survey = _keep(sys.argv[1])
    from pipeline.cli import main

    sys.exit(main(sys.argv[2:]))
