"""3D views: off-screen pictures, ``view/*.vtp`` against ``points.laz``, ``bathy view``.

The pictures are checked on hand-built scenes with a known colour gradient; the run is a tiny
Palmer survey (40 m x 40 m, 3 kHz, no posteriors) over a smooth plane seabed, whose true depth
is written here: ``2 m + tan(5.33 deg) x`` (aspect east, flat water at level 0).
"""

from __future__ import annotations

import io
import math
import os
import tomllib
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from pipeline.cli import main
from pipeline.outputs import view3d as V
from pipeline.outputs import view_render
from pipeline.outputs.las import read_points_laz
from pipeline.outputs.view_scene import Surface, ViewScene, surface_grid
from pipeline.run import existing_outputs, run_scene
from pipeline.scene import parse_scene

ROOT = Path(__file__).resolve().parents[2]
DEPTH_AT_0_M, SLOPE_DEG = 2.0, 5.33


def _true_depth_m(x):
    return DEPTH_AT_0_M + math.tan(math.radians(SLOPE_DEG)) * x


def _synthetic(error_m, tpu_m, x, y):
    """Class-40 points on the plane z = -5 m, no beams, a flat seabed below and water at 0."""
    xyz = np.c_[x, y, np.full(x.size, -5.0)]
    bounds = (x.min(), x.max(), y.min(), y.max())
    return ViewScene(
        xyz_m=xyz,
        classification=np.full(x.size, 40, np.uint8),
        depth_m=np.full(x.size, 5.0),
        error_m=error_m,
        uncertainty_v_m=tpu_m,
        seabed=surface_grid(lambda a, b: np.full(np.shape(a), -5.2), bounds, 20),
        water=surface_grid(lambda a, b: np.zeros(np.shape(a)), bounds, 20),
        beams_m=np.zeros((0, 3, 3)),
        beam_pulse_id=np.zeros(0, np.int64),
        origin_m=np.array([500000.0, 4000000.0, 0.0]),
        crs="EPSG:32619",
    )


def _drawn(img):
    """Pixels that are not the white background, in the middle of the picture (the points
    cover it; the title and the scalar bar stay out)."""
    h, w, _ = img.shape
    mask = np.any(img < 245, axis=2)
    mask[:, int(0.75 * w) :] = False
    mask[: int(0.25 * h)] = False
    mask[int(0.75 * h) :] = False
    return mask


def _colormap_value(rgb, cmap):
    """Where along ``cmap`` (0 to 1) each ``(n, 3)`` colour lies: the nearest entry in hue.

    The spheres are lit (shaded darker toward their rims), which scales a colour more than it
    turns it: colours are compared as unit RGB vectors.
    """
    import matplotlib

    lut = matplotlib.colormaps[cmap](np.linspace(0.0, 1.0, 256))[:, :3]
    lut /= np.linalg.norm(lut, axis=1, keepdims=True)
    unit = rgb / np.linalg.norm(rgb, axis=1, keepdims=True)
    return np.argmin(((unit[:, None, :] - lut[None]) ** 2).sum(axis=2), axis=1) / 255.0


def _inner(index):
    """The middle 90 % of the rows or columns the points cover (not the surfaces' rims)."""
    lo, hi = np.percentile(index, [5, 95])
    return index[(index >= lo) & (index <= hi)]


@pytest.fixture(scope="module")
def gradient_pictures():
    x, y = (a.ravel() for a in np.meshgrid(np.linspace(0, 30, 80), np.linspace(0, 30, 80)))
    # error rises west to east from -0.2 m to +0.2 m, TPU south to north from 0.05 to 0.25 m
    scene = _synthetic(-0.2 + 0.4 * x / 30.0, 0.05 + 0.2 * y / 30.0, x, y)
    m = V.meshes(scene)
    return {c: V.render(m, c, camera="top", window_size=(600, 500)) for c in ("error", "tpu")}


