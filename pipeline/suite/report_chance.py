"""The suite's TPU floors judged against chance, stratum by stratum (report section)."""

from __future__ import annotations

from pipeline.suite.chance_tpu import beyond_chance
from pipeline.suite.report_format import head as _head
from pipeline.suite.report_format import pct as _pct
from pipeline.suite.report_format import row as _row

__all__ = ["chance_section", "shared_chance"]


def _chance_table(strata, chance) -> tuple[list[str], dict[str, dict[str, int]]]:
    """Observed TPU coverage per stratum against an exactly right TPU's 95 % range.

    Returns the table's lines and, per half and floor, how many judged strata lie beyond it.
    """
    lines = _head(
        ["stratum"] + [f"{h} {q} % observed [range]" for h in ("H", "T") for q in ("68", "95")]
    )
    beyond = {h: {k: 0 for k in chance[h]} for h in chance}
    for s in strata:
        if not s["in_floor_window"]:
            continue
        key, cells = (s["dimension"], s["label"]), []
        for h in ("heldout", "tuning"):
            for name, q in (("tpu68", "cov68"), ("tpu95", "cov95")):
                rng = chance[h][name]["ranges"].get(key)
                if rng is None:
                    cells.append("-")
                    continue
                cov = s[h]["tpu"][q]
                mark = beyond_chance(cov, rng)
                beyond[h][name] += bool(mark)
                cells.append(
                    f"{_pct(cov)} [{_pct(rng[0])}-{_pct(rng[1])}]"
                    + (f" **{mark}**" if mark else "")
                )
        if any(c != "-" for c in cells):
            lines.append(_row([f"{key[0]}: {key[1]}", *cells]))
    return lines, beyond


def shared_chance(chance: dict[str, dict[str, dict[str, float]]]) -> str:
    """The sentence on the TPU floors' chance with the shared terms drawn once per scene."""

    def half(h: str) -> str:
        return ", ".join(
            f"{k} {v['mean']:.1f} ({v['p10']:.0f}-{v['p90']:.0f}) of {v['strata']}"
            for k, v in chance[h].items()
        )

    return (
        ": with the TPU's own terms as the truth's model, those shared by a scene (navigation,"
        " attitude, heading, forward scattering, temperature, salinity) drawn once per scene"
        " and the rest per point (`pipeline/suite/chance_tpu.py`), a TPU exactly right would"
        f" fail on average {half('heldout')} held-out strata (10-90 % of the simulated suites"
        f" in brackets; tuning: {half('tuning')})."
    )


def chance_section(strata, chance) -> list[str]:
    """The TPU floors judged against chance stratum by stratum (:func:`_chance_table`)."""
    table, beyond = _chance_table(strata, chance)

    def counts(h: str) -> str:
        return ", ".join(f"{k} {beyond[h][k]} of {chance[h][k]['strata']}" for k in beyond[h])

    return [
        "## TPU coverage against chance, stratum by stratum",
        "",
        "The band of each TPU floor is narrower than the scatter of an exactly right TPU's"
        " coverage over a few scenes, its shared terms drawn once per scene. Per stratum, the"
        " range in brackets is where that TPU's coverage falls in 95 % of the simulated suites"
        " (2.5-97.5 %; `pipeline/suite/chance_tpu.py`, the TPU's own terms as the truth's"
        " model); **low** / **high**: the observed coverage lies outside it, a miscalibration"
        " the shared draws do not explain (low: the TPU too small). The model leans favourable"
        " (terms it draws per point are partly shared), so its ranges are, if anything, too"
        f" narrow. Beyond chance: held-out {counts('heldout')}; tuning {counts('tuning')}.",
        "",
        *table,
        "",
    ]
