"""The report's TPU coverage against chance: each coverage read against its own floor's range.

A hand-made pair of strata and ranges: the expected marks and counts are written here.
"""

from __future__ import annotations

from pipeline.suite.report_chance import chance_section


def _stratum(label, h68, h95, t68, t95):
    def half(c68, c95):
        return {"tpu": {"n": 1000, "cov68": c68, "cov95": c95}}

    return {
        "dimension": "wind m/s",
        "label": label,
        "in_floor_window": True,
        "heldout": half(h68, h95),
        "tuning": half(t68, t95),
    }


def _chance(r68, r95):
    return {
        "tpu68": {"mean": 0.0, "p10": 0.0, "p90": 0.0, "strata": len(r68), "ranges": r68},
        "tpu95": {"mean": 0.0, "p10": 0.0, "p90": 0.0, "strata": len(r95), "ranges": r95},
    }


def test_each_coverage_is_marked_against_its_own_floors_range():
    strata = [
        # held-out: 68 % above its range, 95 % below its range; tuning: both inside
        _stratum("0-2", 0.80, 0.90, 0.68, 0.95),
        # held-out: both inside; tuning: 68 % inside, 95 % above
        _stratum("2-5", 0.70, 0.95, 0.66, 0.99),
    ]
    r68 = {("wind m/s", "0-2"): (0.60, 0.75), ("wind m/s", "2-5"): (0.60, 0.75)}
    r95 = {("wind m/s", "0-2"): (0.92, 0.97), ("wind m/s", "2-5"): (0.92, 0.97)}
    chance = {"heldout": _chance(r68, r95), "tuning": _chance(r68, r95)}
    lines = chance_section(strata, chance)
    text = "\n".join(lines)
    assert "held-out tpu68 1 of 2, tpu95 1 of 2; tuning tpu68 0 of 2, tpu95 1 of 2" in text
    row = {ln.split(" | ")[0][2:]: ln.split(" | ")[1:] for ln in lines if ln.startswith("| wind")}
    h68, h95, t68, t95 = row["wind m/s: 0-2"]
    assert h68.startswith("80.0 [60.0-75.0]") and h68.endswith("**high**")
    assert h95.startswith("90.0 [92.0-97.0]") and h95.endswith("**low**")
    assert "**" not in t68 and "**" not in t95
    h68, h95, t68, t95 = row["wind m/s: 2-5"]
    assert "**" not in h68 + h95 + t68 and t95.rstrip(" |").endswith("**high**")
