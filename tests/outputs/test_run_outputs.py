"""What ``bathy run`` leaves on disk, opened as a user's tools open it (xarray, rasterio, laspy).

A small two-line Palmer survey; the checks are the formats' own rules (LAS return numbers
1..n per pulse, CF attributes, COG layout), not figures of the simulation.
"""

import tomllib
from pathlib import Path

import laspy
import numpy as np
import pytest
import rasterio

from pipeline.run import run_scene
from pipeline.scene import parse_scene

ROOT = Path(__file__).resolve().parents[2]
xr = pytest.importorskip("xarray")
pytest.importorskip("netCDF4")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["flight"].update(area_m=[0.0, 60.0, 0.0, 60.0], run_in_m=0.0, n_lines=2)
    data["scanner"]["prf_hz"] = 4000.0
    data["process"].update(posterior_pulses_per_km2=0.0, posterior_min_pulses=0)
    out = tmp_path_factory.mktemp("run")
    run_scene(parse_scene(data), out, log=lambda _: None)
    return out


def test_every_pulse_is_numbered_one_to_n(run_dir):
    las = laspy.read(run_dir / "points.laz")
    pid = np.asarray(las.pulse_id)
    num = np.asarray(las.return_number, int)
    tot = np.asarray(las.number_of_returns, int)
    cls = np.asarray(las.classification)
    assert {40, 41, 45} <= set(np.unique(cls).tolist())
    # per pulse: the sorted return numbers are exactly 1..n and every point says n
    order = np.lexsort((num, pid))
    p, r, t = pid[order], num[order], tot[order]
    start = np.flatnonzero(np.r_[True, p[1:] != p[:-1]])
    size = np.diff(np.r_[start, p.size])
    k = np.repeat(np.arange(start.size), size)
    np.testing.assert_array_equal(r, np.arange(p.size) - start[k] + 1)
    np.testing.assert_array_equal(t, size[k])
    # a class-45 point comes after its pulse's surface: never return 1 when the pulse has 2+
    c45 = cls[order] == 45
    assert np.all(r[c45 & (t > 1)] > 1)
    assert np.all(np.asarray(las.synthetic, bool)[cls == 45])


def test_points_carry_time_line_angle_and_intensity(run_dir):
    las = laspy.read(run_dir / "points.laz")
    psid = np.asarray(las.point_source_id)
    assert set(np.unique(psid).tolist()) == {1, 2}  # two flight lines, told apart
    pid, t = np.asarray(las.pulse_id), np.asarray(las.gps_time)
    assert np.all(t >= 0) and np.ptp(t) > 0
    assert t[psid == 2].min() > t[psid == 1].max()  # the second line is flown after the first
    for line in (1, 2):
        sel = psid == line
        o = np.argsort(pid[sel], kind="stable")
        assert np.all(np.diff(t[sel][o]) >= 0)  # later pulses, later times
    # a 20-degree Palmer scanner: across-track angles both sides, none beyond 20 deg + attitude
    angle = np.asarray(las.scan_angle) * 0.006
    assert angle.min() < -10 and angle.max() > 10 and np.abs(angle).max() < 25
    measured = ~np.asarray(las.synthetic, bool)
    assert np.mean(np.asarray(las.intensity)[measured] > 0) > 0.9
    assert np.all(np.asarray(las.intensity)[~measured] == 0)


def test_grids_are_written_and_self_described(run_dir):
    with xr.open_dataset(run_dir / "grid.nc") as ds:
        assert ds.attrs["Conventions"] == "CF-1.8"
        assert ds["crs"].attrs["grid_mapping_name"] == "transverse_mercator"
        assert ds["depth"].attrs["positive"] == "down"
        filled = ds["count"].values > 0
        assert filled.sum() > 10
        assert np.all(np.isfinite(ds["tvu95"].values[filled]))
        order = ds["iho_order"].values[filled]
        assert np.all((order >= 0) & (order <= 4))
        nc_depth = ds["depth"].values
    with rasterio.open(run_dir / "grid.tif") as src:
        assert src.tags(ns="IMAGE_STRUCTURE")["LAYOUT"] == "COG" and src.overviews(1)
        tif = {d: src.read(i + 1, masked=True) for i, d in enumerate(src.descriptions)}
    np.testing.assert_array_equal(tif["depth_m"].filled(np.nan), nc_depth)
    np.testing.assert_array_equal(tif["count"].filled(0) > 0, filled)
