"""The command line people use: --version, --json, --quiet, no silent mixing of old outputs."""

import json

import pytest

from pipeline.cli import main
from pipeline.provenance import inputs_sha256

from .conftest import ROOT

PALMER = (ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text()


def _tiny(tmp_path, seed=7):
    text = (
        PALMER.replace("area_m = [0.0, 300.0, 0.0, 600.0]", "area_m = [0.0, 40.0, 0.0, 40.0]")
        .replace("run_in_m = 150.0", "run_in_m = 0.0")
        .replace("prf_hz = 35000.0", "prf_hz = 3000.0")
        .replace("seed = 7", f"seed = {seed}")
        .replace("[process]", "[process]\nposterior_pulses_per_km2 = 0.0\nposterior_min_pulses = 0")
    )
    path = tmp_path / f"tiny{seed}.toml"
    path.write_text(text)
    return path


def test_version(capsys):
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("bathy ") and "commit" in out


def test_json_then_refuse_then_overwrite(tmp_path, capsys):
    scene, out = _tiny(tmp_path), tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)  # stdout holds the JSON alone
    assert summary["pulses"] > 100 and summary["files"]["points"] == "points.laz"
    assert "evaluate" in summary["stages"] and summary["provenance"]["libraries"]["numpy"]
    # a folder holding outputs is refused: one line, exit 2, nothing touched
    before = (out / "points.laz").stat().st_mtime_ns
    assert main(["run", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--overwrite" in err and "points.laz" in err
    assert (out / "points.laz").stat().st_mtime_ns == before
    # --overwrite replaces them, and an old output the new run does not write is gone
    (out / "grid.nc").write_text("stale")
    (out / "notes.txt").write_text("the user's own file")
    assert main(["run", str(scene), "--out", str(out), "--overwrite", "--quiet"]) == 0
    assert capsys.readouterr().out == ""  # quiet
    assert not (out / "grid.nc").exists() or (out / "grid.nc").read_text(errors="ignore") != "stale"
    assert (out / "notes.txt").exists()


def test_manifest_records_provenance(tmp_path):
    from pipeline.run import run_scene
    from pipeline.scene import load_scene

    a, b = load_scene(_tiny(tmp_path, 7)), load_scene(_tiny(tmp_path, 8))
    manifest = run_scene(a, tmp_path / "a", log=lambda _: None)
    prov = manifest["provenance"]
    assert prov["bathy_version"] and prov["libraries"]["laspy"] and prov["libraries"]["gdal"]
    assert prov["inputs_sha256"] == inputs_sha256(a.to_dict())
    assert inputs_sha256(a.to_dict()) != inputs_sha256(b.to_dict())  # another seed


def test_no_command_or_an_unknown_one_is_exit_2(capsys):
    assert main([]) == 2
    with pytest.raises(SystemExit) as exc:  # argparse's own usage error
        main(["frobnicate"])
    assert exc.value.code == 2
