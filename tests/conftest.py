"""Shared fixtures: scene paths and loaded scenes; a cache folder of the session's own."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REFERENCE_SCENE = ROOT / "data_synthetic" / "scenes" / "reference_profiler.toml"


@pytest.fixture(scope="session")
def reference_scene():
    from pipeline.scene import load_scene

    return load_scene(REFERENCE_SCENE)


@pytest.fixture(scope="session", autouse=True)
def _own_cache_dir(tmp_path_factory):
    """The forward-scattering tables' cache (``BATHY_CACHE_DIR``) in a folder of this session:
    the tests trace them once and never read a developer's (possibly stale) cache; the `bathy
    run` subprocesses inherit the folder."""
    before = os.environ.get("BATHY_CACHE_DIR")
    os.environ["BATHY_CACHE_DIR"] = str(tmp_path_factory.mktemp("bathy_cache"))
    yield
    if before is None:
        os.environ.pop("BATHY_CACHE_DIR", None)
    else:
        os.environ["BATHY_CACHE_DIR"] = before
