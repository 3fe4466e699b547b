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


def test_a_blocked_grid_no_temporary_disk_holds_is_refused_by_run(tmp_path, capsys, monkeypatch):
    """1 cm cells over a 3 x 6 km blocked survey: its grid's temporary files fill no disk.

    The pulses (a slow pulse rate) fit the output folder's disk; the grid written by tiles
    (:class:`~pipeline.outputs.grid_tiles.GridTiles`, 85 B per cell in the temporary
    directory) does not. ``bathy validate`` does not know the disks; ``bathy run`` checks both.
    """
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr("tempfile.tempdir", None)  # read TMPDIR again
    area = ("area_m = [0.0, 300.0, 0.0, 600.0]", "area_m = [0.0, 3000.0, 0.0, 6000.0]")
    text = PALMER.replace(*area)
    path = tmp_path / "s.toml"
    path.write_text(
        text.replace("prf_hz = 35000.0", "prf_hz = 350.0")
        .replace("grid_resolution_m = 5.0", "grid_resolution_m = 0.01")
        .replace("[scanner]\n", "[run]\nblock_m = 500.0\n\n[scanner]\n", 1)
    )
    assert main(["validate", str(path)]) == 0
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "`process.grid_resolution_m` = 0.01" in err and "GB of temporary disk" in err
    assert str(scratch) in err and "TMPDIR" in err
    assert not out.exists()


def test_the_temporary_disk_is_the_one_measured(tmp_path, monkeypatch):
    """The temporary directory's free space is checked, with the outputs' on a shared disk."""
    import collections
    import shutil

    from pipeline.errors import SceneError
    from pipeline.feasibility import DISK_SHARE, TEMP_BYTES_PER_CELL, check_disk

    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr("tempfile.tempdir", None)
    usage = collections.namedtuple("usage", "total used free")
    free = {str(tmp_path): 1e12, str(scratch): 1e9}
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(0, 0, free[str(p)]))
    fits = int(DISK_SHARE * 1e9 / TEMP_BYTES_PER_CELL)
    check_disk(1000, tmp_path / "out", 0, 5.0)  # not blocked: no temporary grid
    check_disk(0, tmp_path / "out", fits, 5.0)
    with pytest.raises(SceneError, match="temporary disk"):
        check_disk(0, tmp_path / "out", fits + 10, 5.0)
    # the same disk (tmp_path and scratch are): the outputs' pulses take their share of it
    with pytest.raises(SceneError, match="the same disk"):
        check_disk(1000, tmp_path / "out", fits, 5.0)


def test_a_survey_held_whole_is_planned_at_its_measured_cost(tmp_path, capsys, monkeypatch):
    """Held whole, a survey needs 0.5 GB + 1.77 kB a pulse (its largest process).

    The line through the figures measured at 500 k and 1 M pulses (1.38, 2.26 GB;
    ``pipeline/memory_budget.py``). The Palmer scene (~1 M pulses) held whole (``run.whole_pulses``
    and ``run.block_pulses`` raised past it), on a machine
    whose share is just below that: ``bathy validate`` refuses it and names the keys that
    block it. Blocked (blocks of a quarter of its pulses, a sample of a fifth), its sample and
    a block fit, and it passes.
    """
    import pipeline.feasibility as feas
    from pipeline.memory_budget import held_bytes
    from pipeline.scene import load_scene
    from pipeline.simulate.trajectory import plan_lines

    two_m = "[run]\nblock_pulses = 2000000\nwhole_pulses = 2000000\n\n[process]"
    path = _scene(tmp_path, "[process]", two_m)
    scene = load_scene(path)
    n = plan_lines(scene.flight, scene.scanner).n_pulses_total
    assert 500_000 < n < scene.run.whole_pulses  # held whole
    whole = 0.5e9 + 1.77e3 * n
    assert held_bytes(n, scene.run.block_pulses, scene.run.sample_pulses, False) == whole
    share = 0.95 * whole  # the run's share of the machine: just below what it needs
    monkeypatch.setattr(feas, "machine_memory_bytes", lambda: share / feas.MEMORY_SHARE)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "held whole" in err
    assert "`run.whole_pulses` = 2_000_000" in err and "`run.block_pulses` = 2_000_000" in err
    blocked = _scene(
        tmp_path,
        "[process]",
        f"[run]\nblock_pulses = {n // 4}\nsample_pulses = {n // 5}\n\n[process]",
    )
    assert main(["validate", str(blocked)]) == 0
    capsys.readouterr()
    # a machine without room for its sample held whole: refused, blocked, the values named
    sample = 0.5e9 + 1.77e3 * (n // 5)
    monkeypatch.setattr(feas, "machine_memory_bytes", lambda: 0.9 * sample / feas.MEMORY_SHARE)
    assert main(["validate", str(blocked)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "blocked" in err
    assert f"`run.sample_pulses` = {n // 5:_}" in err and f"`run.block_pulses` = {n // 4:_}" in err


def test_a_survey_past_whole_pulses_is_blocked_though_smaller_than_a_block():
    """Held whole, a survey's process grows ~1.77 kB a pulse; past ``run.whole_pulses`` it is
    blocked even when one block (``run.block_pulses``) could hold it, and ``block_m`` blocks any.
    """
    import dataclasses

    from pipeline.scene import load_scene
    from pipeline.survey_blocks import is_blocked

    scene = load_scene(ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml")
    run = dataclasses.replace(scene.run, whole_pulses=750_000, block_pulses=1_000_000)
    at = dataclasses.replace(scene, run=run)
    assert not is_blocked(at, 750_000) and is_blocked(at, 750_001)
    small_blocks = dataclasses.replace(run, whole_pulses=2_000_000, block_pulses=100_000)
    assert is_blocked(dataclasses.replace(scene, run=small_blocks), 100_001)
    assert is_blocked(dataclasses.replace(scene, run=dataclasses.replace(run, block_m=50.0)), 10)