def test_error_colours_run_blue_to_red_west_to_east(gradient_pictures):
    img = gradient_pictures["error"].astype(float)
    assert img.shape == (500, 600, 3)
    assert np.any(img < 245, axis=2).mean() > 0.3  # the points cover a good part of it
    drawn = _drawn(img)
    cols = _inner(np.flatnonzero(drawn.sum(axis=0) > 20))
    # each column's median colour read back on the colour map: the error's place in the
    # symmetric limits [-0.2, 0.2] m, i.e. rising linearly west to east (north up)
    median = np.array([np.median(img[drawn[:, c], c], axis=0) for c in cols])
    value = _colormap_value(median, "RdBu_r")
    assert cols.size > 200
    assert np.corrcoef(cols, value)[0, 1] > 0.95
    # (blue -0.2 m and red +0.2 m: the colour map's ends are dark, their hue less sure)
    assert value[:10].mean() < 0.25 and value[-10:].mean() > 0.65, (value[:10], value[-10:])


def test_tpu_colours_brighten_south_to_north(gradient_pictures):
    img = gradient_pictures["tpu"].astype(float)
    drawn = _drawn(img)
    rows = _inner(np.flatnonzero(drawn.sum(axis=1) > 20))
    median = np.array([np.median(img[r, drawn[r]], axis=0) for r in rows])
    value = _colormap_value(median, "viridis")
    # the colour limits are the 2nd-98th percentiles: TPU 0.054 to 0.246 m, south to north;
    # rows count down the picture, so the value falls with the row
    assert np.corrcoef(rows, value)[0, 1] < -0.95
    assert value[:10].mean() > 0.7 and value[-10:].mean() < 0.3, (value[:10], value[-10:])


def test_points_outside_class_40_are_not_coloured_by_error():
    x, y = (a.ravel() for a in np.meshgrid(np.linspace(0, 30, 40), np.linspace(0, 30, 40)))
    scene = _synthetic(np.full(x.size, np.nan), np.full(x.size, 0.1), x, y)
    scene = ViewScene(**{**scene.__dict__, "classification": np.full(x.size, 41, np.uint8)})
    img = V.render(V.meshes(scene), "error", camera="top", window_size=(600, 500))
    # no point drawn: only the translucent seabed and water, no red or blue anywhere
    diff = img[..., 0].astype(int) - img[..., 2].astype(int)
    assert np.abs(diff[_drawn(img)]).max() < 40


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["flight"].update(area_m=[0.0, 40.0, 0.0, 40.0], run_in_m=0.0)
    data["scanner"]["prf_hz"] = 3000.0
    data["seabed"].update(depth_m=DEPTH_AT_0_M, slope_deg=SLOPE_DEG, roughness_rms_m=0.0)
    data["process"].update(posterior_pulses_per_km2=0.0, posterior_min_pulses=0)
    out = tmp_path_factory.mktemp("view3d") / "out"
    lines = []
    manifest = run_scene(parse_scene(data), out, log=lines.append)
    return out, manifest, lines


def test_vtp_files_hold_the_las_points_with_their_errors_and_tpu(tiny_run):
    import pyvista as pv

    out, manifest, lines = tiny_run
    assert not [ln for ln in lines if "WARNING: 3D" in ln]
    for key, name in V.MESH_FILES.items():
        assert manifest["files"][f"view_{key}"] == f"view/{name}"
    las = read_points_laz(out / "points.laz")
    pts = pv.read(out / "view" / "points.vtp")
    n = las.points.pulse_id.size
    assert n > 1000 and pts.n_points == n
    # the same points in the same order, in the same local frame (to the LAS's 1 mm scale)
    np.testing.assert_allclose(pts.field_data["origin_m"], las.origin_m)
    np.testing.assert_allclose(pts.points, las.points.xyz_m, atol=2e-3)
    np.testing.assert_array_equal(pts["classification"], las.points.classification)
    np.testing.assert_allclose(pts["depth_m"], las.points.depth_m, atol=1e-9)
    np.testing.assert_allclose(pts["uncertainty_v_m"], las.points.uncertainty_v_m, rtol=1e-6)
    is40 = las.points.classification == 40
    assert is40.sum() > 300
    err = np.asarray(pts["error_m"])
    assert np.all(np.isfinite(err[is40])) and np.all(np.isnan(err[~is40]))
    # the error against the plane written above
    expected = pts["depth_m"][is40] - _true_depth_m(pts.points[is40, 0])
    np.testing.assert_allclose(err[is40], expected, atol=1e-9)
    assert np.sqrt(np.mean(expected**2)) < 0.3
    seabed = pv.read(out / "view" / "seabed_truth.vtp")
    np.testing.assert_allclose(seabed.points[:, 2], -_true_depth_m(seabed.points[:, 0]), atol=1e-6)
    water = pv.read(out / "view" / "water_surface.vtp")
    assert np.all(water.points[:, 2] == 0.0)
    # files written with the mode a plain open() gives (the umask honoured, as points.laz)
    assert (out / "view" / "points.vtp").stat().st_mode == (out / "points.laz").stat().st_mode


