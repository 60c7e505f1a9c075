"""What the timing tests share: the frame grid, a rest pose, and the divided differences they
check limits with (independent of the timing code's own derivatives)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

FPS = 24.0
HOME = np.array([5.0, 0.0, 0.0, 0.7, -1.5, 0.0, 0.0, 0.0])
"""A pose inside every limit, away from the wrist singularity [m, rad]."""
SLACK = 1e-3
"""The brief's numerical slack for limits checked by finite differences."""


def frame_times(n: int, fps: float = FPS) -> Array:
    """Times [s] of ``n`` film frames from t = 0."""
    out: Array = np.arange(n) / fps
    return out


def divided(t: Array, y: Array, order: int) -> Array:
    """``order! * y[t_i, ..., t_{i+order}]`` per column: the mean-value estimate of y's
    ``order``-th derivative between the samples."""
    d = y.copy()
    for level in range(1, order + 1):
        d = (d[1:] - d[:-1]) / (t[level:] - t[:-level])[:, None]
    out: Array = d * math.factorial(order)
    return out
