"""The lens as axes: zoom, focus and iris motors driven from the previs lens (issue 16).

A lens file (``--lens LENS.toml``, or the same keys as a ``[lens]`` table in the robot file)
describes the lens motors of a motion-control rig: per axis ``zoom``, ``focus`` and ``iris``
a calibration table from the lens quantity to the motor position, the motor's position,
velocity, acceleration and jerk limits and optionally its controller counts. A prime lens
has no ``zoom`` table and gives its ``focal_length`` instead. Examples ship in
``camtraj/data/lenses/``.

Units: the lens quantities are the focal length [mm], the focus distance [m] and the stop
(f-number, or T-stop on a cine lens: the table's marks; the shot's ``fStop`` is taken as that
number). A motor position is the angle of the lens ring its motor turns, in the file's
``angle_unit`` and in radians inside camtraj (the axes are timed as revolute axes, so
messages show degrees).

Interpolation: a table maps the quantity ``x`` to the motor position through the variable
``u`` = ln x for the focal length and the stop (zoom and iris rings are close to linear in
stops and in the log of the focal length), ``u`` = 1 / x [1/m] for the focus distance (focus
rings are close to linear in dioptres, and ``inf`` marks infinity, u = 0). Between the rows it
is a monotone piecewise-cubic Hermite curve in ``u`` (scipy's ``CubicHermiteSpline``): PCHIP's
Fritsch-Butland slopes inside, the end intervals' secant slopes at the two ends, so it is C1,
passes through every row, never turns back (the rows must be strictly monotone) and never goes
flat, so its inverse (motor position to lens quantity, :meth:`Calibration.value`, by
bisection to the last bit) is well conditioned. Outside the table's range there is no
calibration: a shot that leaves it is an error at that frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.controller import CONTROLLER_KEYS, ControllerUnits, controller_units
from camtraj.errors import InputError, LensFileError, LensRangeError, frame_ranges
from camtraj.inputs import MIN_FILE_RATE, one_line, parse_toml, read_text, reject_unknown_keys

if TYPE_CHECKING:
    from camtraj.timing import Limits
    from camtraj.usd_shot import Shot

Array = NDArray[np.float64]

LENS_AXES: tuple[str, ...] = ("zoom", "focus", "iris")
"""The lens axes, in the order they follow the eight joints."""
QUANTITY: dict[str, str] = {"zoom": "focal length", "focus": "focus distance", "iris": "stop"}
"""What each axis's calibration table is indexed by."""
UNITS: dict[str, dict[str, float]] = {
    "zoom": {"mm": 1.0},
    "focus": {"m": 1.0, "cm": 0.01, "mm": 0.001, "ft": 0.3048, "in": 0.0254},
    "iris": {"T-stop": 1.0, "f-stop": 1.0},
}
"""Per axis, the units its table may be written in and their factor to mm, m or stops."""
MAX_MOTOR = 1.0e6
"""Largest magnitude of a motor position or limit in a lens file (deg or rad, per s ...)."""
RANGE_RTOL = 1e-6
"""A lens quantity this close (relative) to the end of the calibrated range is inside it
(USD keeps focal lengths, focus distances and stops as 32-bit floats: f/2.8 reads 2.7999999)."""
RING_TURNS = 1.0
"""A calibration table spanning more turns of its lens ring than this gets a warning (a lens
ring turns less than once; degrees read as radians turn it 57 times as far)."""
PRIME_RTOL = 1e-3
"""A shot's focal length this close (relative) to a prime's is the prime's: 0.05 mm on a 50 mm,
far below what a lens is marked to (a zoom easing away from 32 mm read as off a 32 mm prime at
32.00005 mm)."""
BISECTIONS = 80
"""Bisection steps of the inverse map: enough to reach the last bit of any double."""


