"""Shared fixtures: scene paths and loaded scenes."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REFERENCE_SCENE = ROOT / "data_synthetic" / "scenes" / "reference_profiler.toml"


@pytest.fixture(scope="session")
def reference_scene():
    from pipeline.scene import load_scene

    return load_scene(REFERENCE_SCENE)
