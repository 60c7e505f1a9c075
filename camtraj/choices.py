"""The named choices a run offers, in one place for the command line, the job files and the
stages that act on them (a module of its own, with no imports: the command line reads it
without loading the solver or USD)."""

from __future__ import annotations

__all__ = ["FOCAL_LENGTH_UNITS", "OBJECTIVES", "TIMING_MODES"]

TIMING_MODES = ("shot", "scale", "optimal")
"""How a take is timed: at the shot's own timing, slowed down uniformly, or retimed
time-optimally (:func:`camtraj.timing.time_shot`)."""
OBJECTIVES = ("shot", "paper")
"""What the IK solves for: the whole shot's take, or the papers' per-frame optimum
(:func:`camtraj.ik.solve_path`)."""
FOCAL_LENGTH_UNITS = ("schema", "mm")
"""``focalLength`` as the UsdGeom.Camera schema says (tenths of a scene unit), or
millimetres (:func:`camtraj.usd_shot.read_shot`)."""
