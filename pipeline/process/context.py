"""What processing assumes about the instrument, the navigation and the water, named in one place.

Processing never reads the simulator's truth; it does take over what a survey would know from
its own records: the system's wavelength and beam (the datasheet), the navigation solution's
quality figures (as an SBET reports them), the index of the air. Each of those values is a
``[process]`` key whose scene default is ``None``, meaning "from the scene's description of the
instrument"; a value the user sets always wins. :func:`processing_context` resolves them once,
and :meth:`ProcessingContext.to_dict` records every value used and where it came from (the
manifest's ``processing_context``).

The water indices are an assumption, not a record: by default processing assumes sea water of
``process.tpu.salinity_psu`` and ``process.tpu.temperature_c`` at the system's wavelength
(Quan & Fry 1995, :func:`pipeline.optics.water_phase_index`), never the scene's true water.

The wind is a record too: the survey's wind log (``process.wind_speed_m_s``; None: the scene's
``water.wind_speed_m_s`` stands for it, as cBLUE asks its user for the wind), uncertain by
``process.wind_sigma_m_s``. With ``process.wave_facet_correction`` (off by default: it failed
the held-out check) it sets the sea's mean-square slope (Cox & Munk 1954) whose facet path
excess refraction takes off the soundings (:mod:`pipeline.process.facet_excess`), only where
the survey's own echoes show a wave sea; off, ``RefractionSettings.facet_mss`` is 0.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from pipeline import optics
from pipeline.errors import SceneError
from pipeline.lidar_equation import COX_MUNK_SLOPE_PER_M_S, cox_munk_mean_square_slope
from pipeline.process.photon_windows import PhotonWindows, resolve_windows, sea_band_m
from pipeline.process.refraction import RefractionSettings
from pipeline.process.scatter_bias import bias_model
from pipeline.process.surface_fit import SurfaceFitSettings
from pipeline.uncertainty.tpu import TpuSettings
from pipeline.water_optics import attenuation_from_column

__all__ = [
    "Instrument",
    "ProcessingContext",
    "instrument",
    "processing_context",
    "with_measured_attenuation",
]

#: ``process.tpu`` keys taken over from the scene's instrument description when left unset:
#: key -> (dotted scene key, function of the scene giving the value).
_TPU_FROM_SCENE = {
    "position_sigma_h_m": (
        "navigation.gnss_horizontal_sigma_m",
        lambda s: s.navigation.gnss_horizontal_sigma_m,
    ),
    "position_sigma_v_m": (
        "navigation.gnss_vertical_sigma_m",
        lambda s: s.navigation.gnss_vertical_sigma_m,
    ),
    "attitude_sigma_deg": (
        "max(navigation.ins_roll_sigma_deg, navigation.ins_pitch_sigma_deg)",
        lambda s: max(s.navigation.ins_roll_sigma_deg, s.navigation.ins_pitch_sigma_deg),
    ),
    "heading_sigma_deg": (
        "navigation.ins_heading_sigma_deg",
        lambda s: s.navigation.ins_heading_sigma_deg,
    ),
    "beam_divergence_mrad": (
        "scanner.beam_divergence_mrad",
        lambda s: s.scanner.beam_divergence_mrad,
    ),
    "wavelength_nm": ("system.wavelength_nm", lambda s: s.system.wavelength_nm),
}


@dataclass(frozen=True)
class Instrument:
    """What processing knows of the receiver: its datasheet and its range gate.

    Attributes
    ----------
    mode : str
        ``"full_waveform"`` or ``"photon_counting"``.
    system_fwhm_s : float
        FWHM of the system response (transmitted pulse ⊗ detector impulse response).
    sample_interval_s : float
        Digitiser sample interval.
    noise_samples : int
        Leading samples of a waveform that hold noise only: the gate opens ``pre_trigger_s``
        before the first echo, less two system FWHM so the echo's leading edge stays out.
    shot_noise_counts : float
        The detector's excess-noise factor × counts per photoelectron (signal-dependent noise).
    window_s, pre_trigger_s : float
        Recording window and how long before the first echo it opens.
    air_index : float
        Index of air for the air range (the surface fit's).
    shots_per_window : int
        Photon counting: shots accumulated per detection window (one sounding), or per slab
        that ``window_cell_m`` splits.
    window_cell_m : float
        Photon counting: side of the cells that group a scan's shots into windows (0:
        consecutive shots), as given or sized from the plan
        (:func:`~pipeline.process.photon_windows.resolve_windows`).
    window_slab_shots : int
        Photon counting with cells: consecutive shots per slab of time the cells split.
    window_sea_band_m : float
        Photon counting with cells: the waves' height band at the logged wind below which a
        cell's bottom must lie (:func:`~pipeline.process.photon_windows.sea_band_m`).
    amplitude_full_scale : float
        The receiver's dynamic range in the detections' amplitude units, what LAS 1.4 scales
        intensity by (``65536 / dynamic range``): full waveform, the digitiser's
        ``2**bit_depth`` codes; photon counting, 65536 (an intensity unit per photon).
    """

    mode: str
    system_fwhm_s: float
    sample_interval_s: float
    noise_samples: int
    shot_noise_counts: float
    window_s: float
    pre_trigger_s: float
    air_index: float
    shots_per_window: int
    amplitude_full_scale: float = 65536.0
    window_cell_m: float = 0.0
    window_slab_shots: int = 0
    window_sea_band_m: float = 0.0

    @property
    def photon_counting(self) -> bool:
        """True for a photon-counting receiver."""
        return self.mode == "photon_counting"

    @property
    def windows(self) -> PhotonWindows | None:
        """How the photon-counting detector grouped the shots; None for full waveforms."""
        if not self.photon_counting:
            return None
        return PhotonWindows(
            self.shots_per_window,
            self.window_cell_m,
            self.window_slab_shots,
            self.window_sea_band_m,
        )


def instrument(scene, air_index: float) -> Instrument:
    """The receiver as the scene's ``[system]`` and ``[detector]`` records describe it."""
    det = scene.detector
    fwhm = math.hypot(scene.system.pulse_fwhm_s, det.impulse_response_fwhm_s)
    quiet_s = det.pre_trigger_s - 2.0 * fwhm
    pd, fl = scene.process.photon_detect, scene.flight
    win = PhotonWindows(pd.shots_per_window)
    if det.mode == "photon_counting" and fl is not None:
        win = resolve_windows(
            pd.shots_per_window, pd.window_cell_m, scene.scanner, fl.altitude_m, fl.speed_m_s
        )
    return Instrument(
        mode=det.mode,
        system_fwhm_s=fwhm,
        sample_interval_s=1.0 / det.sample_rate_hz,
        noise_samples=max(4, int(quiet_s * det.sample_rate_hz)),
        shot_noise_counts=det.excess_noise_factor * det.counts_per_photoelectron,
        window_s=det.window_s,
        pre_trigger_s=det.pre_trigger_s,
        air_index=air_index,
        shots_per_window=win.shots_per_window,
        window_cell_m=win.cell_m,
        window_slab_shots=win.slab_shots,
        amplitude_full_scale=(
            65536.0 if det.mode == "photon_counting" else float(2**det.bit_depth)
        ),
    )


