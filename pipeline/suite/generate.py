"""Random survey scenes over the conditions users fly, and the tuning / held-out split.

One seed gives one scene, drawn by ``numpy.random.default_rng(seed)`` in a fixed order
(:func:`draw`), written as a TOML scene file that uses only the scene keys ``bathy keys``
lists (:func:`scene_toml`): the same seed always gives the same file, byte for byte.

Conditions (uniform unless said; the issue "Right off the shipped scenes", item 1):

=====================  =======================================================================
wind                   0-12 m/s at 12.5 m; surface ``waves`` with probability 1/2 (from 1 m/s),
                       else ``flat`` (the wind then only sets Cox-Munk slopes and whitecaps)
seabed                 plane, slope 0-20 deg, downslope east (across track) or north (along);
                       roughness with probability 1/2 (0.05-0.3 m RMS, 3-10 m correlation)
attenuation            beam attenuation c log-uniform in 0.05-0.8 1/m
depths                 depth at the line centre from the shoreline (land 0-3 m high, 1 in 6)
                       to past the extinction depth (planning guess 4.5 / c, capped at 60 m)
altitude               200-800 m
scanner / receiver     full waveform (3 in 4): Palmer 1/2, oscillating 3/10, profiler 1/5;
                       photon counting (1 in 4): nadir profiler, windows of consecutive shots
                       (a scanner, with the preset's cell windows, only when ``force`` asks:
                       the draws of the suite's seeds stay those its tables were made from)
features               one IHO cube each of 0.5, 1 and 2 m, under the scan (a Palmer circle's
                       trailing arc) where the plane is 1.5 m to half the planning extinction
                       depth deep, when the slope allows (:func:`_cube_xy`); seabed mesh 0.5 m
                       under a profiler, 1 m under a scanner: the mesh samples a cube, so a
                       cube smaller than two mesh cells loses its top and its detection
                       there is a lower bound
=====================  =======================================================================

**The split** (:func:`half`): a seed is ``"heldout"`` when the first byte of
``sha256(b"bathy-suite:" + str(seed))`` is odd, else ``"tuning"``. Fixed once, independent of
the draw and of the scene's outcome. **Never tune on the held-out half**: no threshold, constant
or model choice may be set by looking at a held-out scene's results.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from pipeline.water_optics import PETZOLD_NONWATER_ALBEDOS

__all__ = [
    "Draw",
    "half",
    "suite_seeds",
    "draw",
    "NONWATER_ALBEDO_RANGE",
    "CI_SCENES",
    "ci_draws",
]

#: Fixed CI subset: (seed, forced values) of small ("ci") scenes. The forced values make the
#: eight cover both receivers, the three scanners, both surfaces, clear and turbid water and
#: depths a few metres to past extinction (and the shoreline); every other value is the
#: seed's own draw. Seeds from both halves (see :func:`half`).
_CI_KEYS = ("receiver", "scanner", "surface", "depth_centre_m", "attenuation_per_m", "wind_m_s")
_FW, _PC = "full_waveform", "photon_counting"
# seed, then the forced values in the order of _CI_KEYS (None: the seed's own draw). 9007's own
# wind, 1 m/s, makes the wave synthesis fail (terrain.WaveField: "mss calibration failed").
_CI_TABLE = (
    (9001, _FW, "palmer", "flat", 6.0, 0.15, None),
    (9002, _FW, "oscillating", "waves", 8.0, 0.1, None),
    (9003, _FW, "profiler", "flat", 4.0, 0.3, None),
    (9004, _PC, "profiler", "flat", 5.0, 0.1, None),
    (9005, _FW, "palmer", "waves", 3.0, 0.6, None),
    (9006, _FW, "oscillating", "flat", 0.5, 0.2, None),
    (9007, _PC, "profiler", "waves", 3.0, 0.15, 3.0),
    (9008, _FW, "profiler", "waves", 25.0, 0.08, None),
)
CI_SCENES: tuple[tuple[int, dict[str, Any]], ...] = tuple(
    (row[0], {k: v for k, v in zip(_CI_KEYS, row[1:], strict=True) if v is not None})
    for row in _CI_TABLE
)

#: The drawn ranges of the beam attenuation (log-uniform) and the altitude (uniform)
ATTENUATION_RANGE_PER_M = (0.05, 0.8)
ALTITUDE_RANGE_M = (200.0, 800.0)
#: The drawn range of the non-sea-water matter's albedo: Petzold's clear ocean to his turbid
#: harbour (:data:`pipeline.water_optics.PETZOLD_NONWATER_ALBEDOS`)
NONWATER_ALBEDO_RANGE = (PETZOLD_NONWATER_ALBEDOS[0], PETZOLD_NONWATER_ALBEDOS[-1])
#: Half the scan angle of the suite's scanners (the presets' Palmer and oscillating scans)
SCAN_HALF_ANGLE_DEG = 20.0
_GROUP_INDEX = 1.3638  # sea water at 532 nm (the presets' value): sizes the range gate only
_C0_M_S = 299_792_458.0


def half(seed: int) -> str:
    """``"tuning"`` or ``"heldout"``: the seed's half, fixed once (see the module docstring)."""
    digest = hashlib.sha256(b"bathy-suite:" + str(int(seed)).encode()).digest()
    return "heldout" if digest[0] & 1 else "tuning"


