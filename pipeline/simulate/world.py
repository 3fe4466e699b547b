"""The simulated world of a scene: seabed and water surface (truth) and their ray casters.

Settings for ``[seabed]``, ``[[seabed.features]]``, ``[water_surface]`` and ``[frame]`` live
here; :func:`build_truth` turns them into :mod:`terrain` surfaces (the exact truth, kept for
evaluation) and :func:`build_world` into meshes for the tracer.

The wave field is periodic, so its mesh is one period tile plus a margin; rays are moved to the
slab that holds the waves, wrapped into the tile, cast, and moved back (:class:`PeriodicCaster`).
That keeps the water mesh small (one tile at wave-resolving resolution) at any survey size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.config import setting
from pipeline.errors import SceneError

__all__ = [
    "FeatureSettings",
    "SeabedSettings",
    "WaterSurfaceSettings",
    "FrameSettings",
    "Truth",
    "PeriodicCaster",
    "build_truth",
    "build_world",
    "wave_surface",
]

FEATURE_KINDS = ("cube", "wreck", "ridge", "channel")


@dataclass(frozen=True, kw_only=True)
class FeatureSettings:
    """One seabed feature, added to the base seabed."""

    kind: str = setting(choices=FEATURE_KINDS, doc="feature type")
    x_m: float = setting(doc="local easting of its centre")
    y_m: float = setting(doc="local northing of its centre")
    size_m: float = setting(1.0, gt=0.0, le=1000.0, doc="cube side (IHO: 0.5, 1, 2 m)")
    length_m: float = setting(20.0, gt=0.0, doc="wreck length, or ridge/channel length")
    width_m: float = setting(5.0, gt=0.0, doc="wreck width, or ridge/channel FWHM")
    height_m: float = setting(2.0, gt=0.0, le=100.0, doc="wreck/ridge height or channel depth")
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
    mesh_resolution_m: float = setting(1.0, gt=0.0, le=100.0, doc="seabed mesh grid spacing")
    features: tuple[FeatureSettings, ...] = setting((), doc="cubes, wrecks, ridges, channels")

    def __post_init__(self) -> None:
        if self.kind == "dem" and not self.dem_path:
            raise SceneError("`seabed.dem_path` must name a GeoTIFF when `seabed.kind` = 'dem'.")


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
    tile_peak_wavelengths: float = setting(
        2.0, ge=1.0, le=16.0, doc="periodic wave tile size, in peak wavelengths"
    )
    grid_nodes: int = setting(512, ge=64, le=4096, doc="wave grid nodes per tile side")

    def __post_init__(self) -> None:
        # the mesh must carry 40 peak wavenumbers at 4 nodes per shortest wave for the slope
        # calibration to Cox-Munk (terrain.water): nodes >= 160 x tile in peak wavelengths
        need = math.ceil(160 * self.tile_peak_wavelengths)
        if self.kind == "waves" and self.grid_nodes < need:
            raise SceneError(
                f"`water_surface.grid_nodes` must be >= 160 x `tile_peak_wavelengths` = {need} "
                f"to resolve the wave slopes; got {self.grid_nodes}."
            )


@dataclass(frozen=True, kw_only=True)
class FrameSettings:
    """The local frame: its origin in projected coordinates and the CRS."""

    crs: str = setting("EPSG:32631", doc="projected CRS (metres), e.g. a UTM zone")
    origin_easting_m: float = setting(500_000.0, ge=-1e8, le=1e8, doc="easting of local (0, 0)")
    origin_northing_m: float = setting(5_700_000.0, ge=-1e8, le=1e8, doc="northing of local (0, 0)")


@dataclass(frozen=True)
class Truth:
    """The exact world: surfaces valid at any point (evaluation reads only this)."""

    seabed: object
    water: object
    frame: object

    def depth_m(self, x_m, y_m):
        """True water depth (positive down) at local points."""
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
                extent=extent_m,
                rng=rng,
                spacing_m=min(sb.mesh_resolution_m, sb.roughness_correlation_m / 4),
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
    """The scene's wind sea (``water_surface.kind = 'waves'``) at t = 0: a periodic surface."""
    return _wave_field(scene).at_time(0.0)


