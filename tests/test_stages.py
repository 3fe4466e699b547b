"""The plan is what runs: stages declared once, left out with a reason, executed exactly."""

import ast
import json
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.run import run_scene
from pipeline.scene import load_scene, parse_scene
from pipeline.stages import STAGES, StageClock, plan

from .conftest import ROOT

SHIPPED = [ROOT / "pipeline" / "scenes" / "default.toml"] + sorted(
    (ROOT / "data_synthetic" / "scenes").glob("*.toml")
)


def test_shipped_scenes_get_plans_that_differ_where_the_scenes_differ():
    plans = {p.stem: tuple(plan(load_scene(p)).running()) for p in SHIPPED}
    assert len(plans) == 6 and len(set(plans.values())) == 6
    assert "waves" in plans["palmer_survey_waves"] and "waves" not in plans["palmer_survey"]
    assert "receiver_photon" in plans["photon_profiler"]
    assert "receiver_waveform" not in plans["photon_profiler"]
    assert "water_column" in plans["water_column_layer"]
    assert "water_column" not in plans["palmer_survey"]
    assert plans["reference_profiler"] == ("photon_budget", "photon_histograms", "profiler_figures")
    # photon counting samples its window histograms (pipeline.uncertainty.photon_posterior)
    assert "posterior" in plans["default"] and "posterior" in plans["photon_profiler"]


def test_every_stage_left_out_says_why():
    for p in SHIPPED:
        for st in plan(load_scene(p)):
            assert st.reason, f"{p.stem}: {st.name} has no reason"
    assert len({s.name for s in STAGES}) == len(STAGES)


def test_bathy_plan_prints_the_plan(capsys):
    assert main(["plan", str(SHIPPED[-1])]) == 0
    out = capsys.readouterr().out
    assert "skip waves" in out and "run  water_column" in out


def _small(name, **changes):
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / f"{name}.toml").read_text())
    data["flight"].update(changes.pop("flight", {}))
    for table, values in changes.items():
        data.setdefault(table, {}).update(values)
    return parse_scene(data)


def _palmer(**process):
    return _small(
        "palmer_survey",
        flight={"area_m": [0.0, 60.0, 0.0, 60.0], "run_in_m": 0.0},
        scanner={"prf_hz": 4000.0},
        process=process,
    )


def _photon():
    # and without the 3D views: the plan leaves a stage out by a run key too
    return _small(
        "photon_profiler", flight={"area_m": [-1.0, 1.0, 0.0, 40.0]}, run={"views": False}
    )


@pytest.mark.parametrize("which", ["palmer", "photon"])
def test_run_executes_exactly_the_plan_and_times_each_stage(tmp_path, monkeypatch, which):
    scene = _palmer() if which == "palmer" else _photon()
    if which == "photon":
        # a photon-counting scene must never call the digitiser
        import pipeline.simulate.waveform as W

        def forbidden(*a, **k):
            raise AssertionError("the digitiser ran in a photon-counting scene")

        monkeypatch.setattr(W, "simulate_waveforms", forbidden)
        monkeypatch.setattr(W, "digitise", forbidden, raising=False)
    manifest = run_scene(scene, tmp_path, log=lambda _: None)
    for st in manifest["plan"]:
        assert ("wall_s" in st) == st["runs"], st
        if st["runs"]:
            assert st["wall_s"] >= 0.0 and st["cpu_s"] >= 0.0
    ev = json.loads((tmp_path / "evaluation.json").read_text())
    assert set(ev["stages"]) <= {s["stage"] for s in manifest["plan"] if s["runs"]}
    views = next(s for s in manifest["plan"] if s["stage"] == "views")
    assert views["runs"] == (which == "palmer")
    assert (tmp_path / "view").is_dir() == (which == "palmer")
    if which == "photon":
        assert views["reason"] == "run.views = false"
        assert "left out of this run" in (tmp_path / "report.html").read_text()


_PROBE = """
import sys, tomllib, json
sys.path.insert(0, {root!r})
from pipeline.scene import parse_scene
from pipeline.run import run_scene
data = tomllib.loads(open({scene!r}).read())
data["flight"].update(area_m=[0.0, 40.0, 0.0, 40.0], run_in_m=0.0)
data["scanner"]["prf_hz"] = 3000.0
data["process"].update({process})
run_scene(parse_scene(data), {out!r}, log=lambda _: None)
print(json.dumps("emcee" in sys.modules))
"""


