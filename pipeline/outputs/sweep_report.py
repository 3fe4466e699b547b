"""The outputs of ``bathy sweep``: ``sweep.png``, ``sweep.html``, and the run report's pointer.

``sweep.png``: depth RMSE (left) and the TPU / posterior 95 % coverage (right) against CPU
seconds per km², one marker per run coloured by knob, the Pareto front of RMSE against cost
drawn, and the cheapest run meeting each IHO S-44 order ringed. ``sweep.html``: the figure
(base64, self-contained like ``report.html``), the design and the table. Each run of a sweep
gets a section in its ``report.html`` pointing at ``sweep.html`` (:func:`run_report_section`).
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.iho import CLASSIFIED_ORDERS, IHO_CONFIDENCE
from pipeline.outputs.atomic import atomic_path
from pipeline.outputs.report_html import img, page, para, table

__all__ = ["sweep_figure", "write_sweep_figure", "write_sweep_html", "run_report_section"]

#: Marker rings of the cheapest run per order.
_ORDER_STYLE = {"exclusive": "tab:purple", "special": "tab:red", "1a": "tab:orange", "2": "0.4"}


def _col(rows: list[dict[str, Any]], key: str) -> np.ndarray:
    return np.array([np.nan if r.get(key) is None else r[key] for r in rows], dtype=float)


def sweep_figure(rows: list[dict[str, Any]], summary: dict[str, Any]) -> bytes:
    """The two-panel PNG of a sweep (see the module)."""
    from pipeline.outputs.report_figures import _figure, png

    cost, rmse = _col(rows, "cpu_s_per_km2"), _col(rows, "rmse_m")
    front = np.array([bool(r.get("pareto")) for r in rows])
    knobs = list(dict.fromkeys(r["knob"] for r in rows))
    colours = {k: f"C{i % 10}" for i, k in enumerate(knobs)}
    fig = _figure(11.0, 4.6)
    ax, ax2 = fig.subplots(1, 2)
    for k in knobs:
        sel = np.array([r["knob"] == k for r in rows])
        marker = "s" if k == "scene" else "o"
        ax.scatter(cost[sel], rmse[sel], color=colours[k], marker=marker, label=k, zorder=3)
        ax2.scatter(cost[sel], _col(rows, "tpu_coverage_95")[sel], color=colours[k], marker=marker)
        ax2.scatter(
            cost[sel],
            _col(rows, "posterior_coverage_95")[sel],
            facecolor="none",
            edgecolor=colours[k],
            marker=marker,
        )
    for i, r in enumerate(rows):
        if r["knob"] != "scene" and np.isfinite(cost[i]) and np.isfinite(rmse[i]):
            v = r["value"]
            ax.annotate(
                f"{v:.3g}" if isinstance(v, (int, float)) else str(v),
                (cost[i], rmse[i]),
                fontsize=7,
                xytext=(3, 3),
                textcoords="offset points",
            )
    if front.any():
        o = np.argsort(cost[front])
        ax.step(
            cost[front][o],
            rmse[front][o],
            where="post",
            color="k",
            lw=1.0,
            label="Pareto front",
            zorder=2,
        )
    for k, (order, best) in enumerate(summary.get("cheapest_per_order", {}).items()):
        if best is None:
            continue
        i = next(j for j, r in enumerate(rows) if r["run"] == best["run"])
        ax.scatter(  # rings of growing size: several orders met by one run all show
            cost[i],
            rmse[i],
            s=120 + 90 * k,
            facecolor="none",
            edgecolor=_ORDER_STYLE[order],
            lw=1.6,
            zorder=4,
            label=f"cheapest meeting {order}",
        )
    # a log axis needs a positive cost on a plotted (finite RMSE) run: a tiny run's clock can
    # read 0, and a survey with no class-40 point plots nothing
    log_x = bool(np.any(np.isfinite(cost) & (np.asarray(cost) > 0) & np.isfinite(rmse)))
    for a in (ax, ax2):
        if log_x:
            a.set_xscale("log")
        a.set_xlabel("CPU seconds per km² (survey stages)")
        a.grid(True, which="both", alpha=0.3)
    finite = rmse[np.isfinite(rmse) & (rmse > 0)]
    if finite.size and finite.max() > 20.0 * finite.min():  # a poor run would flatten the rest
        ax.set_yscale("log")
    ax.set_ylabel("depth RMSE of class-40 points (m)")
    ax.set_title("Error against run time (one knob at a time)", fontsize=10)
    ax.legend(fontsize=7, loc="best")
    ax2.axhline(IHO_CONFIDENCE, color="k", ls="--", lw=0.8, label="nominal 95 %")
    ax2.set_ylabel("true depth within the 95 % interval")
    ax2.set_title("Coverage: TPU ±1.96σ (filled), posterior 95 % (hollow)", fontsize=10)
    ax2.set_ylim(0.0, 1.02)
    ax2.legend(fontsize=7, loc="lower right")
    return png(fig)


def write_sweep_figure(path: Path, rows: list[dict[str, Any]], summary: dict[str, Any]) -> Path:
    """``sweep.png``, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(sweep_figure(rows, summary))
    return Path(path)


