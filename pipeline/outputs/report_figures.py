"""The figures of a survey's ``report.html``: each a PNG (bytes), units on every axis.

Plain :class:`matplotlib.figure.Figure` objects drawn on the Agg canvas (no pyplot state, so a
report written in a long process leaks nothing). Every function takes plain arrays: what they
mean, and where the truth comes in, is :mod:`pipeline.outputs.report`'s business.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

__all__ = [
    "png",
    "MAP_CELLS",
    "nearest_cells",
    "coverage_map",
    "waveforms",
    "grid_map",
    "order_map",
    "error_figure",
    "calibration",
    "depth_limits",
]

#: Colours of the strictest IHO order met (exclusive, special, 1a/1b, 2, none).
ORDER_COLOURS = ("#1a9850", "#91cf60", "#fee08b", "#fc8d59", "#d73027")
DPI = 90


def _figure(w_in: float = 7.0, h_in: float = 4.5) -> Figure:
    fig = Figure(figsize=(w_in, h_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def png(fig: Figure) -> bytes:
    """The figure as PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


#: Cells a map shows along each axis, at most: a map is a few hundred pixels wide, and
#: matplotlib's image pipeline holds ~100 B a cell (``error_figure`` of a million cells:
#: 106 MiB traced, against 6 MiB for ten thousand).
MAP_CELLS = 1024


def nearest_cells(n: int) -> np.ndarray:
    """Rows (or columns) of ``n`` shown: all, or :data:`MAP_CELLS` picked at even spacing.

    Each picked index is the cell under the centre of its share of the axis, as
    nearest-neighbour drawing picks a cell under each pixel.
    """
    if n <= MAP_CELLS:
        return np.arange(n)
    return ((np.arange(MAP_CELLS) + 0.5) * (n / MAP_CELLS)).astype(np.int64)


def _show(ax, values, x_m, y_m, res_m: float, **kw):
    """Show a cell-centred grid north up, whichever way its rows run (GeoTIFF: north first).

    ``x_m``, ``y_m``: the whole grid's cell centres (its extent). At most :data:`MAP_CELLS`
    cells a side are drawn (:func:`nearest_cells`): ``values`` is the whole grid's, or the
    cells those pick (:func:`pipeline.outputs.report.map_cells`), stretched over the extent.
    """
    h = 0.5 * res_m
    extent = (x_m.min() - h, x_m.max() + h, y_m.min() - h, y_m.max() + h)
    origin = "upper" if y_m.size > 1 and y_m[0] > y_m[-1] else "lower"
    values = np.asarray(values)
    if max(values.shape) > MAP_CELLS:
        values = values[np.ix_(nearest_cells(values.shape[0]), nearest_cells(values.shape[1]))]
    return ax.imshow(values, origin=origin, extent=extent, interpolation="nearest", **kw)


def _area(ax, area_m: Sequence[float], label: str | None = "flight.area_m (asked)") -> None:
    x0, x1, y0, y1 = area_m
    ax.add_patch(
        Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="k", lw=1.5, ls="--", label=label)
    )


def _map_axes(ax, title: str) -> None:
    ax.set_xlabel("local easting x (m)")
    ax.set_ylabel("local northing y (m)")
    ax.set_aspect("equal")
    ax.set_title(title)


def coverage_map(
    x_m, y_m, res_m, count, area_m, covered: float | None, limits=(None, None)
) -> bytes:
    """Density of the gridded (class-40) points per cell, points/m², the asked area outlined.

    ``covered``: share of the asked area with a point of any class (the run's coverage figure);
    ``limits``: the colour scale's ``(vmin, vmax)`` (default: those of ``count``'s cells).
    """
    fig = _figure()
    ax = fig.add_subplot()
    dens = np.where(count > 0, count / res_m**2, np.nan)
    im = _show(ax, dens, x_m, y_m, res_m, cmap="viridis", vmin=limits[0], vmax=limits[1])
    fig.colorbar(im, ax=ax, label="class-40 soundings per m²")
    _area(ax, area_m)
    cov = "" if covered is None else f"\n{covered:.0%} of the asked area has any point"
    _map_axes(ax, f"Class-40 density, {res_m:g} m cells{cov}")
    ax.legend(loc="upper right", fontsize=8)
    return png(fig)