@dataclass(frozen=True, eq=False)
class Calibration:
    """One axis's calibration: lens quantity -> motor position [rad] (module docstring).

    Attributes:
        axis: ``"zoom"``, ``"focus"`` or ``"iris"``.
        quantity: The table's lens quantities [mm, m or stop], increasing (focus may end
            with ``inf``).
        motor: The motor position of each row [rad], strictly monotone.
    """

    axis: str
    quantity: Array
    motor: Array
    _spline: Any = field(init=False, repr=False)
    _u_range: tuple[float, float] = field(init=False, repr=False)
    _rising: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        from scipy.interpolate import CubicHermiteSpline

        u = self.u(self.quantity)
        order = np.argsort(u)
        us, ms = u[order], self.motor[order]
        h = np.diff(us)
        slope = np.diff(ms) / h
        d = np.empty_like(us)
        d[0], d[-1] = slope[0], slope[-1]
        w1, w2 = 2.0 * h[1:] + h[:-1], h[1:] + 2.0 * h[:-1]
        d[1:-1] = (w1 + w2) / (w1 / slope[:-1] + w2 / slope[1:])
        object.__setattr__(self, "_spline", CubicHermiteSpline(us, ms, d))
        object.__setattr__(self, "_u_range", (float(us[0]), float(us[-1])))
        object.__setattr__(self, "_rising", bool(ms[-1] > ms[0]))

    @property
    def low(self) -> float:
        """The smallest calibrated lens quantity."""
        return float(self.quantity[0])

    @property
    def high(self) -> float:
        """The largest calibrated lens quantity (``inf``: focus to infinity)."""
        return float(self.quantity[-1])

    def u(self, x: ArrayLike) -> Array:
        """The interpolation variable of lens quantities ``x``: ln x, or 1 / x for focus."""
        xa = np.asarray(x, dtype=np.float64)
        with np.errstate(divide="ignore"):
            out: Array = 1.0 / xa if self.axis == "focus" else np.log(xa)
        return out

    def position(self, x: ArrayLike) -> Array:
        """Motor positions [rad] of lens quantities ``x`` inside the calibrated range (a hair
        beyond an end, :data:`RANGE_RTOL`, the end interval's cubic goes on)."""
        out: Array = self._spline(self.u(x))
        return out

    def value(self, motor: ArrayLike) -> Array:
        """The lens quantity at motor positions [rad]: the inverse of :meth:`position`
        (bisection over the table's range and a hair beyond; a position farther out gives
        that bracket's end)."""
        m = np.asarray(motor, dtype=np.float64)
        lo_u, hi_u = self._u_range
        margin = 1e-5 * (hi_u - lo_u)
        lo, hi = np.full(m.shape, lo_u - margin), np.full(m.shape, hi_u + margin)
        rising = self._rising
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            at = self._spline(mid)
            above = (at > m) if rising else (at < m)
            hi = np.where(above, mid, hi)
            lo = np.where(above, lo, mid)
        ends = self._spline(np.stack([lo, hi]))
        u = np.where(np.abs(ends[0] - m) <= np.abs(ends[1] - m), lo, hi)
        if self.axis == "focus":
            with np.errstate(divide="ignore"):
                out: Array = np.where(u > 0.0, 1.0 / np.where(u > 0.0, u, 1.0), np.inf)
            return out
        x: Array = np.exp(u)
        return x


@dataclass(frozen=True, eq=False)
class LensAxis:
    """One lens motor: its calibration and limits (radians, seconds).

    Attributes:
        name: ``"zoom"``, ``"focus"`` or ``"iris"``.
        unit: The unit its table was written in (``"mm"``, ``"m"``, ``"ft"``, ``"T-stop"``...).
        calibration: Lens quantity -> motor position.
        lower, upper: Motor position limits [rad].
        velocity, acceleration, jerk: Motor limits [rad/s, rad/s², rad/s³].
        home: Where the motor stands when the shot does not set its quantity [rad].
        controller: Motor position -> controller counts, if given.
    """

    name: str
    unit: str
    calibration: Calibration
    lower: float
    upper: float
    velocity: float
    acceleration: float
    jerk: float
    home: float
    controller: ControllerUnits | None = None


