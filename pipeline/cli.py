"""The ``bathy`` command line: run, validate, plan, keys, stress, view, sweep, suite."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pipeline.errors import BathyError, SceneError

EXIT_BAD_SCENE = 2


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1; got {value}")
    return value


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
    run.add_argument(
        "--workers",
        type=_positive_int,
        default=None,
        metavar="N",
        help="processes for the simulate + detect chunks (default: every core; 1: no pool)",
    )
    run.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the chunks on this Dask distributed scheduler (e.g. tcp://host:8786)",
    )
    val = sub.add_parser("validate", help="check a scene file; exit 2 if it is invalid")
    val.add_argument("scene", help="scene TOML file")
    pl = sub.add_parser("plan", help="the stages a scene runs, and why the others are left out")
    pl.add_argument("scene", nargs="?", help="scene TOML file (default: built-in scene)")
    sub.add_parser("keys", help="list every scene key with its default, unit and bounds")
    vw = sub.add_parser("view", help="a finished run's 3D scene (view/*.vtp) in a window")
    vw.add_argument("out", help="the run's output folder")
    vw.add_argument(
        "--color",
        default="error",
        choices=["error", "tpu", "depth", "class"],
        help="colour the points by depth error (default), TPU, depth or class",
    )
    vw.add_argument(
        "--screenshot",
        default=None,
        metavar="FILE",
        help="render off-screen to this PNG instead of a window (the default without a display)",
    )
    st = sub.add_parser("stress", help="run the extreme-case suite; exit 1 if a case fails")
    st.add_argument("--out", default="out/stress", help="output folder, one subfolder per case")
    st.add_argument("--only", nargs="+", default=[], metavar="NAME", help="run these cases")
    st.add_argument("--fast", action="store_true", help="only the fast subset")
    sw = sub.add_parser(
        "sweep", help="error against CPU time over the scene's fidelity knobs, one at a time"
    )
    sw.add_argument("scene", nargs="?", help="scene TOML file (default: built-in scene)")
    sw.add_argument("--out", default=None, help="output folder (default: out/<scene name>/sweep)")
    sw.add_argument(
        "--knobs",
        nargs="+",
        default=None,
        metavar="KEY",
        help="scene keys to vary (default: the built-in knobs; with --levels only: its keys)",
    )
    sw.add_argument(
        "--levels",
        nargs="+",
        default=[],
        metavar="KEY=V1,V2",
        help="levels of a knob, replacing its default multiples of the scene's value",
    )
    sw.add_argument(
        "--repeats",
        type=int,
        default=1,
        metavar="N",
        help="run each point N times and keep its least CPU time (a shared machine's clock)",
    )
    sw.add_argument(
        "--overwrite", action="store_true", help="replace a sweep already in the folder"
    )
    sw.add_argument("--quiet", action="store_true", help="no progress, only errors")
    su = sub.add_parser(
        "suite", help="random scenes (tuning and held-out halves), strata and floors"
    )
    su.add_argument("--n", type=int, default=40, help="number of scenes (default 40)")
    su.add_argument("--half", choices=("tuning", "heldout", "both"), default="both")
    su.add_argument(
        "--subset",
        choices=("ci", "shallow", "cubes"),
        default=None,
        help="a fixed subset: ci (the CI's eight), shallow (shoals per receiver, calm and 5 m/s),"
        " cubes (IHO cubes by the dozen)",
    )
    su.add_argument("--out", default="out/suite", help="folder of scenes, runs and tables")
    su.add_argument("--workers", type=int, default=1, help="scenes run side by side")
    su.add_argument("--results", default=None, help="Markdown path (default OUT/RESULTS_suite.md)")
    su.add_argument("--reuse", action="store_true", help="keep earlier runs of identical scenes")
    su.add_argument("--start", type=int, default=0, help="first seed looked at")
    return p


def _sweep(args, path: Path) -> int:
    """``bathy sweep``: validate the whole design first (exit 2 on a bad knob or level)."""
    from pipeline.sweep import DEFAULT_KNOBS, parse_levels, read_scene_data, run_sweep

    def log(line: str) -> None:
        if not args.quiet:
            print(line, flush=True)

    try:
        levels = parse_levels(args.levels)
        knobs = args.knobs if args.knobs is not None else ([] if levels else list(DEFAULT_KNOBS))
        name = (read_scene_data(path).get("scene") or {}).get("name", "scene")
        out = Path(args.out) if args.out else Path("out") / str(name) / "sweep"
        if args.repeats < 1:
            raise SceneError(f"--repeats must be >= 1; got {args.repeats}")
        if (out / "sweep.csv").exists() and not args.overwrite:
            raise SceneError(
                f"output folder {out} already holds a sweep (sweep.csv); give --overwrite to"
                " replace it, or another --out"
            )
        run_sweep(path, out, knobs, levels, log=log, repeats=args.repeats)
    except SceneError as exc:
        print(f"bathy sweep: {exc}", file=sys.stderr)
        return EXIT_BAD_SCENE
    return 0


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


def _view(args) -> int:
    """``bathy view OUT``: reads the run's written files only (view/*.vtp)."""
    from pipeline.outputs.view3d import view_folder

    try:
        shot = view_folder(Path(args.out), args.color, args.screenshot and Path(args.screenshot))
    except FileNotFoundError as exc:
        raise BathyError(str(exc)) from exc
    if shot is not None:
        print(f"bathy view: wrote {shot}")
    return 0


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
            "bathy: a command is required (run, validate, plan, keys, stress, view, sweep, suite)",
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
        if args.command == "view":
            return _view(args)
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
        if args.command == "sweep":
            return _sweep(args, path)
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
        manifest = run_scene(
            scene,
            out,
            log=log,
            progress=not args.quiet,
            workers=args.workers,
            scheduler=args.scheduler,
        )
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
