"""The ``shot`` objective: what a whole-shot choice of (track, extend, branch) minimises.

For a joint path q (n, 8) at frame interval dt, with per-axis usages of the robot's limits

    z1 = dq / (v_max dt),   z2 = d2q / (a_max dt^2),   z3 = d3q / (j_max dt^3)

(finite differences between consecutive frames), the objective is

    J = sum over transitions and axes of  motion * m_i |z1| + velocity * z1^2
                                        + overspeed * max(0, |z1| - 1)^2
      + sum over frames of  acceleration * z2^2 + jerk * z3^2
      + margin * sum over frames of the squared margin intrusions
        max(0, 1 - d / zone)^2 for every axis's distance d to its nearer position limit, the
        wrist singularity distance and the full-stretch distance (:mod:`camtraj.ik.margins`).

``m_i = w_i v_i / sum(w v)``: the papers' weighted motion F in units of "every axis moving one
frame at its velocity limit", so ``motion * sum(m |z1|)`` is F rescaled. The first-order terms
(motion, velocity, overspeed) and the margins are what the dynamic programme sees; acceleration
and jerk join in the continuous refinement. The first frame carries no motion term: the run-up
brings the robot there, whatever the start. A shot that starts or ends in motion needs room for
its run-up and run-out: the first and last frames' positions pushed out by each axis's stopping
distance at its edge velocity carry the same margin cost (``edge_cost``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from camtraj.robot import PRISMATIC, REVOLUTE, Robot

Array = NDArray[np.float64]

TWO_PI = 2.0 * math.pi
N_MEASURES = 10  # the 8 joints, the wrist singularity distance, the full-stretch distance


@dataclass(frozen=True)
class ShotCost:
    """The objective of :mod:`camtraj.ik.shot_cost` for one robot and frame interval.

    Attributes:
        lower, upper: Position limits (8,) [m, rad].
        vel, acc, jerk: What each axis may do in one frame interval: v_max dt, a_max dt^2,
            j_max dt^3 (8,).
        motion_coef: ``motion * m_i`` (8,).
        velocity, overspeed, acceleration, jerk_weight, margin: The weights.
        zone: Width of the margin zone (10,): per axis [m, rad], then wrist and stretch [rad].
    """

    lower: Array
    upper: Array
    vel: Array
    acc: Array
    jerk: Array
    motion_coef: Array
    velocity: float
    overspeed: float
    acceleration: float
    jerk_weight: float
    margin: float
    zone: Array
    dt: float
    a_max: Array
    j_max: Array

    @classmethod
    def for_robot(cls, robot: Robot, dt: float) -> ShotCost:
        s = robot.ik
        vel = robot.max_velocity * dt
        wv = robot.weights * vel
        zone_axes = np.where(PRISMATIC, s.limit_margin_prismatic, s.limit_margin_revolute)
        return cls(
            lower=robot.lower, upper=robot.upper, vel=vel,
            acc=robot.max_acceleration * dt * dt, jerk=robot.max_jerk * dt ** 3,
            motion_coef=s.motion_weight * wv / max(float(wv.sum()), 1e-300),
            velocity=s.velocity_weight, overspeed=s.overspeed_weight,
            acceleration=s.acceleration_weight, jerk_weight=s.jerk_weight,
            margin=s.margin_weight,
            zone=np.concatenate([zone_axes, [s.wrist_margin, s.stretch_margin]]),
            dt=dt, a_max=robot.max_acceleration, j_max=robot.max_jerk,
        )

    # -- parts -----------------------------------------------------------------------------
    def steps(self, qa: Array, qb: Array) -> Array:
        """Velocity usage z1 (..., 8) of a step from qa to qb (revolute differences wrapped)."""
        d = qb - qa
        d = np.where(REVOLUTE, d - TWO_PI * np.rint(d * (1.0 / TWO_PI)), d)
        return np.asarray(d / self.vel)

    def axis_step_cost(self, axis: int, d: Array) -> Array:
        """:meth:`first_order`'s share of one axis for steps ``d`` (any shape) [m, rad]."""
        if REVOLUTE[axis]:
            d = d - TWO_PI * np.rint(d * (1.0 / TWO_PI))
        a = np.abs(d)
        a *= 1.0 / self.vel[axis]
        out = a * self.velocity
        out += self.motion_coef[axis]
        out *= a
        if a.size and a.max() > 1.0:  # the overspeed penalty, where a step exceeds v_max
            a -= 1.0
            np.maximum(a, 0.0, out=a)
            a *= a
            a *= self.overspeed
            out += a
        return np.asarray(out)

    def first_order(self, z1: Array) -> Array:
        """Motion, velocity and overspeed cost of steps with usages z1 (..., 8): (...)."""
        a = np.abs(z1)
        over = np.maximum(a - 1.0, 0.0)
        return np.asarray(a @ self.motion_coef + self.velocity * (z1 * z1).sum(axis=-1)
                          + self.overspeed * (over * over).sum(axis=-1))

    def intrusion(self, y: Array) -> Array:
        """Margin intrusions max(0, 1 - d / zone) (..., 10) of measures y (..., 10)."""
        d = np.concatenate([np.minimum(y[..., :8] - self.lower, self.upper - y[..., :8]),
                            y[..., 8:]], axis=-1)
        return np.asarray(np.maximum(1.0 - d / self.zone, 0.0))

    def unary(self, y: Array) -> Array:
        """Margin cost (...) of frames with measures y (..., 10)."""
        e = self.intrusion(y)
        return np.asarray(self.margin * (e * e).sum(axis=-1))

    def stop_distance(self, v: Array) -> tuple[Array, Array]:
        """Shortest stopping distance (..., 8) [m, rad] of each axis from speed ``v`` >= 0
        (no initial acceleration) within its acceleration and jerk limits, and its derivative
        in ``v``."""
        a, j = self.a_max, self.j_max
        big = v >= a * a / j
        root = np.sqrt(np.maximum(v, 0.0) / j)
        d = np.where(big, 0.5 * v * (v / a + a / j), v * root)
        dd = np.where(big, v / a + 0.5 * a / j, 1.5 * root)
        return np.asarray(d), np.asarray(dd)

    def edge_excursion(self, q_edge: Array, q_inner: Array) -> tuple[Array, Array]:
        """Where the run-up starts (or the run-out stops) at least: the edge frame's position
        pushed out by the stopping distance of its velocity, (..., 8), and d p / d q_edge
        (d p / d q_inner is 1 minus it)."""
        d = q_edge - q_inner
        d = np.where(REVOLUTE, d - TWO_PI * np.rint(d * (1.0 / TWO_PI)), d)
        dist, slope = self.stop_distance(np.abs(d) / self.dt)
        return np.asarray(q_edge + np.sign(d) * dist), np.asarray(1.0 + slope / self.dt)

    def edge_intrusion(self, p: Array) -> Array:
        """Margin intrusions (..., 8) of run-up / run-out excursions ``p`` (..., 8)."""
        d = np.minimum(p - self.lower, self.upper - p)
        return np.asarray(np.maximum(1.0 - d / self.zone[:8], 0.0))

    def edge_cost(self, q_edge: Array, q_inner: Array) -> Array:
        """Margin cost (...) of the run-up or run-out room at a shot's end frame."""
        e = self.edge_intrusion(self.edge_excursion(q_edge, q_inner)[0])
        return np.asarray(self.margin * (e * e).sum(axis=-1))

    def total(self, y: Array) -> float:
        """J of a continuous path with measures y (n, 10) (joints unwrapped)."""
        q = y[:, :8]
        j = float(self.unary(y).sum())
        if q.shape[0] > 1:
            j += float(self.first_order(np.diff(q, axis=0) / self.vel).sum())
            j += float(self.edge_cost(q[0], q[1]) + self.edge_cost(q[-1], q[-2]))
        if q.shape[0] > 2:
            z2 = np.diff(q, 2, axis=0) / self.acc
            j += self.acceleration * float((z2 * z2).sum())
        if q.shape[0] > 3:
            z3 = np.diff(q, 3, axis=0) / self.jerk
            j += self.jerk_weight * float((z3 * z3).sum())
        return j
