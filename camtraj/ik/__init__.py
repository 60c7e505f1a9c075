"""Inverse kinematics of the PRRPR-S camera robot.

Modules, from the core out:

* :mod:`~camtraj.ik.closed_form`: the six axes in closed form for fixed track and extend;
* :mod:`~camtraj.ik.region`: the analytic feasible region of (track, extend);
* :mod:`~camtraj.ik.sm`, :mod:`~camtraj.ik.sm_search`: the SM method's per-frame optimum of
  the papers' weighted motion F (the ``paper`` objective) and the dense traversal that checks
  it;
* :mod:`~camtraj.ik.shot_cost`, :mod:`~camtraj.ik.shot`, :mod:`~camtraj.ik.refine`: the
  whole-shot solver (the ``shot`` objective, the default): candidates, dynamic programme,
  continuous refinement;
* :mod:`~camtraj.ik.margins`: distances to limits and singularities;
* :mod:`~camtraj.ik.path`: a whole shot under either objective.
"""

from camtraj.ik.closed_form import N_BRANCHES, six_axis_solutions
from camtraj.ik.margins import PathMargins, path_margins
from camtraj.ik.path import (
    OBJECTIVES,
    MoveToStart,
    PathSolution,
    solve_path,
    solve_path_report,
)
from camtraj.ik.shot import camera_holds, camera_rests
from camtraj.ik.sm import IKSolution, motion_cost, solve_ik, traverse

__all__ = [
    "N_BRANCHES",
    "OBJECTIVES",
    "IKSolution",
    "MoveToStart",
    "PathMargins",
    "PathSolution",
    "camera_holds",
    "camera_rests",
    "motion_cost",
    "path_margins",
    "six_axis_solutions",
    "solve_ik",
    "solve_path",
    "solve_path_report",
    "traverse",
]
