"""``bathy sweep``: the design, the Pareto front, the cheapest run per order, bad input, a run."""

import csv
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.scene import DEFAULT_SCENE_PATH
from pipeline.sweep import design, run_sweep
from pipeline.sweep_select import cheapest_meeting, pareto_front, strictest_met

NAN = float("nan")


def _brute_front(cost, err):
    """Written out pair by pair: run i is off the front when some j is no worse in both and
    better in one; runs with a NaN are off it."""
    out = []
    for i in range(len(cost)):
        if not (np.isfinite(cost[i]) and np.isfinite(err[i])):
            out.append(False)
            continue
        beaten = False
        for j in range(len(cost)):
            if j == i or not (np.isfinite(cost[j]) and np.isfinite(err[j])):
                continue
            if cost[j] <= cost[i] and err[j] <= err[i] and (cost[j] < cost[i] or err[j] < err[i]):
                beaten = True
        out.append(not beaten)
    return out


def test_pareto_front_on_a_hand_made_table():
    # cost (CPU s/km²), RMSE (m): (10, .5) cheapest; (20, .3); (20, .4) beaten by (20, .3);
    # (40, .3) beaten by (20, .3); (80, .1) best; (5, NaN) no error: never on the front
    cost = [10.0, 20.0, 20.0, 40.0, 80.0, 5.0]
    rmse = [0.5, 0.3, 0.4, 0.3, 0.1, NAN]
    assert pareto_front(cost, rmse).tolist() == [True, True, False, False, True, False]


def test_pareto_front_against_brute_force():
    rng = np.random.default_rng(7)
    for n in (1, 2, 5, 12, 30):
        # coarse values, so ties in one or both coordinates occur
        cost = rng.integers(1, 6, n).astype(float)
        err = rng.integers(1, 6, n).astype(float)
        err[rng.random(n) < 0.1] = NAN
        assert pareto_front(cost, err).tolist() == _brute_front(cost, err)


def test_strictest_order_and_cheapest_run_per_order_on_a_hand_made_table():
    # fractions of soundings within each order's TVU, four runs
    frac = {
        "exclusive": [0.50, 0.96, 0.94, NAN],
        "special": [0.90, 0.99, 0.95, NAN],
        "1a": [0.97, 1.00, 0.99, NAN],
        "2": [0.99, 1.00, 1.00, NAN],
    }
    assert strictest_met(frac).tolist() == ["1a", "exclusive", "special", "none"]
    cost = [10.0, 50.0, 30.0, 1.0]
    # 1a and 2: run 0 (cost 10); special: run 2 (30) beats run 1 (50); exclusive: only run 1
    assert cheapest_meeting(cost, frac) == {"exclusive": 1, "special": 2, "1a": 0, "2": 0}
    assert cheapest_meeting(cost, {k: [0.5] * 4 for k in frac}) == dict.fromkeys(frac)


def test_default_design_is_the_centre_and_multiples_of_the_scene_values():
    data = tomllib.loads(DEFAULT_SCENE_PATH.read_text())
    pts = design(data, ["scanner.prf_hz", "trace.subrays", "detector.mode"])
    # the default scene: 12 kHz, 1 sub-ray, full waveform; the profiler table is dropped
    assert [(p.knob, p.value) for p in pts] == [
        ("scene", ""),
        ("scanner.prf_hz", 6000.0),
        ("scanner.prf_hz", 24000.0),
        ("trace.subrays", 4),
        ("detector.mode", "photon_counting"),
    ]
    assert all(p.scene.profiler is None for p in pts)
    assert pts[3].scene.trace.subrays == 4 and pts[3].scene.scanner.prf_hz == 12000.0


