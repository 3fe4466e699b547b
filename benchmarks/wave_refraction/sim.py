# ruff: noqa: E501, E702, E731  (the diagnosis scripts as they were run; issue 13, session 7)
"""Scratch: simulate a scene once, keep detections + per-pulse truth summaries of the trace."""

import dataclasses
import functools
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from pipeline import run_survey as RS
from pipeline.detection_store import DetectionStore
from pipeline.process.context import processing_context
from pipeline.scene import load_scene
from pipeline.simulate import survey
from pipeline.simulate import waveform as W
from pipeline.stages import StageClock
from pipeline.stages import plan as make_plan

scene_path, out = sys.argv[1], sys.argv[2]
scene = load_scene(scene_path)
SUM = []
orig = W.return_budget


def hook(paths, scene_, detector, settings=None):
    b = orig(paths, scene_, detector, settings)
    lb = b.log_bottom
    mb = lb.max(axis=1, keepdims=True)
    wb = np.exp(lb - mb) * (lb > -1e5)
    wbs = wb.sum(1, keepdims=True)
    has_b = wbs[:, 0] > 0
    wb = wb / np.maximum(wbs, 1e-300)
    ls = b.log_surface
    ms = ls.max(axis=1, keepdims=True)
    wsf = np.exp(ls - ms) * (ls > -1e5)
    wsf = wsf / np.maximum(wsf.sum(1, keepdims=True), 1e-300)

    def m(w, a):
        return np.einsum("nk,nk...->n...", w, a)

    nb = m(wb, paths.surface_normal)
    nb /= np.maximum(np.linalg.norm(nb, axis=1, keepdims=True), 1e-300)
    ns = m(wsf, paths.surface_normal)
    ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-300)
    sw = paths.subray_weight
    dax = np.einsum("k,nkj->nj", sw, paths.direction)
    dax /= np.linalg.norm(dax, axis=1, keepdims=True)
    SUM.append(
        dict(
            pulse_id=paths.pulse_id,
            has_b=has_b,
            origin=paths.origin_m,
            d_axis=dax,
            tb=m(wb, b.t_bottom_s),
            ts=m(wsf, b.t_surface_s),
            tail=m(wb, b.bottom_tail_weight * b.bottom_tail_s),
            E_b=m(wb, paths.surface_xyz_m),
            E_s=m(wsf, paths.surface_xyz_m),
            N_b=nb,
            N_s=ns,
            R_b=m(wb, paths.refracted_dir),
            B_b=m(wb, paths.bottom_xyz_m),
            L_b=m(wb, paths.water_path_m),
            r_air_b=m(wb, paths.air_range_m),
            r_air_s=m(wsf, paths.air_range_m),
            zsd_b=np.sqrt(
                np.maximum(
                    m(wb, paths.surface_xyz_m[..., 2] ** 2)
                    - m(wb, paths.surface_xyz_m[..., 2]) ** 2,
                    0,
                )
            ),
        )
    )
    return b


W.return_budget = hook
plan = make_plan(scene)
ctx = processing_context(scene)
clock = StageClock()
t0 = time.time()
with DetectionStore(Path(out).parent, ctx.instrument.air_index) as store:
    sim = RS.simulate_detections(scene, plan, ctx, clock, store, log=print)
print("sim s", time.time() - t0)
summ = {k: np.concatenate([s[k] for s in SUM]) for k in SUM[0]}
o = np.argsort(summ["pulse_id"])
summ = {k: v[o] for k, v in summ.items()}
truth = dataclasses.replace(
    sim.truth, pulse_time_s=functools.partial(survey.pulse_times_s, sim.lines, scene.scanner.prf_hz)
)
sim = dataclasses.replace(sim, truth=truth)
with open(out, "wb") as f:
    pickle.dump(dict(sim=sim, summ=summ, scene_path=scene_path), f, protocol=5)
print("saved", out, len(sim.returns))