def test_beams_run_from_the_aircraft_through_the_surface_to_a_bottom_point(tiny_run):
    import pyvista as pv

    out = tiny_run[0]
    beams = pv.read(out / "view" / "beams.vtp")
    pts = pv.read(out / "view" / "points.vtp")
    p = np.asarray(beams.points).reshape(-1, 3, 3)
    assert 1 <= p.shape[0] <= 8 and beams.n_lines == p.shape[0]
    assert np.all(np.abs(p[:, 0, 2] - 400.0) < 5.0)  # the aircraft at 400 m
    assert np.all(np.abs(p[:, 1, 2]) < 0.5)  # the surface point at the water level
    bottom40 = pts.points[pts["classification"] == 40]
    for b in p[:, 2]:  # each bottom end is a class-40 point
        assert np.min(np.linalg.norm(bottom40 - b, axis=1)) < 1e-6
    # the in-water leg is steeper than the air leg (refraction toward the normal)
    air, water = p[:, 0] - p[:, 1], p[:, 1] - p[:, 2]
    tilt = lambda v: np.hypot(v[:, 0], v[:, 1]) / np.abs(v[:, 2])  # noqa: E731
    assert np.all(tilt(water) < tilt(air))


def _coverage(png):
    img = mpimg.imread(png)[..., :3]
    return np.mean(np.any(img < 0.96, axis=2)), img.shape


def test_bathy_view_screenshot_renders_the_written_run(tiny_run, tmp_path, capsys):
    out = tiny_run[0]
    shot = tmp_path / "shot.png"
    assert main(["view", str(out), "--screenshot", str(shot), "--color", "tpu"]) == 0
    assert f"wrote {shot}" in capsys.readouterr().out
    frac, shape = _coverage(shot)
    assert shape == (V.WINDOW_SIZE[1], V.WINDOW_SIZE[0], 3)
    assert frac > 0.05


def test_bathy_view_without_a_display_writes_into_the_view_folder(tiny_run, monkeypatch, capsys):
    out = tiny_run[0]
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(out), "--color", "class"]) == 0
    assert "no display" in capsys.readouterr().out
    assert _coverage(out / "view" / "screenshot.png")[0] > 0.05
    # a later run in the folder counts the views as outputs (and --overwrite clears them)
    assert {"view/points.vtp", "view/screenshot.png"} <= set(existing_outputs(out))


def test_bathy_view_of_a_folder_without_views_fails_cleanly(tmp_path, capsys):
    assert main(["view", str(tmp_path)]) == 1
    assert "points.vtp" in capsys.readouterr().err


