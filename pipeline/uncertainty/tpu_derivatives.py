"""The TPU's derivatives of one pass, kept for the next: the points moved along each input.

:func:`~pipeline.uncertainty.tpu_neighbours.timing_from_scatter` and
:func:`~pipeline.uncertainty.tpu.point_tpu` move the same inputs of the same bottom pulses
(the return times, the beam, the local plane's height and tilt) by the same steps
(:data:`~pipeline.uncertainty.tpu_terms.TIMING_STEP_S`): the first's derivatives serve the
second to the bit, and are passed on rather than made again.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from pipeline.process.refraction import RefractionSettings
from pipeline.process.surface_fit import WaterSurface

__all__ = ["Derivatives"]


@dataclass(frozen=True, eq=False)
class Derivatives:
    """The nominal points and their derivatives along each input moved, kept for another pass.

    :func:`~pipeline.uncertainty.tpu_neighbours.timing_from_scatter` makes its random terms'
    (the times, the pointing, the plane's height; its tilts where the waves' slope sigma is
    not 0), every move that some block of rows of its pass needed (:func:`~pipeline.
    uncertainty.tpu_terms._terms`); :func:`~pipeline.uncertainty.tpu.point_tpu` of the same
    pulses, surface and indices reads them and makes the others (module notes).

    Attributes
    ----------
    row : (n,) int ndarray
        The bottom pulses (rows of the returns).
    moves : dict of str to ndarray
        ``"xyzd"``: the points and depths ``(n, 4)``; each input moved
        (:func:`~pipeline.uncertainty.tpu_terms._moves`): their derivative ``(n, 4)`` per
        unit of it.
    inputs_digest : bytes
        BLAKE2b of the rows' times, origins and beams (:func:`_digest`).
    surface, refraction : WaterSurface, RefractionSettings
        The objects the moves were made with (compared by identity).
    pointing_jitter_deg : float
        The pointing steps' setting.
    """

    row: np.ndarray
    moves: dict
    inputs_digest: bytes
    surface: WaterSurface
    refraction: RefractionSettings
    pointing_jitter_deg: float

    @classmethod
    def made(cls, inp, moves: dict, surface: WaterSurface, st) -> Derivatives:
        """Those of the TPU's inputs ``inp`` taken from ``surface``, with settings ``st``."""
        return cls(inp.row, moves, _digest(inp.ret), surface, inp.rst, st.pointing_jitter_deg)

    def of(self, inp, surface: WaterSurface, st) -> dict | None:
        """The moves, where ``inp`` are these rows of the same pulses and inputs; else None.

        ``inp``: the TPU's inputs (:func:`~pipeline.uncertainty.tpu_terms._inputs`), ``st``
        its settings, ``surface`` the whole surface ``inp`` was taken from. Checked: the same
        rows, the same surface and refraction objects, the same pointing jitter, and the
        rows' times, origins and beams the same bytes (the timing sigmas may differ: no
        derivative reads them).
        """
        same = (
            surface is self.surface
            and inp.rst is self.refraction
            and st.pointing_jitter_deg == self.pointing_jitter_deg
            and np.array_equal(inp.row, self.row)
            and _digest(inp.ret) == self.inputs_digest
        )
        return self.moves if same else None


#: The returns' fields the derivatives read besides the surface (the bottom rows').
_READ = ("t_surface_s", "t_bottom_s", "origin_meas_m", "direction_meas", "has_surface", "t_emit_s")


def _digest(ret) -> bytes:
    """BLAKE2b of :data:`_READ`'s bytes (a copy of them would hold ~70 B a pulse).

    ``t_emit_s``: the kriged sea above a sounding is read at the pulse's time where the
    surface's sea is not held (:func:`~pipeline.process.refraction.seabed_points`).
    """
    h = hashlib.blake2b(digest_size=32)
    for name in _READ:
        v = getattr(ret, name)
        if v is None:  # (t_emit_s: the sea is not kriged at the pulses' times)
            h.update(f"{name}None".encode())
            continue
        a = np.ascontiguousarray(v)
        h.update(f"{name}{a.dtype.str}{a.shape}".encode())
        h.update(a.data)
    return h.digest()
