"""``bathy stress``: the extreme-case suite, each case run end to end on a tiny scene.

Every case is data (:class:`StressCase`, the table in :mod:`pipeline.stress_cases`): a base
scene (a few thousand pulses), the scene keys it overrides, and what it expects. A run case
goes through every stage the scene needs (:func:`pipeline.run.run_scene`: simulate, detect,
process, TPU, grid, outputs, evaluation) and must complete, leave every numeric output finite
(``points.laz`` coordinates, depths, uncertainties and confidences, ``grid.tif``'s valid
cells, every number in ``evaluation.json`` and ``manifest.json``; JSON null is allowed where a
quantity does not exist) and meet its own expectations. A bad-input case writes its scene to
TOML, runs ``bathy run`` through :func:`pipeline.cli.main` and expects exit status 2 with one
stderr line naming the key.

A case whose failure comes from a known defect elsewhere carries ``known_failure`` (the measured
reason): it is reported as "known failure", not PASS, and does not fail the suite; if it passes,
the suite fails, so the table is updated when the defect is fixed.
"""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.stress_cases import CASES, StressCase
from pipeline.stress_support import CHECKS, read_outputs, to_toml, with_overrides

__all__ = ["StressCase", "CaseResult", "CASES", "scene_data", "run_case", "run_cases"]


@dataclass(frozen=True)
class CaseResult:
    """Outcome of one case: ``status`` is PASS, FAIL or KNOWN (a known failure)."""

    name: str
    status: str
    seconds: float
    detail: str

    def line(self) -> str:
        """The case's one report line."""
        label = {"KNOWN": "known failure"}.get(self.status, self.status)
        return f"{self.name:<22} {label:<13} {self.seconds:6.1f} s  {self.detail}".rstrip()


def scene_data(case: StressCase) -> dict[str, Any]:
    """The case's scene as a TOML-like mapping: its base with the overrides set."""
    return with_overrides(case.base, f"stress_{case.name}", case.overrides)


#: The CLI's entry point: ``argv`` in, exit status out.
CliMain = Callable[[list[str]], int]

# ---------------------------------------------------------------------------------------------
# running a case


def _bad_input(case: StressCase, out: Path, cli_main: CliMain | None) -> str:
    """Run ``bathy run`` on the case's scene file: exit 2 with one line naming the key.

    ``cli_main`` is :func:`pipeline.cli.main` when the CLI runs the suite (handed in: this
    module does not import the CLI that imports it); without it, ``python -m pipeline.cli``.
    """
    out.mkdir(parents=True, exist_ok=True)
    path = out / "scene.toml"
    path.write_text(to_toml(scene_data(case)))
    argv = ["run", str(path), "--out", str(out / "run")]
    if cli_main is not None:
        err, std = io.StringIO(), io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
            status = cli_main(argv)
        stderr = err.getvalue()
    else:
        res = subprocess.run(
            [sys.executable, "-m", "pipeline.cli", *argv], capture_output=True, text=True
        )
        status, stderr = res.returncode, res.stderr
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if status != case.exit_status:
        return f"exit {status}, expected {case.exit_status}: {' | '.join(lines)[:200]}"
    if len(lines) != 1:
        return f"{len(lines)} stderr lines, expected 1"
    missing = [k for k in case.expect if k not in lines[0]]
    return f"message does not name {missing}: {lines[0]}" if missing else ""


def _end_to_end(case: StressCase, out: Path) -> str:
    """Run the case's scene through :func:`pipeline.run.run_scene`; check its outputs."""
    from pipeline.run import run_scene
    from pipeline.scene import parse_scene

    out.mkdir(parents=True, exist_ok=True)
    log_lines: list[str] = []
    try:
        scene = parse_scene(scene_data(case), source=case.name)
        run_scene(scene, out, log=log_lines.append)
    except Exception as exc:  # the suite reports every crash as the case's failure
        (out / "traceback.txt").write_text(traceback.format_exc())
        where = traceback.extract_tb(exc.__traceback__)[-1]
        return (
            f"raised {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            f" ({Path(where.filename).name}:{where.lineno} in {where.name})"
        )
    finally:
        (out / "run.log").write_text("\n".join(log_lines) + "\n")
    try:
        outputs, problems = read_outputs(out)
    except Exception as exc:  # unreadable output: a failure of the case, not of the suite
        return f"outputs unreadable: {type(exc).__name__}: {exc}"
    for item in case.expect:
        name, _, arg = item.partition(":")
        msg = CHECKS[name](outputs, arg)
        if msg:
            problems.append(msg)
    return "; ".join(problems)


def run_case(case: StressCase, out_dir: str | Path, cli_main: CliMain | None = None) -> CaseResult:
    """Run one case into ``out_dir/<case name>`` and judge it."""
    out = Path(out_dir) / case.name
    t0 = time.perf_counter()
    failure = _bad_input(case, out, cli_main) if case.exit_status else _end_to_end(case, out)
    seconds = time.perf_counter() - t0
    if case.known_failure:
        if failure:
            return CaseResult(case.name, "KNOWN", seconds, f"{case.known_failure} [{failure}]")
        return CaseResult(
            case.name, "FAIL", seconds, "known failure now passes: update the case table"
        )
    return CaseResult(case.name, "FAIL" if failure else "PASS", seconds, failure)


def select_cases(only: Sequence[str] = (), fast: bool = False) -> list[StressCase]:
    """The cases named in ``only`` (all if empty), the fast subset if ``fast``.

    Raises
    ------
    ValueError
        When a name in ``only`` is not a case.
    """
    names = {c.name for c in CASES}
    unknown = [n for n in only if n not in names]
    if unknown:
        raise ValueError(f"no stress case {', '.join(unknown)}; cases: {', '.join(sorted(names))}")
    return [c for c in CASES if (not only or c.name in only) and (c.fast or not fast)]


def run_cases(
    cases: Sequence[StressCase],
    out_dir: str | Path,
    log: Callable[[str], None] = print,
    cli_main: CliMain | None = None,
) -> list[CaseResult]:
    """Run ``cases`` one after the other, logging each one's report line as it ends."""
    results = []
    for case in cases:
        results.append(run_case(case, out_dir, cli_main))
        log(results[-1].line())
    return results