@dataclass(frozen=True, eq=False)
class Lens:
    """A lens's motors (those it has, in :data:`LENS_AXES` order) and, for a prime, its
    focal length [mm]."""

    name: str
    source: str
    axes: tuple[LensAxis, ...]
    focal_length_mm: float | None = None

    @classmethod
    def from_toml(cls, path: str | Path) -> Lens:
        """Read a lens file (UTF-8 TOML, through :func:`camtraj.inputs.read_text`).

        Raises:
            LensFileError: Unreadable, not TOML, a key missing, unknown or out of range, a
                table not monotone; one line naming the file, the key and the range.
        """
        where = f"lens file {one_line(path)}"
        text = read_text(path, "lens file", LensFileError)
        data = parse_toml(text, where, LensFileError)
        return lens_from_table(data, where=where, source=str(path), prefix="",
                               error=LensFileError)

    @property
    def names(self) -> tuple[str, ...]:
        """The axis names, in order."""
        return tuple(a.name for a in self.axes)

    def axis(self, name: str) -> LensAxis | None:
        """The axis ``name``, or None if this lens has no such motor."""
        return next((a for a in self.axes if a.name == name), None)

    def limits(self) -> Limits:
        """The motors' limits, for the timing stage (revolute axes: ring angles)."""
        from camtraj.timing import Limits

        def col(key: str) -> Array:
            return np.array([getattr(a, key) for a in self.axes], dtype=np.float64)

        return Limits(col("lower"), col("upper"), col("velocity"), col("acceleration"),
                      col("jerk"), names=self.names, kinds=("revolute",) * len(self.axes))

    def counts(self, q: ArrayLike) -> dict[str, Array]:
        """Controller counts of motor positions ``q`` (..., axes) for axes that have them."""
        qa = np.asarray(q, dtype=np.float64)
        return {a.name: a.controller.counts(qa[..., i]) for i, a in enumerate(self.axes)
                if a.controller is not None}

    def describe(self) -> dict[str, Any]:
        """A JSON-friendly summary (MCAP metadata, reports): per axis its position unit, the
        lens quantity, its calibrated range (in ``quantity_unit``: mm, m or stops; the file's
        own unit is ``file_unit``; an end at infinity is None, JSON null) and its limits (rad,
        per s...)."""
        return {
            "name": self.name,
            "source": self.source,
            "focal_length_mm": self.focal_length_mm,
            "axes": {
                a.name: {
                    "position_unit": "rad (lens ring angle)",
                    "quantity": QUANTITY[a.name],
                    "quantity_unit": {"zoom": "mm", "focus": "m"}.get(a.name, a.unit),
                    "file_unit": a.unit,
                    "range": [_json_number(a.calibration.low * 1.0),
                              _json_number(a.calibration.high * 1.0)],
                    "lower": a.lower, "upper": a.upper, "max_velocity": a.velocity,
                    "max_acceleration": a.acceleration, "max_jerk": a.jerk,
                }
                for a in self.axes
            },
        }


def _json_number(x: float) -> float | None:
    """A range's end for JSON: null where it is infinity (a focus calibrated to infinity), as
    every JSON camtraj writes has it."""
    return x if math.isfinite(x) else None


# ---------------------------------------------------------------------------------------------
# The shot's lens on the motors
# ---------------------------------------------------------------------------------------------


def shot_quantity(shot: Shot, axis: str) -> Array:
    """The shot's lens quantity for ``axis`` per frame: focal length [mm], focus distance
    [m] or f-stop."""
    if axis == "zoom":
        return shot.focal_length_mm
    return shot.focus_distance_m if axis == "focus" else shot.f_stop


def _show(axis: str, x: float, unit: str = "") -> str:
    """A lens quantity for people: a stop as T or f/, a focal length in mm, a focus distance
    in m and, for a lens file written in another unit, in that unit too (12 m (39.37 ft))."""
    if axis == "iris":
        return f"{'T' if unit == 'T-stop' else 'f/'}{x:.3g}"
    if not math.isfinite(x):
        return "infinity"
    if axis == "zoom":
        return f"{x:.4g} mm"
    factor = UNITS["focus"].get(unit, 1.0)
    return f"{x:.4g} m" + (f" ({x / factor:.4g} {unit})" if factor != 1.0 else "")