@pytest.mark.parametrize("posteriors", [False, True])
def test_emcee_is_imported_only_when_posteriors_run(tmp_path, posteriors):
    process = {} if posteriors else {"posterior_pulses_per_km2": 0.0, "posterior_min_pulses": 0}
    code = _PROBE.format(
        root=str(ROOT),
        scene=str(ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml"),
        process=repr(process),
        out=str(tmp_path / "out"),
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=600
    )
    assert json.loads(res.stdout.strip().splitlines()[-1]) is posteriors


def _imports(path: Path, package_root: Path) -> set[str]:
    """Every pipeline/terrain module ``path`` imports, at module or function level."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out |= {f"{node.module}.{a.name}" for a in node.names}
    return out


def test_no_import_circle():
    mods = {}
    for pkg in ("pipeline", "terrain"):
        for p in (ROOT / pkg).rglob("*.py"):
            name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
            mods[name.removesuffix(".__init__")] = p
    graph = {m: {i for i in _imports(p, ROOT) if i in mods and i != m} for m, p in mods.items()}
    # packages' __init__ re-export their modules: an edge to a package is not a circle
    graph = {m: {i for i in deps if not mods[i].name == "__init__.py"} for m, deps in graph.items()}
    seen, stack, cycles = set(), [], []

    def visit(m):
        if m in stack:
            cycles.append(stack[stack.index(m) :] + [m])
            return
        if m in seen:
            return
        seen.add(m)
        stack.append(m)
        for d in sorted(graph[m]):
            visit(d)
        stack.pop()

    for m in sorted(graph):
        visit(m)
    assert cycles == []


def test_no_module_over_450_lines():
    long = {
        str(p.relative_to(ROOT)): n
        for pkg in ("pipeline", "terrain")
        for p in (ROOT / pkg).rglob("*.py")
        if (n := len(p.read_text().splitlines())) > 450
    }
    assert long == {}


def test_stage_clock_records_the_memory_peak_a_stage_raised():
    # in a fresh interpreter: ru_maxrss is the process's high-water mark, which the tests run
    # before this one have already raised
    code = """
import json
import numpy as np
from pipeline.stages import StageClock

clock = StageClock()
with clock.stage("small"):
    pass
with clock.stage("big"):
    a = np.ones(25_000_000)  # 200 MB, every page written
    del a
print(json.dumps(clock.to_dict()))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    d = json.loads(out.stdout.strip().splitlines()[-1])
    # the high-water mark is the kernel's (ru_maxrss), not the clock's bookkeeping: the 200 MB
    # array raised it by most of its size, and it stays raised after the array is gone
    assert d["big"]["peak_rss_mb"] - d["small"]["peak_rss_mb"] > 150.0


def test_a_stage_that_does_not_raise_the_mark_gets_its_own_peak():
    # the process's high-water mark cannot give a later, lower stage's peak: the sampler does.
    # Known allocations are the reference: every page of np.ones is written
    code = """
import json, time
import numpy as np
from pipeline.stages import StageClock
from pipeline.rss_watch import current_rss_mb

clock = StageClock()
base = current_rss_mb()
with clock.stage("first"):
    a = np.ones(40_000_000)  # 305 MiB
    del a
with clock.stage("outer"):
    with clock.stage("second"):
        b = np.ones(13_000_000)  # 99 MiB, held long enough for 10 ms samples
        time.sleep(0.2)
        del b
    with clock.stage("third"):
        c = np.ones(52_000_000)  # 397 MiB: raises the mark
        del c
print(json.dumps({"base": base, "clock": clock.to_dict()}))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    res = json.loads(out.stdout.strip().splitlines()[-1])
    d, base = res["clock"], res["base"]
    assert d["first"]["peak_exact"] and d["first"]["peak_rss_mb"] - base > 290.0
    # sampled, not the mark: within a few MiB of its 99 MiB above the start
    assert not d["second"]["peak_exact"]
    assert 90.0 < d["second"]["peak_rss_mb"] - base < 140.0
    # the nested stage raised the mark: it and the stage around it get it exactly
    assert d["third"]["peak_exact"] and d["third"]["peak_rss_mb"] - base > 380.0
    assert d["outer"]["peak_exact"]
    assert d["outer"]["peak_rss_mb"] == d["third"]["peak_rss_mb"]


def test_worker_figures_add_seconds_and_keep_the_larger_peak():
    clock = StageClock()
    clock.add({"trace": {"wall_s": 1.0, "cpu_s": 2.0, "peak_rss_mb": 500.0, "peak_exact": True}})
    clock.add({"trace": {"wall_s": 0.5, "cpu_s": 1.0, "peak_rss_mb": 300.0, "peak_exact": False}})
    d = clock.to_dict()["trace"]
    assert d == {"wall_s": 1.5, "cpu_s": 3.0, "peak_rss_mb": 500.0, "peak_exact": True}


def test_the_sampler_works_in_a_forked_worker():
    # a forked child inherits no sampling thread (and maybe a held lock): it starts its own
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:
        d = pool.apply(_stage_in_worker)
    assert d["w"]["peak_rss_mb"] > 0.0


def _stage_in_worker():
    clock = StageClock()
    with clock.stage("w"):
        time.sleep(0.05)
    return clock.to_dict()
