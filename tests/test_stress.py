"""``bathy stress``: the fast subset of the extreme cases runs end to end and meets its
expectations (known failures are reported as such, never as PASS); the command reports one
line per case and its exit status says whether a case failed."""

import dataclasses
import math

import pytest

from pipeline.cli import main
from pipeline.stress import CASES, run_case, run_cases, select_cases
from pipeline.stress_support import to_toml


def test_fast_subset_passes_or_fails_only_as_known(tmp_path):
    cases = select_cases(fast=True)
    assert len(cases) >= 20
    # every case of the table passes today (saturation and all_land were known failures)
    assert [c.name for c in CASES if c.known_failure] == []
    # the 40 m/s sea is in the fast subset (small, frozen), its full versions in the full run
    assert {"tir", "wind_40"} <= {c.name for c in cases}
    results = run_cases(cases, tmp_path, log=lambda _: None, cli_main=main)
    bad = [r.line() for r in results if r.status == "FAIL"]
    assert not bad, "\n".join(bad)
    for case, r in zip(cases, results, strict=True):
        assert r.status == ("KNOWN" if case.known_failure else "PASS"), r.line()
    # every numeric output was checked: a run case leaves its three outputs behind
    for case in cases:
        if case.exit_status == 0:
            assert (tmp_path / case.name / "points.laz").exists()
            assert (tmp_path / case.name / "evaluation.json").exists()


def test_a_case_that_misses_its_expectation_fails_and_a_fixed_known_failure_too(tmp_path):
    base = next(c for c in CASES if c.name == "baseline")
    wrong = dataclasses.replace(base, name="wrong", expect=("class:99",))
    r = run_case(wrong, tmp_path)
    assert r.status == "FAIL" and "no class-99 point" in r.detail
    # a known failure that now passes must be noticed, so the table gets updated
    healed = dataclasses.replace(base, name="healed", known_failure="was broken")
    r = run_case(healed, tmp_path)
    assert r.status == "FAIL" and "update the case table" in r.detail


def test_cli_reports_one_line_per_case_and_exit_status(tmp_path, capsys):
    out = str(tmp_path / "s")
    assert main(["stress", "--out", out, "--only", "empty_area", "bad_wind"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[:2] == ["empty_area", "PASS"]
    assert lines[2].split()[:2] == ["bad_wind", "PASS"]
    assert lines[3] == "2 passed, 0 known failures, 0 failed"
    assert main(["stress", "--out", out, "--only", "no_such_case"]) == 2
    assert "no stress case no_such_case" in capsys.readouterr().err


@pytest.mark.parametrize("value", [1.5, -3, True, 'a "b"', [0.0, 1e-300], math.nan])
def test_scene_toml_round_trips(value):
    import tomllib

    data = {"scene": {"name": "x"}, "process": {"detect": {"v": value}}}
    back = tomllib.loads(to_toml(data))["process"]["detect"]["v"]
    if isinstance(value, float) and math.isnan(value):
        assert math.isnan(back)
    else:
        assert back == value


def test_noise_and_abstention_checks_on_hand_made_outputs():
    from types import SimpleNamespace

    import numpy as np

    from pipeline.stress_support import CHECKS, Outputs

    def outputs(classes, max_abs_m):
        las = SimpleNamespace(classification=np.array(classes, dtype=np.uint8))
        points = {} if max_abs_m is None else {"max_abs_m": max_abs_m}
        return Outputs({"error": {"points": points}}, las, {})

    # noise alone classed 7 or 18 passes; one surface (41) among it does not
    assert CHECKS["only_noise"](outputs([7, 18, 7], None), "") == ""
    assert CHECKS["only_noise"](outputs([], None), "") == ""
    assert "41" in CHECKS["only_noise"](outputs([7, 41], None), "")
    # abstaining (no class-40 point compared) passes; a claimed depth 1.2 m off does not
    assert CHECKS["max_error"](outputs([2, 2], None), "1.0") == ""
    assert CHECKS["max_error"](outputs([40], 0.4), "1.0") == ""
    assert "1.200 m off" in CHECKS["max_error"](outputs([40], 1.2), "1.0")


def test_datum_source_check_on_hand_made_outputs():
    from pipeline.stress_support import CHECKS, Outputs

    def outputs(source):
        return Outputs({"datum": {"source": source, "water_level_m": 0.1}}, None, {})

    assert CHECKS["datum_source"](outputs("clipped_bound"), "clipped_bound") == ""
    assert "'surface_mean'" in CHECKS["datum_source"](outputs("surface_mean"), "clipped_bound")
