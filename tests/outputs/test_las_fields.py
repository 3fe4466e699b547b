"""points.laz standard fields on hand-built points: return numbers, GPS time, intensity, scan
angle, point source ID, synthetic flag, WKT 1 compound CRS; decoded by LASzip and laspy.

Every expected value is written here from the LAS 1.4 R15 definitions (return numbers 1..n in
time order within a pulse; scan angle in 0.006 degree steps, counter-clockwise seen from the
rear, i.e. positive to starboard; intensity normalised by 65536 / dynamic range).
"""

import laspy
import numpy as np
import pyproj
import pytest

from pipeline.outputs.las import read_points_laz, write_points_laz
from pipeline.process.returns import DetectedReturns, PointFlag, Points

ORIGIN = (512_000.0, 5_432_000.0, 0.0)
S, B, DER, COL = 1, 2, 3, 4  # ReturnKind values


def _dir(east_deg):
    a = np.radians(east_deg)
    return [np.sin(a), 0.0, -np.cos(a)]


def hand_returns():
    # line 0 flown north (y grows with time), line 1 flown south
    return DetectedReturns(
        pulse_id=np.array([100, 101, 200, 201]),
        origin_meas_m=np.array([[0, 0, 300], [0, 30, 300], [100, 30, 300], [100, 0, 300.0]]),
        direction_meas=np.array([_dir(10), _dir(10), _dir(10), _dir(-5)]),
        has_surface=np.ones(4, bool),
        t_surface_s=np.full(4, 2e-6),
        has_bottom=np.zeros(4, bool),
        t_bottom_s=np.zeros(4),
        surface_confidence=np.ones(4),
        bottom_confidence=np.zeros(4),
        flags=np.zeros(4, np.uint16),
        t_emit_s=np.array([10.0, 10.5, 50.0, 50.5]),
        line_id=np.array([0, 0, 1, 1]),
    )


# (pulse, kind, class, z, amplitude, flags) in a deliberately shuffled order, with the
# numbering processing gave before: surface "1 of 1" next to its class-45 point "2 of 2"
ROWS = [
    (101, B, 40, -8.0, 50.0, 0),
    (100, B, 45, -15.0, 0.0, 0),  # no-bottom-found-at, not flagged synthetic by the caller
    (201, DER, 42, 0.0, 0.0, PointFlag.SYNTHETIC),
    (200, B, 40, -5.0, 80.0, 0),
    (101, COL, 64, -3.0, 20.0, 0),
    (100, S, 41, 0.1, 200.0, 0),
    (201, B, 40, -6.0, 60.0, 0),
    (101, S, 41, 0.0, 300.0, 0),
    (201, S, 41, 0.05, 100.0, 0),
]
OLD_NUMBER = [2, 2, 1, 2, 1, 1, 2, 1, 1]
OLD_TOTAL = [2, 2, 1, 2, 1, 1, 2, 2, 2]
# time order: surface (the higher of surface / derived entry first), column, bottom or class 45
EXPECTED_NUMBER = [3, 2, 2, 1, 2, 1, 3, 1, 1]
EXPECTED_TOTAL = [3, 2, 3, 1, 3, 2, 3, 3, 3]