def lens_positions(lens: Lens, shot: Shot) -> Array:
    """The motor position of every lens axis at every frame [rad], shape (n, axes).

    An axis follows its shot quantity through its calibration; an axis whose quantity the
    shot leaves unset (focus distance or f-stop 0 at every frame, USD's "not authored") holds
    at its ``home``.

    Raises:
        LensRangeError: Where a quantity leaves the calibrated range (the first such frame,
            its value and the lens's end of range named, and every frame outside).
        InputError: A focus distance or f-stop unset (0) on some frames but set on others.
    """
    n = shot.frames.shape[0]
    out = np.empty((n, len(lens.axes)))
    for i, axis in enumerate(lens.axes):
        x = np.asarray(shot_quantity(shot, axis.name), dtype=np.float64)
        if axis.name != "zoom" and not np.any(x):
            out[:, i] = axis.home
            continue
        if axis.name != "zoom" and not np.all(x):  # unset (0) on some frames only
            unset = [int(f) for f in shot.frames[x == 0.0]]
            msg = (f"{QUANTITY[axis.name]} is unset (0) on {frame_ranges(unset)} but set on the "
                   f"others: the {axis.name} motor needs a value on every frame (set it on "
                   f"every frame, or on none to hold the motor at its home)")
            raise InputError(msg)
        cal = axis.calibration
        low = x < cal.low * (1.0 - RANGE_RTOL)
        high = x > cal.high * (1.0 + RANGE_RTOL)
        bad = np.flatnonzero(low | high | ~(x == x))
        if bad.size:
            k = int(bad[0])
            side, end = ("below", cal.low) if low[k] else ("beyond", cal.high)
            if axis.name == "focus":
                side = "nearer than" if low[k] else "farther than"
            read = (f" (the shot's fStop {float(x[k]):.3g})"
                    if axis.name == "iris" and axis.unit == "T-stop" else "")
            shown = _show(axis.name, float(x[k]), axis.unit)
            also = ("" if bad.size == 1 else
                    f" (outside on {frame_ranges([int(f) for f in shot.frames[bad]])})")
            msg = (f"{QUANTITY[axis.name]} {shown}{read} at frame "
                   f"{int(shot.frames[k])}{also} is {side} the lens's "
                   f"{_show(axis.name, end, axis.unit)} ({lens.name} covers "
                   f"{_show(axis.name, cal.low, axis.unit)} to "
                   f"{_show(axis.name, cal.high, axis.unit)}; lens file {lens.source})")
            raise LensRangeError(msg)
        pos = cal.position(x)
        # a value within RANGE_RTOL beyond an end (a 32-bit float's round-off) maps beyond the
        # end's position; where that is past a motor limit set on the end, it is the end
        past = ((x < cal.low) | (x > cal.high)) & ((pos < axis.lower) | (pos > axis.upper))
        out[:, i] = np.where(past, cal.position(np.clip(x, cal.low, cal.high)), pos)
    return out


def commanded_lens(lens: Lens, positions: Array, shot: Shot) -> dict[str, Array]:
    """The lens the motors give at each frame: ``focal_length_mm``, ``focus_distance_m`` and
    ``f_stop``, each (n,): an axis's motor positions (``positions``, (n, axes)) mapped back
    through its calibration, a prime's focal length, or the shot's own value for a quantity
    the lens has no motor for."""
    out = {"focal_length_mm": shot.focal_length_mm, "focus_distance_m": shot.focus_distance_m,
           "f_stop": shot.f_stop}
    if lens.focal_length_mm is not None:
        out["focal_length_mm"] = np.full(shot.frames.shape[0], lens.focal_length_mm)
    for i, axis in enumerate(lens.axes):
        key = {"zoom": "focal_length_mm", "focus": "focus_distance_m", "iris": "f_stop"}
        out[key[axis.name]] = axis.calibration.value(positions[:, i])
    return out


