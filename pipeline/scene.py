"""Scene files: TOML → validated, frozen settings, and the plan of stages a scene needs.

A scene file is the pipeline's serialisable spec: ``bathy run SCENE`` and
``pipeline.run.run_scene(load_scene(SCENE))`` produce the same outputs. Every key carries its
unit in its name (``altitude_m``, ``pulse_energy_j``, ``off_nadir_deg``); angles are in degrees in
the file and radians inside the code.

Examples
--------
>>> scene = load_scene(DEFAULT_SCENE_PATH)
>>> scene.system.wavelength_nm
532.0
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.config import from_mapping, setting
from pipeline.errors import SceneError
from pipeline.process.settings import ProcessSettings
from pipeline.simulate.budget import ReturnSettings
from pipeline.simulate.detector import DetectorSettings
from pipeline.simulate.noise import NavigationNoiseSettings
from pipeline.simulate.scanner import ScannerSettings
from pipeline.simulate.trace_settings import TraceSettings
from pipeline.simulate.trajectory import AttitudeSettings, FlightSettings
from pipeline.simulate.world import FrameSettings, SeabedSettings, WaterSurfaceSettings
from pipeline.water_optics import (
    default_backscatter_180_per_m_sr,
    default_diffuse_attenuation_per_m,
)

__all__ = [
    "SceneInfo",
    "SystemSettings",
    "AtmosphereSettings",
    "WaterSettings",
    "SeabedSettings",
    "BackgroundSettings",
    "ProfilerSettings",
    "RunSettings",
    "Scene",
    "load_scene",
    "parse_scene",
    "DEFAULT_SCENE_PATH",
]

#: The built-in scene run by ``bathy run`` with no argument.
DEFAULT_SCENE_PATH = Path(__file__).parent / "scenes" / "default.toml"


@dataclass(frozen=True, kw_only=True)
class SceneInfo:
    """Name, seed and free-text description of a scene."""

    name: str = setting(doc="short name used in output files")
    preset: str = setting(
        "", doc="system preset merged under this file's tables (pipeline/scenes/presets)"
    )
    seed: int = setting(0, ge=0, doc="seed of every random draw (with the chunk index)")
    description: str = setting("", doc="free text")


@dataclass(frozen=True, kw_only=True)
class SystemSettings:
    """The lidar instrument: transmitter, receiver and detector (the scan is in `scanner`)."""

    wavelength_nm: float = setting(532.0, gt=200.0, lt=2000.0, doc="laser wavelength")
    pulse_energy_j: float = setting(gt=0.0, le=1.0, doc="energy per transmitted pulse")
    transmitter_efficiency: float = setting(1.0, gt=0.0, le=1.0, doc="transmit optics")
    receiver_efficiency: float = setting(
        gt=0.0, le=1.0, doc="receive optics incl. filter and detector quantum efficiency"
    )
    telescope_diameter_m: float = setting(gt=0.0, le=5.0, doc="receiver aperture diameter")
    overlap_factor: float = setting(1.0, ge=0.0, le=1.0, doc="geometric overlap G(R)")
    pulse_fwhm_s: float = setting(gt=0.0, le=1e-6, doc="transmitted pulse FWHM")
    filter_bandwidth_nm: float = setting(gt=0.0, le=100.0, doc="receiver optical filter width")
    dark_count_rate_hz: float = setting(0.0, ge=0.0, doc="detector dark counts")


@dataclass(frozen=True, kw_only=True)
class AtmosphereSettings:
    """Air between the aircraft and the water."""

    extinction_per_m: float = setting(
        1.5e-4, ge=0.0, le=1.0, doc="air extinction at the laser wavelength"
    )
    refractive_index: float = setting(1.000277, ge=1.0, le=1.01, doc="phase index of air")


@dataclass(frozen=True, kw_only=True)
class WaterSettings:
    """Water optics and surface state."""

    phase_index: float = setting(1.3415, ge=1.0, le=2.0, doc="bends rays (Snell)")
    group_index: float = setting(1.3638, ge=1.0, le=2.0, doc="sets the pulse's travel time")
    extinction_per_m: float = setting(ge=0.0, le=100.0, doc="beam attenuation c = a + b")
    backscatter_180_per_m_sr: float | None = setting(
        None,
        ge=0.0,
        le=10.0,
        doc="volume scattering function at 180 degrees; None: from c and the albedo through "
        "Petzold's phase function (pipeline.water_optics)",
    )
    # 0.55: b/c of Petzold's (1972) coastal station (b = 0.219, c = 0.398 1/m at 530 nm)
    single_scattering_albedo: float = setting(
        0.55,
        ge=0.0,
        le=1.0,
        doc="b / c: sets the scattering of the default beta(180) and of "
        "the forward-scattering delay",
    )
    diffuse_attenuation_per_m: float | None = setting(
        None,
        ge=0.0,
        le=100.0,
        doc="diffuse attenuation K_d (<= c), the wide-field limit of the lidar attenuation; "
        "None: min(0.2 c + 0.04, c)",
    )
    wind_speed_m_s: float = setting(
        0.0, ge=0.0, le=40.0, doc="wind at 12.5 m; sets Cox-Munk slopes and whitecaps"
    )
    # an optional horizontal scattering layer (plankton, turbidity, thermocline): a uniform
    # slab whose extra backscatter gives an in-column echo (pipeline.simulate.budget)
    layer_depth_m: float = setting(
        0.0, ge=0.0, le=11000.0, doc="scattering layer's centre below the mean water level; 0: none"
    )
    layer_thickness_m: float = setting(
        1.0, gt=0.0, le=1000.0, doc="vertical thickness of the scattering layer"
    )
    layer_backscatter_per_m_sr: float = setting(
        0.0, ge=0.0, le=10.0, doc="extra volume scattering function at 180 degrees in the layer"
    )

    @property
    def scattering_per_m(self) -> float:
        """Scattering coefficient ``b = omega_0 c``."""
        return self.single_scattering_albedo * self.extinction_per_m

    @property
    def kd_per_m(self) -> float:
        """K_d: the scene's, or ``min(0.2 c + 0.04, c)`` (:mod:`pipeline.water_optics`)."""
        if self.diffuse_attenuation_per_m is not None:
            return self.diffuse_attenuation_per_m
        return default_diffuse_attenuation_per_m(self.extinction_per_m)

    def beta_180_per_m_sr(self, wavelength_nm: float) -> float:
        """beta(180): the scene's, or from ``c`` and the albedo via the named phase functions."""
        if self.backscatter_180_per_m_sr is not None:
            return self.backscatter_180_per_m_sr
        return default_backscatter_180_per_m_sr(
            self.extinction_per_m, self.single_scattering_albedo, wavelength_nm
        )

    @property
    def has_layer(self) -> bool:
        """True when the scene has a scattering layer (``layer_depth_m > 0``)."""
        return self.layer_depth_m > 0.0

    def __post_init__(self) -> None:
        kd = self.diffuse_attenuation_per_m
        if kd is not None and kd > self.extinction_per_m:
            raise SceneError(
                f"`water.diffuse_attenuation_per_m` must be <= `water.extinction_per_m` = "
                f"{self.extinction_per_m} (the lidar attenuation runs from c down to K_d); "
                f"got {kd}."
            )
        d, t, b = self.layer_depth_m, self.layer_thickness_m, self.layer_backscatter_per_m_sr
        if d > 0.0 and b <= 0.0:
            raise SceneError(
                f"`water.layer_backscatter_per_m_sr` must be > 0 when `water.layer_depth_m` > 0 "
                f"(a layer needs backscatter); got {b}."
            )
        if d == 0.0 and b > 0.0:
            raise SceneError(
                f"`water.layer_depth_m` must be > 0 when `water.layer_backscatter_per_m_sr` is "
                f"set (0 means no layer); got {d}."
            )
        if d > 0.0 and t > 2.0 * d:
            raise SceneError(
                f"`water.layer_thickness_m` must be <= 2 x `water.layer_depth_m` = {2.0 * d} m "
                f"(the layer lies below the surface); got {t}."
            )


