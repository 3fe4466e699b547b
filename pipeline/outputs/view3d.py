"""3D views of a survey run with pyvista: ``view/*.vtp`` for ParaView, PNGs, ``bathy view``.

One path from the scene to the picture: a :class:`~pipeline.outputs.view_scene.ViewScene`
becomes meshes (:func:`meshes`), which are written as ``.vtp`` files (:func:`write_vtp`) and
rendered (:func:`render`; a run's pictures in a child interpreter,
:mod:`pipeline.outputs.view_render`); ``bathy view OUT`` reads the written files back
(:func:`read_vtp`) and renders them the same way, in a window or off-screen to a PNG.

pyvista (VTK) is imported here alone and only when called, so a machine where it cannot load
or render still gets every other output of a run
(:func:`pipeline.outputs.view_render.write_views` turns any failure into one warning line).
Off-screen rendering uses VTK's EGL window (Mesa's EGL needs no X server).
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from pipeline.outputs.atomic import atomic_path
from pipeline.process.classify import BATHYMETRIC_POINT, CLASS_NAMES

__all__ = ["MESH_FILES", "COLOR_BY", "meshes", "write_vtp", "read_vtp", "render", "png_bytes"]
__all__ += ["has_display", "view_folder"]

#: The ``.vtp`` file of each mesh, in the run's ``view/`` folder.
MESH_FILES = {
    "points": "points.vtp",
    "seabed": "seabed_truth.vtp",
    "water": "water_surface.vtp",
    "beams": "beams.vtp",
}
#: What the points can be coloured by: point array, colour map, scalar bar title.
COLOR_BY = {
    "error": ("error_m", "RdBu_r", "depth error (m)"),
    "tpu": ("uncertainty_v_m", "viridis", "TPU sigma z (m)"),
    "depth": ("depth_m", "viridis_r", "depth (m)"),
    "class": ("classification", None, "class (ASPRS)"),
}
#: Colour of the common classes (others get one of ``_OTHER_COLOURS``).
CLASS_COLOURS = {
    1: "#9e9e9e",
    2: "#8c564b",
    40: "#1f4e9c",
    41: "#17becf",
    42: "#9edae5",
    43: "#e377c2",
    45: "#d62728",
    64: "#2ca02c",
}
_OTHER_COLOURS = ("#000000", "#ff7f0e", "#bcbd22", "#7f7f7f")
#: Points rendered at most (an even subsample beyond): keeps a render to about a second.
MAX_RENDER_POINTS = 200_000
#: Length of the air part of a beam in a picture, in units of the scene's depth range (the
#: aircraft, hundreds of metres up, would shrink the water to a line).
AIR_RAY_DEPTHS = 1.5
#: The pictures of a run's report: colour of the points, alt text.
REPORT_VIEWS = (("error", "3D view: points by depth error"), ("tpu", "3D view: points by TPU"))
WINDOW_SIZE = (1000, 700)
#: Zoom of the oblique view beyond the fit of every mesh (which leaves wide white margins).
OBLIQUE_ZOOM = 1.25
#: Vertical exaggeration at most (a picture of a wide, shallow survey gets up to this).
MAX_EXAGGERATION = 4.0


def _pyvista(off_screen: bool):
    """pyvista, with VTK's EGL window for off-screen rendering (set before a window exists)."""
    if off_screen:
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    pv.OFF_SCREEN = off_screen
    return pv


