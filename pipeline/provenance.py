"""What made a run: the bathy version and commit, every library's version, a hash of the inputs.

Recorded in ``manifest.json`` so that a result can be traced to the code and the inputs that
made it, and printed by ``bathy --version``.
"""

from __future__ import annotations

import hashlib
import json
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = ["version", "commit", "library_versions", "inputs_sha256", "provenance"]

#: Distributions whose versions a run records (looked up, never imported: a run without
#: posteriors does not import emcee just to name its version).
LIBRARIES = (
    "numpy",
    "scipy",
    "open3d-cpu",
    "trimesh",
    "laspy",
    "lazrs",
    "rasterio",
    "pyproj",
    "emcee",
    "matplotlib",
)


def version() -> str:
    """The installed bathy version (``0+unknown`` when run from a tree that is not installed)."""
    try:
        return metadata.version("bathy-pipeline")
    except metadata.PackageNotFoundError:
        return "0+unknown"


def commit() -> str | None:
    """The source tree's git commit (``+dirty`` with uncommitted changes); None outside git."""
    root = Path(__file__).resolve().parents[1]
    try:
        sha = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return sha + ("+dirty" if dirty else "") if sha else None


def library_versions() -> dict[str, str | None]:
    """Versions of Python, the libraries of :data:`LIBRARIES`, and GDAL and PROJ when present."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    try:  # the C libraries inside the wheels (rasterio and pyproj are imported by a run anyway)
        import pyproj
        import rasterio

        out["gdal"] = rasterio.__gdal_version__
        out["proj"] = pyproj.proj_version_str
    except ImportError:
        pass
    return out


def inputs_sha256(scene_dict: dict[str, Any], files: list[str | Path] = ()) -> str:
    """SHA-256 of the validated scene (canonical JSON) and of every input file's bytes."""
    h = hashlib.sha256(json.dumps(scene_dict, sort_keys=True, default=str).encode())
    for f in files:
        h.update(Path(f).read_bytes())
    return h.hexdigest()


def provenance(scene) -> dict[str, Any]:
    """The manifest's ``provenance`` block for ``scene``."""
    files = [scene.seabed.dem_path] if scene.seabed.kind == "dem" else []
    return {
        "bathy_version": version(),
        "commit": commit(),
        "libraries": library_versions(),
        "inputs_sha256": inputs_sha256(scene.to_dict(), files),
    }
