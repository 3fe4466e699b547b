"""The simulated world of a scene: seabed and water surface (truth) and their ray casters.

Settings for ``[seabed]``, ``[[seabed.features]]``, ``[water_surface]`` and ``[frame]`` live
here; :func:`build_truth` turns them into :mod:`terrain` surfaces (the exact truth, kept for
evaluation) and :func:`build_world` into meshes for the tracer.

The wave field is periodic and moves: it is one period tile evaluated at each pulse's time
(:class:`terrain.evolving_sea.EvolvingSea`), and rays meet it on the height field itself
(:class:`pipeline.simulate.wave_caster.WaveCaster`), with no mesh, so memory stays a few tile
grids at any survey size and length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from pipeline.config import setting
from pipeline.errors import SceneError

__all__ = [
    "FeatureSettings",
    "SeabedSettings",
    "WaterSurfaceSettings",
    "FrameSettings",
    "Truth",
    "build_truth",
    "build_world",
    "wave_surface",
]

FEATURE_KINDS = ("cube", "wreck", "ridge", "channel")
#: Nodes a side of the roughness field's periodic tile by default: 33 MB, ~130 MB while
#: synthesised. The Palmer scene's 1 m nodes and 8 m correlation make it 256 correlation
#: lengths (variance sampled to ~sqrt(pi) 8 / 2048 = 0.7 %); a finer mesh shortens it (0.1 m:
#: 205 m, 26 lengths, ~7 %): set ``seabed.roughness_period_m`` for more.
ROUGHNESS_MAX_NODES = 2048


@dataclass(frozen=True, kw_only=True)
class FeatureSettings:
    """One seabed feature, added to the base seabed."""

    kind: str = setting(choices=FEATURE_KINDS, doc="feature type")
    x_m: float = setting(doc="local easting of its centre")
    y_m: float = setting(doc="local northing of its centre")
    # at least 1 cm: below any footprint, and a smaller box's triangles degenerate against
    # coordinates of hundreds of metres (seabed.features[0].size_m = 1e-300 was a crash)
    size_m: float = setting(1.0, ge=0.01, le=1000.0, doc="cube side (IHO: 0.5, 1, 2 m)")
    length_m: float = setting(20.0, ge=0.01, doc="wreck length, or ridge/channel length")
    width_m: float = setting(5.0, ge=0.01, doc="wreck width, or ridge/channel FWHM")
    height_m: float = setting(2.0, ge=0.01, le=100.0, doc="wreck/ridge height or channel depth")
    heading_deg: float = setting(0.0, ge=-360.0, le=360.0, doc="orientation, from north")


@dataclass(frozen=True, kw_only=True)
class SeabedSettings:
    """The seabed: a plane or beach, plus roughness and features; or a GeoTIFF DEM."""

    kind: str = setting("plane", choices=("plane", "beach", "dem"), doc="base surface")
    depth_m: float = setting(
        ge=-50.0,
        le=11000.0,
        doc="plane/beach: depth below the water level at (0, 0); dem: unused (z is absolute)",
    )
    reflectance: float = setting(ge=0.0, le=1.0, doc="Lambertian bottom reflectance")
    slope_deg: float = setting(0.0, ge=0.0, lt=60.0, doc="plane: seabed slope")
    aspect_deg: float = setting(0.0, ge=-360.0, le=360.0, doc="plane: downslope azimuth")
    beach_gradient: float = setting(0.02, gt=0.0, le=1.0, doc="beach: seaward gradient")
    seaward_deg: float = setting(0.0, ge=-360.0, le=360.0, doc="beach: seaward azimuth")
    berm_height_m: float = setting(2.0, ge=0.0, le=50.0, doc="beach: berm above the shoreline")
    dem_path: str = setting("", doc="dem: GeoTIFF of elevation (m, positive up)")
    roughness_rms_m: float = setting(0.0, ge=0.0, le=50.0, doc="RMS height of roughness")
    roughness_correlation_m: float = setting(10.0, gt=0.0, le=1e4, doc="correlation length")
    roughness_spectrum: str = setting(
        "gaussian", choices=("gaussian", "von_karman"), doc="roughness autocorrelation"
    )
    roughness_hurst: float = setting(0.8, gt=0.0, lt=1.0, doc="von Karman Hurst exponent")
    roughness_period_m: float | None = setting(
        None,
        gt=0.0,
        doc="side of the roughness field's repeating tile (None: the survey's extent, at most "
        f"{ROUGHNESS_MAX_NODES} grid nodes a side, so memory does not grow with the area)",
    )
    mesh_resolution_m: float = setting(1.0, gt=0.0, le=100.0, doc="seabed mesh grid spacing")
    features: tuple[FeatureSettings, ...] = setting((), doc="cubes, wrecks, ridges, channels")

    def __post_init__(self) -> None:
        if self.kind == "dem" and not self.dem_path:
            raise SceneError("`seabed.dem_path` must name a GeoTIFF when `seabed.kind` = 'dem'.")
        if self.roughness_period_m is not None:
            nodes = self.roughness_period_m / self.roughness_spacing_m
            if not 8 <= nodes <= 8192:
                raise SceneError(
                    f"`seabed.roughness_period_m` = {self.roughness_period_m} gives {nodes:.0f} "
                    f"roughness nodes a side at {self.roughness_spacing_m} m; allowed: 8 to 8192"
                )

    @property
    def roughness_spacing_m(self) -> float:
        """Node spacing of the roughness field: the mesh's, finer for short correlations."""
        return min(self.mesh_resolution_m, self.roughness_correlation_m / 4)

    def roughness_period(self, extent_m) -> tuple[float, float, float, float]:
        """The roughness field's periodic tile over ``extent_m`` (xmin, xmax, ymin, ymax)."""
        xmin, xmax, ymin, ymax = extent_m
        if self.roughness_period_m is not None:
            side = self.roughness_period_m
            return (xmin, xmin + side, ymin, ymin + side)
        side = ROUGHNESS_MAX_NODES * self.roughness_spacing_m
        return (xmin, min(xmax, xmin + side), ymin, min(ymax, ymin + side))


