"""Tables that are constants of the code, computed once per machine and kept on disk.

Some tables cost seconds and depend on nothing a run sets: the forward-scattering tables (a
photon tracing, :mod:`pipeline.forward_scatter_mc`), the detector's peak shift on skewed
echoes (:mod:`pipeline.process.scatter_bias`). Every process of every run computed them again
(each pool worker too). :func:`cached_table` keeps them in :func:`cache_dir`, under a name made
of what determines them:

* :func:`code_key`: the sources that compute them, hashed once at import (an edit after
  import must not store the old code's table under the new sources' name), numpy's and
  scipy's versions, the machine and the CPU features numpy's loops dispatch on (SIMD ``exp``
  and ``log`` may differ in the last bit between instruction sets, in a shared folder);
* the table's own parameters (their ``repr``).

A read that fails in any way (a missing, empty, foreign or damaged file, no home folder)
computes; a write that fails (a read-only home) only costs the time. Files appear whole or not
at all (:func:`~pipeline.outputs.atomic.atomic_path`): processes racing to store one store the
same bytes. Old files are never removed; deleting the folder is always safe.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import platform
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from pipeline.outputs.atomic import atomic_path

__all__ = ["cache_dir", "code_key", "cached_table"]


def cache_dir() -> Path:
    """Folder of the cached tables.

    ``$BATHY_CACHE_DIR``, else ``$XDG_CACHE_HOME/bathy``, else ``~/.cache/bathy``.
    """
    if os.environ.get("BATHY_CACHE_DIR"):
        return Path(os.environ["BATHY_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "bathy"


def code_key(sources: Iterable[str | Path]) -> str | None:
    """Hash of ``sources`` (files, or folders: their ``*.py``) and of the platform.

    Call at import, so the hash is of the code that runs. None when a source cannot be read
    (an install without sources): nothing is then cached.
    """
    import scipy

    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # another numpy layout: the versions and the machine still key it
        features = {}
    key = hashlib.sha256(f"{np.__version__} {scipy.__version__} {platform.machine()}".encode())
    key.update(" ".join(sorted(k for k, on in features.items() if on)).encode())
    try:
        for src in sources:
            src = Path(src)
            for path in sorted(src.glob("*.py")) if src.is_dir() else [src]:
                key.update(path.name.encode())
                key.update(path.read_bytes())
    except OSError:
        return None
    return key.hexdigest()[:24]


def cached_table(
    name: str, params: str, key: str | None, make: Callable[[], np.ndarray], shape: tuple
) -> np.ndarray:
    """``make()``'s float64 array of ``shape``, from the cache when there, else made and kept.

    ``name`` and ``params`` (the table's own parameters) name the file with ``key``
    (:func:`code_key`; None: made, not stored). See the module notes.
    """
    path = None
    if key is not None:
        try:
            digest = hashlib.sha256(f"{key} {params}".encode()).hexdigest()[:24]
            path = cache_dir() / f"{name}_{digest}.npy"
            table = np.load(path, allow_pickle=False)
            if (
                isinstance(table, np.ndarray)
                and table.dtype == np.float64
                and table.shape == tuple(shape)
            ):
                return table
        except Exception:  # any unreadable cache is made again
            pass
    table = np.asarray(make(), dtype=np.float64)
    if path is not None:
        with contextlib.suppress(OSError):
            with atomic_path(path) as tmp, open(tmp, "wb") as f:
                np.save(f, table, allow_pickle=False)
    return table
