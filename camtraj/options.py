"""Convert options, and their command-line form shared by convert, check, batch and farm.

Light on purpose (no numpy, scipy or USD): a batch parent, ``farm export`` and ``--help`` import
it without loading the pipeline.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import click

from camtraj.choices import FOCAL_LENGTH_UNITS, OBJECTIVES, TIMING_MODES
from camtraj.errors import InputError

EDGE_OPTIONS = ("gentle", "fast", "still")
"""--edges: the timing stage's run-up and run-out modes, and still (gentle ends where the
camera does not rest; the robot still on an end frame where it does)."""
F = TypeVar("F", bound=Callable[..., Any])
RATE_RANGE = (10.0, 10000.0)
"""The servo rates a take may be sampled at [Hz]."""


@dataclass(frozen=True)
class ConvertOptions:
    """Options of ``camtraj convert`` / ``check`` (the CLI maps its flags onto these).

    Attributes:
        camera: Camera prim path; default the stage's only camera.
        robot: Robot description file; default the built-in robot.
        placement: Robot base in the stage as (x, y, z [m], yaw [deg]); default identity.
        set_file: A TOML file with a ``[placement]`` table (used when ``placement`` is None).
        frames: Inclusive film frame range (first, last); default the stage's range.
        rate: Requested servo rate [Hz].
        timing: ``"shot"`` (keep the film's timing), ``"scale"`` or ``"optimal"`` (jerk-limited
            time-optimal retime).
        start_from: Joint vector (8,) [m, rad] the robot starts from; default its home.
        objective: IK objective override (``"shot"`` or ``"paper"``).
        focal_length_unit: ``"schema"`` (USD's tenths of a scene unit) or ``"mm"`` (what some
            older exporters write).
        clearance: Distance the robot must keep from the set file's obstacles [m]; default
            the set file's ``[collision] clearance_m``.
        edges: How the run-up and run-out move: ``"still"`` (the default: where the camera
            is at rest on the first or last frame, an eased start or stop, the robot stands
            still there too, its velocity zero on that frame, and its acceleration too where
            the camera settles into it, and the solver plans for it;
            elsewhere as gentle), ``"gentle"`` (per axis no more of the acceleration and
            jerk limits than the shot uses, at least a quarter of them; the robot may move
            on a still end frame, for a take up to 16% faster on the shot set's moves it
            changes) or ``"fast"``
            (the full limits: the shortest, time-optimal run-up and run-out).
        lens: A lens file (:mod:`camtraj.lens`): its zoom, focus and iris motors are timed
            and written with the joints; default the robot file's ``[lens]``, if any.
    """

    camera: str | None = None
    robot: str | None = None
    placement: tuple[float, float, float, float] | None = None
    set_file: str | None = None
    frames: tuple[int, int] | None = None
    rate: float = 250.0
    timing: str = "shot"
    start_from: tuple[float, ...] | None = None
    objective: str | None = None
    focal_length_unit: str = "schema"
    clearance: float | None = None
    edges: str = "still"
    lens: str | None = None

    def __post_init__(self) -> None:
        if self.timing not in TIMING_MODES:
            msg = f"timing must be one of {', '.join(TIMING_MODES)}, got {self.timing!r}"
            raise InputError(msg)
        if not (math.isfinite(self.rate) and RATE_RANGE[0] <= self.rate <= RATE_RANGE[1]):
            msg = (f"rate must be between {RATE_RANGE[0]:g} and {RATE_RANGE[1]:g} Hz, got "
                   f"{self.rate}")
            raise InputError(msg)
        if self.start_from is not None and len(self.start_from) != 8:
            msg = f"start-from needs 8 joint values, got {len(self.start_from)}"
            raise InputError(msg)
        if self.objective is not None and self.objective not in OBJECTIVES:
            msg = f"objective must be one of {', '.join(OBJECTIVES)}, got {self.objective!r}"
            raise InputError(msg)
        if self.focal_length_unit not in FOCAL_LENGTH_UNITS:
            msg = (
                f"focal-length-unit must be one of {', '.join(FOCAL_LENGTH_UNITS)}, "
                f"got {self.focal_length_unit!r}"
            )
            raise InputError(msg)
        if self.clearance is not None and not 0.0 <= self.clearance <= 5.0:
            msg = f"clearance must be between 0 and 5 m, got {self.clearance}"
            raise InputError(msg)
        if self.edges not in EDGE_OPTIONS:
            msg = f"edges must be one of {', '.join(EDGE_OPTIONS)}, got {self.edges!r}"
            raise InputError(msg)
        if self.placement is not None and not (
                all(abs(v) <= 1e6 for v in self.placement[:3])
                and abs(self.placement[3]) <= 360.0):
            msg = (f"placement must be x, y, z within ±1e6 m and yaw within ±360 deg (as a set "
                   f"file's [placement]), got {','.join(f'{v:g}' for v in self.placement)}")
            raise InputError(msg)

    @property
    def timing_edges(self) -> str:
        """The run-up and run-out the timing stage builds (:func:`timing_edges`)."""
        return timing_edges(self.edges)


def timing_edges(edges: str) -> str:
    """The run-up and run-out the timing stage builds for ``--edges``: ``"still"`` ends are
    gentle ones (what keeps them still is the path's zero velocity where the camera rests, and
    zero acceleration where it settles)."""
    return "gentle" if edges == "still" else edges



# --------------------------------------------------------------------------------------------
# Their command-line form, shared by convert, check, batch and farm export.
# --------------------------------------------------------------------------------------------


def _parse_placement(text: str) -> tuple[float, float, float, float]:
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        msg = f"placement must be x,y,z,yaw_deg (4 finite numbers), got {text!r}"
        raise InputError(msg)
    return (values[0], values[1], values[2], values[3])


def _parse_frames(text: str) -> tuple[int, int]:
    first, sep, last = text.partition(":")
    try:
        frames = (int(first), int(last))
    except ValueError:
        sep = ""
    if not sep:
        msg = f"frames must be A:B (two whole frame numbers), got {text!r}"
        raise InputError(msg)
    if frames[1] < frames[0]:
        msg = f"frames {text!r}: the last frame is before the first"
        raise InputError(msg)
    return frames


def _parse_start_from(text: str) -> tuple[float, ...]:
    """``--start-from``: 8 joint values, metres for track/extend, degrees for the rest -> SI."""
    from camtraj.robot import REVOLUTE

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != len(REVOLUTE) or not all(math.isfinite(v) for v in values):
        msg = (
            f"--start-from needs {len(REVOLUTE)} numbers (m for track/extend, deg for the rest), "
            f"got {text!r}"
        )
        raise InputError(msg)
    return tuple(math.radians(v) if REVOLUTE[i] else v for i, v in enumerate(values))


def start_from_text(values: Sequence[float]) -> str:
    """``--start-from``'s text for joint values (8,) [m, rad]: metres, and the shortest degrees
    that convert back to the same radians (``--start-from 30`` is echoed as 30.0, not as
    math.degrees' 29.999999999999996)."""
    from camtraj.robot import REVOLUTE

    return ",".join(
        _shortest_degrees(float(v)) if REVOLUTE[i] else repr(float(v))
        for i, v in enumerate(values)
    )


def _shortest_degrees(radians: float) -> str:
    """The shortest decimal of degrees whose radians are exactly ``radians``."""
    degrees = math.degrees(radians)
    for digits in range(16):
        text = repr(round(degrees, digits))
        if math.radians(float(text)) == radians:
            return text
    near = degrees  # math.degrees may land an ulp or two off the value that was given
    for _ in range(4):
        near = math.nextafter(near, math.inf if math.radians(near) < radians else -math.inf)
        if math.radians(near) == radians:
            return repr(near)
    return repr(degrees)


def convert_options(func: F) -> F:
    """Click decorator adding the options of ``camtraj convert`` that a batch or a job passes on.

    Adds ``--camera``, ``--robot``, ``--placement``, ``--frames``, ``--rate`` and ``--timing``;
    turn their values into :class:`camtraj.convert.ConvertOptions` with :func:`build_options`.
    """
    decorators = [
        click.option(
            "--camera", metavar="PRIM", help="Camera prim path (default: the only camera)."
        ),
        click.option(
            "--robot",
            type=click.Path(),
            metavar="ROBOT.toml",
            help="Robot description file (default: the built-in robot).",
        ),
        click.option(
            "--placement",
            metavar="X,Y,Z,YAW_DEG",
            help="Where the robot base stands in the stage: x,y,z [m] and yaw about up [deg] "
            "(default: at the stage origin).",
        ),
        click.option("--frames", metavar="A:B",
                     help="Film frame range of the shot to use (inclusive)."),
        click.option(
            "--rate",
            type=click.FloatRange(*RATE_RANGE),
            default=250.0,
            show_default=True,
            help="Servo rate [Hz].",
        ),
        click.option(
            "--timing",
            type=click.Choice(TIMING_MODES),
            default="shot",
            show_default=True,
            help="Keep the shot's timing, scale it to fit the limits, or retime it "
            "time-optimally under velocity, acceleration and jerk limits.",
        ),
    ]
    for decorator in reversed(decorators):
        func = decorator(func)
    return func


def more_convert_options(func: F) -> F:
    """Click decorator adding ``--set-file``, ``--start-from``, ``--objective``,
    ``--focal-length-unit``, ``--clearance``, ``--edges`` and ``--lens``.

    The less common convert options; pass their values to :func:`build_options` too.
    """
    decorators = [
        click.option(
            "--set-file",
            type=click.Path(),
            metavar="SET.toml",
            help="A TOML file whose [placement] table places the robot; --placement wins.",
        ),
        click.option(
            "--start-from",
            metavar="Q1,...,Q8",
            help="Joint values the robot starts from (m for track/extend, deg for the rest).",
        ),
        click.option(
            "--objective",
            type=click.Choice(OBJECTIVES),
            help="IK objective (default: the robot file's).",
        ),
        click.option(
            "--focal-length-unit",
            type=click.Choice(FOCAL_LENGTH_UNITS),
            default="schema",
            show_default=True,
            help="How the shot's focalLength is read: schema = tenths of a scene unit (USD); "
            "mm = millimetres, as some older exporters write it.",
        ),
        click.option(
            "--clearance",
            type=float,
            metavar="M",
            help="Distance [m] the robot must keep from the set file's [collision] prims "
            "(default: the set file's clearance_m).",
        ),
        click.option(
            "--edges",
            type=click.Choice(EDGE_OPTIONS),
            default="still",
            show_default=True,
            help="Run-up and run-out: still = where the camera is at rest on the first or last "
            "frame the robot stands still there too (not even accelerating where the camera "
            "settles), elsewhere as gentle; gentle = per axis no "
            "more acceleration and jerk than the shot uses (at least 25% of the limits), the "
            "robot free to move on a still end frame (on the shot set's moves it changes up to "
            "16% faster, median 8%); fast = the full limits (shortest).",
        ),
        click.option(
            "--lens",
            type=click.Path(),
            metavar="LENS.toml",
            help="Lens file: drive its zoom, focus and iris motors from the shot's lens, "
            "timed with the joints (default: the robot file's [lens], if any).",
        ),
    ]
    for decorator in reversed(decorators):
        func = decorator(func)
    return func


RIG_SUFFIX = ".rig.usda"
"""File name ending of the USD rig layer that batch and farm tasks write beside NAME.mcap."""


def rig_layer_for(mcap: str | os.PathLike[str]) -> Path:
    """The rig layer a batch or farm task writes with ``--usd``: ``NAME.rig.usda`` beside
    ``NAME.mcap``."""
    path = Path(mcap)
    return path.with_name(path.stem + RIG_SUFFIX)


def rig_layer_flag(func: F) -> F:
    """Click decorator adding ``--usd`` (a flag) to batch and farm export: every shot also
    writes its USD rig layer (``camtraj convert --usd``) as ``NAME.rig.usda`` beside
    ``NAME.mcap``. The value reaches the command as ``rig_layers``."""
    return click.option(
        "--usd",
        "rig_layers",
        is_flag=True,
        help="Also write NAME.rig.usda beside each NAME.mcap: the robot driving the move as a "
        "USD layer to sublayer onto the shot.",
    )(func)


def build_options(
    *,
    camera: str | None,
    robot: str | None,
    placement: str | None,
    frames: str | None,
    rate: float,
    timing: str,
    set_file: str | None = None,
    start_from: str | None = None,
    objective: str | None = None,
    focal_length_unit: str = "schema",
    clearance: float | None = None,
    edges: str = "still",
    lens: str | None = None,
) -> ConvertOptions:
    """Build convert options from the command-line strings of the option decorators.

    Raises:
        InputError: A malformed ``placement``, ``frames`` or ``start_from``, or a value that
            :class:`~camtraj.convert.ConvertOptions` refuses.
    """
    return ConvertOptions(
        camera=camera,
        robot=robot,
        placement=_parse_placement(placement) if placement is not None else None,
        set_file=set_file,
        frames=_parse_frames(frames) if frames is not None else None,
        rate=float(rate),
        timing=timing,
        start_from=_parse_start_from(start_from) if start_from is not None else None,
        objective=objective,
        focal_length_unit=focal_length_unit,
        clearance=clearance,
        edges=edges,
        lens=lens,
    )


def option_values(options: ConvertOptions) -> list[tuple[str, str]]:
    """``(flag, value)`` of every ``camtraj convert`` option that reproduces ``options``.

    ``--rate`` and ``--timing`` always; the others when set. Values are command-line text
    (placement and start-from in metres and degrees).
    """
    pairs: list[tuple[str, str]] = []
    if options.camera is not None:
        pairs.append(("--camera", options.camera))
    if options.robot is not None:
        pairs.append(("--robot", str(options.robot)))
    if options.placement is not None:
        pairs.append(("--placement", ",".join(repr(float(v)) for v in options.placement)))
    if options.set_file is not None:
        pairs.append(("--set-file", str(options.set_file)))
    if options.frames is not None:
        pairs.append(("--frames", f"{options.frames[0]}:{options.frames[1]}"))
    pairs.append(("--rate", repr(float(options.rate))))
    pairs.append(("--timing", options.timing))
    if options.start_from is not None:
        pairs.append(("--start-from", start_from_text(options.start_from)))
    if options.objective is not None:
        pairs.append(("--objective", options.objective))
    if options.focal_length_unit != "schema":
        pairs.append(("--focal-length-unit", options.focal_length_unit))
    if options.clearance is not None:
        pairs.append(("--clearance", repr(float(options.clearance))))
    if options.edges != "still":
        pairs.append(("--edges", options.edges))
    if options.lens is not None:
        pairs.append(("--lens", str(options.lens)))
    return pairs


def options_to_args(options: ConvertOptions) -> list[str]:
    """The ``camtraj convert`` arguments that reproduce ``options``.

    Returns:
        Arguments, one list item per argv word (not shell-quoted).
    """
    return [word for pair in option_values(options) for word in pair]


def options_to_json(options: ConvertOptions) -> dict[str, Any]:
    """Convert options as a JSON-able dict (tuples become lists)."""
    return {
        f.name: list(value) if isinstance(value, tuple) else value
        for f in dataclasses.fields(options)
        for value in [getattr(options, f.name)]
    }


def options_from_json(data: dict[str, Any]) -> ConvertOptions:
    """Inverse of :func:`options_to_json`.

    Raises:
        InputError: ``data`` names an option that this camtraj does not have.
    """
    known = {f.name for f in dataclasses.fields(ConvertOptions)}
    unknown = sorted(set(data) - known)
    if unknown:
        msg = f"unknown convert option(s) {unknown}; this camtraj knows {sorted(known)}"
        raise InputError(msg)
    values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    return ConvertOptions(**values)