@dataclass(frozen=True, kw_only=True)
class WaterSurfaceSettings:
    """The water surface: flat at a tide level, or a wind sea."""

    kind: str = setting("flat", choices=("flat", "waves"), doc="flat or wind waves")
    level_m: float = setting(0.0, ge=-20.0, le=20.0, doc="mean water level (tide), local z")
    wind_direction_deg: float = setting(0.0, ge=-360.0, le=360.0, doc="waves travel toward")
    spectrum: str = setting(
        "pierson-moskowitz", choices=("pierson-moskowitz", "jonswap"), doc="wave spectrum"
    )
    fetch_m: float = setting(50_000.0, gt=0.0, doc="JONSWAP fetch")
    hs_sampling_error: float = setting(
        0.025,
        ge=0.002,
        le=0.5,
        doc="tile size: expected relative sampling std of the realised Hs on the periodic tile",
    )
    tile_peak_wavelengths: float | None = setting(
        None, ge=1.0, le=64.0, doc="periodic tile size in peak wavelengths (None: from Hs error)"
    )
    resolved_footprints: float = setting(
        4.0,
        ge=1.0,
        le=100.0,
        doc="shortest wave the grid resolves, in nadir footprint diameters (shorter: statistics)",
    )
    grid_nodes: int | None = setting(
        None, ge=64, le=4096, doc="wave grid nodes per tile side (None: from the footprint)"
    )
    evolving: bool = setting(True, doc="the sea moves (False: frozen at t = 0 for all pulses)")
    time_tolerance_m: float = setting(
        0.002, gt=0.0, le=0.1, doc="height error of the sea's time interpolation (slab length)"
    )
    slope_variance_tolerance: float = setting(
        0.001,
        gt=0.0,
        lt=0.5,
        doc="relative mean-square-slope loss of the time interpolation at mid-slab (slab length;"
        " the glint at 20 deg moves ~10x as much at low wind)",
    )
    dispersion_depth_m: float | None = setting(
        None, gt=0.0, le=11000.0, doc="finite-depth dispersion w^2 = g k tanh(k h) (None: deep)"
    )


@dataclass(frozen=True, kw_only=True)
class FrameSettings:
    """The local frame: its origin in projected coordinates and the CRS."""

    crs: str = setting("EPSG:32631", doc="projected CRS (metres), e.g. a UTM zone")
    origin_easting_m: float = setting(500_000.0, ge=-1e8, le=1e8, doc="easting of local (0, 0)")
    origin_northing_m: float = setting(5_700_000.0, ge=-1e8, le=1e8, doc="northing of local (0, 0)")


@dataclass(frozen=True)
class Truth:
    """The exact world: surfaces valid at any point (evaluation reads only this).

    ``pulse_time_s``: emission time of pulses by id (``(n,) int -> (n,) s``), for the depth
    below a moving sea as each pulse saw it (:attr:`depth_at_pulses_m`); None: t = 0.
    """

    seabed: object
    water: object
    frame: object
    pulse_time_s: object = None

    @cached_property
    def depth_at_pulses_m(self):
        """Truth callable ``(x, y[, pulse_id])``: depth below the sea at each pulse's time.

        One instance per truth, which remembers the sea heights it has met
        (:class:`~pipeline.simulate.pulse_truth.PulseDepth`).
        """
        from pipeline.simulate.pulse_truth import PulseDepth

        return PulseDepth(self)

    def depth_m(self, x_m, y_m, t_s=0.0):
        """True water depth (positive down) at local points, below the surface at ``t_s``."""
        if hasattr(self.water, "evolving"):  # a moving sea: its surface at the given time
            return self.water.height_m(x_m, y_m, t_s) - self.seabed.height_m(x_m, y_m)
        return self.water.height_m(x_m, y_m) - self.seabed.height_m(x_m, y_m)


