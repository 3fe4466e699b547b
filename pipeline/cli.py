"""The ``bathy`` command line: ``run``, ``validate``, ``keys`` and ``stress`` (extreme cases)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.errors import BathyError, SceneError

EXIT_BAD_SCENE = 2


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bathy", description="Open survey pipeline for airborne bathymetric lidar."
    )
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scene end to end (the built-in default if none)")
    run.add_argument("scene", nargs="?", help="scene TOML file (default: built-in scene)")
    run.add_argument("--out", default=None, help="output folder (default: out/<scene name>)")
    val = sub.add_parser("validate", help="check a scene file; exit 2 if it is invalid")
    val.add_argument("scene", help="scene TOML file")
    sub.add_parser("keys", help="list every scene key with its default, unit and bounds")
    st = sub.add_parser("stress", help="run the extreme-case suite; exit 1 if a case fails")
    st.add_argument("--out", default="out/stress", help="output folder, one subfolder per case")
    st.add_argument("--only", nargs="+", default=[], metavar="NAME", help="run these cases")
    st.add_argument("--fast", action="store_true", help="only the fast subset")
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
    results = run_cases(cases, args.out)
    counts = {k: sum(r.status == k for r in results) for k in ("PASS", "KNOWN", "FAIL")}
    print(f"{counts['PASS']} passed, {counts['KNOWN']} known failures, {counts['FAIL']} failed")
    return 1 if counts["FAIL"] else 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``bathy`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
    # imported late so `bathy --help` stays fast
    from pipeline.scene import DEFAULT_SCENE_PATH, Scene, load_scene

    try:
        if args.command == "keys":
            from pipeline.config import describe

            print("\n".join(describe(Scene)))
            return 0
        if args.command == "stress":
            return _stress(args)
        path = Path(args.scene) if getattr(args, "scene", None) else DEFAULT_SCENE_PATH
        scene = load_scene(path)
        if args.command == "validate":
            print(f"{path}: valid scene '{scene.scene.name}'")
            return 0
        from pipeline.run import run_scene

        out = Path(args.out) if args.out else Path("out") / scene.scene.name
        print(f"bathy run {path} -> {out}")
        run_scene(scene, out)
        return 0
    except SceneError as exc:
        print(f"bathy: invalid scene: {exc}", file=sys.stderr)
        return EXIT_BAD_SCENE
    except BathyError as exc:
        print(f"bathy: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
