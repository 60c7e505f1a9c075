"""``"optimal"`` timing: the same path retimed time-optimally with toppra.

toppra (and matplotlib, which it imports) is loaded only when this mode runs.
Units: SI (m, rad, s); the path parameter of toppra is normalised per moving stretch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.timing.limits import N_AXES, Limits, TimingLimitError
from camtraj.timing.path import FramePath, Samples, runs

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Relative slack for velocity and acceleration in "optimal" mode (toppra is discretised).
OPTIMAL_SLACK = 1e-3
#: toppra gridpoints per film-frame interval.
TOPPRA_GRID_PER_FRAME = 4



class _ToppraPath:
    """One moving stretch of the path for toppra: s in [0, 1] maps to frames a..b.

    toppra misbehaves with unnormalised path parameters, so s is normalised.
    """

    def __init__(self, path: FramePath, a: int, b: int) -> None:
        self._path = path
        self._a = a
        self._len = float(b - a)
        self.dof = N_AXES
        self.path_interval = np.array([0.0, 1.0])

    def __call__(self, ss: ArrayLike, order: int = 0) -> Array:
        s = np.atleast_1d(np.asarray(ss, dtype=np.float64))
        x = self._a + s * self._len
        values = self._path.at(x, order)[order] * self._len**order
        if np.ndim(ss) == 0:
            first: Array = values[0]
            return first
        return values


@dataclass(frozen=True, eq=False)
class _TimeLaw:
    """Piecewise constant path acceleration: x(t) on one moving stretch of frames a..b."""

    a: int
    b: int
    t_grid: Array  # (N+1,) time of each gridpoint from the stretch start [s]
    s_grid: Array  # (N+1,) normalised path parameter of each gridpoint
    sd: Array  # (N+1,) ds/dt at gridpoints [1/s]
    sdd: Array  # (N,) d²s/dt² on each grid interval [1/s²]

    def frame_times(self) -> Array:
        """Time of every frame a..b from the stretch start [s]."""
        per = (self.s_grid.size - 1) // (self.b - self.a)
        return self.t_grid[::per]

    def eval(self, t: Array) -> tuple[Array, Array, Array]:
        """Frame coordinate x, dx/dt, d²x/dt² at times t from the stretch start."""
        k = np.clip(np.searchsorted(self.t_grid, t, side="right") - 1, 0, self.sdd.size - 1)
        tau = t - self.t_grid[k]
        u = self.sdd[k]
        s = self.s_grid[k] + self.sd[k] * tau + 0.5 * u * tau**2
        s = np.clip(s, self.s_grid[k], self.s_grid[k + 1])
        sd = self.sd[k] + u * tau
        length = float(self.b - self.a)
        return self.a + s * length, sd * length, u * length

    def stretched(self, factor: float) -> _TimeLaw:
        """The same time law played ``factor`` times slower."""
        return _TimeLaw(self.a, self.b, self.t_grid * factor, self.s_grid, self.sd / factor,
                        self.sdd / factor**2)


def optimal(
    path: FramePath, limits: Limits, rate: float, scale_factor: float
) -> tuple[Array, Array, Samples, IntArray]:
    """Time-optimal traversal of the path under velocity and acceleration limits (toppra).

    Stretches where no axis moves are split out and kept as holds of their original length
    (toppra fails on them). Each moving stretch is retimed with toppra on a normalised path
    parameter, with gridpoints at the frames (subdivided). A stretch that starts or ends the
    shot does so at the path speed of ``"scale"`` mode (so the take is never slower than
    ``"scale"``, and the run-up and run-out are like those of ``"scale"``); a stretch next to
    a hold starts or ends at rest. toppra's constant-path-acceleration time law is sampled
    directly: every frame interval is cut into the fewest equal steps no longer than
    ``1 / rate``, so every frame is a sample. The sampled stream is verified; toppra's
    discretisation can overshoot a limit slightly, in which case that axis's limit is
    tightened and the stretch retimed, and as a last resort the stretch is slowed uniformly.

    Returns:
        Sample times of the shot part from the first frame [s], the frame coordinate of each
        sample, the samples, and the sample index of every frame.
    """
    n = path.n
    dt = path.dt
    still_all = np.all(path.still, axis=1)
    moving = runs(~still_all)
    laws: dict[int, _TimeLaw] = {}
    for a, b in moving:
        laws[a] = _retime_stretch(path, a, b, limits, scale_factor, dt, rate)

    # Frame times and per-interval sampling.
    frame_t = np.zeros(n)
    i = 0
    while i < n - 1:
        if i in laws:
            law = laws[i]
            frame_t[law.a : law.b + 1] = frame_t[law.a] + law.frame_times()
            i = law.b
        else:
            frame_t[i + 1] = frame_t[i] + dt
            i += 1

    # Every frame interval cut into the fewest equal steps no longer than 1 / rate; the
    # last frame is one more sample.
    durations = np.diff(frame_t)
    steps = np.maximum(1, np.ceil(durations * rate - 1e-9)).astype(np.int64)
    counts = np.concatenate([steps, [1]])
    frame_idx = np.concatenate([[0], np.cumsum(counts[:-1])]).astype(np.int64)
    interval = np.repeat(np.arange(n, dtype=np.int64), counts)
    j = np.arange(interval.size) - frame_idx[interval]
    frac = j / counts[interval]
    local = frac * np.concatenate([durations, [0.0]])[interval]
    t = frame_t[interval] + local
    x = interval + frac  # exact on frames; holds advance linearly at the original speed
    xd = np.full(t.size, 1.0 / dt)
    xdd = np.zeros(t.size)
    for law in laws.values():
        sel = (interval >= law.a) & (interval < law.b)
        sel[frame_idx[law.b]] = True  # the stretch's last frame belongs to it too
        xl, xdl, xddl = law.eval(t[sel] - frame_t[law.a])
        xd[sel], xdd[sel] = xdl, xddl
        on_frame = j[sel] == 0
        x[sel] = np.where(on_frame, x[sel], xl)
    samples = path.timed(x, xd, xdd, jerk_by_difference=True, t=t)
    return t, x, samples, frame_idx


def _retime_stretch(
    path: FramePath, a: int, b: int, limits: Limits, scale_factor: float, dt: float,
    rate: float,
) -> _TimeLaw:
    """toppra on frames a..b, verified by sampling; limits tightened where it overshoots."""
    # Imported here: toppra imports matplotlib (slow) and only this mode needs it.
    import toppra
    import toppra.algorithm
    import toppra.constraint

    length = float(b - a)
    n_grid = (b - a) * TOPPRA_GRID_PER_FRAME
    grid = np.arange(n_grid + 1, dtype=np.float64) / n_grid
    grid[-1] = 1.0
    tp_path = _ToppraPath(path, a, b)
    # Path speed of "scale" mode, in normalised parameter per second.
    sd_scale = 1.0 / (scale_factor * dt * length)
    sd_start = sd_scale if a == 0 else 0.0
    sd_end = sd_scale if b == path.n - 1 else 0.0

    vel = np.array(limits.velocity, dtype=np.float64)
    acc = np.array(limits.acceleration, dtype=np.float64)
    law: _TimeLaw | None = None
    for _attempt in range(4):
        constraints = [
            toppra.constraint.JointVelocityConstraint(vel),
            toppra.constraint.JointAccelerationConstraint(acc),
        ]
        law = None
        for start, end in ((sd_start, sd_end), (0.0, 0.0)):
            instance = toppra.algorithm.TOPPRA(
                constraints, tp_path, gridpoints=grid, solver_wrapper="seidel",
                parametrizer="ParametrizeConstAccel",
            )
            result = instance.compute_parameterization(start, end)
            sd = result[1]
            if sd is not None and np.all(np.isfinite(sd)):
                law = _law_from_sd(a, b, grid, np.asarray(sd, dtype=np.float64))
                if law is not None:
                    break
        if law is None:
            msg = (
                f"the time-optimal retime failed on frames {a}-{b} (toppra found no "
                "feasible timing); try --timing scale"
            )
            raise TimingLimitError(msg)
        kv, ka = _law_ratios(path, law, limits, rate)
        if np.all(kv <= 1.0 + 0.5 * OPTIMAL_SLACK) and np.all(ka <= 1.0 + 0.5 * OPTIMAL_SLACK):
            return law
        vel = vel / np.maximum(kv, 1.0) * (1.0 - 1e-4)
        acc = acc / np.maximum(ka, 1.0) * (1.0 - 1e-4)
    assert law is not None
    kv, ka = _law_ratios(path, law, limits, rate)
    factor = max(1.0, float(kv.max()), math.sqrt(float(ka.max()))) * (1.0 + 1e-6)
    return law.stretched(factor)


def _law_from_sd(a: int, b: int, grid: Array, sd: Array) -> _TimeLaw | None:
    ds = np.diff(grid)
    sd = np.maximum(sd, 0.0)
    mean = sd[:-1] + sd[1:]
    if np.any(mean <= 0):
        return None
    dts = 2.0 * ds / mean
    t_grid = np.concatenate([[0.0], np.cumsum(dts)])
    sdd = (sd[1:] ** 2 - sd[:-1] ** 2) / (2.0 * ds)
    if not (np.all(np.isfinite(t_grid)) and np.all(np.isfinite(sdd))):
        return None
    return _TimeLaw(a=a, b=b, t_grid=t_grid, s_grid=grid, sd=sd, sdd=sdd)


def _law_ratios(path: FramePath, law: _TimeLaw, limits: Limits, rate: float) -> tuple[
    Array, Array
]:
    """Peak |velocity| / limit and |acceleration| / limit per axis, sampled densely.

    Sampled at both ends and the middle of every grid interval (the path acceleration jumps
    at gridpoints, so both one-sided values count) and at the servo rate.
    """
    spans = np.diff(law.t_grid)
    mids = law.t_grid[:-1] + 0.5 * spans
    ends = law.t_grid[1:] - 1e-9 * spans
    servo = np.arange(0.0, float(law.t_grid[-1]), 1.0 / rate)
    t = np.concatenate([law.t_grid, mids, ends, servo])
    x, xd, xdd = law.eval(t)
    s = path.timed(x, xd, xdd)
    kv: Array = (np.abs(s.qd) / limits.velocity).max(axis=0)
    ka: Array = (np.abs(s.qdd) / limits.acceleration).max(axis=0)
    return kv, ka