_SHOWN = (
    ("run", "run"),
    ("cpu_s", "CPU (s)"),
    ("cpu_s_per_km2", "CPU s/km²"),
    ("n_pulses", "pulses"),
    ("rmse_m", "RMSE (m)"),
    ("bias_m", "bias (m)"),
    ("p95_abs_m", "|error| 95 % (m)"),
    ("max_abs_m", "max |error| (m)"),
    ("grid_rmse_m", "grid RMSE (m)"),
    ("tpu_coverage_95", "TPU 95 % coverage"),
    ("posterior_coverage_95", "posterior 95 % coverage"),
    ("iho_order", "order met"),
    ("pareto", "Pareto"),
)


def write_sweep_html(path: Path, rows: list[dict[str, Any]], summary: dict[str, Any]) -> Path:
    """``sweep.html``: the figure, the design, the cheapest run per order and the table."""
    s = [
        img(sweep_figure(rows, summary), "error against run time"),
        para(
            f"Design: {summary['design']}. Cost: {summary['cost']}. An order is met when "
            f"{summary['order_rule']}. Scene: {summary['scene']}."
        ),
    ]
    cheap = summary.get("cheapest_per_order", {})
    s.append(
        table(
            ["IHO S-44 order", "cheapest run meeting it", "CPU s/km²", "RMSE (m)"],
            [
                [
                    o,
                    *(
                        ["none meets it", None, None]
                        if b is None
                        else [b["run"], b["cpu_s_per_km2"], b["rmse_m"]]
                    ),
                ]
                for o, b in cheap.items()
            ],
        )
    )
    s.append(
        table(
            [h for _, h in _SHOWN],
            [
                [("yes" if r[k] else "") if k == "pareto" else r.get(k) for k, _ in _SHOWN]
                for r in rows
            ],
        )
    )
    s.append(para("Every run's own report: runs/<run>/report.html; the numbers: sweep.csv."))
    with atomic_path(path) as tmp:
        tmp.write_text(page("bathy sweep: error against run time", s), encoding="utf-8")
    return Path(path)


def _sweep_dir(out_dir: Path) -> tuple[Path, dict[str, Any] | None] | None:
    """Where the sweep of a run is, and the run's point in it (None: no sweep)."""
    marker = out_dir / "sweep_point.json"
    if marker.is_file():
        point = json.loads(marker.read_text(encoding="utf-8"))
        return (out_dir / point["sweep_html"]).resolve().parent, point
    if (out_dir / "sweep" / "sweep.json").is_file():
        return out_dir / "sweep", None
    return None


def _link(href: str) -> str:
    """A relative link to ``sweep.html`` (the page stays valid when the folder moves)."""
    return f"<p><a href='{html.escape(href, quote=True)}'>open sweep.html</a></p>"


def run_report_section(out_dir: str | Path) -> str:
    """The ``report.html`` section "Error against run time", or ``""`` when no sweep was run.

    A run of a sweep (``sweep_point.json`` beside it) names its knob and where ``sweep.html``
    is (written when the sweep ends); a plain run whose folder holds a finished sweep
    (``bathy sweep SCENE`` writes ``out/<name>/sweep`` by default) gets its cheapest runs.
    """
    found = _sweep_dir(Path(out_dir))
    if found is None:
        return ""
    where, point = found
    head = "<h2 id='sweep'>Error against run time</h2>"
    html_path = where / "sweep.html"
    if point is not None:
        what = (
            "the sweep's centre run (the scene as written)"
            if point["knob"] == "scene"
            else f"the sweep's run with {point['knob']} = {point['value']}"
        )
        return (
            head
            + para(
                f"This run is {what}. The depth error against CPU time of every run of the sweep, "
                f"its Pareto front and the cheapest run meeting each IHO S-44 order are in "
                f"{html_path} (written when the sweep ends)."
            )
            + _link(point["sweep_html"])
        )
    summary = json.loads((where / "sweep.json").read_text(encoding="utf-8"))
    rows = [
        [o, "none" if b is None else b["run"], None if b is None else b["cpu_s_per_km2"]]
        for o, b in summary.get("cheapest_per_order", {}).items()
        if o in CLASSIFIED_ORDERS
    ]
    return (
        head
        + para(f"A sweep of this scene's fidelity knobs is in {html_path}; its cheapest runs:")
        + _link("sweep/sweep.html")
        + table(["IHO S-44 order", "cheapest run meeting it", "CPU s/km²"], rows)
    )
