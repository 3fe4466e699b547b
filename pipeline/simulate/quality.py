"""Per-pulse quality flags from the expected returns: what a pulse's data can be trusted for.

The flags (:data:`pipeline.simulate.detector.PULSE_FLAG_NAMES`) are computed from the noise-free
budget, so they say what the instrument could see, not what one noisy draw happened to show;
receiver saturation is added by the receivers themselves.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.constants import FWHM_TO_SIGMA
from pipeline.simulate import detector as D
from pipeline.simulate import paths as P
from pipeline.simulate.layer import truncated_exponential_moments
from pipeline.simulate.photon import KIND_COLUMN
from pipeline.simulate.shapes import column_cdf

if TYPE_CHECKING:
    from pipeline.simulate.budget import ReturnBudget
    from pipeline.simulate.photon import Components

__all__ = ["pulse_flags", "return_stats"]


def return_stats(comps: Components, ctype: np.ndarray, t, present=None):
    """(n,) expected total, mean centre and effective sigma of the components of type ``t``.

    Weighted by expected photoelectrons; where the total is 0, equally over the components
    ``present`` (n, k) marks (the echo exists geometrically but carries no light).
    """
    sel = ctype == t
    n_j = comps.expected[:, sel]
    tot = n_j.sum(axis=1)
    # column-shaped components (delayed bottom tails): start + the exponential's moments
    col_w = np.where(comps.kind[:, sel] == KIND_COLUMN, comps.width_s[:, sel], 0.0)
    shift, extra = truncated_exponential_moments(comps.rate_per_s[:, sel], col_w)
    centre = comps.centre_s[:, sel] + shift
    var_j = comps.sigma_s[:, sel] ** 2 + extra
    if present is not None:
        present = np.tile(present, (1, n_j.shape[1] // present.shape[1]))
        fallback = present / np.maximum(present.sum(axis=1, keepdims=True), 1)
        n_j = np.where((tot > 0)[:, None], n_j, fallback)
        tot_w = n_j.sum(axis=1)
    else:
        tot_w = tot
    w = n_j / np.where(tot_w > 0, tot_w, 1.0)[:, None]
    mu = (w * centre).sum(axis=1)
    var = (w * (var_j + (centre - mu[:, None]) ** 2)).sum(1)
    return tot, mu, np.sqrt(var)


def pulse_flags(budget: ReturnBudget, detector, comps, ctype) -> np.ndarray:
    """Per-pulse quality flags from the expected returns (receiver saturation excepted).

    A return's detection SNR is ``N / sqrt(F (N + B) + n_s (sigma_e / G)^2)`` with ``B`` the
    background and column photoelectrons and ``n_s`` the samples within ``+-2 sigma`` of it
    (``F = 1`` and no electronic noise for photon counting). ``comps``, ``ctype``: the pulses'
    components (:func:`pipeline.simulate.waveform.build_components`).

    Returns
    -------
    (n_pulses,) uint16
    """
    fl = budget.subray_flags
    pc = detector.mode == "photon_counting"
    f = 1.0 if pc else detector.excess_noise_factor
    e2 = detector.noise_photoelectrons_per_sample()
    dt = budget.sample_interval_s
    col = comps.expected[:, -2]

    present = {0: (fl & P.MISS) == 0, 1: fl == P.OK}

    def snr(t):
        tot, mu, sig = return_stats(comps, ctype, t, present[t])
        x = mu - budget.column_start_s
        cdf = [
            column_cdf(x + s * sig, budget.column_rate_per_s, budget.column_width_s,
                       budget.column_sigma_s)
            for s in (-2.0, 2.0)
        ]  # fmt: skip
        noise_pe = budget.background_rate_hz * 4.0 * sig + col * (cdf[1] - cdf[0])
        n_s = np.maximum(4.0 * sig / dt, 1.0)
        return tot / np.sqrt(f * (tot + noise_pe) + n_s * e2 + 1e-300), tot, mu, sig

    snr_s, _, mu_s, sig_s = snr(0)
    snr_b, _, mu_b, sig_b = snr(1)
    thr = detector.detection_snr
    has_bottom = np.any(fl == P.OK, axis=1)
    out = np.zeros(budget.n_pulses, dtype=np.uint16)
    out |= np.where((snr_s < thr) & (~has_bottom | (snr_b < thr)), D.NO_SIGNAL, 0).astype(np.uint16)
    out |= np.where(has_bottom & (snr_b < thr), D.BOTTOM_BELOW_NOISE, 0).astype(np.uint16)
    fwhm = np.maximum(sig_s, sig_b) / FWHM_TO_SIGMA
    merged = has_bottom & (mu_b - mu_s < fwhm)
    out |= np.where(merged, D.MERGED_SURFACE_BOTTOM, 0).astype(np.uint16)
    beyond = budget.t0_s + (budget.n_samples - 0.5) * dt
    out |= np.where(has_bottom & (mu_b > beyond), D.BOTTOM_OUTSIDE_WINDOW, 0).astype(np.uint16)
    partial = np.any((fl & (P.MISS | P.NO_BOTTOM | P.TIR_RETURN)) != 0, axis=1)
    out |= np.where(partial, D.PARTIAL_FOOTPRINT, 0).astype(np.uint16)
    out |= np.where(np.any((fl & P.LAND) != 0, axis=1), D.LAND_RETURN, 0).astype(np.uint16)
    if pc:
        per_channel = np.stack([return_stats(comps, ctype, t)[0] for t in range(3)], axis=1)
        hot = np.any(per_channel / detector.n_channels >= D.PC_SATURATION_PE_PER_CHANNEL, axis=1)
        out |= np.where(hot, D.SATURATED, 0).astype(np.uint16)
    return out