def hand_points():
    pid, kind, cls, z, amp, flags = (np.array(c) for c in zip(*ROWS, strict=True))
    n = len(ROWS)
    return Points(
        pulse_id=pid,
        xyz_m=np.column_stack([np.arange(n, dtype=float), np.zeros(n), z]),
        depth_m=-z,
        classification=cls.astype(np.uint8),
        kind=kind.astype(np.uint8),
        flags=flags.astype(np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.array(OLD_NUMBER, np.uint8),
        number_of_returns=np.array(OLD_TOTAL, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=np.full(n, 0.1),
        uncertainty_h_m=np.full(n, 0.2),
        amplitude=amp.astype(float),
    )


def write_hand_file(tmp_path):
    return write_points_laz(
        tmp_path / "p.laz",
        hand_points(),
        crs=32633,
        origin_m=ORIGIN,
        returns=hand_returns(),
        amplitude_full_scale=4096.0,  # a 12-bit digitiser: intensity = 16 x amplitude
    )


def test_return_numbers_run_one_to_n_in_time_order_in_every_pulse(tmp_path):
    path = write_points_laz(tmp_path / "p.laz", hand_points(), crs=32633, origin_m=ORIGIN)
    las = laspy.read(path)
    np.testing.assert_array_equal(las.return_number, EXPECTED_NUMBER)
    np.testing.assert_array_equal(las.number_of_returns, EXPECTED_TOTAL)
    # derived points are synthetic: class 45 (flag not set by the caller) and the derived surface
    np.testing.assert_array_equal(np.asarray(las.synthetic, bool), [r[2] in (45, 42) for r in ROWS])


def test_pulse_fields_and_wkt1_compound_crs(tmp_path):
    path = write_hand_file(tmp_path)
    las = laspy.read(path)
    t_of = {100: 10.0, 101: 10.5, 200: 50.0, 201: 50.5}
    np.testing.assert_array_equal(las.gps_time, [t_of[r[0]] for r in ROWS])
    # synthetic points have no echo of their own: intensity 0
    np.testing.assert_array_equal(
        las.intensity, [0 if r[2] in (45, 42) else 16 * r[4] for r in ROWS]
    )
    # 10 deg east on a north line: starboard, +10 deg; on a south line: port, -10 deg;
    # 5 deg west on a south line: starboard, +5 deg (0.006 deg steps)
    angle_of = {100: 1667, 101: 1667, 200: -1667, 201: 833}
    np.testing.assert_array_equal(las.scan_angle, [angle_of[r[0]] for r in ROWS])
    np.testing.assert_array_equal(las.point_source_id, [1 if r[0] < 200 else 2 for r in ROWS])
    # CRS: OGC WKT 1 (LAS 1.4 R15), compound, the vertical part naming the local frame
    assert las.header.global_encoding.wkt
    (vlr,) = las.header.vlrs.get("WktCoordinateSystemVlr")
    wkt = vlr.string.rstrip("\0")
    assert wkt.startswith("COMPD_CS[")
    assert 'VERT_CS["Local height above scene mean water level"' in wkt
    crs = pyproj.CRS.from_wkt(wkt)
    assert crs.is_compound and crs.sub_crs_list[0] == pyproj.CRS.from_epsg(32633)
    back = read_points_laz(path)
    np.testing.assert_array_equal(back.point_source_id, [1 if r[0] < 200 else 2 for r in ROWS])
    np.testing.assert_allclose(back.scan_angle_deg, [0.006 * angle_of[r[0]] for r in ROWS])


# LAS 1.4 R15 Table 16, point data record format 6 (30 bytes), little endian
FORMAT6 = np.dtype(
    [
        ("X", "<i4"),
        ("Y", "<i4"),
        ("Z", "<i4"),
        ("intensity", "<u2"),
        ("returns", "u1"),  # return number bits 0-3, number of returns bits 4-7
        ("flags", "u1"),  # classification flags bits 0-3 (synthetic = bit 0), channel, ...
        ("classification", "u1"),
        ("user_data", "u1"),
        ("scan_angle", "<i2"),
        ("point_source_id", "<u2"),
        ("gps_time", "<f8"),
    ]
)


def test_laszip_reference_decoder_reads_the_same_points_as_laspy(tmp_path):
    laszip = pytest.importorskip("laszip")
    path = write_hand_file(tmp_path)
    with open(path, "rb") as f:
        unzipper = laszip.LasUnZipper(f)
        hdr = unzipper.header
        assert hdr.point_data_format == 6
        n = hdr.extended_number_of_point_records or hdr.number_of_point_records
        raw = bytearray(n * hdr.point_data_record_length)
        unzipper.decompress_into(raw)
    las = laspy.read(path, laz_backend=laspy.LazBackend.Lazrs)
    assert n == len(ROWS) == len(las.points)
    assert bytes(raw) == las.points.array.tobytes()  # identical records, extra bytes included
    size = hdr.point_data_record_length
    base = np.frombuffer(
        b"".join(raw[i * size : i * size + FORMAT6.itemsize] for i in range(n)), FORMAT6
    )
    np.testing.assert_array_equal(base["returns"] & 0x0F, EXPECTED_NUMBER)
    np.testing.assert_array_equal(base["returns"] >> 4, EXPECTED_TOTAL)
    np.testing.assert_array_equal(base["flags"] & 1, [r[2] in (45, 42) for r in ROWS])
    np.testing.assert_array_equal(base["point_source_id"], [1 if r[0] < 200 else 2 for r in ROWS])
    np.testing.assert_array_equal(base["classification"], [r[2] for r in ROWS])