def lens_warnings(lens: Lens, shot: Shot) -> list[str]:
    """What the lens cannot follow of the shot: a focal length a prime does not have, a
    focus distance or f-stop animated without a motor to drive."""
    out = []
    for motor in lens.axes:  # a lens ring turns less than once: more reads as the wrong unit
        turned = float(np.ptp(motor.calibration.motor))
        if turned > RING_TURNS * 2.0 * math.pi:
            out.append(
                f"the lens file's {motor.name} table spans {math.degrees(turned):,.0f} deg of "
                f"the ring ({turned / (2.0 * math.pi):.1f} turns; a lens ring turns less than "
                f"once): is its angle_unit right? (lens file {lens.source})")
    if lens.axis("zoom") is None and lens.focal_length_mm is not None:
        fl = shot.focal_length_mm
        off = np.abs(fl - lens.focal_length_mm) > PRIME_RTOL * lens.focal_length_mm
        if off.any():
            span = (f"{float(fl.min()):.4g} mm" if float(np.ptp(fl)) == 0.0 else
                    f"{float(fl.min()):.4g} to {float(fl.max()):.4g} mm")
            out.append(
                f"the shot's focal length ({span}, first at frame "
                f"{int(shot.frames[int(np.argmax(off))])}) is not reachable with the "
                f"{lens.focal_length_mm:g} mm prime {lens.name}: the camera info shows "
                f"{lens.focal_length_mm:g} mm")
    for axis, what, unit in (("focus", "focus distance", " m"), ("iris", "f-stop", "")):
        x = shot_quantity(shot, axis)
        if lens.axis(axis) is None and float(x.max()) > float(x.min()):  # inf: focus at infinity
            span = (f"{_show(axis, float(x.min()))} to {_show(axis, float(x.max()))}" if unit
                    else f"f/{float(x.min()):.4g} to f/{float(x.max()):.4g}")
            out.append(
                f"the shot animates its {what} ({span}) "
                f"but the lens {lens.name} has no {axis} calibration: the {axis} is not "
                "driven")
        driven = lens.axis(axis)
        if driven is not None and not np.any(x):  # USD's "not authored": the motor holds home
            cal = driven.calibration
            lo, hi = float(np.min(cal.motor)), float(np.max(cal.motor))
            if not lo - 1e-9 <= driven.home <= hi + 1e-9:  # no lens value there: say where
                end = lo if driven.home < lo else hi
                shown = (f"{math.degrees(driven.home):.2f} deg, outside its calibration, "
                         f"which ends at {math.degrees(end):.2f} deg")
            else:
                home = float(cal.value(np.array([driven.home]))[0])
                at_inf = (bool(np.isinf(cal.quantity[-1]))
                          and abs(driven.home - cal.motor[-1]) < 1e-9)
                shown = (_show(axis, home, driven.unit) if math.isfinite(home) and not at_inf
                         else "infinity")
            out.append(
                f"the shot does not set its {what}: the {axis} motor holds at its home "
                f"({shown}, lens file {lens.source})")
    return out


# ---------------------------------------------------------------------------------------------
# The lens file
# ---------------------------------------------------------------------------------------------

_AXIS_KEYS = {"unit", "calibration", "min", "max", "max_velocity", "max_acceleration",
              "max_jerk", "home"}


class _Reader:
    """Checks of a lens table's values; every error names the file and the key."""

    def __init__(self, where: str, prefix: str, error: type[InputError]) -> None:
        self.where, self.prefix, self.error = where, prefix, error

    def fail(self, key: str, what: str) -> InputError:
        return self.error(f"{self.where}: [{self.prefix}{key}] {what}")

    def table(self, data: dict[str, Any], key: str) -> dict[str, Any]:
        value = data.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(key, "must be a table")
        return value

    def no_unknown(self, table: dict[str, Any], allowed: set[str], key: str) -> None:
        what = f"[{self.prefix}{key}]" if key else (
            f"[{self.prefix[:-1]}]" if self.prefix else "the top level")
        reject_unknown_keys(table, allowed, self.where, what, self.error)

    def number(self, value: Any, key: str, *, finite: bool = True) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"= {value!r}: must be a number")
        if math.isnan(value) or (finite and not math.isfinite(value)):
            raise self.fail(key, f"= {value!r}: must be finite")
        return float(value)

    def required(self, table: dict[str, Any], key: str, at: str) -> Any:
        if key not in table:
            raise self.fail(f"{at}.{key}", "is missing")
        return table[key]


