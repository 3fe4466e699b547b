"""The chunk loop's detections spilled to disk, and the small summaries kept in memory.

:class:`DetectionStore` writes each chunk's measured navigation and detections (the ``part``
dict of :func:`pipeline.survey_chunks.run_chunk`) as one ``.npy`` file per field into a
temporary directory of the run's output folder, and keeps only a :class:`ChunkSummary` per chunk
(pulse count, pulse-id range, the xy bounding box of the chunk's returns): later stages load the
chunks they need (all of them, or those meeting a tile). The directory is removed when the store
closes, on success or failure, so nothing half-written stays. A chunk is written under a
temporary name and renamed once complete.

Survey-wide aggregates that used to need every pulse (:class:`SurveyAggregates`) are gathered
as the chunks arrive, on a **bounded sample** of the pulses: every pulse while the survey has at
most :data:`SAMPLE_PULSES` pulses (so those surveys are unchanged), else a fixed share chosen by
a hash of the pulse id (:func:`~pipeline.uncertainty.posterior_selection.kept_for_posterior`),
which does not depend on the chunk size, the order of arrival or the workers. Counts are exact
(sums of integers).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.returns import DetectedReturns
from pipeline.uncertainty.posterior_selection import kept_for_posterior

__all__ = ["SAMPLE_PULSES", "ChunkSummary", "DetectionStore", "SurveyAggregates"]

#: Pulses whose values the survey-wide statistics keep, at most (about 8 bytes each per
#: statistic): a survey this size or smaller uses every pulse.
SAMPLE_PULSES = 1_000_000

#: Hash offset of the aggregates' sample (not the posterior's waveforms).
_SAMPLE_SALT = 0x5EED


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


class DetectionStore:
    """Per-chunk detections on disk (``<out>/.detections.tmp``); a context manager.

    Parameters
    ----------
    out : Path
        The run's output folder (created if missing).
    air_index : float
        Processing's refractive index of air (the chunk positions of :func:`pulse_position_m`).
    """

    def __init__(self, out: Path, air_index: float) -> None:
        self.dir = Path(out) / ".detections.tmp"
        if self.dir.exists():  # left by a killed run
            shutil.rmtree(self.dir)
        self.dir.mkdir(parents=True)
        self.air_index = float(air_index)
        self.chunks: list[ChunkSummary] = []
        self._fields: list[str] = []

    def __enter__(self) -> DetectionStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Remove the directory and everything in it."""
        shutil.rmtree(self.dir, ignore_errors=True)

    @property
    def n_pulses(self) -> int:
        """Pulses stored."""
        return sum(c.n_pulses for c in self.chunks)

    def append(self, part: dict[str, np.ndarray]) -> ChunkSummary:
        """Write one chunk (the next in pulse order) and return its summary."""
        c = len(self.chunks)
        tmp = self.dir / f"c{c:06d}.part"
        tmp.mkdir()
        for name, arr in part.items():
            np.save(tmp / f"{name}.npy", np.asarray(arr), allow_pickle=False)
        tmp.rename(self.dir / f"c{c:06d}")
        if not self._fields:
            self._fields = list(part)
        ids = part["pulse_id"]
        n = len(ids)
        bbox = None
        if n:
            xy = pulse_position_m(part, self.air_index)
            bbox = np.array([xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()])
        summary = ChunkSummary(c, n, (int(ids[0]), int(ids[-1])) if n else (0, -1), bbox)
        self.chunks.append(summary)
        return summary

    def load_chunk(self, c: int, fields: list[str] | None = None) -> dict[str, np.ndarray]:
        """Fields of chunk ``c`` (all by default)."""
        d = self.dir / f"c{c:06d}"
        return {k: np.load(d / f"{k}.npy", allow_pickle=False) for k in fields or self._fields}

    def replace_field(self, c: int, name: str, values: np.ndarray) -> None:
        """Overwrite (or add) one field of chunk ``c``, atomically."""
        d = self.dir / f"c{c:06d}"
        tmp = d / f"{name}.tmp.npy"
        np.save(tmp, np.asarray(values), allow_pickle=False)
        tmp.replace(d / f"{name}.npy")
        if name not in self._fields:
            self._fields.append(name)

    def drop_field(self, name: str) -> None:
        """Forget a field of every chunk (and delete its files)."""
        for c in range(len(self.chunks)):
            (self.dir / f"c{c:06d}" / f"{name}.npy").unlink(missing_ok=True)
        self._fields = [f for f in self._fields if f != name]

    def load(self, chunks: list[int] | None = None) -> dict[str, np.ndarray]:
        """The fields of ``chunks`` (default: all) concatenated in pulse order."""
        idx = range(len(self.chunks)) if chunks is None else chunks
        parts = [self.load_chunk(c) for c in idx]
        return {k: np.concatenate([p[k] for p in parts]) for k in self._fields}

    def returns(self, chunks: list[int] | None = None) -> DetectedReturns:
        """The detections of ``chunks`` (default: all) as one DetectedReturns."""
        return detected_returns(self.load(chunks))


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
    nb_t_b, nb_loss, nb_alpha : list of arrays
        Full waveform: sampled bottom losses (the excess-decay fit) and column decays.
    nb_counts : dict of str to int
        Exact counts of the no-bottom inputs.
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
    nb_alpha: list = field(default_factory=list)
    nb_counts: dict = field(default_factory=lambda: {"bottoms": 0, "no_column": 0})

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
            self.nb_alpha.append(nb["alpha"][nb["ok"] & s])
            self.nb_counts["bottoms"] += int(nb["t_b"].size)
            self.nb_counts["no_column"] += int(np.count_nonzero(nb["none"] & ~nb["ok"]))

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

    def no_bottom_sample(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sampled ``(t_b, loss, alpha)`` of the no-bottom inputs (pulse order)."""

        def cat(xs):
            return np.concatenate(xs) if xs else np.zeros(0)

        return cat(self.nb_t_b), cat(self.nb_loss), cat(self.nb_alpha)
