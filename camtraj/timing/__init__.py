"""Timing stage: the joint path of every film frame to a timed take at the servo rate.

Input is the inverse-kinematics solution of every film frame (``q_frames``, shape (n, 8),
[m, rad]; a lens adds its zoom, focus and iris motors as more columns, with their own limits)
at uniformly spaced ``frame_times`` [s]. Output is a :class:`Take`: position,
velocity, acceleration and jerk of every axis at every servo sample, from rest to rest.

The stages inside :func:`time_shot`, one module each:

1. **Path** (:mod:`~camtraj.timing.path`, :mod:`~camtraj.timing.quintic`). A quintic spline
   per axis through the frame solutions: still where the frames hold, natural (zero jerk) at
   the free ends, inside every position limit between frames.
2. **Real-time check** (:mod:`~camtraj.timing.limits`). The path is sampled at the servo rate
   with the shot's own timing and every limit is checked at every sample (not only at
   frames). This gives :attr:`TimingReport.max_speed` and :attr:`TimingReport.limiting`.
3. **Timing mode** (:mod:`~camtraj.timing.take`, :mod:`~camtraj.timing.optimal`). ``"shot"``
   keeps the film's timing (and raises :class:`TimingLimitError` if a limit is exceeded);
   ``"scale"`` slows the whole move uniformly by the smallest factor at which it and its
   run-up and run-out fit;
   ``"optimal"`` retimes the same path time-optimally under velocity, acceleration and jerk
   limits (scipy's linear programming, imported only then), or keeps the scale take.
4. **Run-up and run-out** (:mod:`~camtraj.timing.edges`). Jerk-limited ruckig moves from rest
   into the first frame's full state and from the last frame's state to rest; gentle by
   default (no more acceleration and jerk per axis than the shot uses, at least 25%).

Every film frame is a servo sample and the stream passes exactly through each frame's solution.

Units: SI throughout (m, rad, s); error messages show revolute axes in degrees.
"""

from camtraj.timing.limits import QUANTITIES, Limits, LimitViolation, TimingLimitError
from camtraj.timing.take import Take, TimingReport, feasible_speed, time_shot

__all__ = [
    "QUANTITIES",
    "LimitViolation",
    "Limits",
    "Take",
    "TimingLimitError",
    "TimingReport",
    "feasible_speed",
    "time_shot",
]