@dataclass(frozen=True, kw_only=True)
class BackgroundSettings:
    """Solar background seen by the receiver."""

    solar_irradiance_w_m2_nm: float = setting(
        0.0, ge=0.0, le=2.5, doc="downwelling spectral irradiance at the sea surface"
    )
    scene_reflectance: float = setting(
        0.05, ge=0.0, le=1.0, doc="water-leaving + reflected sunlight, as a Lambertian albedo"
    )


@dataclass(frozen=True, kw_only=True)
class ProfilerSettings:
    """The nadir profiling bathymeter of the reference document (Figures 14-17)."""

    altitude_m: float = setting(gt=0.0, le=20000.0, doc="height above the water surface")
    depth_sweep_m: tuple[float, float] = setting(
        (0.1, 60.0), gt=0.0, le=500.0, doc="depth range of the photon-budget figures"
    )
    shot_counts: tuple[int, ...] = setting(
        (1, 10, 100, 1000, 10000), ge=1, le=10_000_000, doc="shots accumulated per histogram"
    )
    bin_width_s: float = setting(5e-10, gt=0.0, le=1e-6, doc="histogram bin width")
    gate_before_surface_s: float = setting(5e-8, ge=0.0, le=1e-5, doc="range gate opens")
    gate_after_floor_s: float = setting(5e-8, ge=0.0, le=1e-5, doc="range gate closes")

    def __post_init__(self) -> None:
        lo, hi = self.depth_sweep_m
        if not lo < hi:
            raise SceneError(
                f"`profiler.depth_sweep_m` must be [min, max] with min < max; got [{lo}, {hi}]."
            )