@dataclass(frozen=True)
class ProcessingContext:
    """Resolved processing assumptions: every value a processing stage uses from outside the data.

    Attributes
    ----------
    tpu : TpuSettings
        A-priori uncertainties with every scene-derived value filled in.
    surface_fit : SurfaceFitSettings
        Surface-fit settings with the index of air filled in.
    refraction : RefractionSettings
        The water's phase and group index processing assumes, and the navigation sigmas of
        the a-priori point uncertainties (the TPU's).
    instrument : Instrument
        The receiver, its response and its gate.
    sources : dict of str to str
        For each resolved key, ``"user"`` or the scene key or model it came from.
    user_attenuation : bool
        The user set ``process.forward_scatter.beam_attenuation_per_m`` (a measured one
        does not replace it).
    """

    tpu: TpuSettings
    surface_fit: SurfaceFitSettings
    refraction: RefractionSettings
    instrument: Instrument
    sources: dict[str, str]
    user_attenuation: bool = False

    def to_dict(self) -> dict[str, Any]:
        """Values and sources, JSON-ready (the manifest's ``processing_context``)."""
        return {
            "values": {
                "tpu": dataclasses.asdict(self.tpu),
                "surface_fit": dataclasses.asdict(self.surface_fit),
                "refraction": dataclasses.asdict(self.refraction),
                "instrument": dataclasses.asdict(self.instrument),
            },
            "sources": dict(self.sources),
        }


