"""Atomic file writing: a file is either complete or absent, never half-written.

Even a SIGKILL (or a power cut) leaves nothing behind: on Linux the data go into an anonymous
file (``O_TMPFILE``: an inode without a name, freed by the kernel when the process dies) that
only gets a name once it is complete, by ``linkat`` straight onto the target when there is none,
otherwise onto a hidden unique name that ``os.replace`` moves onto the target at once (a window
of microseconds between two system calls). Writers that need a path get ``/proc/self/fd/N``,
which reopens that anonymous file. The output's folder is made only when its first file is
complete, so a run killed before any output leaves no folder either.

Where ``O_TMPFILE`` or ``/proc`` is missing (other systems, some network filesystems) the
writer falls back to a hidden temporary file beside the target, renamed on success and removed
on an exception; only there can a SIGKILL leave a ``.<name>.*.tmp`` file behind.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import secrets
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["atomic_path", "write_json"]

_PROC_FD = Path("/proc/self/fd")
# errors that mean "this filesystem or kernel has no O_TMPFILE", not "you may not write here"
_NO_TMPFILE = {errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL, errno.ENOENT}


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; it becomes ``path`` only when the block succeeds.

    The yielded path may be opened (and truncated) any number of times by any writer; its
    suffix is not ``path``'s, so give writers the format explicitly. The file gets the mode a
    plain ``open()`` would give it (``0o666`` less the umask). Missing parent folders are
    made when the file is complete.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_path(d / "new" / "a.txt") as tmp:
    ...     _ = tmp.write_text("done")
    ...     (d / "new").exists()  # nothing there until the file is complete
    False
    >>> (d / "new" / "a.txt").read_text()
    'done'
    """
    path = Path(path)
    fd = _anonymous_file(path.parent)
    if fd is None:
        with _beside(path) as tmp:
            yield tmp
        return
    try:
        yield _PROC_FD / str(fd)
        os.fsync(fd)  # complete on disk before it has a name: a power cut cannot half-write it
        path.parent.mkdir(parents=True, exist_ok=True)
        _link_onto(fd, path)
    finally:
        os.close(fd)


def _anonymous_file(folder: Path) -> int | None:
    """An ``O_TMPFILE`` descriptor on ``folder``'s filesystem, or None where there is none.

    The file is made in the nearest existing ancestor of ``folder`` (the folders still to be
    made will be on the same filesystem), so nothing is created before the file is complete.
    """
    if not hasattr(os, "O_TMPFILE") or not _PROC_FD.is_dir():
        return None
    anchor = folder.absolute()
    while not anchor.is_dir() and anchor != anchor.parent:
        anchor = anchor.parent
    try:
        # the mode less the umask, as a plain open() would create it
        return os.open(anchor, os.O_TMPFILE | os.O_RDWR | os.O_CLOEXEC, 0o666)
    except OSError as exc:
        if exc.errno in _NO_TMPFILE:
            return None
        raise


def _link_onto(fd: int, path: Path) -> None:
    """Give the anonymous file ``fd`` the name ``path``, replacing any file there atomically."""
    proc = os.open(_PROC_FD, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        # linkat(AT_SYMLINK_FOLLOW) on /proc/self/fd/N names the open file itself (a plain
        # link() would try to link the magic symlink); src_dir_fd makes os.link use linkat
        def link(dst: Path) -> None:
            os.link(str(fd), dst, src_dir_fd=proc, follow_symlinks=True)

        try:
            link(path)  # no file there yet: it appears complete in one step
            return
        except FileExistsError:
            pass
        hidden = path.with_name(f".{path.name}.{secrets.token_hex(8)}.tmp")
        link(hidden)
        try:
            os.replace(hidden, path)
        except BaseException:
            hidden.unlink(missing_ok=True)
            raise
    finally:
        os.close(proc)


@contextlib.contextmanager
def _beside(path: Path) -> Iterator[Path]:
    """The fallback: a hidden temporary file beside ``path``, renamed onto it on success."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        # mkstemp makes the file 0600; an output gets the mode a plain open() would give it
        os.chmod(tmp, 0o666 & ~_current_umask())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _current_umask() -> int:
    """The process's umask (os has no getter: set and restore it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_json(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(
            json.dumps(data, indent=2, sort_keys=False, allow_nan=False) + "\n", encoding="utf-8"
        )
