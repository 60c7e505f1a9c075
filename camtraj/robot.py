"""The PRRPR-S camera robot: its description file, DH model and forward kinematics.

Conventions (design.md §2–3): SI units (m, rad), robot base frame with x along the track and
z up, joints ordered track, rotate, lift, extend, elbow, pan, tilt, roll. Transforms are named
``a2b``: ``flange2base`` maps flange coordinates into base coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.controller import CONTROLLER_KEYS, ControllerUnits, controller_units
from camtraj.errors import InputError, RobotFileError
from camtraj.inputs import MIN_FILE_RATE, parse_toml, read_text, reject_unknown_keys

if TYPE_CHECKING:
    from camtraj.lens import Lens

Array = NDArray[np.float64]

JOINT_NAMES: tuple[str, ...] = (
    "track", "rotate", "lift", "extend", "elbow", "pan", "tilt", "roll",
)
JOINT_KINDS: tuple[str, ...] = (
    "prismatic", "revolute", "revolute", "prismatic", "revolute", "revolute", "revolute",
    "revolute",
)
N_JOINTS = len(JOINT_NAMES)
PRISMATIC = np.array([k == "prismatic" for k in JOINT_KINDS])
REVOLUTE = ~PRISMATIC
WRIST_FRAME = 6
"""The DH frame whose origin is the wrist centre, where the pan, tilt and roll axes meet."""


@dataclass(frozen=True)
class DHRow:
    """One standard DH transform ``Rz(theta0 + s*q) Tz(d0 + s*q) Tx(a) Rx(alpha)``.

    ``joint`` is the index of the joint variable that moves this row (``None`` for the fixed
    A0), ``kind`` says whether it turns theta or slides d, ``sign`` is +1 or -1 (A8 turns
    the other way, design.md §3).
    """

    theta0: float
    d0: float
    a: float
    alpha: float
    joint: int | None
    kind: str
    sign: float = 1.0


@dataclass(frozen=True)
class DHConstants:
    """The paper's fixed lengths [m]."""

    r10: float = 1.000
    r2: float = 0.300
    l3: float = 0.333
    r40: float = 2.500
    r6: float = 0.963

    def rows(self) -> tuple[DHRow, ...]:
        """The nine DH transforms A0..A8 of the SM paper's Table 1 / eq. (1)."""
        h = math.pi / 2
        return (
            DHRow(h, 0.0, 0.0, h, None, "fixed"),
            DHRow(0.0, self.r10, 0.0, -h, 0, "prismatic"),
            DHRow(-h, self.r2, 0.0, -h, 1, "revolute"),
            DHRow(-h, 0.0, self.l3, -h, 2, "revolute"),
            DHRow(0.0, self.r40, 0.0, h, 3, "prismatic"),
            DHRow(h, 0.0, 0.0, -h, 4, "revolute"),
            DHRow(0.0, self.r6, 0.0, h, 5, "revolute"),
            DHRow(-h, 0.0, 0.0, -h, 6, "revolute"),
            DHRow(0.0, 0.0, 0.0, 0.0, 7, "revolute", -1.0),
        )


