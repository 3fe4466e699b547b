"""Waveforms from the lidar equation: one photon model, two receivers.

``paths`` (:class:`~pipeline.simulate.paths.Paths`) → :func:`~.returns.return_budget` (expected
photoelectrons of every return, in log space, with its time shape) → per pulse a set of
components: one Gaussian per sub-ray for the surface or land echo, one per sub-ray for the
bottom echo, one per sub-ray for the scattering layer's echo (only when the scene has a layer),
one water-column component and one uniform background (sunlight + dark counts) over the window.
Then

* :func:`simulate_waveforms` (full-waveform receiver): weak components are drawn as
  photoelectrons (:mod:`.photon`) and binned on the digitiser clock, strong ones (at least
  ``detector.strong_return_photoelectrons`` in the pulse) enter as their expected shape, and
  gain noise, electronic noise and the digitiser follow (:func:`.receivers.digitise`);
* :func:`simulate_photon_events` (photon-counting receiver): all components are drawn as
  photoelectrons (at most ``strong_return_photoelectrons`` per pulse: flagged saturated
  beyond), spread over ``n_channels`` channels and thinned by the dead time.

So the two receivers cannot disagree: weak returns are the very same photoelectrons (same
counter-based draws), strong returns share the same expectation and variance (Gaussian with
the excess-noise factor in the full waveform). The expected waveform
(:func:`expected_waveform`) is the noise-free limit of both.

Chunk invariance: a pulse's photons come from a counter-based stream keyed by
``(scene seed, pulse_id)`` and its sample noise from fixed blocks of pulse ids, so any split of a
survey into chunks gives bit-identical output. Work is done in slices of
:data:`SLICE_PULSES` pulses to bound memory.

Examples
--------
>>> from pipeline.scene import DEFAULT_SCENE_PATH, load_scene
>>> from pipeline.simulate.flat_paths import flat_paths
>>> from pipeline.simulate.detector import DetectorSettings
>>> scene = load_scene(DEFAULT_SCENE_PATH)
>>> paths = flat_paths(4, altitude_m=300.0, depth_m=5.0, water_phase_index=1.3415)
>>> wf = simulate_waveforms(paths, scene, DetectorSettings(window_s=2e-7))
>>> wf.samples.shape, wf.samples.dtype.name
((4, 200), 'float32')
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import NumericalError
from pipeline.simulate import detector as D
from pipeline.simulate import paths as P
from pipeline.simulate.budget import ReturnBudget, ReturnSettings, return_budget
from pipeline.simulate.geometry import LOG_ZERO
from pipeline.simulate.photon import (
    KIND_COLUMN,
    KIND_GAUSS,
    KIND_UNIFORM,
    Components,
    block_normals,
    draw_events,
    pulse_keys,
    uniform_pair,
)
from pipeline.simulate.quality import pulse_flags
from pipeline.simulate.receivers import (
    dead_time_filter,
    digitise,
    digitise_drawn,
    expected_samples,
)

__all__ = [
    "Waveforms",
    "PhotonEvents",
    "SLICE_PULSES",
    "RETURNS",
    "TYPES",
    "build_components",
    "expected_waveform",
    "pulse_flags",
    "simulate_waveforms",
    "simulate_photon_events",
]

SLICE_PULSES = 1024
"""Pulses processed at once inside a chunk (bounds the (pulses x samples) temporaries)."""
STREAM_PHOTONS = 101
STREAM_SAMPLES = 102
#: Return types (the index is a component's type); components are ordered surface-or-land,
#: bottom, layer (scenes with a scattering layer only), column, background.
TYPES = ("surface", "bottom", "column", "background", "layer")


@dataclass(frozen=True)
class Waveforms:
    """Digitised full waveforms of a chunk of pulses.

    Attributes
    ----------
    pulse_id : (n_pulses,) int64
    t0_s : (n_pulses,) float64
        Time after emission of sample 0 (the centre of its bin).
    sample_interval_s : float
    samples : (n_pulses, n_samples) float32
        Digitiser counts, baseline included, in ``[0, 2^bits - 1]``.
    flags : (n_pulses,) uint16
        :data:`~pipeline.simulate.detector.PULSE_FLAG_NAMES`.
    """

    pulse_id: np.ndarray
    t0_s: np.ndarray
    sample_interval_s: float
    samples: np.ndarray
    flags: np.ndarray

    def sample_times_s(self) -> np.ndarray:
        """(n_pulses, n_samples) time after emission of every sample."""
        m = self.samples.shape[1]
        return self.t0_s[:, None] + self.sample_interval_s * np.arange(m)


@dataclass(frozen=True)
class PhotonEvents:
    """Recorded photon events of a chunk of shots, as a ragged array.

    Attributes
    ----------
    pulse_id : (n_pulses,) int64
    gate_start_s : (n_pulses,) float64
        Opening of the range gate after emission.
    gate_length_s : float
    offsets : (n_pulses + 1,) int64
        Events of shot ``i`` are ``times_s[offsets[i]:offsets[i + 1]]``.
    times_s : (n_events,) float64
        Arrival times after emission, increasing within a shot and channel.
    channel : (n_events,) int16
        Detector channel of each event.
    flags : (n_pulses,) uint16
    """

    pulse_id: np.ndarray
    gate_start_s: np.ndarray
    gate_length_s: float
    offsets: np.ndarray
    times_s: np.ndarray
    channel: np.ndarray
    flags: np.ndarray

    def shot(self, i: int) -> np.ndarray:
        """Event times of shot ``i`` (a view)."""
        return self.times_s[self.offsets[i] : self.offsets[i + 1]]


def _exp(log_pe):
    return np.where(log_pe > LOG_ZERO / 2, np.exp(np.maximum(log_pe, -745.0)), 0.0)


#: Every return the components can hold (land echoes share the surface slot of their sub-ray).
RETURNS = ("surface", "land", "bottom", "layer", "column", "background")


#: A delay tail shorter than this many pulse sigmas is a Gaussian with the tail's mean and
#: variance (skewness below 0.02); longer ones are the pulse convolved with the exponential.
TAIL_MIN_SIGMAS = 0.2
#: The exponential tail is a column shape truncated at this many means (e^-40: untruncated).
TAIL_SPAN_MEANS = 40.0


def _bottom_tail(t_bottom_s, sigma_s, tau_s):
    """(centre, sigma, kind, rate, width) of the delayed part of each bottom echo."""
    long_ = tau_s >= TAIL_MIN_SIGMAS * sigma_s
    kind = np.where(long_, KIND_COLUMN, KIND_GAUSS)
    centre = np.where(long_, t_bottom_s, t_bottom_s + tau_s)
    sigma = np.where(long_, sigma_s, np.sqrt(sigma_s**2 + tau_s**2))
    safe = np.where(long_, tau_s, 1.0)
    rate = np.where(long_, 1.0 / safe, 0.0)
    width = np.where(long_, TAIL_SPAN_MEANS * safe, 0.0)
    return centre, sigma, kind, rate, width


def build_components(budget: ReturnBudget, include=RETURNS) -> tuple[Components, np.ndarray]:
    """Components ``(n_pulses, g n_sub + 2)`` of every pulse, and the type of each component.

    ``g`` is 3 (surface-or-land Gaussian, undelayed bottom Gaussian and delayed bottom tail per
    sub-ray, :func:`_bottom_tail`), or 4 when the budget has a scattering layer (its Gaussians
    follow the bottom's). The column and the background stay the last two components.

    Parameters
    ----------
    budget : ReturnBudget
    include : tuple of str
        Returns (:data:`RETURNS`) to keep; the others get 0 expected photoelectrons.

    Returns
    -------
    comps : Components
    ctype : (g n_sub + 2,) int64
        Index into :data:`TYPES` of each component.
    """
    n, k = budget.log_surface.shape
    surf = _exp(budget.log_surface) * ("surface" in include)
    surf = surf + _exp(budget.log_land) * ("land" in include)
    bottom = _exp(budget.log_bottom) * ("bottom" in include)
    column = _exp(budget.column_log_pe) * ("column" in include)
    bg = budget.background_rate_hz * budget.window_length_s * ("background" in include)
    sig_b = np.where(budget.sigma_bottom_s > 0, budget.sigma_bottom_s, 1.0)
    w = budget.bottom_tail_weight
    tail = _bottom_tail(budget.t_bottom_s, sig_b, budget.bottom_tail_s)
    gauss_pe = [surf, bottom * (1.0 - w), bottom * w]
    centres = [budget.t_surface_s, budget.t_bottom_s, tail[0]]
    sigmas = [budget.sigma_surface_s, sig_b, tail[1]]
    types = [np.zeros(k), np.ones(k), np.ones(k)]
    kinds = [np.full((n, k), KIND_GAUSS), np.full((n, k), KIND_GAUSS), tail[2]]
    rates = [np.zeros((n, k)), np.zeros((n, k)), tail[3]]
    widths = [np.zeros((n, k)), np.zeros((n, k)), tail[4]]
    if budget.has_layer:
        gauss_pe.append(_exp(budget.log_layer) * ("layer" in include))
        centres.append(budget.t_layer_s)
        sigmas.append(np.where(budget.sigma_layer_s > 0, budget.sigma_layer_s, 1.0))
        types.append(np.full(k, TYPES.index("layer")))
        kinds.append(np.full((n, k), KIND_GAUSS))
        rates.append(np.zeros((n, k)))
        widths.append(np.zeros((n, k)))
    zeros = np.zeros((n, 1))
    expected = np.concatenate([*gauss_pe, column[:, None], bg[:, None]], axis=1)
    kind = np.concatenate([*kinds, zeros + KIND_COLUMN, zeros + KIND_UNIFORM], axis=1)
    comps = Components(
        expected=expected,
        kind=kind.astype(np.int8),
        centre_s=np.concatenate(
            [*centres, budget.column_start_s[:, None], budget.window_start_s[:, None]], axis=1
        ),
        sigma_s=np.concatenate([*sigmas, budget.column_sigma_s[:, None], zeros + 1.0], axis=1),
        rate_per_s=np.concatenate([*rates, budget.column_rate_per_s[:, None], zeros], axis=1),
        width_s=np.concatenate(
            [*widths, budget.column_width_s[:, None], zeros + budget.window_length_s], axis=1
        ),
    )
    ctype = np.r_[np.concatenate(types), 2, 3].astype(np.int64)
    return comps, ctype


def expected_waveform(budget: ReturnBudget) -> dict[str, np.ndarray]:
    """Noise-free expected photoelectrons per sample, by return type.

    Returns
    -------
    dict of str to (n_pulses, n_samples) float64
        ``surface``, ``land``, ``bottom``, ``layer`` (zeros without a layer), ``column``,
        ``background`` and ``total``.
    """
    out = {}
    m, dt = budget.n_samples, budget.sample_interval_s
    for name in RETURNS:
        comps, _ = build_components(budget, include=(name,))
        out[name] = expected_samples(comps, budget.t0_s, dt, m)
    out["total"] = sum(out[k] for k in RETURNS)
    return out


def _slices(n: int):
    for lo in range(0, n, SLICE_PULSES):
        yield slice(lo, min(n, lo + SLICE_PULSES))


def _sub_budget(b: ReturnBudget, s: slice) -> ReturnBudget:
    kw = {}
    for name, val in vars(b).items():
        kw[name] = val[s] if isinstance(val, np.ndarray) else val
    return ReturnBudget(**kw)


def _check_finite(name: str, a: np.ndarray) -> None:
    if not np.all(np.isfinite(a)):
        raise NumericalError(f"waveform stage produced non-finite `{name}`; please report.")


def simulate_waveforms(
    paths: P.Paths,
    scene,
    detector,
    settings: ReturnSettings | None = None,
    *,
    noise: bool = True,
    budget: ReturnBudget | None = None,
) -> Waveforms:
    """Full-waveform receiver: digitised waveforms of a chunk of traced pulses.

    Parameters
    ----------
    paths : Paths
        Traced geometry of the chunk.
    scene : Scene
        Optics, water, seabed, background and ``scene.seed``.
    detector : DetectorSettings
        Gain, noise, digitiser and window (its ``mode`` is not consulted here).
    settings : ReturnSettings, optional
        Model choices of the return budget.
    noise : bool
        False: the expected waveform through gain, baseline and clipping, unrounded.
    budget : ReturnBudget, optional
        A budget already computed for these paths (skips :func:`return_budget`).

    Returns
    -------
    Waveforms
    """
    b = budget or return_budget(paths, scene, detector, settings)
    seed = scene.scene.seed
    m, dt = b.n_samples, b.sample_interval_s
    samples = np.empty((b.n_pulses, m), dtype=np.float32)
    flags = np.empty(b.n_pulses, dtype=np.uint16)
    thr = detector.strong_return_photoelectrons
    for s in _slices(b.n_pulses):
        sb = _sub_budget(b, s)
        comps, ctype = build_components(sb)
        fl = pulse_flags(sb, detector, comps, ctype)
        if not noise:
            mean = expected_samples(comps, sb.t0_s, dt, m)
            samples[s], sat = digitise(detector, mean)
        else:
            totals = np.stack([comps.expected[:, ctype == t].sum(1) for t in range(len(TYPES))], 1)
            strong = (totals >= thr)[:, ctype]
            weak = comps.with_expected(np.where(strong, 0.0, comps.expected))
            keys = pulse_keys(seed, STREAM_PHOTONS, sb.pulse_id)
            counts, pulse, times, _, _, _ = draw_events(keys, weak)
            idx = np.floor((times - sb.t0_s[pulse]) / dt + 0.5).astype(np.int64)
            ok = (idx >= 0) & (idx < m)
            n_pe = np.bincount(pulse[ok] * m + idx[ok], minlength=sb.n_pulses * m)
            mu = None
            if strong.any():
                mu = expected_samples(comps.with_expected(np.where(strong, comps.expected, 0.0)),
                                      sb.t0_s, dt, m)  # fmt: skip
            z = block_normals(seed, STREAM_SAMPLES, sb.pulse_id, m)
            # (digitise of n + mu, (F - 1) n + F mu, in one compiled pass)
            samples[s], sat = digitise_drawn(detector, n_pe, mu, z)
        flags[s] = fl | np.where(sat, D.SATURATED, 0).astype(np.uint16)
    _check_finite("samples", samples)
    return Waveforms(b.pulse_id.copy(), b.t0_s.copy(), dt, samples, flags)


def simulate_photon_events(
    paths: P.Paths,
    scene,
    detector,
    settings: ReturnSettings | None = None,
    *,
    budget: ReturnBudget | None = None,
) -> PhotonEvents:
    """Photon-counting receiver: recorded event times per shot, after dead time.

    Parameters are those of :func:`simulate_waveforms` (without ``noise``).

    Returns
    -------
    PhotonEvents
        Events inside the range gate ``[gate_start, gate_start + n_samples dt)``; channel
        ``floor(u n_channels)`` with ``u`` from the event's own random stream.
    """
    b = budget or return_budget(paths, scene, detector, settings)
    seed = scene.scene.seed
    cap = detector.strong_return_photoelectrons
    parts_t, parts_c, counts_all, flags = [], [], [], np.empty(b.n_pulses, dtype=np.uint16)
    for s in _slices(b.n_pulses):
        sb = _sub_budget(b, s)
        comps, ctype = build_components(sb)
        fl = pulse_flags(sb, detector, comps, ctype)
        keys = pulse_keys(seed, STREAM_PHOTONS, sb.pulse_id)
        _, pulse, times, _, k, capped = draw_events(keys, comps, cap)
        _, u_ch = uniform_pair(keys[pulse], 2 * k + 2)
        chan = np.minimum((u_ch * detector.n_channels).astype(np.int64), detector.n_channels - 1)
        gate0 = sb.window_start_s[pulse]
        inside = (times >= gate0) & (times < gate0 + sb.window_length_s)
        pulse, times, chan = pulse[inside], times[inside], chan[inside]
        order, kept = dead_time_filter(pulse * detector.n_channels + chan, times,
                                       detector.dead_time_s)  # fmt: skip
        sel = order[kept]
        # back to shot order with times increasing per shot (channels interleaved)
        sel = sel[np.argsort(pulse[sel].astype(np.float64) + 1j * times[sel], kind="stable")]
        parts_t.append(times[sel])
        parts_c.append(chan[sel].astype(np.int16))
        counts_all.append(np.bincount(pulse[sel], minlength=sb.n_pulses))
        flags[s] = fl | np.where(capped, D.SATURATED, 0).astype(np.uint16)
    counts = np.concatenate(counts_all) if counts_all else np.zeros(0, dtype=np.int64)
    offsets = np.r_[0, np.cumsum(counts)].astype(np.int64)
    times = np.concatenate(parts_t) if parts_t else np.zeros(0)
    _check_finite("times_s", times)
    return PhotonEvents(
        pulse_id=b.pulse_id.copy(),
        gate_start_s=b.window_start_s.copy(),
        gate_length_s=b.window_length_s,
        offsets=offsets,
        times_s=times,
        channel=np.concatenate(parts_c) if parts_c else np.zeros(0, dtype=np.int16),
        flags=flags,
    )
