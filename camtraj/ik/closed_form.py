"""Closed-form six-axis substructure of the PRRPR-S robot (the SM method's core).

With track (r1) and extend (r4) fixed, the flange origin is the wrist centre W, and:

* the shoulder S = (r1 + r10, 0, r2) lies on the vertical rotate axis; rotate points the arm's
  vertical plane at W (front branch) or away from it (back branch);
* in that plane the arm is a planar chain S -> U (l3, perpendicular to the arm) -> E
  (r4 + r40 along the arm) -> W (r6, forearm), a triangle S-E-W with two elbow branches;
* pan/tilt/roll form a spherical wrist with two branches (tilt flip); where pan and roll align
  (tilt = ±90°) the previous pan is kept.

Every function is vectorised over candidates (and, with one target per candidate, over frames).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.robot import DHConstants

Array = NDArray[np.float64]

TWO_PI = 2.0 * math.pi
N_BRANCHES = 8  # rotate front/back x elbow up/down x wrist flip
TRACK, ROTATE, LIFT, EXTEND, ELBOW, PAN, TILT, ROLL = range(8)
WRIST_EPS = 1e-10  # |cos tilt| below this is the wrist singularity
EDGE = 1e-12  # rounding allowance at closed-form boundaries (reach, limits) [-, m, rad]
_FRONT_BACK = np.array([0.0, math.pi])
_SIGN2 = np.array([1.0, -1.0])

# ---------------------------------------------------------------------------------------------
# Closed-form six-axis substructure
# ---------------------------------------------------------------------------------------------


# Packed layout of the closed-form solutions of one candidate: each distinct value once
# (track, extend, 2 rotate, 4 lift, 4 elbow, 8 pan, 8 tilt, 8 roll). Wrapping, limit checks
# and costs run on these 36 columns instead of the 8 x 8 expanded joint vectors; IDX maps
# every branch's joint vector back to its columns.
AX = np.array([TRACK, EXTEND, *[ROTATE] * 2, *[LIFT] * 4, *[ELBOW] * 4,
                *[PAN] * 8, *[TILT] * 8, *[ROLL] * 8])
IDX = np.array([[0, 2 + i, 4 + 2 * i + j, 1, 8 + 2 * i + j, 12 + b, 20 + b, 28 + b]
                 for b in range(N_BRANCHES) for i, j in [divmod(b >> 1, 2)]])
PAIR = np.repeat(np.arange(4), 2)  # the wrist's two flips share the arm (rotate, elbow)
USES = np.zeros((AX.size, N_BRANCHES))  # USES[c, b] = 1 where branch b uses column c
for _b in range(N_BRANCHES):
    USES[IDX[_b], _b] = 1.0


def six_axis_solutions(
    dh: DHConstants,
    target: Array,
    r1: ArrayLike,
    r4: ArrayLike,
    previous: Array,
    lower: Array,
    upper: Array,
    stretch_margin: float | Array = 0.0,
    wrist_margin: float | Array = 0.0,
) -> tuple[Array, NDArray[np.bool_]]:
    """All closed-form branches for fixed track and extend values.

    Args:
        dh: The robot's DH constants.
        target: Flange pose in the base frame (``flange2base``), shape (4, 4) [m], or one
            pose per candidate, shape (N, 4, 4).
        r1: Track values, shape (N,) [m].
        r4: Extend values, shape (N,) [m].
        previous: Joint vector the revolute axes stay nearest to (2π-equivalents), (8,), or
            one per candidate, (N, 8).
        lower, upper: Position limits (8,) the solutions must respect, or per candidate (N, 8).
        stretch_margin: Minimum elbow angle away from full stretch [rad], scalar or (N,).
        wrist_margin: Minimum tilt angle away from the wrist singularity (±90°) [rad], scalar
            or (N,).

    Returns:
        ``q`` of shape (N, 8, 8): for each candidate and branch, the joint vector; and the
        feasibility mask of shape (N, 8). Infeasible entries hold NaN or out-of-limit values.
    """
    packed, ok = six_axis_packed(dh, target, r1, r4, previous,
                                  packed_limits(previous, lower, upper), stretch_margin,
                                  wrist_margin)
    return packed[:, IDX], ok


def packed_limits(previous: Array, lower: Array, upper: Array) -> tuple[Array, ...]:
    """Previous values and limits per packed column, (36,) or (N, 36), for six_axis_packed:
    previous, lower, upper of the revolute columns, then lower and upper with the rounding
    allowance of all columns."""
    lo, hi = lower[..., AX], upper[..., AX]
    return (np.asarray(previous, dtype=float)[..., AX[2:]], lo[..., 2:], hi[..., 2:],
            lo - EDGE, hi + EDGE)


def six_axis_packed(
    dh: DHConstants,
    target: Array,
    r1: ArrayLike,
    r4: ArrayLike,
    previous: Array,
    limits: tuple[Array, ...],
    stretch_margin: float | Array = 0.0,
    wrist_margin: float | Array = 0.0,
) -> tuple[Array, NDArray[np.bool_]]:
    """:func:`six_axis_solutions` in the packed layout: values (N, 36) and feasibility (N, 8).

    ``limits`` is :func:`packed_limits` of the previous joint vector and the limits.
    """
    r1a = np.asarray(r1, dtype=float)
    r4a = np.asarray(r4, dtype=float)
    n = r1a.shape[0]
    batched = target.ndim == 3  # one target per candidate
    W = target[..., :3, 3].T  # (3,) or (3, N)
    # rotation entries: scalars, or (N, 1) columns that broadcast against (N, 2) arrays
    R = target[:, :3, :3].transpose(1, 2, 0)[..., None] if batched else target[:3, :3]
    prev = np.asarray(previous, dtype=float)
    prev_rotate, prev_pan = prev[..., ROTATE], prev[..., PAN]
    dx = W[0] - dh.r10 - r1a  # (N,)
    dy = W[1]
    dz = W[2] - dh.r2
    hor = np.hypot(dx, dy)
    ws2 = np.maximum(hor * hor + dz * dz, 1e-300)
    dz_col = np.asarray(dz)[..., None]  # (1,) or (N, 1)

    # rotate: front (arm plane towards W) and back (plane turned by pi, arm reaching over)
    th2f = np.arctan2(dy, dx)
    if hor.min() <= 1e-12:  # wrist centre right above the rotate axis: keep the previous
        th2f = np.where(hor > 1e-12, th2f, prev_rotate)
    th2 = th2f[:, None] + _FRONT_BACK  # (N, 2)
    rho = hor[:, None] * _SIGN2  # (N, 2) signed horizontal distance in the arm plane

    L = r4a + dh.r40
    dse2 = L * L + dh.l3 * dh.l3
    cos_g = (ws2 + dse2 - dh.r6 * dh.r6) / (2.0 * np.sqrt(dse2 * ws2))
    # interior angle at the elbow E (pi at full stretch)
    cos_e = (dse2 + dh.r6 * dh.r6 - ws2) / (2.0 * dh.r6 * np.sqrt(dse2))
    reach_ok = (np.abs(cos_g) <= 1.0 + EDGE) & (cos_e >= -np.cos(stretch_margin) - EDGE)
    gamma = np.arccos(np.minimum(np.maximum(cos_g, -1.0), 1.0))  # (N,)
    beta = np.arctan2(dh.l3, L)

    # elbow branches: arm elevation a = angle(w) - beta -/+ gamma   -> (N, 2, 2)
    a = (np.arctan2(dz_col, rho) - beta[:, None])[:, :, None] - gamma[:, None, None] * _SIGN2
    ca, sa = np.cos(a), np.sin(a)
    Lb = L[:, None, None]
    dpx = rho[:, :, None] - (Lb * ca - dh.l3 * sa)  # forearm vector W - E in the plane
    dpz = dz_col[..., None] - (Lb * sa + dh.l3 * ca)
    psi = np.arctan2(dpx, -dpz)  # forearm angle; theta3 + theta5 = -psi
    cs, ss = np.cos(psi), -np.sin(psi)  # cos/sin of sigma = theta3 + theta5

    # spherical wrist: R58 = R05^T R. With c2, s2 of rotate, the columns of R05 are
    # x5 = (c2 cs, s2 cs, -ss), y5 = (s2, -c2, 0), z5 = (-c2 ss, -s2 ss, -cs).
    c2 = np.cos(th2)
    s2 = np.sin(th2)
    P0 = (c2 * R[0, 0] + s2 * R[1, 0])[:, :, None]
    P1 = (c2 * R[0, 1] + s2 * R[1, 1])[:, :, None]
    P2 = (c2 * R[0, 2] + s2 * R[1, 2])[:, :, None]
    R2 = R[2][..., None] if batched else R[2]  # bottom row, broadcast against (N, 2, 2)
    m02 = cs * P2 - ss * R2[2]
    m12 = (s2 * R[0, 2] - c2 * R[1, 2])[:, :, None]
    m22 = -ss * P2 - cs * R2[2]
    m20 = -ss * P0 - cs * R2[0]
    m21 = -ss * P1 - cs * R2[1]
    c7abs = np.hypot(m02, m12)
    s7 = np.minimum(np.maximum(m22, -1.0), 1.0)

    # wrist flip: cos(tilt) = +|c7| / -|c7|   -> (N, 2, 2, 2)
    sg = _SIGN2
    th7 = np.arctan2(s7[..., None], c7abs[..., None] * sg)
    th6 = np.arctan2(m12[..., None] * sg, m02[..., None] * sg)  # (N,2,2,2) by broadcasting
    th8 = np.arctan2(m21[..., None] * -sg, m20[..., None] * -sg)
    singular = c7abs < WRIST_EPS
    if singular.any():
        # pan and roll aligned: keep the previous pan, roll takes the rest
        m00 = cs * P0 - ss * R2[0]
        m10 = (s2 * R[0, 0] - c2 * R[1, 0])[:, :, None]
        s7s = np.where(s7 >= 0, 1.0, -1.0)[..., None]
        combo = np.arctan2(s7s * m10[..., None], s7s * m00[..., None])
        th6_keep = np.broadcast_to(np.asarray(prev_pan).reshape(-1, 1, 1, 1), th6.shape)
        th8_keep = np.where(s7s > 0, th6_keep - combo, combo - th6_keep)
        th6 = np.where(singular[..., None], th6_keep, th6)
        th8 = np.where(singular[..., None], th8_keep, th8)

    packed = np.concatenate([
        r1a[:, None], r4a[:, None], th2, (-a).reshape(n, 4), (a - psi).reshape(n, 4),
        th6.reshape(n, 8), th7.reshape(n, 8), th8.reshape(n, 8)], axis=1)
    prev_rev, lo_rev, hi_rev, lo_e, hi_e = limits
    # every column after track and extend is revolute: its 2π-equivalent nearest previous
    packed[:, 2:] = nearest_equivalent(packed[:, 2:], prev_rev, lo_rev, hi_rev)
    bad = (packed < lo_e) | (packed > hi_e)
    ok = (bad @ USES == 0.0) & reach_ok[:, None]
    if np.ndim(wrist_margin) == 0:
        if wrist_margin > 0.0:
            ok &= (c7abs.reshape(n, 4) >= math.sin(float(wrist_margin)))[:, PAIR]
    elif np.max(wrist_margin) > 0.0:
        ok &= (c7abs.reshape(n, 4) >= np.sin(wrist_margin).reshape(-1, 1))[:, PAIR]
    return packed, ok


def nearest_equivalent(x: Array, prev: Array, lo: Array, hi: Array) -> Array:
    """The 2π-equivalent of each angle nearest ``prev`` inside [lo, hi] (else the nearest)."""
    y = x + TWO_PI * np.rint((prev - x) * (1.0 / TWO_PI))
    out_y = (y < lo) | (y > hi)
    if not out_y.any():
        return y
    alt = y - TWO_PI * np.sign(y - prev)
    alt_in = (alt >= lo) & (alt <= hi)
    return np.where(out_y & alt_in, alt, y)



def six_axis_branch(
    dh: DHConstants,
    target: Array,
    r1: Array,
    r4: Array,
    previous: Array,
    lower: Array,
    upper: Array,
    branch: NDArray[np.intp],
) -> tuple[Array, NDArray[np.bool_]]:
    """One closed-form branch per candidate: :func:`six_axis_solutions` restricted to it.

    Args:
        dh: The robot's DH constants.
        target: Flange poses (N, 4, 4) [m], one per candidate.
        r1, r4: Track and extend values (N,) [m].
        previous: Joint vectors (N, 8) the revolute axes stay nearest to.
        lower, upper: Position limits (8,).
        branch: Branch index 0..7 per candidate (N,): rotate back (4), elbow (2), wrist flip (1).

    Returns:
        Joint vectors (N, 8) and their feasibility (N,) (no stretch or wrist margin).
    """
    s_i = 1.0 - 2.0 * (branch >> 2)  # front / back
    s_j = 1.0 - 2.0 * ((branch >> 1) & 1)  # elbow
    s_f = 1.0 - 2.0 * (branch & 1)  # wrist flip
    W = target[:, :3, 3]
    R = target[:, :3, :3]
    dx = W[:, 0] - dh.r10 - r1
    dy = W[:, 1]
    dz = W[:, 2] - dh.r2
    hor = np.hypot(dx, dy)
    ws2 = np.maximum(hor * hor + dz * dz, 1e-300)
    th2f = np.arctan2(dy, dx)
    if hor.min() <= 1e-12:
        th2f = np.where(hor > 1e-12, th2f, previous[:, ROTATE])
    th2 = th2f + math.pi * (s_i < 0)
    rho = hor * s_i
    L = r4 + dh.r40
    dse2 = L * L + dh.l3 * dh.l3
    cos_g = (ws2 + dse2 - dh.r6 * dh.r6) / (2.0 * np.sqrt(dse2 * ws2))
    cos_e = (dse2 + dh.r6 * dh.r6 - ws2) / (2.0 * dh.r6 * np.sqrt(dse2))
    reach_ok = (np.abs(cos_g) <= 1.0 + EDGE) & (cos_e >= -1.0 - EDGE)
    gamma = np.arccos(np.clip(cos_g, -1.0, 1.0))
    a = np.arctan2(dz, rho) - np.arctan2(dh.l3, L) - gamma * s_j
    ca, sa = np.cos(a), np.sin(a)
    psi = np.arctan2(rho - (L * ca - dh.l3 * sa), -(dz - (L * sa + dh.l3 * ca)))
    cs, ss = np.cos(psi), -np.sin(psi)
    c2, s2 = np.cos(th2), np.sin(th2)
    P0 = c2 * R[:, 0, 0] + s2 * R[:, 1, 0]
    P1 = c2 * R[:, 0, 1] + s2 * R[:, 1, 1]
    P2 = c2 * R[:, 0, 2] + s2 * R[:, 1, 2]
    m02 = cs * P2 - ss * R[:, 2, 2]
    m12 = s2 * R[:, 0, 2] - c2 * R[:, 1, 2]
    m22 = -ss * P2 - cs * R[:, 2, 2]
    m20 = -ss * P0 - cs * R[:, 2, 0]
    m21 = -ss * P1 - cs * R[:, 2, 1]
    c7abs = np.hypot(m02, m12)
    th7 = np.arctan2(np.clip(m22, -1.0, 1.0), c7abs * s_f)
    th6 = np.arctan2(m12 * s_f, m02 * s_f)
    th8 = np.arctan2(-m21 * s_f, -m20 * s_f)
    singular = c7abs < WRIST_EPS
    if singular.any():  # pan and roll aligned: keep the previous pan, roll takes the rest
        m00 = cs * P0 - ss * R[:, 2, 0]
        m10 = s2 * R[:, 0, 0] - c2 * R[:, 1, 0]
        s7s = np.where(m22 >= 0, 1.0, -1.0)
        combo = np.arctan2(s7s * m10, s7s * m00)
        keep = previous[:, PAN]
        th6 = np.where(singular, keep, th6)
        th8 = np.where(singular, np.where(s7s > 0, keep - combo, combo - keep), th8)
    q = np.stack([r1, th2, -a, r4, a - psi, th6, th7, th8], axis=1)
    rev = np.array([False, True, True, False, True, True, True, True])
    q[:, rev] = nearest_equivalent(q[:, rev], previous[:, rev], lower[rev], upper[rev])
    ok = reach_ok & np.all((q >= lower - EDGE) & (q <= upper + EDGE), axis=1)
    return q, ok
