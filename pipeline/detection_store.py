"""The chunk loop's detections spilled to disk, and the small summaries kept in memory.

:class:`DetectionStore` appends each chunk's measured navigation and detections (the ``part``
dict of :func:`pipeline.survey_chunks.run_chunk`), field by field, to one unnamed temporary
file beside the run's outputs, and keeps only a :class:`ChunkSummary` per chunk (pulse count,
pulse-id range, the xy bounding box of the chunk's pulses) and each field's offset: later
stages load the chunks they need (all of them, or those meeting a tile). The file never has a
name (``O_TMPFILE``): closing the store, ending the run or killing it frees it, so nothing
half-written stays (the output folder keeps its rule of appearing only with its first complete
file, :mod:`pipeline.outputs.atomic`).

Survey-wide aggregates that used to need every pulse (:class:`SurveyAggregates`) are gathered
as the chunks arrive, on a **bounded sample** of the pulses: every pulse while the survey has at
most :data:`SAMPLE_PULSES` pulses (so those surveys are unchanged), else a fixed share chosen by
a hash of the pulse id (:func:`~pipeline.uncertainty.posterior_selection.kept_for_posterior`),
which does not depend on the chunk size, the order of arrival or the workers. Counts are exact
(sums of integers).
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.detection_reader import (
    ChunkSummary,
    StoreReader,
    _ChunkReads,
    detected_returns,
    file_identity,
)
from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.column_stack import ColumnStack
from pipeline.uncertainty.posterior_selection import kept_for_posterior

__all__ = [
    "SAMPLE_PULSES",
    "ChunkSummary",
    "DetectionStore",
    "StoreReader",
    "SurveyAggregates",
    "detected_returns",
]

#: Pulses whose values the survey-wide statistics keep, at most (about 8 bytes each per
#: statistic): a survey this size or smaller uses every pulse.
SAMPLE_PULSES = 1_000_000

#: Hash offset of the aggregates' sample (not the posterior's waveforms).
_SAMPLE_SALT = 0x5EED


#: The fields a pulse's position is made of (:func:`pulse_position_m`).
POSITION_FIELDS = (
    "origin_meas_m",
    "direction_meas",
    "has_surface",
    "t_surface_s",
    "has_bottom",
    "t_bottom_s",
    "has_column",
    "t_column_s",
)


def pulse_position_m(part: dict[str, np.ndarray], air_index: float) -> np.ndarray:
    """Horizontal position of each pulse, ``(n, 2)``: where its beam meets its first return.

    The surface return's position (straight in air), else the bottom's, else the first
    in-column return's; a pulse with no return at all: its measured origin. Measured data only.
    """
    o, d = part["origin_meas_m"], part["direction_meas"]
    t = np.where(part["has_surface"], part["t_surface_s"], 0.0)
    t = np.where((t == 0.0) & part["has_bottom"], part["t_bottom_s"], t)
    if "has_column" in part:
        t = np.where((t == 0.0) & part["has_column"], part["t_column_s"], t)
    r = SPEED_OF_LIGHT_M_S * t / (2.0 * air_index)
    return o[:, :2] + d[:, :2] * r[:, None]


def scratch_dir(out: Path) -> Path:
    """Where a run's unnamed temporary files go: its output folder, else its nearest parent."""
    out = Path(out)
    return out if out.is_dir() else next(p for p in out.parents if p.is_dir())


class SetAside:
    """Objects pickled to an unnamed temporary file (:func:`scratch_dir`) until taken back.

    What a blocked survey's sample made is needed again only after the blocks have run; held
    meanwhile, it would add to every block's memory.
    """

    def __init__(self, out: Path, *objects) -> None:
        self._file = tempfile.TemporaryFile(dir=scratch_dir(out))
        pickle.dump(objects, self._file, protocol=pickle.HIGHEST_PROTOCOL)

    def take(self) -> tuple:
        """The objects, as they were; the file is closed (and so freed)."""
        with self._file as f:
            f.seek(0)
            return pickle.load(f)


