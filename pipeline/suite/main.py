"""``bathy suite``: draw the scenes, run them, pool the strata, write the results."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from pipeline.suite.chance_tpu import simulated_tpu_failures
from pipeline.suite.cubes import cube_draws
from pipeline.suite.generate import ci_draws, draw, suite_seeds
from pipeline.suite.report import write_csv, write_markdown
from pipeline.suite.run import collect, run_suite
from pipeline.suite.shallow import shallow_draws
from pipeline.suite.strata import all_strata, pool_rows

__all__ = ["suite"]

_PREFACE = (
    "Random scenes over the conditions users fly (`pipeline/suite/generate.py`), split once"
    " by a hash of the seed into a tuning and a held-out half. **No threshold, constant or"
    " model choice may be tuned on the held-out half.**"
)


def suite(
    n: int = 40,
    which: str = "both",
    subset: str | None = None,
    out: str | Path = "out/suite",
    workers: int = 1,
    results: str | Path | None = None,
    reuse: bool = False,
    start: int = 0,
    log=print,
) -> int:
    """Run the suite and write ``suite.csv`` and the results Markdown; return an exit status.

    Parameters
    ----------
    n : int
        Scenes (ignored with a ``subset``).
    which : {"tuning", "heldout", "both"}
        Half to draw from.
    subset : {None, "ci", "shallow", "cubes"}
        ``ci``: the fixed CI subset (:data:`pipeline.suite.generate.CI_SCENES`); ``shallow``:
        the shoal subset (:mod:`pipeline.suite.shallow`); ``cubes``: the cube subset
        (:mod:`pipeline.suite.cubes`).
    out : path
        Folder of the scenes and the runs (and by default of the results).
    workers : int
        Scenes run side by side.
    results : path, optional
        Where to write the Markdown (default ``out/RESULTS_suite.md``); ``suite.csv`` goes
        beside it.
    reuse : bool
        Keep earlier successful runs of identical scenes in ``out``.
    start : int
        First seed looked at.

    Returns
    -------
    int
        0 when every scene ran (the floors do not set it: they are reported), 1 otherwise.
    """
    out = Path(out)
    if subset is not None:
        draws = {"ci": ci_draws, "shallow": shallow_draws, "cubes": cube_draws}[subset]()
        if which != "both":
            draws = [d for d in draws if d.half == which]
    else:
        draws = [draw(s) for s in suite_seeds(n, which, start)]
    log(f"bathy suite: {len(draws)} scenes -> {out}")
    res = run_suite(draws, out, workers=workers, log=log, reuse=reuse)
    rows = collect(res)
    failed = [r.draw.seed for r in res if not r.ok]
    if not rows:
        log("bathy suite: no scene ran")
        return 1
    pool = pool_rows(rows)
    strata = all_strata(pool)
    # a TPU exactly right, its shared terms one draw per scene: ~1 s per simulated suite
    chance = {h: simulated_tpu_failures(pool, rows, h, n_rep=100) for h in ("tuning", "heldout")}
    md_path = Path(results) if results else out / "RESULTS_suite.md"
    csv_path = write_csv(md_path.with_name("suite.csv"), strata)
    command = "bathy " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    md = write_markdown(
        md_path,
        command,
        pool,
        strata,
        [(r["wall_s"], r["cpu_s"]) for r in rows],
        failed,
        preface=_PREFACE,
        tpu_chance=chance,
    )
    log(f"bathy suite: wrote {csv_path} and {md}")
    return 1 if failed else 0
