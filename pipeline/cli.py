"""The ``bathy`` command line: ``run``, ``validate``, ``plan``, ``keys``, ``stress``, ``suite``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pipeline.errors import BathyError, SceneError

EXIT_BAD_SCENE = 2


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bathy", description="Open survey pipeline for airborne bathymetric lidar."
    )
    p.add_argument("--version", action="store_true", help="print the version and commit")
    sub = p.add_subparsers(dest="command")
    run = sub.add_parser("run", help="run a scene end to end (the built-in default if none)")
    run.add_argument("scene", nargs="?", help="scene TOML file (default: built-in scene)")
    run.add_argument("--out", default=None, help="output folder (default: out/<scene name>)")
    run.add_argument(
        "--overwrite", action="store_true", help="replace the outputs already in the folder"
    )
    run.add_argument("--quiet", action="store_true", help="no progress, only errors")
    run.add_argument(
        "--json", action="store_true", help="a machine-readable summary on stdout (log on stderr)"
    )
    val = sub.add_parser("validate", help="check a scene file; exit 2 if it is invalid")
    val.add_argument("scene", help="scene TOML file")
    pl = sub.add_parser("plan", help="the stages a scene runs, and why the others are left out")
    pl.add_argument("scene", nargs="?", help="scene TOML file (default: built-in scene)")
    sub.add_parser("keys", help="list every scene key with its default, unit and bounds")
    st = sub.add_parser("stress", help="run the extreme-case suite; exit 1 if a case fails")
    st.add_argument("--out", default="out/stress", help="output folder, one subfolder per case")
    st.add_argument("--only", nargs="+", default=[], metavar="NAME", help="run these cases")
    st.add_argument("--fast", action="store_true", help="only the fast subset")
    su = sub.add_parser(
        "suite", help="random scenes (tuning and held-out halves), strata and floors"
    )
    su.add_argument("--n", type=int, default=40, help="number of scenes (default 40)")
    su.add_argument("--half", choices=("tuning", "heldout", "both"), default="both")
    su.add_argument("--subset", choices=("ci",), default=None, help="the fixed CI subset")
    su.add_argument("--out", default="out/suite", help="folder of scenes, runs and tables")
    su.add_argument("--workers", type=int, default=1, help="scenes run side by side")
    su.add_argument("--results", default=None, help="Markdown path (default OUT/RESULTS_suite.md)")
    su.add_argument("--reuse", action="store_true", help="keep earlier runs of identical scenes")
    su.add_argument("--start", type=int, default=0, help="first seed looked at")
    return p


def _stress(args) -> int:
    """``bathy stress``: one line per case; 1 if any case fails (a known failure does not)."""
    from pipeline.stress import run_cases, select_cases

    try:
        cases = select_cases(args.only, args.fast)
    except ValueError as exc:
        print(f"bathy stress: {exc}", file=sys.stderr)
        return EXIT_BAD_SCENE
    print(f"bathy stress: {len(cases)} cases -> {args.out}")
    results = run_cases(cases, args.out, cli_main=main)
    counts = {k: sum(r.status == k for r in results) for k in ("PASS", "KNOWN", "FAIL")}
    print(f"{counts['PASS']} passed, {counts['KNOWN']} known failures, {counts['FAIL']} failed")
    return 1 if counts["FAIL"] else 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``bathy`` console script; returns the exit status."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.version:
        from pipeline.provenance import commit, version

        print(f"bathy {version()} (commit {commit() or 'unknown'})")
        return 0
    if args.command is None:
        parser.print_usage(sys.stderr)
        print(
            "bathy: a command is required (run, validate, plan, keys, stress, suite)",
            file=sys.stderr,
        )
        return EXIT_BAD_SCENE
    # imported late so `bathy --help` stays fast
    from pipeline.scene import DEFAULT_SCENE_PATH, Scene, load_scene

    try:
        if args.command == "keys":
            from pipeline.config import describe

            print("\n".join(describe(Scene)))
            return 0
        if args.command == "stress":
            return _stress(args)
        if args.command == "suite":
            from pipeline.suite.main import suite

            return suite(
                args.n,
                args.half,
                args.subset,
                args.out,
                args.workers,
                args.results,
                args.reuse,
                args.start,
            )
        path = Path(args.scene) if getattr(args, "scene", None) else DEFAULT_SCENE_PATH
        scene = load_scene(path)
        if args.command == "validate":
            print(f"{path}: valid scene '{scene.scene.name}'")
            return 0
        if args.command == "plan":
            from pipeline.stages import plan

            print(f"bathy plan {path}: scene '{scene.scene.name}'")
            print("\n".join(plan(scene).lines()))
            return 0
        from pipeline.run import clear_outputs, existing_outputs, run_scene

        out = Path(args.out) if args.out else Path("out") / scene.scene.name
        old = existing_outputs(out)
        if old and not args.overwrite:
            raise SceneError(
                f"output folder {out} already holds outputs ({', '.join(old)}); give"
                " --overwrite to replace them, or another --out"
            )
        clear_outputs(out)
        stream = sys.stderr if args.json else sys.stdout

        def log(line: str) -> None:
            if not args.quiet:
                print(line, file=stream, flush=True)

        log(f"bathy run {path} -> {out}")
        manifest = run_scene(scene, out, log=log, progress=not args.quiet)
        if args.json:
            print(json.dumps(_summary(out, manifest), indent=2))
        return 0
    except SceneError as exc:
        print(f"bathy: invalid scene: {exc}", file=sys.stderr)
        return EXIT_BAD_SCENE
    except BathyError as exc:
        print(f"bathy: {exc}", file=sys.stderr)
        return 1


def _summary(out: Path, manifest: dict) -> dict:
    """The ``--json`` summary: where the outputs are and the headline figures."""
    ev = manifest.get("evaluation") or {}
    err = ev.get("error") or {}
    cov = ev.get("tpu_coverage_against_truth") or {}
    return {
        "out": str(out),
        "files": manifest["files"],
        "stages": [s["stage"] for s in manifest["plan"] if s["runs"]],
        "pulses": ev.get("pulses"),
        "points_bias_m": (err.get("points") or {}).get("bias_m"),
        "points_rmse_m": (err.get("points") or {}).get("rmse_m"),
        "grid_rmse_m": (err.get("grid") or {}).get("rmse_m"),
        "tpu_within_95": cov.get("fraction_within"),
        "provenance": manifest["provenance"],
    }


if __name__ == "__main__":
    sys.exit(main())
