"""The file's clock: a take's samples at the whole nanoseconds the MCAP stamps them with.

The timing stage plans a take in exact times (a uniform take at ``k / rate``, an optimal one
at even steps of each frame's own duration); the file can only hold whole nanoseconds. Rounded
after sampling, the written positions sit up to half a nanosecond away from where the take is
at their stamps, and a reader that differences them over the stamps (it has no other times)
reads that as motion: third differences over steps of a few milliseconds turn half a
nanosecond at 2 m/s into 0.1-2% of a jerk limit. :func:`on_the_clock` instead stamps every
sample first and moves its position to where the take is at that stamp:

* every sample is stamped at its planned time rounded to the nanosecond;
* a film frame's stamp stands for the frame's planned time, so the frame keeps its position
  exactly (the frame's solution): the clock runs up to half a nanosecond from the plan there;
* between frames that offset is eased from one frame's to the next (a quintic easing, flat to
  second order at the frames; held before the first frame and after the last), so the
  clock's rate stays within 2 ns per frame interval of the plan's (5e-8 at 24 fps) and
  changes smoothly: a rate that jumped at each frame (each interval mapped linearly onto its
  stamps) kinked the velocity there, and the third differences of an optimal take of a 60 s
  sinusoid read 0.13% over the jerk limit (0.08% with the easing: the easing itself, up to a
  nanosecond over a 35 ms frame, is what remains);
* each position is moved from its planned time to the time its stamp stands for by the
  take's own derivatives (third order: exact for the splines and jerk-limited profiles the
  take is made of, and far below 1e-20 m from an optimal law over a nanosecond).

The velocities, accelerations and jerks stay the take's at the planned times (a nanosecond
and a relative 2 ns per frame interval from their values at the stamps), so they keep every
limit exactly as the timing stage checked them.

Where frames are one or two servo steps apart (240 fps at 250 Hz; 120 fps) the easing has no
room: every sample (or every other one) is a frame pinned to its solution, and a reader's
third differences still see the half-nanosecond roundings (0.5% of a jerk limit at 2 m/s with
one step per frame, 0.12% with two, 0.05% at 60 fps, 0.005% at 24 fps).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

_BLOCK = 4096  # rows moved at a time

#: [frames/s] The most film frames a take passes per second: a frame interval lasts at least
#: 4 ms. Each frame is a sample pinned to its solution, and a reader's third differences over
#: a frame interval of D see its stamp's half nanosecond as jerk growing with 1 / D^3 (0.5%
#: of a limit at 2 m/s and 4 ms): a 1 mm/s creep played 1000x faster by ``--timing optimal``
#: (frames 42 us apart, a 24 kHz servo rate outside --rate's range) read 1843x its track's
#: jerk limit. Takes faster than real time (``--timing optimal``) keep to it.
MAX_FRAME_RATE = 250.0


def on_the_clock(t: Array, frame_samples: IntArray, q: Array, qd: Array, qdd: Array,
                 qddd: Array) -> Array:
    """Stamp a take on the file's clock; ``q`` is moved in place to the stamps.

    Args:
        t: Planned sample times [s] (m,), increasing, steps far above a nanosecond.
        frame_samples: The sample of every film frame (n,), increasing.
        q, qd, qdd, qddd: Samples (m, axes) at ``t``; only ``q`` is changed.

    Returns:
        The stamps [s] (m,): whole nanoseconds, as the file holds them.
    """
    stamps = np.round(t * 1e9).astype(np.int64)  # as the MCAP writer rounds them
    if t.size > 1 and not np.all(np.diff(stamps) > 0):  # pragma: no cover - steps >= 10 us
        msg = "internal error: two servo samples share a nanosecond"
        raise RuntimeError(msg)
    clock = stamps / 1e9
    fs = np.asarray(frame_samples, dtype=np.int64)
    if fs.size == 0:
        msg = "a take has at least one film frame"
        raise ValueError(msg)
    lag = t[fs] - clock[fs]  # each frame's planned time after its stamp, |lag| <= 0.5 ns
    eased = np.full(t.size, lag[0])  # the lag at each sample: held before the first frame
    if fs.size >= 2:  # eased from frame to frame, held after the last
        first, last = int(fs[0]), int(fs[-1])
        i = np.searchsorted(fs, np.arange(first, last), side="right") - 1  # their intervals
        c0, c1 = clock[fs[i]], clock[fs[i + 1]]
        u = (clock[first:last] - c0) / (c1 - c0)
        ease = u * u * u * (10.0 + u * (6.0 * u - 15.0))  # 0 to 1, flat to 2nd order at both
        eased[first:last] = lag[i] + (lag[i + 1] - lag[i]) * ease
        eased[last:] = lag[-1]
    d = ((clock - t) + eased)[:, None]  # [s] from each planned time to its stamp's
    d[fs] = 0.0  # a frame's stamp is its planned time: its solution, exactly
    for a in range(0, t.size, _BLOCK):  # a block of rows at a time: no (m, axes) temporaries
        b = a + _BLOCK
        db = d[a:b]
        q[a:b] += db * (qd[a:b] + (db / 2.0) * (qdd[a:b] + (db / 3.0) * qddd[a:b]))
    return clock
