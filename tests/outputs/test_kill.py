"""`bathy run` killed with SIGKILL at any moment leaves complete files or nothing.

A small survey (60 m x 60 m, 5 kHz, no posteriors: ~2 s) runs in a subprocess and is killed
before it starts, in the middle of the simulation, and in the middle of each of its output
writes (seen from outside: the child holds a file open under the output's parent folder).
Afterwards the folder holds no temporary file, and every file in it parses to the end.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest
import rasterio

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/PID/fd"),
]
OUTPUTS = {
    "points.laz",
    "grid.tif",
    "grid.nc",
    "evaluation.json",
    "evaluation_points.npz",
    "report.html",
    "manifest.json",
    "view",
}
#: The 3D scene's files in ``view/`` (pipeline.outputs.view3d.MESH_FILES).
VIEW_FILES = {"points.vtp", "seabed_truth.vtp", "water_surface.vtp", "beams.vtp"}
TIMEOUT_S = 300.0


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    text = (ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text()
    for old, new in (
        ("area_m = [0.0, 300.0, 0.0, 600.0]", "area_m = [0.0, 60.0, 0.0, 60.0]"),
        ("run_in_m = 150.0", "run_in_m = 0.0"),
        ("prf_hz = 35000.0", "prf_hz = 5000.0"),
        ("[process]\n", "[process]\nposterior_min_pulses = 0\nposterior_pulses_per_km2 = 0.0\n"),
    ):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path_factory.mktemp("scene") / "small.toml"
    path.write_text(text + "\n[run]\nchunk_pulses = 3000\n")
    return path


@pytest.fixture(autouse=True)
def _no_stray_runs():
    """A run the test left alive (a failure mid-way) is killed at teardown."""
    yield
    for proc in _STARTED:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    _STARTED.clear()


_STARTED = []


def _start(scene, work):
    """`bathy run` into ``work/out``; its output lines go to ``work.log``."""
    # a SIGKILL leaves the NetCDF writer's private staging folder behind (nothing can remove
    # it): it goes to the test's own folder, not the machine's /tmp
    scratch = work.with_name(work.name + "-tmp")
    scratch.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", "TMPDIR": str(scratch)}
    log = open(work.with_suffix(".log"), "wb")  # closed by _finish
    cmd = [sys.executable, "-u", "-m", "pipeline.cli", "run", str(scene), "--out"]
    proc = subprocess.Popen(cmd + [str(work / "out")], stdout=log, stderr=log, env=env)
    _STARTED.append(proc)
    return proc, log


def _open_under(pid, folder):
    """Whether process ``pid`` holds a file open under ``folder`` (an output being written)."""
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return False
    for fd in fds:
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}").startswith(str(folder) + os.sep):
                return True
        except OSError:  # closed meanwhile
            continue
    return False


def _finish(proc, log, kill):
    if kill:
        proc.send_signal(signal.SIGKILL)
    rc = proc.wait(timeout=TIMEOUT_S)
    log.close()
    return rc


def _assert_complete_or_nothing(work):
    """``work`` holds at most ``out``; ``out`` only whole output files."""
    assert [p.name for p in work.iterdir()] in ([], ["out"]), list(work.iterdir())
    out = work / "out"
    names = {p.name for p in out.iterdir()} if out.exists() else set()
    assert names <= OUTPUTS, names  # no temporary (".points.laz.XXXX.tmp"), nothing else
    if "points.laz" in names:
        las = laspy.read(out / "points.laz")
        assert len(las.points) == las.header.point_count > 0
        assert np.all(np.isfinite(las.x))
    if "grid.tif" in names:
        with rasterio.open(out / "grid.tif") as src:
            assert src.read().shape == (src.count, src.height, src.width)
    if "grid.nc" in names:
        import xarray as xr

        with xr.open_dataset(out / "grid.nc") as ds:
            assert ds["depth"].shape == (ds.sizes["y"], ds.sizes["x"])
    if "view" in names:  # the folder comes with its first file, each file whole
        views = {p.name for p in (out / "view").iterdir()}
        assert views and views <= VIEW_FILES, views
        from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

        for name in views:
            reader = vtkXMLPolyDataReader()
            reader.SetFileName(str(out / "view" / name))
            reader.Update()
            assert reader.GetOutput().GetNumberOfPoints() > 0, name
    if "report.html" in names:
        assert (out / "report.html").read_text().rstrip().endswith("</html>")
    for name in names & {"evaluation.json", "manifest.json"}:
        json.loads((out / name).read_text())
    if "evaluation_points.npz" in names:  # a whole zip: every array reads back
        with np.load(out / "evaluation_points.npz") as z:
            assert all(z[k].size >= 0 for k in z.files)
    return names


def test_killed_before_any_output_leaves_no_folder(tmp_path, scene_file):
    for i, trigger in enumerate((0.5, " pulses, swath ")):  # at once; in the simulation
        work = tmp_path / f"run{i}"
        work.mkdir()
        proc, log = _start(scene_file, work)
        t0 = time.monotonic()
        while proc.poll() is None and time.monotonic() - t0 < TIMEOUT_S:
            if trigger == 0.5:
                hit = time.monotonic() - t0 >= trigger
            else:
                hit = trigger in work.with_suffix(".log").read_text(errors="replace")
            if hit:
                break
            time.sleep(0.005)
        assert _finish(proc, log, kill=True) == -signal.SIGKILL, trigger  # killed, not ended
        assert list(work.iterdir()) == [], trigger  # the folder comes with its first file


# the four view/*.vtp share one writer: the first (it makes the folder) and the last are
# enough; the middle two cost a run each (~20 s of CI) and test nothing the others do not
@pytest.mark.parametrize("nth_write", [1, 2, 3, 4, 7, 8, 9, 10])
def test_killed_while_writing_leaves_only_complete_files(tmp_path, scene_file, nth_write):
    """SIGKILL as the ``nth_write`` output (points, grids, the first and last view/*.vtp,
    evaluation, report, manifest) is written."""
    work = tmp_path / "run"
    work.mkdir()
    proc, log = _start(scene_file, work)
    writes, was_open = 0, False
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < TIMEOUT_S:
        now_open = _open_under(proc.pid, work)
        writes += now_open and not was_open
        was_open = now_open
        if writes == nth_write:
            break
        # a look per millisecond: the shortest write caught (points.laz) lasts tens of ms, and
        # a spinning loop would take a core from the run it watches and from other tests
        time.sleep(0.001)
    caught = writes == nth_write and proc.poll() is None
    rc = _finish(proc, log, kill=caught)
    names = _assert_complete_or_nothing(work)
    if nth_write == 1:
        # the first output (points.laz, tens of ms) is always caught in the act
        assert caught and rc == -signal.SIGKILL and names == set(), (writes, rc, names)
    if not caught:  # a short JSON write slipped between two looks: the run ended whole
        assert rc == 0 and names == OUTPUTS, (writes, rc, names)
