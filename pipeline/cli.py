"""The ``bathy`` command line: ``run [SCENE] [--out DIR]``, ``validate``, ``plan``, ``keys``."""

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
    pl = sub.add_parser("plan", help="the stages a scene runs, and why the others are left out")
    pl.add_argument("scene", nargs="?", help="scene TOML file (default: built-in scene)")
    sub.add_parser("keys", help="list every scene key with its default, unit and bounds")
    return p


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
