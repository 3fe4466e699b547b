# ruff: noqa: E501, E702, E731  (the diagnosis scripts as they were run; issue 13, session 7)
"""Scratch: frame-free decomposition of the depth error (truth only here)."""

import pickle
import sys

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S as C
from pipeline.optics import refract_direction
from pipeline.process.classify import SEABED_CLASSES
from pipeline.process.context import processing_context, with_measured_attenuation
from pipeline.process.returns import PointFlag
from pipeline.process.scatter_bias import range_bias_m
from pipeline.process.survey_points import process_detections
from pipeline.scene import load_scene

pk = sys.argv[1]
D = pickle.load(open(pk, "rb"))
sim, S = D["sim"], D["summ"]
scene = load_scene(D["scene_path"])
ctx = processing_context(scene)
ret = sim.returns
if sim.no_bottom is not None:
    r_air = C * ret.t_surface_s[ret.has_surface] / (2.0 * ctx.instrument.air_index)
    ctx = with_measured_attenuation(
        ctx, sim.no_bottom.get("column_decay_per_m"), float(np.median(r_air))
    )
proc = process_detections(ret, ctx, scene.process.classify, water_column=False)
pts = proc.points
sel = np.isin(pts.classification, np.asarray(SEABED_CLASSES, np.uint8))
pid = pts.pulse_id[sel]
row = np.searchsorted(ret.pulse_id, pid)
srow = np.searchsorted(S["pulse_id"], pid)
surf = proc.surface
rs = ctx.refraction
truth = sim.truth
na, nw, ng = surf.air_index, rs.phase_index, rs.group_index
o, d = ret.origin_meas_m[row], ret.direction_meas[row]
tb, ts = ret.t_bottom_s[row], ret.t_surface_s[row]
t_p = truth.pulse_time_s(pid)
nrm, r_e = surf.normal[row], surf.range_to_entry_m[row]
flags = surf.flags[row]
own = ret.has_surface[row] & ((flags & PointFlag.SURFACE_OUTLIER) == 0)
r_s = C * ts / (2 * na)
w = np.where(own & surf.is_water[row] & (r_s > 0), surf.own_weight[row], 0.0)
r_in = r_e + w * (r_s - r_e)
dO = o - S["origin"][srow]  # navigation error: true-frame point = measured - dO (translation)
sea = (
    (lambda x, y: truth.water.height_m(x, y, t_p))
    if hasattr(truth.water, "evolving")
    else (lambda x, y: truth.water.height_m(x, y))
)
true_depth = truth.depth_at_pulses_m(pts.xyz_m[sel, 0], pts.xyz_m[sel, 1], pid)


def point(r_in_, nrm_, tb_, tdir=None, fs=True):
    L = (C * tb_ / 2 - na * r_in_) / ng
    if tdir is None:
        tdir, _ = refract_direction(d, nrm_, na, nw)
    if fs:
        L = L - range_bias_m(rs.forward_scatter, L, r_in_, na, nw, ng)
    E = o + d * r_in_[:, None]
    return E + tdir * L[:, None], E


def ref_proc(B, E, r_in_):
    z = surf.surface_z_m(row, B[:, 0], B[:, 1])
    corr = surf.sea_correlation
    if corr is not None:
        z = z + corr.at(np.hypot(B[:, 0] - E[:, 0], B[:, 1] - E[:, 1])) * d[:, 2] * (r_in_ - r_e)
    return z


def ref_relief(B, E):  # entry height used + the true relief from E to B at the pulse's time
    Bt, Et = B - dO, E - dO
    return E[:, 2] + sea(Bt[:, 0], Bt[:, 1]) - sea(Et[:, 0], Et[:, 1])


def err(B, ref):  # depth error in the true frame at the point's true position
    Bt = B - dO
    dt_ = sea(Bt[:, 0], Bt[:, 1]) - truth.seabed.height_m(Bt[:, 0], Bt[:, 1])
    return ref - B[:, 2] - dt_


def stats(name, e):
    s = f"{name:62s} {e.mean():+.4f} {np.sqrt(np.mean(e * e)):.4f} |"
    for lo, hi in ((1, 3), (3, 6), (6, 10), (10, 20), (20, 40)):
        m = (true_depth >= lo) & (true_depth < hi)
        s += (
            f" {e[m].mean():+.3f}/{np.sqrt(np.mean(e[m] ** 2)):.3f}"
            if m.sum() > 50
            else "      -     "
        )
    print(s)


print(f"{pk}: n = {sel.sum()}; bias rmse | per band bias/rmse 1-3 3-6 6-10 10-20 20-40 m")
r_true = S["r_air_b"][srow]
Nb = S["N_b"][srow]
Rb = S["R_b"][srow]
Rb = Rb / np.linalg.norm(Rb, axis=1, keepdims=True)
tb_t = S["tb"][srow]
B, E = point(r_in, nrm, tb)
stats("A shipped: processing's surface above B", err(B, ref_proc(B, E, r_in)))
stats("B  shipped point, true sea relief E->B as reference", err(B, ref_relief(B, E)))
B, E = point(r_true, nrm, tb)
stats("C  + true entry range (no surface-echo timing error)", err(B, ref_relief(B, E)))
B, E = point(r_true, Nb, tb)
stats("D  + true footprint-mean normal", err(B, ref_relief(B, E)))
B, E = point(r_true, Nb, tb, Rb)
stats("E  + true mean refracted direction (unresolved facets)", err(B, ref_relief(B, E)))
B, E = point(r_true, Nb, tb_t, Rb, fs=False)
stats("F  + true bottom time (energy-weighted, no fs delay)", err(B, ref_relief(B, E)))
print("-- one thing at a time from the shipped point (reference: true relief)")
B, E = point(r_in, Nb, tb)
stats("D' shipped + true normal only", err(B, ref_relief(B, E)))
print("-- processing's reference with the better point")
B, E = point(r_true, nrm, tb)
stats("C+proc ref", err(B, ref_proc(B, E, r_true)))
B, E = point(r_true, Nb, tb)
stats("D+proc ref", err(B, ref_proc(B, E, r_true)))
h = d[:, :2] / np.linalg.norm(d[:, :2], axis=1, keepdims=True)
slope = lambda n: -(n[:, 0] * h[:, 0] + n[:, 1] * h[:, 1]) / n[:, 2]
perp = lambda n: -(-n[:, 0] * h[:, 1] + n[:, 1] * h[:, 0]) / n[:, 2]
print(
    f"surface slope along the beam's horizontal direction (rising away from the aircraft > 0): proc - true mean {np.mean(slope(nrm) - slope(Nb)):+.4f} (sd {np.std(slope(nrm) - slope(Nb)):.4f}); across: {np.mean(perp(nrm) - perp(Nb)):+.4f}"
)
print(
    f"surface echo range bias (echo - true air range, m): {np.mean(r_s - r_true):+.4f}; entry range bias {np.mean(r_in - r_true):+.4f}"
)
