"""numba's cache folder follows the kernels' sources (pipeline.kernel_cache)."""

import os
import subprocess
import sys

from pipeline.kernel_cache import kernel_key, kernel_sources
from tests.conftest import ROOT


def test_the_key_follows_the_kernel_modules_and_the_constants_only(tmp_path):
    (tmp_path / "sub").mkdir()
    kernel = tmp_path / "sub" / "kern.py"
    kernel.write_text("import numba\n\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1\n")
    caller = tmp_path / "caller.py"
    caller.write_text("import numba\nfrom sub.kern import f\n")
    plain = tmp_path / "plain.py"
    plain.write_text("X = 1\n")
    constants = tmp_path / "constants.py"
    constants.write_text("MAD_TO_SIGMA = 1.4826\n")
    assert kernel_sources(tmp_path) == [caller, constants, kernel]
    before = kernel_key(tmp_path)
    plain.write_text("X = 2\n")  # no kernel reads it: the compiled code cannot be stale
    assert kernel_key(tmp_path) == before
    # the callee alone changes: numba's own per-file key would keep the caller's old build
    kernel.write_text(kernel.read_text().replace("x + 1", "x + 2"))
    changed = kernel_key(tmp_path)
    assert changed != before
    constants.write_text("MAD_TO_SIGMA = 1.5\n")
    assert kernel_key(tmp_path) not in (before, changed)


def _cache_dir_seen(env):
    code = "import pipeline, os, numba; print(os.environ['NUMBA_CACHE_DIR'])\n"
    code += "print(numba.config.CACHE_DIR)"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True, check=True
    )
    return out.stdout.split()


def test_importing_the_package_points_numba_at_this_versions_folder(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(BATHY_CACHE_DIR=str(tmp_path), PYTHONPATH=str(ROOT))
    want = str(tmp_path / "numba" / kernel_key())
    assert _cache_dir_seen(env) == [want, want]
    # a user's own folder wins
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    assert _cache_dir_seen(env) == [str(tmp_path / "mine")] * 2
