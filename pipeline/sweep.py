"""``bathy sweep SCENE``: depth error against CPU time over the scene's fidelity knobs.

Design: one knob at a time. The scene itself is run once (the centre point), then each knob
(a real scene key) is set to each of its levels with every other key at the scene's value,
so a sweep of ``k`` knobs with ``l`` levels each is ``1 + k l`` full runs
(:func:`pipeline.run.run_scene`, in this process). One-at-a-time finds the knobs that matter
and the cheap end of each, not their interactions; its cost stays linear in the knobs.

Default knobs and levels (:data:`KNOBS`) are multiples of the scene's own value, so the same
sweep fits any scene: sub-rays x4, digitiser rate x0.5 and x2, pulse rate x0.5 and x2,
posterior budget (``process.posterior_min_pulses``) x0 and x2, grid cell x0.5 and x2, and the
other receiver. ``--knobs`` picks knobs (any scene key), ``--levels KEY=V1,V2`` sets levels.

Each run's cost is its CPU seconds (process time, all threads) summed over the stages that
a survey needs (simulation and processing; not ``evaluate``, which compares with the truth and
writes the report, nor the profiler's figures: a sweep drops the ``[profiler]`` table),
per km² of ``flight.area_m``; its error comes from its ``evaluation.json``
(:func:`row_of_run`).
"""

from __future__ import annotations

import copy
import csv
import io
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.errors import SceneError
from pipeline.iho import CLASSIFIED_ORDERS
from pipeline.outputs.atomic import atomic_path, write_json
from pipeline.scene import Scene, parse_scene

__all__ = ["Knob", "KNOBS", "DEFAULT_KNOBS", "SweepPoint", "design", "row_of_run", "run_sweep"]


@dataclass(frozen=True)
class Knob:
    """A fidelity knob: its scene key, what it sets, its default levels.

    ``factors`` multiply the scene's value (rounded for integer keys); ``choices`` replace it
    (a key with named values: the levels are the choices other than the scene's).
    """

    key: str
    what: str
    factors: tuple[float, ...] = ()
    choices: tuple[str, ...] = ()


#: The knobs a sweep varies by default, in order.
KNOBS: dict[str, Knob] = {
    k.key: k
    for k in (
        Knob("trace.subrays", "sub-rays per footprint", factors=(4.0,)),
        Knob("detector.sample_rate_hz", "digitiser sample rate", factors=(0.5, 2.0)),
        Knob("scanner.prf_hz", "pulse rate, so point density", factors=(0.5, 2.0)),
        Knob("process.posterior_min_pulses", "depth posterior budget", factors=(0.0, 2.0)),
        Knob("process.grid_resolution_m", "grid cell", factors=(0.5, 2.0)),
        Knob("detector.mode", "receiver", choices=("full_waveform", "photon_counting")),
    )
}
DEFAULT_KNOBS: tuple[str, ...] = tuple(KNOBS)
#: Label of the centre run (the scene as written).
CENTRE = "scene"
#: CSV columns, in order.
COLUMNS = (
    "run",
    "knob",
    "value",
    "cpu_s",
    "cpu_s_per_km2",
    "cpu_s_simulate",
    "cpu_s_process",
    "wall_s",
    "cpu_s_spread",
    "n_pulses",
    "n_points",
    "rmse_m",
    "bias_m",
    "p95_abs_m",
    "max_abs_m",
    "grid_rmse_m",
    "tpu_coverage_95",
    "posterior_coverage_95",
    *(f"within_tvu_{o}" for o in CLASSIFIED_ORDERS),
    "iho_order",
    "pareto",
)
#: Stages that simulate what the instrument records (the rest of the survey processes it).
SIMULATE_STAGES = (
    "terrain",
    "waves",
    "survey",
    "trace",
    "receiver_waveform",
    "receiver_photon",
)
#: Stages not counted as the survey's cost: the truth comparison and the profiler's figures.
NOT_COUNTED = ("evaluate", "photon_budget", "photon_histograms", "profiler_figures")


@dataclass(frozen=True)
class SweepPoint:
    """One run of the sweep: the knob set (``CENTRE`` for the scene) and the scene data."""

    knob: str
    value: Any
    data: dict[str, Any]
    scene: Scene


