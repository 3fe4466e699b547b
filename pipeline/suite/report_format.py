"""Markdown cells and tables of the suite's report (shared by its modules)."""

from __future__ import annotations

import math

__all__ = ["f", "pct", "row", "head"]


def f(v, fmt="{:+.3f}") -> str:
    """A number as ``fmt``, or ``-`` for None and non-finite."""
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


def pct(v) -> str:
    """A fraction as a percentage with one decimal."""
    return f(None if v is None else 100.0 * v, "{:.1f}")


def row(cells) -> str:
    """One Markdown table row."""
    return "| " + " | ".join(str(c) for c in cells) + " |"


def head(cells) -> list[str]:
    """A Markdown table's header and rule."""
    return [row(cells), "|" + "---|" * len(cells)]