def waveforms(
    t_ns: np.ndarray,
    samples: np.ndarray,
    marks: list[dict[str, float]],
    fits: list[np.ndarray | None] | None = None,
) -> bytes:
    """A few recorded waveforms with their surface and bottom detections.

    ``t_ns`` (n_samples,) time since sample 0; ``samples`` (k, n_samples); ``marks[i]`` the
    detection times (ns since sample 0) of waveform ``i``, keys ``surface`` / ``bottom`` /
    ``no-bottom limit``, and its ``title``; ``fits[i]`` (n_samples,) the depth posterior's
    fitted waveform of waveform ``i``, drawn over it, or None (no posterior).
    """
    fig = _figure(7.0, 1.6 + 1.4 * len(samples))
    axes = fig.subplots(len(samples), 1, sharex=True, squeeze=False)[:, 0]
    fits = [None] * len(samples) if fits is None else fits
    for ax, s, m, fit in zip(axes, samples, marks, fits, strict=True):
        ax.plot(t_ns, s, lw=0.8, color="0.2", label="waveform")
        if fit is not None:
            ax.plot(t_ns, fit, lw=1.0, color="tab:green", alpha=0.8, label="posterior fit")
        for key, colour in (
            ("surface", "tab:blue"),
            ("bottom", "tab:red"),
            ("no-bottom limit", "tab:orange"),
        ):
            if key in m:
                ax.axvline(m[key], color=colour, ls="--", label=key)
        ax.set_ylabel("counts")
        ax.set_title(m["title"], fontsize=9)
        ax.legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("time since the first sample (ns)")
    return png(fig)


def grid_map(
    x_m, y_m, res_m, values, area_m, label: str, title: str, cmap="viridis_r", limits=(None, None)
) -> bytes:
    """One grid quantity as a map (NaN cells blank); ``limits``: the colour scale's."""
    fig = _figure()
    ax = fig.add_subplot()
    im = _show(ax, values, x_m, y_m, res_m, cmap=cmap, vmin=limits[0], vmax=limits[1])
    fig.colorbar(im, ax=ax, label=label)
    _area(ax, area_m)
    _map_axes(ax, title)
    ax.legend(loc="upper right", fontsize=8)
    return png(fig)


def order_map(x_m, y_m, res_m, codes, labels: Sequence[str], area_m) -> bytes:
    """Strictest IHO S-44 order met per cell (codes 0..len(labels)-1; -1 no data)."""
    fig = _figure()
    ax = fig.add_subplot()
    n = len(labels)
    cmap = ListedColormap(ORDER_COLOURS[:n])
    norm = BoundaryNorm(np.arange(-0.5, n), n)
    vals = np.where(codes < 0, np.nan, codes.astype(float))
    im = _show(ax, vals, x_m, y_m, res_m, cmap=cmap, norm=norm)
    cb = fig.colorbar(im, ax=ax, ticks=np.arange(n), label="strictest order met")
    cb.ax.set_yticklabels(labels)
    _area(ax, area_m)
    _map_axes(ax, "IHO S-44 order met per cell (propagated TVU and THU)")
    ax.legend(loc="upper right", fontsize=8)
    return png(fig)


