"""Closed-form feasible region of the redundant axes (track r1, extend r4) for one target.

The wrist centre W is reachable from track r1 with extend r4 when the shoulder-wrist distance
lies between the folded and the stretched arm (with a stretch margin). For one r1 that gives
an extend interval in closed form; r1 itself is confined to at most two intervals (behind and
ahead of the target along the track). :func:`track_intervals` is the same over many frames.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from camtraj.robot import DHConstants

Array = NDArray[np.float64]

@dataclass(frozen=True)
class Region:
    """Closed-form superset of the feasible (r1, r4) region for one target."""

    dh: DHConstants
    W: Array
    r1_lo: float
    r1_hi: float
    r4_lo: float
    r4_hi: float
    stretch: float

    @functools.cached_property
    def _reach(self) -> tuple[Any, ...]:
        """Constants of :meth:`r4_interval` (scalars, or arrays for one region per frame)."""
        dh = self.dh
        cm, sm = np.cos(self.stretch), np.sin(self.stretch)
        return (self.W[0] - dh.r10, self.W[1] ** 2 + (self.W[2] - dh.r2) ** 2, -dh.r6 * cm,
                (dh.r6 * sm) ** 2, dh.l3 * dh.l3, (dh.r6 - dh.l3) ** 2, dh.r40)

    def r4_interval(self, r1: Array) -> tuple[Array, Array]:
        """Extend range [lo, hi] that can reach W from track r1 (empty where lo > hi)."""
        c, perp2, a, b2, l3_2, e2, r40 = self._reach
        dx = c - r1
        ws2 = dx * dx + perp2  # squared distance shoulder -> wrist centre
        dse_min = a + np.sqrt(np.maximum(ws2 - b2, 0.0))
        l_min = np.sqrt(np.maximum(dse_min * dse_min - l3_2, 0.0))
        l_max = np.sqrt(np.maximum(ws2 - e2, 0.0))
        lo = np.maximum(l_min - r40, self.r4_lo)
        hi = np.minimum(l_max - r40, self.r4_hi)
        return lo, hi

    def r1_kinks(self, r4: float) -> list[float]:
        """Track values where extend ``r4`` is exactly at the end of its reach interval."""
        dh = self.dh
        cm, sm = math.cos(self.stretch), math.sin(self.stretch)
        L = r4 + dh.r40
        dse = math.hypot(L, dh.l3)
        perp2 = self.W[1] ** 2 + (self.W[2] - dh.r2) ** 2
        c = self.W[0] - dh.r10
        out: list[float] = []
        for ws2 in ((dse + dh.r6 * cm) ** 2 + (dh.r6 * sm) ** 2, L * L + (dh.r6 - dh.l3) ** 2):
            if ws2 > perp2:
                d = math.sqrt(ws2 - perp2)
                out += [c - d, c + d]
        return [r for r in out if self.r1_lo <= r <= self.r1_hi]

    def r1_intervals(self) -> tuple[list[tuple[float, float]], float]:
        """Track intervals from which W is within reach, and the miss distance [m] if none."""
        dh = self.dh
        cm, sm = math.cos(self.stretch), math.sin(self.stretch)
        dse_max = math.hypot(self.r4_hi + dh.r40, dh.l3)
        ws_out = math.sqrt((dse_max + dh.r6 * cm) ** 2 + (dh.r6 * sm) ** 2)
        ws_in = math.sqrt((self.r4_lo + dh.r40) ** 2 + (dh.r6 - dh.l3) ** 2)
        perp = math.hypot(self.W[1], self.W[2] - dh.r2)
        c = self.W[0] - dh.r10
        # beyond the farthest reach from every track value: the miss is W's distance from the
        # shoulder's line segment over the track, less that reach (sideways, past an end, or
        # both at once)
        along = max(self.r1_lo - c, c - self.r1_hi, 0.0)
        outside = math.hypot(along, perp) - ws_out
        if outside > 0.0:
            return [], outside
        a_out = math.sqrt(ws_out * ws_out - perp * perp)
        a_in = math.sqrt(max(ws_in * ws_in - perp * perp, 0.0))
        out: list[tuple[float, float]] = []
        miss = math.inf
        for lo, hi in ((c - a_out, c - a_in), (c + a_in, c + a_out)):
            clo, chi = max(lo, self.r1_lo), min(hi, self.r1_hi)
            if clo <= chi:
                out.append((clo, chi))
            else:
                miss = min(miss, lo - self.r1_hi if lo > self.r1_hi else self.r1_lo - hi)
        if len(out) == 2 and out[0][1] >= out[1][0]:
            out = [(out[0][0], out[1][1])]
        return out, miss



def track_intervals(dh: DHConstants, wrist: Array, r1_lo: float, r1_hi: float, r4_lo: float,
                    r4_hi: float, stretch: float = 0.0) -> tuple[Array, Array]:
    """:meth:`Region.r1_intervals` for many wrist centres at once.

    Args:
        dh: DH constants.
        wrist: Wrist centres (n, 3) [m].
        r1_lo, r1_hi: Track limits [m].
        r4_lo, r4_hi: Extend limits [m].
        stretch: Stretch margin [rad].

    Returns:
        ``lo``, ``hi`` of shape (n, 2): the track interval behind and ahead of each target
        (merged into the first where they overlap); empty where ``lo > hi``.
    """
    cm, sm = math.cos(stretch), math.sin(stretch)
    dse_max = math.hypot(r4_hi + dh.r40, dh.l3)
    ws_out = math.sqrt((dse_max + dh.r6 * cm) ** 2 + (dh.r6 * sm) ** 2)
    ws_in = math.sqrt((r4_lo + dh.r40) ** 2 + (dh.r6 - dh.l3) ** 2)
    perp = np.hypot(wrist[:, 1], wrist[:, 2] - dh.r2)
    a_out = np.sqrt(np.maximum(ws_out * ws_out - perp * perp, 0.0))
    a_out = np.where(perp > ws_out, -np.inf, a_out)
    a_in = np.sqrt(np.maximum(ws_in * ws_in - perp * perp, 0.0))
    c = wrist[:, 0] - dh.r10
    lo = np.stack([c - a_out, c + a_in], axis=1)
    hi = np.stack([c - a_in, c + a_out], axis=1)
    lo, hi = np.maximum(lo, r1_lo), np.minimum(hi, r1_hi)
    both = (lo[:, 0] <= hi[:, 0]) & (lo[:, 1] <= hi[:, 1]) & (hi[:, 0] >= lo[:, 1])
    hi[both, 0] = hi[both, 1]
    lo[both, 1], hi[both, 1] = np.inf, -np.inf
    return lo, hi