@dataclass(frozen=True)
class IKSettings:
    """How the redundancy (track, extend) and the branch are chosen (the ``[ik]`` table).

    objective: ``"shot"`` (whole-shot choice, the default) or ``"paper"`` (the papers'
        per-frame optimum of the weighted motion F).
    The rest configure the shot objective (``camtraj.ik.shot_cost`` gives the formula):
    stretch_margin, wrist_margin: widths of the zones [rad] near full stretch and near the
        wrist singularity (tilt ±90°) where a margin cost applies.
    limit_margin_prismatic [m], limit_margin_revolute [rad]: the same near position limits.
    motion_weight, velocity_weight, overspeed_weight, margin_weight: the weights of the
        dynamic programme's terms (``camtraj.ik.shot_cost``).
    peak_margin_weight, tie_break_weight: the weights of the margins and of the papers'
        weighted motion F next to the take's peak use in the refinement.
    track_samples, extend_samples: the candidate grid (``camtraj.ik.shot``).
    refine_rounds: most Gauss-Newton steps of each stage of the refinement.
    refine_tolerance: a stage has converged after three steps in a row that lower its
        objective by less than this fraction (the first stage; the later ones, which
        polish its answer, at ten times it), each by no more than the step before.
    """

    objective: str = "shot"
    stretch_margin: float = math.radians(20.0)
    wrist_margin: float = math.radians(25.0)
    limit_margin_prismatic: float = 0.1
    limit_margin_revolute: float = math.radians(25.0)
    motion_weight: float = 1.0
    velocity_weight: float = 1.0
    overspeed_weight: float = 1000.0
    margin_weight: float = 10.0
    peak_margin_weight: float = 0.1
    tie_break_weight: float = 0.01
    track_samples: int = 4
    extend_samples: int = 2
    refine_rounds: int = 25
    refine_tolerance: float = 1e-4


