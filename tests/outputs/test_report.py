"""report.html: written by every survey run, self-contained, every figure a PNG, opens in a browser.

The run is a tiny Palmer survey (40 m x 40 m asked, 3 kHz, no posteriors, one 2 m cube: ~5 s).
The helpers' figures are checked against hand-built data with an analytic answer.
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import pytest

from pipeline.outputs.report import depth_bands
from pipeline.run import run_scene
from pipeline.scene import parse_scene

ROOT = Path(__file__).resolve().parents[2]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SECTIONS = (
    "scene",
    "coverage",
    "waveforms",
    "depth",
    "tvu",
    "iho",
    "error",
    "calibration",
    "limits",
    "features",
    "view3d",
)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["flight"]["area_m"] = [0.0, 40.0, 0.0, 40.0]
    data["scanner"]["prf_hz"] = 3000.0
    data["process"].update(posterior_pulses_per_km2=0.0, posterior_min_pulses=0)
    data["seabed"]["features"] = [{"kind": "cube", "x_m": 20.0, "y_m": 20.0, "size_m": 2.0}]
    out = tmp_path_factory.mktemp("report")
    manifest = run_scene(parse_scene(data), out, log=lambda _: None)
    return out / "report.html", manifest


def test_every_survey_run_writes_report_html_listed_in_the_manifest(report):
    path, manifest = report
    assert manifest["files"]["report"] == "report.html"
    on_disk = json.loads((path.parent / "manifest.json").read_text())
    assert on_disk["files"]["report"] == "report.html"
    text = path.read_text(encoding="utf-8")
    for sec in SECTIONS:
        assert f"id='{sec}'" in text, sec
    # in the order a hydrographer reads
    where = [text.index(f"id='{sec}'") for sec in SECTIONS]
    assert where == sorted(where)
    # posteriors did not run: the waveform section says why there is no figure
    assert "No waveform was kept" in text
    assert "Rule: a cube is detected" in text
    # how the surface was timed, as evaluation.json records it (a full-waveform survey)
    echoes = json.loads((path.parent / "evaluation.json").read_text())["surface_echoes"]
    assert f"{echoes['clear']}, {echoes['ambiguous']}: an ambiguous one weighs" in text


def test_report_is_self_contained_and_every_image_is_a_png(report):
    import matplotlib.image as mpimg

    text = report[0].read_text(encoding="utf-8")
    # nothing fetched from elsewhere: no link, no external src, no url()
    assert not re.search(r"<link|href=|url\(|@import", text)
    srcs = re.findall(r'<img[^>]*src="([^"]*)"', text)
    # coverage, depth, TVU, orders, error, calibration, limits (no waveform kept), and the
    # two 3D views (points by depth error, by TPU)
    assert len(srcs) == text.count("<img") == 9
    for src in srcs:
        prefix = "data:image/png;base64,"
        assert src.startswith(prefix)
        raw = base64.b64decode(src[len(prefix) :], validate=True)
        assert raw[:8] == PNG_SIGNATURE
        pixels = mpimg.imread(io.BytesIO(raw), format="png")
        assert pixels.shape[0] > 200 and pixels.shape[1] > 300, pixels.shape
        assert np.ptp(pixels[..., :3]) > 0  # not a blank canvas


def _chromium() -> str | None:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        msg = "chromium is not on PATH: `bash dev.sh test` installs it (Debian package chromium)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return found


def test_report_renders_in_headless_chromium(report, tmp_path):
    """Every image decodes in a real browser (the page's own script sets body[data-images]),
    no console message (an uncaught error would log one), and a screenshot is drawn."""
    exe = _chromium()
    url = report[0].resolve().as_uri()
    common = [
        exe,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        f"--user-data-dir={tmp_path / 'profile'}",
    ]
    dom = subprocess.run(
        [*common, "--enable-logging=stderr", "--v=0", "--dump-dom", url],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert 'data-images="ok"' in dom.stdout
    console = [ln for ln in dom.stderr.splitlines() if ":CONSOLE" in ln]
    assert console == []
    shot = tmp_path / "shot.png"
    subprocess.run(
        [*common, f"--screenshot={shot}", "--window-size=1280,2000", url],
        capture_output=True,
        timeout=120,
        check=True,
    )
    assert shot.read_bytes()[:8] == PNG_SIGNATURE


def test_depth_bands_hold_each_point_once_with_its_band_statistics():
    # depths 0..12 m (the deepest point exactly on a band edge); errors +0.1 m above 6 m,
    # -0.2 m below: bands of 2 m (12 / 6), biases exact
    depth = np.linspace(0.0, 12.0, 121)
    err = np.where(depth < 6.0, 0.1, -0.2)
    bands = depth_bands(depth, err)
    assert [b["from_m"] for b in bands] == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0]
    assert sum(b["n"] for b in bands) == depth.size
    assert [round(b["bias_m"], 12) for b in bands] == [0.1, 0.1, 0.1, -0.2, -0.2, -0.2, -0.2]
    # IHO S-44 Special order at 1 m: sqrt(0.25^2 + (0.0075 * 1)^2)
    assert bands[0]["special_m"] == pytest.approx(math.hypot(0.25, 0.0075))


@pytest.mark.parametrize("north_first", [True, False])
def test_maps_are_drawn_north_up_whichever_way_the_rows_run(north_first):
    # two rows of cells: the northern one 0 (black), the southern one 1 (white); a GeoTIFF-like
    # grid lists the north row first, another order the south row first
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from pipeline.outputs.report_figures import _show

    y = np.array([15.0, 5.0]) if north_first else np.array([5.0, 15.0])
    values = np.where(y[:, None] > 10.0, 0.0, 1.0) * np.ones((2, 3))
    fig = Figure(figsize=(3, 2), dpi=50)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    _show(ax, values, np.array([5.0, 15.0, 25.0]), y, 10.0, cmap="gray", vmin=0.0, vmax=1.0)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    top, bottom = rgba[5, rgba.shape[1] // 2, 0], rgba[-5, rgba.shape[1] // 2, 0]
    assert top < 50 and bottom > 200, (top, bottom)


def test_a_map_of_more_cells_than_it_shows_draws_the_same_picture_from_a_bounded_image():
    # a 4000 x 1500 grid (a blocked survey's sample spread over a long survey's bounds):
    # nearest-neighbour drawing of every cell against the bounded image _show hands matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from pipeline.outputs import report_figures as F

    ny, nx, res = 4000, 1500, 1.0
    y, x = np.arange(ny) + 0.5, np.arange(nx) + 0.5
    rng = np.random.default_rng(3)
    values = np.full((ny, nx), np.nan)
    for _ in range(12):  # blocks of soundings in empty space, like a sample's blocks
        r, c = rng.integers(0, ny - 200), rng.integers(0, nx - 200)
        values[r : r + 200, c : c + 200] = rng.uniform(0.0, 1.0)

    def draw(show):
        fig = Figure(figsize=(3, 4), dpi=100)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_axis_off()
        im = show(ax)
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].astype(int), im

    full, _ = draw(
        lambda ax: ax.imshow(
            values, origin="lower", extent=(0, nx, 0, ny), interpolation="nearest",
            cmap="viridis", vmin=0.0, vmax=1.0,
        )
    )  # fmt: skip
    bounded, im = draw(lambda ax: F._show(ax, values, x, y, res, cmap="viridis", vmin=0, vmax=1))
    assert max(im.get_array().shape) <= F.MAP_CELLS
    same = np.all(np.abs(full - bounded) <= 2, axis=-1)
    # the pixels that differ lie on the blocks' edges (a pixel's cell is picked a cell off)
    assert same.mean() > 0.99, same.mean()
