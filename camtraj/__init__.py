"""camtraj: previs USD camera moves to motion-control camera robot moves.

The names below load on first use, so that ``import camtraj`` (and the command line, which
handles signals before anything heavy is imported) starts quickly.
"""

from __future__ import annotations

TYPE_CHECKING = False  # not typing's: importing typing costs the command line's start time
if TYPE_CHECKING:
    from typing import Any

    from camtraj.errors import (
        CamtrajError,
        InfeasibleError,
        InputError,
        LimitError,
        RobotFileError,
        ShotFileError,
        UnreachableError,
        UnreachableFramesError,
    )
    from camtraj.ik import IKSolution, solve_ik, solve_path
    from camtraj.robot import JOINT_NAMES, Robot

__version__ = "0.1.0"

_ERRORS = "camtraj.errors"
_LAZY = {
    "CamtrajError": _ERRORS,
    "InfeasibleError": _ERRORS,
    "InputError": _ERRORS,
    "LimitError": _ERRORS,
    "RobotFileError": _ERRORS,
    "ShotFileError": _ERRORS,
    "UnreachableError": _ERRORS,
    "UnreachableFramesError": _ERRORS,
    "IKSolution": "camtraj.ik",
    "solve_ik": "camtraj.ik",
    "solve_path": "camtraj.ik",
    "JOINT_NAMES": "camtraj.robot",
    "Robot": "camtraj.robot",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    msg = f"module 'camtraj' has no attribute {name!r}"
    raise AttributeError(msg)


__all__ = [
    "JOINT_NAMES",
    "CamtrajError",
    "IKSolution",
    "InfeasibleError",
    "InputError",
    "LimitError",
    "Robot",
    "RobotFileError",
    "ShotFileError",
    "UnreachableError",
    "UnreachableFramesError",
    "__version__",
    "solve_ik",
    "solve_path",
]