def has_display() -> bool:
    """Whether an interactive window can open (an X11 or Wayland display is set)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _surface_mesh(pv, surface, name: str):
    xx, yy = np.meshgrid(surface.x_m, surface.y_m)
    grid = pv.StructuredGrid(xx, yy, surface.z_m)
    poly = grid.extract_surface(algorithm=None, pass_pointid=False, pass_cellid=False)
    poly.point_data["height_m"] = poly.points[:, 2].copy()
    poly.field_data["source"] = [f"{name}: the scene's truth (evaluation side)"]
    return poly


def meshes(scene) -> dict:
    """The meshes of a :class:`~pipeline.outputs.view_scene.ViewScene` (pyvista PolyData).

    ``points``: one vertex per point with the arrays ``error_m``, ``uncertainty_v_m``,
    ``depth_m``, ``classification``; ``seabed``, ``water``: the truth surfaces (``height_m``);
    ``beams``: one 3-point polyline per beam (aircraft, surface point, bottom point) with
    ``pulse_id`` per line. Every mesh carries the frame's origin and CRS as field data.
    """
    pv = _pyvista(off_screen=True)
    pts = pv.PolyData(np.ascontiguousarray(scene.xyz_m, dtype=np.float64))
    pts.point_data["error_m"] = scene.error_m
    pts.point_data["uncertainty_v_m"] = scene.uncertainty_v_m
    pts.point_data["depth_m"] = scene.depth_m
    pts.point_data["classification"] = scene.classification.astype(np.uint8)
    pts.field_data["error_m_note"] = ["NaN where the point is not class 40 (not a seabed depth)"]
    k = scene.beams_m.shape[0]
    beams = pv.PolyData()
    if k:
        lines = np.c_[np.full(k, 3), np.arange(3 * k).reshape(k, 3)].ravel()
        beams = pv.PolyData(scene.beams_m.reshape(-1, 3).astype(np.float64), lines=lines)
        beams.cell_data["pulse_id"] = scene.beam_pulse_id.astype(np.int64)
    out = {
        "points": pts,
        "seabed": _surface_mesh(pv, scene.seabed, "seabed"),
        "water": _surface_mesh(pv, scene.water, "water surface"),
        "beams": beams,
    }
    for m in out.values():
        m.field_data["origin_m"] = scene.origin_m
        m.field_data["crs"] = [scene.crs]
    return out


def write_vtp(mesh_by_name: dict, folder: Path) -> dict[str, Path]:
    """Write each mesh as ``folder/<MESH_FILES[name]>`` (VTK XML, zlib), each atomically."""
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    files = {}
    for name, mesh in mesh_by_name.items():
        path = Path(folder) / MESH_FILES[name]
        with atomic_path(path) as tmp:
            w = vtkXMLPolyDataWriter()
            w.SetFileName(str(tmp))
            w.SetInputData(mesh)
            w.SetDataModeToAppended()
            w.SetCompressorTypeToZLib()
            if not w.Write():
                raise OSError(f"VTK could not write {path}")
        files[name] = path
    return files


def read_vtp(folder: Path) -> dict:
    """The meshes written in ``folder`` (those present), read back with pyvista."""
    pv = _pyvista(off_screen=True)
    found = {n: Path(folder) / f for n, f in MESH_FILES.items() if (Path(folder) / f).is_file()}
    if "points" not in found:
        raise FileNotFoundError(f"no {MESH_FILES['points']} in {folder}: not a run's view folder")
    return {n: pv.read(p) for n, p in found.items()}


def _shown_points(points, color_by: str, max_points: int):
    """The points a picture shows: class 40 for error/TPU/depth, all for class; subsampled."""
    cls = np.asarray(points.point_data["classification"])
    keep = np.ones(cls.size, bool) if color_by == "class" else cls == BATHYMETRIC_POINT
    keep &= np.isfinite(np.asarray(points.point_data[COLOR_BY[color_by][0]], dtype=float))
    rows = np.flatnonzero(keep)
    if rows.size > max_points:  # an even subsample keeps the spatial pattern
        rows = rows[np.linspace(0, rows.size - 1, max_points).round().astype(int)]
    return points.extract_points(rows, adjacent_cells=False, include_cells=True), rows.size


def _add_classes(pl, shown) -> None:
    """The points in one colour per ASPRS class, with a legend of the classes present."""
    cls = np.asarray(shown.point_data["classification"]).astype(int)
    rgb = np.zeros((cls.size, 3), np.uint8)
    legend = []
    for k, code in enumerate(np.unique(cls)):
        colour = CLASS_COLOURS.get(int(code), _OTHER_COLOURS[k % len(_OTHER_COLOURS)])
        rgb[cls == code] = [int(colour[i : i + 2], 16) for i in (1, 3, 5)]
        legend.append((f"{code} {CLASS_NAMES.get(int(code), '')}", colour))
    shown = shown.copy()
    shown.point_data["rgb"] = rgb
    pl.add_mesh(shown, scalars="rgb", rgb=True, point_size=6, render_points_as_spheres=True)
    pl.add_legend(legend, bcolor="white", size=(0.25, 0.05 * len(legend)), loc="upper right")


def _limits(values: np.ndarray, color_by: str) -> tuple[float, float]:
    """Colour limits: symmetric about 0 for the error, else the 2nd-98th percentiles."""
    if not values.size:
        return 0.0, 1.0
    if color_by == "error":
        top = max(float(np.percentile(np.abs(values), 98)), 1e-3)
        return -top, top
    lo, hi = np.percentile(values, [2, 98])
    return float(lo), float(max(hi, lo + 1e-3))


def _short_air(beams, depth_range_m: float):
    """The beams with the air part cut to ``AIR_RAY_DEPTHS`` depth ranges above the surface."""
    if beams.n_points == 0:
        return beams
    b = beams.copy()
    p = np.asarray(b.points).reshape(-1, 3, 3).copy()
    air = p[:, 0] - p[:, 1]
    length = np.linalg.norm(air, axis=1, keepdims=True)
    p[:, 0] = p[:, 1] + air / np.maximum(length, 1e-9) * AIR_RAY_DEPTHS * depth_range_m
    b.points = p.reshape(-1, 3)
    return b


def render(
    mesh_by_name: dict,
    color_by: str = "error",
    *,
    window_size: tuple[int, int] = WINDOW_SIZE,
    camera: str = "oblique",
    off_screen: bool = True,
    max_points: int = MAX_RENDER_POINTS,
    title: str = "",
) -> np.ndarray | None:
    """Draw the seabed, the water surface, the beams and the points coloured by ``color_by``.

    Parameters
    ----------
    mesh_by_name : dict
        From :func:`meshes` or :func:`read_vtp`; ``points`` required, the others optional.
    color_by : {"error", "tpu", "depth", "class"}
    window_size : (width, height) in pixels
    camera : {"oblique", "top"}
        An isometric view from above, or straight down (north up).
    off_screen : bool
        Render off-screen and return the picture; else open a window (returns None on close).
    max_points : int
        Points drawn at most (an even subsample beyond).
    title : str

    Returns
    -------
    (height, width, 3) uint8 array or None
    """
    if color_by not in COLOR_BY:
        raise ValueError(f"color_by must be one of {sorted(COLOR_BY)}; got {color_by!r}")
    pv = _pyvista(off_screen)
    array, cmap, bar = COLOR_BY[color_by]
    shown, n = _shown_points(mesh_by_name["points"], color_by, max_points)
    seabed, water = mesh_by_name.get("seabed"), mesh_by_name.get("water")
    z = [np.asarray(m.points[:, 2]) for m in (seabed, water, shown) if m is not None and m.n_points]
    zlo, zhi = (min(a.min() for a in z), max(a.max() for a in z)) if z else (0.0, 1.0)
    depth_range = max(zhi - zlo, 0.1)
    pl = pv.Plotter(off_screen=off_screen, window_size=list(window_size))
    try:
        pl.set_background("white")
        if seabed is not None and seabed.n_points:
            pl.add_mesh(seabed, color="#c8b68e", opacity=0.65, smooth_shading=True, name="seabed")
        if water is not None and water.n_points:
            pl.add_mesh(water, color="#2f6fc4", opacity=0.3, name="water")
        beams = mesh_by_name.get("beams")
        if beams is not None and beams.n_points:
            pl.add_mesh(_short_air(beams, depth_range), color="#ff7f00", line_width=3)
        if n:
            values = np.asarray(shown.point_data[array], dtype=float)
            if color_by == "class":
                _add_classes(pl, shown)
            else:
                pl.add_mesh(
                    shown,
                    scalars=array,
                    cmap=cmap,
                    clim=_limits(values, color_by),
                    point_size=6,
                    render_points_as_spheres=True,
                    scalar_bar_args={
                        "title": bar,
                        "color": "black",
                        "vertical": True,
                        "position_x": 0.87,
                        "width": 0.05,
                        "position_y": 0.15,
                        "height": 0.7,
                    },
                    name="points",
                )
        span = max(
            np.ptp(shown.points[:, 0]) if n else 1.0, np.ptp(shown.points[:, 1]) if n else 1.0
        )
        # a vertical exaggeration so that relief a few metres deep shows over a wide area
        zscale = float(np.clip(0.2 * span / depth_range, 1.0, MAX_EXAGGERATION))
        pl.set_scale(zscale=zscale)
        pl.add_text(
            f"{title}{' ' if title else ''}{n} points; vertical x{zscale:.3g}",
            font_size=9,
            color="black",
        )
        if camera == "top":
            pl.view_xy()
        else:
            pl.view_isometric()
            pl.camera.zoom(OBLIQUE_ZOOM)
        if not off_screen:
            pl.show()
            return None
        return pl.screenshot(None, return_img=True)
    finally:
        pl.close()


def png_bytes(image: np.ndarray) -> bytes:
    """The PNG file of an ``(h, w, 3)`` uint8 picture."""
    import matplotlib.image as mpimg

    buf = io.BytesIO()
    mpimg.imsave(buf, image, format="png")
    return buf.getvalue()


def view_folder(
    out_dir: Path, color_by: str = "error", screenshot: Path | None = None, log=print
) -> Path | None:
    """``bathy view``: the run in ``out_dir`` (its ``view/*.vtp``) in a window, or as a PNG.

    Without a display (no ``DISPLAY``/``WAYLAND_DISPLAY``) and no ``screenshot``, the picture
    goes to ``out_dir/view/screenshot.png``. Returns the PNG written, or None after a window.
    """
    folder = Path(out_dir) / "view"
    mesh_by_name = read_vtp(folder)
    if screenshot is None and not has_display():
        screenshot = folder / "screenshot.png"
        log(f"bathy view: no display; rendering off-screen to {screenshot}")
    title = f"{Path(out_dir).name}:"
    if screenshot is None:
        render(mesh_by_name, color_by, off_screen=False, title=title)
        return None
    picture = render(mesh_by_name, color_by, title=title)
    with atomic_path(screenshot) as tmp:
        tmp.write_bytes(png_bytes(picture))
    return Path(screenshot)
