"""The servo samples reduced to what the report shows, a block of samples at a time.

A long take has millions of servo samples; the report shows a few numbers per axis, a few per
film frame and plots a few hundred pixels wide. :func:`reduce_samples` folds blocks of samples
into a :class:`Samples` whose size depends on the film frames and the plot width only:

- per plot (axis and quantity, as a fraction of the limit) the minimum and the maximum of each
  pixel column (bucket of take time), each a real sample, so every peak and every violation
  stays visible (a take of at most ``2 * columns`` samples keeps them all);
- per film frame the peak use of each limit over the samples that count for it (a sample
  between two frames counts for both, the run-up for the first, the run-out for the last);
- the shot's peak use, the run-up's and run-out's peak use and their extents.

:func:`jerk_by_differences` gives a take read back from MCAP its jerk, block by block.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from camtraj.timing.limits import QUANTITIES

Array = NDArray[np.float64]
Block = tuple[Array, Array, Array, Array, Array]  # t, q, qd, qdd, qddd

#: Pixel columns of a plot; servo samples are reduced to a min/max pair per column.
ENVELOPE_COLUMNS = 700
#: Float noise allowed when a sample time is compared with a film frame's time [s].
EPS = 1e-9
BLOCK = 8192


@dataclass(frozen=True, eq=False)
class Samples:
    """What the report keeps of the servo samples.

    Attributes:
        count: Number of servo samples. start, end: First and last sample time [s].
        curves: ``(quantity, axis)`` -> ``(t, y)``: the fraction of the limit (±1 at the
            limits; position: ±1 at the bounds) reduced to its minimum and maximum per
            column, real samples in time order.
        frame_peak: Peak ``|fraction|`` per quantity, film frame and axis, (4, n, 8).
        shot_peak: Peak ``|fraction|`` over the shot part (first to last film frame), (4, 8).
        edge_peak: The same over the run-up (before the first frame) and the run-out
            (after the last), (2, 4, 8).
        edge_extent: Travel (max - min position) of the run-up (up to the first frame) and
            the run-out (from the last frame), (2, 8) [m or rad].
    """

    count: int
    start: float
    end: float
    curves: dict[tuple[str, int], tuple[Array, Array]]
    frame_peak: Array
    shot_peak: Array
    edge_peak: Array
    edge_extent: Array


def fractions(q: Array, qd: Array, qdd: Array, qddd: Array, lower: Array, upper: Array,
              limits: tuple[Array, Array, Array]) -> Array:
    """Each quantity as a fraction of its limit, (4, m, 8): ±1 at the limits.

    Position: ``(q - mid) / half_range`` (the timing report's position use, signed).
    """
    mid, half = 0.5 * (upper + lower), 0.5 * (upper - lower)
    return np.stack([(q - mid) / half, qd / limits[0], qdd / limits[1], qddd / limits[2]])


def _runs(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """Start index of each run of equal values in a non-decreasing array."""
    out: NDArray[np.int64] = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    return out


class _Reducer:
    """Folds blocks of samples, in time order, into :class:`Samples`."""

    def __init__(self, count: int, start: float, end: float, frame_times: Array,
                 shot: tuple[float, float], lower: Array, upper: Array,
                 limits: tuple[Array, Array, Array], columns: int) -> None:
        self.count, self.start, self.end = count, start, end
        self.frame_times, self.shot = frame_times, shot
        self.lower, self.upper, self.limits = lower, upper, limits
        self.columns = columns
        w = lower.shape[0]
        self.keep_all = count <= 2 * columns or end <= start
        self.kept: list[tuple[Array, Array]] = []  # (t, fractions (m, 4w)) of a short take
        self.lo = np.full((columns, 4 * w), np.inf)
        self.hi = np.full((columns, 4 * w), -np.inf)
        self.t_lo = np.zeros((columns, 4 * w))
        self.t_hi = np.zeros((columns, 4 * w))
        self.frame_peak = np.zeros((4, frame_times.shape[0], w))
        self.shot_peak = np.zeros((4, w))
        self.edge_peak = np.zeros((2, 4, w))
        self.q_lo = np.full((2, w), np.inf)
        self.q_hi = np.full((2, w), -np.inf)

    def add(self, t: Array, q: Array, qd: Array, qdd: Array, qddd: Array) -> None:
        if not t.size:
            return
        fr = fractions(q, qd, qdd, qddd, self.lower, self.upper, self.limits)
        use = np.abs(fr)
        ft, last = self.frame_times, self.frame_times.shape[0] - 1
        for idx in (np.clip(np.searchsorted(ft, t - EPS, side="left"), 0, last),
                    np.clip(np.searchsorted(ft, t + EPS, side="right") - 1, 0, last)):
            starts = _runs(idx)
            frames = idx[starts]
            self.frame_peak[:, frames] = np.maximum(self.frame_peak[:, frames],
                                                    np.maximum.reduceat(use, starts, axis=1))
        a, b = self.shot
        for mask, peak in (((t >= a - EPS) & (t <= b + EPS), self.shot_peak),
                           (t < a - EPS, self.edge_peak[0]), (t > b + EPS, self.edge_peak[1])):
            if np.any(mask):
                np.maximum(peak, use[:, mask].max(axis=1), out=peak)
        for k, mask in enumerate((t <= a + EPS, t >= b - EPS)):
            if np.any(mask):
                np.minimum(self.q_lo[k], q[mask].min(axis=0), out=self.q_lo[k])
                np.maximum(self.q_hi[k], q[mask].max(axis=0), out=self.q_hi[k])
        y = fr.transpose(1, 0, 2).reshape(t.shape[0], -1)  # (m, 4w): quantity-major
        if self.keep_all:
            self.kept.append((t, y))
        else:
            self._columns(t, y)

    def _columns(self, t: Array, y: Array) -> None:
        """Each column's minimum and maximum, the first sample holding each."""
        col = np.minimum(((t - self.start) / (self.end - self.start) * self.columns)
                         .astype(np.int64), self.columns - 1)
        starts = _runs(col)
        lengths = np.diff(np.r_[starts, t.shape[0]])
        c = col[starts]
        where = np.arange(t.shape[0])[:, None]
        for best, t_best, reduce, better in ((self.lo, self.t_lo, np.minimum, np.less),
                                             (self.hi, self.t_hi, np.maximum, np.greater)):
            value = reduce.reduceat(y, starts, axis=0)
            hit = y == np.repeat(value, lengths, axis=0)
            first = np.minimum.reduceat(np.where(hit, where, t.shape[0]), starts, axis=0)
            first = np.minimum(first, t.shape[0] - 1)  # NaN columns: any sample
            new = better(value, best[c])  # an earlier block keeps equal values
            best[c] = np.where(new, value, best[c])
            t_best[c] = np.where(new, t[first], t_best[c])

    def result(self) -> Samples:
        w = self.lower.shape[0]
        curves: dict[tuple[str, int], tuple[Array, Array]] = {}
        if self.keep_all:
            t = np.concatenate([k[0] for k in self.kept]) if self.kept else np.zeros(0)
            y = (np.concatenate([k[1] for k in self.kept]) if self.kept
                 else np.zeros((0, 4 * w)))
            for s in range(4 * w):
                curves[(QUANTITIES[s // w], s % w)] = (t, y[:, s].copy())
        else:
            seen = np.isfinite(self.lo) | np.isfinite(self.hi)
            for s in range(4 * w):
                v = seen[:, s]
                ts = np.concatenate([self.t_lo[v, s], self.t_hi[v, s]])
                ys = np.concatenate([self.lo[v, s], self.hi[v, s]])
                t_out, first = np.unique(ts, return_index=True)
                curves[(QUANTITIES[s // w], s % w)] = (t_out, ys[first])
        extent = np.where(np.isfinite(self.q_lo), self.q_hi - self.q_lo, 0.0)
        return Samples(self.count, self.start, self.end, curves, self.frame_peak,
                       self.shot_peak, self.edge_peak, extent)


def reduce_samples(
    blocks: Iterable[Block],
    *,
    count: int,
    start: float,
    end: float,
    frame_times: Array,
    shot: tuple[float, float],
    lower: Array,
    upper: Array,
    limits: tuple[Array, Array, Array],
    columns: int = ENVELOPE_COLUMNS,
) -> Samples:
    """Fold servo samples into what the report shows.

    Args:
        blocks: ``(t, q, qd, qdd, qddd)`` blocks in time order, ``count`` samples in all.
        start, end: The first and the last sample time [s] (the plots' time range).
        frame_times: The film frames' take times [s], (n,), non-decreasing.
        shot: Take time of the first and the last film frame [s].
        lower, upper: Position limits, (8,). limits: Velocity, acceleration, jerk limits.
        columns: Plot columns.
    """
    reducer = _Reducer(count, start, end, frame_times, shot, lower, upper, limits, columns)
    for block in blocks:
        reducer.add(*block)
    return reducer.result()


def in_blocks(t: Array, q: Array, qd: Array, qdd: Array, qddd: Array,
              size: int = BLOCK) -> Iterator[Block]:
    """Arrays already in memory as blocks for :func:`reduce_samples`."""
    for a in range(0, t.shape[0], size):
        yield t[a:a + size], q[a:a + size], qd[a:a + size], qdd[a:a + size], qddd[a:a + size]


def jerk_by_differences(
    blocks: Iterable[tuple[Array, Array, Array, Array]], count: int, shot: tuple[int, int]
) -> Iterator[Block]:
    """Blocks ``(t, q, qd, qdd)`` with their jerk by differences of the accelerations.

    Central differences (one-sided at the ends): each value is a weighted mean of the mean
    jerks over the neighbouring steps, so it never overstates the true peak. No difference
    spans the switch from the run-up to the shot's path or from it to the run-out (``shot``:
    the sample indices of the first and the last film frame, which keep the shot's values).
    Each block is extended by a sample on each side, so the values are those of the whole
    take's differences.
    """
    a, b = shot
    parts = ((0, a, 0, a - 1), (a, b, a, b), (b, count - 1, b + 1, count - 1))
    pending: tuple[int, tuple[Array, Array, Array, Array]] | None = None
    before: tuple[Array, Array] | None = None  # the last (t, qdd) sample before `pending`

    def done(first: int, block: tuple[Array, Array, Array, Array],
             after: tuple[Array, Array] | None) -> Block:
        t, q, qd, qdd = block
        pre = [] if before is None else [before]
        post = [] if after is None else [after]
        t_ext = np.concatenate([p[0] for p in pre] + [t] + [p[0] for p in post])
        a_ext = np.concatenate([p[1] for p in pre] + [qdd] + [p[1] for p in post])
        g0 = first - len(pre)  # global index of t_ext[0]
        g1 = g0 + t_ext.shape[0] - 1
        jerk = np.zeros_like(qdd)
        last = first + t.shape[0] - 1
        for lo, hi, keep_lo, keep_hi in parts:
            p0, p1 = max(lo, g0), min(hi, g1)
            k0, k1 = max(keep_lo, first), min(keep_hi, last)
            if p1 > p0 and k1 >= k0 and hi > lo:
                diff = np.gradient(a_ext[p0 - g0:p1 - g0 + 1], t_ext[p0 - g0:p1 - g0 + 1],
                                   axis=0)
                jerk[k0 - first:k1 - first + 1] = diff[k0 - p0:k1 - p0 + 1]
        return t, q, qd, qdd, jerk

    first = 0
    for block in blocks:
        if pending is not None:
            yield done(pending[0], pending[1], (block[0][:1], block[3][:1]))
            before = (pending[1][0][-1:], pending[1][3][-1:])
        pending = (first, block)
        first += block[0].shape[0]
    if pending is not None:
        yield done(pending[0], pending[1], None)