def lens_from_table(data: dict[str, Any], *, where: str, source: str, prefix: str,
                    error: type[InputError]) -> Lens:
    """A :class:`Lens` from a lens file's keys (``prefix`` ``""``) or a robot file's ``[lens]``
    table (``prefix`` ``"lens."``); errors are ``error`` naming ``where`` and the key.

    Keys: ``name``, ``angle_unit`` (``"deg"`` or ``"rad"``: motor positions and limits),
    ``focal_length`` [mm] (a prime's; not with ``[zoom]``), ``[zoom]``, ``[focus]``,
    ``[iris]`` (``unit``, ``calibration`` = [[quantity, motor position], ...] with the
    quantity increasing, ``min``, ``max``, ``max_velocity``, ``max_acceleration``,
    ``max_jerk``, optional ``home``), optional ``[controller.AXIS]`` (``scale``, ``offset``,
    ``sign``: counts = offset + sign * scale * position [rad]).
    """
    r = _Reader(where, prefix, error)
    r.no_unknown(data, {"name", "angle_unit", "focal_length", "controller", *LENS_AXES}, "")
    name = data.get("name", "lens")
    if not isinstance(name, str):
        raise r.fail("name", f"= {name!r}: must be a string")
    if "angle_unit" not in data:
        raise r.fail("angle_unit", "is missing: say \"deg\" or \"rad\" (the motor positions' "
                     "unit)")
    unit = data["angle_unit"]
    if unit not in ("deg", "rad"):
        raise r.fail("angle_unit", f"= {unit!r}: must be \"deg\" or \"rad\"")
    ang = math.pi / 180.0 if unit == "deg" else 1.0
    axes = tuple(_axis(r, r.table(data, axis), axis, ang) for axis in LENS_AXES
                 if axis in data)
    if not axes:
        raise r.fail("zoom", "is missing, and so are [focus] and [iris]: a lens file "
                     "describes the motors that drive the lens; give at least one")
    focal: float | None = None
    if "focal_length" in data:
        if any(a.name == "zoom" for a in axes):
            raise r.fail("focal_length", "is a prime lens's focal length: a zoom lens takes "
                         "its range from [zoom]; give one or the other")
        focal = r.number(data["focal_length"], "focal_length")
        if not 1.0 <= focal <= 5000.0:
            raise r.fail("focal_length", f"= {focal:g}: must be between 1 and 5000 mm")
    elif not any(a.name == "zoom" for a in axes):
        raise r.fail("focal_length", "is missing: a lens without a [zoom] table is a prime "
                     "and needs its focal length [mm]")
    controllers = r.table(data, "controller")
    r.no_unknown(controllers, {a.name for a in axes}, "controller")
    if controllers:
        axes = tuple(_with_controller(r, controllers, a) for a in axes)
    return Lens(name=name, source=source, axes=axes, focal_length_mm=focal)


