"""camtraj: previs USD camera moves to motion-control camera robot moves."""

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