def suite_seeds(n: int, which: str = "both", start: int = 0) -> list[int]:
    """The first ``n`` seeds from ``start`` of the half ``which`` (``both``: half of each).

    Parameters
    ----------
    n : int
        Number of scenes.
    which : {"tuning", "heldout", "both"}
    start : int
        First seed looked at.

    Returns
    -------
    list of int
        Increasing seeds; with ``both``, ``ceil(n/2)`` tuning and ``floor(n/2)`` held-out.
    """
    if which not in ("tuning", "heldout", "both"):
        raise ValueError(f"half must be tuning, heldout or both, not {which!r}")
    want = {"tuning": n, "heldout": 0} if which == "tuning" else {"tuning": 0, "heldout": n}
    if which == "both":
        want = {"tuning": (n + 1) // 2, "heldout": n // 2}
    out, seed = [], start
    while sum(want.values()) > 0:
        h = half(seed)
        if want[h] > 0:
            out.append(seed)
            want[h] -= 1
        seed += 1
    return out


@dataclass(frozen=True)
class Draw:
    """The drawn conditions of one scene (SI units in the names)."""

    seed: int
    size: str
    receiver: str
    scanner: str
    surface: str
    wind_m_s: float
    attenuation_per_m: float
    slope_deg: float
    aspect_deg: float
    roughness_rms_m: float
    roughness_correlation_m: float
    altitude_m: float
    depth_centre_m: float
    line_length_m: float
    prf_hz: float
    reflectance: float
    window_s: float
    cubes: tuple[tuple[float, float, float], ...] = field(default_factory=tuple)
    logged_wind_m_s: float | None = None
    #: seabed mesh resolution (m); None: 0.5 under a profiler, 1 under a scanner
    mesh_m: float | None = None
    #: b / c of the water's matter that is not sea water (:func:`_nonwater_albedo`); None: the
    #: scene keeps the default single-scattering albedo
    nonwater_albedo: float | None = None

    @property
    def half(self) -> str:
        """The seed's half (:func:`half`)."""
        return half(self.seed)

    def to_dict(self) -> dict[str, Any]:
        """Plain data, with the half."""
        return {**asdict(self), "half": self.half, "cubes": [list(c) for c in self.cubes]}


def _choice(rng, options: tuple[str, ...], p: tuple[float, ...]) -> str:
    return str(options[int(rng.choice(len(options), p=p))])


def draw(seed: int, size: str = "suite", force: dict[str, str] | None = None) -> Draw:
    """The scene conditions of ``seed``.

    Parameters
    ----------
    seed : int
    size : {"suite", "ci"}
        ``suite``: lines of 120-200 m (tens of seconds per scene); ``ci``: lines of 40-60 m and
        a lower pulse rate (a few seconds).
    force : dict, optional
        Values to impose (``receiver``, ``scanner``, ``surface``, ``depth_centre_m``,
        ``attenuation_per_m``, ``wind_m_s``, ``slope_deg``, ``aspect_deg``,
        ``roughness_rms_m``, ``altitude_m``); every value is still drawn first, in the same
        order, so the rest of the scene does not change.

    Returns
    -------
    Draw
    """
    rng = np.random.default_rng(int(seed))
    receiver = _choice(rng, ("full_waveform", "photon_counting"), (0.75, 0.25))
    scanner = _choice(rng, ("palmer", "oscillating", "profiler"), (0.5, 0.3, 0.2))
    wind = float(rng.uniform(0.0, 12.0))
    surface = "waves" if (rng.uniform() < 0.5 and wind >= 1.0) else "flat"
    c = float(math.exp(rng.uniform(*np.log(ATTENUATION_RANGE_PER_M))))
    slope = float(rng.uniform(0.0, 20.0))
    aspect = float(rng.choice((0.0, 90.0)))
    rough = rng.uniform() < 0.5
    rough_rms = float(rng.uniform(0.05, 0.3)) if rough else 0.0
    rough_corr = float(rng.uniform(3.0, 10.0))
    altitude = float(rng.uniform(*ALTITUDE_RANGE_M))
    ext_guess = min(4.5 / c, 60.0)
    shore = rng.uniform() < 1.0 / 6.0
    d_centre = float(rng.uniform(-3.0, 1.0) if shore else rng.uniform(0.1, 1.2 * ext_guess))
    reflectance = float(rng.uniform(0.1, 0.4))
    u_line = float(rng.uniform())
    u_prf = float(rng.uniform())
    u_cubes = rng.uniform(size=(3, 2))
    force = force or {}
    receiver = force.get("receiver", receiver)
    scanner = force.get("scanner", scanner)
    surface = force.get("surface", surface)
    d_centre = float(force.get("depth_centre_m", d_centre))
    c = float(force.get("attenuation_per_m", c))
    wind = float(force.get("wind_m_s", wind))
    slope = float(force.get("slope_deg", slope))
    aspect = float(force.get("aspect_deg", aspect))
    rough_rms = float(force.get("roughness_rms_m", rough_rms))
    altitude = float(force.get("altitude_m", altitude))
    ext_guess = min(4.5 / c, 60.0)
    if surface == "waves":
        wind = max(wind, 1.0)  # a wind sea needs wind
    if receiver == "photon_counting" and "scanner" not in force:
        scanner = "profiler"  # a scan's cell windows are drawn only when forced (below)
    ci = size == "ci"
    line = (40.0 + 20.0 * u_line) if ci else (120.0 + 80.0 * u_line)
    if receiver == "photon_counting":
        prf = 32000.0 if not ci else 16000.0  # the preset's rate; CI halves it
    elif scanner == "profiler":
        prf = 2000.0 + 3000.0 * u_prf
    else:
        prf = (4000.0 + 4000.0 * u_prf) if ci else (8000.0 + 17000.0 * u_prf)
    half_swath = half_swath_m(scanner, altitude)
    cubes = []
    for size_m, (ua, ub) in zip((0.5, 1.0, 2.0), u_cubes, strict=True):
        x, y = _cube_xy(
            ua, ub, half_swath, line, scanner == "palmer", d_centre, slope, aspect, ext_guess
        )
        cubes.append((round(float(x), 2), round(float(y), 2), size_m))
    # deepest seabed in view: the centre depth plus the slope across the swath or along the line
    reach = half_swath if aspect == 90.0 else 0.5 * line + half_swath
    d_max = max(d_centre + math.tan(math.radians(slope)) * reach + 3.0 * rough_rms, 1.0)
    d_max = min(d_max, 1.5 * ext_guess + 5.0)  # past extinction nothing comes back anyway
    theta_w = math.asin(math.sin(math.radians(SCAN_HALF_ANGLE_DEG)) / 1.34)
    window = 2e-8 + 2.0 * _GROUP_INDEX * (d_max / math.cos(theta_w) + 2.0) / _C0_M_S + 4e-8
    window = float(np.clip(window, 1.5e-7, 8e-7))
    return Draw(
        seed=int(seed),
        size=size,
        receiver=receiver,
        scanner=scanner,
        surface=surface,
        wind_m_s=round(wind, 3),
        attenuation_per_m=round(c, 4),
        slope_deg=round(slope, 3),
        aspect_deg=aspect,
        roughness_rms_m=round(rough_rms, 3),
        roughness_correlation_m=round(rough_corr, 2),
        altitude_m=round(altitude, 1),
        depth_centre_m=round(d_centre, 3),
        line_length_m=round(line, 1),
        prf_hz=round(prf, 0),
        reflectance=round(reflectance, 3),
        window_s=float(f"{window:.3e}"),
        cubes=tuple(cubes),
        logged_wind_m_s=_logged_wind(seed, wind),
        nonwater_albedo=_nonwater_albedo(seed),
    )


#: Sigma of the survey's logged wind against the wind the sea was raised by (m/s): a met
#: station's or a forecast's hourly mean against the local sea's, as ``process.wind_sigma_m_s``
#: assumes by default.
LOGGED_WIND_SIGMA_M_S = 2.0


def _logged_wind(seed: int, wind_m_s: float) -> float:
    """The wind the survey logged: the sea's wind plus a met record's error, to 0.5 m/s.

    Its own random stream (``[seed, 1954]``), so every other condition of the seed's draw is as
    before the log was drawn. Processing reads this, never the sea's wind.
    """
    err = float(np.random.default_rng([int(seed), 1954]).normal(0.0, LOGGED_WIND_SIGMA_M_S))
    return round(max(wind_m_s + err, 0.0) * 2.0) / 2.0


def _nonwater_albedo(seed: int) -> float:
    """``b / c`` of the matter in the water beside sea water, over Petzold's three waters.

    Uniform over :data:`NONWATER_ALBEDO_RANGE`; with sea water's own absorption and scattering
    it sets the scene's single-scattering albedo
    (:func:`pipeline.water_optics.albedo_from_nonwater`), which the forward-scattering delay of
    the bottom echo follows and processing does not know. Its own random stream (``[seed,
    1972]``), so every other condition of the seed's draw is as before.
    """
    u = float(np.random.default_rng([int(seed), 1972]).uniform(*NONWATER_ALBEDO_RANGE))
    return round(u, 3)


#: cube bases between these depths where the plane allows (m; and a fraction of 4.5 / c)
_CUBE_MIN_DEPTH_M = 1.5
_CUBE_EXT_FRACTION = 0.5


def cube_base_range_m(ext_guess: float) -> tuple[float, float]:
    """Depths (m) a cube's base is drawn between, for a planning extinction depth."""
    return _CUBE_MIN_DEPTH_M, max(_CUBE_MIN_DEPTH_M + 1.0, _CUBE_EXT_FRACTION * ext_guess)


def half_swath_m(scanner: str, altitude_m: float) -> float:
    """Half the swath's width on the ground (m): 0 under a profiler."""
    if scanner == "profiler":
        return 0.0
    return altitude_m * math.tan(math.radians(SCAN_HALF_ANGLE_DEG))


def _cube_xy(ua, ub, half_swath, line, palmer, d_centre, slope_deg, aspect_deg, ext_guess):
    """Where a cube goes: under the scan, on seabed a survey can reach.

    The cube's base depth is drawn (``ua``) between :data:`_CUBE_MIN_DEPTH_M` and
    :data:`_CUBE_EXT_FRACTION` of the planning extinction depth, and the cube put where the
    plane (depth ``d_centre`` at the origin, ``tan(slope)`` per metre along the aspect) has that
    depth, clipped to the swath (0.9 of its half width across, 0.15-0.85 of the line along);
    without slope across (or along) the track, ``ua`` (``ub``) places it uniformly instead. A
    Palmer scan's footprints lie on a circle of the half swath's radius about the aircraft, so
    its cubes go on the circle's trailing arc (``y = y_aircraft - sqrt(R^2 - x^2)``) for an
    aircraft position within the line: inside the circle a short line leaves no sounding. A
    profiler's cubes sit on its planned track (the flown track wanders by metres: see the
    issue's feature report).
    """
    lo, hi = cube_base_range_m(ext_guess)
    grad = math.tan(math.radians(slope_deg))
    target = lo + ua * (hi - lo)
    across = aspect_deg == 90.0 and grad > 1e-3
    if across:  # depth varies with x
        x = float(np.clip((target - d_centre) / grad, -0.9 * half_swath, 0.9 * half_swath))
    else:
        x = (2.0 * ua - 1.0) * 0.9 * half_swath
    back = math.sqrt(max(half_swath**2 - x**2, 0.0)) if palmer else 0.0
    y_ac = (0.15 + 0.7 * ub) * line
    if not across and grad > 1e-3:  # depth varies with y: the aircraft where the cube is
        y_want = (target - d_centre) / grad + back
        # out of the line: the uniform place (clipping would stack a profiler's cubes)
        if 0.15 * line <= y_want <= 0.85 * line:
            y_ac = y_want
    return x, y_ac - back


def ci_draws() -> list[Draw]:
    """The fixed CI subset (:data:`CI_SCENES`), small scenes."""
    return [draw(seed, "ci", force) for seed, force in CI_SCENES]