def _wave_field(scene):
    import terrain

    ws = scene.water_surface
    u = scene.water.wind_speed_m_s
    if u <= 0:
        raise SceneError(
            f"`water.wind_speed_m_s` must be > 0 when `water_surface.kind` = 'waves'; got {u}."
        )
    probe = terrain.WaveField(
        u,
        extent=(0, 100, 0, 100),
        spacing_m=100 / 64,
        rng=0,
        wind_height_m=12.5,
        calibrate_mss=False,
    )
    tile = ws.tile_peak_wavelengths * probe.peak_wavelength_m
    return terrain.WaveField(
        u,
        extent=(0.0, tile, 0.0, tile),
        spacing_m=tile / ws.grid_nodes,
        rng=np.random.default_rng([scene.scene.seed, 202]),
        wind_height_m=12.5,
        direction_rad=math.radians(ws.wind_direction_deg),
        spectrum=ws.spectrum,
        fetch_m=ws.fetch_m if ws.spectrum == "jonswap" else None,
        mean_level_m=ws.level_m,
    )


class PeriodicCaster:
    """Ray casting against a surface periodic in x and y, from one tile's mesh.

    Parameters
    ----------
    surface : GridSurface
        Periodic surface with period ``(period_x_m, period_y_m)`` starting at ``(x0, y0)``.
    resolution_m : float
        Mesh grid spacing.
    margin_m : float
        Mesh beyond the tile on every side; rays must cross the slab ``zmin ≤ z ≤ zmax``
        within this horizontal distance (true for beams within ~60° of vertical).
    """

    def __init__(
        self,
        surface,
        x0: float,
        y0: float,
        period_x_m: float,
        period_y_m: float,
        resolution_m: float,
        margin_m: float,
    ) -> None:
        self.x0, self.y0, self.px, self.py = x0, y0, period_x_m, period_y_m
        bounds = (
            x0 - margin_m,
            x0 + period_x_m + margin_m,
            y0 - margin_m,
            y0 + period_y_m + margin_m,
        )
        from pipeline.simulate.trace import MeshCaster

        mesh = surface.to_mesh(resolution_m, bounds)
        self.mesh = MeshCaster.from_trimesh(mesh)
        z = np.asarray(mesh.vertices)[:, 2]
        self.zmin, self.zmax = float(z.min()), float(z.max())
        self.margin_m = margin_m

    def cast(self, origin_m: np.ndarray, direction: np.ndarray, nthreads: int = 0):
        """First hit of each ray; same contract as :meth:`MeshCaster.cast`."""
        dz = direction[:, 2]
        top, bottom = self.zmax + 1e-3, self.zmin - 1e-3
        # distance along the ray to the slab's entry plane (never negative: inside stays put)
        entry_z = np.where(dz < 0, top, bottom)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(dz != 0, (entry_z - origin_m[:, 2]) / dz, 0.0)
        inside = (origin_m[:, 2] <= top) & (origin_m[:, 2] >= bottom)
        s = np.where(inside | (s < 0), 0.0, s)
        start = origin_m + s[:, None] * direction
        shift_x = np.floor((start[:, 0] - self.x0) / self.px) * self.px
        shift_y = np.floor((start[:, 1] - self.y0) / self.py) * self.py
        local = start - np.column_stack([shift_x, shift_y, np.zeros_like(shift_x)])
        hit, t, nrm = self.mesh.cast(local, direction, nthreads)
        # rays moving away from the slab, or flat ones, never meet it
        away = ((dz >= 0) & (origin_m[:, 2] > top)) | ((dz <= 0) & (origin_m[:, 2] < bottom))
        hit &= ~away
        t = np.where(hit, t + s, 0.0)
        return hit, t, np.where(hit[:, None], nrm, 0.0)


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
    from pipeline.simulate.trace import MeshCaster, World

    sb = scene.seabed
    ws = scene.water_surface
    seabed_mesh = truth.seabed.to_mesh(sb.mesh_resolution_m, extent_m)
    seabed = MeshCaster.from_trimesh(seabed_mesh)
    if ws.kind == "flat":
        water = _plane_caster(ws.level_m, extent_m, pad_m=1000.0)
    else:
        s = truth.water  # a periodic GridSurface: one period is nx × dx by ny × dy
        px, py = s.dx_m * s.z_m.shape[1], s.dy_m * s.z_m.shape[0]
        # half the wave grid spacing: the shortest waves carried span 4 grid nodes, so a
        # mesh at the grid spacing would cut their crests (cm errors); at half it is mm
        water = PeriodicCaster(
            s,
            s.x0_m,
            s.y0_m,
            px,
            py,
            resolution_m=0.5 * min(s.dx_m, s.dy_m),
            margin_m=min(px, py) / 4,
        )
    return World(
        water=water,
        seabed=seabed,
        n_air=scene.atmosphere.refractive_index,
        n_water=scene.water.phase_index,
    )
