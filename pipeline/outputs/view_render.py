"""A run's 3D views: ``view/*.vtp`` written, and the report's pictures rendered by a child.

:func:`write_views` makes the meshes (:mod:`pipeline.outputs.view3d`) and writes them;
:func:`render_pictures` runs :func:`main` in a child interpreter, which renders each of
:data:`~pipeline.outputs.view3d.REPORT_VIEWS` from the meshes written and writes them as
``OUT_DIR/0.png``, ``OUT_DIR/1.png``, ... (each atomically), and reads them back.

Why a child: the OpenGL stack (Mesa's llvmpipe) takes ~300 MiB whatever is drawn, 160 of
which its heap keeps after the window is closed, and a driver that crashes ends the process
it runs in. In a child it costs the run neither that memory (the survey's arrays stay in the
parent, beside nothing) nor, on a crash, more than the pictures. A plain interpreter, not a
``multiprocessing`` one: a spawned process would run again the main script of whoever called
``run_scene`` without an ``if __name__ == "__main__"`` guard. The child reads the files just
written: VTK's XML keeps every float64 exactly, so the pictures are those of the meshes.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from pipeline.outputs import view3d as V

__all__ = ["write_views", "render_pictures", "main"]

#: Seconds a render may take before the pictures are given up (two pictures take ~2-5 s).
TIMEOUT_S = 600.0


def render_pictures(folder: Path, timeout_s: float = TIMEOUT_S) -> list[tuple[bytes, str]]:
    """The report's pictures (png bytes, alt text) of the ``.vtp`` files in ``folder``.

    Raises
    ------
    RuntimeError
        The child failed (its last line of error), crashed (the signal) or timed out.
    """
    # the parent's own `pipeline` (a source tree, or site-packages when installed), whatever
    # the path holds (a relative PYTHONPATH entry, or the current directory without -P, could
    # name another checkout): imported from its folder, which then leaves the path, so that
    # the package's submodules come from it and nothing else is shadowed
    root = str(Path(__file__).resolve().parents[2])
    boot = (
        f"import sys; sys.path.insert(0, {root!r}); import pipeline; sys.path.pop(0); "
        "from pipeline.outputs.view_render import main; sys.exit(main(sys.argv[1:]))"
    )
    with tempfile.TemporaryDirectory(prefix="bathy_views_") as tmp:
        cmd = [sys.executable, "-P", "-c", boot, str(folder), tmp]
        try:
            done = subprocess.run(
                cmd, capture_output=True, text=True, errors="replace", timeout=timeout_s
            )
        except subprocess.TimeoutExpired as exc:
            raise RuntimeError(f"the pictures' render took more than {timeout_s:g} s") from exc
        if done.returncode != 0:
            lines = done.stderr.strip().splitlines()
            why = lines[-1] if lines else f"exit status {done.returncode}"
            if done.returncode < 0:
                why = f"the render process was killed by signal {-done.returncode}"
            raise RuntimeError(why)
        return [
            ((Path(tmp) / f"{i}.png").read_bytes(), alt)
            for i, (_, alt) in enumerate(V.REPORT_VIEWS)
        ]


def write_views(
    folder: Path, points, sim, origin_m, crs: str, log=print
) -> tuple[dict[str, Path], list[tuple[bytes, str]]]:
    """Write ``folder/*.vtp`` and render the report's pictures of a run; never raises.

    The scene is :func:`pipeline.outputs.view_scene.view_scene` of the processed ``points``
    and ``sim`` (its detections, and its truth: this runs on the evaluation side). A failure
    (no pyvista, no OpenGL, a writer error, the render child's failure) costs only the 3D
    views: one warning line in the log, and the files written before it are kept; the
    pictures come all or none (one child renders them).

    Returns
    -------
    files : dict of str to Path
        The ``.vtp`` files written, by mesh name.
    images : list of (png bytes, alt text)
    """
    from pipeline.outputs.view_scene import view_scene

    files, images = {}, []
    try:
        scene = view_scene(points, sim.returns, sim.truth, origin_m, crs)
        files = V.write_vtp(V.meshes(scene), folder)
        del scene
        images = render_pictures(folder)
    except Exception as exc:  # noqa: BLE001 - any failure here must not end the run
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        log(
            f"  WARNING: 3D views incomplete ({len(files)} .vtp files, {len(images)} pictures):"
            f" {type(exc).__name__}: {msg}"
        )
    return files, images


def main(argv: list[str] | None = None) -> int:
    """Render the pictures of ``argv[0]``'s meshes into ``argv[1]`` (see the module notes)."""
    from pipeline.outputs.atomic import atomic_path

    folder, out = (sys.argv[1:] if argv is None else argv)[:2]
    mesh_by_name = V.read_vtp(Path(folder))
    for i, (color_by, _) in enumerate(V.REPORT_VIEWS):
        with atomic_path(Path(out) / f"{i}.png") as tmp:
            tmp.write_bytes(V.png_bytes(V.render(mesh_by_name, color_by)))
    return 0
