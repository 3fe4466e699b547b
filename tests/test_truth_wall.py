"""Processing must never see the truth: no import of `terrain`, no truth file read."""

import ast
import re
from pathlib import Path

PIPELINE = Path(__file__).resolve().parents[1] / "pipeline"
#: every package that processes measured data
PROCESSING = (PIPELINE / "process", PIPELINE / "uncertainty")
TRUTH_WORDS = ("truth", "terrain")
# a string naming a file or a path, e.g. "out/truth.npz", "terrain_truth.tif"
FILE_LIKE = re.compile(r"(/|\\)|\.(npz|npy|tif|tiff|json|toml|laz|las|nc|csv|h5|pkl|txt)\b")


def _violations(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            names = [node.module or ""]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            # a path or file name mentioning the truth is a read of the truth
            if any(w in node.value.lower() for w in TRUTH_WORDS) and FILE_LIKE.search(node.value):
                found.append(f"{path.name}: string {node.value!r}")
            continue
        else:
            continue
        found += [f"{path.name}: import {n}" for n in names if n.split(".")[0] == "terrain"]
        truthy = ("evaluate", "simulate", "run_survey", "survey_report")
        found += [f"{path.name}: import {n}" for n in names if any(w in n for w in truthy)]
    return found


def test_process_does_not_import_terrain_or_read_truth():
    files = sorted(f for pkg in PROCESSING for f in pkg.rglob("*.py"))
    assert len(files) > 40  # both packages found
    problems = [v for f in files for v in _violations(f)]
    assert problems == []


def test_the_check_catches_a_leak(tmp_path):
    leak = tmp_path / "leak.py"
    leak.write_text("from terrain.seabed import plane\nopen('out/truth.npz')\n")
    assert len(_violations(leak)) == 2
