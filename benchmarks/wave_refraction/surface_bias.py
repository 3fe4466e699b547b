# ruff: noqa: E501  (a diagnosis script; issue 13, session 8)
"""Scratch: surface-echo time minus the true entry time of each pulse (truth only here).

The true entry time is the round trip over the air range where the pulse's bottom-echo energy
entered the water (``sim.py``'s ``r_air_b``), on pulses with a surface, a bottom and bottom
energy: the timing error that lengthens the in-water path (range = c t / (2 n_air)).
"""

import pickle
import sys

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S as C
from pipeline.process.context import processing_context
from pipeline.scene import load_scene

for pk in sys.argv[1:]:
    D = pickle.load(open(pk, "rb"))
    ret, S = D["sim"].returns, D["summ"]
    n_air = processing_context(load_scene(D["scene_path"])).instrument.air_index
    srow = np.searchsorted(S["pulse_id"], ret.pulse_id)
    m = ret.has_surface & ret.has_bottom & S["has_b"][srow]
    e = (ret.t_surface_s[m] - 2 * n_air * S["r_air_b"][srow][m] / C) * 1e9
    print(
        f"{pk.split('/')[-1]:18s} n {m.sum():6d} surface time - true entry (ns): mean {e.mean():+.3f} median {np.median(e):+.3f} sd {e.std():.3f}"
    )