def _feature(f: FeatureSettings):
    import terrain

    h = math.radians(f.heading_deg)
    if f.kind == "cube":
        return terrain.cube(f.x_m, f.y_m, f.size_m, h)
    if f.kind == "wreck":
        return terrain.wreck(f.x_m, f.y_m, f.length_m, f.width_m, f.height_m, h)
    if f.kind == "ridge":
        return terrain.ridge(f.x_m, f.y_m, h, f.height_m, f.width_m, length_m=f.length_m)
    return terrain.channel(f.x_m, f.y_m, h, f.height_m, f.width_m, length_m=f.length_m)


def build_truth(scene, extent_m: tuple[float, float, float, float], water=None) -> Truth:
    """The scene's seabed and water surface over ``extent_m`` = (xmin, xmax, ymin, ymax).

    Random parts (roughness, waves) are seeded from the scene seed, so the truth is the same
    for every run of the scene. ``water``: the wave surface already synthesised
    (:func:`wave_surface`), for a wave scene whose waves are a stage of their own.
    """
    import terrain

    sb: SeabedSettings = scene.seabed
    ws: WaterSurfaceSettings = scene.water_surface
    fr = scene.frame
    frame = terrain.LocalFrame(fr.origin_easting_m, fr.origin_northing_m, fr.crs)
    level = ws.level_m
    if sb.kind == "plane":
        # `depth_m` is below the water level, so the seabed sits at z = level - depth at (0, 0):
        # the tide enters once, here (adding Plane(level) as well counted it twice).
        base = terrain.plane_seabed(
            sb.depth_m - level,
            slope_rad=math.radians(sb.slope_deg),
            aspect_rad=math.radians(sb.aspect_deg),
        )
    elif sb.kind == "beach":
        base = terrain.Beach(
            0.0,
            0.0,
            math.radians(sb.seaward_deg),
            sb.beach_gradient,
            shoreline_z_m=level - sb.depth_m,
            berm_height_m=sb.berm_height_m,
        )
    else:
        base, dem_frame = terrain.read_dem(sb.dem_path, frame=frame)
        frame = dem_frame
    parts = [base]
    if sb.roughness_rms_m > 0:
        rng = np.random.default_rng([scene.scene.seed, 101])
        make = (
            terrain.gaussian_roughness
            if sb.roughness_spectrum == "gaussian"
            else terrain.von_karman_roughness
        )
        kwargs = {} if sb.roughness_spectrum == "gaussian" else {"hurst": sb.roughness_hurst}
        parts.append(
            make(
                sb.roughness_rms_m,
                sb.roughness_correlation_m,
                extent=sb.roughness_period(extent_m),
                rng=rng,
                spacing_m=sb.roughness_spacing_m,
                **kwargs,
            )
        )
    parts += [_feature(f) for f in sb.features]
    seabed = parts[0] if len(parts) == 1 else terrain.compose(*parts)
    if ws.kind == "flat":
        water = terrain.FlatWater(level)
    elif water is None:
        water = wave_surface(scene)
    return Truth(seabed=seabed, water=water, frame=frame)


def wave_surface(scene):
    """The scene's wind sea (``water_surface.kind = 'waves'``): an evolving periodic sea.

    Returns
    -------
    terrain.evolving_sea.EvolvingSea
        The wave field at any time (frozen at t = 0 when ``water_surface.evolving`` is false).
    """
    from terrain.evolving_sea import EvolvingSea, slab_for_tolerances_s

    ws = scene.water_surface
    field = _wave_field(scene)
    slab = slab_for_tolerances_s(field, ws.time_tolerance_m, ws.slope_variance_tolerance)
    return EvolvingSea(field, slab, evolving=ws.evolving)