@dataclass(frozen=True)
class Robot:
    """A PRRPR-S camera robot: geometry, limits, weights, mount and IK settings.

    Every per-joint array has shape (8,) in joint order, SI units. ``lens``: the lens whose
    motors are timed and commanded with the joints (the robot file's ``[lens]`` table, or
    ``--lens``; :mod:`camtraj.lens`), or None.
    """

    name: str
    dh: DHConstants
    lower: Array
    upper: Array
    max_velocity: Array
    max_acceleration: Array
    max_jerk: Array
    weights: Array
    home: Array
    camera2flange: Array
    ik: IKSettings
    controller: dict[str, ControllerUnits] = field(default_factory=dict)
    source: str = "builtin"
    joint_names: tuple[str, ...] = JOINT_NAMES
    joint_kinds: tuple[str, ...] = JOINT_KINDS
    lens: Lens | None = None

    # -- construction -------------------------------------------------------------------
    @classmethod
    def default(cls) -> Robot:
        """The papers' robot with camtraj's documented default limits."""
        text = resources.files("camtraj").joinpath("data/robot.toml").read_text()
        return cls.from_toml_text(text, source="builtin robot.toml")

    @classmethod
    def from_toml(cls, path: str | Path) -> Robot:
        """Load a robot description file (UTF-8 TOML).

        Raises:
            RobotFileError: The file is missing, not a regular file, not UTF-8 text, not
                TOML, or lacks or mistypes a value; the message names the file and the key.
        """
        path = Path(path)
        return cls.from_toml_text(_read_text(path), source=str(path))

    @classmethod
    def from_toml_text(cls, text: str, *, source: str = "<text>") -> Robot:
        return _robot_from_dict(parse_toml(text, f"robot file {source}", RobotFileError),
                                source)

    # -- kinematics ---------------------------------------------------------------------
    def link_frames(self, q: ArrayLike) -> Array:
        """Frames 0..8 (after A0..A8) in the base frame, shape (..., 9, 4, 4) for q (..., 8)."""
        return link_frames(self.dh, q)

    def fk(self, q: ArrayLike) -> Array:
        """Flange (frame 8) pose in the base frame: ``flange2base``, shape (..., 4, 4) [m]."""
        return self.link_frames(q)[..., -1, :, :]

    def camera_pose(self, q: ArrayLike) -> Array:
        """Camera pose in the base frame (``camera2base``), shape (..., 4, 4)."""
        return self.fk(q) @ self.camera2flange

    def within_limits(self, q: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """Whether each joint vector is inside the position limits, shape (...,)."""
        qa = np.asarray(q, dtype=float)
        inside: NDArray[np.bool_] = np.all(
            (qa >= self.lower - tol) & (qa <= self.upper + tol), axis=-1
        )
        return inside

    def joint_vector(self, q: ArrayLike, what: str) -> Array:
        """``q`` as an (8,) joint vector inside the position limits [m, rad].

        Args:
            q: Joint values, shape (8,).
            what: Where they come from, for the message (e.g. ``"--start-from"``).

        Raises:
            InputError: Not 8 finite values, or an axis outside its limits (the message names
                the axis, the value and the limit, in m or deg).
        """
        try:
            qa = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            qa = np.full(0, np.nan)
        if qa.shape != (N_JOINTS,) or not np.all(np.isfinite(qa)):
            msg = f"{what} needs {N_JOINTS} finite joint values, got {q!r}"
            raise InputError(msg)
        for j, name in enumerate(self.joint_names):
            if self.lower[j] - 1e-9 <= qa[j] <= self.upper[j] + 1e-9:
                continue
            scale, unit = (1.0, "m") if PRISMATIC[j] else (180.0 / math.pi, "deg")
            side, bound = ("upper", self.upper[j]) if qa[j] > self.upper[j] else (
                "lower", self.lower[j])
            msg = (
                f"{what}: {name} = {qa[j] * scale:g} {unit} is beyond its {side} limit "
                f"{bound * scale:g} {unit} (limits {self.lower[j] * scale:g} to "
                f"{self.upper[j] * scale:g} {unit}, robot file {self.source})"
            )
            raise InputError(msg)
        return qa

    def counts(self, q: ArrayLike) -> dict[str, Array]:
        """Controller counts for the axes that have controller units."""
        qa = np.asarray(q, dtype=float)
        return {
            name: unit.counts(qa[..., JOINT_NAMES.index(name)])
            for name, unit in self.controller.items()
        }

    def describe(self) -> dict[str, Any]:
        """A JSON-friendly summary (for metadata and reports)."""
        return {
            "name": self.name,
            "source": self.source,
            "joints": list(self.joint_names),
            "lower": self.lower.tolist(),
            "upper": self.upper.tolist(),
            "max_velocity": self.max_velocity.tolist(),
            "max_acceleration": self.max_acceleration.tolist(),
            "max_jerk": self.max_jerk.tolist(),
            "weights": self.weights.tolist(),
            "ik_objective": self.ik.objective,
            **({} if self.lens is None else {"lens": self.lens.describe()}),
        }


def dh_matrices(dh: DHConstants, q: ArrayLike) -> Array:
    """The nine DH transforms for joint vectors q (..., 8), shape (..., 9, 4, 4)."""
    qa = np.asarray(q, dtype=float)
    if qa.shape[-1] != N_JOINTS:
        msg = f"joint vectors must have {N_JOINTS} values, got shape {qa.shape}"
        raise ValueError(msg)
    batch = qa.shape[:-1]
    rows = dh.rows()
    theta = np.empty((*batch, len(rows)))
    d = np.empty_like(theta)
    for i, row in enumerate(rows):
        qi = row.sign * qa[..., row.joint] if row.joint is not None else 0.0
        theta[..., i] = row.theta0 + (qi if row.kind == "revolute" else 0.0)
        d[..., i] = row.d0 + (qi if row.kind == "prismatic" else 0.0)
    a = np.array([r.a for r in rows])
    alpha = np.array([r.alpha for r in rows])
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    A = np.zeros((*batch, len(rows), 4, 4))
    A[..., 0, 0] = ct
    A[..., 0, 1] = -st * ca
    A[..., 0, 2] = st * sa
    A[..., 0, 3] = a * ct
    A[..., 1, 0] = st
    A[..., 1, 1] = ct * ca
    A[..., 1, 2] = -ct * sa
    A[..., 1, 3] = a * st
    A[..., 2, 1] = sa
    A[..., 2, 2] = ca
    A[..., 2, 3] = d
    A[..., 3, 3] = 1.0
    return A


def link_frames(dh: DHConstants, q: ArrayLike) -> Array:
    """Cumulative products A0·…·Ai, shape (..., 9, 4, 4)."""
    A = dh_matrices(dh, q)
    out = np.empty_like(A)
    T = A[..., 0, :, :]
    out[..., 0, :, :] = T
    for i in range(1, A.shape[-3]):
        T = T @ A[..., i, :, :]
        out[..., i, :, :] = T
    return out


# ---------------------------------------------------------------------------------------------
# Robot description file
# ---------------------------------------------------------------------------------------------

MAX_FILE_VALUE = 1.0e6
"""Largest magnitude of a joint limit in a robot file (m, deg; per s, s², s³): beyond it the
solver's arithmetic overflows, and no machine comes near it."""
def _read_text(path: Path) -> str:
    """The file's text, refusing what is not a regular UTF-8 file (a FIFO would block)."""
    return read_text(path, "robot file", RobotFileError)


_TOP_KEYS = {"robot", "dh", "joints", "mount", "ik", "controller", "lens"}
_JOINT_KEYS = {
    "kind", "min", "max", "max_velocity", "max_acceleration", "max_jerk", "weight", "home",
}


def _robot_from_dict(data: dict[str, Any], source: str) -> Robot:
    where = f"robot file {source}"

    def fail(key: str, what: str) -> RobotFileError:
        return RobotFileError(f"{where}: [{key}] {what}")

    _no_unknown(data, _TOP_KEYS, where, "top level")
    meta = _table(data, "robot", where, required=True)
    _no_unknown(meta, {"name", "angle_unit"}, where, "[robot]")
    name = meta.get("name", "camera robot")
    if not isinstance(name, str):
        raise fail("robot.name", f"= {name!r}: must be a string")
    if "angle_unit" not in meta:
        raise fail("robot.angle_unit", "is missing: say \"deg\" or \"rad\"")
    unit = meta["angle_unit"]
    if unit not in ("deg", "rad"):
        raise fail("robot", f"angle_unit = {unit!r}: must be \"deg\" or \"rad\"")
    ang = math.pi / 180.0 if unit == "deg" else 1.0

    dh_tab = _table(data, "dh", where, required=True)
    _no_unknown(dh_tab, {"r10", "r2", "l3", "r40", "r6"}, where, "[dh]")
    dh_vals: dict[str, float] = {}
    for key in ("r10", "r2", "l3", "r40", "r6"):
        if key not in dh_tab:
            raise fail(f"dh.{key}", "is missing: the DH model needs r10, r2, l3, r40 and r6 [m]")
        val = _number(dh_tab[key], f"dh.{key}", where)
        if not 0.0 <= val <= 50.0:
            raise fail(f"dh.{key}", f"= {val}: must be between 0 and 50 m")
        dh_vals[key] = val
    dh = DHConstants(**dh_vals)
    if dh.r6 <= 0 or dh.r40 <= 0:
        raise fail("dh", "r40 and r6 must be positive lengths")

    joints = _table(data, "joints", where, required=True)
    _no_unknown(joints, set(JOINT_NAMES), where, "[joints]")
    cols: dict[str, list[float]] = {k: [] for k in _JOINT_KEYS - {"kind"}}
    for jname, kind in zip(JOINT_NAMES, JOINT_KINDS, strict=True):
        key = f"joints.{jname}"
        if jname not in joints:
            raise fail(key, "is missing: every axis needs its table")
        jt = joints[jname]
        if not isinstance(jt, dict):
            raise fail(key, "must be a table")
        _no_unknown(jt, _JOINT_KEYS, where, f"[{key}]")
        if jt.get("kind", kind) != kind:
            raise fail(f"{key}.kind", f"= {jt.get('kind')!r}: axis {jname} is {kind}")
        scale = 1.0 if kind == "prismatic" else ang
        for col in cols:
            if col not in jt:
                raise fail(f"{key}.{col}", "is missing")
            cols[col].append(_number(jt[col], f"{key}.{col}", where) * (
                1.0 if col == "weight" else scale
            ))
        lo, hi = cols["min"][-1], cols["max"][-1]
        if not lo < hi:
            raise fail(f"{key}", f"min ({jt['min']}) must be below max ({jt['max']})")
        if max(abs(jt["min"]), abs(jt["max"])) > MAX_FILE_VALUE:
            raise fail(key, f"min and max must lie within ±{MAX_FILE_VALUE:g}")
        for col in ("max_velocity", "max_acceleration", "max_jerk"):
            if not MIN_FILE_RATE <= jt[col] <= MAX_FILE_VALUE:
                raise fail(f"{key}.{col}", f"= {jt[col]}: must be between {MIN_FILE_RATE:g} "
                           f"and {MAX_FILE_VALUE:g}")
        if cols["weight"][-1] < 0:
            raise fail(f"{key}.weight", f"= {jt['weight']}: must not be negative")
        if not lo <= cols["home"][-1] <= hi:
            raise fail(f"{key}.home", f"= {jt.get('home')}: outside [{jt['min']}, {jt['max']}]")
    elbow = JOINT_NAMES.index("elbow")
    if cols["min"][elbow] < -math.pi - 1e-9 or cols["max"][elbow] > 1e-9:
        given = f"[{cols['min'][elbow] / ang:g}, {cols['max'][elbow] / ang:g}] {unit}"
        inside = "[-180, 0] deg" if unit == "deg" else f"[{-math.pi:.6g}, 0] rad"
        raise fail("joints.elbow", f"min and max = {given}: must lie inside {inside} (the "
                   "mechanism's range)")

    mount = _table(data, "mount", where, required=True)
    _no_unknown(mount, {"rotation", "offset"}, where, "[mount]")
    for key in ("rotation", "offset"):
        if key not in mount:
            raise fail(f"mount.{key}", "is missing")
    rot = _array(mount["rotation"], (3, 3), "mount.rotation", "a 3x3 matrix of numbers", where)
    off = float(np.abs(rot @ rot.T - np.eye(3)).max())
    if off > 1e-6 or np.linalg.det(rot) < 0:
        why = [f"R R^T is {off:.2g} from the identity, more than 1e-06"
               + (" (give its entries to 7 or more decimals)" if off < 1e-3 else "")
               if off > 1e-6 else "", "it is mirrored (det < 0)" if np.linalg.det(rot) < 0
               else ""]
        raise fail("mount.rotation", "must be a proper rotation (orthonormal, det +1): "
                   + "; ".join(w for w in why if w))
    offset = _array(mount["offset"], (3,), "mount.offset", "three numbers [m]", where)
    if np.abs(offset).max() > 5:
        raise fail("mount.offset", "must be three numbers [m], each within ±5 m")
    camera2flange = np.eye(4)
    camera2flange[:3, :3] = rot
    camera2flange[:3, 3] = offset

    ik = _ik_settings(_table(data, "ik", where, required=False), ang, where)
    lower, upper = np.array(cols["min"]), np.array(cols["max"])

    controller: dict[str, ControllerUnits] = {}
    ctab = _table(data, "controller", where, required=False)
    _no_unknown(ctab, set(JOINT_NAMES), where, "[controller]")
    for jname, ct in ctab.items():
        key = f"controller.{jname}"
        if not isinstance(ct, dict):
            raise fail(key, "must be a table")
        _no_unknown(ct, set(CONTROLLER_KEYS), where, f"[{key}]")
        controller[jname] = controller_units(
            ct, key, lambda value, k: _number(value, k, where), fail)

    lens = None
    if "lens" in data:
        from camtraj.lens import lens_from_table

        lens = lens_from_table(_table(data, "lens", where, required=True), where=where,
                               source=f"{source} [lens]", prefix="lens.", error=RobotFileError)
    return Robot(
        name=name,
        dh=dh,
        lower=lower,
        upper=upper,
        max_velocity=np.array(cols["max_velocity"]),
        max_acceleration=np.array(cols["max_acceleration"]),
        max_jerk=np.array(cols["max_jerk"]),
        weights=np.array(cols["weight"]),
        home=np.array(cols["home"]),
        camera2flange=camera2flange,
        ik=ik,
        controller=controller,
        source=source,
        lens=lens,
    )


_IK_RANGES: dict[str, tuple[float, float, str]] = {
    # key: (min, max, unit) with unit "angle" (the file's angle unit), "m", "" or "int"
    "stretch_margin": (math.radians(0.1), math.radians(60.0), "angle"),
    "wrist_margin": (math.radians(0.1), math.radians(60.0), "angle"),
    "limit_margin_revolute": (math.radians(0.1), math.radians(60.0), "angle"),
    "limit_margin_prismatic": (1e-3, 1.0, "m"),
    "motion_weight": (0.0, 1e4, ""),
    "velocity_weight": (0.0, 1e4, ""),
    "overspeed_weight": (0.0, 1e6, ""),
    "margin_weight": (0.0, 1e4, ""),
    "peak_margin_weight": (0.0, 1e4, ""),
    "tie_break_weight": (0.0, 1e4, ""),
    "track_samples": (1, 16, "int"),
    "extend_samples": (1, 16, "int"),
    "refine_rounds": (0, 1000, "int"),
    "refine_tolerance": (1e-12, 0.1, ""),
}


def _ik_settings(tab: dict[str, Any], ang: float, where: str) -> IKSettings:
    """The ``[ik]`` table; every value range-checked, angles in the file's unit."""
    _no_unknown(tab, {"objective", *_IK_RANGES}, where, "[ik]")
    objective = tab.get("objective", "shot")
    if objective not in ("shot", "paper"):
        msg = f"{where}: [ik.objective] = {objective!r}: must be \"shot\" or \"paper\""
        raise RobotFileError(msg)
    defaults = IKSettings()
    values: dict[str, Any] = {"objective": objective}
    for key, (lo, hi, unit) in _IK_RANGES.items():
        scale = ang if unit == "angle" else 1.0
        default = getattr(defaults, key)
        if key not in tab:
            values[key] = default
            continue
        val = _number(tab[key], f"ik.{key}", where)
        if unit == "int" and val != int(val):
            msg = f"{where}: [ik.{key}] = {tab[key]!r}: must be a whole number"
            raise RobotFileError(msg)
        val *= scale
        if not lo <= val <= hi:
            shown = f"{lo / scale:g} and {hi / scale:g}"
            msg = f"{where}: [ik.{key}] = {tab[key]!r}: must be between {shown}"
            raise RobotFileError(msg)
        values[key] = int(val) if unit == "int" else val
    return IKSettings(**values)


def _table(data: dict[str, Any], key: str, where: str, *, required: bool) -> dict[str, Any]:
    if key not in data:
        if required:
            msg = f"{where}: [{key}] is missing"
            raise RobotFileError(msg)
        return {}
    val = data[key]
    if not isinstance(val, dict):
        msg = f"{where}: [{key}] must be a table"
        raise RobotFileError(msg)
    return val


def _no_unknown(table: dict[str, Any], allowed: set[str], where: str, what: str) -> None:
    reject_unknown_keys(table, allowed, where, what, RobotFileError)


def _array(value: Any, shape: tuple[int, ...], key: str, what: str, where: str) -> Array:
    """A nested list of finite numbers of exactly ``shape`` (no ragged rows, no strings)."""

    def values(v: Any, dims: tuple[int, ...]) -> list[Any]:
        if not isinstance(v, list) or len(v) != dims[0]:
            msg = f"{where}: [{key}] = {value!r}: must be {what}"
            raise RobotFileError(msg)
        if len(dims) == 1:
            return [_number(x, key, where) for x in v]
        return [values(row, dims[1:]) for row in v]

    return np.array(values(value, shape), dtype=np.float64)


def _number(value: Any, key: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        msg = f"{where}: [{key}] = {value!r}: must be a number"
        raise RobotFileError(msg)
    if not math.isfinite(value):
        msg = f"{where}: [{key}] = {value!r}: must be finite"
        raise RobotFileError(msg)
    return float(value)
