"""Sample runs' kept full-waveform posteriors again under other settings; score them.

Usage::

    PYTHONPATH=. python benchmarks/posterior_clip/replay.py DIR SEEDS [key=value ...]

``DIR`` holds, per seed ``S`` of the comma-separated ``SEEDS``, ``pS.pkl`` (``hook.py``) and
the run's output folder ``oS`` (its ``evaluation_points.npz`` has the evaluation's true depths
of the same posteriors, in order: truth is read here, never by processing). ``key=value``
overrides :class:`~pipeline.uncertainty.posterior_settings.PosteriorSettings` fields (Python
literals), ``system.key=value`` the :class:`~pipeline.uncertainty.waveform_model.
WaveformSystem`'s, ``nuisance=(names,)`` the TPU terms left out of the nuisance (``hook.py``'s
``pS_terms.pkl``). Prints per scene and pooled: the posteriors' median depth error, the
coverage of their 68 / 95 % intervals (with the TPU's other terms, as ``bathy run``), the
share converged and the sampler's CPU time. ``-v`` lists every pulse.
"""

from __future__ import annotations

import ast
import dataclasses
import pickle
import sys
import time

import numpy as np

from pipeline.uncertainty.posterior_settings import PosteriorFlag
from pipeline.uncertainty.seabed_posterior import seabed_posteriors


def replay(pkl: str, run_dir: str, over: dict, verbose: bool = False) -> dict:
    """One run's posteriors sampled again with ``over``; their errors and hits."""
    with open(pkl, "rb") as f:
        args, kwargs = pickle.load(f)
    ev = np.load(f"{run_dir}/evaluation_points.npz")
    sys_over = {k[7:]: v for k, v in over.items() if k.startswith("system.")}
    set_over = {k: v for k, v in over.items() if not k.startswith("system.") and k != "nuisance"}
    if "nuisance" in over:
        # the nuisance made of the TPU terms but those named (``nuisance=("timing_surface",)``)
        with open(pkl.replace(".pkl", "_terms.pkl"), "rb") as f:
            terms = pickle.load(f)
        kwargs = dict(kwargs)
        kwargs["nuisance_depth_sigma_m"] = np.sqrt(
            sum(v**2 for k, v in terms.items() if k not in over["nuisance"])
        )
    args = list(args)
    args[4] = dataclasses.replace(args[4], **sys_over)
    if set_over:
        args[5] = dataclasses.replace(args[5], **set_over)
    t0 = time.process_time()
    p = seabed_posteriors(*args, **kwargs)
    cpu = time.process_time() - t0
    started = (p.flags & PosteriorFlag.NO_START) == 0
    truth = ev["post_true_depth_m"]
    d = {k: np.asarray(v)[started] for k, v in p.depth_m.items()}
    bad = PosteriorFlag.NOT_CONVERGED | PosteriorFlag.ACCEPTANCE
    out = {
        "err": d["median"] - truth,
        "in68": (d["lo68"] <= truth) & (truth <= d["hi68"]),
        "in95": (d["lo95"] <= truth) & (truth <= d["hi95"]),
        "conv": (np.asarray(p.flags)[started] & bad) == 0,
        "cpu": cpu,
    }
    if verbose:
        th = np.asarray(p.theta_median)[started]
        for i in range(len(truth)):
            print(
                f"{i:3d} err {out['err'][i]:+.4f} sd {d['std'][i]:.4f} "
                f"68 {int(out['in68'][i])} 95 {int(out['in95'][i])} k {np.exp(th[i, 5]):.3f} "
                f"wsurf {np.exp(th[i, 8]):.2f} wbot {np.exp(th[i, 7]):.2f} "
                f"conv {int(out['conv'][i])} acc {np.asarray(p.acceptance)[started][i]:.2f}"
            )
    return out


def _line(name, r):
    n = len(r["err"])
    if n == 0:
        return f"{name:>8} n 0"
    return (
        f"{name:>8} n {n:3d} median err {np.median(r['err']):+.4f} coverage 68 "
        f"{r['in68'].mean():6.1%} 95 {r['in95'].mean():6.1%} converged {r['conv'].mean():6.1%} "
        f"cpu {r['cpu']:.1f} s"
    )


def main(argv):
    verbose = "-v" in argv
    argv = [a for a in argv if a != "-v"]
    folder, seeds = argv[0], [int(s) for s in argv[1].split(",")]
    over = {k: ast.literal_eval(v) for k, v in (a.split("=", 1) for a in argv[2:])}
    print(f"overrides: {over or 'none'}")
    runs = {s: replay(f"{folder}/p{s}.pkl", f"{folder}/o{s}", over, verbose) for s in seeds}
    for s, r in runs.items():
        print(_line(str(s), r))
    pooled = {
        k: np.concatenate([r[k] for r in runs.values()]) for k in ("err", "in68", "in95", "conv")
    }
    pooled["cpu"] = sum(r["cpu"] for r in runs.values())
    print(_line("pooled", pooled))


if __name__ == "__main__":
    main(sys.argv[1:])