class DetectionStore(_ChunkReads):
    """Per-chunk detections in one unnamed temporary file; a context manager.

    The file is made by :func:`tempfile.TemporaryFile` in the run's output folder (or, before
    that folder exists, its parent: the output folder appears only with its first complete
    file, :mod:`pipeline.outputs.atomic`): on Linux an ``O_TMPFILE`` inode that never has a
    name, so even a killed run leaves nothing behind, and the space is freed when the store
    closes. Each field of each chunk is appended as raw bytes; only its offset, dtype and shape
    stay in memory.

    Parameters
    ----------
    out : Path
        The run's output folder.
    air_index : float
        Processing's refractive index of air (the chunk positions of :func:`pulse_position_m`).
    """

    def __init__(self, out: Path, air_index: float) -> None:
        self._file = tempfile.TemporaryFile(dir=scratch_dir(out))
        self._end = 0
        self.air_index = float(air_index)
        self.chunks: list[ChunkSummary] = []
        self._index: list[dict[str, tuple[int, str, tuple[int, ...]]]] = []

    def __enter__(self) -> DetectionStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close (and so free) the file."""
        self._file.close()

    def _fileno(self) -> int:
        return self._file.fileno()

    def reader(self) -> StoreReader | None:
        """A read-only view for another process of this machine (None: no ``/proc`` here).

        The chunks stored so far; the view reads the same unnamed file through this
        process's ``/proc/<pid>/fd/<n>``, so it is valid while the store is open.
        """
        path = f"/proc/{os.getpid()}/fd/{self._file.fileno()}"
        if not os.path.exists(path):
            return None
        return StoreReader(
            path,
            file_identity(self._file.fileno()),
            self.air_index,
            list(self.chunks),
            [dict(i) for i in self._index],
        )

    @property
    def n_pulses(self) -> int:
        """Pulses stored."""
        return sum(c.n_pulses for c in self.chunks)

    def _put(self, c: int, name: str, values: np.ndarray) -> None:
        a = np.ascontiguousarray(values)
        os.pwrite(self._file.fileno(), a.tobytes(), self._end)
        self._index[c][name] = (self._end, a.dtype.str, a.shape)
        self._end += a.nbytes

    def append(self, part: dict[str, np.ndarray]) -> ChunkSummary:
        """Write one chunk (the next in pulse order) and return its summary."""
        c = len(self.chunks)
        self._index.append({})
        for name, arr in part.items():
            self._put(c, name, np.asarray(arr))
        ids = part["pulse_id"]
        n = len(ids)
        bbox = None
        if n:
            xy = pulse_position_m(part, self.air_index)
            bbox = np.array([xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()])
        summary = ChunkSummary(c, n, (int(ids[0]), int(ids[-1])) if n else (0, -1), bbox)
        self.chunks.append(summary)
        return summary

    def fields(self, c: int) -> list[str]:
        """The fields stored for chunk ``c``."""
        return list(self._index[c])

    def replace_field(self, c: int, name: str, values: np.ndarray) -> None:
        """Overwrite (or add) one field of chunk ``c`` (appended; the old bytes are left).

        A field the pulse positions are made of (:func:`pulse_position_m`) moves the chunk's
        bounding box with it.
        """
        self._put(c, name, np.asarray(values))
        if name in POSITION_FIELDS and self.chunks[c].n_pulses:
            names = [k for k in POSITION_FIELDS if k in self._index[c]]
            xy = pulse_position_m(self.load_chunk(c, names), self.air_index)
            bbox = np.array([xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()])
            self.chunks[c] = dataclasses.replace(self.chunks[c], bbox_m=bbox)

    def drop_field(self, name: str) -> None:
        """Forget a field of every chunk."""
        for idx in self._index:
            idx.pop(name, None)


@dataclass
class SurveyAggregates:
    """Survey-wide statistics gathered chunk by chunk (bounded sample, exact counts).

    Parameters
    ----------
    n_pulses_total : int
        Pulses the survey will have (the flight plan's): sets the sample's share.
    seed : int
        The scene seed (the sample's hash).
    air_index : float

    Attributes
    ----------
    fraction : float
        Share of pulses in the sample: ``min(1, SAMPLE_PULSES / n_pulses_total)``.
    r_air_m : list of arrays
        Sampled pulses' slant range to their surface return (the forward-scatter correction's
        median range).
    photon : dict
        Photon counting: sampled detection-limit paths and exact counts.
    nb_t_b, nb_loss, nb_floor, nb_alpha : list of arrays
        Full waveform: sampled bottom losses and their floors (the excess-decay fit) and
        column decays.
    nb_counts : dict of str to int
        Exact counts of the no-bottom inputs.
    nb_stack, nb_stack_open : ColumnStack or None
        Full waveform: the stacked closed and open columns of every chunk, added chunk by
        chunk (exact; :func:`pipeline.process.no_bottom.chunk_inputs`).
    """

    n_pulses_total: int
    seed: int
    air_index: float
    fraction: float = 1.0
    r_air_m: list = field(default_factory=list)
    photon_path: list = field(default_factory=list)
    photon_counts: dict = field(default_factory=lambda: {"with_limit": 0, "beyond": 0})
    nb_t_b: list = field(default_factory=list)
    nb_loss: list = field(default_factory=list)
    nb_floor: list = field(default_factory=list)
    nb_alpha: list = field(default_factory=list)
    nb_counts: dict = field(default_factory=lambda: {"bottoms": 0, "no_column": 0})
    nb_stack: ColumnStack | None = None
    nb_stack_open: ColumnStack | None = None

    def __post_init__(self) -> None:
        self.fraction = min(1.0, SAMPLE_PULSES / max(self.n_pulses_total, 1))

    def sampled(self, pulse_id: np.ndarray) -> np.ndarray:
        """Which of ``pulse_id`` are in the sample (all of them when ``fraction`` is 1)."""
        if self.fraction >= 1.0:
            return np.ones(pulse_id.shape, dtype=bool)
        return kept_for_posterior(pulse_id, self.fraction, self.seed + _SAMPLE_SALT)

    def add(
        self,
        part: dict[str, np.ndarray],
        nb: dict[str, np.ndarray] | None,
        group_index: float,
        beyond_bit: int,
    ) -> None:
        """Take one chunk's share."""
        ids = part["pulse_id"]
        s = self.sampled(ids)
        has_s = part["has_surface"]
        r_air = SPEED_OF_LIGHT_M_S * part["t_surface_s"][has_s & s] / (2.0 * self.air_index)
        self.r_air_m.append(r_air)
        if "t_detection_limit_s" in part:
            t_lim = part["t_detection_limit_s"]
            ok = t_lim > 0
            path = (t_lim - part["t_surface_s"]) * SPEED_OF_LIGHT_M_S / (2.0 * group_index)
            self.photon_path.append(path[ok & s])
            self.photon_counts["with_limit"] += int(ok.sum())
            beyond = part["has_bottom"] & ((part["flags"] & np.uint16(beyond_bit)) != 0)
            self.photon_counts["beyond"] += int(beyond.sum())
        if nb is not None:
            sb = s[nb["b_row"]]
            self.nb_t_b.append(nb["t_b"][sb])
            self.nb_loss.append(nb["loss"][sb])
            self.nb_floor.append(nb["floor"][sb])
            self.nb_alpha.append(nb["alpha_fit"][nb["ok"] & s])
            self.nb_counts["bottoms"] += int(nb["t_b"].size)
            self.nb_counts["no_column"] += int(np.count_nonzero(nb["none"] & ~nb["ok"]))
            stack, open_ = nb["column_stack"], nb["column_stack_open"]
            self.nb_stack = stack if self.nb_stack is None else self.nb_stack + stack
            self.nb_stack_open = open_ if self.nb_stack_open is None else self.nb_stack_open + open_

    def median_surface_range_m(self) -> float | None:
        """Median slant range to the surface returns (sampled); None without any."""
        r = np.concatenate(self.r_air_m) if self.r_air_m else np.zeros(0)
        return float(np.median(r)) if r.size else None

    def photon_summary(self) -> dict[str, Any]:
        """:func:`~pipeline.process.photon_limit.photon_limit_summary`'s figures, streamed.

        The percentiles are of the sampled shots, the counts of all shots.
        """
        path = np.concatenate(self.photon_path) if self.photon_path else np.zeros(0)
        pct = np.percentile(path, [5, 50, 95]) if path.size else [None] * 3
        return {
            "photon_shots_with_detection_limit": self.photon_counts["with_limit"],
            "photon_detection_limit_path_m_p05": None if pct[0] is None else float(pct[0]),
            "photon_detection_limit_path_m_median": None if pct[1] is None else float(pct[1]),
            "photon_detection_limit_path_m_p95": None if pct[2] is None else float(pct[2]),
            "photon_bottoms_beyond_detection_limit": self.photon_counts["beyond"],
        }

    def no_bottom_sample(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Sampled ``(t_b, loss, floor, alpha)`` of the no-bottom inputs (pulse order)."""

        def cat(xs):
            return np.concatenate(xs) if xs else np.zeros(0)

        return cat(self.nb_t_b), cat(self.nb_loss), cat(self.nb_floor), cat(self.nb_alpha)
