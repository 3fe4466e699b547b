"""The stages of a run, declared once as data, and the plan a scene gets from them.

Each :class:`Stage` says what it does and when a scene needs it (a function of the scene that
returns None when it runs, or the reason it is left out). :func:`plan` evaluates them for a scene;
``bathy plan SCENE`` prints the result and ``bathy run`` executes exactly the stages that run,
timing each one (:class:`StageClock`) so the manifest can show wall and CPU seconds per stage.
"""

from __future__ import annotations

import contextlib
import resource
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Stage", "PlannedStage", "Plan", "STAGES", "plan", "StageClock", "peak_rss_mb"]


def _profiler(scene) -> str | None:
    return None if scene.profiler is not None else "no [profiler] table"


def _survey(scene) -> str | None:
    return None if scene.flight is not None else "no [flight] table: not a survey"


def _survey_and(test: Callable[[Any], str | None]) -> Callable[[Any], str | None]:
    def needed(scene) -> str | None:
        return _survey(scene) or test(scene)

    return needed


def _waves(scene) -> str | None:
    return None if scene.water_surface.kind == "waves" else "flat water: no wave field"


def _full_waveform(scene) -> str | None:
    if scene.detector.mode == "full_waveform":
        return None
    return "photon-counting receiver: no digitiser, no waveform"


def _photon(scene) -> str | None:
    if scene.detector.mode == "photon_counting":
        return None
    return "full-waveform receiver: no photon events"


def _no_bottom_limit(scene) -> str | None:
    if scene.detector.mode == "full_waveform":
        return None
    return "photon counting: class 45 stays at the window's end (no column to measure)"


def _views(scene) -> str | None:
    return None if scene.run.views else "run.views = false"


def _water_column(scene) -> str | None:
    if scene.detector.mode != "full_waveform":
        return "the photon-counting detector reports no in-column return"
    choice = scene.process.water_column_points
    if choice == "off":
        return "process.water_column_points = 'off'"
    if choice == "auto" and scene.water.layer_depth_m <= 0.0:
        return "no scattering layer in the scene (process.water_column_points = 'auto')"
    return None


def _posterior(scene) -> str | None:
    ps = scene.process
    if ps.posterior_pulses_per_km2 <= 0.0 and ps.posterior_min_pulses <= 0:
        return "process.posterior_pulses_per_km2 = 0 and posterior_min_pulses = 0"
    return None


@dataclass(frozen=True)
class Stage:
    """One stage: its name, what it does, and when a scene needs it.

    ``needed(scene)`` returns None when the stage runs, else the reason it is left out.
    """

    name: str
    does: str
    needed: Callable[[Any], str | None]


#: Every stage in execution order (the survey's chunked stages run per chunk in this order).
STAGES: tuple[Stage, ...] = (
    Stage("photon_budget", "lidar equation along one nadir path", _profiler),
    Stage("photon_histograms", "accumulated shots with background", _profiler),
    Stage("profiler_figures", "the reference document's Figures 14-17", _profiler),
    Stage("terrain", "seabed and water-surface truth and meshes", _survey),
    Stage("waves", "wind sea synthesised from its spectrum", _survey_and(_waves)),
    Stage("survey", "flight lines, attitude, scanner, measured navigation", _survey),
    Stage("trace", "refracted ray paths to the seabed", _survey),
    Stage("receiver_waveform", "lidar equation per pulse, digitised", _survey_and(_full_waveform)),
    Stage("receiver_photon", "lidar equation per pulse, photon events", _survey_and(_photon)),
    Stage("detect_waveform", "surface, bottom, column returns", _survey_and(_full_waveform)),
    Stage("detect_photon", "height histograms per window of shots", _survey_and(_photon)),
    Stage("no_bottom_limit", "each pulse's detection limit", _survey_and(_no_bottom_limit)),
    Stage("process", "surface fit, refraction, classes, class 45", _survey),
    Stage("water_column", "class 64 points of in-column returns", _survey_and(_water_column)),
    Stage("grid", "datum and bathymetry grid", _survey),
    Stage("tpu", "propagated uncertainty, per cell, IHO orders", _survey),
    Stage(
        "posterior",
        "emcee depth posteriors of a bounded sample (photon counting: of window histograms)",
        _survey_and(_posterior),
    ),
    Stage("outputs", "points.laz, grid.tif (COG), grid.nc (CF)", _survey),
    Stage(
        "views", "3D scene: view/*.vtp for ParaView, pictures for the report", _survey_and(_views)
    ),
    Stage("evaluate", "points and grid against the truth; report.html", _survey),
)


@dataclass(frozen=True)
class PlannedStage:
    """A stage as a scene's plan has it: whether it runs and why (or why not)."""

    name: str
    runs: bool
    reason: str


