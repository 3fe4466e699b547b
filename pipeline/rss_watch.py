"""Resident memory while a span of code runs: its peak, for the stages of a run.

The kernel keeps one exact high-water mark per process (``VmHWM``), which only rises. A span
whose run raised it has that mark as its own peak, exactly: the mark is updated before any
page is given back, so short spikes are caught. A span that did not raise it peaked lower, at
a value the mark cannot give without being reset (``/proc/self/clear_refs``). A reset would
also lower what ``wait4`` and ``/usr/bin/time`` report for the whole process after it exits,
so it is not done: such a span's peak is the largest of the RSS samples a thread takes every
``interval_s`` while the span is open (a lower bound, which can miss spikes shorter than the
interval). :class:`~pipeline.stages.StageClock` records which of the two each stage's figure
is (``peak_exact``).

The sampler reads ``/proc/self/statm`` (Linux); elsewhere spans get only the exact kind, when
the process's ``ru_maxrss`` rose.
"""

from __future__ import annotations

import itertools
import os
import threading

__all__ = ["current_rss_mb", "RssWatch", "WATCH"]

try:
    _PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2**20
except (AttributeError, ValueError, OSError):  # not POSIX
    _PAGE_MB = 4096 / 2**20


def current_rss_mb() -> float | None:
    """Resident memory of the running process now, MiB; None where ``/proc`` is unreadable."""
    try:
        with open("/proc/self/statm", encoding="ascii") as f:
            return int(f.read().split()[1]) * _PAGE_MB
    except (OSError, IndexError, ValueError):
        return None


class RssWatch:
    """The largest RSS sampled while each open span runs (one sampling thread per process).

    Parameters
    ----------
    interval_s : float
        Seconds between samples. At 0.01 s a sample costs ~20 us: 0.2 % of a core.
    """

    def __init__(self, interval_s: float = 0.01):
        self.interval_s = interval_s
        self._ids = itertools.count()
        self._fresh()

    def _fresh(self) -> None:
        # also in a forked child: the parent's lock may have been held at the fork, and the
        # child has no sampling thread
        self._open: dict[int, float] = {}
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._pid: int | None = None

    def enter(self) -> int:
        """Open a span; returns its token for :meth:`exit`."""
        now = current_rss_mb()
        with self._lock:
            token = next(self._ids)
            self._open[token] = -1.0 if now is None else now
            if now is not None and self._pid != os.getpid():
                self._pid = os.getpid()
                threading.Thread(target=self._sample, name="rss-watch", daemon=True).start()
            self._wake.notify()
        return token

    def exit(self, token: int) -> float | None:
        """Close a span: the largest RSS sampled while it was open (its ends included), MiB."""
        now = current_rss_mb()
        with self._lock:
            peak = self._open.pop(token)
        if now is not None:
            peak = max(peak, now)
        return None if peak < 0.0 else peak

    def _sample(self) -> None:
        with self._lock:
            while True:
                # the wait lets go of the lock; while no span is open, it lasts until one opens.
                # The sample is read under the lock (~20 us), so it belongs to the spans open
                # when it was taken
                self._wake.wait(self.interval_s if self._open else None)
                now = current_rss_mb() if self._open else None
                if now is None:
                    continue
                for k, v in self._open.items():
                    if now > v:
                        self._open[k] = now


WATCH = RssWatch()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=WATCH._fresh)