def _axis(r: _Reader, tab: dict[str, Any], axis: str, ang: float) -> LensAxis:
    r.no_unknown(tab, _AXIS_KEYS, axis)
    unit = r.required(tab, "unit", axis)
    units = UNITS[axis]
    if unit not in units:
        raise r.fail(f"{axis}.unit", f"= {unit!r}: is not a unit of {QUANTITY[axis]}; say "
                     + " or ".join(f'"{u}"' for u in units))
    limits = {}
    for key in ("min", "max", "max_velocity", "max_acceleration", "max_jerk"):
        value = r.number(r.required(tab, key, axis), f"{axis}.{key}")
        if key.startswith("max_") and not MIN_FILE_RATE <= value <= MAX_MOTOR:
            raise r.fail(f"{axis}.{key}", f"= {value:g}: must be between {MIN_FILE_RATE:g} "
                         f"and {MAX_MOTOR:g}")
        if abs(value) > MAX_MOTOR:
            raise r.fail(f"{axis}.{key}", f"= {value:g}: must be within ±{MAX_MOTOR:g}")
        limits[key] = value * ang
    if not limits["min"] < limits["max"]:
        raise r.fail(axis, f"min ({tab['min']}) must be below max ({tab['max']})")
    quantity, motor = _table(r, r.required(tab, "calibration", axis), axis,
                             units[unit], ang)
    lo, hi = limits["min"], limits["max"]
    outside = np.flatnonzero((motor < lo - 1e-12) | (motor > hi + 1e-12))
    if outside.size:
        k = int(outside[0])
        raise r.fail(f"{axis}.calibration", f"row {k + 1}: motor position {motor[k] / ang:g} "
                     f"is outside the motor's range [{tab['min']}, {tab['max']}]")
    home = motor[0]
    if "home" in tab:
        home = r.number(tab["home"], f"{axis}.home") * ang
        if not lo <= home <= hi:
            raise r.fail(f"{axis}.home", f"= {tab['home']}: outside [{tab['min']}, "
                         f"{tab['max']}]")
    return LensAxis(axis, unit, Calibration(axis, quantity, motor), lo, hi,
                    limits["max_velocity"], limits["max_acceleration"], limits["max_jerk"],
                    float(home))


def _table(r: _Reader, value: Any, axis: str, scale: float, ang: float) -> tuple[Array, Array]:
    """The calibration rows as (quantity [mm, m, stop], motor [rad]), checked."""
    key = f"{axis}.calibration"
    what = (f"must be a list of [{QUANTITY[axis]}, motor position] pairs, at least two, "
            f"{QUANTITY[axis]} increasing")
    if not isinstance(value, list) or len(value) < 2:
        raise r.fail(key, what)
    rows = []
    for k, row in enumerate(value):
        if not isinstance(row, list) or len(row) != 2:
            raise r.fail(key, f"row {k + 1} = {row!r}: {what}")
        x = r.number(row[0], f"{key} row {k + 1}", finite=False)
        m = r.number(row[1], f"{key} row {k + 1}")
        if abs(m) > MAX_MOTOR:
            raise r.fail(key, f"row {k + 1}: motor position {m:g} must be within ±{MAX_MOTOR:g}")
        if not x > 0.0 or (math.isinf(x) and (axis != "focus" or k != len(value) - 1)):
            raise r.fail(key, f"row {k + 1}: {QUANTITY[axis]} {x:g} must be a positive finite "
                         "number" + (" (inf only as the last focus mark)"
                                     if axis == "focus" else ""))
        rows.append((x * scale, m * ang))
    quantity = np.array([x for x, _ in rows])
    motor = np.array([m for _, m in rows])
    dq, dm = np.diff(quantity), np.diff(motor)
    bad = np.flatnonzero(~(dq > 0))
    if bad.size == 0:
        sign = np.sign(dm[0])
        bad = np.flatnonzero(~(np.sign(dm) == sign) | (dm == 0))
    if bad.size:
        k = int(bad[0]) + 1
        raise r.fail(key, f"is not monotone at row {k + 1} ({value[k][0]!r}, {value[k][1]!r}) "
                     f"after ({value[k - 1][0]!r}, {value[k - 1][1]!r}): the {QUANTITY[axis]} "
                     "must increase down the table and the motor position rise (or fall) "
                     "all the way")
    return quantity, motor


def _with_controller(r: _Reader, controllers: dict[str, Any], axis: LensAxis) -> LensAxis:
    if axis.name not in controllers:
        return axis
    key = f"controller.{axis.name}"
    ct = r.table(controllers, axis.name)
    r.no_unknown(ct, set(CONTROLLER_KEYS), key)
    return replace(axis, controller=controller_units(ct, key, r.number, r.fail, "radian"))


__all__ = [
    "LENS_AXES",
    "QUANTITY",
    "UNITS",
    "Calibration",
    "Lens",
    "LensAxis",
    "commanded_lens",
    "lens_from_table",
    "lens_positions",
    "lens_warnings",
]
