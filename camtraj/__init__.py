"""camtraj: previs USD camera moves to motion-control camera robot moves.

The names below load on first use, so that ``import camtraj`` (and the command line, which
handles signals before anything heavy is imported) starts quickly.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

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

if TYPE_CHECKING:
    from camtraj.ik import IKSolution, solve_ik, solve_path
    from camtraj.robot import JOINT_NAMES, Robot

__version__ = "0.1.0"

_LAZY = {
    "IKSolution": "camtraj.ik",
    "solve_ik": "camtraj.ik",
    "solve_path": "camtraj.ik",
    "JOINT_NAMES": "camtraj.robot",
    "Robot": "camtraj.robot",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
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