def wave_grid(scene, peak_wavelength_m: float, hs_error_4: float) -> tuple[float, int]:
    """Tile side (m) and grid nodes of the scene's wave field (documented criteria).

    * Tile: the realised Hs of a periodic tile has a sampling error ``~ 1 / side`` (each mode's
      energy is exponentially distributed; :attr:`terrain.WaveField.hs_sampling_error`), so the
      side is ``4 lambda_p x err(4 lambda_p) / hs_sampling_error`` (err measured on a 4-peak-
      wavelength probe), unless ``tile_peak_wavelengths`` is given.
    * Grid: 4 nodes per shortest resolved wave, the shortest being ``resolved_footprints``
      nadir footprint diameters: slopes on scales below it vary inside one footprint and are
      handled statistically by the surface echo (Cox-Munk with the unresolved variance), longer
      waves tilt whole footprints and are traced. Clipped to [64, 4096] nodes, unless
      ``grid_nodes`` is given.
    """
    from pipeline.simulate.scanner import footprint_diameter_m

    ws = scene.water_surface
    if ws.tile_peak_wavelengths is not None:
        tile = ws.tile_peak_wavelengths * peak_wavelength_m
    else:
        tile = 4.0 * peak_wavelength_m * max(hs_error_4 / ws.hs_sampling_error, 0.25)
    if ws.grid_nodes is not None:
        return tile, ws.grid_nodes
    shortest = ws.resolved_footprints * footprint_diameter_m(scene.scanner, scene.flight.altitude_m)
    nodes = int(min(max(math.ceil(4.0 * tile / shortest), 64), 4096))
    return tile, nodes + nodes % 2


def _wave_field(scene):
    import terrain

    ws = scene.water_surface
    u = scene.water.wind_speed_m_s
    if u <= 0:
        raise SceneError(
            f"`water.wind_speed_m_s` must be > 0 when `water_surface.kind` = 'waves'; got {u}."
        )
    common = {
        "wind_height_m": 12.5,
        "direction_rad": math.radians(ws.wind_direction_deg),
        "spectrum": ws.spectrum,
        "fetch_m": ws.fetch_m if ws.spectrum == "jonswap" else None,
        # the footprint split: the spectrum as published down to the shortest resolved wave;
        # the rest of the Cox-Munk slope variance is the surface echo's (run_survey, budget)
        "calibrate_mss": False,
    }
    lp = terrain.WaveField(
        u, extent=(0, 100, 0, 100), spacing_m=100 / 64, rng=0, **common
    ).peak_wavelength_m
    probe = terrain.WaveField(
        u, extent=(0, 4 * lp, 0, 4 * lp), spacing_m=4 * lp / 128, rng=0, **common
    )
    tile, nodes = wave_grid(scene, lp, probe.hs_sampling_error)
    return terrain.WaveField(
        u,
        extent=(0.0, tile, 0.0, tile),
        spacing_m=tile / nodes,
        rng=np.random.default_rng([scene.scene.seed, 202]),
        mean_level_m=ws.level_m,
        water_depth_m=ws.dispersion_depth_m,
        **common,
    )


def _plane_caster(z_m: float, extent_m, pad_m: float):
    from pipeline.simulate.trace import MeshCaster

    xmin, xmax, ymin, ymax = extent_m
    v = np.array(
        [
            [xmin - pad_m, ymin - pad_m, z_m],
            [xmax + pad_m, ymin - pad_m, z_m],
            [xmax + pad_m, ymax + pad_m, z_m],
            [xmin - pad_m, ymax + pad_m, z_m],
        ]
    )
    return MeshCaster(v, np.array([[0, 1, 2], [0, 2, 3]]))


def build_world(scene, truth: Truth, extent_m):
    """Meshes of ``truth`` over ``extent_m`` ready for :func:`pipeline.simulate.trace.trace`.

    Returns
    -------
    pipeline.simulate.trace.World
    """
    from pipeline.simulate.tiled_seabed import TiledSeabed
    from pipeline.simulate.trace import World

    sb = scene.seabed
    ws = scene.water_surface
    # meshed tile by tile as the rays reach it, so memory does not grow with the area;
    # boxes (IHO cubes, wrecks) as exact tops and walls: a regular grid alone turns a cube
    # narrower than two cells into a pyramid the truth does not have (terrain.box_mesh)
    seabed = TiledSeabed(truth.seabed, sb.mesh_resolution_m, extent_m)
    if ws.kind == "flat":
        water = _plane_caster(ws.level_m, extent_m, pad_m=1000.0)
    else:
        from pipeline.simulate.budget import surface_mean_square_slope
        from pipeline.simulate.wave_caster import WaveCaster

        # the moving sea: each ray meets the surface at its pulse's time, no mesh; the
        # slopes it does not resolve tilt each sub-ray's entry (trace)
        resolved = truth.water.field.mean_square_slope(0.0)
        unresolved = float(surface_mean_square_slope(scene.water.wind_speed_m_s, resolved))
        water = WaveCaster(truth.water, unresolved_mss=unresolved, seed=scene.scene.seed)
    return World(
        water=water,
        seabed=seabed,
        n_air=scene.atmosphere.refractive_index,
        n_water=scene.water.phase_index,
    )
