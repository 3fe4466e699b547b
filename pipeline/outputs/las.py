"""``points.laz``: LAS 1.4, point format 6, CRS as WKT, per-point extras, written atomically.

Layout
------
* Coordinates are world coordinates (local + origin) stored as int32 with scale
  ``scale_m`` (default 1 mm) and offsets = the origin rounded to whole metres, so millimetres
  survive next to UTM-sized eastings/northings (int32 covers +-2147 km around the offset at
  1 mm). The exact origin is kept in a ``bathy`` VLR (JSON) so the reader returns the same local
  frame.
* CRS: an OGC WKT 1 VLR (the WKT LAS 1.4 R15 specifies; the WKT bit of the global encoding is
  set): a compound CRS, the horizontal CRS + a local vertical CRS named for what z is (height
  above the scene's mean water level, :func:`pipeline.outputs.las_fields.las_crs`).
* Class meanings: the LAS 1.4 Classification Lookup VLR (``LASF_Spec``, record 0) names every
  class code present in the file, so readers see that the user-definable code 64 is "water
  column" next to the topo-bathy classes 40-45 (:mod:`pipeline.process.classify`). Its
  descriptions are at most 15 ASCII letters, digits and spaces (the record's size, and what
  laspy reads back).
* Standard fields: classification (ASPRS codes of :mod:`pipeline.process.classify`); return
  number / number of returns 1..n in time order over *all* the points of a pulse, class 45 and
  64 and derived points included (:mod:`pipeline.process.return_order`); synthetic flag on
  every derived point (``PointFlag.SYNTHETIC``, class 45, derived surface); withheld flag on
  the rejected soundings (``TVU_EXCEEDED``, ``SURFACE_IMPLAUSIBLE``, ``SEABED_OUTLIER``: class 7,
  :mod:`pipeline.process.seabed_outliers`). Given the
  detections (``returns``): GPS time, intensity, scan angle and point source ID (flight line)
  of :mod:`pipeline.outputs.las_fields`; without them those four are 0.
* Extra bytes (LAS 1.4 extra-bytes VLR): ``depth_m`` (f8; below the *local* sea at the
  pulse's time (fitted plane and sea correlation), as its description says; the grid's
  datum is in ``grid.tif`` and ``evaluation.json``), ``uncertainty_v_m``, ``uncertainty_h_m``,
  ``confidence`` (f4), ``pulse_id`` (i8), ``kind`` (u1),
  ``process_flags``, ``detector_flags`` (u2), and ``amplitude`` (f4) when present.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import laspy
import numpy as np
import pyproj
from laspy.vlrs.known import ClassificationLookupVlr, WktCoordinateSystemVlr

from pipeline.outputs.atomic import atomic_path
from pipeline.outputs.las_fields import SCAN_ANGLE_UNIT_DEG, las_crs, pulse_fields
from pipeline.process.classify import CLASS_NAMES, NO_BOTTOM_FOUND_AT
from pipeline.process.return_order import time_order_numbers
from pipeline.process.returns import DetectedReturns, PointFlag, Points, ReturnKind

__all__ = [
    "LOOKUP_NAMES",
    "LazContents",
    "LazTileWriter",
    "las_header",
    "las_records",
    "write_points_laz",
    "read_points_laz",
]

#: Classification Lookup VLR descriptions of the classes of :mod:`pipeline.process.classify`
#: (15 bytes each; laspy keeps only letters, digits and spaces when reading them).
LOOKUP_NAMES: dict[int, str] = {
    0: "not classified",
    1: "unclassified",
    2: "ground",
    7: "low noise",
    18: "high noise",
    40: "bathymetry",
    41: "water surface",
    42: "derived surface",
    43: "submerged obj",
    44: "IHO S57 object",
    45: "no bottom found",
    64: "water column",
}

_VLR_USER = "bathy"
_VLR_RECORD = 1
_EXTRA = (
    # the point's own reference: below the water surface fitted around it (under waves it moves
    # with them); grid.tif's depth is below the survey's datum (pipeline.process.datum)
    ("depth_m", "f8", "below local sea at pulse time, m"),
    ("uncertainty_v_m", "f4", "vertical 1-sigma uncertainty (m)"),
    ("uncertainty_h_m", "f4", "horiz. 1-sigma uncertainty (m)"),
    ("confidence", "f4", "detection confidence 0-1"),
    ("pulse_id", "i8", "global pulse number"),
    ("kind", "u1", "1 surf 2 bot 3 derived 4 column"),
    ("process_flags", "u2", "processing flag bits"),
    ("detector_flags", "u2", "detector flag bits"),
)
_INT32 = 2**31 - 1


@dataclass(frozen=True)
class LazContents:
    """What :func:`read_points_laz` returns."""

    points: Points
    crs: pyproj.CRS | None
    origin_m: np.ndarray
    scales: np.ndarray
    offsets: np.ndarray
    #: Class code -> description from the Classification Lookup VLR (empty if none).
    class_names: dict[int, str] = field(default_factory=dict)
    #: Standard per-point fields, ``(n,)``: GPS time (s), intensity, scan angle (degrees),
    #: point source ID.
    gps_time_s: np.ndarray | None = None
    intensity: np.ndarray | None = None
    scan_angle_deg: np.ndarray | None = None
    point_source_id: np.ndarray | None = None


def _lookup_name(code: int) -> str:
    """A Classification Lookup description of ``code``: <= 15 letters, digits and spaces."""
    if code in LOOKUP_NAMES:
        return LOOKUP_NAMES[code]
    text = CLASS_NAMES.get(code, f"class {code}")
    return "".join(ch for ch in text if ch.isalnum() or ch == " ")[:15]


def _classification_lookup(classes: np.ndarray) -> ClassificationLookupVlr:
    """The Classification Lookup VLR naming every class code present in ``classes``."""
    vlr = ClassificationLookupVlr()
    for code in np.unique(classes).tolist():
        vlr[int(code)] = _lookup_name(int(code))
    return vlr


def write_points_laz(
    path: str | Path,
    points: Points,
    *,
    crs: Any,
    origin_m: Sequence[float] = (0.0, 0.0, 0.0),
    scale_m: float = 0.001,
    compress: bool | None = None,
    returns: DetectedReturns | None = None,
    amplitude_full_scale: float = 65536.0,
) -> Path:
    """Write ``points`` as LAS 1.4 point format 6 (LAZ if ``.laz``), atomically.

    Parameters
    ----------
    path : str or Path
        Output file; ``.laz`` compresses (unless ``compress`` says otherwise).
    points : Points
        Points in the local frame.
    crs : any
        Horizontal CRS of the world coordinates (EPSG code, WKT, ``pyproj.CRS``).
    origin_m : (easting, northing, height)
        World coordinates of the local origin.
    scale_m : float
        Coordinate quantum (default 1 mm).
    compress : bool, optional
        LAZ or LAS; default by the suffix.
    returns : DetectedReturns, optional
        The detections the points come from, with ``t_emit_s`` and ``line_id``: GPS time,
        intensity, scan angle and point source ID of every point (else 0).
    amplitude_full_scale : float
        The receiver's dynamic range in amplitude units (intensity scale
        ``65536 / amplitude_full_scale``).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        If a coordinate does not fit int32 at this scale around the offset.
    """
    path = Path(path)
    header = las_header(points.classification, points.amplitude is not None, crs, origin_m, scale_m)
    las = las_records(header, points, returns, amplitude_full_scale)
    do_compress = path.suffix.lower() == ".laz" if compress is None else compress
    # a stream, not a path: laspy takes the compression from a path's suffix and ignores
    # do_compress (and the temporary path has no suffix)
    with atomic_path(path) as tmp, open(tmp, "wb+") as f:
        las.write(f, do_compress=do_compress)
    return path


def las_header(
    classes: np.ndarray,
    amplitude: bool,
    crs: Any,
    origin_m: Sequence[float] = (0.0, 0.0, 0.0),
    scale_m: float = 0.001,
) -> laspy.LasHeader:
    """The LAS 1.4 header :func:`write_points_laz` writes (``classes``: the codes to name)."""
    origin = np.asarray(origin_m, dtype=np.float64)
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise ValueError(f"`origin_m` must be 3 finite numbers; got {origin_m!r}")
    if not (np.isfinite(scale_m) and scale_m > 0):
        raise ValueError(f"`scale_m` must be finite and > 0; got {scale_m!r}")
    offsets = np.round(origin)
    scales = np.full(3, float(scale_m))

    header = laspy.LasHeader(version="1.4", point_format=6)
    header.offsets = offsets
    header.scales = scales
    header.system_identifier = "bathy pipeline"
    header.generating_software = "bathy pipeline (laspy)"
    extras = list(_EXTRA)
    if amplitude:
        extras.append(("amplitude", "f4", "amplitude (detector units)"))
    header.add_extra_dims(
        [laspy.ExtraBytesParams(name=n, type=t, description=desc) for n, t, desc in extras]
    )
    # LAS 1.4 R15: the WKT VLR holds OGC WKT 1 (laspy's add_crs writes pyproj's WKT2)
    wkt1 = las_crs(crs).to_wkt("WKT1_GDAL")
    if wkt1 is None:
        raise ValueError(f"`crs` has no OGC WKT 1 form (LAS 1.4 needs one): {crs!r}")
    header.vlrs.append(WktCoordinateSystemVlr(wkt1))
    header.global_encoding.wkt = True
    header.vlrs.append(_classification_lookup(np.asarray(classes)))
    meta = {"origin_m": origin.tolist(), "frame": "local = world - origin_m; z up; metres"}
    header.vlrs.append(
        laspy.VLR(
            user_id=_VLR_USER,
            record_id=_VLR_RECORD,
            description="local frame origin",
            record_data=json.dumps(meta).encode("utf-8"),
        )
    )
    return header


def las_records(
    header: laspy.LasHeader,
    points: Points,
    returns: DetectedReturns | None,
    amplitude_full_scale: float,
    lines=None,
) -> laspy.LasData:
    """The point records of ``points`` under ``header`` (every pulse's points must be there).

    ``lines``: the survey's :class:`~pipeline.outputs.las_fields.LineEnds` when ``returns``
    are a part of it (the scan angle).
    """
    las = laspy.LasData(header)
    origin = _header_origin(header)
    offsets, scales = np.asarray(header.offsets), np.asarray(header.scales)
    world = points.xyz_m + origin
    ints = np.round((world - offsets) / scales)
    if ints.size and np.max(np.abs(ints)) > _INT32:
        raise ValueError(
            f"coordinates span more than int32 at scale {scales[0]} m around offset "
            f"{offsets.tolist()}; use a coarser `scale_m`"
        )
    las.X, las.Y, las.Z = (ints[:, i].astype(np.int32) for i in range(3))
    las.classification = points.classification
    # numbered here whatever the caller's numbering: a file's pulses always read 1..n
    number, total = time_order_numbers(points.pulse_id, points.kind, points.xyz_m[:, 2])
    las.return_number, las.number_of_returns = number, total
    las.synthetic = (
        ((points.flags & np.uint16(PointFlag.SYNTHETIC)) != 0)
        | (points.kind == ReturnKind.DERIVED_SURFACE)
        | (points.classification == NO_BOTTOM_FOUND_AT)
    )
    # rejected soundings (class 7) stay in the file, withheld as LAS 1.4 defines the bit: a
    # point that should not be used in normal processing
    rejected = PointFlag.TVU_EXCEEDED | PointFlag.SEABED_OUTLIER | PointFlag.SURFACE_IMPLAUSIBLE
    las.withheld = (points.flags & np.uint16(rejected)) != 0
    if returns is not None:
        pf = pulse_fields(points, returns, amplitude_full_scale, lines)
        las.gps_time = pf.gps_time_s
        las.intensity = pf.intensity
        las.scan_angle = pf.scan_angle
        las.point_source_id = pf.point_source_id
    las.depth_m = points.depth_m
    las.uncertainty_v_m = points.uncertainty_v_m.astype(np.float32)
    las.uncertainty_h_m = points.uncertainty_h_m.astype(np.float32)
    las.confidence = points.confidence.astype(np.float32)
    las.pulse_id = points.pulse_id
    las.kind = points.kind
    las.process_flags = points.flags
    las.detector_flags = points.detector_flags
    if points.amplitude is not None:
        las.amplitude = points.amplitude.astype(np.float32)
    return las


def _header_origin(header: laspy.LasHeader) -> np.ndarray:
    """The exact local origin kept in the header's ``bathy`` VLR."""
    for vlr in header.vlrs:
        if vlr.user_id == _VLR_USER and vlr.record_id == _VLR_RECORD:
            return np.asarray(json.loads(bytes(vlr.record_data).decode())["origin_m"], float)
    return np.asarray(header.offsets, dtype=np.float64)


class LazTileWriter:
    """``points.laz`` appended tile by tile (laspy's chunked writer), renamed when complete.

    The header (:func:`las_header`) names the classes given up front; each :meth:`write`
    appends the records of whole pulses (:func:`las_records`). Used as a context manager: the
    file appears only if the block completes (:func:`~pipeline.outputs.atomic.atomic_path`).
    """

    def __init__(self, path: str | Path, header: laspy.LasHeader, amplitude_full_scale: float):
        self.path, self.header, self.afs = Path(path), header, amplitude_full_scale
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> LazTileWriter:
        tmp = self._stack.enter_context(atomic_path(self.path))
        f = self._stack.enter_context(open(tmp, "wb+"))
        compress = self.path.suffix.lower() == ".laz"
        self._writer = self._stack.enter_context(
            laspy.open(f, mode="w", header=self.header, do_compress=compress, closefd=False)
        )
        return self

    def write(self, points: Points, returns: DetectedReturns | None, lines=None) -> None:
        """Append the records of ``points`` (whole pulses; ``lines``: :func:`las_records`)."""
        if len(points):
            recs = las_records(self.header, points, returns, self.afs, lines)
            self._writer.write_points(recs.points)

    def __exit__(self, *exc) -> None:
        self._stack.__exit__(*exc)


def read_points_laz(path: str | Path) -> LazContents:
    """Read a file written by :func:`write_points_laz` back into local-frame :class:`Points`.

    Files without the ``bathy`` origin VLR use the header offsets as the origin; missing extra
    dimensions get neutral values (depth = -z, confidence 1, zeros elsewhere).
    """
    las = laspy.read(str(path))
    hdr = las.header
    origin = np.asarray(hdr.offsets, dtype=np.float64)
    for vlr in hdr.vlrs:
        if vlr.user_id == _VLR_USER and vlr.record_id == _VLR_RECORD:
            origin = np.asarray(json.loads(bytes(vlr.record_data).decode())["origin_m"], float)
    lookup = hdr.vlrs.get("ClassificationLookupVlr")
    class_names = dict(lookup[0].lookups) if lookup else {}
    world = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    xyz = world - origin
    n = len(xyz)
    names = set(las.point_format.extra_dimension_names)

    def extra(name, default, dtype):
        return np.asarray(las[name], dtype=dtype) if name in names else np.full(n, default, dtype)

    points = Points(
        pulse_id=extra("pulse_id", 0, np.int64),
        xyz_m=xyz,
        depth_m=extra("depth_m", 0.0, np.float64) if "depth_m" in names else -xyz[:, 2],
        classification=np.asarray(las.classification, dtype=np.uint8),
        kind=extra("kind", 0, np.uint8),
        flags=extra("process_flags", 0, np.uint16),
        detector_flags=extra("detector_flags", 0, np.uint16),
        return_number=np.asarray(las.return_number, dtype=np.uint8),
        number_of_returns=np.asarray(las.number_of_returns, dtype=np.uint8),
        confidence=extra("confidence", 1.0, np.float64),
        uncertainty_v_m=extra("uncertainty_v_m", 0.0, np.float64),
        uncertainty_h_m=extra("uncertainty_h_m", 0.0, np.float64),
        amplitude=extra("amplitude", 0.0, np.float64) if "amplitude" in names else None,
    )
    return LazContents(
        points=points,
        crs=hdr.parse_crs(),
        origin_m=origin,
        scales=np.asarray(hdr.scales, dtype=np.float64),
        offsets=np.asarray(hdr.offsets, dtype=np.float64),
        class_names=class_names,
        gps_time_s=np.asarray(las.gps_time, dtype=np.float64),
        intensity=np.asarray(las.intensity, dtype=np.uint16),
        scan_angle_deg=np.asarray(las.scan_angle, dtype=np.float64) * SCAN_ANGLE_UNIT_DEG,
        point_source_id=np.asarray(las.point_source_id, dtype=np.uint16),
    )
