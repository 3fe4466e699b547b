"""report.html's example waveforms: the posterior fit is overlaid only when posteriors ran.

Hand-built kept waveforms, detections and classified points; the posterior's per-parameter
median is a parameter vector written here, whose waveform has analytic properties: the offset
alone before the surface, the surface echo's peak at its time, and the echo areas summing
to the counts above the offset.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from pipeline.outputs import report_figures, report_waveforms
from pipeline.uncertainty.waveform_model import WaveformSystem

DT_S = 1e-9
N_SAMPLES = 200
OFFSET = 100.0
SURFACE_NS, DEPTH_M = 30.0, 5.0
SURFACE_AREA, BOTTOM_AREA = 1000.0, 200.0
# depth, t_surface_ns, log areas (surface, column: negligible, bottom), log k, background,
# log widths (bottom, surface): echoes as wide as the system response
THETA = np.array(
    [
        DEPTH_M,
        SURFACE_NS,
        math.log(SURFACE_AREA),
        -30.0,
        math.log(BOTTOM_AREA),
        math.log(0.15),
        0.0,
        0.0,
        0.0,
    ]
)
SYSTEM = WaveformSystem(
    sample_interval_s=DT_S, pulse_fwhm_s=2e-9, offset_counts=OFFSET, electronic_noise_counts=1.5
)


def _inputs():
    pid = np.array([10, 11, 12])
    kept = SimpleNamespace(
        pulse_id=pid, t0_s=np.zeros(3), samples=np.full((3, N_SAMPLES), OFFSET, np.float32)
    )
    returns = SimpleNamespace(
        pulse_id=pid,
        has_surface=np.ones(3, bool),
        t_surface_s=np.full(3, SURFACE_NS * 1e-9),
        t_bottom_s=np.full(3, 75e-9),
        t_no_bottom_s=None,
    )
    pts = SimpleNamespace(
        pulse_id=pid, classification=np.full(3, 40, np.uint8), depth_m=np.array([3.0, 5.0, 7.0])
    )
    sim = SimpleNamespace(kept=kept, returns=returns)
    ctx = SimpleNamespace(instrument=SimpleNamespace(sample_interval_s=DT_S))
    return sim, ctx, pts


def _posterior(pulse_ids):
    n = len(pulse_ids)
    return SimpleNamespace(
        posteriors=SimpleNamespace(
            pulse_id=np.asarray(pulse_ids),
            flags=np.zeros(n, np.uint16),
            theta_median=np.tile(THETA, (n, 1)),
            cos_water=np.ones(n),
        )
    )


def _drawn(monkeypatch, *args):
    seen = {}

    def capture(t_ns, samples, marks, fits=None):
        seen.update(t_ns=t_ns, marks=marks, fits=fits)
        return b"\x89PNG"

    monkeypatch.setattr(report_figures, "waveforms", capture)
    html = report_waveforms.waveform_section(*args)
    return seen, html


def test_posterior_fit_is_drawn_over_the_waveforms_it_sampled(monkeypatch):
    sim, ctx, pts = _inputs()
    # pulses 10 and 12 sampled: they are the examples (shallowest and deepest), with fits
    seen, html = _drawn(monkeypatch, sim, ctx, pts, _posterior([10, 12]), SYSTEM)
    titles = [m["title"] for m in seen["marks"]]
    assert titles == [
        "pulse 10: class-40 bottom at 3.00 m depth",
        "pulse 12: class-40 bottom at 7.00 m depth",
    ]
    t = seen["t_ns"]
    for fit in seen["fits"]:
        assert fit is not None and fit.shape == (N_SAMPLES,)
        # the offset alone well before the surface echo (8 sigma of a 2 ns FWHM response)
        assert np.allclose(fit[t < SURFACE_NS - 8.0], OFFSET)
        # the surface echo peaks at its time; the echoes' areas are the counts above the offset
        assert abs(t[np.argmax(fit)] - SURFACE_NS) <= 1.0
        assert np.sum(fit - OFFSET) == np_approx(SURFACE_AREA + BOTTOM_AREA)
    assert "2 of them show the depth posterior" in html


def test_no_fit_over_a_waveform_the_posteriors_did_not_sample(monkeypatch):
    sim, ctx, pts = _inputs()
    seen, html = _drawn(monkeypatch, sim, ctx, pts, _posterior([99]), SYSTEM)
    assert len(seen["marks"]) == 3 and all(f is None for f in seen["fits"])
    assert "No posterior fit" in html


def test_no_fit_is_drawn_when_the_posteriors_did_not_run(monkeypatch):
    sim, ctx, pts = _inputs()
    for post in (None, SimpleNamespace(posteriors=None)):
        seen, html = _drawn(monkeypatch, sim, ctx, pts, post, None)
        assert seen["fits"] is None or all(f is None for f in seen["fits"])
        assert "No posterior fit" in html


def np_approx(x, rel=1e-3):
    import pytest

    return pytest.approx(x, rel=rel)