@dataclass(frozen=True, kw_only=True)
class RunSettings:
    """How the run is executed.

    Never what it computes, except that a blocked survey with more than ``sample_pulses``
    pulses measures its survey-wide figures, and is evaluated, on a sample of its blocks.
    """

    chunk_pulses: int = setting(100_000, ge=1, le=10_000_000, doc="pulses per streamed chunk")
    tile_m: float | None = setting(
        250.0,
        gt=0.0,
        le=1e6,
        doc="side of the square tiles the grid and the points file are made by (local frame), "
        "rounded to a whole number of grid cells so a cell lies in one tile; larger than the "
        "survey: one tile (the outputs are the same for any tile size)",
    )
    views: bool = setting(
        True,
        doc="write the 3D views (view/*.vtp) and the report's pictures; false leaves them out "
        "(runs of many scenes, as bathy suite makes: a few seconds and hundreds of MB each)",
    )
    whole_pulses: int = setting(
        750_000,
        ge=1000,
        le=1_000_000_000,
        doc="a survey of more pulses (or of more than run.block_pulses) is processed block by "
        "block: held whole, its process needs about 0.5 GB + 1.77 kB a pulse (2 GiB near "
        "930 000 pulses; pipeline.memory_budget), blocked at most what its sample or a block "
        "needs, whatever the survey's size (the sample, run.sample_pulses, is held whole: "
        "keep it below)",
    )
    block_pulses: int = setting(
        1_000_000,
        ge=1000,
        le=1_000_000_000,
        doc="a survey of more pulses (or of more than run.whole_pulses) is processed block by "
        "block after the chunk loop, each block (with its halo) holding about this many "
        "pulses: memory stays bounded "
        "(pipeline.survey_blocks)",
    )
    block_m: float | None = setting(
        None,
        gt=0.0,
        le=1e6,
        doc="side of those blocks (local frame, rounded to whole grid cells); set: blocks "
        "whatever the survey's size; None: from run.block_pulses and the pulse density",
    )
    sample_pulses: int = setting(
        500_000,
        ge=1000,
        le=1_000_000_000,
        doc="a blocked survey's survey-wide figures (water level, sea, TPU figures) and its "
        "evaluation, report and views come from whole blocks holding at most this many pulses, "
        "spread over it and processed as a survey of their own (all of it when it has fewer)",
    )


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A whole validated scene; sections a scene does not have are ``None``."""

    scene: SceneInfo = setting(doc="name and seed")
    system: SystemSettings = setting(doc="the lidar")
    scanner: ScannerSettings = setting(doc="scan pattern, pulse rate, beam and field of view")
    atmosphere: AtmosphereSettings = setting(AtmosphereSettings(), doc="air")
    water: WaterSettings = setting(doc="water")
    seabed: SeabedSettings = setting(doc="the seabed (truth)")
    water_surface: WaterSurfaceSettings = setting(WaterSurfaceSettings(), doc="flat or waves")
    frame: FrameSettings = setting(FrameSettings(), doc="local origin and CRS")
    background: BackgroundSettings = setting(BackgroundSettings(), doc="sunlight")
    profiler: ProfilerSettings | None = setting(None, doc="nadir profiling bathymeter")
    flight: FlightSettings | None = setting(None, doc="survey flight lines")
    attitude: AttitudeSettings = setting(AttitudeSettings(), doc="aircraft motion")
    navigation: NavigationNoiseSettings = setting(
        NavigationNoiseSettings(), doc="GNSS/INS errors of the measured trajectory"
    )
    trace: TraceSettings = setting(TraceSettings(), doc="sub-rays per footprint")
    detector: DetectorSettings = setting(DetectorSettings(), doc="receiver and digitiser")
    returns: ReturnSettings = setting(ReturnSettings(), doc="return-model choices")
    process: ProcessSettings = setting(ProcessSettings(), doc="processing of measured data")
    run: RunSettings = setting(RunSettings(), doc="chunking")

    def to_dict(self) -> dict[str, Any]:
        """Return the scene as plain data (what was validated, defaults filled in)."""
        return dataclasses.asdict(self)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """Deep merge: tables of ``over`` update those of ``base`` key by key."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def _with_preset(data: dict[str, Any]) -> dict[str, Any]:
    """The scene mapping with its preset's tables underneath (the file's keys win)."""
    info = data.get("scene")
    name = info.get("preset") if isinstance(info, dict) else None
    if not name:
        return data
    if not isinstance(name, str):
        raise SceneError(f"`scene.preset` must be a string; got {name!r}.")
    from pipeline.simulate.detector import load_preset

    return _merge(load_preset(name), data)


def parse_scene(data: dict[str, Any], source: str = "scene") -> Scene:
    """Validate parsed TOML ``data`` into a :class:`Scene`.

    Raises
    ------
    SceneError
        Naming the first offending key, its value and what is allowed.
    """
    data = _with_preset(data)
    scene = from_mapping(Scene, data, "")
    if scene.profiler is None and scene.flight is None:
        raise SceneError(
            f"{source}: no stage to run: add a `[profiler]` table (nadir profiling bathymeter) "
            "or a `[flight]` table (a survey)."
        )
    from pipeline.feasibility import check_feasible

    check_feasible(scene)
    return scene


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file.

    Parameters
    ----------
    path : str or Path
        The scene file.

    Raises
    ------
    SceneError
        If the file is missing, is not valid TOML, or any key is invalid.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(f"Scene file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"Cannot read scene file {path}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path} is not valid TOML: {exc}") from None
    return parse_scene(data, str(path))
