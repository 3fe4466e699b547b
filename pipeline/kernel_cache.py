"""Where numba keeps the compiled kernels: one folder per version of the kernels' sources.

numba keys a cached kernel by its own source file alone (its date and size). A kernel that
calls a kernel of another module (``pipeline.process.row_kernels.pairwise_sum``, the
posterior's compiled model), or that compiles in another module's constant, is therefore not
compiled again when only that other file changes: after an update it would keep running the
old code, silently. So the cache lives in ``<cache_dir>/numba/<key>``
(:func:`~pipeline.table_cache.cache_dir`), ``key`` a hash of every module of the package that
uses numba and of :mod:`pipeline.constants` (:func:`kernel_sources`): any edit to them starts a
fresh folder, and every kernel is compiled once more. A user's ``NUMBA_CACHE_DIR`` wins. Old
folders are not removed; deleting them is always safe.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["kernel_sources", "kernel_key", "use_kernel_cache"]

_PACKAGE = Path(__file__).resolve().parent


def kernel_sources(root: Path = _PACKAGE) -> list[Path]:
    """The modules under ``root`` whose text names numba, and ``constants.py``; sorted."""
    found = []
    for path in sorted(root.rglob("*.py")):
        try:
            if path.name == "constants.py" or b"numba" in path.read_bytes():
                found.append(path)
        except OSError:
            continue
    return found


def kernel_key(root: Path = _PACKAGE) -> str | None:
    """:func:`~pipeline.table_cache.code_key` of :func:`kernel_sources` (None: one unreadable).

    The tables' key: the sources' bytes, numpy's and scipy's versions, the machine and its
    CPU features (compiled code is the machine's too).
    """
    from pipeline.table_cache import code_key

    return code_key(kernel_sources(root))


def use_kernel_cache() -> Path | None:
    """Point numba's cache at this version's folder (module notes); the folder, or None.

    Nothing changes when ``NUMBA_CACHE_DIR`` is set or the folder cannot be made (numba then
    keeps its default, beside the sources).
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    from pipeline.table_cache import cache_dir

    key = kernel_key()
    if key is None:
        return None
    try:
        folder = cache_dir() / "numba" / key
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    # the environment for the processes this one starts (pool workers read it when they
    # import numba), and numba's own setting if it is already imported here (a kernel's cache
    # takes its folder when the kernel is defined)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    numba = sys.modules.get("numba")
    if numba is not None:
        numba.config.CACHE_DIR = str(folder)
    return folder