def scene_value(scene: Scene, key: str) -> Any:
    """The value of dotted ``key`` in ``scene``; SceneError naming it when there is none."""
    node: Any = scene
    for part in key.split("."):
        if node is None or not hasattr(node, part) or part.startswith("_"):
            raise SceneError(
                f"unknown knob {key!r}: not a scene key (`bathy keys` lists them; default "
                f"knobs: {', '.join(DEFAULT_KNOBS)})"
            )
        node = getattr(node, part)
    if hasattr(node, "__dataclass_fields__"):
        raise SceneError(f"knob {key!r} is a table, not a key (`bathy keys` lists the keys)")
    return node


def _parse_value(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    low = text.strip().lower()
    return {"true": True, "false": False}.get(low, text.strip())


def parse_levels(specs: Sequence[str]) -> dict[str, list[Any]]:
    """``["KEY=V1,V2", ...]`` as ``{KEY: [V1, V2]}`` (numbers parsed); SceneError if malformed."""
    out: dict[str, list[Any]] = {}
    for spec in specs:
        key, sep, vals = spec.partition("=")
        items = [v for v in vals.split(",") if v.strip()]
        if not sep or not key.strip() or not items:
            raise SceneError(
                f"bad --levels {spec!r}: give KEY=V1,V2 (e.g. scanner.prf_hz=6e3,24e3)"
            )
        out[key.strip()] = [_parse_value(v) for v in items]
    return out


def default_levels(knob: Knob, value: Any) -> list[Any]:
    """The knob's default levels around the scene's ``value`` (the scene's own left out)."""
    if knob.choices:
        return [c for c in knob.choices if c != value]
    out = []
    for f in knob.factors:
        v = f * value
        v = int(round(v)) if isinstance(value, int) and not isinstance(value, bool) else v
        if v != value and v not in out:
            out.append(v)
    return out


def _set(data: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    out = copy.deepcopy(data)
    node = out
    *parents, leaf = key.split(".")
    for p in parents:
        node = node.setdefault(p, {})
    node[leaf] = value
    return out


def read_scene_data(path: str | Path) -> dict[str, Any]:
    """The scene file's TOML as data (SceneError if unreadable), validated once."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SceneError(f"Scene file not found: {path}") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"Cannot read scene file {path}: {exc}") from None
    parse_scene(data, str(path))
    return data


def design(
    data: dict[str, Any], knobs: Sequence[str] = DEFAULT_KNOBS, levels: dict | None = None
) -> list[SweepPoint]:
    """Every run of the sweep, validated before any runs: the centre, then knob by knob.

    Parameters
    ----------
    data : dict
        The scene file's data (its ``[profiler]`` table is dropped: a sweep times the survey).
    knobs : sequence of str
        Scene keys to vary; a key outside :data:`KNOBS` needs ``levels``.
    levels : dict of str to list, optional
        Levels per key (replacing the defaults); keys not in ``knobs`` are added.

    Raises
    ------
    SceneError
        An unknown key, a knob without levels, a level the scene rejects, or a scene without
        a survey.
    """
    levels = dict(levels or {})
    base = {k: v for k, v in data.items() if k != "profiler"}
    name = (data.get("scene") or {}).get("name", "scene")
    if base.get("flight") is None:
        raise SceneError(f"scene {name!r} has no [flight] table: nothing to sweep")
    centre = parse_scene(base, name)
    points = [SweepPoint(CENTRE, "", base, centre)]
    for key in [*knobs, *(k for k in levels if k not in knobs)]:
        value = scene_value(centre, key)
        if key == "trace.subrays" and value is None:
            # None: the trace's own choice for the scene's surface (what the run will use)
            from pipeline.simulate.trace_settings import resolved_trace_settings

            value = resolved_trace_settings(centre).subrays
        if key in levels:
            vals = levels[key]
        elif key in KNOBS:
            vals = default_levels(KNOBS[key], value)
        else:
            raise SceneError(f"knob {key!r} has no default levels: give --levels {key}=V1,V2")
        for v in vals:
            d = _set(base, key, v)
            try:
                sc = parse_scene(d, name)
            except SceneError as exc:
                raise SceneError(f"level {key}={v!r} is not a valid scene: {exc}") from None
            points.append(SweepPoint(key, v, d, sc))
    return points


def _area_km2(scene: Scene) -> float:
    xmin, xmax, ymin, ymax = scene.flight.area_m
    return (xmax - xmin) * (ymax - ymin) / 1e6


def _get(d: Any, *path: str) -> Any:
    for p in path:
        d = d.get(p) if isinstance(d, dict) else None
    return d


def row_of_run(point: SweepPoint, manifest: dict[str, Any], run: str) -> dict[str, Any]:
    """One CSV row: the run's cost (from the manifest's stage clock) and its evaluation."""
    from pipeline.sweep_select import strictest_met

    st = {s["stage"]: s for s in manifest["plan"] if s["runs"] and "cpu_s" in s}
    counted = [k for k in st if k not in NOT_COUNTED]
    cpu = sum(st[k]["cpu_s"] for k in counted)
    sim = sum(st[k]["cpu_s"] for k in counted if k in SIMULATE_STAGES)
    ev = manifest.get("evaluation") or {}
    iho = _get(ev, "error", "iho_points") or {}
    within = {o: _get(iho, o, "fraction_within") for o in CLASSIFIED_ORDERS}
    frac = {o: [float("nan") if v is None else v] for o, v in within.items()}
    row = {
        "run": run,
        "knob": point.knob,
        "value": point.value,
        "cpu_s": cpu,
        "cpu_s_per_km2": cpu / _area_km2(point.scene),
        "cpu_s_simulate": sim,
        "cpu_s_process": cpu - sim,
        "wall_s": sum(st[k]["wall_s"] for k in counted),
        "n_pulses": ev.get("pulses"),
        "n_points": _get(ev, "error", "points", "n"),
        "rmse_m": _get(ev, "error", "points", "rmse_m"),
        "bias_m": _get(ev, "error", "points", "bias_m"),
        # the RMSE of a few thousand points moves with a handful of gross errors (metres):
        # the 95th percentile of |error| and the largest say whether it did
        "p95_abs_m": _get(ev, "error", "points", "p95_abs_m"),
        "max_abs_m": _get(ev, "error", "points", "max_abs_m"),
        "grid_rmse_m": _get(ev, "error", "grid", "rmse_m"),
        "tpu_coverage_95": _get(ev, "tpu_coverage_against_truth", "fraction_within"),
        "posterior_coverage_95": _get(ev, "posterior_against_truth", "coverage_95"),
        **{f"within_tvu_{o}": v for o, v in within.items()},
        "iho_order": str(strictest_met(frac)[0]),
        "pareto": None,
    }
    return row


def _csv_text(rows: list[dict[str, Any]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: "" if r.get(k) is None else r[k] for k in COLUMNS})
    return buf.getvalue()


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """``sweep.csv``, atomically (empty cells where a run has no value)."""
    with atomic_path(path) as tmp:
        tmp.write_text(_csv_text(rows), encoding="utf-8")


def _finish(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Mark the Pareto front in ``rows``; the summary of ``sweep.json``."""
    import numpy as np

    from pipeline.sweep_select import cheapest_meeting, pareto_front

    def col(k):
        return np.array([np.nan if r[k] is None else r[k] for r in rows], dtype=float)

    cost = col("cpu_s_per_km2")
    front = pareto_front(cost, col("rmse_m"))
    for r, f in zip(rows, front, strict=True):
        r["pareto"] = bool(f)
    cheap = cheapest_meeting(cost, {o: col(f"within_tvu_{o}") for o in CLASSIFIED_ORDERS})
    return {
        "pareto_runs": [r["run"] for r, f in zip(rows, front, strict=True) if f],
        "cheapest_per_order": {
            o: None
            if i is None
            else {k: rows[i][k] for k in ("run", "knob", "value", "cpu_s_per_km2", "rmse_m")}
            for o, i in cheap.items()
        },
    }


def _warm_up(centre: SweepPoint, log: Callable[[str], None]) -> None:
    """Run the centre scene once at a tenth of its pulse rate, untimed, into a temporary folder.

    The first run of a process pays one-off costs (lazy imports, library and cache set-up:
    ~20 % of the default scene's CPU seconds): without this the centre run, which goes first,
    would look dearer than it is.
    """
    import tempfile

    from pipeline.run import run_scene

    data = _set(centre.data, "scanner.prf_hz", 0.1 * centre.scene.scanner.prf_hz)
    ps = centre.scene.process
    data = _set(data, "process.posterior_pulses_per_km2", 0.0)
    data = _set(data, "process.posterior_min_pulses", min(ps.posterior_min_pulses, 2))
    try:
        scene = parse_scene(data, "warm-up")
    except SceneError:
        scene = centre.scene
    log("  warm-up run (untimed): the centre scene at a tenth of its pulse rate")
    with tempfile.TemporaryDirectory(prefix="bathy-sweep-") as tmp:
        run_scene(scene, tmp, log=lambda _line: None)


def run_sweep(
    scene_path: str | Path,
    out_dir: str | Path,
    knobs: Sequence[str] = DEFAULT_KNOBS,
    levels: dict | None = None,
    log: Callable[[str], None] = print,
    repeats: int = 1,
) -> dict[str, Any]:
    """Run every point of :func:`design` and write ``sweep.csv``, ``sweep.json``, the figure.

    Each run writes its outputs under ``out_dir/runs/NN_KNOB=VALUE``; ``sweep.csv`` is
    rewritten after every run (a stopped sweep keeps what it ran), and ``sweep.png`` and
    ``sweep.html`` at the end (:mod:`pipeline.outputs.sweep_report`). With ``repeats`` > 1
    each point runs that many times and keeps its least CPU time (``cpu_s_spread``: the
    largest minus the least).

    Returns
    -------
    dict
        The summary written to ``sweep.json``.
    """
    from pipeline.outputs.sweep_report import write_sweep_figure, write_sweep_html
    from pipeline.run import clear_outputs, run_scene

    if repeats < 1:
        raise SceneError(f"--repeats must be >= 1; got {repeats}")
    out = Path(out_dir)
    data = read_scene_data(scene_path)
    points = design(data, knobs, levels)
    log(f"bathy sweep {scene_path} -> {out}: {len(points)} runs, one knob at a time")
    _warm_up(points[0], log)
    rows: list[dict[str, Any]] = []
    for i, pt in enumerate(points):
        run = f"{i:02d}_{pt.knob}" + (f"={pt.value}" if pt.knob != CENTRE else "")
        run_dir = out / "runs" / run
        clear_outputs(run_dir)
        write_json(
            run_dir / "sweep_point.json",
            {"knob": pt.knob, "value": pt.value, "sweep_html": "../../sweep.html"},
        )
        t0 = time.perf_counter()
        # repeats: the least-disturbed timing (the minimum, as timeit advises) of identical,
        # seeded runs on a shared machine; the spread says how noisy the clock was
        tries = [
            row_of_run(pt, run_scene(pt.scene, run_dir, log=lambda _line: None), run)
            for _ in range(repeats)
        ]
        row = min(tries, key=lambda r: r["cpu_s"])
        row["cpu_s_spread"] = max(r["cpu_s"] for r in tries) - row["cpu_s"]
        rows.append(row)
        write_csv(out / "sweep.csv", rows)
        rmse = "-" if row["rmse_m"] is None else f"{row['rmse_m']:.3f} m"
        log(
            f"  [{i + 1}/{len(points)}] {run}: {row['cpu_s']:.1f} CPU s "
            f"({row['cpu_s_per_km2']:.0f} s/km²), RMSE {rmse}, order {row['iho_order']}"
            f" ({time.perf_counter() - t0:.0f} s)"
        )
    summary = _finish(rows)
    write_csv(out / "sweep.csv", rows)
    summary = {
        "scene": str(scene_path),
        "design": "one knob at a time around the scene (the centre run), profiler table dropped",
        "cost": "CPU s of the survey's stages (not evaluate) per km² of flight.area_m",
        "repeats": repeats,
        "order_rule": ">= 95 % of class-40 soundings within the order's TVU at their true depth",
        "knobs": {
            k: KNOBS[k].what if k in KNOBS else k
            for k in dict.fromkeys(r["knob"] for r in rows)
            if k != CENTRE
        },
        **summary,
        "rows": rows,
    }
    write_json(out / "sweep.json", summary)
    write_sweep_figure(out / "sweep.png", rows, summary)
    write_sweep_html(out / "sweep.html", rows, summary)
    for name in ("sweep.csv", "sweep.json", "sweep.png", "sweep.html"):
        log(f"  wrote {out / name}")
    return summary
