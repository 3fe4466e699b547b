"""Scenes that pass key-by-key validation but cannot run: one clear line and exit 2, no output.

The three values below crashed `bathy run` with a traceback and exit 1 before (the issue's
fuzzing found them); a CRS in degrees would have given a survey in degrees.
"""

import pytest

from pipeline.cli import main

from .conftest import ROOT

PALMER = (ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text()


def _scene(tmp_path, old, new):
    assert old in PALMER
    path = tmp_path / "s.toml"
    path.write_text(PALMER.replace(old, new))
    return path


CASES = [
    ("[process]", '[frame]\ncrs = "text"\n\n[process]', "`frame.crs`", "text"),
    ("[process]", '[frame]\ncrs = "EPSG:4326"\n\n[process]', "`frame.crs`", "degree"),
    ("prf_hz = 35000.0", "prf_hz = 1e300", "`scanner.prf_hz`", "more pulses than can be counted"),
    # 1.4e9 pulses in blocks of 1e9: no memory holds them
    (
        "[scanner]\nprf_hz = 35000.0",
        "[run]\nblock_pulses = 1000000000\n\n[scanner]\nprf_hz = 5e7",
        "`run.block_pulses`",
        "GB",
    ),
    ("mesh_resolution_m = 1.0", "mesh_resolution_m = 1e-300", "`seabed.mesh_resolution_m`", "GB"),
]


@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize("old, new, key, words", CASES)
def test_unrunnable_scene_is_one_line_and_exit_2(tmp_path, capsys, command, old, new, key, words):
    path = _scene(tmp_path, old, new)
    out = tmp_path / "out"
    args = [command, str(path)] + (["--out", str(out)] if command == "run" else [])
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert key in err and words in err
    assert not out.exists()


def test_a_runnable_survey_passes(tmp_path):
    assert main(["validate", str(_scene(tmp_path, "[process]", "[process]"))]) == 0


def test_a_survey_no_disk_holds_is_refused_by_run(tmp_path, capsys):
    """1.4e12 pulses: held a block at a time, but no disk holds their detections.

    ``bathy validate`` does not know where the outputs will go; ``bathy run`` checks there.
    """
    path = _scene(tmp_path, "prf_hz = 35000.0", "prf_hz = 5e10")
    assert main(["validate", str(path)]) == 0
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "GB of disk" in err and str(tmp_path) in err
    assert not out.exists()
