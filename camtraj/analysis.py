"""What one run computed: the robot's placement on set and the :class:`Analysis` of a shot.

``convert`` (and ``check``) fill an :class:`Analysis`; the report, the summary and the MCAP
read it. It lives in its own module so that what reads it does not import what makes it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from camtraj.ik import PathSolution
    from camtraj.robot import Robot
    from camtraj.timing import Limits, Take
    from camtraj.usd_shot import Shot

__all__ = ["DEFAULT_SOURCE", "Analysis", "Placement", "axis_value", "camera_travel",
           "margins_summary", "placement_text", "take_axes",
           "take_limits"]

Array = NDArray[np.float64]


DEFAULT_SOURCE = "default (identity)"
"""The source of the placement at the stage origin (no ``--placement``, no set file's)."""


@dataclass(frozen=True)
class Placement:
    """Where the robot base stands in the stage (metres, Z-up after unit/axis conversion).

    ``base2world`` maps robot base coordinates into the converted stage world.
    """

    base2world: Array = field(default_factory=lambda: np.eye(4))
    source: str = DEFAULT_SOURCE
    overrides: str | None = None
    """The set file's placement that this one (``--placement``) replaces, as
    :func:`placement_text` shows it; None when nothing was replaced."""
    notes: tuple[str, ...] = ()
    """What a person should know of where it stands (warnings of the run): a set file with no
    placement of its own, a rail over the set file's keep-outs or off its floor region."""

    @classmethod
    def from_xyz_yaw(cls, x: float, y: float, z: float, yaw_deg: float,
                     source: str = "--placement") -> Placement:
        """x, y, z [m] and yaw [deg] about up, as a set file's ``[placement]`` means them."""
        from camtraj.set_file import yaw_pose

        return cls(yaw_pose(x, y, z, yaw_deg), source)

    def describe(self) -> dict[str, Any]:
        R = self.base2world[:3, :3]
        return {
            "source": self.source,
            "translation_m": self.base2world[:3, 3].tolist(),
            "yaw_deg": math.degrees(math.atan2(R[1, 0], R[0, 0])),
            "rotation": R.tolist(),
        }


def placement_text(desc: dict[str, Any]) -> str:
    """A placement (:meth:`Placement.describe`) for people: where the base stands and from
    which file or option."""
    x, y, z = desc.get("translation_m", (0.0, 0.0, 0.0))
    return (f"x {x:.3f} m, y {y:.3f} m, z {z:.3f} m, yaw {desc.get('yaw_deg', 0.0):.2f} deg "
            f"({desc.get('source', '?')})")


@dataclass
class Analysis:
    """Everything one run computed; ``take`` is None when the IK or timing stage failed."""

    shot: Shot
    robot: Robot
    placement: Placement
    targets: Array  # (n, 4, 4) camera2base
    path: PathSolution | None = None
    take: Take | None = None
    timings: dict[str, float] = field(default_factory=dict)
    collision: dict[str, Any] | None = None  # what the collision check found, if it ran
    lens_q: Array | None = None  # (n, lens axes) lens motor positions per frame [rad]
    warnings: list[str] | None = None  # convert.run_warnings, once the take is made


def axis_value(name: str, value: float) -> float:
    """SI value for display: degrees for revolute axes and lens motors (ring angles), metres
    otherwise."""
    from camtraj.robot import JOINT_NAMES, REVOLUTE

    revolute = name not in JOINT_NAMES or REVOLUTE[JOINT_NAMES.index(name)]
    return math.degrees(value) if revolute else value


def take_limits(robot: Robot) -> Limits:
    """The limits of a take's axes: the robot's joints, then its lens's motors where it has a
    lens (convert, place and the report all time a shot so)."""
    from camtraj.timing import Limits

    limits = Limits.from_robot(robot)
    return limits if robot.lens is None else limits.joined(robot.lens.limits())


def take_axes(robot: Robot, q: Array, lens_q: Array | None) -> tuple[Array, Limits]:
    """The axes a take times and their limits (:func:`take_limits`): the joint path q (n, 8),
    then the lens's motor positions ``lens_q`` (n, k) where there are any."""
    from camtraj.timing import Limits

    if robot.lens is None or lens_q is None:
        return q, Limits.from_robot(robot)
    return np.hstack([q, lens_q]), take_limits(robot)


def margins_summary(analysis: Analysis) -> dict[str, Any]:
    """Smallest distances to the position limits (per axis, the lens motors after the
    joints), the wrist singularity and full stretch over the shot, with the film frame where
    each occurs (degrees / metres). Needs ``analysis.path``."""
    from camtraj.robot import JOINT_NAMES

    assert analysis.path is not None
    m, frames = analysis.path.margins, analysis.shot.frames
    to_limits = {k: axis_value(k, float(v)) for k, v in zip(JOINT_NAMES, m.to_limits,
                                                            strict=True)}
    at = {k: int(frames[i]) for k, i in zip(JOINT_NAMES, m.to_limits_frame, strict=True)}
    lens = analysis.robot.lens
    if lens is not None and analysis.lens_q is not None:
        lim = lens.limits()
        room = np.minimum(analysis.lens_q - lim.lower, lim.upper - analysis.lens_q)
        for j, name in enumerate(lens.names):
            k = int(np.argmin(room[:, j]))
            to_limits[name] = axis_value(name, float(room[k, j]))
            at[name] = int(frames[k])
    return {
        "to_limits": to_limits,
        "to_limits_frame": at,
        "wrist_singularity_deg": math.degrees(m.wrist),
        "wrist_singularity_frame": int(frames[m.wrist_frame]),
        "full_stretch_deg": math.degrees(m.stretch),
        "full_stretch_frame": int(frames[m.stretch_frame]),
    }


def camera_travel(analysis: Analysis) -> tuple[tuple[float, float], tuple[float, float]]:
    """How far the camera moves [m] and turns [deg] from its first frame's pose during the
    run-up, and from its last frame's during the run-out, at most (a robot whose redundant
    axes still move on a frame where the camera is at rest swings the camera around it:
    ``--edges still``)."""
    take, robot = analysis.take, analysis.robot
    assert take is not None
    out = []
    for part, frame in ((slice(0, int(take.frame_samples[0]) + 1), int(take.frame_samples[0])),
                        (slice(int(take.frame_samples[-1]), None), int(take.frame_samples[-1]))):
        at = robot.camera_pose(take.q[part, :8])
        here = robot.camera_pose(take.q[frame, :8])
        moved = float(np.linalg.norm(at[:, :3, 3] - here[:3, 3], axis=1).max())
        # the angle of each pose's rotation from the frame's: trace(R0^T R) = 1 + 2 cos
        cos = (np.einsum("ij,kij->k", here[:3, :3], at[:, :3, :3]) - 1.0) / 2.0
        out.append((moved, math.degrees(float(np.arccos(np.clip(cos, -1.0, 1.0)).max()))))
    return out[0], out[1]
