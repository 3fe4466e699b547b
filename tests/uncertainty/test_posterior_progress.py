"""The posterior stage shows a progress bar over its batches, and nothing when asked not to."""

from __future__ import annotations

import numpy as np

from pipeline.uncertainty import seabed_posterior as sp
from pipeline.uncertainty.posterior import PulseChains
from pipeline.uncertainty.posterior_settings import PosteriorFlag, PosteriorSettings
from pipeline.uncertainty.waveform_model import N_PARAMS, WaveformSystem


class _Rows:
    """Just what seabed_posteriors reads of the returns and the surface, ``n`` rows."""

    def __init__(self, n):
        self.n = n
        self.pulse_id = np.arange(n)
        self.direction_meas = np.tile([0.0, 0.0, -1.0], (n, 1))
        self.normal = np.tile([0.0, 0.0, 1.0], (n, 1))
        self.is_water = np.ones(n, bool)
        self.air_index = 1.0003

    def __len__(self):
        return self.n


def _fake_batch(waveforms, system, settings, **kw):
    p = len(waveforms)
    return PulseChains(
        draws=np.zeros((p, 4, N_PARAMS)),
        mode=np.zeros((p, N_PARAMS)),
        acceptance=np.zeros(p),
        tau_steps=np.ones((p, N_PARAMS)),
        n_steps=np.zeros(p, dtype=np.int64),
        flags=np.full(p, PosteriorFlag.NO_START, dtype=np.uint16),  # no draws to carry
    )


def test_progress_bar_over_posterior_batches(monkeypatch, capsys):
    monkeypatch.setattr(sp, "sample_batch", _fake_batch)
    rows = _rows = _Rows(5)
    system = WaveformSystem(sample_interval_s=1e-9, pulse_fwhm_s=2e-9, electronic_noise_counts=1)
    args = (np.zeros((5, 16)), np.zeros(5), rows, _rows, system, PosteriorSettings(batch_size=2))
    sp.seabed_posteriors(*args, progress=True)
    err = capsys.readouterr().err
    assert "posteriors" in err and "5/5" in err  # 3 batches of 2, 2 and 1 pulses
    sp.seabed_posteriors(*args, progress=False)
    assert capsys.readouterr().err == ""
