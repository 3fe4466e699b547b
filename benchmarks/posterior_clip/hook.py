"""`bathy run` that also keeps the full-waveform posterior's inputs, for replays.

Usage::

    PYTHONPATH=. python benchmarks/posterior_clip/hook.py OUT.pkl run SCENE.toml --out DIR

The run is `bathy run` itself; the arguments of its one
:func:`pipeline.uncertainty.seabed_posterior.seabed_posteriors` call (waveforms, detections,
surface, system, settings) are pickled to ``OUT.pkl``; ``replay.py`` samples them again under
other posterior settings and scores them against the run's ``evaluation_points.npz`` (the truth
there is the evaluation's, never processing's).
"""

from __future__ import annotations

import pickle
import sys

import pipeline.uncertainty.survey_posterior as sp

_orig = sp.seabed_posteriors


_orig_nuisance = sp.nuisance_depth_sigma_m


def _keep(out_path):
    def seabed_posteriors(*args, **kwargs):
        with open(out_path, "wb") as f:
            pickle.dump((args, kwargs), f)
        return _orig(*args, **kwargs)

    return seabed_posteriors


def _keep_terms(out_path):
    """The sampled points' TPU terms (depth column), for nuisances made otherwise."""

    def nuisance_depth_sigma_m(terms, index):
        with open(out_path, "wb") as f:
            pickle.dump({k: v[index, -1] for k, v in terms.items()}, f)
        return _orig_nuisance(terms, index)

    return nuisance_depth_sigma_m


if __name__ == "__main__":
    out = sys.argv[1]
    sp.seabed_posteriors = _keep(out)
    sp.nuisance_depth_sigma_m = _keep_terms(out.replace(".pkl", "_terms.pkl"))
    from pipeline.cli import main

    sys.exit(main(sys.argv[2:]))
