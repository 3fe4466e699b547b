"""Reading the chunk loop's detections back, in the run's process or in another one.

:class:`~pipeline.detection_store.DetectionStore` writes the detections; the reads are shared
with :class:`StoreReader`, which a worker of this machine receives pickled (the blocks of a
blocked survey, :mod:`pipeline.survey_block_task`) and which reads the same unnamed file
through the run's ``/proc/<pid>/fd/<n>``.
"""

from __future__ import annotations

import os
import threading
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.process.returns import DetectedReturns

__all__ = ["ChunkSummary", "StoreReader", "detected_returns", "file_identity"]


@dataclass(frozen=True)
class ChunkSummary:
    """What stays in memory of a spilled chunk.

    Attributes
    ----------
    index : int
        Chunk number (pulse order).
    n_pulses : int
    pulse_id_range : (int, int)
        First and last pulse id.
    bbox_m : (4,) float or None
        Local ``(xmin, xmax, ymin, ymax)`` of the chunk's pulse positions
        (:func:`pulse_position_m`); None when the chunk has no pulse.
    """

    index: int
    n_pulses: int
    pulse_id_range: tuple[int, int]
    bbox_m: np.ndarray | None


def _boot_id() -> str:
    try:
        with open("/proc/sys/kernel/random/boot_id", encoding="ascii") as f:
            return f.read().strip()
    except OSError:
        return ""


def file_identity(fd_or_path) -> tuple[int, int, str]:
    """``(st_dev, st_ino, boot id)`` of an open descriptor or a path.

    The same file only on the same running machine: a device and inode alone can repeat in
    look-alike containers.
    """
    st = os.fstat(fd_or_path) if isinstance(fd_or_path, int) else os.stat(fd_or_path)
    return st.st_dev, st.st_ino, _boot_id()


def _close_all(fds: list[int]) -> None:
    while fds:
        os.close(fds.pop())


class _ChunkReads:
    """Reading a store's chunks back: needs ``chunks``, ``_index`` and ``_fileno()``."""

    chunks: list[ChunkSummary]
    _index: list[dict[str, tuple[int, str, tuple[int, ...]]]]

    def _fileno(self) -> int:
        raise NotImplementedError

    def load_chunk(self, c: int, fields: list[str] | None = None) -> dict[str, np.ndarray]:
        """Fields of chunk ``c`` (all by default)."""
        out = {}
        for k in fields or list(self._index[c]):
            off, dtype, shape = self._index[c][k]
            n = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
            buf = os.pread(self._fileno(), n, off) if n else b""
            out[k] = np.frombuffer(buf, dtype=dtype).reshape(shape).copy()
        return out

    def load(self, chunks: list[int] | None = None) -> dict[str, np.ndarray]:
        """The fields of ``chunks`` (default: all) concatenated in pulse order."""
        idx = list(range(len(self.chunks)) if chunks is None else chunks)
        # filled chunk by chunk: the survey's arrays once, not beside a list of their parts
        n = sum(self._index[c]["pulse_id"][2][0] for c in idx)
        out = {}
        for k, (_, dtype, shape) in self._index[idx[0]].items():
            out[k] = np.empty((n, *shape[1:]), dtype=dtype)
        lo = 0
        for c in idx:
            part = self.load_chunk(c, list(out))
            m = len(part["pulse_id"])
            for k, v in part.items():
                out[k][lo : lo + m] = v
            lo += m
        return out

    def returns(self, chunks: list[int] | None = None) -> DetectedReturns:
        """The detections of ``chunks`` (default: all) as one DetectedReturns."""
        return detected_returns(self.load(chunks))


class StoreReader(_ChunkReads):
    """A :class:`DetectionStore`'s chunks, read by another process (:meth:`~DetectionStore.reader`).

    Pickled, it carries the file's path and the chunks' index, not an open file: the file is
    opened on first read, and must be the store's own (the same device and inode), so a
    process on another machine fails on its first read instead of reading another file.
    """

    def __init__(
        self,
        path: str,
        identity: tuple,
        air_index: float,
        chunks: list[ChunkSummary],
        index: list[dict[str, tuple[int, str, tuple[int, ...]]]],
    ) -> None:
        self.path, self.identity, self.air_index = path, tuple(identity), float(air_index)
        self.chunks, self._index = chunks, index
        self._setup()

    def _setup(self) -> None:
        self._fd: list[int] = []  # the open descriptor, once opened (shared with the finalizer)
        self._lock = threading.Lock()  # a Dask worker's threads share one reader
        self._closer = weakref.finalize(self, _close_all, self._fd)

    def __getstate__(self) -> dict[str, Any]:
        return {k: self.__dict__[k] for k in ("path", "identity", "air_index", "chunks", "_index")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._setup()

    def close(self) -> None:
        """Close the descriptor, if opened (reading again opens it again)."""
        with self._lock:
            _close_all(self._fd)

    def _fileno(self) -> int:
        with self._lock:
            if not self._fd:
                try:
                    fd = os.open(self.path, os.O_RDONLY)
                except OSError as exc:
                    raise OSError(
                        f"cannot open the run's detection store at {self.path} ({exc.strerror}):"
                        " a worker reads it through the run's process, which must be alive and"
                        " on this machine"
                    ) from None
                if file_identity(fd) != self.identity:
                    os.close(fd)
                    raise OSError(
                        f"{self.path} is not the detection store this reader was made for "
                        "(a process on another machine?)"
                    )
                self._fd.append(fd)
            return self._fd[0]

    @property
    def n_pulses(self) -> int:
        """Pulses stored."""
        return sum(c.n_pulses for c in self.chunks)


def detected_returns(cat: dict[str, np.ndarray]) -> DetectedReturns:
    """The chunks' navigation and detections, concatenated, as one DetectedReturns."""
    required = (
        "pulse_id origin_meas_m direction_meas has_surface t_surface_s has_bottom t_bottom_s "
        "surface_confidence bottom_confidence flags surface_amplitude bottom_amplitude "
        # the photon detector's no-bottom limits (full waveform: set by the no-bottom stage
        # once the survey's bottoms are in); the shot's timestamp and flight line
        "t_no_bottom_s t_emit_s line_id"
    ).split()
    # optional: the full-waveform detector's timing sigma of each return (photon counting:
    # none, the TPU sets it from the scatter of the soundings) and the in-column returns
    optional = ("t_surface_sigma_s", "t_bottom_sigma_s", *DetectedReturns.COLUMN_FIELDS)
    return DetectedReturns(
        **{k: cat[k] for k in required}, **{k: cat[k] for k in optional if k in cat}
    )