def processing_context(scene) -> ProcessingContext:
    """Resolve the scene's ``[process]`` assumptions once (a user's value always wins).

    Parameters
    ----------
    scene : Scene
        A validated scene; only its ``process`` table and its description of the instrument
        (``system``, ``scanner``, ``navigation``, ``atmosphere``) are read.

    Returns
    -------
    ProcessingContext
    """
    ps = scene.process
    sources: dict[str, str] = {}
    tpu_fill = {}
    for key, (where, value) in _TPU_FROM_SCENE.items():
        if getattr(ps.tpu, key) is None:
            tpu_fill[key] = float(value(scene))
            sources[f"process.tpu.{key}"] = where
        else:
            sources[f"process.tpu.{key}"] = "user"
    tpu = dataclasses.replace(ps.tpu, **tpu_fill)
    fit = ps.surface_fit
    if fit.air_index is None:
        fit = dataclasses.replace(fit, air_index=float(scene.atmosphere.refractive_index))
        sources["process.surface_fit.air_index"] = "atmosphere.refractive_index"
    else:
        sources["process.surface_fit.air_index"] = "user"
    if not 400.0 <= tpu.wavelength_nm <= 700.0:
        # the sea-water index model and the TPU's index derivatives are fitted over 400-700 nm
        raise SceneError(
            f"`process.tpu.wavelength_nm` (from {sources['process.tpu.wavelength_nm']}) must be "
            f"within 400-700 nm for the water index processing assumes; got "
            f"{tpu.wavelength_nm:g}. Set `process.tpu.wavelength_nm`, "
            "`process.assumed_phase_index` and `process.assumed_group_index`."
        )
    lam_m = tpu.wavelength_nm * 1e-9
    water = (lam_m, tpu.salinity_psu, tpu.temperature_c)
    model = (
        f"sea water by Quan & Fry (1995) at {tpu.wavelength_nm:g} nm, "
        f"{tpu.salinity_psu:g} psu, {tpu.temperature_c:g} degC (process.tpu)"
    )
    phase, group = ps.assumed_phase_index, ps.assumed_group_index
    sources["process.assumed_phase_index"] = "user" if phase is not None else model
    sources["process.assumed_group_index"] = "user" if group is not None else model
    inst = instrument(scene, fit.air_index)
    fs = ps.forward_scatter
    fov = fs.receiver_fov_mrad
    sources["process.forward_scatter.receiver_fov_mrad"] = (
        "user" if fov is not None else "scanner.receiver_fov_mrad"
    )
    att = fs.beam_attenuation_per_m
    sources["process.forward_scatter.beam_attenuation_per_m"] = (
        "user" if att is not None else "process.forward_scatter.fallback_attenuation_per_m"
    )
    wind = ps.wind_speed_m_s
    sources["process.wind_speed_m_s"] = (
        "user" if wind is not None else "water.wind_speed_m_s (the survey's wind log)"
    )
    wind = float(wind if wind is not None else scene.water.wind_speed_m_s)
    if inst.photon_counting and inst.window_cell_m > 0.0:  # a scan's cells: the waves' band
        inst = dataclasses.replace(inst, window_sea_band_m=sea_band_m(wind))
    c_assumed = att if att is not None else fs.fallback_attenuation_per_m
    sources["process.facet_decay_per_m"] = (
        f"K_d = 0.2 c + 0.04 at c = {c_assumed:g}/m (process.forward_scatter)"
    )
    refr = RefractionSettings(
        facet_mss=float(cox_munk_mean_square_slope(wind)) if ps.wave_facet_correction else 0.0,
        # left uncorrected, the excess is still known to be there: the TPU carries its size
        facet_mss_uncorrected=(
            0.0 if ps.wave_facet_correction else float(cox_munk_mean_square_slope(wind))
        ),
        facet_mss_sigma=COX_MUNK_SLOPE_PER_M_S * ps.wind_sigma_m_s,
        facet_decay_per_m=0.2 * c_assumed + 0.04,
        phase_index=float(phase if phase is not None else optics.water_phase_index(*water)),
        group_index=float(group if group is not None else optics.water_group_index(*water)),
        position_sigma_h_m=tpu.position_sigma_h_m,
        position_sigma_v_m=tpu.position_sigma_v_m,
        forward_scatter=bias_model(
            fs,
            fov_mrad=float(fov if fov is not None else scene.scanner.receiver_fov_mrad),
            system_fwhm_s=inst.system_fwhm_s,
            sample_interval_s=0.0 if inst.photon_counting else inst.sample_interval_s,
            trend_fwhm=ps.detect.trend_fwhm,
            wavelength_nm=tpu.wavelength_nm,
            attenuation_per_m=att if att is not None else fs.fallback_attenuation_per_m,
        ),
    )
    return ProcessingContext(
        tpu=tpu,
        surface_fit=fit,
        refraction=refr,
        instrument=inst,
        sources=sources,
        user_attenuation=att is not None,
    )


def with_measured_attenuation(
    ctx: ProcessingContext, column_decay_per_m: float | None, r_air_m: float
) -> ProcessingContext:
    """The context with the forward-scattering correction at the measured water's ``c``.

    Only when the user gave no ``process.forward_scatter.beam_attenuation_per_m`` (theirs wins)
    and the survey measured its column decay (``column_decay_per_m``, the lidar decay of the
    stacked columns of its pulses, :mod:`pipeline.process.column_stack`); ``c`` is the one
    whose lidar decay at the median slant air range ``r_air_m`` matches it
    (:func:`~pipeline.water_optics.attenuation_from_column`).
    """
    fs = ctx.refraction.forward_scatter
    if fs is None or ctx.user_attenuation or column_decay_per_m is None:
        return ctx
    if not (math.isfinite(column_decay_per_m) and column_decay_per_m > 0.0):
        return ctx
    c = attenuation_from_column(column_decay_per_m, fs.fov_half_tan, r_air_m)
    sources = dict(ctx.sources)
    sources["process.forward_scatter.beam_attenuation_per_m"] = (
        f"measured column decay {column_decay_per_m:.4f}/m through Gordon's bridge "
        f"(K_d = 0.2 c + 0.04) at {r_air_m:.0f} m air range"
    )
    # the facets' paths are weighted by the bottom echo's own decay: the measured one
    sources["process.facet_decay_per_m"] = f"measured column decay {column_decay_per_m:.4f}/m"
    refr = dataclasses.replace(
        ctx.refraction,
        # the albedo follows the measured c when the user gave none (scatter_bias)
        forward_scatter=fs.at_attenuation(c),
        facet_decay_per_m=float(column_decay_per_m),
    )
    return dataclasses.replace(ctx, refraction=refr, sources=sources)