def test_a_render_failure_costs_only_the_views(tmp_path, monkeypatch):
    def broken(*a, **k):
        raise RuntimeError("no OpenGL here")

    # the pictures are rendered in a child interpreter (view_render), where a monkeypatch of
    # V.render does not reach: the child's failure is what the run sees
    monkeypatch.setattr(view_render, "render_pictures", broken)
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["flight"].update(area_m=[0.0, 20.0, 0.0, 20.0], run_in_m=0.0)
    data["scanner"]["prf_hz"] = 2000.0
    data["process"].update(posterior_pulses_per_km2=0.0, posterior_min_pulses=0)
    lines = []
    manifest = run_scene(parse_scene(data), tmp_path, log=lines.append)
    warnings = [ln for ln in lines if "WARNING: 3D views" in ln]
    assert len(warnings) == 1 and "RuntimeError: no OpenGL here" in warnings[0]
    for name in ("points.laz", "grid.tif", "grid.nc", "evaluation.json", "report.html"):
        assert (tmp_path / name).is_file(), name
    # the .vtp files came before the failed picture, and the report says there is none
    assert (tmp_path / "view" / "points.vtp").is_file()
    assert manifest["files"]["view_points"] == "view/points.vtp"
    text = (tmp_path / "report.html").read_text()
    assert "id='view3d'" in text and "were not rendered" in text
    assert os.path.getsize(tmp_path / "manifest.json") > 0


def test_a_failure_in_the_render_child_reaches_the_run(tmp_path):
    # the child reads the folder: without points.vtp it fails, and the parent raises with the
    # child's own last line (not a hang, not a silent empty list)
    with pytest.raises(RuntimeError, match="FileNotFoundError: no points.vtp"):
        view_render.render_pictures(tmp_path)


def _random_scene(n: int, seed: int) -> ViewScene:
    """``n`` class-40 points over a 50 m x 30 m box, 2-8 m deep, with flat truth surfaces."""
    rng = np.random.default_rng(seed)
    xyz = np.c_[rng.uniform(0, 50, n), rng.uniform(0, 30, n), -rng.uniform(2, 8, n)]
    x, y = np.linspace(-5, 55, 12), np.linspace(-5, 35, 9)
    return ViewScene(
        xyz_m=xyz,
        classification=np.full(n, 40, np.uint8),
        depth_m=-xyz[:, 2],
        error_m=rng.normal(0, 0.1, n),
        uncertainty_v_m=np.full(n, 0.1),
        seabed=Surface(x, y, np.full((9, 12), -8.0)),
        water=Surface(x, y, np.zeros((9, 12))),
        beams_m=np.zeros((0, 3, 3)),
        beam_pulse_id=np.zeros(0, np.int64),
        origin_m=np.zeros(3),
        crs="EPSG:32619",
    )


def test_the_child_imports_this_pipeline_not_the_current_directorys(tmp_path, monkeypatch):
    # a run started in a folder holding another `pipeline` (another checkout): the child must
    # not import it (it would fail here, the pictures lost)
    (tmp_path / "pipeline").mkdir()
    (tmp_path / "pipeline" / "__init__.py").write_text("raise ImportError('the wrong pipeline')")
    folder = tmp_path / "view"
    V.write_vtp(V.meshes(_random_scene(4, 1)), folder)
    monkeypatch.chdir(tmp_path)
    pictures = view_render.render_pictures(folder)
    assert len(pictures) == len(V.REPORT_VIEWS) and all(
        p[:8] == b"\x89PNG\r\n\x1a\n" for p, _ in pictures
    )


def test_the_child_renders_what_the_parent_would(tmp_path):
    # the pictures from the files written equal those rendered from the meshes in memory
    # (VTK's XML keeps every float64): a child interpreter changes nothing but the process
    scene = _random_scene(400, 5)
    mesh_by_name = V.meshes(scene)
    V.write_vtp(mesh_by_name, tmp_path)
    pictures = view_render.render_pictures(tmp_path)
    assert [alt for _, alt in pictures] == [alt for _, alt in V.REPORT_VIEWS]
    for (png, _), (color_by, _) in zip(pictures, V.REPORT_VIEWS, strict=True):
        child = mpimg.imread(io.BytesIO(png))
        here = mpimg.imread(io.BytesIO(V.png_bytes(V.render(mesh_by_name, color_by))))
        np.testing.assert_array_equal(child, here)