@pytest.mark.parametrize(
    "args, says",
    [
        (["--knobs", "scanner.no_such_key"], "unknown knob"),
        (["--knobs", "scanner"], "is a table"),
        (["--knobs", "water.extinction_per_m"], "no default levels"),
        (["--levels", "scanner.prf_hz=-5"], "scanner.prf_hz=-5"),
        (["--levels", "scanner.prf_hz"], "bad --levels"),
        (["--levels", "trace.subrays=1,0"], "trace.subrays=0"),
        (["--repeats", "0"], "--repeats must be >= 1"),
    ],
)
def test_bad_sweep_input_is_one_line_and_exit_2(tmp_path, capsys, args, says):
    out = tmp_path / "sw"
    assert main(["sweep", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and err.startswith("bathy sweep:")
    assert not out.exists()  # checked before any run


def test_an_existing_sweep_is_kept_without_overwrite(tmp_path, capsys):
    (tmp_path / "sweep.csv").write_text("run\n")
    assert main(["sweep", "--out", str(tmp_path), "--knobs", "trace.subrays"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (tmp_path / "sweep.csv").read_text() == "run\n"


TINY = """
[scene]
name = "tiny"
seed = 3
preset = "topobathy_full_waveform"
[scanner]
prf_hz = 600.0
[flight]
area_m = [0.0, 30.0, 0.0, 30.0]
n_lines = 1
run_in_m = 150.0
[water]
extinction_per_m = 0.15
wind_speed_m_s = 5.0
[seabed]
depth_m = 4.0
reflectance = 0.25
mesh_resolution_m = 2.0
[detector]
window_s = 3.5e-7
[process]
grid_resolution_m = 4.0
posterior_pulses_per_km2 = 0.0
posterior_min_pulses = 0
"""


@pytest.mark.slow
def test_sweep_of_a_tiny_scene_writes_a_row_per_run(tmp_path):
    scene = tmp_path / "tiny.toml"
    scene.write_text(TINY)
    out = tmp_path / "sweep"
    levels = {"scanner.prf_hz": [300.0, 1200.0], "process.grid_resolution_m": [2.0, 8.0]}
    run_sweep(scene, out, [], levels, log=lambda _: None)
    with open(out / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["knob"], r["value"]) for r in rows] == [
        ("scene", ""),
        ("scanner.prf_hz", "300.0"),
        ("scanner.prf_hz", "1200.0"),
        ("process.grid_resolution_m", "2.0"),
        ("process.grid_resolution_m", "8.0"),
    ]
    pulses = [int(r["n_pulses"]) for r in rows]
    # pulses scale with the pulse rate (same lines): half and twice the centre's
    assert pulses[1] == pytest.approx(pulses[0] / 2, rel=0.01)
    assert pulses[2] == pytest.approx(2 * pulses[0], rel=0.01)
    assert pulses[3] == pulses[4] == pulses[0]
    area_km2 = 30.0 * 30.0 / 1e6
    for r in rows:
        assert float(r["cpu_s"]) > 0 and float(r["rmse_m"]) >= 0
        assert float(r["cpu_s_per_km2"]) == pytest.approx(float(r["cpu_s"]) / area_km2)
        assert r["pareto"] in ("True", "False")
    summary = json.loads((out / "sweep.json").read_text())
    assert set(summary["cheapest_per_order"]) == {"exclusive", "special", "1a", "2"}
    assert (out / "sweep.png").read_bytes()[:4] == b"\x89PNG"
    page = (out / "sweep.html").read_text()
    assert "data:image/png;base64," in page and "Pareto" in page
    # each run's report says where the sweep is
    report = (out / "runs" / "01_scanner.prf_hz=300.0" / "report.html").read_text()
    assert "Error against run time" in report and "scanner.prf_hz = 300.0" in report
    assert str(Path("sweep.html")) in report


def test_run_report_section_only_when_a_sweep_was_run(tmp_path):
    from pipeline.outputs.sweep_report import run_report_section

    assert run_report_section(tmp_path) == ""  # a plain run, no sweep
    run = tmp_path / "sw" / "runs" / "01_scanner.prf_hz=6000.0"
    run.mkdir(parents=True)
    marker = {"knob": "scanner.prf_hz", "value": 6000.0, "sweep_html": "../../sweep.html"}
    (run / "sweep_point.json").write_text(json.dumps(marker))
    sec = run_report_section(run)
    assert "Error against run time" in sec and "scanner.prf_hz = 6000.0" in sec
    assert str(tmp_path / "sw" / "sweep.html") in sec and "href='../../sweep.html'" in sec
    # a plain run whose folder holds a finished sweep: its cheapest runs
    (tmp_path / "sweep").mkdir()
    best = {"run": "02_x", "knob": "x", "value": 1, "cpu_s_per_km2": 12.5, "rmse_m": 0.1}
    cheapest = {"exclusive": None, "special": best, "1a": best, "2": best}
    (tmp_path / "sweep" / "sweep.json").write_text(json.dumps({"cheapest_per_order": cheapest}))
    sec = run_report_section(tmp_path)
    assert "02_x" in sec and "12.5" in sec and "href='sweep/sweep.html'" in sec