class Plan(tuple):
    """The planned stages, in order (a tuple of :class:`PlannedStage`)."""

    def runs(self, name: str) -> bool:
        """Whether stage ``name`` runs (KeyError for a name no stage has)."""
        for st in self:
            if st.name == name:
                return st.runs
        raise KeyError(f"no stage named {name!r}")

    def running(self) -> list[str]:
        """Names of the stages that run, in order."""
        return [st.name for st in self if st.runs]

    def lines(self) -> list[str]:
        """One printable line per stage."""
        return [f"  {'run ' if st.runs else 'skip'} {st.name:<18} {st.reason}" for st in self]


def plan(scene) -> Plan:
    """The plan of ``scene``: every stage, whether it runs, what it does or why it is left out."""
    out = []
    for st in STAGES:
        why_not = st.needed(scene)
        out.append(PlannedStage(st.name, why_not is None, st.does if why_not is None else why_not))
    return Plan(out)


def peak_rss_mb() -> float:
    """Peak resident memory of the running process so far, MiB.

    ``VmHWM`` of ``/proc/self/status`` (Linux): the high-water mark of this process image, which
    starts afresh at ``exec``, unlike ``ru_maxrss``, which a child inherits from the process
    that forked it (a run started from a large parent, a test runner, would show the parent's
    peak). Elsewhere ``ru_maxrss`` (KiB on Linux, bytes on macOS).
    """
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024.0


def trim_heap() -> None:
    """Hand the heap's freed pages back to the system (glibc's ``malloc_trim``; else nothing).

    Freed arrays below glibc's mmap threshold stay in the process's heap: after the chunk loop
    run in-process, 300 000 pulses left 586 MiB resident that a trim brought to 331. Called
    between the stages and blocks whose arrays are done with, so the next one starts low.
    """
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


@dataclass
class StageClock:
    """Wall and CPU seconds per stage, its resident-memory peak, and the order stages ran in.

    A stage that runs per chunk is timed across all its chunks. ``cpu_s`` is the process's CPU
    time (all threads), so a stage using several cores can show more CPU than wall time.
    ``peak_rss_mb`` is the stage's own peak in the process that ran it, over all its runs
    (:mod:`pipeline.rss_watch`): exact (``peak_exact``) where the stage raised the process's
    high-water mark (:func:`peak_rss_mb`), which is how the stage that sets a run's peak
    shows; else the largest RSS sampled every 10 ms while it ran, a lower bound.
    """

    wall_s: dict[str, float] = field(default_factory=dict)
    cpu_s: dict[str, float] = field(default_factory=dict)
    peak_rss_mb: dict[str, float] = field(default_factory=dict)
    peak_exact: dict[str, bool] = field(default_factory=dict)

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the block as stage ``name`` (added to earlier blocks of the same stage)."""
        from pipeline.rss_watch import WATCH

        w0, c0 = time.perf_counter(), time.process_time()
        mark0, token = peak_rss_mb(), WATCH.enter()
        try:
            yield
        finally:
            self.wall_s[name] = self.wall_s.get(name, 0.0) + time.perf_counter() - w0
            self.cpu_s[name] = self.cpu_s.get(name, 0.0) + time.process_time() - c0
            sampled, mark = WATCH.exit(token), peak_rss_mb()
            # the mark only rises: if it rose, its new value was reached inside this stage
            raised = mark > mark0
            self._add_peak(name, mark if raised else sampled, raised)

    def _add_peak(self, name: str, peak: float | None, exact: bool) -> None:
        if peak is not None and peak > self.peak_rss_mb.get(name, -1.0):
            self.peak_rss_mb[name], self.peak_exact[name] = peak, exact

    def add(self, other: dict[str, dict[str, float]]) -> None:
        """Add another process's :meth:`to_dict` (a pool worker's chunk).

        Seconds add up; the peak is the larger of the two.
        """
        for k, v in other.items():
            self.wall_s[k] = self.wall_s.get(k, 0.0) + v["wall_s"]
            self.cpu_s[k] = self.cpu_s.get(k, 0.0) + v["cpu_s"]
            self._add_peak(k, v.get("peak_rss_mb"), bool(v.get("peak_exact")))

    def ran(self) -> list[str]:
        """Names of the stages timed, in the order they first ran."""
        return list(self.wall_s)

    def to_dict(self) -> dict[str, dict[str, float]]:
        """``{stage: {"wall_s", "cpu_s", "peak_rss_mb", "peak_exact"}}``, JSON-ready.

        ``peak_rss_mb`` is None where no RSS could be read.
        """
        return {
            k: {
                "wall_s": self.wall_s[k],
                "cpu_s": self.cpu_s[k],
                "peak_rss_mb": self.peak_rss_mb.get(k),
                "peak_exact": self.peak_exact.get(k, False),
            }
            for k in self.wall_s
        }