def error_figure(
    x_m,
    y_m,
    res_m,
    grid_err_m,
    area_m,
    point_err_m,
    point_depth_m,
    bands: list[dict],
    err_limit_m: float | None = None,
) -> bytes:
    """Grid error map, point error histogram, and bias / RMSE / IHO allowance per depth band.

    ``err_limit_m``: the error scale's half-width (default: the 98th percentile of the
    cells' ``|grid_err_m|``).
    """
    fig = _figure(11.0, 4.2)
    a, b, c = fig.subplots(1, 3)
    lim = err_limit_m
    if lim is None:  # the 98th percentile of the cells' |error|
        finite = np.isfinite(grid_err_m).any()
        lim = float(np.nanpercentile(np.abs(grid_err_m), 98)) if finite else 1
    im = _show(
        a,
        grid_err_m,
        x_m,
        y_m,
        res_m,
        cmap="RdBu_r",
        vmin=-lim,
        vmax=lim,
    )
    fig.colorbar(im, ax=a, label="cell depth error (m), + too deep")
    _area(a, area_m, None)
    _map_axes(a, "Grid error against truth")
    e = point_err_m[np.isfinite(point_err_m)]
    if e.size:
        lo, hi = np.percentile(e, [0.5, 99.5])
        b.hist(e, bins=60, range=(lo, hi), color="tab:gray", label=f"{e.size} class-40 points")
        b.axvline(0.0, color="k", lw=0.8)
        b.axvline(float(np.mean(e)), color="tab:red", ls="--", label=f"bias {np.mean(e):+.3f} m")
        b.legend(fontsize=8)
    b.set_xlabel("point depth error (m), + too deep")
    b.set_ylabel("points")
    b.set_title("Point errors (class 40)")
    if bands:
        mid = np.array([0.5 * (r["from_m"] + r["to_m"]) for r in bands])
        w = 0.8 * np.array([r["to_m"] - r["from_m"] for r in bands])
        c.bar(mid, [r["rmse_m"] for r in bands], width=w, color="0.7", label="RMSE")
        c.plot(mid, [r["bias_m"] for r in bands], "o-", color="tab:red", label="bias")
        c.plot(mid, [r["p95_abs_m"] for r in bands], "s-", color="tab:purple", label="|error| 95 %")
        c.plot(mid, [r["special_m"] for r in bands], "k--", label="Special order TVU")
        c.axhline(0.0, color="k", lw=0.6)
        # a few gross errors (e.g. land taken for seabed) would flatten the rest on a linear axis
        c.set_yscale("symlog", linthresh=0.05)
        c.legend(fontsize=8)
    c.set_xlabel("true depth (m)")
    c.set_ylabel("error (m), linear within ±0.05")
    c.set_title("Error by depth band")
    return png(fig)


def calibration(tpu_rows: list[dict], posterior: dict | None) -> bytes:
    """Share of true depths within ±kσ against the normal distribution's, per k."""
    fig = _figure(6.0, 4.2)
    ax = fig.add_subplot()
    kk = np.linspace(0.0, 3.2, 100)
    ax.plot(kk, [math.erf(k / math.sqrt(2.0)) for k in kk], "k-", lw=1, label="nominal (normal)")
    rows = [r for r in tpu_rows if r["fraction_within"] is not None]
    if rows:
        ax.errorbar(
            [r["k"] for r in rows],
            [r["fraction_within"] for r in rows],
            yerr=[2 * r["standard_error"] for r in rows],
            fmt="o",
            color="tab:blue",
            capsize=3,
            label="TPU σ_depth (±2 s.e.)",
        )
    if posterior:
        ax.errorbar(
            [1.0, 1.96],
            [posterior["coverage_68"], posterior["coverage_95"]],
            yerr=[
                2 * posterior["coverage_68_standard_error"],
                2 * posterior["coverage_95_standard_error"],
            ],
            fmt="s",
            color="tab:orange",
            capsize=3,
            label=f"posterior 68/95 % intervals (n={posterior['n']})",
        )
    ax.set_xlabel("coverage factor k (interval ±k σ)")
    ax.set_ylabel("fraction of true depths within")
    ax.set_ylim(0.0, 1.02)
    ax.set_title("Uncertainty calibration against truth")
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)
    return png(fig)


def depth_limits(
    depth40_m: np.ndarray, depth45_m: np.ndarray, shallow_m: float | None, deep_m: float | None
) -> bytes:
    """Depths of the bottoms found (class 40) and of the no-bottom limits (class 45)."""
    fig = _figure(7.0, 3.8)
    ax = fig.add_subplot()
    both = np.concatenate([depth40_m, depth45_m])
    both = both[np.isfinite(both)]
    rng = (float(both.min()), float(both.max())) if both.size else (0.0, 1.0)
    if depth40_m.size:
        ax.hist(depth40_m, bins=60, range=rng, alpha=0.7, label="bottoms found (class 40)")
    if depth45_m.size:
        ax.hist(depth45_m, bins=60, range=rng, alpha=0.7, label="no bottom down to (class 45)")
    for v, name, colour in (
        (shallow_m, "shallow limit", "tab:green"),
        (deep_m, "extinction depth", "k"),
    ):
        if v is not None:
            ax.axvline(v, color=colour, ls="--", label=f"{name} {v:.1f} m")
    ax.set_xlabel("depth below the water surface (m)")
    ax.set_ylabel("points")
    ax.set_title("Depth range: shallow limit and extinction depth")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    return png(fig)
